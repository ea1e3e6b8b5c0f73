"""The study protocol: every study of ``exposim validate`` is a registered ``Study``, pyproject.toml and the
built-in list agree, studies of other distributions join them, and a broken one says why."""

from __future__ import annotations

import argparse
import sys
import tomllib
import types
from importlib import metadata
from pathlib import Path

import pytest

from emulator.commands.cli import build_parser, main
from emulator.errors import ExposimError
from validation.commands.validate import OWN_STUDIES, STUDY_GROUP, load_studies, register, study_entry_points
from validation.protocol import Study

ROOT = Path(__file__).resolve().parents[3]


def _validate_parser(studies) -> argparse.ArgumentParser:
    top = argparse.ArgumentParser(prog="exposim")
    register(top.add_subparsers(dest="command"), studies)
    return top


def test_pyproject_registers_exactly_the_built_in_studies_in_order():
    eps = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["entry-points"][STUDY_GROUP]
    assert list(eps.items()) == list(OWN_STUDIES)


def test_every_own_study_loads_and_validate_offers_it_in_order():
    studies = load_studies()
    assert [s.name for s in studies] == [name for name, _ in OWN_STUDIES]
    assert all(isinstance(s, Study) for s in studies)
    validate = build_parser()._subparsers._group_actions[0].choices["validate"]  # noqa: SLF001
    offered = list(validate._subparsers._group_actions[0].choices)  # noqa: SLF001
    assert offered == [name for name, _ in OWN_STUDIES]
    assert {"emulation", "live", "native", "study-power", "level-shift", "monte-carlo"} <= set(offered)


def test_without_installed_entry_points_the_own_studies_remain():
    own = study_entry_points(installed=[])
    assert [(ep.name, ep.value) for ep in own] == list(OWN_STUDIES)
    again = study_entry_points(installed=[metadata.EntryPoint(n, v, STUDY_GROUP) for n, v in OWN_STUDIES])
    assert [(ep.name, ep.value) for ep in again] == list(OWN_STUDIES)  # this project's own registration: once


def test_a_study_of_another_distribution_follows_and_runs(monkeypatch, capsys):
    ran = []
    mod = types.ModuleType("fake_exposim_study")
    mod.STUDY = Study("fake", "a fake study", lambda p: p.add_argument("--n", type=int, default=2),
                      lambda args: ran.append(args.n) or 0, extras=())
    monkeypatch.setitem(sys.modules, "fake_exposim_study", mod)
    ep = metadata.EntryPoint("fake", "fake_exposim_study:STUDY", STUDY_GROUP)
    eps = study_entry_points(installed=[ep, ep])
    assert [e.name for e in eps][-1] == "fake" and len(eps) == len(OWN_STUDIES) + 1
    args = _validate_parser(load_studies(eps[-1:])).parse_args(["validate", "fake", "--n", "5"])
    assert (args.experiment, args.extras) == ("fake", ()) and args.func(args) == 0 and ran == [5]


@pytest.mark.parametrize("value, why", [("no_such_exposim_module:STUDY", "cannot load no_such_exposim_module:STUDY"),
                                        ("argparse:ArgumentParser", "is not the Study 'ghost'")])
def test_a_broken_study_is_offered_and_says_why(value, why):
    studies = load_studies([metadata.EntryPoint("ghost", value, STUDY_GROUP)])
    assert studies[0][0] == "ghost" and why in studies[0][1]
    args = _validate_parser(studies).parse_args(["validate", "ghost", "x"])
    with pytest.raises(ExposimError, match="this study is broken"):
        args.func(args)


def test_a_moved_study_runs_through_validate_and_names_a_bad_folder(tmp_path, capsys):
    for name, prefix in (("level-shift", "level_shift"), ("monte-carlo", "monte_carlo"),
                         ("own-residuals", "own_residuals"), ("study-calibration", "study_calibration")):
        assert main(["validate", name, str(tmp_path / "nowhere")]) == 1
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith(f"{prefix}: ") and "nowhere" in err[0], err


def test_the_calibration_study_runs_through_validate_and_records_its_command(tmp_path, monkeypatch, capsys):
    from validation.calibration_study import cli

    seen = {}
    monkeypatch.setattr(cli, "run_study", lambda output, **kw: seen.update(output=output, **kw))
    assert main(["validate", "calibration", "-o", str(tmp_path / "cal"), "--quick", "--parts", "static, real"]) == 0
    assert seen["output"] == tmp_path / "cal" and seen["quick"] and not seen["force"]
    assert seen["parts"] == ("static", "real") and seen["radiance_source"] == "static_lab"
    assert seen["command"] == (f"exposim validate calibration -o {tmp_path / 'cal'} --quick --radiance static_lab "
                               "--parts 'static, real'")
    assert capsys.readouterr().out.startswith(f"wrote {tmp_path / 'cal' / 'results.json'}")

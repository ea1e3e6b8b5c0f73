"""``exposim calibrate --noise SEQ -o noise.json``: the in-situ noise model, printed and written.

The recording is synth's BorealHDR-like camera (the builder of tests/emulator/noise/test_noise_insitu.py:
320x240, static textured chart, three sweeps), whose gain is known: the in-situ estimate
is within 5 % of it there (+3.1 % measured, about 4 standard errors allowed).  The CLI must
print the estimator's own values and write a file that reads back to the same model.
"""

from __future__ import annotations

import json

import pytest

from emulator.commands.cli import main
from emulator.io.borealhdr import sequence_response
from emulator.io.noisemodel import read_noise_model
from emulator.noise import bracket_groups, estimate_noise_model
from synth.noise_model import noise_model_of

from tests.emulator.noise.test_noise_insitu import _recording

GROUPS = 6


def test_cli_calibrate_noise_writes_and_prints_the_estimate(tmp_path, capsys):
    cam, seq = _recording(tmp_path, 0.0)
    out = tmp_path / "models" / "noise.json"
    args = ["calibrate", "--noise", str(seq.path), "-o", str(out), "--max-groups", str(GROUPS), "--no-progress"]
    assert main(args) == 0
    text = capsys.readouterr().out
    response = sequence_response(seq)
    est = estimate_noise_model(bracket_groups(seq, max_groups=GROUPS), response, name=f"in-situ:{seq.path}")
    truth = noise_model_of(cam)
    assert abs(est.gain_e_per_h / truth.gain_e_per_h - 1) < 0.05
    top = float(response.g[response.white_level])
    lines = {ln[:12].strip(): ln[12:] for ln in text.splitlines()}
    assert lines["gain"] == f"{est.gain_e_per_h:.4g} +- {est.gain_std:.4g} e- per unit of g"
    assert lines["read noise"] == f"{est.read_noise_e:.3g} +- {est.read_noise_std:.3g} e- rms"
    assert lines["full well"] == f"{est.full_well_e:.4g} +- {est.gain_std * top:.4g} e- at DN {response.white_level}"
    assert lines["wrote"] == str(out)

    # the file reads back to the same model, through the same response
    model = read_noise_model(out, response)
    assert model.gain_e_per_h == est.gain_e_per_h and model.read_noise_e == est.read_noise_e
    assert model.name == f"in-situ:{seq.path}"
    data = json.loads(out.read_text())
    assert data["estimate"]["gain_std"] == est.gain_std and len(data["estimate"]["per_group"]) == GROUPS

    # never overwritten without --force, and the file is untouched
    before = out.read_bytes()
    assert main(args) == 1
    assert "noise.json: exists; refusing to overwrite (use --force)" in capsys.readouterr().err
    assert out.read_bytes() == before
    assert main(args + ["--force", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["gain_e_per_h"] == est.gain_e_per_h and d["full_well_std"] == pytest.approx(est.gain_std * top)
    assert out.read_bytes() == before  # same inputs, same bytes


def test_cli_calibrate_noise_errors(tmp_path, capsys):
    assert main(["calibrate", "--noise", str(tmp_path / "missing"), "-o", str(tmp_path / "n.json")]) == 1
    assert "missing" in capsys.readouterr().err
    assert not (tmp_path / "n.json").exists()
    assert main(["calibrate", str(tmp_path), "--noise", str(tmp_path), "-o", str(tmp_path / "n.json")]) == 1
    assert "give one of a STACK folder, --from-recording SEQ or --noise SEQ" in capsys.readouterr().err


def test_readme_row_names_the_noise_option():
    from pathlib import Path

    from emulator.commands.cli import build_parser

    readme = (Path(__file__).resolve().parents[3] / "docs" / "commands.md").read_text(encoding="utf-8")
    row = next(line for line in readme.splitlines() if line.startswith("| `exposim calibrate "))
    assert "`--noise SEQ -o noise.json`" in row
    sub = build_parser()._subparsers._group_actions[0].choices  # noqa: SLF001 - argparse has no public accessor
    assert any("--noise" in a.option_strings for a in sub["calibrate"]._actions)

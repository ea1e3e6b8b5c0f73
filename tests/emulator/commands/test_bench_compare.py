"""``exposim bench compare``: methods of several run folders in one table (issue 46).

A plugin-only run and an earlier built-in run make one ranking; a cycle-rate and a native-rate run of the
same methods stand side by side, judged on the same recorder cycles.
"""

from __future__ import annotations

import csv
import json
import warnings
from pathlib import Path

import numpy as np
import pytest

from emulator.commands.cli import main
from emulator.orchestration.runner import run_to_folder
from tests.conftest import static_chart_recording  # noqa: E402

EXAMPLES = Path(__file__).resolve().parents[3] / "examples"


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """On one static chart (4 recorder cycles): built-ins at cycle rate, the same at native rate, and
    the plugin guide's example alone at cycle rate."""
    base = tmp_path_factory.mktemp("cmp")
    seq = static_chart_recording(base / "static", 40, 24, dynamic_range_db=50.0, n_shots=24, noise=True)
    mp = pytest.MonkeyPatch()
    mp.syspath_prepend(str(EXAMPLES))
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            run_to_folder(seq, "classical-50,fixed", base / "builtins", initial_ms=1.0)
            run_to_folder(seq, "classical-50,fixed", base / "native", initial_ms=1.0, rate="native")
            run_to_folder(seq, "my_ae:MyAE", base / "plugin", initial_ms=1.0)
    finally:
        mp.undo()
    return base


def _column(path, name, keep=None):
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    if keep is not None:
        rows = [r for r in rows if r[keep] == "1"]
    return np.array([float(r[name]) for r in rows])


def test_a_plugin_run_and_an_earlier_builtin_run_make_one_ranking(runs, tmp_path, capsys):
    out = tmp_path / "cmp"
    assert main(["bench", "compare", str(runs / "builtins"), str(runs / "plugin"), "-o", str(out)]) == 0
    err = capsys.readouterr().err
    results = json.loads((out / "results.json").read_text())
    sat = results["comparisons"]["mean_saturated_fraction"]
    assert set(sat["methods"]) == {"classical-50", "fixed", "my-ae"}  # one name each: no suffix
    assert sorted(results["ranking"]) == ["classical-50", "fixed", "my-ae"]
    for label, folder in (("classical-50", "builtins"), ("my-ae", "plugin")):
        expected = _column(runs / folder / label / "exposures.csv", "saturated_fraction").mean()
        assert sat["methods"][label]["estimate"] == pytest.approx(expected)
    ests = [sat["methods"][m]["estimate"] for m in results["ranking"]]
    assert ests == sorted(ests)  # lower saturation ranks first
    assert results["comparisons"]["n_common_units"] == 4  # paired on the 4 recorder cycles
    report = (out / "report.md").read_text()
    assert "## One ranking" in report and "Ranking: " in report and (out / "report.html").is_file()
    assert f"1. {results['ranking'][0]}: mean saturated fraction" in err


def test_cycle_rate_and_native_rate_side_by_side(runs, tmp_path, capsys):
    out = tmp_path / "cmp"
    assert main(["bench", "compare", str(runs / "builtins"), str(runs / "native"), "-o", str(out), "-q"]) == 0
    results = json.loads((out / "results.json").read_text())
    assert set(results["rows"]) == {"classical-50 (cycle)", "fixed (cycle)", "classical-50 (native)",
                                    "fixed (native)"}
    native = results["rows"]["fixed (native)"]
    assert native["rate"] == "native" and native["n_units"] == 4  # the benchmarked frame of each recorder cycle
    exp = results["comparisons"]["mean_exposure_ms"]
    expected = _column(runs / "native" / "fixed" / "exposures.csv", "target_ms", keep="benchmarked").mean()
    assert exp["fixed (native)"]["estimate"] == pytest.approx(expected)
    report = (out / "report.md").read_text()
    by_rate = report.split("## By method and rate", 1)[1].strip().splitlines()
    assert by_rate[0] == "| method | mean saturated (%), cycle | mean saturated (%), native |"
    assert by_rate[2].startswith("| classical-50 | ") and by_rate[3].startswith("| fixed | ")


def test_compare_refuses_mixed_inputs_in_one_line(runs, tmp_path, capsys):
    assert main(["bench", "compare", str(runs / "builtins"), str(tmp_path), "-o", str(tmp_path / "o")]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "neither a run folder" in err
    assert not (tmp_path / "o").exists()


def test_features_folders_compare_on_matches_and_keep_a_shared_method_apart(tmp_path, capsys):
    try:
        from tests.emulator.metrics.test_metrics_vo import make_synthetic_run
    except ImportError:  # tests collected as a package
        from tests.test_metrics_vo import make_synthetic_run

    a = make_synthetic_run(tmp_path / "a", n_frames=4, methods=("fixed", "shim"))["run"]
    b = make_synthetic_run(tmp_path / "b", n_frames=4, methods=("fixed", "kim"))["run"]
    for run, out in ((a, "fa"), (b, "fb")):
        assert main(["bench", "features", str(run), "-o", str(tmp_path / out), "-q"]) == 0
    assert main(["bench", "compare", str(tmp_path / "fa"), str(tmp_path / "fb"), "-o", str(tmp_path / "c"),
                 "-q"]) == 0
    results = json.loads((tmp_path / "c" / "results.json").read_text())
    assert results["kind"] == "features"
    matches = results["comparisons"]["median_matches"]["methods"]
    assert set(matches) == {"fixed (fa)", "shim", "fixed (fb)", "kim"}  # one recording, one rate: by folder
    fa = json.loads((tmp_path / "fa" / "results.json").read_text())
    assert matches["shim"]["estimate"] == fa["methods"]["shim"]["median_matches"]
    assert "| method | median matches, fa | median matches, fb |" in (tmp_path / "c" / "report.md").read_text()
    # a run folder and a features folder are not compared
    assert main(["bench", "compare", str(a), str(tmp_path / "fa"), "-o", str(tmp_path / "x")]) == 1
    assert "not both" in capsys.readouterr().err

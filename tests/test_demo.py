"""``exposim demo --quick`` runs the whole chain: synth -> emulation check -> 7 AE methods -> features/VO."""

import json

import pytest

from emulator.cli import main
from emulator.errors import OutputExistsError
from validation.demo import new_output_dir, run_demo

pytestmark = [pytest.mark.render, pytest.mark.slow]


def test_quick_demo_end_to_end(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("EXPOSIM_DENOISE", "off")  # not a rendering test: raw renders keep it fast
    out = tmp_path / "demo"
    assert main(["demo", "--quick", "-q", "-o", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "# exposim demo" in printed and f"wrote {out}" in printed
    assert (out / "report.md").read_text() in printed
    results = json.loads((out / "results.json").read_text())
    assert (out / "report.md").is_file() and (out / "run" / "exposure.png").is_file()
    assert set(results["run"]["methods"]) == {
        "fixed", "classical-30", "classical-50", "classical-70", "shim", "zhang", "kim"
    }
    emu = results["emulation"]
    # emulated vs noiseless ground truth at the same instant: the source bracket's own
    # sensor noise (a few tenths of a percent) plus quantisation; far below a wrong response
    assert 0 < emu["median_rmse_percent"] < 1.5
    assert emu["max_rmse_percent"] < 3.0
    assert (out / "features" / "results.json").is_file() and (out / "vo" / "results.json").is_file()
    with pytest.raises(OutputExistsError):
        run_demo(out, quick=True)


def test_default_output_never_overwrites(tmp_path):
    base = tmp_path / "exposim-demo"
    (tmp_path / "exposim-demo-1").mkdir()
    assert new_output_dir(base) == tmp_path / "exposim-demo-2"

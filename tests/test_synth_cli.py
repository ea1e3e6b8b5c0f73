"""``exposim synth``: a rendered scene through the synthetic camera into the BorealHDR layout."""

import json

import numpy as np
import pytest

from emulator.cli import main
from emulator.io.borealhdr import load_sequence, sequence_response
from emulator.io.png import read_png16
from emulator.emulate import emulate

pytestmark = pytest.mark.render


def test_synth_writes_a_loadable_dataset_with_ground_truth(tmp_path, capsys):
    out = tmp_path / "lab"
    args = ["synth", "static_lab", "-o", str(out), "--cycles", "1", "--size", "48x30", "--spp", "4",
            "--gt-exposures", "3,5", "--quiet", "--noiseless", "--denoise", "off"]
    assert main(args) == 0
    assert "wrote" in capsys.readouterr().out
    seq = load_sequence(out)
    assert seq.cameras == ("left", "right") and len(seq) == 1
    assert seq.brackets == (1.0, 2.0, 4.0, 8.0, 16.0, 32.0) and not seq[0].partial
    for b in seq.brackets:  # a stereo pair shares one timestamp
        assert seq[0].frames["left"][b].timestamp_ns == seq[0].frames["right"][b].timestamp_ns
    meta = json.loads((out / "exposim.json").read_text())
    assert meta["white_level"] == seq.white_level
    for f in ("calibration/left.yaml", "calibration/right.yaml", "calibration/response.txt",
              "ground_truth/poses_left.txt", "ground_truth/poses_right.txt"):
        assert (out / f).is_file(), f
    # static scene, noiseless: emulating the 3 ms ground truth from the 4 ms bracket stays
    # within the quantisation bound of a downward ratio (1-2 DN on this response)
    frame = seq[0].frames["left"][4.0]
    gt = read_png16(out / "ground_truth" / "captures_noiseless" / "camera_left" / "3.0" / f"{frame.timestamp_ns}.png")
    emu = emulate(frame.load(), 4.0, 3.0, sequence_response(seq))
    inside = (frame.load() > 0) & (frame.load() < seq.white_level)
    assert np.abs(emu.astype(int) - gt.astype(int))[inside].max() <= 2
    # never overwrites
    assert main(args) == 1
    assert "exists" in capsys.readouterr().err


def test_synth_rejects_bad_arguments(tmp_path, capsys):
    assert main(["synth", "forest_winter", "-o", str(tmp_path / "x"), "--cycles", "0", "--quiet"]) == 1
    assert "n_cycles must be >= 1" in capsys.readouterr().err
    assert main(["synth", "forest_winter", "-o", str(tmp_path / "y"), "--gt-exposures", "3,a", "--quiet"]) == 1
    assert "--gt-exposures" in capsys.readouterr().err


def test_synth_records_the_denoiser(tmp_path, monkeypatch):
    monkeypatch.delenv("EXPOSIM_DENOISE", raising=False)
    args = ["synth", "static_lab", "--cycles", "1", "--size", "24x16", "--spp", "1", "--mono", "--quiet",
            "--noiseless"]
    assert main(args + ["--denoise", "off", "-o", str(tmp_path / "off")]) == 0
    meta = json.loads((tmp_path / "off" / "exposim.json").read_text())
    assert meta["source"]["render"]["denoise"] == {"name": "off"}
    assert meta["source"]["render"]["denoise_fallback"] is None
    assert main(args + ["-o", str(tmp_path / "on")]) == 0
    render = json.loads((tmp_path / "on" / "exposim.json").read_text())["source"]["render"]
    from scenes.denoise import oidn_status

    if oidn_status()[0]:
        assert render["denoise"]["name"] == "oidn" and render["denoise_fallback"] is None
    else:  # pragma: no cover - depends on the machine
        assert render["denoise"] == {"name": "off"} and render["denoise_fallback"]
    # a denoised dataset differs from the raw one (same seeds, same poses)
    off = load_sequence(tmp_path / "off")[0].frames["left"][32.0].load()
    on = load_sequence(tmp_path / "on")[0].frames["left"][32.0].load()
    assert on.shape == off.shape and (not oidn_status()[0] or not np.array_equal(on, off))

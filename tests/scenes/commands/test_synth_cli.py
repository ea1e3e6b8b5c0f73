"""``exposim synth``: a rendered scene through the synthetic camera into the BorealHDR layout."""

import json

import numpy as np
import pytest

from emulator.commands.cli import main
from emulator.io.borealhdr import load_sequence, sequence_response
from emulator.io.png import read_png16
from emulator.core.emulate import emulate

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
    # --force keeps a file the user added: one line naming it, rc 1, the old dataset intact
    (out / "ground_truth" / "notes.md").write_text("field notes")
    assert main(args + ["--force"]) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith("exposim synth: error:") and "ground_truth/notes.md" in err and len(err.splitlines()) == 1
    assert (out / "ground_truth" / "notes.md").read_text() == "field notes" and (out / "exposim.json").is_file()
    (out / "ground_truth" / "notes.md").unlink()
    assert main(args + ["--force"]) == 0


def test_synth_rejects_bad_arguments(tmp_path, capsys):
    assert main(["synth", "forest_winter", "-o", str(tmp_path / "x"), "--cycles", "0", "--quiet"]) == 1
    assert "n_cycles must be >= 1" in capsys.readouterr().err
    assert main(["synth", "forest_winter", "-o", str(tmp_path / "y"), "--gt-exposures", "3,a", "--quiet"]) == 1
    assert "--gt-exposures" in capsys.readouterr().err


@pytest.mark.slow
def test_ctrl_c_during_rendering_stops_cleanly_with_130(tmp_path):
    """issue 11: SIGINT during rendering gave a Dr.Jit traceback and rc 1.

    A real ``exposim synth`` sub-process (empty render cache, so every image is rendered) gets
    SIGINT once its first bracket PNG is in the staging folder, i.e. while it renders: at
    256 spp the render kernel takes most of the time between images, which is where the
    interrupt used to surface inside Dr.Jit (without the fix this test fails most times).
    """
    import os
    import signal
    import subprocess
    import sys
    import time

    out = tmp_path / "walk"
    env = dict(os.environ, EXPOSIM_CACHE=str(tmp_path / "cache"))
    proc = subprocess.Popen(
        [sys.executable, "-m", "emulator.commands.cli", "synth", "forest_winter", "-o", str(out), "--size", "64x40",
         "--spp", "256", "--cycles", "200", "--quiet"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env,
    )
    try:
        deadline = time.monotonic() + 120
        while not list(tmp_path.glob(".walk.partial-*/camera_left/*/*.png")):
            if proc.poll() is not None or time.monotonic() > deadline:
                pytest.skip(f"exposim synth did not start rendering in time (rc {proc.returncode})")
            time.sleep(0.02)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    err = err.decode()
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "drjit" not in err.lower()
    assert err.strip().splitlines()[-1] == "exposim synth: interrupted"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cache"]  # no dataset, no staging folder


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

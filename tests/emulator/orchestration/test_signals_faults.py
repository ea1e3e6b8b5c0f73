"""Fault suite, issue 24 (signals, OS errors): SIGTERM is handled like Ctrl-C (run.json records
"interrupted" and the run resumes to the same bytes); a full disk names the file; a serial
dataset run names a unit that hits an OS error and keeps the others."""

from __future__ import annotations

import errno
import json
import os
import signal
import subprocess
import sys
import time

import pytest

from emulator.commands.cli import main
from tests.emulator.playback.test_playback import write_static_sequence

SLOW = '''
import time


class Slow:
    name = "slow"

    def reset(self):
        pass

    def next_exposure(self, raw, exposure_ms):
        time.sleep(0.3)
        return 5.0
'''


def test_sigterm_is_handled_like_ctrl_c_and_the_run_resumes(tmp_path, monkeypatch):
    (tmp_path / "slow_term.py").write_text(SLOW)
    seq, _ = write_static_sequence(tmp_path / "seq", n_cycles=12, shape=(32, 48))
    out = tmp_path / "run"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path), os.environ.get("PYTHONPATH", "")])}
    cmd = [sys.executable, "-m", "emulator.commands.cli", "run", str(seq), "--methods", "classical-50,slow_term:Slow",
           "-o", str(out), "--no-progress"]
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    csv = out / "slow" / "exposures.csv"
    deadline = time.monotonic() + 60
    while not (csv.is_file() and csv.read_text().count("\n") >= 3):
        assert time.monotonic() < deadline and proc.poll() is None
        time.sleep(0.05)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 143
    assert err.decode().strip().splitlines()[-1] == "exposim run: terminated (SIGTERM)"
    info = json.loads((out / "run.json").read_text())
    assert info["status"] == "interrupted" and 0 < info["cycles_done"] < 12
    monkeypatch.syspath_prepend(str(tmp_path))
    assert main(["run", str(seq), "-o", str(out), "--resume", "--no-progress"]) == 0
    info = json.loads((out / "run.json").read_text())
    assert info["status"] == "complete" and info["cycles_done"] == 12
    assert csv.read_text().count("\n") == 13


def test_no_space_left_names_the_file(tmp_path, monkeypatch, capsys):
    import emulator.io.files as files

    real_fdopen = os.fdopen

    def full(fd, mode="r", *a, **k):
        fh = real_fdopen(fd, mode, *a, **k)

        class Full:
            def __enter__(self):
                return self

            def __exit__(self, *exc):
                fh.close()

            def write(self, data):
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

        return Full()

    monkeypatch.setattr(files.os, "fdopen", full)
    target = tmp_path / "out" / "x.bin"
    with pytest.raises(OSError) as exc:
        files.atomic_write_bytes(target, b"data")
    assert exc.value.errno == errno.ENOSPC and exc.value.filename == str(target)
    assert list((tmp_path / "out").iterdir()) == []  # no partial file left
    from emulator.commands.cli import _os_error

    assert _os_error(exc.value) == f"{target}: No space left on device"


def test_serial_dataset_run_names_a_unit_with_an_os_error_and_keeps_the_others(tmp_path, capsys):
    data = tmp_path / "data"
    for name in ("a", "b", "c"):
        write_static_sequence(data / name, n_cycles=2, shape=(32, 48))
    png = sorted((data / "b" / "camera_left").rglob("*.png"))[0]
    png.unlink()
    png.symlink_to(tmp_path / "nowhere.png")  # dangling
    out = tmp_path / "out"
    rc = main(["run", str(data), "--sequences", "all", "--scheduler", "serial", "--methods", "classical-50",
               "-o", str(out), "--no-progress"])
    err = [ln for ln in capsys.readouterr().err.strip().splitlines() if "no imu/imu.csv" not in ln]
    assert rc == 1 and len(err) == 1 and "1 unit(s) failed" in err[0] and "b/classical-50" in err[0]
    results = json.loads((out / "results.json").read_text())
    assert [u["sequence"] for u in results["units"]] == ["a", "c"]
    assert results["errors"][0]["unit"] == "b/classical-50"
    assert png.name in results["errors"][0]["error"]  # the file is named


@pytest.mark.parametrize("damage", ["truncate", "flip"])
def test_a_damaged_png_is_one_line_without_libpng_noise(tmp_path, damage):
    seq, _ = write_static_sequence(tmp_path / "seq", n_cycles=2, shape=(32, 48))
    pngs = sorted((seq / "camera_left").rglob("*.png"))
    for png in pngs:  # every left frame: whichever bracket the loop reads first is damaged
        data = png.read_bytes()
        png.write_bytes(data[: len(data) - 20] if damage == "truncate" else data[:60] + bytes([data[60] ^ 0xFF]) +
                        data[61:])
    proc = subprocess.run([sys.executable, "-m", "emulator.commands.cli", "run", str(seq), "--methods", "classical-50",
                           "-o", str(tmp_path / "run"), "--no-progress"], capture_output=True, text=True)
    # (the one warning line for a recording without imu/imu.csv is not ours to judge here)
    lines = [ln for ln in proc.stderr.strip().splitlines() if "no imu/imu.csv" not in ln]
    assert proc.returncode == 1 and len(lines) == 1, lines
    assert any(p.name in lines[0] for p in pngs) and "corrupt or truncated PNG" in lines[0]
    assert "libpng" not in proc.stderr

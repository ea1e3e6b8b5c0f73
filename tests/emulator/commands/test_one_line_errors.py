"""Fault suite, issue 34 (loud defects of the second tour): each bad input gives one line naming
the file, the method or the flag, loses nothing, and every JSON document exposim prints is
strict JSON (no NaN: a non-finite figure is null, with the reason)."""

from __future__ import annotations

import errno
import json
import shutil
import struct
import warnings

import pytest

from emulator.commands.cli import main
from tests.emulator.playback.test_playback import write_static_sequence


@pytest.fixture(scope="module")
def seq(tmp_path_factory):
    root, _ = write_static_sequence(tmp_path_factory.mktemp("loud") / "seq", n_cycles=4, shape=(32, 48))
    return root


def _error_line(capsys) -> str:
    err = [ln for ln in capsys.readouterr().err.strip().splitlines() if "no imu/imu.csv" not in ln]
    assert len(err) == 1, err
    return err[0]


def _copy(seq, tmp_path):
    dst = tmp_path / "seq"
    shutil.copytree(seq, dst)
    return dst


def test_an_exposure_folder_entry_that_is_a_folder_is_named(seq, tmp_path, capsys):
    root = _copy(seq, tmp_path)
    png = sorted((root / "camera_left" / "4.0").glob("*.png"))[1]
    png.unlink()
    png.mkdir()
    assert main(["run", str(root), "--methods", "fixed", "-o", str(tmp_path / "run"), "--no-progress"]) == 1
    assert _error_line(capsys) == f"exposim run: error: {png}: is a folder, expected an image file <timestamp_ns>.png"


def test_a_full_disk_while_writing_a_csv_header_names_the_file_and_run_json_says_failed(seq, tmp_path, capsys,
                                                                                         monkeypatch):
    import emulator.io.runfolder as runfolder

    real_open = open

    def full_open(path, mode="r", *args, **kwargs):
        if str(path).endswith("exposures.csv") and "a" in mode:
            raise OSError(errno.ENOSPC, "No space left on device")  # no file name, as a write reports it
        return real_open(path, mode, *args, **kwargs)

    monkeypatch.setattr(runfolder, "open", full_open, raising=False)
    out = tmp_path / "run"
    assert main(["run", str(seq), "--methods", "fixed", "-o", str(out), "--no-progress"]) == 1
    assert _error_line(capsys) == f"exposim run: error: {out / 'fixed' / 'exposures.csv'}: No space left on device"
    info = json.loads((out / "run.json").read_text())
    assert info["status"] == "failed" and "No space left on device" in info["error"]


def test_a_frame_cache_entry_replaced_by_a_folder_is_not_used_and_the_run_goes_on(seq, tmp_path, capsys):
    root = _copy(seq, tmp_path)
    plain = tmp_path / "plain"
    assert main(["run", str(root), "--methods", "classical-50,shim", "-o", str(plain), "--no-progress"]) == 0
    assert main(["cache", str(root), "-q"]) == 0
    entries = sorted((root / ".exposim-frames").rglob("*.npy.zst"))
    assert entries
    for entry in entries[:3]:
        entry.unlink()
        entry.mkdir()
    out = tmp_path / "cached"
    assert main(["run", str(root), "--methods", "classical-50,shim", "-o", str(out), "--no-progress"]) == 0
    for m in ("classical-50", "shim"):
        assert (out / m / "exposures.csv").read_bytes() == (plain / m / "exposures.csv").read_bytes()


def _drop_idat(path):
    data = path.read_bytes()
    out, pos = data[:8], 8
    while pos < len(data):
        (n,) = struct.unpack(">I", data[pos:pos + 4])
        if data[pos + 4:pos + 8] != b"IDAT":
            out += data[pos:pos + 12 + n]
        pos += 12 + n
    path.write_bytes(out)


def test_a_png_without_image_data_is_one_line_without_libpng_noise(seq, tmp_path, capfd):
    root = _copy(seq, tmp_path)
    png = sorted((root / "camera_left" / "4.0").glob("*.png"))[0]
    _drop_idat(png)
    assert main(["run", str(root), "--methods", "fixed", "-o", str(tmp_path / "run"), "--no-progress"]) == 1
    err = [ln for ln in capfd.readouterr().err.strip().splitlines() if "no imu/imu.csv" not in ln]
    assert err == [f"exposim run: error: {png}: cannot decode image (corrupt or truncated PNG: no IDAT chunk (the "
                   f"image data is missing), {png.stat().st_size} bytes)"]


PLUGINS = '''
import sys


class Rec:
    name = "rec"

    def reset(self):
        pass

    def next_exposure(self, raw, exposure_ms):
        sys.setrecursionlimit(60)
        return exposure_ms
'''


@pytest.fixture
def plugins(tmp_path, monkeypatch):
    (tmp_path / "loud_plugins.py").write_text(PLUGINS)
    (tmp_path / "loud_kbi.py").write_text("raise KeyboardInterrupt\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    return tmp_path


def test_a_plugin_that_raises_keyboard_interrupt_at_import_is_named(seq, plugins, tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["run", str(seq), "--methods", "fixed,loud_kbi:X", "-o", str(out), "--no-progress"]) == 1
    assert _error_line(capsys) == ("exposim run: error: AE method 'loud_kbi:X': importing or building it raised "
                                   "KeyboardInterrupt in its worker process")
    assert not out.exists()  # refused before the folder is made


def test_a_plugin_that_lowers_the_recursion_limit_changes_nothing_else(seq, plugins, tmp_path):
    alone, out = tmp_path / "alone", tmp_path / "run"
    assert main(["run", str(seq), "--methods", "shim", "-o", str(alone), "--no-progress"]) == 0
    assert main(["run", str(seq), "--methods", "shim,loud_plugins:Rec", "-o", str(out), "--no-progress"]) == 0
    assert (out / "shim" / "exposures.csv").read_bytes() == (alone / "shim" / "exposures.csv").read_bytes()
    assert json.loads((out / "run.json").read_text())["method_status"] == {"shim": "ok", "rec": "ok"}
    assert (out / "exposure.png").is_file() and (out / "report.md").is_file()


def test_a_comma_separated_pcalib_is_named_without_quoting_the_file(seq, tmp_path, capsys):
    pcalib = tmp_path / "pcalib_comma.txt"
    pcalib.write_text(",".join(f"{0.17 + i:.15f}" for i in range(256)) + "\n")
    assert main(["run", str(seq), "--methods", "fixed", "-o", str(tmp_path / "run"), "--no-progress",
                 "--response", str(pcalib)]) == 1
    line = _error_line(capsys)
    assert line.startswith(f"exposim run: error: {pcalib}: sample 0 is '0.170000000000000,1.170000000000000,")
    assert line.endswith(f"... ({pcalib.stat().st_size - 1} characters)', not a number; samples are separated by ',', "
                         "a pcalib file separates them by spaces")
    assert len(line) < 300


def test_emulate_a_target_beyond_the_imu_record_is_strict_json_with_a_reason(sample_seq, tmp_path, capsys):
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        assert main(["emulate", str(sample_seq), "--cycle", "1", "--exposure-ms", "1000", "--json",
                     "-o", str(tmp_path)]) == 0
    text = capsys.readouterr().out

    def refuse(name):
        raise AssertionError(f"{name} in strict JSON")

    info = json.loads(text, parse_constant=refuse)
    left = info["cameras"]["left"]
    assert left["target_blur_px"] is None and left["blur_mismatch_px"] is None
    assert left["blur_note"] == "no blur predicted for the 1000 ms exposure window: the IMU record does not cover it"
    assert left["source_blur_px"] > 0


def test_emulate_a_huge_exposure_warns_of_nothing_and_prints_no_nan(sample_seq, tmp_path, capfd):
    assert main(["emulate", str(sample_seq), "--cycle", "1", "--exposure-ms", "1e308", "-o", str(tmp_path)]) == 0
    captured = capfd.readouterr()
    assert "RuntimeWarning" not in captured.err and "nan" not in captured.out.lower()
    assert "no blur predicted for the 1e+308 ms exposure window" in captured.out


def test_a_resume_mismatch_names_the_column_that_differs(seq, tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["run", str(seq), "--methods", "shim", "-o", str(out), "--no-progress"]) == 0
    csv = out / "shim" / "exposures.csv"
    lines = csv.read_text().splitlines()
    header, row = lines[0].split(","), lines[2].split(",")
    i = header.index("guarded")
    row[i] = "1" if row[i] == "0" else "0"
    edited = row[i]
    lines[2] = ",".join(row)
    csv.write_text("\n".join(lines) + "\n")
    info = json.loads((out / "run.json").read_text())
    info["status"] = "interrupted"
    (out / "run.json").write_text(json.dumps(info))
    assert main(["run", str(seq), "-o", str(out), "--resume", "--no-progress"]) == 1
    assert _error_line(capsys) == (
        f"exposim run: error: {csv}: resume replay of cycle 1 differs from the recorded row (guarded {edited} "
        f"recorded, {1 - int(edited)} replayed); the table was edited, or the folder was written by another configuration or "
        "version of exposim")


def test_strict_json_turns_non_finite_figures_into_null_with_a_reason():
    from emulator.io.files import strict_json

    doc = json.loads(strict_json({"a": float("nan"), "b": [1.0, float("inf")], "c": {"d": 2}},
                                 reasons={"a": "no data"}))
    assert doc == {"a": None, "b": [1.0, None], "c": {"d": 2},
                   "null_reasons": {"a": "no data", "b[1]": "not a finite number (inf)"}}

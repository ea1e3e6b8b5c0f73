import json
import subprocess
import sys

import numpy as np
import pytest

from emulator.commands.cli import main
from emulator.io.png import read_png16


def test_help_lists_commands(capsys):
    with pytest.raises(SystemExit) as e:
        main(["--help"])
    assert e.value.code == 0
    out = capsys.readouterr().out
    for cmd in ("info", "emulate", "demo"):
        assert cmd in out


def test_console_script_runs():
    r = subprocess.run([sys.executable, "-m", "emulator.commands.cli", "info", "--help"], capture_output=True, text=True)
    assert r.returncode == 0 and "--json" in r.stdout


def test_info_json_real_sample(sample_seq, capsys):
    assert main(["info", str(sample_seq), "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert isinstance(d["cycles"], list) and len(d["cycles"]) == 4
    c1 = d["cycles"][1]
    assert c1["index"] == 1
    assert set(c1["left"]) == {"1.0", "2.0", "4.0", "8.0", "16.0", "32.0"}
    assert c1["left"] == c1["right"]
    assert d["cycles"][0]["right"] == {
        "8.0": 1695668703364771328,
        "16.0": 1695668703411462400,
        "32.0": 1695668703456804608,
    }
    assert d["partial_cycles"] == [0, 3]


def test_emulate_cli_real_sample(sample_seq, tmp_path, capsys):
    args = ["emulate", str(sample_seq), "--exposure-ms", "5.3", "--cycle", "1", "-o", str(tmp_path), "--json"]
    assert main(args) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["bracket_ms"] == 8.0 and d["ratio"] == pytest.approx(5.3 / 8.0)
    ts = {c["timestamp_ns"] for c in d["cameras"].values()}
    assert ts == {1695668703639032576}
    left = read_png16(d["cameras"]["left"]["output"])
    assert left.dtype == np.uint16 and left.shape == (1200, 1920) and left.max() <= 4094
    assert 0.99 < d["valid_fraction"] <= 1.0
    # refuses to overwrite, then --force works
    assert main(args) == 1
    assert "exists; refusing to overwrite" in capsys.readouterr().err
    assert main(args + ["--force"]) == 0


def test_emulate_cli_errors(sample_seq, tmp_path, capsys):
    base = ["emulate", str(sample_seq), "-o", str(tmp_path)]
    assert main(base + ["--exposure-ms", "5", "--cycle", "9"]) == 1
    assert "cycle 9 out of range" in capsys.readouterr().err
    assert main(base + ["--exposure-ms", "nan", "--cycle", "1"]) == 1
    assert "--exposure-ms must be finite and positive" in capsys.readouterr().err
    # cycle 3 has only the 1 ms bracket: outside the range above it, so 1 ms is used
    assert main(base + ["--exposure-ms", "20", "--cycle", "3", "--camera", "right", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["bracket_ms"] == 1.0
    assert main(["info", str(tmp_path / "nope")]) == 1
    assert "sequence folder not found" in capsys.readouterr().err


def test_long_commands_print_stage_lines_in_a_log():
    """Issue 46: off a terminal (nohup, CI) a long command prints a line as each stage starts, at least every
    LOG_EVERY_S seconds of work within it, and as it ends; nothing when quiet or on a terminal."""
    import io

    from emulator.commands.progress import LOG_EVERY_S, log_lines

    now = [0.0]
    log = io.StringIO()
    lines = log_lines("exposim bench vo", stream=log, clock=lambda: now[0])
    for stage in ("VO fixed", "VO kim"):
        for done in range(6):
            lines(stage, done, 5)
            now[0] += LOG_EVERY_S / 4  # a line at least every LOG_EVERY_S seconds
    assert log.getvalue().splitlines() == [
        "exposim bench vo [0 s]: VO fixed 0/5", "exposim bench vo [20 s]: VO fixed 4/5",
        "exposim bench vo [25 s]: VO fixed 5/5", "exposim bench vo [30 s]: VO kim 0/5",
        "exposim bench vo [50 s]: VO kim 4/5", "exposim bench vo [55 s]: VO kim 5/5"]
    assert log_lines("x", quiet=True, stream=io.StringIO()) is None
    # the heartbeat: a line when LOG_EVERY_S passes without one (one slow image), from the start
    log, now[0] = io.StringIO(), 0.0
    with log_lines("exposim run", stream=log, clock=lambda: now[0]) as lines:
        lines.beat()
        now[0] = LOG_EVERY_S
        lines.beat()
        lines("frames", 1, 18)
        now[0] = 1.5 * LOG_EVERY_S
        lines.beat()
        now[0] = 2 * LOG_EVERY_S
        lines.beat()
    assert log.getvalue().splitlines() == ["exposim run [20 s]: preparing, working", "exposim run [20 s]: frames 1/18",
                                           "exposim run [40 s]: frames 1/18, working"]
    # closed: its thread has ended and nothing more is printed, however late a beat comes
    log, now[0] = io.StringIO(), 0.0
    lines = log_lines("exposim run", stream=log, clock=lambda: now[0], heartbeat=True)
    thread = lines._thread
    assert thread is not None and thread.is_alive()
    lines.close()
    assert not thread.is_alive()
    now[0] = 10 * LOG_EVERY_S
    lines.beat()
    assert log.getvalue() == ""

    class Tty(io.StringIO):
        def isatty(self):
            return True

    assert log_lines("x", stream=Tty()) is None

"""Bounded inputs (issue 24), written independently of tests/test_faults_*.py.

Each bad flag gives exit code 1 or 2, one error line naming the flag or the value, nothing
written, and costs neither time nor memory (the risky ones run in a child process with a
memory limit and a timeout).
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys

import pytest

from emulator.commands.cli import main
from test_playback import write_static_sequence


@pytest.fixture(scope="module")
def seq(tmp_path_factory):
    root, _ = write_static_sequence(tmp_path_factory.mktemp("iseq") / "seq", n_cycles=3, shape=(32, 48))
    return root


def _error_lines(err: str) -> list[str]:
    return [x for x in err.strip().splitlines() if x.strip() and "warning" not in x and not x.startswith(("usage:", " "))]


def _refused(argv, capsys, *words):
    capsys.readouterr()
    try:
        rc = main(argv)
    except SystemExit as exc:  # argparse
        rc = exc.code
    err = capsys.readouterr().err
    lines = _error_lines(err)
    assert rc in (1, 2), (rc, err)
    assert len(lines) == 1, err
    assert any(w in lines[0] for w in words), (words, err)
    assert "Traceback" not in err
    return lines[0]


def _run(seq, out, *extra):
    return ["run", str(seq), "--methods", "classical-50,kim", "-o", str(out), "-q", *extra]


@pytest.mark.parametrize("option", ["kim.window=abc", "kim.window=2.9", "kim.window=true", "kim.window=1e30",
                                    "kim.window=-3", "kim.window=nan", "kim.seed=-1", "kim.seed=4294967296",
                                    "kim.seed=1e30", "kim.seed=1.5", "zhang.percentile=nan",
                                    "zhang.percentile=true", "zhang.percentile=abc", "classical-50.nonexistent=1",
                                    "kim", "=3", ".x=1", "nosuch.x=1"])
def test_bad_method_options(seq, tmp_path, capsys, option):
    out = tmp_path / "run"
    key = option.split("=")[0]
    methods = "classical-50,kim,zhang"
    line = _refused(["run", str(seq), "--methods", methods, "-o", str(out), "-q", "--option", option], capsys,
                    key.split(".")[0] or option, option, "--option", "METHOD.KEY")
    if "." in key and key.split(".")[0] and key.split(".")[1]:
        method, name = key.split(".")
        assert method in line and name in line, line  # which method, which option
    assert not out.exists() or not any(out.iterdir()), line


@pytest.mark.parametrize("flag, value", [("--seed", "-5"), ("--seed", "4294967296"), ("--seed", "1e30"),
                                         ("--seed", "abc"), ("--noise-seed", "-1"), ("--jobs", "0"),
                                         ("--jobs", "-1"), ("--method-timeout", "0"), ("--method-timeout", "-1"),
                                         ("--method-timeout", "nan"), ("--initial-ms", "nan")])
def test_bad_run_flags(seq, tmp_path, capsys, flag, value):
    out = tmp_path / "run"
    _refused(_run(seq, out, flag, value), capsys, flag, value)
    assert not out.exists() or not any(out.iterdir())


@pytest.mark.parametrize("low, high", [("5", "1"), ("nan", "5"), ("0", "50"), ("-1", "5"), ("1", "nan")])
def test_bad_range(seq, tmp_path, capsys, low, high):
    out = tmp_path / "run"
    _refused(_run(seq, out, "--range-ms", low, high), capsys, "--range-ms", "range_ms", "range")
    assert not out.exists() or not any(out.iterdir())


@pytest.mark.parametrize("flag", ["--workers", "--dataset-workers", "--group-size"])
@pytest.mark.parametrize("value", ["0", "-2"])
def test_bad_dataset_flags_write_nothing(seq, tmp_path, capsys, flag, value):
    out = tmp_path / "run"
    _refused(["run", str(seq.parent), "--sequences", "all", "--scheduler", "serial", "--methods", "classical-50",
              "-o", str(out), "-q", flag, value], capsys, flag, value)
    assert not out.exists() or not any(out.iterdir())


def test_bad_option_in_a_dataset_run_leaves_no_trap(seq, tmp_path, capsys):
    """A refused dataset run must not leave a dataset.json that refuses the corrected rerun."""
    out = tmp_path / "run"
    common = ["run", str(seq.parent), "--sequences", "all", "--scheduler", "serial", "--methods", "classical-50,kim",
              "-o", str(out), "-q"]
    _refused([*common, "--option", "kim.window=abc"], capsys, "kim.window", "abc")
    capsys.readouterr()
    assert main([*common, "--option", "kim.window=3"]) == 0


def test_response_is_a_directory(seq, tmp_path, capsys):
    out = tmp_path / "run"
    _refused(_run(seq, out, "--response", str(tmp_path)), capsys, str(tmp_path))


def test_response_is_empty_or_text(seq, tmp_path, capsys):
    for text in ("", "hello world\n", "1 2 3\n", "nan " * 256):
        p = tmp_path / "bad.txt"
        p.write_text(text)
        _refused(_run(seq, tmp_path / "run", "--response", str(p)), capsys, str(p))


def _child(args, timeout=60):
    """``exposim ARGS`` in a child limited to 3 GB of address space."""
    def limit():
        resource.setrlimit(resource.RLIMIT_AS, (3 << 30, 3 << 30))

    return subprocess.run([sys.executable, "-m", "emulator.commands.cli", *args], capture_output=True, text=True,
                          timeout=timeout, preexec_fn=limit, env={**os.environ, "MPLBACKEND": "Agg"})


def test_response_dev_zero_and_a_huge_sparse_file(seq, tmp_path):
    huge = tmp_path / "huge.txt"
    with open(huge, "wb") as fh:
        fh.truncate(8 << 30)  # 8 GiB of zeros, sparse
    for path in ("/dev/zero", str(huge)):
        proc = _child(_run(seq, tmp_path / "run", "--response", path), timeout=30)
        lines = _error_lines(proc.stderr)
        assert proc.returncode == 1 and len(lines) == 1 and path in lines[0], proc.stderr
        assert "MemoryError" not in proc.stderr


@pytest.mark.parametrize("argv, words", [
    (["validate", "render", "--size", "100000x100000"], ("--size", "100000x100000")),
    (["validate", "live", "--size", "8192x8192"], ("--size", "8192x8192")),
    (["validate", "render", "--size", "0x10"], ("--size", "0x10")),
    (["validate", "render", "--size", "4x-4"], ("--size", "4x-4")),
    (["validate", "render", "--size", "axb"], ("--size", "axb")),
    (["validate", "render", "--size", "99999999999999999999x4"], ("--size",)),
    (["synth", "static_lab", "--size", "1x1"], ("--size", "1x1")),
])
def test_sizes_are_checked_before_anything_is_allocated(tmp_path, capsys, argv, words):
    out = tmp_path / "out"
    _refused([*argv, "-o", str(out)], capsys, *words)
    assert not out.exists()


@pytest.mark.parametrize("white, black", [("4096", None), ("65536", None), ("-1", None), ("100", "200"),
                                          ("4000", "4000"), ("nan", None), ("4094.5", None)])
@pytest.mark.parametrize("source", ["stack", "--from-recording"])
def test_calibrate_levels(seq, tmp_path, capsys, white, black, source):
    """Out-of-range levels are refused; with --from-recording, where the levels come from the
    recording, a level flag is refused rather than silently ignored."""
    out = tmp_path / "resp.txt"
    if source == "stack":
        import numpy as np

        from emulator.io.stack import write_stack

        base = np.random.default_rng(0).uniform(0.5, 1.5, (16, 16))
        stack = write_stack(tmp_path / "stack", [np.clip(np.rint(150 * t * base), 0, 4095).astype(np.uint16)
                                                 for t in (1.0, 2.0, 4.0, 8.0)], [1.0, 2.0, 4.0, 8.0])
        where = [str(stack)]
    else:
        where = ["--from-recording", str(seq)]
    argv = ["calibrate", *where, "-o", str(out), "--white-level", white, "-q"]
    if black is not None:
        argv += ["--black-level", black]
    _refused(argv, capsys, "--white-level", "--black-level", "white", white)
    assert not out.exists()

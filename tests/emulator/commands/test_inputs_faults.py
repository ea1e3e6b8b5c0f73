"""Faults of the inputs: each bad flag or value is refused in one line naming it, before anything is written (two suites written independently, one after the other).

Fault suite, issue 24 (recorded fallbacks, seeds, typed options, bounded counts): each bad
input is refused in one line naming it, before anything is written; a method's internal
fallback is recorded per cycle and in the report, never reported as "ok".
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from emulator.autoexposure import AutoExposureError, Kim2018, make_method
from emulator.commands.cli import main
from tests.emulator.playback.test_playback import write_static_sequence
import os
import resource
import subprocess
import sys


@pytest.fixture(scope="module")
def seq(tmp_path_factory):
    root, _ = write_static_sequence(tmp_path_factory.mktemp("inputs") / "seq", n_cycles=5, shape=(32, 48))
    return root


def _one_line_error(capsys, *words):
    """One error line naming the input (argparse puts its usage block above it)."""
    err = capsys.readouterr().err.strip().splitlines()
    # the recording's one-time notes (e.g. no IMU) may come first, depending on which test ran before
    err = [line for line in err if not line.startswith("exposim: warning: ")]
    assert err and err[-1].startswith("exposim run: error: "), err
    assert len(err) == 1 or err[0].startswith("usage: "), err
    assert sum("error" in line for line in err) == 1, err
    err = err[-1:]
    for w in words:
        assert w in err[0], err[0]
    return err[0]


def test_kim_fit_failure_is_recorded_per_cycle_and_in_the_report(seq, tmp_path, monkeypatch, capsys):
    import emulator.autoexposure.kim as kim_mod

    def failing_fit(self):
        raise np.linalg.LinAlgError("forced")

    monkeypatch.setattr(kim_mod.Kim2018, "_fit", failing_fit)
    out = tmp_path / "run"
    # the patch is in this process: the methods run here too (--workers inline)
    assert main(["run", str(seq), "--methods", "kim,classical-50", "-o", str(out), "--no-progress",
                 "--workers", "inline"]) == 0
    rows = (out / "kim" / "exposures.csv").read_text().splitlines()
    header = rows[0].split(",")
    guarded = [int(r.split(",")[header.index("guarded")]) for r in rows[1:]]
    assert guarded == [1] * 5  # every cycle's fit failed and the method kept its exposure
    results = json.loads((out / "results.json").read_text())
    kim = results["methods"]["kim"]
    assert kim["status"].startswith("fell back in 5 of 5 cycles") and kim["fallback_cycles"] == [0, 1, 2, 3, 4]
    assert results["methods"]["classical-50"]["status"] == "ok"
    assert "Methods that fell back" in (out / "report.md").read_text()


def test_kim_fit_failure_increments_the_guard_count():
    k = Kim2018(mode="borealhdr")
    k._fit = lambda: (_ for _ in ()).throw(FloatingPointError("x"))
    assert k.update(4.0, 100.0) == 4.0 and k.guard_count == 1
    assert k.update(4.0, float("nan")) == 4.0 and k.guard_count == 2


@pytest.mark.parametrize("seed", [-5, 2**32, 1e30, True, "3"])
def test_kim_seed_out_of_range_is_refused_in_the_api(seed):
    with pytest.raises(AutoExposureError, match="seed"):
        Kim2018(mode="borealhdr", seed=seed)


def test_kim_seed_at_the_bounds_is_taken():
    assert Kim2018(seed=0).seed == 0 and Kim2018(seed=2**32 - 1).seed == 2**32 - 1


@pytest.mark.parametrize("args,words", [
    (["--seed", "-5"], ["--seed -5", "0..4294967295"]),
    (["--seed", "4294967296"], ["--seed 4294967296", "0..4294967295"]),
    (["--seed", "1e30"], ["--seed", "'1e30'"]),
    (["--noise-seed", "-1"], ["--noise-seed"]),
    (["--noise-seed", "4294967296"], ["--noise-seed 4294967296", "0..4294967295"]),
    (["--option", "kim.seed=-5"], ["seed", "-5"]),
    (["--option", "kim.seed=1e30"], ["kim.seed", "1e+30"]),
    (["--option", "kim.window=2.9"], ["kim.window", "integer", "2.9"]),
    (["--option", "kim.window=true"], ["kim.window", "integer", "True"]),
    (["--option", "kim.window=abc"], ["kim.window", "integer", "'abc'"]),
    (["--option", "kim.gamma_mi=true"], ["kim.gamma_mi", "number"]),
    (["--jobs", "0"], ["--jobs 0", ">= 1"]),
    (["--workers", "0"], ["--workers 0", ">= 1"]),
    (["--dataset-workers", "0"], ["--dataset-workers 0", ">= 1"]),
    (["--group-size", "0"], ["--group-size 0", ">= 1"]),
])
def test_bad_run_arguments_are_refused_in_one_line_and_write_nothing(seq, tmp_path, capsys, args, words):
    out = tmp_path / "run"
    with pytest.raises(SystemExit) if args[1] == "1e30" else _no_raise():  # argparse: not an integer
        rc = main(["run", str(seq), "--methods", "kim", "-o", str(out), "--no-progress", *args])
        assert rc == 1
    _one_line_error(capsys, *words)
    assert not out.exists()


class _no_raise:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False


def test_options_keep_their_types():
    k = make_method("kim", window=3, gamma_mi=2, seed=7)
    assert k.window == 3 and k.gamma_mi == 2.0 and k.seed == 7


def test_bad_option_in_a_dataset_run_leaves_no_dataset_json(tmp_path, capsys):
    data = tmp_path / "data"
    for name in ("a", "b"):
        write_static_sequence(data / name, n_cycles=2, shape=(32, 48))
    out = tmp_path / "out"
    rc = main(["run", str(data), "--sequences", "all", "--scheduler", "serial", "--methods", "kim", "-o", str(out),
               "--option", "kim.window=abc", "--no-progress"])
    assert rc == 1
    _one_line_error(capsys, "kim.window", "'abc'")
    assert not out.exists()  # the corrected rerun is not refused
    assert main(["run", str(data), "--sequences", "all", "--scheduler", "serial", "--methods", "kim", "-o", str(out),
                 "--option", "kim.window=3", "--no-progress"]) == 0
    assert (out / "dataset.json").is_file()


# ------------------------------------------------------------------ bounded before they cost memory
def test_response_from_dev_zero_is_refused_without_reading_it_all(seq, tmp_path, capsys):
    import os

    if not os.path.exists("/dev/zero"):
        pytest.skip("no /dev/zero")
    out = tmp_path / "run"
    assert main(["run", str(seq), "--methods", "shim", "-o", str(out), "--response", "/dev/zero",
                 "--no-progress"]) == 1
    _one_line_error(capsys, "/dev/zero", "larger than 4 MiB")
    assert not out.exists()


@pytest.mark.parametrize("argv,words", [
    (["validate", "render", "--size", "100000x100000"], ["--size", "10000.0 megapixels"]),
    (["validate", "live", "--size", "8192x8192"], ["--size", "67.1 megapixels"]),
    (["validate", "render", "--size", "1x1"], ["--size", "at least 4 pixels"]),
])
def test_image_sizes_are_checked_before_anything_is_allocated(argv, words, capsys):
    import resource

    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith(f"exposim {argv[0]} {argv[1]}: error: ") and all(w in err[-1] for w in words)
    assert resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before < 200_000  # kB: nothing big allocated


def test_synth_refuses_a_size_run_would_refuse(tmp_path, capsys):
    out = tmp_path / "syn"
    rc = main(["synth", "forest_winter", "--size", "1x1", "-o", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 1 and len(err) == 1 and "--size" in err[0] and "at least 4" in err[0]
    assert not out.exists()


@pytest.mark.parametrize("white", [4096, 65536])
def test_calibrate_white_level_beyond_the_bit_depth_is_refused(tmp_path, capsys, white):
    from emulator.io.stack import write_stack

    imgs = [np.full((16, 16), v, np.uint16) for v in (100, 400, 1600)]
    root = write_stack(tmp_path / "st", imgs, [1.0, 4.0, 16.0])
    out = tmp_path / "resp.txt"
    rc = main(["calibrate", str(root), "-o", str(out), "--white-level", str(white), "--no-progress"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 1 and len(err) == 1 and f"white_level {white}" in err[0] and "4095" in err[0]
    assert not out.exists()


@pytest.mark.parametrize("argv,words", [
    (["class"], ["'class'", "keyword"]),
    (["None"], ["'None'", "keyword"]),
    (["numpy"], ["'numpy'", "already importable"]),
    (["my-fine-ae-xyz", "--class-name", "def"], ["'def'"]),
    (["my-fine-ae-xyz", "--class-name", "None"], ["'None'"]),
])
def test_new_method_refuses_names_that_would_not_compile_or_shadow(tmp_path, capsys, argv, words):
    out = tmp_path / "nm"
    assert main(["new-method", *argv, "-o", str(out)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and all(w in err[0] for w in words), err
    assert not out.exists()


def test_new_method_output_compiles(tmp_path):
    out = tmp_path / "nm"
    assert main(["new-method", "my-fine-ae-xyz", "-o", str(out)]) == 0
    for f in out.glob("*.py"):
        compile(f.read_text(), str(f), "exec")


def test_long_method_groups_get_folder_names_the_filesystem_takes(tmp_path, monkeypatch):
    from emulator.orchestration.datasetrun import MAX_GROUP_NAME_BYTES, plan_units

    long_a, long_b = "a" * 150, "b" * 150
    plug = tmp_path / "long_plug.py"
    plug.write_text("".join(f'''
class {c.upper()}:
    name = "{n}"

    def reset(self):
        pass

    def next_exposure(self, raw, exposure_ms):
        return 5.0
''' for c, n in (("a", long_a), ("b", long_b))))
    monkeypatch.syspath_prepend(str(tmp_path))
    data = tmp_path / "data"
    write_static_sequence(data / "s", n_cycles=2, shape=(32, 48))
    units = plan_units({"s": data / "s"}, [long_a, long_b], 2)
    assert len(units[0].group.encode()) <= MAX_GROUP_NAME_BYTES
    assert plan_units({"s": data / "s"}, [long_a, long_b + "c"], 2)[0].group != units[0].group
    out = tmp_path / "out"
    assert main(["run", str(data), "--sequences", "all", "--scheduler", "serial", "--methods",
                 "long_plug:A,long_plug:B", "-o", str(out), "--no-progress"]) == 0
    results = __import__("json").loads((out / "results.json").read_text())
    assert results["errors"] == [] and results["per_method"][long_a]["cycles"] == 2


# ------------------------------------------------------------------------------------------------
# Bounded inputs (issue 24), written independently of the suite above.
#
# Each bad flag gives exit code 1 or 2, one error line naming the flag or the value, nothing
# written, and costs neither time nor memory (the risky ones run in a child process with a
# memory limit and a timeout).
# ------------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def hostile_seq(tmp_path_factory):
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


def _run(hostile_seq, out, *extra):
    return ["run", str(hostile_seq), "--methods", "classical-50,kim", "-o", str(out), "-q", *extra]


@pytest.mark.parametrize("option", ["kim.window=abc", "kim.window=2.9", "kim.window=true", "kim.window=1e30",
                                    "kim.window=-3", "kim.window=nan", "kim.seed=-1", "kim.seed=4294967296",
                                    "kim.seed=1e30", "kim.seed=1.5", "zhang.percentile=nan",
                                    "zhang.percentile=true", "zhang.percentile=abc", "classical-50.nonexistent=1",
                                    "kim", "=3", ".x=1", "nosuch.x=1"])
def test_bad_method_options(hostile_seq, tmp_path, capsys, option):
    out = tmp_path / "run"
    key = option.split("=")[0]
    methods = "classical-50,kim,zhang"
    line = _refused(["run", str(hostile_seq), "--methods", methods, "-o", str(out), "-q", "--option", option], capsys,
                    key.split(".")[0] or option, option, "--option", "METHOD.KEY")
    if "." in key and key.split(".")[0] and key.split(".")[1]:
        method, name = key.split(".")
        assert method in line and name in line, line  # which method, which option
    assert not out.exists() or not any(out.iterdir()), line


@pytest.mark.parametrize("flag, value", [("--seed", "-5"), ("--seed", "4294967296"), ("--seed", "1e30"),
                                         ("--seed", "abc"), ("--noise-seed", "-1"), ("--jobs", "0"),
                                         ("--jobs", "-1"), ("--method-timeout", "0"), ("--method-timeout", "-1"),
                                         ("--method-timeout", "nan"), ("--initial-ms", "nan")])
def test_bad_run_flags(hostile_seq, tmp_path, capsys, flag, value):
    out = tmp_path / "run"
    _refused(_run(hostile_seq, out, flag, value), capsys, flag, value)
    assert not out.exists() or not any(out.iterdir())


@pytest.mark.parametrize("low, high", [("5", "1"), ("nan", "5"), ("0", "50"), ("-1", "5"), ("1", "nan")])
def test_bad_range(hostile_seq, tmp_path, capsys, low, high):
    out = tmp_path / "run"
    _refused(_run(hostile_seq, out, "--range-ms", low, high), capsys, "--range-ms", "range_ms", "range")
    assert not out.exists() or not any(out.iterdir())


@pytest.mark.parametrize("flag", ["--workers", "--dataset-workers", "--group-size"])
@pytest.mark.parametrize("value", ["0", "-2"])
def test_bad_dataset_flags_write_nothing(hostile_seq, tmp_path, capsys, flag, value):
    out = tmp_path / "run"
    _refused(["run", str(hostile_seq.parent), "--sequences", "all", "--scheduler", "serial", "--methods", "classical-50",
              "-o", str(out), "-q", flag, value], capsys, flag, value)
    assert not out.exists() or not any(out.iterdir())


def test_bad_option_in_a_dataset_run_leaves_no_trap(hostile_seq, tmp_path, capsys):
    """A refused dataset run must not leave a dataset.json that refuses the corrected rerun."""
    out = tmp_path / "run"
    common = ["run", str(hostile_seq.parent), "--sequences", "all", "--scheduler", "serial", "--methods", "classical-50,kim",
              "-o", str(out), "-q"]
    _refused([*common, "--option", "kim.window=abc"], capsys, "kim.window", "abc")
    capsys.readouterr()
    assert main([*common, "--option", "kim.window=3"]) == 0


def test_response_is_a_directory(hostile_seq, tmp_path, capsys):
    out = tmp_path / "run"
    _refused(_run(hostile_seq, out, "--response", str(tmp_path)), capsys, str(tmp_path))


def test_response_is_empty_or_text(hostile_seq, tmp_path, capsys):
    for text in ("", "hello world\n", "1 2 3\n", "nan " * 256):
        p = tmp_path / "bad.txt"
        p.write_text(text)
        _refused(_run(hostile_seq, tmp_path / "run", "--response", str(p)), capsys, str(p))


def _child(args, timeout=60):
    """``exposim ARGS`` in a child limited to 3 GB of address space."""
    def limit():
        resource.setrlimit(resource.RLIMIT_AS, (3 << 30, 3 << 30))

    return subprocess.run([sys.executable, "-m", "emulator.commands.cli", *args], capture_output=True, text=True,
                          timeout=timeout, preexec_fn=limit, env={**os.environ, "MPLBACKEND": "Agg"})


def test_response_dev_zero_and_a_huge_sparse_file(hostile_seq, tmp_path):
    huge = tmp_path / "huge.txt"
    with open(huge, "wb") as fh:
        fh.truncate(8 << 30)  # 8 GiB of zeros, sparse
    for path in ("/dev/zero", str(huge)):
        proc = _child(_run(hostile_seq, tmp_path / "run", "--response", path), timeout=30)
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
def test_calibrate_levels(hostile_seq, tmp_path, capsys, white, black, source):
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
        where = ["--from-recording", str(hostile_seq)]
    argv = ["calibrate", *where, "-o", str(out), "--white-level", white, "-q"]
    if black is not None:
        argv += ["--black-level", black]
    _refused(argv, capsys, "--white-level", "--black-level", "white", white)
    assert not out.exists()

"""Faults of resume: a resumed run validates its tables and damaged run folders resume to the clean bytes or are refused (two suites written independently, one after the other).

Fault suite, issue 24 (resume): a resumed run validates its tables before appending; a table
that is not an ordered, unique prefix of the run is cut back to its valid prefix and recomputed,
so the result equals an uninterrupted run, byte for byte, and run.json says what was repaired.
"""

from __future__ import annotations

import json

import pytest

from emulator.commands.cli import main
from emulator.orchestration.runner import run_to_folder
from tests.emulator.playback.test_playback import write_static_sequence

METHODS = ["classical-50", "shim"]
N = 6


@pytest.fixture(scope="module")
def seq(tmp_path_factory):
    root, _ = write_static_sequence(tmp_path_factory.mktemp("resume") / "seq", n_cycles=N, shape=(32, 48))
    return root


@pytest.fixture(scope="module")
def clean(seq, tmp_path_factory):
    out = tmp_path_factory.mktemp("clean") / "run"
    run_to_folder(seq, METHODS, out)
    return {m: (out / m / "exposures.csv").read_bytes() for m in METHODS}


def _interrupted(seq, out, after=4):
    def stop(done, total):
        if done == after:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_to_folder(seq, METHODS, out, progress=stop)


def _damage(path, how):
    lines = path.read_text().splitlines(keepends=True)
    header, rows = lines[0], lines[1:]
    if how == "missing-middle":
        rows = rows[:1] + rows[2:]
    elif how == "duplicate":
        rows = rows[:3] + [rows[2]] + rows[3:]
    elif how == "out-of-order":
        rows[1], rows[2] = rows[2], rows[1]
    elif how == "foreign-cycle":
        rows = rows + [rows[-1].replace(rows[-1].split(",")[0] + ",", "99,", 1)]
    path.write_text(header + "".join(rows))


@pytest.mark.parametrize("how,why", [
    ("missing-middle", "row 2 is cycle 2, expected cycle 1"),
    ("duplicate", "row 4 is cycle 2, expected cycle 3"),
    ("out-of-order", "row 2 is cycle 2, expected cycle 1"),
    ("foreign-cycle", "row 5 is cycle 99, expected cycle 4"),
])
def test_resume_repairs_a_damaged_table_to_the_uninterrupted_result(seq, clean, tmp_path, how, why):
    out = tmp_path / "run"
    _interrupted(seq, out)
    _damage(out / "shim" / "exposures.csv", how)
    assert main(["run", str(seq), "-o", str(out), "--resume", "--no-progress"]) == 0
    for m in METHODS:
        assert (out / m / "exposures.csv").read_bytes() == clean[m], m
    info = json.loads((out / "run.json").read_text())
    assert info["status"] == "complete"
    assert len(info["resume_repairs"]) == 1 and info["resume_repairs"][0].startswith(f"shim: {why}; kept the first")
    results = json.loads((out / "results.json").read_text())
    assert all(results["methods"][m]["cycles"] == N for m in METHODS)


def test_resume_of_valid_tables_repairs_nothing(seq, clean, tmp_path):
    out = tmp_path / "run"
    _interrupted(seq, out)
    assert main(["run", str(seq), "-o", str(out), "--resume", "--no-progress"]) == 0
    assert "resume_repairs" not in json.loads((out / "run.json").read_text())
    for m in METHODS:
        assert (out / m / "exposures.csv").read_bytes() == clean[m]


# ------------------------------------------------------------------------------------------------
# Damaged run folders under --resume, written independently of the suite above (issue 24).
#
# An interrupted run's tables are damaged the ways a crash, an editor or a copy can damage them;
# ``--resume`` must then give exactly the bytes of an uninterrupted run, or refuse in one line
# naming the file and leave it as it was. It must never finish "complete" with a wrong table.
# ------------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def hostile_seq(tmp_path_factory):
    root, _ = write_static_sequence(tmp_path_factory.mktemp("rseq") / "seq", n_cycles=N, shape=(32, 48))
    return root


def _tables(run_dir):
    return {m: (run_dir / m / "exposures.csv").read_bytes() for m in METHODS}


@pytest.fixture(scope="module")
def hostile_clean(hostile_seq, tmp_path_factory):
    out = tmp_path_factory.mktemp("rclean") / "run"
    assert main(["run", str(hostile_seq), "--methods", ",".join(METHODS), "-o", str(out), "-q"]) == 0
    return out


def _hostile_interrupted(hostile_seq, out, after=4):
    def stop(done, total):
        if done == after:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_to_folder(hostile_seq, METHODS, out, progress=stop, command="exposim run (hostile test)")
    assert json.loads((out / "run.json").read_text())["status"] == "interrupted"


def _lines(path):
    return path.read_text().splitlines(keepends=True)


def _missing_middle(lines):
    return lines[:2] + lines[3:]


def _duplicated(lines):
    return lines[:3] + [lines[2]] + lines[3:]


def _reordered(lines):
    return [lines[0], lines[2], lines[1], *lines[3:]]


def _truncated(lines):
    return lines[:-1] + [lines[-1][: len(lines[-1]) // 2]]


def _other_recording(lines):
    fields = lines[2].split(",")
    fields[1] = str(int(fields[1]) + 7)  # a timestamp this recording does not have
    return lines[:2] + [",".join(fields)] + lines[3:]


def _blank_inside(lines):
    return lines[:2] + ["\n"] + lines[2:]


def _future_cycle(lines):
    fields = lines[-1].split(",")
    fields[0] = "99"
    return lines + [",".join(fields)]


def _no_header(lines):
    return lines[1:]


def _crlf(lines):
    return [line.replace("\n", "\r\n") for line in lines]


def _nan_target(lines):
    fields = lines[2].split(",")
    fields[2] = "nan"
    return lines[:2] + [",".join(fields)] + lines[3:]


DAMAGES = [_missing_middle, _duplicated, _reordered, _truncated, _other_recording, _blank_inside,
           _future_cycle, _no_header, _crlf, _nan_target]


def _resume_outcome(hostile_seq, out, hostile_clean, path, damaged_text, capsys):
    capsys.readouterr()
    rc = main(["run", str(hostile_seq), "-o", str(out), "--resume", "-q"])
    err = capsys.readouterr().err.strip()
    if rc == 0:
        # repaired: exactly an uninterrupted run, nothing lost, nothing doubled
        assert _tables(out) == _tables(hostile_clean)
        results = json.loads((out / "results.json").read_text())
        for m in METHODS:
            assert results["methods"][m]["cycles"] == N
            assert results["methods"][m]["final_exposure_ms"] == json.loads(
                (hostile_clean / "results.json").read_text())["methods"][m]["final_exposure_ms"]
        assert json.loads((out / "run.json").read_text())["status"] == "complete"
    else:
        # refused: one line naming the damaged table, which is left as it was
        assert rc == 1 and len(err.splitlines()) == 1 and "exposures.csv" in err, err
        assert path.read_text() == damaged_text


@pytest.mark.parametrize("damage", DAMAGES, ids=lambda f: f.__name__.strip("_"))
def test_resume_of_a_damaged_interrupted_run(hostile_seq, hostile_clean, tmp_path, damage, capsys):
    out = tmp_path / "run"
    _hostile_interrupted(hostile_seq, out)
    path = out / "classical-50" / "exposures.csv"
    text = "".join(damage(_lines(path)))
    path.write_text(text, newline="")
    _resume_outcome(hostile_seq, out, hostile_clean, path, text, capsys)


@pytest.mark.parametrize("damage", [_missing_middle, _duplicated, _reordered], ids=lambda f: f.__name__.strip("_"))
def test_resume_of_a_damaged_complete_run(hostile_seq, hostile_clean, tmp_path, damage, capsys):
    """A finished run whose table was damaged afterwards: --resume must not call it complete as is."""
    out = tmp_path / "run"
    assert main(["run", str(hostile_seq), "--methods", ",".join(METHODS), "-o", str(out), "-q"]) == 0
    path = out / "shim" / "exposures.csv"
    text = "".join(damage(_lines(path)))
    path.write_text(text, newline="")
    _resume_outcome(hostile_seq, out, hostile_clean, path, text, capsys)


def test_resume_with_one_table_deleted(hostile_seq, hostile_clean, tmp_path, capsys):
    out = tmp_path / "run"
    _hostile_interrupted(hostile_seq, out)
    path = out / "shim" / "exposures.csv"
    path.unlink()
    rc = main(["run", str(hostile_seq), "-o", str(out), "--resume", "-q"])
    err = capsys.readouterr().err.strip()
    if rc == 0:
        assert _tables(out) == _tables(hostile_clean)
    else:
        assert rc == 1 and len(err.splitlines()) == 1 and "shim" in err, err


def test_resume_with_run_json_damaged(hostile_seq, tmp_path, capsys):
    out = tmp_path / "run"
    _hostile_interrupted(hostile_seq, out)
    before = _tables(out)
    (out / "run.json").write_text('{"status": "interrupted", "methods": ')
    assert main(["run", str(hostile_seq), "-o", str(out), "--resume", "-q"]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "run.json" in err, err
    assert _tables(out) == before

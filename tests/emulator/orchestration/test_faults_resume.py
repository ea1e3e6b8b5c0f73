"""Fault suite, issue 24 (resume): a resumed run validates its tables before appending; a table
that is not an ordered, unique prefix of the run is cut back to its valid prefix and recomputed,
so the result equals an uninterrupted run, byte for byte, and run.json says what was repaired."""

from __future__ import annotations

import json

import pytest

from emulator.commands.cli import main
from emulator.orchestration.runner import run_to_folder
from test_playback import write_static_sequence

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

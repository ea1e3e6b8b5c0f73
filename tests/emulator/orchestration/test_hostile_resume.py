"""Damaged run folders under --resume, written independently of tests/test_faults_*.py (issue 24).

An interrupted run's tables are damaged the ways a crash, an editor or a copy can damage them;
``--resume`` must then give exactly the bytes of an uninterrupted run, or refuse in one line
naming the file and leave it as it was. It must never finish "complete" with a wrong table.
"""

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
    root, _ = write_static_sequence(tmp_path_factory.mktemp("rseq") / "seq", n_cycles=N, shape=(32, 48))
    return root


def _tables(run_dir):
    return {m: (run_dir / m / "exposures.csv").read_bytes() for m in METHODS}


@pytest.fixture(scope="module")
def clean(seq, tmp_path_factory):
    out = tmp_path_factory.mktemp("rclean") / "run"
    assert main(["run", str(seq), "--methods", ",".join(METHODS), "-o", str(out), "-q"]) == 0
    return out


def _interrupted(seq, out, after=4):
    def stop(done, total):
        if done == after:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_to_folder(seq, METHODS, out, progress=stop, command="exposim run (hostile test)")
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


def _resume_outcome(seq, out, clean, path, damaged_text, capsys):
    capsys.readouterr()
    rc = main(["run", str(seq), "-o", str(out), "--resume", "-q"])
    err = capsys.readouterr().err.strip()
    if rc == 0:
        # repaired: exactly an uninterrupted run, nothing lost, nothing doubled
        assert _tables(out) == _tables(clean)
        results = json.loads((out / "results.json").read_text())
        for m in METHODS:
            assert results["methods"][m]["cycles"] == N
            assert results["methods"][m]["final_exposure_ms"] == json.loads(
                (clean / "results.json").read_text())["methods"][m]["final_exposure_ms"]
        assert json.loads((out / "run.json").read_text())["status"] == "complete"
    else:
        # refused: one line naming the damaged table, which is left as it was
        assert rc == 1 and len(err.splitlines()) == 1 and "exposures.csv" in err, err
        assert path.read_text() == damaged_text


@pytest.mark.parametrize("damage", DAMAGES, ids=lambda f: f.__name__.strip("_"))
def test_resume_of_a_damaged_interrupted_run(seq, clean, tmp_path, damage, capsys):
    out = tmp_path / "run"
    _interrupted(seq, out)
    path = out / "classical-50" / "exposures.csv"
    text = "".join(damage(_lines(path)))
    path.write_text(text, newline="")
    _resume_outcome(seq, out, clean, path, text, capsys)


@pytest.mark.parametrize("damage", [_missing_middle, _duplicated, _reordered], ids=lambda f: f.__name__.strip("_"))
def test_resume_of_a_damaged_complete_run(seq, clean, tmp_path, damage, capsys):
    """A finished run whose table was damaged afterwards: --resume must not call it complete as is."""
    out = tmp_path / "run"
    assert main(["run", str(seq), "--methods", ",".join(METHODS), "-o", str(out), "-q"]) == 0
    path = out / "shim" / "exposures.csv"
    text = "".join(damage(_lines(path)))
    path.write_text(text, newline="")
    _resume_outcome(seq, out, clean, path, text, capsys)


def test_resume_with_one_table_deleted(seq, clean, tmp_path, capsys):
    out = tmp_path / "run"
    _interrupted(seq, out)
    path = out / "shim" / "exposures.csv"
    path.unlink()
    rc = main(["run", str(seq), "-o", str(out), "--resume", "-q"])
    err = capsys.readouterr().err.strip()
    if rc == 0:
        assert _tables(out) == _tables(clean)
    else:
        assert rc == 1 and len(err.splitlines()) == 1 and "shim" in err, err


def test_resume_with_run_json_damaged(seq, tmp_path, capsys):
    out = tmp_path / "run"
    _interrupted(seq, out)
    before = _tables(out)
    (out / "run.json").write_text('{"status": "interrupted", "methods": ')
    assert main(["run", str(seq), "-o", str(out), "--resume", "-q"]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "run.json" in err, err
    assert _tables(out) == before

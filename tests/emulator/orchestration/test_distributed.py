"""Dataset runs on Dask: byte-identical to the serial and threaded runs, the same error rows when a
method or a unit raises, and a worker killed mid-task loses no rows."""

from __future__ import annotations

import json
import sys

import pytest

from emulator.orchestration.datasetrun import run_dataset
from emulator.orchestration.distributed import run_tasks

try:
    from tests.emulator.orchestration.test_datasetrun import csv_bytes, make_dataset
except ImportError:  # tests collected as a package
    from tests.test_datasetrun import csv_bytes, make_dataset

METHODS = "classical-50,zhang"

#: A plugin method that kills its own process on its first call while ``MARKER`` does not exist
#: (creating it first), as a worker that dies mid-task does; otherwise it holds the exposure.  The
#: test hook lives here, in a method, never in the library's task.
KILLER = '''
import os

MARKER = {marker!r}


class Killer:
    name = "killer"

    def reset(self):
        pass

    def next_exposure(self, raw, exposure_ms):
        if not os.path.exists(MARKER):
            with open(MARKER, "w") as fh:
                fh.write("killed\\n")
            os._exit(3)
        return exposure_ms


class Raiser:
    name = "raiser"

    def reset(self):
        pass

    def next_exposure(self, raw, exposure_ms):
        raise RuntimeError("raiser always raises")
'''


def _boom(x):
    if x == 2:
        raise KeyError("two")
    return x * 10


def test_run_tasks_one_error_policy_serial_and_threads():
    for threads in (1, 3):
        out = run_tasks(_boom, [(i,) for i in range(4)], threads=threads, keys=list("abcd"))
        assert [o.key for o in out] == list("abcd")
        assert [o.result for o in out] == [0, 10, None, 30]
        assert [o.error for o in out] == [None, None, "KeyError: 'two'", None]


@pytest.fixture
def killer_module(tmp_path, monkeypatch):
    marker = tmp_path / "killed.txt"
    (tmp_path / "mods").mkdir()
    (tmp_path / "mods" / "killer_ae.py").write_text(KILLER.format(marker=str(marker)))
    monkeypatch.syspath_prepend(str(tmp_path / "mods"))
    monkeypatch.setenv("PYTHONPATH", str(tmp_path / "mods"))
    sys.modules.pop("killer_ae", None)
    yield marker
    sys.modules.pop("killer_ae", None)


@pytest.mark.slow
def test_dask_runs_equal_serial_and_survive_a_killed_worker(tmp_path, killer_module):
    distributed = pytest.importorskip("dask.distributed")
    marker = killer_module
    methods = METHODS + ",killer_ae:Killer,killer_ae:Raiser"
    root = make_dataset(tmp_path / "root")
    marker.write_text("not now\n")  # in this process the killer only holds its exposure
    serial = tmp_path / "serial"
    ref = run_dataset(root, serial, methods=methods, scheduler="serial")
    expected = csv_bytes(serial)
    assert len(expected) == 8 and all(v.count(b"\n") in (1, 4, 5) for v in expected.values())
    threads = run_dataset(root, tmp_path / "threads", methods=methods, scheduler="threads", n_workers=2, jobs=2)
    assert csv_bytes(tmp_path / "threads") == expected and threads["errors"] == ref["errors"] == []

    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address=None) as cluster:
        address = cluster.scheduler_address
        assert address.startswith("tcp://")
        # one unit per sequence (every method in a group): the CSVs do not depend on the grouping
        plain = run_dataset(root, tmp_path / "dask", methods=methods, group_size=4, scheduler=address)
        assert plain["errors"] == [] and csv_bytes(tmp_path / "dask") == expected

        # The killer's first call kills its process with a partial staging folder behind; methods run
        # inline here, so that process is the Dask worker (in their own processes, the default, the
        # killer fails alone: tests/emulator/playback/test_workers_faults.py); the scheduler runs the task again on a
        # fresh worker.
        marker.unlink()
        killed = run_dataset(root, tmp_path / "killed", methods=methods, group_size=4, scheduler=address,
                             retries=2, workers="inline")
    assert marker.read_text() == "killed\n"
    assert killed["errors"] == [] and len(killed["units"]) == 2
    assert csv_bytes(tmp_path / "killed") == expected  # no row lost, none written twice
    assert not list((tmp_path / "killed").glob("*/.*staging*"))
    res, ref_seq = (json.loads((d / "results.json").read_text())["per_sequence"] for d in (tmp_path / "killed", serial))
    for per in (res, ref_seq):  # everything but the timings
        for figures in per.values():
            for m in figures.values():
                m.pop("method_ms_per_frame")
    assert res == ref_seq and set(res) == {"seqA", "seqB"}
    assert {f["status"] for per in res.values() for name, f in per.items() if name == "raiser"} == {
        "failed: raised RuntimeError: raiser always raises at cycle 0"}


@pytest.mark.slow
def test_a_unit_that_raises_is_the_same_error_row_on_every_path(tmp_path):
    distributed = pytest.importorskip("dask.distributed")
    root = make_dataset(tmp_path / "root")
    (root / "broken.zip").write_bytes(b"PK\x03\x04 truncated")
    rows = {}
    for name, kw in (("serial", {}), ("threads", {"n_workers": 2})):
        res = run_dataset(root, tmp_path / name, methods="fixed", scheduler=name, **kw)
        rows[name] = res["errors"]
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address=None) as cluster:
        rows["dask"] = run_dataset(root, tmp_path / "dask", methods="fixed", scheduler=cluster.scheduler_address,
                                   retries=0)["errors"]
    assert rows["serial"] == rows["threads"] == rows["dask"]
    assert [e["unit"] for e in rows["serial"]] == ["broken/fixed"]
    assert "not a readable zip archive" in rows["serial"][0]["error"]
    assert csv_bytes(tmp_path / "serial") == csv_bytes(tmp_path / "threads") == csv_bytes(tmp_path / "dask")

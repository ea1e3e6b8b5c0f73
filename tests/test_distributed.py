"""Dataset runs on Dask: byte-identical to the serial run, and a worker killed mid-task loses no rows."""

from __future__ import annotations

import json

import pytest

from emulator.datasetrun import run_dataset

try:
    from test_datasetrun import csv_bytes, make_dataset
except ImportError:  # tests collected as a package
    from tests.test_datasetrun import csv_bytes, make_dataset

distributed = pytest.importorskip("dask.distributed")

METHODS = "classical-50,zhang"


def test_dask_runs_equal_serial_and_survive_a_killed_worker(tmp_path):
    root = make_dataset(tmp_path / "root")
    serial = tmp_path / "serial"
    run_dataset(root, serial, methods=METHODS, scheduler="serial")
    expected = csv_bytes(serial)
    assert len(expected) == 4 and all(v.count(b"\n") in (4, 5) for v in expected.values())

    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address=None) as cluster:
        address = cluster.scheduler_address
        assert address.startswith("tcp://")
        # one unit per sequence (both methods in a group): the CSVs do not depend on the grouping
        plain = run_dataset(root, tmp_path / "dask", methods=METHODS, group_size=2, scheduler=address)
        assert plain["errors"] == [] and csv_bytes(tmp_path / "dask") == expected

        # The first unit to finish a cycle kills its worker process (os._exit) with a partial staging
        # folder behind; the scheduler runs the task again on a fresh worker.
        marker = tmp_path / "killed.txt"
        killed = run_dataset(root, tmp_path / "killed", methods=METHODS, group_size=2, scheduler=address,
                             retries=2, fault_marker=str(marker))
    assert marker.read_text().startswith("killed ")
    assert killed["errors"] == [] and len(killed["units"]) == 2
    assert csv_bytes(tmp_path / "killed") == expected  # no row lost, none written twice
    assert not list((tmp_path / "killed").glob("*/.*staging*"))
    res, ref = (json.loads((d / "results.json").read_text())["per_sequence"] for d in (tmp_path / "killed", serial))
    for per in (res, ref):  # everything but the timings
        for figures in per.values():
            for m in figures.values():
                m.pop("method_ms_per_frame")
    assert res == ref and set(res) == {"seqA", "seqB"}

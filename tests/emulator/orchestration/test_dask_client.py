"""Dask as people run it: tcp/tls addresses, scheduler files, $DASK_SCHEDULER_ADDRESS, a Client, no dashboard."""

from __future__ import annotations

import json
import os
import socket
import urllib.error
import urllib.request
import warnings

import pytest

from emulator.orchestration.distributed import (SchedulerError, check_scheduler, connect, is_address, local_client, open_client,
                                  resolve_scheduler)

try:
    from tests.emulator.orchestration.test_datasetrun import csv_bytes, make_dataset
except ImportError:  # tests collected as a package
    from tests.test_datasetrun import csv_bytes, make_dataset

METHODS = "classical-50,zhang"


def test_addresses_and_the_resolution_order(tmp_path):
    assert is_address("tcp://10.0.0.1:8786") and is_address("tls://[::1]:8786") and is_address("tls://h.example:1")
    assert not is_address("tcp://h") and not is_address("udp://h:1") and not is_address("local")
    with pytest.raises(SchedulerError, match=r"unknown scheduler 'http://h:1'.*tls://HOST:PORT"):
        check_scheduler("http://h:1")
    env = {"DASK_SCHEDULER_ADDRESS": "tls://h:8786"}
    assert resolve_scheduler(None, environ=env) == ("tls://h:8786", None)
    assert resolve_scheduler("local", environ=env) == ("local", None)  # the flag wins over the environment
    assert resolve_scheduler(None, environ={}) == ("local", None)
    with pytest.raises(SchedulerError, match=r"\$DASK_SCHEDULER_ADDRESS='h:8786' is not"):
        resolve_scheduler(None, environ={"DASK_SCHEDULER_ADDRESS": "h:8786"})
    with pytest.raises(SchedulerError, match="no such scheduler file"):
        resolve_scheduler(None, tmp_path / "missing.json")
    (tmp_path / "s.json").write_text("{}")
    assert resolve_scheduler(None, tmp_path / "s.json", environ=env) == ("file", str(tmp_path / "s.json"))
    with pytest.raises(SchedulerError, match="not both"):
        resolve_scheduler("local", tmp_path / "s.json")


def test_a_tls_address_is_tried_and_named_when_unreachable():
    with socket.socket() as s:  # a free port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    with pytest.raises(SchedulerError, match=rf"tls://127.0.0.1:{port}: a tls:// scheduler needs TLS certificates"):
        with connect(f"tls://127.0.0.1:{port}", timeout_s=1.0):
            pass
    with pytest.raises(SchedulerError, match=rf"tcp://127.0.0.1:{port}: cannot reach the Dask scheduler"):
        with connect(f"tcp://127.0.0.1:{port}", timeout_s=1.0):
            pass


def test_local_cluster_starts_no_dashboard_warns_nothing_and_leaves_no_files(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with socket.socket() as busy:
        busy.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            busy.bind(("127.0.0.1", 8787))
            busy.listen()
        except OSError:  # 8787 already taken by someone else: just as busy
            pass
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            with local_client(1) as client:
                assert client.submit(sum, [1, 2]).result() == 3
                port = client.scheduler_info()["services"]["dashboard"]  # the health-check HTTP server
                assert port != 8787
                with pytest.raises(urllib.error.HTTPError) as status:
                    urllib.request.urlopen(f"http://127.0.0.1:{port}/status", timeout=5)
                assert status.value.code == 404  # no dashboard page
    assert [str(w.message) for w in caught if "8787" in str(w.message) or "dashboard" in str(w.message)] == []
    assert os.listdir(tmp_path) == []


def test_run_dataset_by_scheduler_file_by_client_and_by_environment(tmp_path, monkeypatch):
    distributed = pytest.importorskip("dask.distributed")
    from emulator.commands.cli import main
    from emulator.orchestration.datasetrun import run_dataset

    root = make_dataset(tmp_path / "root")
    run_dataset(root, tmp_path / "serial", methods=METHODS, scheduler="serial")
    expected = csv_bytes(tmp_path / "serial")
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        sched_file = tmp_path / "scheduler.json"
        client.write_scheduler_file(str(sched_file))
        by_file = run_dataset(root, tmp_path / "file", methods=METHODS, scheduler_file=sched_file)
        assert by_file["scheduler"] == f"file {sched_file}" and csv_bytes(tmp_path / "file") == expected

        by_client = run_dataset(root, tmp_path / "client", methods=METHODS, scheduler=client)
        assert by_client["scheduler"] == f"client {cluster.scheduler_address}"
        assert csv_bytes(tmp_path / "client") == expected
        assert client.status == "running"  # the caller's client is left open
        with open_client(client) as same:
            assert same is client

        monkeypatch.setenv("DASK_SCHEDULER_ADDRESS", cluster.scheduler_address)
        assert main(["run", str(root), "--sequences", "all", "--methods", METHODS, "--save", "none",
                     "-o", str(tmp_path / "env"), "--json", "--no-progress"]) == 0
        summary = json.loads((tmp_path / "env" / "results.json").read_text())
        assert summary["scheduler"] == cluster.scheduler_address
        assert csv_bytes(tmp_path / "env") == expected

        assert main(["run", str(root), "--sequences", "all", "--methods", METHODS, "--save", "none",
                     "-o", str(tmp_path / "cli-file"), "--scheduler-file", str(sched_file), "--no-progress"]) == 0
        assert csv_bytes(tmp_path / "cli-file") == expected


def _pid_after(seconds):
    import time

    time.sleep(seconds)
    return os.getpid()


def test_a_local_clusters_worker_survives_a_pause_longer_than_dasks_worker_ttl():
    """A suspended machine or a SIGSTOPped study pauses every worker; none may be removed for it.

    Dask removes (and its nanny kills) a worker silent for ``worker-ttl`` (5 minutes by
    default; 5 s here, set as a user's own Dask config would); three such pauses failed a
    study's walk with ``KilledWorker``. ``local_client`` turns the limit off.
    """
    import signal
    import time

    import dask

    with dask.config.set({"distributed.scheduler.worker-ttl": "5s"}), local_client(1) as client:
        assert client.run_on_scheduler(lambda dask_scheduler: dask_scheduler.worker_ttl) is None
        (pid,) = client.run(os.getpid).values()
        future = client.submit(_pid_after, 6.0, pure=False)
        time.sleep(1.0)
        os.kill(pid, signal.SIGSTOP)
        try:
            time.sleep(12.0)  # past the 5 s limit and the scheduler's 10-heartbeat floor
        finally:
            os.kill(pid, signal.SIGCONT)
        assert future.result(timeout=60) == pid  # the same worker finished the task, no retry

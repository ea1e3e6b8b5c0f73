"""``exposim render --scheduler``: frames as Dask tasks give the serial render's cache entries and bytes.

The cluster here runs its workers as threads of the test process (``processes=False``) on a
TCP address, so the test exercises the client, the task graph and the ``tcp://`` option
without paying for worker processes that import Mitsuba (``--scheduler local`` starts
those; same code path otherwise).
"""

from __future__ import annotations

import hashlib
import logging

import pytest

from emulator.commands.cli import main
from scenes.errors import RenderError
from scenes.parallel import check_scheduler

pytestmark = pytest.mark.render


def _tree(folder):
    return {p.relative_to(folder).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def test_scheduler_spec_is_checked(tmp_path, capsys):
    assert check_scheduler(None) is None and check_scheduler("local") == "local"
    assert check_scheduler("tcp://10.0.0.5:8786") == "tcp://10.0.0.5:8786"
    assert check_scheduler("tls://10.0.0.5:8786") == "tls://10.0.0.5:8786"
    for bad in ("remote", "tcp://host", "http://h:1", "localx"):
        with pytest.raises(RenderError, match="--scheduler must be 'local' or tcp://HOST:PORT"):
            check_scheduler(bad)
    out = tmp_path / "x"
    assert main(["render", "static_lab", "-o", str(out), "--size", "8x6", "--spp", "1", "--duration", "0",
                 "--scheduler", "everywhere", "--quiet"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("exposim render: error: --scheduler must be") and err.count("\n") == 1
    assert not out.exists()  # refused before anything was created


@pytest.fixture(scope="module")
def cluster():
    from dask.distributed import LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=False, protocol="tcp", dashboard_address=":0",
                      silence_logs=logging.ERROR) as c:
        assert c.scheduler_address.startswith("tcp://")
        yield c


def _tasks_done(cluster) -> int:
    prefix = cluster.scheduler.task_prefixes.get("render_task")
    return 0 if prefix is None else prefix.state_counts["forgotten"]


def test_dask_render_equals_serial_render(tmp_path, monkeypatch, cluster):
    monkeypatch.setenv("EXPOSIM_DENOISE", "off")  # the plumbing, not the denoiser, is under test
    args = ["render", "static_lab", "--size", "24x16", "--spp", "2", "--duration", "1", "--rate", "2",
            "--stereo", "--quiet"]
    monkeypatch.setenv("EXPOSIM_CACHE", str(tmp_path / "cache-serial"))
    assert main(args + ["-o", str(tmp_path / "serial")]) == 0
    before = _tasks_done(cluster)
    monkeypatch.setenv("EXPOSIM_CACHE", str(tmp_path / "cache-dask"))
    assert main(args + ["-o", str(tmp_path / "dask"), "--scheduler", cluster.scheduler_address]) == 0
    assert _tasks_done(cluster) - before == 6  # one task per image, each released once its image was written
    serial, dask = _tree(tmp_path / "serial"), _tree(tmp_path / "dask")
    assert len(serial) == 1 + 2 + 2 * 3  # scene.json, two pose files, 3 timestamps x 2 cameras
    assert dask == serial
    cache_serial, cache_dask = _tree(tmp_path / "cache-serial"), _tree(tmp_path / "cache-dask")
    assert len(cache_serial) == 6 and cache_dask == cache_serial


def test_dask_synth_equals_serial_synth(tmp_path, monkeypatch, cluster):
    import importlib

    render_module = importlib.import_module("scenes.render")

    monkeypatch.setenv("EXPOSIM_DENOISE", "off")
    args = ["synth", "static_lab", "--cycles", "1", "--size", "24x16", "--spp", "2", "--mono", "--quiet"]
    assert main(args + ["-o", str(tmp_path / "serial"), "--cache", str(tmp_path / "cache-serial")]) == 0
    before = _tasks_done(cluster)
    calls = []
    real = render_module._render_uncached
    monkeypatch.setattr(render_module, "_render_uncached", lambda *a, **k: calls.append(1) or real(*a, **k))
    assert main(args + ["-o", str(tmp_path / "dask"), "--cache", str(tmp_path / "cache-dask"),
                        "--scheduler", cluster.scheduler_address]) == 0
    assert _tasks_done(cluster) - before == 6 and len(calls) == 6  # six shots, each rendered once, by a task
    assert _tree(tmp_path / "dask") == _tree(tmp_path / "serial")
    cache = _tree(tmp_path / "cache-dask")
    assert len(cache) == 6 and cache == _tree(tmp_path / "cache-serial")


def test_dask_synth_with_blur_equals_serial_synth(tmp_path, monkeypatch, cluster):
    """A moving scene with exposure-time blur: the Dask prefetch renders each shot's blur renders
    (once per shot and camera) and the dataset has the serial bytes."""
    from scenes.synthesize import synthesize

    monkeypatch.setenv("EXPOSIM_DENOISE", "off")
    kwargs = dict(n_cycles=1, width=24, height=16, spp=2, stereo=True, blur=True, gt_exposures_ms=(3.0,))
    synthesize("forest_winter", tmp_path / "serial", cache_dir=tmp_path / "cache-serial", **kwargs)
    before = _tasks_done(cluster)
    synthesize("forest_winter", tmp_path / "dask", cache_dir=tmp_path / "cache-dask",
               scheduler=cluster.scheduler_address, **kwargs)
    assert _tasks_done(cluster) - before == 12  # six shots, two cameras
    assert _tree(tmp_path / "dask") == _tree(tmp_path / "serial")
    assert _tree(tmp_path / "cache-dask") == _tree(tmp_path / "cache-serial")

"""A method in a worker computes while the run does the second camera's part of its shot
(:meth:`EmulatedTick.split_shot`): the shot is the same, the tables are the same, and an error of
the second camera is the same one-line error it was."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from emulator.errors import DatasetError
from emulator.io.borealhdr import load_sequence
from emulator.playback import RunConfig, run
from emulator.playback.emulated import EmulatedProvider
from tests.emulator.playback.test_playback import write_static_sequence

FIELDS = [f.name for f in dataclasses.fields(__import__("emulator.playback.loop", fromlist=["Shot"]).Shot)]


@pytest.fixture(scope="module")
def seq(tmp_path_factory):
    root, _ = write_static_sequence(tmp_path_factory.mktemp("overlap") / "seq", n_cycles=3, shape=(32, 48))
    return root


@pytest.mark.parametrize("want_right", [False, True])
def test_the_split_shot_with_its_rest_is_the_shot(seq, want_right):
    s = load_sequence(seq, imu_warning=False)
    cfg = RunConfig()
    whole = list(EmulatedProvider(s, cfg, cfg.response_for(s, None)).ticks())
    split = list(EmulatedProvider(s, cfg, cfg.response_for(s, None)).ticks())
    for a, b in zip(whole, split):
        for target in (0.5, 3.0, 6.0, 40.0):
            shot = a.shot(target, want_right)
            part, rest = b.split_shot(target, want_right)
            assert part.saturated_fraction_right is None and part.right is None  # not yet: rest() adds them
            rest()
            for name in FIELDS:
                x, y = getattr(shot, name), getattr(part, name)
                if isinstance(x, np.ndarray) or isinstance(y, np.ndarray):
                    assert np.array_equal(x, y)
                else:
                    assert x == y, name
            assert shot.saturated_fraction_right is not None
            assert (shot.right is not None) == want_right


@pytest.mark.parametrize("workers", ["process", "inline"])
def test_a_stereo_pair_of_two_instants_is_the_same_error_with_workers(seq, workers):
    s = load_sequence(seq, imu_warning=False)
    cycle = s.cycles[0]
    for ms, frame in list(cycle.frames["right"].items()):  # whichever bracket the method's target selects
        cycle.frames["right"][ms] = dataclasses.replace(frame, timestamp_ns=frame.timestamp_ns + 1)
    with pytest.raises(DatasetError, match=r"camera_right.*stereo pair mismatch"):
        run(s, "classical-50,shim", workers=workers)


def test_tables_are_the_same_with_the_second_camera_done_beside_the_method(seq):
    base = run(seq, "classical-50,shim,kim", workers="inline")
    for jobs in (1, 2):
        res = run(seq, "classical-50,shim,kim", workers="process", jobs=jobs)
        assert {k: [dataclasses.replace(st, left=None, right=None) for st in v] for k, v in res.steps.items()} == \
            {k: [dataclasses.replace(st, left=None, right=None) for st in v] for k, v in base.steps.items()}
        assert all(st.saturated_fraction_right is not None for v in res.steps.values() for st in v)


@pytest.mark.parametrize("jobs", [1, 2])
def test_a_worker_killed_between_calls_fails_alone_saying_how(seq, monkeypatch, jobs):
    """A worker killed while idle (the OOM killer, an operator): its next call, sent ahead or not, fails its
    method alone with the signal, not with the broken pipe it meets."""
    import os
    import signal

    from emulator.playback import workers

    real = workers.MethodWorker.send_ahead
    sends = {}

    def send_ahead(self, raw, exposure_ms):
        sends[self.name] = sends.get(self.name, 0) + 1
        if self.name == "shim" and sends["shim"] == 2:
            os.kill(self.pid(), signal.SIGKILL)
            self._proc.join(5)
        return real(self, raw, exposure_ms)

    monkeypatch.setattr(workers.MethodWorker, "send_ahead", send_ahead)
    res = run(seq, "classical-50,shim", workers="process", jobs=jobs)
    assert res.failed == {"shim": "failed: its process was killed by SIGKILL in next_exposure at cycle 1"}
    assert len(res.steps["classical-50"]) == 3 and len(res.steps["shim"]) == 1


@pytest.mark.parametrize("jobs", [1, 2])
def test_a_call_that_cannot_be_handed_over_fails_its_method_alone(seq, monkeypatch, jobs):
    """Handing the image to a worker fails (its shared memory cannot be made: /dev/shm full): sent ahead or
    not, that method fails alone, named, and the others' results are kept."""
    import errno

    from emulator.playback import workers

    real = workers.MethodWorker._message

    def message(self, raw, exposure_ms):
        if self.name == "shim":
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(self, raw, exposure_ms)

    monkeypatch.setattr(workers.MethodWorker, "_message", message)
    res = run(seq, "classical-50,shim", workers="process", jobs=jobs)
    assert set(res.failed) == {"shim"} and "No space left on device" in res.failed["shim"]
    assert res.failed["shim"].endswith("at cycle 0")
    assert len(res.steps["classical-50"]) == 3 and res.steps.get("shim", []) == []

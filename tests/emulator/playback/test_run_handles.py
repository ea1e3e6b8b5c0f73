"""Objects that decide once: the configuration gives the provider of its rate, the provider carries what
the runner reports of it, and methods reach the closed loop as handles that keep their own time limit.
"""

from __future__ import annotations

import ast
import time
from pathlib import Path

import pytest

from emulator.autoexposure.registry import MethodFailed
from emulator.io.runcsv import NATIVE_COLUMNS
from emulator.core.native import NATIVE_RATE, is_native_run, native_record, run_rate, tick_unit
from emulator.playback import EmulatedProvider, NativeProvider, RunConfig, closed_loop, prepare_run, resolve_sequence
from emulator.playback.seam import InlineMethod, MethodHandle, as_handle, call_method
from emulator.playback.workers import start_methods
from tests.emulator.playback.test_playback import write_static_sequence

ROOT = Path(__file__).resolve().parents[3]


@pytest.fixture(scope="module")
def seq(tmp_path_factory):
    return resolve_sequence(write_static_sequence(tmp_path_factory.mktemp("handles") / "seq", n_cycles=4,
                                                  shape=(16, 24))[0])


class Const:
    name = "const"

    def __init__(self, value=2.0, sleep_s=0.0):
        self.value, self.sleep_s, self.calls = value, sleep_s, 0

    def next_exposure(self, raw, exposure_ms):
        self.calls += 1
        time.sleep(self.sleep_s)
        return self.value


@pytest.mark.parametrize("rate, cls, unit, columns", [("cycle", EmulatedProvider, "cycles", ()),
                                                      (NATIVE_RATE, NativeProvider, "frames", NATIVE_COLUMNS)])
def test_the_configuration_gives_the_provider_of_its_rate(seq, rate, cls, unit, columns):
    config = RunConfig(rate=rate, workers="inline")
    assert config.provider_class is cls
    prep = prepare_run(seq, [Const()], config)
    provider = prep.provider
    assert type(provider) is cls and provider.unit == unit and provider.columns == columns
    assert provider.latency_ticks == config.latency_ticks == (1 if rate == NATIVE_RATE else 0)
    ticks = [t.index for t in provider.ticks()]
    frames = sum(len(c.frames["left"]) for c in seq.cycles)
    assert provider.tick_indices == ticks and len(ticks) == (len(seq.cycles) if rate == "cycle" else frames)
    record = provider.run_json()
    assert (set(record) == {NATIVE_RATE}) if rate == NATIVE_RATE else record == {}
    run_json = {**RunConfig(rate=rate).to_json(), **record}
    assert (run_rate(run_json), is_native_run(run_json), tick_unit(run_json)) == (rate, rate == NATIVE_RATE, unit)
    assert native_record(run_json) == (provider.describe() if rate == NATIVE_RATE else {})


def test_inline_methods_are_handles_that_keep_the_runs_limit(seq):
    handles = start_methods([Const()], RunConfig(workers="inline", method_timeout_s=5), None)
    assert isinstance(handles["const"], InlineMethod) and handles["const"].limit_s == 5.0
    assert handles["const"].value == 2.0  # the method's own attributes through its handle
    assert as_handle(handles["const"]) is handles["const"]


def test_an_inline_call_over_its_limit_fails_the_method_after_it_returns():
    method = Const(sleep_s=0.05)
    with pytest.raises(MethodFailed, match=r"over the limit of 0.01 s"):
        call_method(InlineMethod(method, 0.01), None, 4.0, range_ms=(0.1, 10.0))
    assert method.calls == 1  # the call ran to its end
    answer = call_method(InlineMethod(Const(), None), None, 4.0, range_ms=(0.1, 10.0))
    assert (answer.proposed_ms, answer.next_ms, answer.guarded) == (2.0, 2.0, False)


def test_the_loop_asks_every_handle_the_same_way(seq):
    """A handle of its own making: the loop takes the shot from it and asks it, with no test of its kind."""

    class Counting(MethodHandle):
        name = "counting"

        def __init__(self):
            self.shots = self.proposals = 0
            self.closed = False

        def shot(self, tick, target_ms, want_right):
            self.shots += 1
            return tick.shot(target_ms, want_right)

        def propose(self, raw, exposure_ms):
            self.proposals += 1
            return exposure_ms * 2

        def close(self):
            self.closed = True

    handle = Counting()
    config = RunConfig(initial_ms=1.0, range_ms=(0.5, 6.0))
    steps = [cs.steps["counting"] for cs in closed_loop(EmulatedProvider(seq, config, RunConfig().response_for(seq)),
                                                         {"counting": handle}, config)]
    assert handle.shots == handle.proposals == len(steps) == len(seq.cycles)
    assert [s.target_ms for s in steps] == [1.0, 2.0, 4.0, 6.0]
    assert handle.closed  # stopped with the loop


def test_the_loop_does_not_test_what_kind_of_method_it_calls():
    tree = ast.parse((ROOT / "emulator" / "playback" / "loop.py").read_text())
    imported = {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
    assert "emulator.playback.workers" not in imported
    assert "MethodWorker" not in {n.id for n in ast.walk(tree) if isinstance(n, ast.Name)}
    config_src = (ROOT / "emulator" / "playback" / "config.py").read_text()
    assert "playback.workers" not in config_src  # config gives workers their default, not the other way


def test_the_native_rate_is_named_in_one_place():
    count = sum(path.read_text().count('"native"') for path in (ROOT / "emulator").rglob("*.py"))
    assert count <= 3

"""The one run configuration (RunConfig), the one call site of a method, and the one closed loop's providers."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from emulator.autoexposure.registry import MethodFailed
from emulator.commands.emulate_body import emulate_cycle
from emulator.errors import DatasetError, PlaybackError
from emulator.io.borealhdr import load_sequence
from emulator.playback import (DEFAULT_RANGE_MS, LiveCycleProvider, LiveRateProvider, RunConfig, call_method,
                               closed_loop, iter_run, parse_options)

try:
    from tests.emulator.playback.test_playback import write_static_sequence
except ImportError:  # tests collected as a package
    from tests.test_playback import write_static_sequence


class Doubler:
    """Proposes twice the exposure it saw (a known, exact sequence of proposals)."""

    name = "doubler"

    def reset(self):
        pass

    def next_exposure(self, raw, exposure_ms):
        return 2.0 * exposure_ms


class Seen(Doubler):
    name = "seen"

    def __init__(self):
        self.seen = []

    def next_exposure(self, raw, exposure_ms):
        self.seen.append((int(raw[0, 0]), exposure_ms))
        return super().next_exposure(raw, exposure_ms)


# ------------------------------------------------------------------ RunConfig
@pytest.mark.parametrize("field, value, match", [
    ("initial_ms", math.nan, "initial_ms must be a finite, positive"),
    ("initial_ms", 0, "initial_ms must be a finite, positive"),
    ("initial_ms", True, "initial_ms must be a number"),
    ("range_ms", (5, 1), "range_ms must satisfy 0 < low <= high"),
    ("range_ms", (0, 1), "range_ms must satisfy 0 < low <= high"),
    ("range_ms", "x", r"range_ms must be \(low_ms, high_ms\)"),
    ("selector", "best", "unknown selector 'best'"),
    ("mode", "fast", "mode must be one of paper, borealhdr"),
    ("options", {"kim": 3}, "options must map a method name"),
    ("jobs", 0, "jobs must be an integer >= 1"),
    ("jobs", 1.5, "jobs must be an integer >= 1"),
    ("save", "jpg", "save must be one of none, png16, png8"),
    ("noise", "loud", "noise must be one of none, consistent"),
    ("noise_seed", -1, "noise_seed must be a non-negative integer"),
    ("method_timeout_s", 0, "method_timeout_s must be finite and positive"),
    ("method_timeout_s", "x", "method_timeout_s must be a number"),
    ("png_level", 10, "png_level must be an integer 0..9"),
])
def test_run_config_refuses_each_bad_field_by_name(field, value, match):
    with pytest.raises(PlaybackError, match=match):
        RunConfig(**{field: value})


def test_run_config_normalises_and_clamps_the_start():
    cfg = RunConfig(initial_ms=1e9, range_ms=[0.5, 20], jobs=np.int64(2), noise_seed=np.int32(3),
                    method_timeout_s=2, options={"kim": {"seed": 1}})
    assert cfg.range_ms == (0.5, 20.0) and cfg.jobs == 2 and type(cfg.jobs) is int and cfg.noise_seed == 3
    assert cfg.initial_ms == 1e9 and cfg.start_ms == 20.0 and RunConfig(initial_ms=0.01).start_ms == 0.02
    assert cfg.method_timeout_s == 2.0 and RunConfig().range_ms is not None
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.jobs = 3
    assert RunConfig.from_kwargs(method_timeout=1.5).method_timeout_s == 1.5  # the older name
    with pytest.raises(PlaybackError, match=r"method_timeout \(method_timeout_s\)"):
        RunConfig.from_kwargs(method_timeout=-1)
    with pytest.raises(TypeError, match="unknown run setting"):
        RunConfig.from_kwargs(colour="red")
    assert RunConfig.from_kwargs(cfg, selector=None, jobs=None) is cfg  # None: not given


def test_parse_options_folds_json_values():
    assert parse_options(["kim.seed=3", "zhang.percentile=0.7", "my-ae.name=abc", "kim.window=8"]) == {
        "kim": {"seed": 3, "window": 8}, "zhang": {"percentile": 0.7}, "my-ae": {"name": "abc"}}
    for bad in ("kim", "kim=3", ".seed=3", "kim.=3"):
        with pytest.raises(PlaybackError, match="expected METHOD.KEY=VALUE"):
            parse_options([bad])


def test_run_json_round_trip_and_the_one_resume_rule(tmp_path):
    cfg = RunConfig(initial_ms=3.0, range_ms=(0.1, 40.0), selector="closest", mode="borealhdr",
                    options={"kim": {"seed": 2}}, jobs=2, save="png8", method_timeout_s=5.0)
    recorded = {**cfg.to_json(), "sequence": "/s", "methods": ["kim"], "response": "linear"}
    back = RunConfig.from_json(recorded)
    assert back == cfg
    assert RunConfig.from_json({**recorded, "method_timeout": 7.0, "method_timeout_s": None}).method_timeout_s is None
    old = {k: v for k, v in recorded.items() if k != "method_timeout_s"} | {"method_timeout": 7.0}
    assert RunConfig.from_json(old).method_timeout_s == 7.0  # run folders written before the unit was named
    # the recorded configuration wins; what is given again must equal it; jobs may differ
    assert cfg.replace(jobs=1).resumed(recorded, identity={"methods": ["kim"]}) == cfg.replace(jobs=1)
    with pytest.raises(PlaybackError, match=r"different configuration \(selector, mode\)"):
        cfg.replace(selector="higher-no-sat", mode="paper").resumed(recorded)
    with pytest.raises(PlaybackError, match=r"different configuration \(methods\)"):
        cfg.resumed(recorded, identity={"methods": ["kim", "shim"]})
    # a field not given is not compared
    assert cfg.replace(selector="higher-no-sat").resumed(recorded, given=("mode",)).selector == "closest"
    # blur-consistent folders record the placement of the copies, with or without a hook (dataset.json);
    # one from before tiled copies (no placement: uniform sub-instants) is not resumed by this version
    blurred = cfg.replace(blur="consistent")
    rec_blur = {**blurred.to_json(), "sequence": "/s"}
    assert rec_blur["blur"] == {"mode": "consistent", "placement": "tiled"}
    assert blurred.resumed(rec_blur).blur == "consistent"
    with pytest.raises(PlaybackError, match=r"different configuration \(blur\)"):
        blurred.resumed({**rec_blur, "blur": {"mode": "consistent"}})
    assert cfg.resumed({**recorded, "blur": {"mode": "none"}}) == cfg  # --blur none still resumes
    # the response: two paths naming one file agree
    f = tmp_path / "pcalib.txt"
    f.write_text("x")
    rel = {**recorded, "response": str(f)}
    cfg.resumed(rel, identity={"response": str(tmp_path / "." / "pcalib.txt")})
    with pytest.raises(PlaybackError, match=r"\(response\)"):
        cfg.resumed(rel, identity={"response": str(tmp_path / "other.txt")})


# ------------------------------------------------------------------ the one call site
def test_call_method_guards_clamps_and_times():
    raw = np.zeros((4, 4), np.uint16)

    class Answer:
        name = "a"

        def __init__(self, value, sleep_s=0.0):
            self.value, self.sleep_s = value, sleep_s

        def next_exposure(self, raw, exposure_ms):
            import time

            time.sleep(self.sleep_s)
            return self.value

    a = call_method(Answer(7.0), raw, 4.0, range_ms=(1.0, 50.0))
    assert (a.proposed_ms, a.next_ms, a.guarded, a.clamped) == (7.0, 7.0, False, False) and a.elapsed_s >= 0
    a = call_method(Answer(80.0), raw, 4.0, range_ms=(1.0, 50.0))
    assert (a.proposed_ms, a.next_ms, a.guarded, a.clamped) == (80.0, 50.0, False, True)
    a = call_method(Answer(math.nan), raw, 4.0, range_ms=(1.0, 50.0))
    assert math.isnan(a.proposed_ms) and (a.next_ms, a.guarded, a.clamped) == (4.0, True, False)
    a = call_method(Answer("x"), raw, 0.5, range_ms=(1.0, 50.0))
    assert math.isnan(a.proposed_ms) and (a.next_ms, a.guarded, a.clamped) == (1.0, True, True)
    with pytest.raises(MethodFailed, match="over the limit of 0.01 s"):
        call_method(Answer(7.0, sleep_s=0.05), raw, 4.0, range_ms=DEFAULT_RANGE_MS, timeout_s=0.01)


# ------------------------------------------------------------------ live providers
def _shoot_log():
    calls = []

    def shoot(timestamp_ns, camera, exposure_ms, index):
        calls.append((timestamp_ns, camera, exposure_ms, index))
        return np.full((8, 8), min(int(round(100 * exposure_ms)), 4094), np.uint16)

    return shoot, calls


@pytest.mark.parametrize("latency, expected", [
    (0, [4.0, 8.0, 16.0, 32.0, 40.0, 40.0]),
    (1, [4.0, 4.0, 8.0, 8.0, 16.0, 16.0]),
    (2, [4.0, 4.0, 4.0, 8.0, 8.0, 8.0]),
])
def test_native_rate_provider_latency_and_mid_exposure_stamps(latency, expected):
    shoot, calls = _shoot_log()
    provider = LiveRateProvider(shoot, n_frames=6, white_level=4094, black_level=0, start_ns=10**9,
                                latency_frames=latency)
    seen = Seen()
    cycles = list(closed_loop(provider, {"seen": seen, "doubler": Doubler()},
                              RunConfig(initial_ms=4.0, range_ms=(1.0, 40.0)), keep_images=True))
    assert [cs.cycle for cs in cycles] == list(range(6))
    for name in ("seen", "doubler"):
        assert [cs.steps[name].target_ms for cs in cycles] == expected
    assert [s for s in seen.seen] == [(round(100 * t), t) for t in expected]  # the image of its own exposure
    for k, cs in enumerate(cycles):
        st = cs.steps["seen"]
        start = 10**9 + round(k * 1e9 / 22.0)
        assert st.timestamp_ns == start + round(st.target_ms * 1e6 / 2)  # mid-exposure
        assert st.next_ms == min(2 * st.target_ms, 40.0) and st.ratio == 1.0 and st.valid_fraction == 1.0
        assert st.left is cs.steps["doubler"].left  # one shot per (camera, exposure) and frame
    assert len(calls) == 6 and [c[3] for c in calls] == list(range(6)) and {c[1] for c in calls} == {"left"}


def test_native_rate_provider_refuses_bad_settings():
    shoot, _ = _shoot_log()
    for kw, match in (({"latency_frames": -1}, "latency_frames"), ({"frame_rate_hz": 0.0}, "frame_rate_hz"),
                      ({"n_frames": -2}, "n_frames"), ({"white_level": 0}, "levels")):
        with pytest.raises(PlaybackError, match=match):
            LiveRateProvider(shoot, **{"n_frames": 3, "white_level": 4094, "black_level": 0, **kw})
    provider = LiveRateProvider(lambda *a: np.zeros((4, 4), np.float32), n_frames=1, white_level=4094,
                                black_level=0)
    with pytest.raises(PlaybackError, match="uint16"):
        list(closed_loop(provider, {"doubler": Doubler()}, RunConfig()))


def test_cycle_rate_live_provider_shoots_at_the_selected_brackets_instant(tmp_path):
    root, _ = write_static_sequence(tmp_path / "seq", n_cycles=3, shape=(16, 24))
    seq = load_sequence(root)
    shoot, calls = _shoot_log()
    cfg = RunConfig(initial_ms=4.0, selector="closest")
    live = list(closed_loop(LiveCycleProvider(seq, shoot, cfg), {"doubler": Doubler()}, cfg, want_right=True))
    emulated = list(iter_run(seq, [Doubler()], cfg, emulate_right=True))
    for lc, ec in zip(live, emulated):
        a, b = lc.steps["doubler"], ec.steps["doubler"]
        assert (a.timestamp_ns, a.bracket_ms, a.target_ms) == (b.timestamp_ns, b.bracket_ms, b.target_ms)
    assert {c[1] for c in calls} == {"left", "right"}
    fixed = list(closed_loop(LiveCycleProvider(seq, shoot, cfg, instant="fixed"), {"doubler": Doubler()}, cfg))
    assert [cs.steps["doubler"].timestamp_ns for cs in fixed] == [c.frames["left"][c.available(("left", "right"))[0]]
                                                                  .timestamp_ns for c in seq.cycles]
    with pytest.raises(PlaybackError, match="instant must be one of"):
        LiveCycleProvider(seq, shoot, cfg, instant="now")


def test_emulate_cycle_refuses_a_stereo_pair_of_two_instants(tmp_path):
    root, _ = write_static_sequence(tmp_path / "seq", n_cycles=2, shape=(16, 24))
    seq = load_sequence(root)
    info, images = emulate_cycle(seq, 1, 6.0)
    assert info["cameras"]["left"]["timestamp_ns"] == info["cameras"]["right"]["timestamp_ns"]
    assert set(images) == {"left", "right"} and info["bracket_ms"] in (4.0, 8.0)
    cycle = seq.cycles[1]
    frame = cycle.frames["right"][info["bracket_ms"]]
    cycle.frames["right"][info["bracket_ms"]] = dataclasses.replace(frame, timestamp_ns=frame.timestamp_ns + 1)
    with pytest.raises(DatasetError, match="stereo pair mismatch"):
        emulate_cycle(seq, 1, 6.0)


# ------------------------------------------------------------------ run folders from memory
def test_run_folder_images_encoded_once_per_target_and_summary_from_memory(tmp_path):
    import csv
    import os

    from emulator.io.runfolder import RunWriter, read_tables
    from emulator.report.run import summarise_run
    from emulator.orchestration.runner import run_to_folder

    root, _ = write_static_sequence(tmp_path / "seq", n_cycles=4, shape=(16, 24))
    out = tmp_path / "run"
    summary = run_to_folder(root, "fixed,classical-50,classical-70", out, RunConfig(save="png16", jobs=2),
                            make_report=False)
    assert summary == summarise_run(out)  # the summary from memory is the one the folder gives
    tables = read_tables(out, ["fixed", "classical-50", "classical-70"])
    for name, t in tables.items():
        rows = list(csv.DictReader(open(out / name / "exposures.csv")))
        assert len(rows) == 4 and all((out / name / "images" / cam / f"{r['timestamp_ns']}.png").is_file()
                                      for r in rows for cam in ("left", "right"))
    # cycle 0: every method at the initial exposure shares one encoded image per camera
    ts0 = int(tables["fixed"]["timestamp_ns"][0])
    for cam in ("left", "right"):
        paths = [out / m / "images" / cam / f"{ts0}.png" for m in tables]
        assert len({p.read_bytes() for p in paths}) == 1
        assert len({os.stat(p).st_ino for p in paths}) == 1  # hard links: one encoding
    # times.txt from memory equals the one built from the CSVs
    before = {m: (out / m / "images" / "times.txt").read_bytes() for m in tables}
    with RunWriter(out, resume=True) as w:
        w.save = "png16"
        w.write_times(list(tables))
    assert {m: (out / m / "images" / "times.txt").read_bytes() for m in tables} == before
    info = __import__("json").loads((out / "run.json").read_text())
    timing = info["timing"]
    assert timing["cycles"] == 4 and timing["steady_cycles"] == 3 and timing["startup_s"] > 0
    assert timing["steady_cycles_per_s"] == pytest.approx(3 / (timing["wall_s"] - timing["startup_s"]))


def test_png_level_changes_bytes_not_images():
    import cv2

    from emulator.io.png import encode_png

    rng = np.random.default_rng(0)
    for img in (rng.integers(0, 4095, (30, 40), dtype=np.uint16), rng.integers(0, 256, (30, 40), dtype=np.uint8)):
        stored, packed = encode_png(img, level=0), encode_png(img, level=6)
        assert stored != packed and len(stored) >= img.nbytes  # level 0 stores the rows
        for data in (stored, packed):
            assert np.array_equal(cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED), img)
    with pytest.raises(DatasetError, match="PNG level must be an integer 0..9"):
        encode_png(img, level=-1)


# ------------------------------------------------------------------ the loop's schedule
class _Tick:
    def __init__(self, provider, index, skipped):
        self.provider, self.index, self.skipped, self.missing = provider, index, skipped, {}

    def shot(self, target_ms, want_right=False):
        from emulator.playback.loop import Shot

        p = self.provider
        with p.lock:
            p.shots.append((self.index, p.yielded))
        if self.index == p.bad_tick:
            raise DatasetError(f"tick {self.index}: corrupt image")
        return Shot(timestamp_ns=self.index, exposure_ms=target_ms, bracket_ms=target_ms, ratio=1.0,
                    left=np.full((4, 4), self.index, np.uint16), saturated_fraction=0.0, valid_fraction=1.0,
                    bracket_saturated_fraction=0.0)


class _Provider:
    """Ticks 0..n-1 (``skip`` skipped); logs each shot's tick and how many ticks had been yielded."""

    cameras = ("left",)
    latency_ticks = 0

    def __init__(self, n, skip=(), ahead=2, bad_tick=None):
        import threading

        self.n, self.skip, self.ticks_ahead, self.bad_tick = n, set(skip), ahead, bad_tick
        self.lock = threading.Lock()
        self.shots, self.yielded = [], 0

    def ticks(self):
        for i in range(self.n):
            yield _Tick(self, i, "skipped" if i in self.skip else None)


class _Paced:
    """Proposes ``exposure * factor`` after ``sleep_s``; fails (MethodFailed) or raises at a tick."""

    def __init__(self, factor, sleep_s=0.0, fail_at=None, raise_at=None):
        self.factor, self.sleep_s, self.fail_at, self.raise_at = factor, sleep_s, fail_at, raise_at
        self.name = "paced"

    def reset(self):
        pass

    def next_exposure(self, raw, exposure_ms):
        import time

        time.sleep(self.sleep_s)
        tick = int(raw[0, 0])
        if tick == self.fail_at:
            raise MethodFailed(f"gave up at {tick}")
        if tick == self.raise_at:
            raise KeyError(f"bug at {tick}")
        return exposure_ms * self.factor


def _schedule_run(jobs, ahead=2, bad_tick=None):
    provider = _Provider(12, skip=(4, 5), ahead=ahead, bad_tick=bad_tick)
    methods = {"slow": _Paced(1.1, sleep_s=0.02), "fast": _Paced(0.9), "quits": _Paced(1.2, fail_at=7),
               "buggy": _Paced(1.05, raise_at=10)}
    cycles, error = [], None
    try:
        for cs in closed_loop(provider, methods, RunConfig(initial_ms=4.0, range_ms=(0.5, 40.0), jobs=jobs)):
            cycles.append((cs.cycle, cs.skipped, {n: (st.target_ms, st.next_ms) for n, st in cs.steps.items()},
                           dict(cs.failed)))
            provider.yielded += 1
    except DatasetError as exc:
        error = str(exc)
    return cycles, error, provider


@pytest.mark.parametrize("bad_tick", [None, 9])
def test_methods_run_ahead_of_the_slowest_yet_give_one_jobs_steps_and_errors(bad_tick):
    """With jobs > 1 a method goes on to its next tick without waiting for the slowest (up to the
    provider's ticks_ahead), but ticks are yielded in order with exactly one job's steps, failures
    and, for an exception that is not MethodFailed, the same ticks yielded before it is raised."""
    one, err_one, _ = _schedule_run(1, bad_tick=bad_tick)
    two, err_two, provider = _schedule_run(2, bad_tick=bad_tick)
    assert two == one and err_two == err_one
    assert [c[0] for c in one] == (list(range(12)) if bad_tick is None else list(range(9)))
    assert one[4][1] == one[5][1] == "skipped" and one[7][3] == {"quits": "failed: gave up at 7 at cycle 7"}
    assert "quits" not in one[8][2] and one[3][2]["slow"] == pytest.approx((4.0 * 1.1 ** 3, 4.0 * 1.1 ** 4))
    assert err_one == (None if bad_tick is None else "tick 9: corrupt image")
    if bad_tick is None:  # a method's own exception is its failure (the plugin wrapper), not the run's
        assert set(one[10][3]) == {"buggy"} and "buggy" not in one[11][2]
    # a shot of tick k was taken while k - yielded ticks were still unfinished ahead of it: at most 1 + ahead
    lead = [tick - yielded for tick, yielded in provider.shots]
    assert max(lead) <= 2 and max(lead) >= 1  # the fast methods did run ahead, within the window


def test_a_provider_without_ticks_ahead_keeps_every_tick_a_barrier():
    two, _, provider = _schedule_run(2, ahead=0)
    assert two == _schedule_run(1)[0]
    assert all(tick == yielded for tick, yielded in provider.shots)

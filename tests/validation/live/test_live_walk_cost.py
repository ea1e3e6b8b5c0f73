"""A walk of the live study integrates each shot's radiance once: the live runs advance together and share it."""

from __future__ import annotations

import numpy as np
import pytest

import synth
from emulator.io.borealhdr import load_sequence, sequence_response
from synth.procedural import hdr_chart
from synth.sequence import BASELINE_M, load_camera
from validation.live.config import LiveError
from validation.live.loops import DatasetRadiance, SharedRadiance, iter_live, lockstep

W, H = 48, 32
METHODS = ("fixed", "classical-50", "shim")


class CountingRadiance:
    """An exposure-aware radiance over a static dataset (brighter with the exposure, as a blurred shot is
    not the still frame) that logs every shot it integrates."""

    exposure_aware = True

    def __init__(self, frames) -> None:
        self.frames, self.computed = frames, []

    def __call__(self, timestamp_ns, camera, exposure_ms):
        self.computed.append((int(timestamp_ns), camera, float(exposure_ms)))
        return (self.frames(timestamp_ns, camera) * np.float32(1.0 + 0.01 * exposure_ms)).astype(np.float32)


@pytest.fixture(scope="module")
def static(tmp_path_factory):
    chart = hdr_chart(W, H, seed=3, dynamic_range_db=60.0)
    right = np.eye(4)
    right[0, 3] = BASELINE_M

    def source(t, cam):
        return chart, (np.eye(4) if cam == "left" else right)

    cam = synth.Camera.preset("borealhdr", width=W, height=H)
    path = synth.capture_sequence(source, tmp_path_factory.mktemp("walk_cost") / "static", cam, n_cycles=4, seed=5,
                                  noise=True, save_radiance=True)
    seq = load_sequence(path)
    return seq, load_camera(path), sequence_response(seq), DatasetRadiance(path)


def test_shared_radiance_integrates_a_shot_once_while_it_is_kept():
    rad = CountingRadiance(lambda t, cam: np.full((2, 3, 3), 1.0 if cam == "left" else 2.0, np.float32))
    shared = SharedRadiance(rad, keep=2)
    a = shared(10, "left", 4.0)
    assert shared(10, "left", 4.0) is a and float(a[0, 0, 0]) == pytest.approx(1.04)
    shared(10, "right", 4.0)
    shared(10, "left", 4.5)  # a third shot: the oldest (10, left, 4.0) is dropped
    assert shared(10, "left", 4.0) is not a
    assert rad.computed == [(10, "left", 4.0), (10, "right", 4.0), (10, "left", 4.5), (10, "left", 4.0)]
    assert (shared.hits, shared.misses) == (1, 4)
    with pytest.raises(LiveError, match="exposure-aware"):
        SharedRadiance(lambda t, cam: None)


def test_lockstep_advances_the_loops_in_turn_and_keeps_each_ones_items():
    pulled = []

    def gen(name, n):
        for i in range(n):
            pulled.append((name, i))
            yield f"{name}{i}"

    ticks = []
    got = lockstep([gen("a", 2), gen("b", 3), gen("c", 0)], on_step=lambda: ticks.append(1))
    assert got == [["a0", "a1"], ["b0", "b1", "b2"], []]
    assert pulled == [("a", 0), ("b", 0), ("a", 1), ("b", 1), ("b", 2)]
    assert len(ticks) == 5


def test_lockstep_closes_every_loop_when_one_raises(static):
    """Loops whose methods run in worker processes (the emulated ones) advanced together, one of them
    failing: the others' workers end with it, not when its error is let go (a Dask worker keeps an erred
    task's traceback until the whole batch is done)."""
    import gc

    from emulator.playback.workers import MethodWorker

    seq, cam, resp, frames = static

    def render_fails():
        yield "cycle 0"
        yield "cycle 1"
        raise RuntimeError("render failed")

    def workers_alive():
        gc.collect()
        return [w for w in gc.get_objects() if isinstance(w, MethodWorker) and w._proc.is_alive()]

    assert workers_alive() == []
    held = []
    from validation.live.loops import iter_emulated

    loops = [iter_emulated(seq, list(METHODS), response=resp) for _ in range(2)]
    with pytest.raises(RuntimeError, match="render failed") as err:
        lockstep([render_fails()] + loops)
    held.append(err.value)  # its traceback holds the loops
    assert workers_alive() == []
    assert len(lockstep([iter_emulated(seq, list(METHODS), response=resp)])[0]) == len(seq.cycles)
    assert workers_alive() == []


def _steps(cycles):
    return [(cs.cycle, m, st.timestamp_ns, st.target_ms, st.next_ms, st.left.tobytes(), st.right.tobytes())
            for cs in cycles for m, st in sorted(cs.steps.items())]


def test_live_runs_advanced_together_are_the_runs_alone_with_each_shot_integrated_once(static):
    seq, cam, resp, frames = static
    runs = [("same-instant", 0), ("fixed-instant", 0), ("same-instant", 77), ("fixed-instant", 91)]
    alone, asked = [], []
    for t, s in runs:
        own = CountingRadiance(frames)
        alone.append(_steps(iter_live(seq, own, cam, list(METHODS), timing=t, seed=s, response=resp)))
        asked += own.computed
    rad = CountingRadiance(frames)
    shared = SharedRadiance(rad, keep=2 * len(METHODS) * len(runs))
    together = lockstep([iter_live(seq, shared, cam, list(METHODS), timing=t, seed=s, response=resp) for t, s in runs])
    assert [_steps(c) for c in together] == alone  # the same targets, proposals and image bytes
    # each shot any run asks for is integrated once, and served again to every other run that asks for it
    assert sorted(rad.computed) == sorted(set(asked)) and shared.misses == len(set(asked))
    assert shared.hits == len(asked) - len(set(asked)) >= 2 * 2  # at least the re-seeded runs' cycle 0
    assert alone[0] != alone[2]  # the capture noise differs between seeds


@pytest.mark.parametrize("keep, made_again", [(4, True), (6, False)])
def test_walk_shots_keep_each_sweeps_renderer_for_a_second_pass(monkeypatch, keep, made_again):
    from scenes.walkshots import WalkShots

    shots = WalkShots(None, None, render={}, fps=22.0, n_brackets=6, max_window_ms=32.0, baseline_m=0.2,
                      render_per="cycle", keep=keep)
    made = []
    monkeypatch.setattr(shots, "_make", lambda first, camera, span: made.append((first, camera)) or object())
    for _ in range(2):  # two runs over three sweeps, both cameras
        for index in range(18):
            for camera in ("left", "right"):
                shots.renderer(index, camera)
    first_pass = [(f, c) for f in (0, 6, 12) for c in ("left", "right")]
    assert made == first_pass + (first_pass if made_again else [])
    with pytest.raises(Exception, match="keep must be an integer >= 1"):
        WalkShots(None, None, render={}, fps=22.0, n_brackets=6, max_window_ms=32.0, baseline_m=0.2, keep=0)


def test_a_walk_keeps_one_renderer_per_camera_and_sweep_up_to_a_bound():
    from dataclasses import replace

    from validation.live.config import CONFIGS
    from validation.live.walk_memory import MAX_RENDERERS_KEPT, renderers_kept

    cfg = CONFIGS["full"]
    assert renderers_kept(replace(cfg, n_cycles=8, render_per="cycle")) == 18
    assert renderers_kept(replace(cfg, n_cycles=8, render_per="shot")) == MAX_RENDERERS_KEPT
    assert renderers_kept(replace(cfg, n_cycles=3, render_per="cycle")) == 8


def test_a_walk_keeps_fewer_renderers_of_a_larger_image():
    """The renderers a walk keeps are bounded in memory too: at the recorder's 1920x1200 (16 times the
    study's pixels, about 55 MB a renderer) 64 of them would hold 3.5 GB."""
    from dataclasses import replace

    from scenes.walkshots import KEEP_RENDERERS
    from validation.live.config import CONFIGS
    from validation.live.walk_memory import MAX_RENDERER_BYTES, RENDERER_BYTES_PER_PX, renderers_kept

    cfg = replace(CONFIGS["full"], n_cycles=40, render_per="cycle")
    assert renderers_kept(cfg) == 64  # the study's 480x300: every sweep's, as before
    big = replace(cfg, width=1920, height=1200)
    assert renderers_kept(big) == 9
    assert renderers_kept(big) * RENDERER_BYTES_PER_PX * 1920 * 1200 <= MAX_RENDERER_BYTES
    assert renderers_kept(replace(cfg, width=4096, height=3072)) == KEEP_RENDERERS  # never below the default


def test_the_shots_a_walk_shares_are_bounded_in_memory():
    """One round of the runs advanced together at the study's size (7 methods, 4 cycle-rate runs: 56 shots,
    97 MB); at 1920x1200 (27.6 MB a shot) only what 512 MB holds."""
    from dataclasses import replace

    from validation.live.config import CONFIGS
    from validation.live.walk_memory import MAX_SHARED_SHOT_BYTES, shots_shared

    cfg = CONFIGS["full"]
    assert shots_shared(cfg, 7, 4) == 56 and shots_shared(cfg, 7, 2) == 28
    big = replace(cfg, width=1920, height=1200)
    assert shots_shared(big, 7, 4) == 19
    assert shots_shared(big, 7, 4) * 3 * 4 * 1920 * 1200 <= MAX_SHARED_SHOT_BYTES
    assert shots_shared(replace(cfg, width=16384, height=16384), 7, 4) == 1


def test_run_images_written_fast_read_the_same_and_dropped_after_measuring(static, tmp_path):
    from emulator.io.png import read_image
    from validation.live.experiment import _live_sheets
    from validation.live.loops import drop_run_images, has_run_images, write_run_folder

    seq, cam, resp, frames = static
    cycles = list(iter_live(seq, CountingRadiance(frames), cam, list(METHODS), timing="fixed-instant", response=resp))
    kw = dict(white_level=seq.white_level, black_level=seq.black_level)
    slow = write_run_folder(tmp_path / "runs" / "walk" / "level1", seq.path, cycles, list(METHODS), **kw)
    fast = write_run_folder(tmp_path / "runs" / "walk" / "level0", seq.path, cycles, list(METHODS), png_level=0, **kw)
    pngs = sorted(p.relative_to(slow) for p in slow.glob("*/images/*/*.png"))
    assert len(pngs) == len(METHODS) * len(cycles) * 2
    assert pngs == sorted(p.relative_to(fast) for p in fast.glob("*/images/*/*.png"))
    for rel in pngs:  # the same pixels, stored uncompressed
        assert np.array_equal(read_image(slow / rel), read_image(fast / rel))
        assert (fast / rel).stat().st_size > (slow / rel).stat().st_size
    assert "level0" in _live_sheets(tmp_path, "walk") and has_run_images(fast)
    kept = sorted(p.relative_to(fast) for p in fast.rglob("*") if p.is_file() and p.suffix != ".png")
    assert drop_run_images(fast) == len(pngs) and not has_run_images(fast)
    assert sorted(p.relative_to(fast) for p in fast.rglob("*") if p.is_file()) == kept  # run.json, csv, times.txt
    assert {"run.json", "fixed/exposures.csv", "fixed/images/times.txt"} <= {str(p) for p in kept}
    sheets = _live_sheets(tmp_path, "walk")  # the report's contact sheets leave the dropped run out
    assert "level1" in sheets and "level0" not in sheets
    assert drop_run_images(fast) == 0


def test_a_native_run_folder_has_its_native_columns_in_the_header_as_in_every_row(static, tmp_path):
    """The study's emulated-native runs: each row carries the native columns, so the header names them."""
    import csv
    from dataclasses import replace

    from emulator.io.runcsv import CSV_COLUMNS, EXTRA_COLUMNS, NATIVE_COLUMNS, read_csv_rows
    from emulator.playback.native import NativeInfo
    from validation.live.loops import write_run_folder

    seq, cam, resp, frames = static
    cycles = list(iter_live(seq, CountingRadiance(frames), cam, list(METHODS), timing="fixed-instant", response=resp))
    native = [replace(cs, steps={name: replace(st, native=NativeInfo(k, True, -1, st.timestamp_ns - 45, 0.25))
                                 for name, st in cs.steps.items()}) for k, cs in enumerate(cycles)]
    kw = dict(white_level=seq.white_level, black_level=seq.black_level, png_level=0)
    folder = write_run_folder(tmp_path / "native", seq.path, native, list(METHODS), **kw)
    for name in METHODS:
        with open(folder / name / "exposures.csv", newline="") as fh:
            table = list(csv.reader(fh))
        assert table[0] == list(CSV_COLUMNS + EXTRA_COLUMNS + NATIVE_COLUMNS)
        assert len(table) == len(cycles) + 1 and {len(row) for row in table} == {len(table[0])}
        assert [row[-5:] for row in table[1:]] == [[str(k), "1", "-1", str(cs.steps[name].timestamp_ns - 45), "0.25"]
                                                    for k, cs in enumerate(cycles)]
        assert len(read_csv_rows(folder / name / "exposures.csv")) == len(cycles)
    plain = write_run_folder(tmp_path / "plain", seq.path, cycles, list(METHODS), **kw)
    with open(plain / METHODS[0] / "exposures.csv", newline="") as fh:
        assert next(csv.reader(fh)) == list(CSV_COLUMNS + EXTRA_COLUMNS)
    with pytest.raises(LiveError, match="either all native-rate or none"):
        write_run_folder(tmp_path / "mixed", seq.path, native[:1] + cycles[1:], list(METHODS), **kw)


def test_no_run_images_reaches_every_walk_and_stays_out_of_the_command(tmp_path, monkeypatch):
    import emulator.orchestration.distributed
    from tests.conftest import SynthesizeCalled

    from validation.live.cli import build_parser, command_line, main

    seen = []

    def no_walks(fn, args, **kwargs):
        seen.append([a[-1] for a in args])  # run_walk's keep_run_images
        raise SynthesizeCalled

    monkeypatch.setattr(emulator.orchestration.distributed, "run_tasks", no_walks)
    for flag, keep in ((["--no-run-images"], False), ([], True)):
        with pytest.raises(SynthesizeCalled):
            main(["-o", str(tmp_path / f"out{keep}"), "--quick", "--no-progress", "--scenes", "forest_edge,sun_glare"]
                 + flag)
        assert seen[-1] == [keep, keep]
    args = build_parser().parse_args(["-o", "x", "--no-run-images"])
    assert "--no-run-images" not in command_line(args, "exposim validate live")  # the results do not depend on it


@pytest.mark.render
@pytest.mark.slow
def test_a_walk_that_fails_after_writing_its_runs_leaves_no_run_images(tmp_path, render_cache, monkeypatch):
    """--no-run-images: a walk that fails once its run folders are written (its benchmarks, here) deletes
    their images too (written uncompressed, they would stay until the walk is run again)."""
    import validation.live.walks as walks
    from tests.validation.live.test_validation_live import TINY
    from validation.live.experiment import run_live_experiment

    monkeypatch.setenv("EXPOSIM_DENOISE", "off")

    def disk_full(*args, **kwargs):
        raise OSError("No space left on device")

    monkeypatch.setattr(walks, "_benchmarks", disk_full)
    out = tmp_path / "out"
    with pytest.raises(LiveError, match="forest_winter/seed0: OSError: No space left on device"):
        run_live_experiment(out, TINY, progress=False, cache_dir=render_cache, keep_run_images=False)
    runs = out / "runs" / "forest_winter"
    assert (runs / "live-same-instant" / "classical-50" / "exposures.csv").is_file()  # the walk got that far
    assert sorted(runs.glob("*/*/images/*/*.png")) == []

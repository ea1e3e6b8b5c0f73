"""Live versus emulated closed loop (issue 14): does the offline benchmark judge AE methods as a live camera would?

Run from the repository root::

    python -m validation.live -o OUT [--quick] [--scenes a,b] [--cycles N] [--size WxH] [--seed S]

(``exposim validate live`` once registered).  For every scene (default ``forest_winter``,
``sun_glare``, ``forest_edge``, ``forest_summer``):

1. **Recording**: a stereo bracketed walk (:func:`scenes.synthesize.synthesize`, 1..32 ms
   sweeps at 22 frames/s, the BorealHDR-fitted camera with noise), with every shot's
   radiance kept as OpenEXR (``save_radiance``): the radiance the camera saw at that instant.
2. **Emulated loops**: the normal closed loop (:func:`emulator.playback.iter_run`) of the
   seven AE methods on the recording, with emulation noise ``"none"`` (exact eq. 2, *plain*)
   and ``"consistent"`` (the noise of a capture at the target, from synth's camera through
   :func:`synth.noise_model.noise_model_of`).
3. **Live loops** (:func:`iter_live`): every cycle the camera captures at the method's own
   exposure from the radiance at that instant (:func:`synth.capture`, with noise, seeded),
   and the method reads that capture.  Two timing variants:

   * ``same-instant``: the capture happens at the timestamp of the bracket the emulator
     would use for the live loop's target (the selector run on the recorded brackets), so
     the pose is the one the emulated image comes from: isolates the photometric error;
   * ``fixed-instant``: the capture happens at one fixed instant per cycle, the cycle's
     **first shot** (the 1 ms bracket's timestamp, so no extra render), whatever bracket
     the emulator would use: adds the motion between brackets that real data has (up to
     5 shots, 227 ms).

   A control, ``same-instant-reseeded``, repeats the same-instant live loop with other
   capture-noise seeds: how far two live runs of the same walk disagree.
4. **Comparison** per method, noise option and timing variant: exposure trajectories
   (|log2(emulated_ms / live_ms)| per cycle, cycle 0 excluded since both start at
   ``initial_ms``), left images (RMSE in % of the DN range over the emulation's valid
   pixels, and the valid fraction), then the benchmark metrics of each run
   (:func:`emulator.metrics.bench.bench_features`, :func:`~emulator.metrics.bench.bench_vo`,
   summarised as :func:`validation.ae_study.summarise` does) and the ranking of the methods
   per metric, live vs emulated (Kendall tau-b, :func:`scipy.stats.kendalltau`); the
   paper's findings (:func:`validation.ae_study.evaluate_findings`) evaluated on either side.
5. **Noise variance ratio**: emulated over live capture noise variance, measured from
   repeated captures of one rendered frame, per intensity bin, for plain and consistent
   emulation (:func:`noise_variance_ratio`).

Writes ``OUT/results.json``, ``OUT/report.md``, ``OUT/exposure_<scene>.png`` (trajectories),
``OUT/metrics.png`` (metric bars), and the runs, datasets and benchmark folders beside
them.  An existing ``OUT`` that is not empty is never overwritten: the next free
``OUT-2``, ``OUT-3`` ... is used and named in the output.
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import math
import shlex
import shutil
import sys
import time
from collections.abc import Callable, Iterator, Mapping
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

if __package__ in (None, ""):  # run as a script: make the repository importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from emulator.errors import ExposimError  # noqa: E402

__all__ = [
    "LiveConfig",
    "CONFIGS",
    "SCENES",
    "METHODS",
    "VARIANTS",
    "NOISE_OPTIONS",
    "METRICS",
    "LiveError",
    "DatasetRadiance",
    "iter_live",
    "iter_emulated",
    "write_run_folder",
    "exposure_log2_errors",
    "image_errors",
    "kendall_tau",
    "noise_variance_ratio",
    "run_live_experiment",
    "redraw",
    "numbered_output",
    "main",
]

#: Scenes of the experiment (issue 14: three named ones and one more).
SCENES = ("forest_winter", "sun_glare", "forest_edge", "forest_summer")
#: The seven AE methods (order of ``emulator.playback.parse_methods``).
METHODS = ("fixed", "classical-30", "classical-50", "classical-70", "shim", "zhang", "kim")
#: Timing variants of the live loop.
VARIANTS = ("same-instant", "fixed-instant")
#: The live control run: same-instant with other capture-noise seeds.
CONTROL = "same-instant-reseeded"
#: Emulation noise options: name in results -> ``emulate(noise=...)``.
NOISE_OPTIONS = {"plain": "none", "consistent": "consistent"}
#: (source, target) ms pairs of the brightening noise variance ratio (the source is the noisier one).
BRIGHTENING_PAIRS = ((1.0, 1.5), (2.0, 3.0), (4.0, 6.0), (8.0, 12.0))
#: Bracket (index in the sweep) whose timestamp is the fixed instant of a cycle: the first shot.
FIXED_INSTANT_BRACKET_INDEX = 0
#: Ranked metrics: name -> (key path in ``ae_study.summarise(...)["overall"][method]``, higher is better).
METRICS = {
    "median_uniformity": (("median_uniformity",), True),
    "median_matches": (("median_matches",), True),
    "success_rate_tau100": (("sequence_success_rate", "100"), True),
    "segment_success_rate_tau100": (("segment_success", "100", "rate"), True),
    "vo_failed_frames": (("vo_failed_frames",), False),
    "rpe_trans_pct": (("rpe_trans_pct_mean_over_scenes",), False),
}
#: Goals of issue 14.
GOAL_TAU_MIN = 0.9
GOAL_EXPOSURE_LOG2_MEDIAN = 0.05
#: Seed-sequence tags (live captures, noise-ratio captures).
_LIVE_TAG = 14_001
_RATIO_TAG = 14_002


class LiveError(ExposimError):
    """An invalid configuration of the live-versus-emulated experiment, or missing ground truth."""


@dataclass(frozen=True)
class LiveConfig:
    """Everything that sets the experiment's numbers (recorded in ``results.json``).

    Attributes
    ----------
    scenes : tuple of str
    n_cycles : int
        Bracket sweeps per walk (273 ms each).
    width, height, spp : int
        Render size and samples per pixel.
    seed : int
        Scene, render and camera (recording) seed; the live captures, the control run and
        the consistent emulation derive their seeds from it.
    methods : tuple of str
    initial_ms : float
        Starting exposure of every method and loop, ms.
    selector : str
        Bracket selector of the emulator (and of the same-instant live timing).
    vo_ratio : float
        Lowe ratio of the stereo VO (the AE study's 0.9 at 256x160).
    segment_pairs, taus
        Segment length and match thresholds of the success rates.
    noise_repeats : int
        Captures per exposure for the noise variance ratio.
    capture_noise : bool
        Sensor noise in the recording and the live captures (False: exact, for tests).
    control : bool
        Also run the re-seeded live control.
    metrics : bool
        Run the feature and VO benchmarks (False: exposure and image comparison only).
    keep_radiance : bool
        Keep the datasets' radiance EXRs (large) after the live loops.
    """

    scenes: tuple[str, ...] = SCENES
    n_cycles: int = 40
    width: int = 256
    height: int = 160
    spp: int = 8
    seed: int = 0
    methods: tuple[str, ...] = METHODS
    initial_ms: float = 4.0
    selector: str = "higher-no-sat"
    vo_ratio: float = 0.9
    segment_pairs: int = 10
    taus: tuple[int, ...] = (5, 100)
    noise_repeats: int = 16
    capture_noise: bool = True
    control: bool = True
    metrics: bool = True
    keep_radiance: bool = False

    def __post_init__(self) -> None:
        import scenes

        from emulator.playback import parse_methods
        from emulator.select import SELECTORS

        if not self.scenes:
            raise LiveError("scenes: at least one scene is needed")
        unknown = [s for s in self.scenes if s not in scenes.SCENES]
        if unknown:
            raise LiveError(f"scenes: unknown {unknown}; valid: {', '.join(sorted(scenes.SCENES))}")
        if len(set(self.scenes)) != len(self.scenes):
            raise LiveError(f"scenes: each scene once, got {list(self.scenes)}")
        if self.n_cycles < 3:
            raise LiveError(f"cycles must be >= 3 (matches and VO need pairs), got {self.n_cycles}")
        if self.width < 32 or self.height < 20:
            raise LiveError(f"size must be at least 32x20, got {self.width}x{self.height}")
        if self.spp < 1:
            raise LiveError(f"spp must be >= 1, got {self.spp}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise LiveError(f"seed must be a non-negative integer, got {self.seed!r}")
        try:
            parse_methods(list(self.methods))
        except ExposimError as exc:
            raise LiveError(f"methods: {exc}") from None
        if self.selector not in SELECTORS:
            raise LiveError(f"unknown selector {self.selector!r}; choose one of {', '.join(SELECTORS)}")
        if self.noise_repeats < 3:
            raise LiveError(f"noise_repeats must be >= 3, got {self.noise_repeats}")

    @property
    def duration_s(self) -> float:
        return self.n_cycles * 6 / 22.0

    def scene_parameters(self, scene: str) -> dict:
        """forest_edge: the exit at half the walked path (as the AE study places it)."""
        if scene == "forest_edge":
            from scenes.trajectory import WALKING_SPEED_MPS

            return {"exit_x_m": max(1.0, round(WALKING_SPEED_MPS * self.duration_s * 0.5, 2))}
        return {}

    def to_dict(self) -> dict:
        d = asdict(self)
        d["scenes"], d["methods"], d["taus"] = list(self.scenes), list(self.methods), [int(t) for t in self.taus]
        d["scene_parameters"] = {s: self.scene_parameters(s) for s in self.scenes}
        d["renders"] = self.n_cycles * 12 * len(self.scenes)
        d["fixed_instant"] = "timestamp of the cycle's first shot (bracket index 0, the 1 ms bracket)"
        return d


#: ``full``: 40 cycles (11 s, ~6 m of walk) per scene at the AE study's 256x160, 8 spp;
#: ``quick``: 3 cycles per scene (a pipeline check in a few minutes on 2 cores).
CONFIGS = {
    "full": LiveConfig(),
    "quick": LiveConfig(n_cycles=3, noise_repeats=8),
}


# ============================================================================ radiance
class DatasetRadiance:
    """The radiance each camera saw at each shot of a synthetic recording (its ground truth).

    ``radiance(timestamp_ns, camera)`` reads ``ground_truth/radiance/camera_<camera>/<ts>.exr``
    (written by ``synth.capture_sequence(save_radiance=True)``), keeping the last few.
    """

    def __init__(self, dataset, keep: int = 24) -> None:
        from emulator.io.borealhdr import CAMERA_FOLDERS

        self.root = Path(dataset) / "ground_truth" / "radiance"
        if not self.root.is_dir():
            raise LiveError(f"{self.root}: no radiance ground truth; synthesise the recording with save_radiance=True")
        self._folders = CAMERA_FOLDERS
        self._keep = int(keep)
        self._memo: dict = {}

    def __call__(self, timestamp_ns: int, camera: str) -> np.ndarray:
        from emulator.io.exr import read_exr

        key = (int(timestamp_ns), camera)
        hit = self._memo.get(key)
        if hit is None:
            path = self.root / self._folders[camera] / f"{int(timestamp_ns)}.exr"
            if not path.is_file():
                raise LiveError(f"{path}: no radiance for the {camera} camera at {timestamp_ns} ns")
            hit = read_exr(path)
            self._memo[key] = hit
            while len(self._memo) > self._keep:
                self._memo.pop(next(iter(self._memo)))
        return hit


# ============================================================================ the loops
def _words(x: float) -> list[int]:
    return np.array([float(x)], dtype=np.float64).view(np.uint32).tolist()


def iter_live(
    sequence,
    radiance: Callable[[int, str], np.ndarray],
    camera,
    methods,
    *,
    timing: str = "same-instant",
    response=None,
    initial_ms: float = 4.0,
    range_ms=None,
    selector: str = "higher-no-sat",
    mode: str = "paper",
    noise: bool = True,
    seed: int = 0,
) -> Iterator:
    """The live closed loop: each cycle, each method's camera captures at its own exposure.

    Parameters
    ----------
    sequence : emulator.dataset.Sequence or path
        The bracketed recording of the walk: it gives the cycles, their shot timestamps,
        and (same-instant timing) the brackets the selector looks at.
    radiance : callable(timestamp_ns, camera) -> ndarray
        The radiance each camera saw at a shot's instant (e.g. :class:`DatasetRadiance`).
    camera : synth.Camera
        The recording's camera (``synth.sequence.load_camera``).
    methods : names or AE method instances
        As :func:`emulator.playback.iter_run` takes them (names are built fresh).
    timing : {"same-instant", "fixed-instant"}
        Capture at the timestamp of the bracket the emulator would select for the live
        target, or at the cycle's first shot.
    response, initial_ms, range_ms, selector, mode
        As in :func:`emulator.playback.iter_run` (the response goes to methods that take it).
    noise : bool
        Sensor noise in the live captures.
    seed : int
        Capture noise of camera c at cycle i and exposure t: ``SeedSequence([seed, 14001,
        i, c, bits of t])``; two methods capturing the same exposure at the same instant
        therefore see the same image (as two methods with the same target share one
        emulated image).

    Yields
    ------
    emulator.playback.CycleStep
        With :class:`emulator.playback.MethodStep` per method, images kept
        (``left``/``right``); ``bracket_ms`` is the bracket whose instant was used,
        ``ratio`` 1, ``valid_fraction`` 1.
    """
    import synth
    from emulator.dataset import CAMERAS
    from emulator.io.borealhdr import load_sequence, sequence_response
    from emulator.playback import DEFAULT_RANGE_MS, CycleStep, MethodStep, build_methods
    from emulator.select import saturated_fraction, select

    if timing not in VARIANTS:
        raise LiveError(f"timing must be one of {', '.join(VARIANTS)}, got {timing!r}")
    seq = sequence if hasattr(sequence, "cycles") else load_sequence(sequence)
    if response is None:
        response = sequence_response(seq)
    lo, hi = (float(v) for v in (DEFAULT_RANGE_MS if range_ms is None else range_ms))
    if not 0 < lo <= hi:
        raise LiveError(f"range_ms must satisfy 0 < low <= high, got {range_ms!r}")
    white, black = int(seq.white_level), int(seq.black_level)
    if (camera.white_level, camera.black_level) != (white, black):
        raise LiveError(f"camera levels {camera.black_level}..{camera.white_level} differ from the recording's "
                        f"{black}..{white}")
    built = build_methods(methods, mode=mode, response=response)
    cams = tuple(c for c in CAMERAS if c in seq.cameras)
    targets = {name: float(initial_ms) for name in built}
    for cycle in seq.cycles:
        avail = cycle.available(cams)
        if not avail:
            yield CycleStep(cycle.index, {}, {c: cycle.missing(c) for c in cams}, skipped="no bracket present")
            continue
        raws: dict = {}

        def bracket_raw(e, cycle=cycle, raws=raws):
            if e not in raws:
                raws[e] = cycle.frames[cams[0]][e].load()
            return raws[e]

        first = cycle.frames[cams[0]][avail[FIXED_INSTANT_BRACKET_INDEX]].timestamp_ns
        captures: dict = {}
        steps = {}
        for name, method in built.items():
            target = targets[name]
            if timing == "same-instant":
                sats = {e: (lambda e=e: saturated_fraction(bracket_raw(e), white_level=white, black_level=black))
                        for e in avail}
                key = select(selector, target, sats, white_level=white, black_level=black)
                ts = int(cycle.frames[cams[0]][key].timestamp_ns)
            else:
                key = avail[FIXED_INSTANT_BRACKET_INDEX]
                ts = int(first)
            images = []
            for c, cam in enumerate(cams):
                ck = (ts, cam, target)
                if ck not in captures:
                    rng = np.random.SeedSequence([int(seed), _LIVE_TAG, int(cycle.index), c, *_words(target)])
                    img = synth.capture(radiance(ts, cam), target, camera, seed=rng, noise=noise)
                    img.setflags(write=False)
                    captures[ck] = img
                images.append(captures[ck])
            left = images[0]
            right = images[1] if len(images) > 1 else None
            before = getattr(method, "guard_count", 0)
            proposed = method.next_exposure(left, target)
            guarded = getattr(method, "guard_count", 0) > before
            try:
                proposed = float(proposed)
            except (TypeError, ValueError):
                proposed = math.nan
            nxt = proposed
            if not (math.isfinite(nxt) and nxt > 0):
                guarded, nxt = True, target
            clamped = min(max(nxt, lo), hi)  # the guard and clamp of emulator.playback.iter_run
            sat = saturated_fraction(left, white_level=white, black_level=black)
            sat_r = None if right is None else saturated_fraction(right, white_level=white, black_level=black)
            steps[name] = MethodStep(
                method=name, cycle=cycle.index, timestamp_ns=ts, target_ms=target, bracket_ms=float(key), ratio=1.0,
                saturated_fraction=sat, valid_fraction=1.0, next_ms=clamped, proposed_ms=proposed,
                guarded=bool(guarded), clamped=clamped != nxt, bracket_saturated_fraction=sat,
                saturated_fraction_right=sat_r, valid_fraction_right=None if right is None else 1.0,
                left=left, right=right)
        for name, st in steps.items():
            targets[name] = st.next_ms
        yield CycleStep(cycle.index, steps, {c: cycle.missing(c) for c in cams})


def iter_emulated(sequence, methods, *, noise: str = "none", noise_model=None, seed: int = 0, response=None,
                  initial_ms: float = 4.0, range_ms=None, selector: str = "higher-no-sat", mode: str = "paper"):
    """The normal closed loop (:func:`emulator.playback.iter_run`), both images emulated and kept."""
    from emulator.playback import DEFAULT_RANGE_MS, iter_run

    return iter_run(sequence, methods, initial_ms=initial_ms, range_ms=DEFAULT_RANGE_MS if range_ms is None else
                    range_ms, selector=selector, response=response, mode=mode, emulate_right=True, keep_images=True,
                    noise=noise, noise_model=noise_model, noise_seed=seed)


# ============================================================================ run folders
def write_run_folder(folder, sequence_path, cycles, names, *, white_level: int, black_level: int,
                     description: dict | None = None) -> Path:
    """Write cycles (with images) as a run folder that ``exposim bench features|vo`` read.

    Same layout as :func:`emulator.playback.run_to_folder` with ``save="png16"``:
    ``run.json``, ``<method>/exposures.csv``, ``<method>/images/{left,right}/<ts>.png``,
    ``<method>/images/times.txt``.  Refuses an existing non-empty folder.
    """
    from emulator.io.png import write_png16
    from emulator.errors import OutputExistsError
    from emulator.io.runfolder import CSV_COLUMNS, EXTRA_COLUMNS, format_row

    folder = Path(folder)
    if folder.exists() and any(folder.iterdir()):
        raise OutputExistsError(f"{folder}: run folder exists and is not empty; refusing to overwrite")
    folder.mkdir(parents=True, exist_ok=True)
    for name in names:
        mdir = folder / name
        rows, times = [], []
        for cs in cycles:
            st = cs.steps.get(name)
            if st is None:
                continue
            rows.append(format_row(st))
            times.append((st.timestamp_ns, st.target_ms))
            for cam, img in (("left", st.left), ("right", st.right)):
                if img is not None:
                    write_png16(mdir / "images" / cam / f"{st.timestamp_ns}.png", img, overwrite=False)
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(CSV_COLUMNS + EXTRA_COLUMNS)
        w.writerows(rows)
        (mdir / "exposures.csv").write_text(buf.getvalue())
        (mdir / "images" / "times.txt").write_text(
            "".join(f"{ns} {ns // 1_000_000_000}.{ns % 1_000_000_000:09d} {ms!r}\n" for ns, ms in sorted(times)))
    meta = {"sequence": str(Path(sequence_path).resolve()), "methods": list(names), "save": "png16",
            "white_level": int(white_level), "black_level": int(black_level), "status": "complete",
            **(description or {})}
    (folder / "run.json").write_text(json.dumps(meta, indent=2, default=str) + "\n")
    return folder


# ============================================================================ comparisons
def exposure_log2_errors(emulated, live, names) -> dict[str, np.ndarray]:
    """Per method, ``|log2(emulated_ms / live_ms)|`` of the targets of cycles 1.. (cycle 0 is shared)."""
    out = {}
    for name in names:
        e = {cs.cycle: cs.steps[name].target_ms for cs in emulated if name in cs.steps}
        v = {cs.cycle: cs.steps[name].target_ms for cs in live if name in cs.steps}
        common = sorted(set(e) & set(v))[1:]
        out[name] = np.array([abs(math.log2(e[c] / v[c])) for c in common], dtype=np.float64)
    return out


def image_errors(emulated, live, names, sequence, response) -> dict[str, dict]:
    """Per method: RMSE (% of the DN range) of the emulated vs the live left image of each
    cycle, over the emulation's valid pixels, and the valid fraction."""
    from emulator.emulate import validity_mask

    white, black = int(sequence.white_level), int(sequence.black_level)
    cycles = {c.index: c for c in sequence.cycles}
    live_by = {cs.cycle: cs for cs in live}
    out = {}
    for name in names:
        rmse, valid = [], []
        for cs in emulated:
            st, lv = cs.steps.get(name), live_by.get(cs.cycle)
            if st is None or lv is None or name not in lv.steps or st.left is None:
                continue
            src = cycles[cs.cycle].frames["left"][st.bracket_ms].load()
            mask = validity_mask(src, st.ratio, response)
            valid.append(float(mask.mean()))
            if mask.any():
                d = st.left[mask].astype(np.float64) - lv.steps[name].left[mask].astype(np.float64)
                rmse.append(100.0 * math.sqrt(float(np.mean(d * d))) / (white - black))
        out[name] = {"rmse_percent": np.array(rmse), "valid_fraction": np.array(valid)}
    return out


def kendall_tau(live: Mapping[str, float], emulated: Mapping[str, float]) -> dict:
    """Kendall tau-b of two rankings of the same methods (:func:`scipy.stats.kendalltau`).

    Methods missing on either side are left out.  When every method ties on both sides
    the rankings agree (tau 1); when one side ties every method and the other does not,
    tau-b is undefined (None) and ``note`` says so.  ``discordant`` lists the method pairs
    ordered oppositely; ``tied_on_one_side_only`` counts the pairs tied on one side only (they
    lower tau-b without being discordant).
    """
    from scipy.stats import kendalltau

    names = [m for m in live if m in emulated and live[m] is not None and emulated[m] is not None]
    x = np.array([float(live[m]) for m in names])
    y = np.array([float(emulated[m]) for m in names])
    disc = [(a, b) for i, a in enumerate(names) for b in names[i + 1:]
            if (x[names.index(a)] - x[names.index(b)]) * (y[names.index(a)] - y[names.index(b)]) < 0]
    ties = sum(1 for i in range(len(names)) for j in range(i + 1, len(names))
               if (x[i] == x[j]) != (y[i] == y[j]))
    res = {"n": len(names), "discordant": [list(p) for p in disc], "tied_on_one_side_only": ties, "tau": None,
           "note": None}
    if len(names) < 2:
        res["note"] = "fewer than two methods with a value"
    elif np.ptp(x) == 0 and np.ptp(y) == 0:
        res["tau"], res["note"] = 1.0, "every method ties on both sides"
    elif np.ptp(x) == 0 or np.ptp(y) == 0:
        res["note"] = f"every method ties on the {'live' if np.ptp(x) == 0 else 'emulated'} side only: tau-b undefined"
    else:
        res["tau"] = float(kendalltau(x, y, variant="b").statistic)
    return res


def noise_variance_ratio(radiance: np.ndarray, camera, response, noise_model, *, repeats: int = 16, seed: int = 0,
                         pairs=((32.0, 22.0), (16.0, 11.0), (8.0, 5.5), (4.0, 2.75)), n_bins: int = 16) -> dict:
    """Emulated noise variance over live capture noise variance, per intensity bin (measured).

    For every (source, target) pair (default: target < source, darkening, where the source is
    the cleaner one and consistent emulation can match the noise; brightening pairs measure
    the excess noise it cannot remove, :data:`BRIGHTENING_PAIRS`): ``repeats`` noisy captures at the
    source, each emulated to the target plainly and noise-consistently, against
    ``repeats`` live captures at the target.  Per pixel the temporal variance over the
    repeats (ddof 1); pixels are binned by their noiseless target DN (log-spaced bins
    between 1 % and 90 % of the range, sources unclipped), and per bin the ratio of the
    mean variances.  Returns ``{"plain": median over bins, "consistent": ..., "bins": [...]}``.

    A local measurement (the noise library has the theoretical ratio,
    :func:`emulator.noise.excess_map`; its value per bin is given beside it as ``theory_*``).
    """
    import synth
    from emulator.emulate import emulate

    white, black = camera.white_level, camera.black_level
    rows = []
    for p, (src_ms, tgt_ms) in enumerate(pairs):
        if not (tgt_ms > 0 and src_ms > 0 and tgt_ms != src_ms):
            raise LiveError(f"noise_variance_ratio: need positive, different exposures, got {src_ms}, {tgt_ms}")
        ss = lambda *k: np.random.SeedSequence([int(seed), _RATIO_TAG, p, *k])  # noqa: E731
        src = [synth.capture(radiance, src_ms, camera, seed=ss(0, r)) for r in range(repeats)]
        live = np.stack([synth.capture(radiance, tgt_ms, camera, seed=ss(1, r)) for r in range(repeats)])
        plain = np.stack([emulate(s, src_ms, tgt_ms, response) for s in src])
        cons = np.stack([emulate(s, src_ms, tgt_ms, response, noise="consistent", noise_model=noise_model,
                                 rng=np.random.default_rng(ss(2, r))) for r, s in enumerate(src)])
        theory_plain = np.mean([emulate(s, src_ms, tgt_ms, response, noise_model=noise_model, return_excess=True)[1]
                                for s in src[:2]], axis=0)
        mean_dn = synth.capture(radiance, tgt_ms, camera, seed=None, noise=False).astype(np.float64)
        src_mean = synth.capture(radiance, src_ms, camera, seed=None, noise=False)
        ok = (src_mean > black) & (src_mean < white)
        lo, hi = black + 0.01 * (white - black), black + 0.90 * (white - black)
        edges = np.geomspace(max(lo, 1.0), hi, n_bins + 1)
        v_live = live.astype(np.float64).var(axis=0, ddof=1)
        v_plain = plain.astype(np.float64).var(axis=0, ddof=1)
        v_cons = cons.astype(np.float64).var(axis=0, ddof=1)
        which = np.digitize(mean_dn, edges) - 1
        for b in range(n_bins):
            m = ok & (which == b)
            if np.count_nonzero(m) < 50 or v_live[m].mean() <= 0:
                continue
            rows.append({"source_ms": src_ms, "target_ms": tgt_ms, "dn_lo": float(edges[b]), "dn_hi": float(edges[b + 1]),
                         "pixels": int(np.count_nonzero(m)), "live_var_dn2": float(v_live[m].mean()),
                         "plain": float(v_plain[m].mean() / v_live[m].mean()),
                         "consistent": float(v_cons[m].mean() / v_live[m].mean()),
                         "theory_plain": float(theory_plain[m].mean())})
    if not rows:
        raise LiveError("noise_variance_ratio: no intensity bin with enough unclipped pixels")
    return {"plain": float(np.median([r["plain"] for r in rows])),
            "consistent": float(np.median([r["consistent"] for r in rows])),
            "theory_plain": float(np.median([r["theory_plain"] for r in rows])),
            "consistent_max_abs_deviation": float(max(abs(r["consistent"] - 1.0) for r in rows)),
            "repeats": int(repeats), "pairs_ms": [list(p) for p in pairs], "bins": rows}


# ============================================================================ output folder
def numbered_output(out) -> Path:
    """``out`` if it does not exist or is empty, else the first free ``out-2``, ``out-3`` ... (never overwrite)."""
    out = Path(out)
    if not out.exists() or (out.is_dir() and not any(out.iterdir())):
        return out
    k = 2
    while True:
        cand = out.with_name(f"{out.name}-{k}")
        if not cand.exists():
            return cand
        k += 1


# ============================================================================ experiment
def _bar(total: int, desc: str, enabled: bool):
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, disable=not enabled, file=sys.stderr, leave=False)


def _runs_summary(cycles, names) -> dict:
    out = {}
    for name in names:
        t = [cs.steps[name].target_ms for cs in cycles if name in cs.steps]
        s = [cs.steps[name].saturated_fraction for cs in cycles if name in cs.steps]
        out[name] = {"median_exposure_ms": float(np.median(t)) if t else None,
                     "mean_saturated_fraction": float(np.mean(s)) if s else None}
    return {"methods": out}


def _value(overall: dict, method: str, path: tuple):
    v = overall.get(method)
    for k in path:
        v = v.get(k) if isinstance(v, dict) else None
    return None if v is None or not math.isfinite(float(v)) else float(v)


def _stats(a) -> dict:
    a = np.asarray(a, dtype=np.float64)
    if a.size == 0:
        return {"median": None, "max": None, "mean": None, "n": 0}
    return {"median": float(np.median(a)), "max": float(np.max(a)), "mean": float(np.mean(a)), "n": int(a.size)}


def run_live_experiment(out, config: LiveConfig = CONFIGS["full"], *, progress: bool = True, command: str | None = None,
                        cache_dir=None, log: Callable[[str], None] | None = None) -> dict:
    """Run the experiment into ``out`` (a new or empty folder; see :func:`numbered_output`).

    Returns the content of ``results.json``.
    """
    import scenes
    from emulator.io.borealhdr import load_sequence, sequence_response
    from emulator.errors import OutputExistsError
    from emulator.noise import NoiseModel
    from scenes.synthesize import synthesize
    from synth.noise_model import noise_model_of
    from synth.sequence import load_camera
    from validation import ae_study

    cfg = config
    out = Path(out)
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise OutputExistsError(f"{out}: exists and is not empty; refusing to overwrite (choose another folder)")
    out.mkdir(parents=True, exist_ok=True)
    say = log or (lambda msg: None)
    names = list(cfg.methods)
    t_start = time.perf_counter()
    timings: dict[str, float] = {}
    run_names = [f"emulated-{n}" for n in NOISE_OPTIONS] + [f"live-{v}" for v in VARIANTS]
    if cfg.control:
        run_names.append(f"live-{CONTROL}")
    per_scene: dict = {}
    run_summaries: dict = {r: {} for r in run_names}
    ratio_input = None
    for k, scene_name in enumerate(cfg.scenes):
        tag = f"[{k + 1}/{len(cfg.scenes)}] {scene_name}"
        scene = scenes.get_scene(scene_name, seed=cfg.seed, **cfg.scene_parameters(scene_name))
        ds = out / "datasets" / scene_name
        t0 = time.perf_counter()
        with _bar(cfg.n_cycles * 6, f"{tag}: render + record", progress) as bar:
            synthesize(scene, ds, n_cycles=cfg.n_cycles, width=cfg.width, height=cfg.height, spp=cfg.spp, stereo=True,
                       seed=cfg.seed, render_seed=cfg.seed, noise=cfg.capture_noise, save_radiance=True,
                       cache_dir=cache_dir, progress=lambda d, n: bar.update(d - bar.n))
        timings[f"record_{scene_name}_s"] = time.perf_counter() - t0
        say(f"{tag}: recorded {cfg.n_cycles} cycles in {timings[f'record_{scene_name}_s']:.0f} s")
        seq = load_sequence(ds)
        response = sequence_response(seq)
        camera = load_camera(ds)
        synth_model = noise_model_of(camera)
        model = NoiseModel(response, synth_model.gain_e_per_h, synth_model.read_noise_e, synth_model.name)
        radiance = DatasetRadiance(ds)
        if ratio_input is None:
            first = seq.cycles[0].frames["left"][seq.cycles[0].available(("left",))[0]].timestamp_ns
            ratio_input = (radiance(first, "left"), camera, response, model)
        common = dict(initial_ms=cfg.initial_ms, selector=cfg.selector, response=response)
        cycles: dict = {}
        t0 = time.perf_counter()
        for opt, mode in NOISE_OPTIONS.items():
            with _bar(len(seq.cycles), f"{tag}: emulated loop ({opt})", progress) as bar:
                got = []
                for cs in iter_emulated(seq, names, noise=mode, noise_model=model, seed=cfg.seed, **common):
                    got.append(cs)
                    bar.update(1)
            cycles[f"emulated-{opt}"] = got
        timings[f"emulated_{scene_name}_s"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        live_runs = [(v, v, cfg.seed) for v in VARIANTS]
        if cfg.control:
            live_runs.append((CONTROL, "same-instant", cfg.seed + 1))
        for label, timing, seed in live_runs:
            with _bar(len(seq.cycles), f"{tag}: live loop ({label})", progress) as bar:
                got = []
                for cs in iter_live(seq, radiance, camera, names, timing=timing, noise=cfg.capture_noise, seed=seed,
                                    **common):
                    got.append(cs)
                    bar.update(1)
            cycles[f"live-{label}"] = got
        timings[f"live_{scene_name}_s"] = time.perf_counter() - t0
        # comparisons (images in memory), then the run folders
        comp: dict = {}
        for opt in NOISE_OPTIONS:
            for v in VARIANTS + ((CONTROL,) if cfg.control else ()):
                emu, lv = cycles[f"emulated-{opt}"], cycles[f"live-{v}"]
                err = exposure_log2_errors(emu, lv, names)
                img = image_errors(emu, lv, names, seq, response)
                comp[f"{opt}/{v}"] = {m: {"exposure_log2_error": err[m], **img[m]} for m in names}
        if cfg.control:
            a, b = cycles["live-same-instant"], cycles[f"live-{CONTROL}"]
            err = exposure_log2_errors(a, b, names)
            comp["live/control"] = {m: {"exposure_log2_error": err[m]} for m in names}
        for r in run_names:
            write_run_folder(out / "runs" / scene_name / r, ds, cycles[r], names, white_level=seq.white_level,
                             black_level=seq.black_level, description={"run": r, "scene": scene_name})
            run_summaries[r][scene_name] = _runs_summary(cycles[r], names)
        trajectories = {r: {m: {"timestamp_ns": [cs.steps[m].timestamp_ns for cs in cycles[r] if m in cs.steps],
                                "target_ms": [cs.steps[m].target_ms for cs in cycles[r] if m in cs.steps],
                                "bracket_ms": [cs.steps[m].bracket_ms for cs in cycles[r] if m in cs.steps]}
                            for m in names} for r in run_names}
        per_scene[scene_name] = {"comparison": comp, "trajectories": trajectories}
        del cycles
        if not cfg.keep_radiance:
            shutil.rmtree(ds / "ground_truth" / "radiance", ignore_errors=True)

    t0 = time.perf_counter()
    nvr = noise_variance_ratio(*ratio_input, repeats=cfg.noise_repeats, seed=cfg.seed)
    nvr["input"] = f"first left radiance of {cfg.scenes[0]}"
    nvr_up = noise_variance_ratio(*ratio_input, repeats=cfg.noise_repeats, seed=cfg.seed, pairs=BRIGHTENING_PAIRS)
    nvr_up["input"] = nvr["input"]
    timings["noise_ratio_s"] = time.perf_counter() - t0

    summaries, findings = {}, {}
    if cfg.metrics:
        from emulator.metrics.bench import bench_features, bench_vo
        from emulator.metrics.features import DEFAULT_TAUS
        from emulator.metrics.vo import VOParameters

        study_cfg = ae_study.StudyConfig(scenes=tuple(cfg.scenes), n_cycles=cfg.n_cycles, width=cfg.width,
                                         height=cfg.height, spp=cfg.spp, vo_ratio=cfg.vo_ratio,
                                         segment_pairs=cfg.segment_pairs, taus=tuple(cfg.taus))
        taus = sorted(set(int(t) for t in DEFAULT_TAUS) | set(int(t) for t in cfg.taus))
        params = VOParameters(ratio=cfg.vo_ratio, seed=cfg.seed)
        for r in run_names:
            t0 = time.perf_counter()
            say(f"metrics: {r}")
            feats = bench_features([out / "runs" / s / r for s in cfg.scenes], out / "features" / r, taus=taus,
                                   seed=cfg.seed, progress=progress, command=command)
            vo = {s: bench_vo(out / "runs" / s / r, out / "vo" / s / r, parameters=params, rpe_on_failure=True,
                              progress=progress, command=command) for s in cfg.scenes}
            summaries[r] = ae_study.summarise(study_cfg, feats, vo, run_summaries[r])
            findings[r] = ae_study.evaluate_findings(summaries[r], cfg.taus)
            timings[f"metrics_{r}_s"] = time.perf_counter() - t0

    timings["total_s"] = time.perf_counter() - t_start
    from emulator import __version__

    raw = {"config": cfg.to_dict(), "command": command, "exposim_version": __version__,
           "render_variant": scenes.choose_variant(), "timings": timings, "per_scene": _jsonable(per_scene),
           "summaries": summaries, "findings": findings, "noise_variance_ratio": nvr,
           "noise_variance_ratio_brightening": nvr_up}
    (out / RAW_FILE).write_text(json.dumps(raw, allow_nan=False) + "\n")
    return finish(out, raw)


#: What :func:`redraw` recomputes the verdicts from (per-cycle comparisons, benchmark summaries).
RAW_FILE = "raw.json"


def _brightening_on_chart(dataset: Path, cfg: LiveConfig) -> dict:
    """The brightening noise variance ratio on an HDR chart through the recording's camera."""
    from emulator.io.borealhdr import load_sequence, sequence_response
    from emulator.noise import NoiseModel
    from synth.noise_model import noise_model_of
    from synth.procedural import hdr_chart
    from synth.sequence import load_camera

    camera = load_camera(dataset)
    response = sequence_response(load_sequence(dataset))
    m = noise_model_of(camera)
    model = NoiseModel(response, m.gain_e_per_h, m.read_noise_e, m.name)
    chart = hdr_chart(camera.width, camera.height, seed=cfg.seed, dynamic_range_db=60.0,
                      max_radiance=float(camera.full_well_e / camera.radiance_scale / 2.0))
    res = noise_variance_ratio(chart, camera, response, model, repeats=cfg.noise_repeats, seed=cfg.seed,
                               pairs=BRIGHTENING_PAIRS)
    res["input"] = "hdr_chart (60 dB) through the recording's camera"
    return res


def ratio_use(per_scene: dict, names) -> dict:
    """Per emulated run and method: the fraction of cycles whose emulation darkened (k < 1),
    copied (k = 1) or brightened (k > 1) the bracket (HigherNoSat brightens when the higher
    bracket saturates)."""
    out = {}
    for opt in NOISE_OPTIONS:
        run = f"emulated-{opt}"
        out[opt] = {}
        for m in names:
            k = np.concatenate([np.asarray(per_scene[s]["trajectories"][run][m]["target_ms"], dtype=np.float64)
                                / np.asarray(per_scene[s]["trajectories"][run][m]["bracket_ms"], dtype=np.float64)
                                for s in per_scene])
            n = max(k.size, 1)
            out[opt][m] = {"darkening": float(np.sum(k < 1) / n), "identity": float(np.sum(k == 1) / n),
                           "brightening": float(np.sum(k > 1) / n)}
    return out


def _jsonable(obj):
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    return obj


def _config_from_dict(d: dict) -> LiveConfig:
    from dataclasses import fields

    kw = {f.name: d[f.name] for f in fields(LiveConfig) if f.name in d}
    for k in ("scenes", "methods", "taus"):
        if k in kw:
            kw[k] = tuple(kw[k])
    return LiveConfig(**kw)


def finish(out, raw: dict) -> dict:
    """Verdicts, figures, ``report.md`` and ``results.json`` from the raw record (see :func:`redraw`)."""
    from emulator.io.files import write_results

    out = Path(out)
    cfg = _config_from_dict(raw["config"])
    per_scene = raw["per_scene"]
    for sc in per_scene.values():
        for comp in sc["comparison"].values():
            for m, d in comp.items():
                for k in list(d):
                    d[k] = np.asarray(d[k], dtype=np.float64)
    nvr_up = raw.get("noise_variance_ratio_brightening")
    if nvr_up is None:  # a record from before this measurement: measure it on a chart with the run's camera
        nvr_up = _brightening_on_chart(out / "datasets" / cfg.scenes[0], cfg)
    results = assemble(cfg, per_scene, raw["summaries"], raw["findings"], raw["noise_variance_ratio"],
                       list(cfg.methods))
    results["noise_variance_ratio_brightening"] = {"plain": nvr_up["plain"], "consistent": nvr_up["consistent"]}
    results["noise_variance_ratio_brightening_detail"] = nvr_up
    results["emulation_ratio_use"] = ratio_use(per_scene, list(cfg.methods))
    results.update({
        "experiment": "live versus emulated (issue 14)",
        "exposim_version": raw.get("exposim_version"),
        "command": raw.get("command"),
        "config": cfg.to_dict(),
        "render_variant": raw.get("render_variant"),
        "timings": raw.get("timings", {}),
        "files": {"report": "report.md", "metrics_figure": "metrics.png" if cfg.metrics else None,
                  "exposure_figures": {s: f"exposure_{s}.png" for s in cfg.scenes}, "raw": RAW_FILE,
                  "runs": "runs/<scene>/<run>", "features": "features/<run>", "vo": "vo/<scene>/<run>"},
    })
    for s in cfg.scenes:
        plot_trajectories(per_scene[s]["trajectories"], out / f"exposure_{s}.png", title=s)
    if cfg.metrics:
        plot_metrics(results, out / "metrics.png")
    (out / "report.md").write_text(report_markdown(results))
    write_results(out / "results.json", results)
    return results


def redraw(out) -> dict:
    """Recompute the verdicts and rewrite ``results.json``, ``report.md`` and the figures of an
    experiment folder from its ``raw.json`` (nothing is rendered, played back or measured again)."""
    path = Path(out) / RAW_FILE
    if not path.is_file():
        raise LiveError(f"{path}: not found; not a finished live experiment folder")
    return finish(out, json.loads(path.read_text()))


# ============================================================================ verdicts
def assemble(cfg: LiveConfig, per_scene: dict, summaries: dict, findings: dict, nvr: dict, names) -> dict:
    """results.json's numbers from the per-scene comparisons and the per-run benchmark summaries."""
    variants = VARIANTS + ((CONTROL,) if cfg.control else ())
    exposure, images = {}, {}
    for opt in NOISE_OPTIONS:
        for v in variants:
            key = f"{opt}/{v}"
            per_method = {}
            pooled_e, pooled_r, pooled_v = [], [], []
            for m in names:
                e = np.concatenate([per_scene[s]["comparison"][key][m]["exposure_log2_error"] for s in per_scene])
                r = np.concatenate([per_scene[s]["comparison"][key][m]["rmse_percent"] for s in per_scene])
                val = np.concatenate([per_scene[s]["comparison"][key][m]["valid_fraction"] for s in per_scene])
                per_method[m] = {"exposure_log2_error": _stats(e), "image_rmse_percent": _stats(r),
                                 "valid_fraction_mean": float(val.mean()) if val.size else None,
                                 "per_scene_exposure_log2_error_median": {
                                     s: _stats(per_scene[s]["comparison"][key][m]["exposure_log2_error"])["median"]
                                     for s in per_scene}}
                pooled_e.append(e)
                pooled_r.append(r)
                pooled_v.append(val)
            e, r, val = np.concatenate(pooled_e), np.concatenate(pooled_r), np.concatenate(pooled_v)
            exposure[key] = {"pooled": _stats(e), "methods": {m: per_method[m]["exposure_log2_error"] for m in names}}
            images[key] = {"pooled": _stats(r), "valid_fraction_mean": float(val.mean()) if val.size else None,
                           "methods": per_method}
    control_exposure = None
    if cfg.control:
        ce = np.concatenate([per_scene[s]["comparison"]["live/control"][m]["exposure_log2_error"]
                             for s in per_scene for m in names])
        control_exposure = _stats(ce)

    values, taus, flips = {}, {}, {}
    if summaries:
        for r, summ in summaries.items():
            values[r] = {metric: {m: _value(summ["overall"], m, path) for m in names}
                         for metric, (path, _) in METRICS.items()}
        for opt in NOISE_OPTIONS:
            for v in variants:
                taus[f"{opt}/{v}"] = {metric: kendall_tau(values[f"live-{v}"][metric], values[f"emulated-{opt}"][metric])
                                      for metric in METRICS}
        if cfg.control:
            taus["live/control"] = {metric: kendall_tau(values["live-same-instant"][metric],
                                                        values[f"live-{CONTROL}"][metric]) for metric in METRICS}
        for opt in NOISE_OPTIONS:
            for v in variants:
                live_f = {f["id"]: f["holds"] for f in findings[f"live-{v}"]}
                emu_f = {f["id"]: f["holds"] for f in findings[f"emulated-{opt}"]}
                flips[f"{opt}/{v}"] = [{"id": fid, "live": live_f[fid], "emulated": emu_f.get(fid)}
                                       for fid in live_f if emu_f.get(fid) != live_f[fid]]

    def worst(opt):
        out = {}
        for metric in METRICS:
            vals = [taus[f"{opt}/{v}"][metric]["tau"] for v in VARIANTS]
            vals = [t for t in vals if t is not None]
            out[metric] = min(vals) if vals else None
        return out

    tau_by_noise = {opt: worst(opt) for opt in NOISE_OPTIONS} if taus else {}
    tau_min_by_noise = {opt: (min([t for t in d.values() if t is not None], default=None)) for opt, d in
                        tau_by_noise.items()}
    if tau_min_by_noise:
        best = max(NOISE_OPTIONS, key=lambda o: (-math.inf if tau_min_by_noise[o] is None else tau_min_by_noise[o],
                                                 o == "plain"))
    else:
        best = min(NOISE_OPTIONS, key=lambda o: exposure[f"{o}/same-instant"]["pooled"]["median"] or 0.0)
    same = exposure[f"{best}/same-instant"]["pooled"]
    worst_max = max((exposure[f"{best}/{v}"]["pooled"]["max"] or 0.0) for v in VARIANTS)
    results = {
        "headline_noise": best,
        "exposure_log2_error_median": same["median"],
        "exposure_log2_error_max": same["max"],
        "image_rmse_percent_median": images[f"{best}/same-instant"]["pooled"]["median"],
        "rank_kendall_tau": tau_by_noise.get(best, {}),
        "rank_kendall_tau_min": tau_min_by_noise.get(best),
        "noise_variance_ratio": {"plain": nvr["plain"], "consistent": nvr["consistent"]},
        "headline_definitions": {
            "headline_noise": "the emulation noise option with the larger rank_kendall_tau_min (plain on a tie)",
            "exposure_log2_error_median": "same-instant live vs emulated (headline noise), |log2(emulated_ms / "
                                          "live_ms)| pooled over scenes, methods and cycles 1..",
            "exposure_log2_error_max": "the same, maximum",
            "image_rmse_percent_median": "same-instant, left images, emulation's valid pixels, % of the DN range",
            "rank_kendall_tau": "per metric, Kendall tau-b of the methods' values live vs emulated, worst of the "
                                "two timing variants (headline noise)",
            "rank_kendall_tau_min": "minimum over the metrics of rank_kendall_tau (undefined taus left out)",
            "noise_variance_ratio": "median over intensity bins of emulated / live capture noise variance, "
                                    "darkening pairs (source cleaner than target), measured",
        },
        "goals": {
            "rank_kendall_tau_min_ge_0.9": None if tau_min_by_noise.get(best) is None
            else tau_min_by_noise[best] >= GOAL_TAU_MIN,
            "exposure_log2_error_median_le_0.05_same_instant": same["median"] is not None
            and same["median"] <= GOAL_EXPOSURE_LOG2_MEDIAN,
            "noise_variance_ratio_consistent_within_10pct": abs(nvr["consistent"] - 1.0) <= 0.1,
        },
        "rank_kendall_tau_by_noise": tau_by_noise,
        "rank_kendall_tau_min_by_noise": tau_min_by_noise,
        "rank_kendall_tau_detail": taus,
        "exposure_worst_variant_max": worst_max,
        "exposure": exposure,
        "exposure_live_control": control_exposure,
        "images": images,
        "metric_values": values,
        "findings_flips": flips,
        "findings": {r: [{k: f[k] for k in ("id", "claim", "holds", "detail")} for f in fl]
                     for r, fl in findings.items()},
        "noise_variance_ratio_detail": nvr,
    }
    results["live_spread"] = live_spread(values) if values else {}
    rows = flip_causes(results, names) if taus else []
    results["flip_causes"] = rows
    results["flip_cause_counts"] = flip_cause_counts(rows)
    for key, per_metric in taus.items():
        for metric, res in per_metric.items():
            res["discordant_beyond_live_spread"] = sum(
                1 for r in rows if f"{r['noise']}/{r['variant']}" == key and r["metric"] == metric
                and r["cause"] != FLIP_CAUSES[0])
    return results


def live_spread(values: dict) -> dict:
    """Per metric, the largest |same-instant - re-seeded control| over the methods: how far two live
    runs of the same walk that differ only in capture noise put one method (None without control)."""
    a, b = values.get("live-same-instant"), values.get(f"live-{CONTROL}")
    if a is None or b is None:
        return {}
    out = {}
    for metric in a:
        d = [abs(a[metric][m] - b[metric][m]) for m in a[metric]
             if a[metric][m] is not None and b[metric].get(m) is not None]
        out[metric] = max(d) if d else None
    return out


#: Causes of a ranking flip, in the order they are tested (:func:`flip_causes`).
FLIP_CAUSES = ("within live spread", "motion", "noise level", "exposure divergence (closed loop, selector)",
               "image difference at equal exposures (noise realisation, quantisation)")


def flip_causes(results: dict, names) -> list[dict]:
    """Why each discordant pair of methods (per metric) flips, with the numbers.

    Per noise option, timing variant and metric, a pair ordered oppositely live and
    emulated is attributed to the first that applies:

    1. ``within live spread``: both differences (live a - b, emulated a - b) are at most
       the metric's live spread (:func:`live_spread`): two live runs differing only in
       capture noise disagree by as much, so the metric cannot order the pair;
    2. ``motion``: the pair flips in ``fixed-instant`` but not in ``same-instant``;
    3. ``noise level``: it flips with plain emulation but not with consistent;
    4. ``exposure divergence``: one of the two methods' exposure trajectories differ by a
       median |log2| above the goal (0.05): the closed loops went apart (the selector's
       bracket, the method's sensitivity to small image differences);
    5. ``image difference at equal exposures``: otherwise (the loops chose the same
       exposures; the images differ by the source's noise realisation and quantisation).
    """
    detail = results["rank_kendall_tau_detail"]
    values = results["metric_values"]
    spread = results.get("live_spread") or {}
    rows = []
    for key, per_metric in detail.items():
        opt, variant = key.split("/")
        if variant not in VARIANTS:
            continue
        live_key = f"live-{variant}"
        other_opt = "consistent" if opt == "plain" else "plain"
        exp = results["exposure"][key]["methods"]
        for metric, res in per_metric.items():
            for a, b in res["discordant"]:
                pair = [a, b]
                lv = {m: values[live_key][metric][m] for m in pair}
                ev = {m: values[f"emulated-{opt}"][metric][m] for m in pair}
                d_live, d_emu = abs(lv[a] - lv[b]), abs(ev[a] - ev[b])
                sp = spread.get(metric)
                if sp is not None and max(d_live, d_emu) <= sp:
                    cause = FLIP_CAUSES[0]
                elif variant == "fixed-instant" and pair not in detail[f"{opt}/same-instant"][metric]["discordant"]:
                    cause = FLIP_CAUSES[1]
                elif opt == "plain" and pair not in detail[f"{other_opt}/{variant}"][metric]["discordant"]:
                    cause = FLIP_CAUSES[2]
                elif max((exp[m]["median"] or 0.0) for m in pair) > GOAL_EXPOSURE_LOG2_MEDIAN:
                    cause = FLIP_CAUSES[3]
                else:
                    cause = FLIP_CAUSES[4]
                rows.append({
                    "noise": opt, "variant": variant, "metric": metric, "pair": pair, "cause": cause,
                    "live": lv, "emulated": ev, "live_difference": d_live, "emulated_difference": d_emu,
                    "live_spread": sp,
                    "exposure_log2_error_median": {m: exp[m]["median"] for m in pair},
                })
    return rows


def flip_cause_counts(rows: list[dict]) -> dict:
    """Counts of :func:`flip_causes` rows per ``noise/variant`` and cause."""
    out: dict = {}
    for r in rows:
        d = out.setdefault(f"{r['noise']}/{r['variant']}", {c: 0 for c in FLIP_CAUSES})
        d[r["cause"]] += 1
    return out


# ============================================================================ figures, report
def plot_trajectories(trajectories: dict, path: Path, title: str = "") -> Path:
    """Exposure against cycle per method: emulated (plain, consistent) and live (variants)."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    runs = list(trajectories)
    names = list(next(iter(trajectories.values())))
    ncols = 4
    nrows = math.ceil(len(names) / ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(4 * ncols, 3 * nrows), dpi=90, squeeze=False, sharex=True)
    styles = {"emulated-plain": ("C0", "-", "o"), "emulated-consistent": ("C1", "--", "s"),
              "live-same-instant": ("k", "-", "."), "live-fixed-instant": ("C2", ":", "x"),
              f"live-{CONTROL}": ("0.6", "-.", "")}
    for ax, name in zip(axes.ravel(), names):
        for r in runs:
            y = trajectories[r][name]["target_ms"]
            c, ls, mk = styles.get(r, ("C3", "-", ""))
            ax.step(range(len(y)), y, where="post", color=c, ls=ls, marker=mk, ms=3, lw=1.1, label=r)
        for b in (1, 2, 4, 8, 16, 32):
            ax.axhline(b, color="0.9", lw=0.6, zorder=0)
        ax.set_yscale("log")
        ax.set_title(name, fontsize=9)
        ax.set_xlabel("cycle")
        ax.set_ylabel("exposure [ms]")
    for ax in axes.ravel()[len(names):]:
        ax.axis("off")
    axes.ravel()[0].legend(fontsize=6)
    fig.suptitle(f"Exposure per cycle, live vs emulated: {title}")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def plot_metrics(results: dict, path: Path) -> Path:
    """Per metric, bars per method: live (variants) and emulated (plain, consistent)."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    values = results["metric_values"]
    runs = list(values)
    metrics = list(METRICS)
    names = results["config"]["methods"]
    fig, axes = plt.subplots(2, math.ceil(len(metrics) / 2), figsize=(16, 7), dpi=90, squeeze=False)
    w = 0.8 / len(runs)
    for ax, metric in zip(axes.ravel(), metrics):
        for i, r in enumerate(runs):
            ys = [values[r][metric].get(m) for m in names]
            ax.bar(np.arange(len(names)) + (i - (len(runs) - 1) / 2) * w, [np.nan if y is None else y for y in ys],
                   w, label=r)
        tau = results["rank_kendall_tau"].get(metric)
        ax.set_title(f"{metric} (tau {'n/a' if tau is None else f'{tau:.2f}'})", fontsize=9)
        ax.set_xticks(range(len(names)))
        ax.set_xticklabels(names, rotation=45, fontsize=7)
    for ax in axes.ravel()[len(metrics):]:
        ax.axis("off")
    axes.ravel()[0].legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def _f(v, spec=".3g") -> str:
    if v is None:
        return "n/a"
    if isinstance(v, bool):
        return "yes" if v else "no"
    return format(float(v), spec)


def report_markdown(results: dict) -> str:
    """The report: verdict in words, generated from the numbers."""
    cfg = results["config"]
    best = results["headline_noise"]
    goals = results["goals"]
    lines = [
        "# Live versus emulated closed loop (issue 14)",
        "",
        f"{len(cfg['scenes'])} synthetic stereo walks ({', '.join(cfg['scenes'])}), {cfg['n_cycles']} cycles each, "
        f"{cfg['width']}x{cfg['height']} px at {cfg['spp']} spp, seven AE methods, seed {cfg['seed']}. "
        f"Fixed instant of the fixed-instant variant: {cfg['fixed_instant']}.",
        f"Command: `{results.get('command')}`",
        "",
        "## Verdict",
        "",
    ]
    tau_min = results["rank_kendall_tau_min"]
    tmb = results["rank_kendall_tau_min_by_noise"]
    verdict = []
    if tau_min is not None:
        verdict.append(
            f"The emulated benchmark ranks the methods as the live camera does with Kendall tau >= {_f(tau_min, '.2f')} "
            f"on every metric (worst timing variant, {best} emulation; plain {_f(tmb.get('plain'), '.2f')}, consistent "
            f"{_f(tmb.get('consistent'), '.2f')}). Goal tau_min >= {GOAL_TAU_MIN}: "
            f"{'met' if goals['rank_kendall_tau_min_ge_0.9'] else 'NOT met'}.")
    verdict.append(
        f"Same-instant exposure trajectories differ by a median |log2| of {_f(results['exposure_log2_error_median'])} "
        f"(max {_f(results['exposure_log2_error_max'])}); goal <= {GOAL_EXPOSURE_LOG2_MEDIAN}: "
        f"{'met' if goals['exposure_log2_error_median_le_0.05_same_instant'] else 'NOT met'}.")
    detail = results["rank_kendall_tau_detail"]
    if "live/control" in detail:
        ctl = {m: detail["live/control"][m]["tau"] for m in METRICS}
        for v in VARIANTS:
            emu = {m: detail[f"{best}/{v}"][m]["tau"] for m in METRICS}
            ok = [m for m in METRICS if emu[m] is not None and ctl[m] is not None and emu[m] >= ctl[m] - 1e-12]
            below = [f"{m} ({_f(emu[m], '.3f')} vs {_f(ctl[m], '.3f')})" for m in METRICS
                     if emu[m] is not None and ctl[m] is not None and emu[m] < ctl[m] - 1e-12]
            verdict.append(
                f"{v.capitalize()}: emulated vs live agrees at least as well as two live runs that differ only in "
                f"capture noise (tau of the control) on {len(ok)} of {len(METRICS)} metrics"
                + (f"; below the control on {', '.join(below)}." if below else "."))
    ctrl = results.get("exposure_live_control")
    if ctrl:
        verdict.append(f"Two live runs that differ only in their capture-noise seeds differ by a median |log2| of "
                       f"{_f(ctrl['median'])} (max {_f(ctrl['max'])}): the floor any emulator is measured against.")
    nvr = results["noise_variance_ratio"]
    verdict.append(f"Noise variance emulated / live (darkening pairs, median over intensity bins): plain "
                   f"{_f(nvr['plain'])}, consistent {_f(nvr['consistent'])}.")
    use, up = results.get("emulation_ratio_use"), results.get("noise_variance_ratio_brightening")
    if use and up:
        dark = float(np.mean([d["darkening"] for d in use[best].values()]))
        bright = float(np.mean([d["brightening"] for d in use[best].values()]))
        verdict.append(
            f"But the loops darken a bracket (the only case consistent emulation can correct) in "
            f"{_f(100 * dark, '.0f')} % of the cycles (mean over methods) and brighten one in {_f(100 * bright, '.0f')} %, "
            f"because HigherNoSat's higher bracket is saturated above 1 %; brightened images carry "
            f"{_f(up['plain'], '.2f')} times the live noise variance, with either option.")
    lines += [" ".join(verdict), ""]
    if results["rank_kendall_tau_detail"]:
        lines += ["## Ranking agreement (Kendall tau-b, live vs emulated)", "",
                  "| metric | " + " | ".join(results["rank_kendall_tau_detail"]) + " |",
                  "| --- | " + " | ".join("---:" for _ in results["rank_kendall_tau_detail"]) + " |"]
        for metric in METRICS:
            cells = []
            for key, d in results["rank_kendall_tau_detail"].items():
                r = d[metric]
                extra = ""
                if r["discordant"]:
                    extra = f" ({len(r['discordant'])} disc."
                    if "discordant_beyond_live_spread" in r and key != "live/control":
                        extra += f", {r['discordant_beyond_live_spread']} beyond spread"
                    extra += ")"
                if r.get("tied_on_one_side_only"):
                    extra += f" [{r['tied_on_one_side_only']} tied one side]"
                cells.append(_f(r["tau"], ".2f") + extra)
            lines.append(f"| {metric} | " + " | ".join(cells) + " |")
        lines += ["", "`live/control`: two live same-instant runs with different capture-noise seeds.", ""]
        lines += ["## Metric values", "", "| metric | method | " + " | ".join(results["metric_values"]) + " |",
                  "| --- | --- | " + " | ".join("---:" for _ in results["metric_values"]) + " |"]
        for metric in METRICS:
            for m in cfg["methods"]:
                lines.append(f"| {metric} | {m} | " + " | ".join(_f(results["metric_values"][r][metric][m])
                                                                  for r in results["metric_values"]) + " |")
        lines += ["", "![metric bars](metrics.png)", ""]
    lines += ["## Exposure trajectories", "",
              "| noise / variant | median abs log2 | max | image RMSE % median | valid fraction |",
              "| --- | ---: | ---: | ---: | ---: |"]
    for key, e in results["exposure"].items():
        im = results["images"][key]
        lines.append(f"| {key} | {_f(e['pooled']['median'])} | {_f(e['pooled']['max'])} | "
                     f"{_f(im['pooled']['median'])} | {_f(im['valid_fraction_mean'])} |")
    lines += ["", "| method | " + " | ".join(f"{k} median" for k in results["exposure"]) + " |",
              "| --- | " + " | ".join("---:" for _ in results["exposure"]) + " |"]
    for m in cfg["methods"]:
        lines.append(f"| {m} | " + " | ".join(_f(results["exposure"][k]["methods"][m]["median"])
                                             for k in results["exposure"]) + " |")
    lines += [""] + [f"![{s}](exposure_{s}.png)" for s in cfg["scenes"]] + [""]
    if results["findings_flips"]:
        lines += ["## Paper findings that flip (live vs emulated)", ""]
        for key, fl in results["findings_flips"].items():
            txt = "; ".join(f"{f['id']} (live {_f(f['live'])}, emulated {_f(f['emulated'])})" for f in fl) or "none"
            lines.append(f"- {key}: {txt}")
        lines.append("")
    if results["flip_causes"]:
        sp = results.get("live_spread") or {}
        lines += ["## Why rankings flip", "",
                  "Each pair of methods ordered oppositely live and emulated, attributed to the first cause that "
                  "applies (`flip_causes` in validation/live.py): within the live spread (both differences at most "
                  "the largest |live - live re-seeded| of the metric over the methods: "
                  + ", ".join(f"{m} {_f(v)}" for m, v in sp.items()) + "), motion (fixed-instant only), noise level "
                  "(plain only), exposure divergence (median |log2| > 0.05), else image difference at equal exposures.",
                  "", "| noise / variant | " + " | ".join(FLIP_CAUSES) + " |",
                  "| --- | " + " | ".join("---:" for _ in FLIP_CAUSES) + " |"]
        for key, counts in results["flip_cause_counts"].items():
            lines.append(f"| {key} | " + " | ".join(str(counts[c]) for c in FLIP_CAUSES) + " |")
        beyond = [r for r in results["flip_causes"] if r["noise"] == best and r["cause"] != FLIP_CAUSES[0]]
        lines += ["", f"Flips beyond the live spread ({best} emulation):", ""]
        if beyond:
            lines += ["| variant | metric | pair | cause | live | emulated | live spread | exposure log2 err median |",
                      "| --- | --- | --- | --- | --- | --- | ---: | --- |"]
            for r in beyond[:60]:
                a, b = r["pair"]
                lines.append(
                    f"| {r['variant']} | {r['metric']} | {a} vs {b} | {r['cause']} | {_f(r['live'][a])} vs "
                    f"{_f(r['live'][b])} | {_f(r['emulated'][a])} vs {_f(r['emulated'][b])} | {_f(r['live_spread'])} | "
                    f"{_f(r['exposure_log2_error_median'][a])}, {_f(r['exposure_log2_error_median'][b])} |")
            if len(beyond) > 60:
                lines.append(f"| ... {len(beyond) - 60} more in results.json | | | | | | | |")
        else:
            lines.append("none.")
        lines.append("")
    nd = results["noise_variance_ratio_detail"]
    lines += ["## Noise variance ratio (measured)", "",
              f"{nd['repeats']} captures per exposure of one rendered frame, pairs (source ms, target ms) "
              f"{nd['pairs_ms']}; per intensity bin emulated / live variance. Plain {_f(nd['plain'])} (theory "
              f"{_f(nd['theory_plain'])}), consistent {_f(nd['consistent'])} (largest deviation from 1 in a bin: "
              f"{_f(nd['consistent_max_abs_deviation'])}).", ""]
    up = results.get("noise_variance_ratio_brightening_detail")
    if up:
        lines += [f"Brightening pairs {up['pairs_ms']} (the source is the noisier one; {up['input']}): plain "
                  f"{_f(up['plain'])}, consistent {_f(up['consistent'])} (theory {_f(up['theory_plain'])}): the "
                  "excess noise that no emulation can remove.", ""]
    use = results.get("emulation_ratio_use")
    if use:
        lines += ["How often the emulated loop darkened (k < 1, where consistent emulation adds noise), copied "
                  "(k = 1) or brightened (k > 1, excess noise) its bracket:", "",
                  "| method | darkening | identity | brightening |", "| --- | ---: | ---: | ---: |"]
        for m, d in use[best].items():
            lines.append(f"| {m} | {_f(d['darkening'], '.2f')} | {_f(d['identity'], '.2f')} | "
                         f"{_f(d['brightening'], '.2f')} |")
        lines.append("")
    t = results.get("timings", {})
    lines += [f"Total time {_f(t.get('total_s', 0) / 60, '.1f')} min."]
    return "\n".join(lines) + "\n"


# ============================================================================ CLI
def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WxH, e.g. 256x160, got {text!r}") from None
    return w, h


def build_parser(prog: str = "python -m validation.live") -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=prog, description=__doc__.split("\n\n")[0])
    p.add_argument("-o", "--output", type=Path, required=True,
                   help="output folder (a non-empty one is never overwritten: OUT-2, OUT-3 ... is used)")
    p.add_argument("--quick", action="store_true", help="3 cycles per scene (a pipeline check, a few minutes)")
    p.add_argument("--scenes", help=f"comma-separated scenes (default {','.join(SCENES)})")
    p.add_argument("--cycles", type=int, help="bracket cycles per scene (full default 40)")
    p.add_argument("--size", type=_size, help="image size WxH (default 256x160)")
    p.add_argument("--spp", type=int, help="render samples per pixel (default 8)")
    p.add_argument("--seed", type=int, help="scene, render, camera and live-capture seed (default 0)")
    p.add_argument("--methods", help="comma-separated AE methods (default all seven)")
    p.add_argument("--no-control", action="store_true", help="skip the re-seeded live control run")
    p.add_argument("--keep-radiance", action="store_true", help="keep the datasets' radiance EXRs")
    p.add_argument("--cache-dir", help="render cache (default $EXPOSIM_CACHE or ~/.cache/exposim/renders)")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.add_argument("--redraw", action="store_true",
                   help="only recompute the verdicts and rewrite results.json, report.md and the figures of the "
                        "existing folder OUT from its raw.json")
    return p


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    cfg = CONFIGS["quick" if args.quick else "full"]
    changes = {}
    if args.cycles is not None:
        changes["n_cycles"] = args.cycles
    if args.size is not None:
        changes["width"], changes["height"] = args.size
    if args.spp is not None:
        changes["spp"] = args.spp
    if args.seed is not None:
        changes["seed"] = args.seed
    if args.scenes:
        changes["scenes"] = tuple(s.strip() for s in args.scenes.split(",") if s.strip())
    if args.methods:
        changes["methods"] = tuple(s.strip() for s in args.methods.split(",") if s.strip())
    if args.no_control:
        changes["control"] = False
    if args.keep_radiance:
        changes["keep_radiance"] = True
    command = "python -m validation.live " + " ".join(
        shlex.quote(a) for a in (sys.argv[1:] if argv is None else argv))
    out = numbered_output(args.output)

    def log(msg: str) -> None:
        print(msg, file=sys.stderr)

    if args.redraw:
        out = args.output
    try:
        if args.redraw:
            results = redraw(out)
            print(_headline(results))
            return 0
        cfg = replace(cfg, **changes)
        if out != args.output:
            log(f"live: {args.output} exists and is not empty; writing to {out}")
        results = run_live_experiment(out, cfg, progress=not args.no_progress, command=command,
                                      cache_dir=args.cache_dir, log=log if not args.no_progress else None)
    except ExposimError as exc:
        print(f"live: {exc}", file=sys.stderr)
        return 1
    print(_headline(results))
    print(f"wrote {out / 'results.json'}, {out / 'report.md'} in {results['timings']['total_s'] / 60:.1f} min")
    return 0


def _headline(results: dict) -> str:
    g = results["goals"]
    return (f"rank_kendall_tau_min {_f(results['rank_kendall_tau_min'], '.3f')} ({results['headline_noise']}; goal "
          f">= {GOAL_TAU_MIN}: {_f(g['rank_kendall_tau_min_ge_0.9'])}), exposure_log2_error_median "
          f"{_f(results['exposure_log2_error_median'], '.4f')} (goal <= {GOAL_EXPOSURE_LOG2_MEDIAN}: "
          f"{_f(g['exposure_log2_error_median_le_0.05_same_instant'])}), noise_variance_ratio plain "
          f"{_f(results['noise_variance_ratio']['plain'], '.3f')} consistent "
          f"{_f(results['noise_variance_ratio']['consistent'], '.3f')}")


if __name__ == "__main__":
    sys.exit(main())

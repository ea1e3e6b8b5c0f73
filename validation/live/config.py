"""The experiment's configuration: scenes, methods, variants, metrics, goals and :class:`LiveConfig`."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, fields

from emulator.errors import ExposimError

__all__ = [
    "SCENES",
    "METHODS",
    "VARIANTS",
    "CONTROL",
    "RESEEDED",
    "NOISE_OPTIONS",
    "BRIGHTENING_PAIRS",
    "DARKENING_PAIRS",
    "FIXED_INSTANT_BRACKET_INDEX",
    "METRICS",
    "PRIMARY_NOISE",
    "CONDITIONS",
    "REFERENCE_LIVE",
    "COMPARISONS",
    "EQUIVALENCE_MARGINS",
    "RPE_RANK",
    "JUDGED_METRICS",
    "HEADLINE_COMPARISONS",
    "HEADLINE_METRICS",
    "LIVE_LIVE",
    "GOAL_TAU_MIN",
    "GOAL_EXPOSURE_LOG2_MEDIAN",
    "STUDY_WIDTH",
    "STUDY_HEIGHT",
    "STUDY_PRESET",
    "STUDY_SPP",
    "STUDY_DENOISE",
    "STUDY_EMITTER_WEIGHTS",
    "STUDY_ADAPTIVE",
    "STUDY_RENDER_PER",
    "LEGACY_STUDY_DENOISE",
    "MAX_STOCHASTIC_SEEDS",
    "LiveError",
    "LiveConfig",
    "CONFIG_CHANGES",
    "DEFAULTS",
    "CONFIGS",
    "config_from_dict",
]

#: Scenes of the experiment (issue 14: three named ones and one more).
SCENES = ("forest_winter", "sun_glare", "forest_edge", "forest_summer")
#: The seven AE methods (order of ``emulator.autoexposure.methodset.parse_methods``).
METHODS = ("fixed", "classical-30", "classical-50", "classical-70", "shim", "zhang", "kim")
#: Timing variants of the live loop.
VARIANTS = ("same-instant", "fixed-instant")
#: The live control run: same-instant with other capture-noise seeds.
CONTROL = "same-instant-reseeded"
#: The re-seeded live runs, one per live reference (the live-live controls, like for like): live run ->
#: the same run again with capture-noise streams of its own (seed, scene and a purpose word each), so that
#: "emulated vs live" stands beside "live vs live re-seeded" of the same condition.  Run with the control
#: (``LiveConfig.control``); the native one only where the native-rate condition runs.
RESEEDED = {"live-same-instant": f"live-{CONTROL}", "live-fixed-instant": "live-fixed-instant-reseeded",
            "live-native": "live-native-reseeded"}
#: Emulation noise options: name in results -> ``emulate(noise=...)``.
NOISE_OPTIONS = {"plain": "none", "consistent": "consistent"}
#: (source, target) ms pairs of the darkening noise variance ratio (the source is the cleaner one).
DARKENING_PAIRS = ((32.0, 22.0), (16.0, 11.0), (8.0, 5.5), (4.0, 2.75))
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
#: The emulation noise option the verdicts are drawn on, declared before any data: plain, the
#: benchmark's default (``exposim run --noise none``); the other option is reported, never selected.
PRIMARY_NOISE = "plain"
#: The three conditions of issue 22, side by side: name -> run name.  ``native-rate live`` is a
#: camera at the recorder's 22 fps with an exposure latency (run only when a native-rate loop is
#: given to :func:`validation.live.experiment.run_live_experiment`); ``cycle-rate live`` captures
#: once per cycle at its own exposure at the cycle's first shot (fixed-instant: not the
#: emulator's bracket instant, which would copy the emulator's timing by construction).
CONDITIONS = {"native-rate live": "live-native", "cycle-rate live": "live-fixed-instant",
              "emulated": f"emulated-{PRIMARY_NOISE}", "emulated native": "emulated-native",
              "native-rate live re-seeded": RESEEDED["live-native"],
              "cycle-rate live re-seeded": RESEEDED["live-fixed-instant"]}
#: The live condition the per-metric verdicts (results.json ``metrics``) judge the emulator against:
#: what emulation changes, at the benchmark's own update rate.
REFERENCE_LIVE = "cycle-rate live"
#: Comparisons reported with omega2 (name -> (live-like reference run, compared run)); the first is
#: results.json's ``metrics``.
COMPARISONS = {
    "emulated vs cycle-rate live": ("live-fixed-instant", f"emulated-{PRIMARY_NOISE}"),
    "cycle-rate vs native-rate live": ("live-native", "live-fixed-instant"),
    "emulated vs native-rate live": ("live-native", f"emulated-{PRIMARY_NOISE}"),
    "emulated native vs native-rate live": ("live-native", "emulated-native"),
    "emulated (consistent noise) vs cycle-rate live": ("live-fixed-instant", "emulated-consistent"),
    "emulated vs same-instant live": ("live-same-instant", f"emulated-{PRIMARY_NOISE}"),
    "cycle-rate live re-seeded vs cycle-rate live": ("live-fixed-instant", RESEEDED["live-fixed-instant"]),
    "native-rate live re-seeded vs native-rate live": ("live-native", RESEEDED["live-native"]),
}
#: Equivalence margin of the difference of differences (emulated minus live, per pair of methods) in
#: each metric's unit: the smallest change of a method difference that would change what a reader
#: concludes: 2 points of uniformity (the paper's M_70% vs M_Kim differ by 1.3), 5 matches, 10 points
#: of success rate (the paper's best and worst differ by 24), 2 failed VO frames per walk, 0.5 % of
#: translation RPE (the paper's best and worst differ by 1.54).
EQUIVALENCE_MARGINS = {
    "median_uniformity": 0.02,
    "median_matches": 5.0,
    "success_rate_tau100": 0.10,
    "segment_success_rate_tau100": 0.10,
    "vo_failed_frames": 2.0,
    "rpe_trans_pct": 0.5,
    "rpe_trans_rank": 1.0,
}
#: Translation RPE with a lost VO as part of the outcome: per walk, each method's rank of translation RPE
#: (1 = lowest), methods whose VO was lost on the walk (no RPE) sharing the worst ranks.  The plain
#: ``rpe_trans_pct`` keeps only the walks where every method kept its VO (the sensitivity analysis beside it).
RPE_RANK = "rpe_trans_rank"
#: Every metric the verdicts judge: name -> higher is better (:data:`METRICS` and :data:`RPE_RANK`, derived
#: from the walks table's RPE and failed-frame columns).
JUDGED_METRICS = {**{k: higher for k, (_, higher) in METRICS.items()}, RPE_RANK: False}
#: The headline, in this order: both live references with equal weight (label -> what it answers), then
#: the cycle-rate benchmark against the native-rate camera beside them.  Their verdicts on
#: :data:`HEADLINE_METRICS` form one family (Holm).
HEADLINE_COMPARISONS = {
    "emulated vs cycle-rate live": "what the offline benchmark can match: a camera updated once per bracket cycle",
    "emulated native vs native-rate live": "what a robot's camera does: every frame at 22 fps, with an exposure "
                                           "latency",
    "emulated vs native-rate live": "beside them: the cycle-rate benchmark against the native-rate camera",
}
#: The distinct metrics of the headline: the sequence success rate is left out (it is computed from the same
#: per-pair matches as the segment success rate: a walk succeeds only when each of its segments does), and RPE
#: counts a lost VO as the worst outcome (:data:`RPE_RANK`).
HEADLINE_METRICS = ("median_uniformity", "median_matches", "segment_success_rate_tau100", "vo_failed_frames",
                    RPE_RANK)
#: The live-against-live control of each live reference: reference run -> its comparison with itself re-seeded.
LIVE_LIVE = {"live-fixed-instant": "cycle-rate live re-seeded vs cycle-rate live",
             "live-native": "native-rate live re-seeded vs native-rate live"}
#: Goals of issue 14.
GOAL_TAU_MIN = 0.9
GOAL_EXPOSURE_LOG2_MEDIAN = 0.05
#: The study's render settings: 480x300, one render per bracket sweep and camera warped to its shots, and the
#: render preset study-adaptive30 (64 spp with the sun weighted 16x, 16x the samples on the 30 % of tiles whose
#: render noise is worst against what 32 ms sees, OIDN with a 1024-spp albedo/normal pass): the cheapest setting
#: measured whose render noise costs SIFT at most 3 points beyond sensor noise on every study scene
#: (docs/results/render-clip-2026-12-04.md).  ``--render study-oidn8`` gives the renders of studies before 2026-12.
#: Literals, not read from scenes.presets, so that ``exposim --help`` imports no scenes (a test checks they agree).
STUDY_WIDTH, STUDY_HEIGHT = 480, 300
STUDY_PRESET = "study-adaptive30"
STUDY_SPP = 64
STUDY_DENOISE = "oidn-hq"
STUDY_EMITTER_WEIGHTS = (("sun", 16.0),)
STUDY_ADAPTIVE = "x16:30%@32ms"
STUDY_RENDER_PER = "cycle"
#: The denoiser of the studies before 2026-12 (the preset study-oidn8): what a record without one reads as.
LEGACY_STUDY_DENOISE = "oidn"


#: Most seeds per walk and condition of a method that draws random numbers (``LiveConfig.stochastic_seeds``).
MAX_STOCHASTIC_SEEDS = 64

#: A pre-registered study's plan, written into its folder before the first walk (validation.live.preregistration).
PREREG_FILE = "preregistration.json"
#: The record of a pre-registered study stopped before its planned walks (its final look).
STOP_FILE = "stop.json"


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
        Also run the re-seeded live runs (:data:`RESEEDED`: same-instant, cycle-rate and, with
        ``native``, native-rate live again with capture-noise streams of their own).
    metrics : bool
        Run the feature and VO benchmarks (False: exposure and image comparison only).
    keep_radiance : bool
        Keep the datasets' radiance EXRs (large) after the live loops.
    native : bool
        Run the native-rate live condition (:func:`validation.live.native.native_rate_loop`).
    latency_frames : int
        Its exposure latency in frames (a proposal made after frame k is used from frame k + 1 + latency).
    frame_rate_hz : float
        Its frame rate (the recorder's 22 fps, or a rate whose frames start on the recorder's shots).
    render_per : str
        ``"shot"`` (one render per shot and camera) or ``"cycle"`` (one render per bracket sweep
        and camera, warped with depth to every shot's exposure window: a sixth of the renders;
        :func:`scenes.synthesize.synthesize`).
    denoise : str or None
        Denoiser of the renders (``"oidn"``, ``"oidn-fast"``, ``"oidn-hq"`` or ``"off"``, :mod:`scenes.denoise`);
        None: ``$EXPOSIM_DENOISE`` when set, else :data:`STUDY_DENOISE`.  Resolved when the
        configuration is built, so ``results.json`` records the one the walks used.
    emitter_weights : tuple of (str, float)
        How the renders' next-event estimation picks a light (:meth:`scenes.Scene.with_emitter_weights`);
        empty: uniform (recorded in ``results.json`` only when set).  ``--render PRESET`` sets it with
        ``spp``, ``denoise`` and ``adaptive`` (:mod:`scenes.presets`).
    adaptive : str or None
        A spatially adaptive sample count (``"x16:30%@32ms"``, :mod:`scenes.adaptive`); None: the same
        ``spp`` everywhere (recorded only when set).  The defaults of ``spp``, ``denoise``,
        ``emitter_weights`` and ``adaptive`` are the preset :data:`STUDY_PRESET`.
    stochastic_seeds : int
        Seeds k per walk and condition of each method that draws random numbers (:mod:`validation.live.seeds`;
        the verdicts use its mean over them); 1 (the default, recorded only when other): its default seed alone.
    """

    scenes: tuple[str, ...] = SCENES
    n_cycles: int = 40
    width: int = STUDY_WIDTH
    height: int = STUDY_HEIGHT
    spp: int = STUDY_SPP
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
    native: bool = True
    latency_frames: int = 1
    frame_rate_hz: float = 22.0
    render_per: str = STUDY_RENDER_PER
    denoise: str | None = None
    emitter_weights: tuple = STUDY_EMITTER_WEIGHTS
    stochastic_seeds: int = 1
    adaptive: str | None = STUDY_ADAPTIVE

    def __post_init__(self) -> None:
        import os

        import scenes
        from scenes.base import check_emitter_weights
        from scenes.denoise import DENOISERS, ENV_DENOISE

        from emulator.autoexposure.methodset import parse_methods
        from emulator.core.select import SELECTORS

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
        if isinstance(self.latency_frames, bool) or not isinstance(self.latency_frames, int) or self.latency_frames < 0:
            raise LiveError(f"latency_frames must be an integer >= 0, got {self.latency_frames!r}")
        if not (isinstance(self.frame_rate_hz, (int, float)) and math.isfinite(self.frame_rate_hz)
                and self.frame_rate_hz > 0):
            raise LiveError(f"frame_rate_hz must be finite and positive, got {self.frame_rate_hz!r}")
        if self.render_per not in ("shot", "cycle"):
            raise LiveError(f"render_per must be 'shot' or 'cycle', got {self.render_per!r}")
        if self.denoise is None:
            env = os.environ.get(ENV_DENOISE, "").strip()
            object.__setattr__(self, "denoise", env or STUDY_DENOISE)
            if env and env not in DENOISERS:
                raise LiveError(f"${ENV_DENOISE}={env!r} is not a denoiser; valid: {', '.join(DENOISERS)}")
        elif self.denoise not in DENOISERS:
            raise LiveError(f"denoise must be one of {', '.join(DENOISERS)}, got {self.denoise!r}")
        k = self.stochastic_seeds
        if isinstance(k, bool) or not isinstance(k, int) or not 1 <= k <= MAX_STOCHASTIC_SEEDS:
            raise LiveError(f"stochastic_seeds must be an integer in 1..{MAX_STOCHASTIC_SEEDS}, got {k!r}")
        try:
            weights = check_emitter_weights(dict(self.emitter_weights), "emitter_weights")
        except (TypeError, ValueError, ExposimError) as exc:
            raise LiveError(str(exc)) from None
        object.__setattr__(self, "emitter_weights", weights)
        if self.adaptive is not None:
            from scenes.adaptive import parse_adaptive
            from scenes.errors import RenderError

            try:  # kept as its canonical text: the record and the render cache key read the same
                object.__setattr__(self, "adaptive", parse_adaptive(self.adaptive).text)
            except (RenderError, TypeError) as exc:
                raise LiveError(f"adaptive: {exc}") from None

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
        weights = d.pop("emitter_weights")  # recorded only when set: the records of earlier studies stay as they were
        if weights:
            d["emitter_weights"] = {k: float(v) for k, v in weights}
        if d["stochastic_seeds"] == 1:  # recorded only when set: the records of earlier studies stay as they were
            del d["stochastic_seeds"]
        if d["adaptive"] is None:  # recorded only when set: the records of earlier studies stay as they were
            del d["adaptive"]
        d["scene_parameters"] = {s: self.scene_parameters(s) for s in self.scenes}
        d["renders"] = self.n_cycles * (12 if self.render_per == "shot" else 2) * len(self.scenes)
        d["fixed_instant"] = "timestamp of the cycle's first shot (bracket index 0, the 1 ms bracket)"
        return d


#: The changes of each named configuration to the defaults: ``full``: 40 cycles (11 s, ~6 m
#: of walk) per scene at the study's render settings (480x300, the preset ``study-adaptive30``, one render per
#: sweep); ``quick``: 3 cycles per scene with the renders of the preset ``study-oidn8`` (a pipeline check in
#: minutes: the default preset's renders take 25-33x as long).
CONFIG_CHANGES = {"full": {}, "quick": {"n_cycles": 3, "noise_repeats": 8, "spp": 8, "denoise": LEGACY_STUDY_DENOISE,
                                        "emitter_weights": (), "adaptive": None}}
#: The defaults of :class:`LiveConfig` (read without building one: ``exposim --help`` stays light).
DEFAULTS = {f.name: f.default for f in fields(LiveConfig)}


class _Configs(Mapping):
    """The named configurations, built (and validated, which imports scenes and the AE
    methods) on first use rather than when ``exposim`` registers its commands."""

    def __init__(self) -> None:
        self._built: dict[str, LiveConfig] = {}

    def __getitem__(self, name: str) -> LiveConfig:
        if name not in self._built:
            self._built[name] = LiveConfig(**CONFIG_CHANGES[name])
        return self._built[name]

    def __iter__(self):
        return iter(CONFIG_CHANGES)

    def __len__(self) -> int:
        return len(CONFIG_CHANGES)


#: ``full`` and ``quick`` (:data:`CONFIG_CHANGES`) as :class:`LiveConfig`.
CONFIGS = _Configs()


def config_from_dict(d: dict) -> LiveConfig:
    """The :class:`LiveConfig` recorded by :meth:`LiveConfig.to_dict` (extra keys ignored)."""
    kw = {f.name: d[f.name] for f in fields(LiveConfig) if f.name in d}
    kw.setdefault("render_per", "shot")  # records from before the option rendered every shot
    # recorded only when set: a record without them rendered with uniform lights and samples
    kw.setdefault("emitter_weights", ())
    kw.setdefault("adaptive", None)
    # records from before --denoise (2026-11-28) read as that option's first default, as they always have (not as
    # today's default: a record's meaning does not move with STUDY_PRESET)
    kw.setdefault("denoise", LEGACY_STUDY_DENOISE)
    for k in ("scenes", "methods", "taus"):
        if k in kw:
            kw[k] = tuple(kw[k])
    if "emitter_weights" in kw:
        kw["emitter_weights"] = tuple(sorted(dict(kw["emitter_weights"]).items()))
    return LiveConfig(**kw)

"""One run configuration: :class:`RunConfig`, validated once, written to and read from ``run.json``.

Every closed-loop run takes a :class:`RunConfig`: ``exposim run`` (single sequence and
dataset), :func:`emulator.runner.run_to_folder`, :func:`emulator.playback.iter_run`, the
dataset units (:mod:`emulator.datasetrun`) and the studies.  The constructor checks every
field and refuses a bad one with a :class:`~emulator.errors.PlaybackError` naming it; no
other place repeats these checks.  What the configuration cannot know alone (the
recording's levels, its response and noise model) is resolved by :meth:`RunConfig.response_for`
and :meth:`RunConfig.noise_for`, once per run.

The ``--resume`` rule lives here too (:meth:`RunConfig.resumed`): **the recorded
configuration wins, and any value given again must equal it**; a difference raises and
names the keys.  ``run.json`` keys: :meth:`RunConfig.to_json` (``method_timeout_s``; the
older ``method_timeout`` key reads back as the same field).
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from emulator.autoexposure import DEFAULT_RANGE_MS
from emulator.errors import PlaybackError
from emulator.io.runfolder import SAVE_MODES

__all__ = [
    "RunConfig",
    "DEFAULT_INITIAL_MS",
    "DEFAULT_SELECTOR",
    "SAVE_MODES",
    "parse_option",
    "parse_options",
]

#: First exposure of every method, ms.
DEFAULT_INITIAL_MS = 4.0
DEFAULT_SELECTOR = "higher-no-sat"
MODES = ("paper", "borealhdr")
#: Keys of ``run.json`` that are the configuration (a resume compares these).
CONFIG_KEYS = ("selector", "initial_ms", "range_ms", "save", "mode", "options", "method_timeout_s", "noise", "blur",
               "skip_partial", "rate", "latency_frames", "native_warp", "native_blur_aware")
#: Longest per-call limit, s: the longest wait the system's poll() takes (2**31 - 1 ms, 24.8 days).
MAX_METHOD_TIMEOUT_S = 2_147_483.0
#: Largest exposure latency, frames (a recording's frame count bounds it further, at native rate).
MAX_LATENCY_FRAMES = 1_000_000
#: How often a method proposes: once per bracket sweep (the paper's) or after every recorded frame.
RATES = ("cycle", "native")


def parse_option(text: str) -> tuple[str, str, object]:
    """``METHOD.KEY=VALUE`` -> (method, key, value); VALUE parsed as JSON when it can be."""
    head, sep, value = str(text).partition("=")
    method, dot, key = head.partition(".")
    if not sep or not dot or not method.strip() or not key.strip():
        raise PlaybackError(f"--option {text!r}: expected METHOD.KEY=VALUE, e.g. kim.seed=3")
    try:
        parsed = json.loads(value)
    except json.JSONDecodeError:
        parsed = value
    return method.strip(), key.strip(), parsed


def parse_options(texts: Iterable[str], base: Mapping | None = None) -> dict[str, dict]:
    """Every ``--option`` text folded into ``{method: {key: value}}`` (over ``base``)."""
    out = {str(k): dict(v) for k, v in dict(base or {}).items()}
    for text in texts:
        method, key, value = parse_option(text)
        out.setdefault(method, {})[key] = value
    return out


def _plain(value):
    """``value`` as it reads back from JSON (tuples -> lists), for comparing configurations."""
    return json.loads(json.dumps(value, sort_keys=True, default=str))


def _same_file(a, b) -> bool:
    """Two recorded paths (relative ones to the working directory) name one existing file."""
    try:
        return bool(a) and bool(b) and Path(a).is_file() and Path(a).resolve() == Path(b).resolve()
    except OSError:
        return False


def _applied_timeout(config) -> float | None:
    from emulator.playback.workers import effective_timeout_s

    return effective_timeout_s(config)


def _number(value, name: str) -> float:
    if isinstance(value, bool):
        raise PlaybackError(f"{name} must be a number, got {value!r}")
    try:
        return float(value)
    except (TypeError, ValueError):
        raise PlaybackError(f"{name} must be a number, got {value!r}") from None


@dataclass(frozen=True)
class RunConfig:
    """The settings of a closed-loop run (not the recording nor the methods).

    Parameters
    ----------
    initial_ms : float
        First exposure of every method, ms (finite, > 0).  Outside ``range_ms`` it is
        clamped (:attr:`start_ms`; ``run.json`` records ``initial_ms_clamped``).
    range_ms : (float, float)
        Clamp of every proposal, ms: finite ``0 < low <= high``.
    selector : str
        Bracket selector (:data:`emulator.select.SELECTORS`).
    mode : {"paper", "borealhdr"}
        Method behaviour (paper: reference defects corrected).
    options : mapping
        Per-method options, ``{method: {key: value}}`` (``--option METHOD.KEY=VALUE``).
    jobs : int
        How many methods compute at once (each in its own worker process; results do not depend on it).
    workers : {"process", "inline"}
        ``process`` (the default): every method in its own worker process, with a time limit that
        interrupts; ``inline``: in the run's own process (for debugging; no isolation from the run).
    save : {"none", "png16", "png8"}
        What a run folder keeps of the emulated images.
    noise : {"none", "consistent"}
        Noise-consistent emulation (needs a noise model, :meth:`noise_for`).
    noise_model : str, path, NoiseModel or None
        A noise-model JSON, a model, or None for the one the recording carries.
    noise_seed : int
        Seed of the added noise (>= 0).
    method_timeout_s : float or None
        Per-call wall-time limit of ``next_exposure``, s (> 0), or None: with workers, the default
        limit (:data:`emulator.playback.workers.DEFAULT_METHOD_TIMEOUT_S`); inline, none.
    response_path : str, path or None
        A pcalib file; None: the one found beside the recording.
    blur : {"none", "consistent"}
        Blur-consistent emulation from the recording's gyro (:func:`emulator.motion.blur_hook`;
        ``run.json`` ``"blur"``, ``blur.csv``).
    blur_aware : bool
        With ``blur="consistent"`` and the ``higher-no-sat`` selector: the hook also selects
        brackets, weighing the higher bracket's excess blur against the lower one's noise.
    png_level : int
        zlib level of the saved images, 0..9 (default 0: stored, the fastest to write and read;
        the decoded images are the same for any level, :func:`emulator.io.png.encode_png`).
    skip_partial : bool
        Leave out every cycle missing a bracket on either camera (``--skip-partial``; skipped
        cycles are listed with what was missing).  ``run.json`` records ``"skip_partial": true``
        when set (absent: false, as in folders from before the setting).
    rate : {"cycle", "native"}
        ``cycle`` (default): a method proposes once per bracket sweep; ``native``: after every
        recorded frame, at the recorder's rate (:mod:`emulator.playback.native`, docs/native.md).
        ``run.json`` records ``"rate"`` and ``"latency_frames"`` for a native run only.
    latency_frames : int
        Native rate: a proposal made after reading frame k is first used at frame k + 1 + N (default 1).
    native_warp : {"rotation", "flow", "flow-sharp", "none"} or None
        Native rate: how a neighbour frame is moved to frame k's instant (:data:`emulator.native.WARP_MODES`);
        None (default): :data:`emulator.native.DEFAULT_NATIVE_WARP` at native rate (set so on construction;
        None at cycle rate, where nothing is warped: :attr:`warp_mode` says ``rotation``).
        ``native_blur_aware``: the native selector also weighs the motion blur a candidate's window carries
        beyond the target's (default False).  ``run.json`` records the warp where it is not ``rotation`` (a
        folder without it: rotation, as before the setting), and ``native_blur_aware`` where it is set.
    """

    initial_ms: float = DEFAULT_INITIAL_MS
    range_ms: tuple[float, float] = DEFAULT_RANGE_MS
    selector: str = DEFAULT_SELECTOR
    mode: str = "paper"
    options: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    jobs: int = 1
    workers: str = "process"
    save: str = "none"
    noise: str = "none"
    noise_model: Any = None
    noise_seed: int = 0
    method_timeout_s: float | None = None
    response_path: str | None = None
    png_level: int = 0
    blur: str = "none"
    blur_aware: bool = False
    skip_partial: bool = False
    rate: str = "cycle"
    latency_frames: int = 1
    native_warp: str | None = None
    native_blur_aware: bool = False

    def __post_init__(self) -> None:
        from emulator.select import SELECTORS

        put = object.__setattr__
        initial = _number(self.initial_ms, "initial_ms")
        if not (math.isfinite(initial) and initial > 0):
            raise PlaybackError(f"initial_ms must be a finite, positive number of ms, got {self.initial_ms!r}")
        put(self, "initial_ms", initial)
        try:
            lo, hi = (float(v) for v in self.range_ms)
        except (TypeError, ValueError):
            raise PlaybackError(f"range_ms must be (low_ms, high_ms), got {self.range_ms!r}") from None
        if not (math.isfinite(lo) and math.isfinite(hi) and 0 < lo <= hi):
            raise PlaybackError(f"range_ms must satisfy 0 < low <= high (ms), got {self.range_ms!r}")
        put(self, "range_ms", (lo, hi))
        if self.selector not in SELECTORS:
            raise PlaybackError(f"unknown selector {self.selector!r}; choose one of {', '.join(SELECTORS)}")
        if self.mode not in MODES:
            raise PlaybackError(f"mode must be one of {', '.join(MODES)}, got {self.mode!r}")
        if not isinstance(self.options, Mapping) or not all(isinstance(v, Mapping) for v in self.options.values()):
            raise PlaybackError(f"options must map a method name to {{key: value}}, got {self.options!r}")
        put(self, "options", {str(k): dict(v) for k, v in self.options.items()})
        if isinstance(self.jobs, bool) or not isinstance(self.jobs, (int, np.integer)) or int(self.jobs) < 1:
            raise PlaybackError(f"jobs must be an integer >= 1, got {self.jobs!r}")
        put(self, "jobs", int(self.jobs))
        if self.workers not in ("process", "inline"):
            raise PlaybackError(f"workers must be process or inline, got {self.workers!r}")
        if self.save not in SAVE_MODES:
            raise PlaybackError(f"save must be one of {', '.join(SAVE_MODES)}, got {self.save!r}")
        from emulator.emulate import NOISE_MODES

        if self.noise not in NOISE_MODES:
            raise PlaybackError(f"noise must be one of {', '.join(NOISE_MODES)}, got {self.noise!r}")
        seed = self.noise_seed
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise PlaybackError(f"noise_seed must be a non-negative integer, got {seed!r}")
        put(self, "noise_seed", int(seed))
        if self.method_timeout_s is not None:
            value = _number(self.method_timeout_s, "method_timeout_s")
            if not (math.isfinite(value) and value > 0):
                raise PlaybackError(f"method_timeout_s must be finite and positive (seconds), got "
                                    f"{self.method_timeout_s!r}")
            if value > MAX_METHOD_TIMEOUT_S:
                raise PlaybackError(f"method_timeout_s must be at most {MAX_METHOD_TIMEOUT_S:.0f} s (24.8 days, the "
                                    f"longest wait the system's poll() takes), got {self.method_timeout_s!r}")
            put(self, "method_timeout_s", value)
        if self.response_path is not None:
            put(self, "response_path", str(self.response_path))
        if isinstance(self.png_level, bool) or not isinstance(self.png_level, (int, np.integer)) \
                or not 0 <= self.png_level <= 9:
            raise PlaybackError(f"png_level must be an integer 0..9, got {self.png_level!r}")
        put(self, "png_level", int(self.png_level))
        from emulator.blur import BLUR_MODES

        if self.blur not in BLUR_MODES:
            raise PlaybackError(f"blur must be one of {', '.join(BLUR_MODES)}, got {self.blur!r}")
        put(self, "blur_aware", bool(self.blur_aware))
        if self.blur_aware and self.blur != "consistent":
            raise PlaybackError("blur_aware: the blur-aware selection needs blur 'consistent' (--blur consistent)")
        if self.blur_aware and self.selector != "higher-no-sat":
            raise PlaybackError(f"blur_aware: the blur-aware selection refines selector higher-no-sat, not "
                                f"{self.selector!r}")
        if not isinstance(self.skip_partial, (bool, np.bool_)):
            raise PlaybackError(f"skip_partial must be true or false, got {self.skip_partial!r}")
        put(self, "skip_partial", bool(self.skip_partial))
        if isinstance(self.noise_model, Path):
            put(self, "noise_model", str(self.noise_model))
        if self.rate not in RATES:
            raise PlaybackError(f"rate must be one of {', '.join(RATES)}, got {self.rate!r}")
        lat = self.latency_frames
        if isinstance(lat, bool) or not isinstance(lat, (int, np.integer)) or not 0 <= lat <= MAX_LATENCY_FRAMES:
            raise PlaybackError(f"latency_frames must be an integer >= 0, at most {MAX_LATENCY_FRAMES} and below "
                                f"the recording's frame count, got {lat!r}")
        put(self, "latency_frames", int(lat))
        from emulator.native import DEFAULT_NATIVE_WARP, WARP_MODES

        if self.native_warp is None and self.rate == "native":
            put(self, "native_warp", DEFAULT_NATIVE_WARP)
        elif self.rate != "native" and self.native_warp == DEFAULT_NATIVE_WARP:  # a native run's default, carried
            put(self, "native_warp", None)  # over (a resume asked at cycle rate is refused for its rate)
        if self.native_warp is not None and self.native_warp not in WARP_MODES:
            raise PlaybackError(f"native_warp must be one of {', '.join(WARP_MODES)}, got {self.native_warp!r}")
        put(self, "native_blur_aware", bool(self.native_blur_aware))
        if self.rate != "native" and (self.native_warp not in (None, "rotation") or self.native_blur_aware):
            raise PlaybackError("native_warp and native_blur_aware: used only at native rate (--rate native)")

    # ------------------------------------------------------------------ derived values
    @property
    def start_ms(self) -> float:
        """The first exposure actually used: :attr:`initial_ms` clamped to :attr:`range_ms`."""
        return self.clamp(self.initial_ms)

    def clamp(self, value_ms: float) -> float:
        lo, hi = self.range_ms
        return min(max(float(value_ms), lo), hi)

    @property
    def warp_mode(self) -> str:
        """The native warp this configuration runs: ``native_warp``, or where None the native default
        (:data:`emulator.native.DEFAULT_NATIVE_WARP`; ``rotation`` at cycle rate, where nothing is warped)."""
        from emulator.native import DEFAULT_NATIVE_WARP

        if self.native_warp is not None:
            return self.native_warp
        return DEFAULT_NATIVE_WARP if self.rate == "native" else "rotation"

    def replace(self, **changes) -> "RunConfig":
        """A copy with ``changes`` (validated again)."""
        return dataclasses.replace(self, **changes)

    @classmethod
    def from_kwargs(cls, config: "RunConfig | None" = None, **kwargs) -> "RunConfig":
        """``config`` (default: the defaults) with the keyword arguments that are not None.

        Accepts ``method_timeout`` as the older name of ``method_timeout_s``.
        """
        legacy = False  # the value came by its older name: an error names both
        if "method_timeout" in kwargs:
            old = kwargs.pop("method_timeout")
            if kwargs.get("method_timeout_s") is None:
                kwargs["method_timeout_s"] = old
                legacy = old is not None
        unknown = set(kwargs) - {f.name for f in dataclasses.fields(cls)}
        if unknown:
            raise TypeError(f"unknown run setting(s): {', '.join(sorted(unknown))}")
        base = config if config is not None else cls()
        given = {k: v for k, v in kwargs.items() if v is not None}
        if not given:
            return base
        try:
            return base.replace(**given)
        except PlaybackError as exc:
            if "method_timeout_s" in str(exc) and legacy:
                raise PlaybackError(str(exc).replace("method_timeout_s", "method_timeout (method_timeout_s)")) from None
            raise

    # ------------------------------------------------------------------ the recording's side
    def response_for(self, sequence, response=None):
        """The run's response at the recording's levels (the one place a response is re-levelled)."""
        from emulator.io.borealhdr import sequence_response

        if response is None:
            response = sequence_response(sequence, self.response_path)
        white, black = int(sequence.white_level), int(sequence.black_level)
        if response.white_level != white or response.black_level != black:
            response = response.with_levels(white_level=white, black_level=black)
        return response

    def response_name(self, response) -> str:
        """How ``run.json`` names the response: the pcalib file (absolute), or the response's name."""
        name = self.response_path if self.response_path is not None else str(getattr(response, "name", "custom"))
        if Path(name).is_file():  # absolute: a resume from another working directory finds it
            name = str(Path(name).resolve())
        return name

    def noise_for(self, sequence, response):
        """``(model, source)`` of the run's noise: ``(None, None)`` for ``noise="none"``.

        The model is :attr:`noise_model` (a NoiseModel or a noise-model JSON), or the one
        the recording's ``exposim.json`` carries; it must refer to ``response``.
        """
        from emulator.emulate import _check_noise_model
        from emulator.io.noisemodel import noise_model_from_metadata, read_noise_model
        from emulator.noise import NoiseModel

        if self.noise == "none":
            return None, None
        if isinstance(self.noise_model, NoiseModel):
            model, source = self.noise_model, str(self.noise_model.name)
        elif self.noise_model is not None:
            model, source = read_noise_model(self.noise_model, response), str(Path(self.noise_model).resolve())
        else:
            meta_path = Path(sequence.path) / "exposim.json"
            model = noise_model_from_metadata(sequence.metadata, response, source=str(meta_path))
            if model is None:
                raise PlaybackError(
                    f'{sequence.path}: noise "{self.noise}" needs a noise model and the recording carries none (no '
                    f"camera in {meta_path.name}); pass --noise-model FILE.json (written by `exposim calibrate "
                    "--noise`)")
            source = str(meta_path.resolve())
        return _check_noise_model(model, response, self.noise, False), source

    # ------------------------------------------------------------------ run.json
    def blur_for(self, sequence, response):
        """The run's blur hook (:class:`emulator.motion.BlurHook`), or None for ``blur="none"``."""
        if self.blur == "none":
            return None
        from emulator.motion import blur_hook

        return blur_hook(self.blur, sequence, response, blur_aware=self.blur_aware)

    def to_json(self, noise_model=None, blur_hook=None) -> dict:
        """The configuration keys of ``run.json`` (``noise`` holds the model's figures when given,
        ``blur`` the hook's description)."""
        from emulator.blur import DEFAULT_PLACEMENT

        if self.noise == "none":
            noise = {"mode": "none"}
        else:
            noise = {"mode": self.noise, "seed": self.noise_seed}
            if noise_model is not None:
                noise["model"] = {k: v for k, v in noise_model.to_dict().items() if k != "response"}
        return _plain({
            "selector": self.selector,
            "initial_ms": self.initial_ms,
            "range_ms": list(self.range_ms),
            "save": self.save,
            "mode": self.mode,
            "options": self.options,
            "method_timeout_s": self.method_timeout_s,
            "noise": noise,
            "jobs": self.jobs,
            "workers": self.workers,
            "method_timeout_applied_s": _applied_timeout(self),
            "png_level": self.png_level,
            "blur": (blur_hook.describe() if blur_hook is not None else
                     {"mode": self.blur, **({"placement": DEFAULT_PLACEMENT} if self.blur == "consistent" else {}),
                      **({"blur_aware": True} if self.blur_aware else {})}),
            **({"skip_partial": True} if self.skip_partial else {}),
            **({"rate": "native", "latency_frames": self.latency_frames} if self.rate == "native" else {}),
            **({"native_warp": self.warp_mode} if self.warp_mode != "rotation" else {}),
            **({"native_blur_aware": True} if self.native_blur_aware else {}),
        })

    @classmethod
    def from_json(cls, run_json: Mapping) -> "RunConfig":
        """The configuration a ``run.json`` (or ``dataset.json``'s ``config``) records."""
        noise = run_json.get("noise") or {"mode": "none"}
        response = run_json.get("response_path") or run_json.get("response")
        timeout = run_json.get("method_timeout_s", run_json.get("method_timeout"))
        model = run_json.get("noise_model_file") or run_json.get("noise_model")
        if model is not None and Path(model).name == "exposim.json":
            model = None  # the recording's own: found again from the recording
        return cls(
            initial_ms=run_json.get("initial_ms", DEFAULT_INITIAL_MS),
            range_ms=tuple(run_json.get("range_ms") or DEFAULT_RANGE_MS),
            selector=run_json.get("selector") or DEFAULT_SELECTOR,
            mode=run_json.get("mode") or "paper",
            options=run_json.get("options") or {},
            jobs=int(run_json.get("jobs") or 1),
            workers=run_json.get("workers") or "process",
            save=run_json.get("save") or "none",
            noise=noise.get("mode", "none"),
            noise_model=model if model and Path(model).is_file() else None,
            noise_seed=int(noise.get("seed", 0)),
            method_timeout_s=timeout,
            response_path=response if response and Path(response).is_file() else None,
            png_level=int(run_json.get("png_level", 1)),  # folders from before the setting: level 1
            blur=(run_json.get("blur") or {}).get("mode", "none"),  # folders from before --blur: none
            blur_aware=bool((run_json.get("blur") or {}).get("blur_aware", False)),
            skip_partial=bool(run_json.get("skip_partial", False)),
            rate=run_json.get("rate") or "cycle",  # folders from before --rate: cycle
            latency_frames=int(run_json.get("latency_frames", 1)),
            # native folders from before the warp modes: rotation; cycle rate has none
            native_warp=run_json.get("native_warp") or ("rotation" if run_json.get("rate") == "native" else None),
            native_blur_aware=bool(run_json.get("native_blur_aware", False)),
        )

    def resumed(self, recorded: Mapping, given: Iterable[str] = CONFIG_KEYS, *, where: str = "run.json",
                noise_model=None, blur_hook=None, identity: Mapping | None = None) -> "RunConfig":
        """The one ``--resume`` rule: the recorded configuration wins; values given must equal it.

        ``recorded`` is the ``run.json`` of the folder; ``given`` names the fields of this
        configuration that were set explicitly (all of :data:`CONFIG_KEYS` when it came
        whole, as from the library).  ``identity`` adds what the run is of (``sequence``,
        ``methods``, ``response``), compared the same way (a response path naming the
        same file as the recorded one agrees).  ``jobs`` may differ (results do not depend on it).
        Returns the recorded configuration (with this one's ``jobs``); a difference raises
        :class:`PlaybackError` naming the keys.
        """
        old = RunConfig.from_json(recorded)
        mine = self.to_json(noise_model, blur_hook)
        theirs = dict(recorded)
        theirs.setdefault("method_timeout_s", theirs.get("method_timeout"))
        theirs["noise"] = theirs.get("noise") or {"mode": "none"}
        theirs["blur"] = dict(theirs.get("blur") or {"mode": "none"})
        if theirs["blur"].get("mode") == "consistent":  # folders from before tiled copies: uniform sub-instants
            theirs["blur"].setdefault("placement", "uniform")
        given = set(given)
        diff = []
        for key in CONFIG_KEYS:
            if key not in given:
                continue
            a, b = mine.get(key), theirs.get(key)
            if key in ("noise", "blur"):  # the figures of a model or hook only where both sides have them
                a, b = ({k: v for k, v in (x or {}).items() if k in ("mode", "seed", "blur_aware", "placement") or k in (y or {})}
                        for x, y in ((a, b), (b, a)))
            if _plain(a) != _plain(b):
                diff.append(key)
        for key, a in dict(identity or {}).items():
            b = theirs.get(key)
            if _plain(a) != _plain(b) and not (key == "response" and _same_file(a, b)):
                diff.append(key)
        if diff:
            raise PlaybackError(f"{where}: --resume with a different configuration ({', '.join(diff)}): recorded "
                                + "; ".join(f"{k}={theirs.get(k)!r}" for k in diff))
        keep = {k: getattr(self, k) for k in ("response_path", "noise_model") if getattr(self, k) is not None}
        return old.replace(jobs=self.jobs, workers=self.workers, **keep)

"""One run configuration: :class:`RunConfig`, validated once, written to and read from ``run.json``.

Every closed-loop run takes a :class:`RunConfig`: ``exposim run`` (single sequence and
dataset), :func:`emulator.orchestration.runner.run_to_folder`, :func:`emulator.playback.iter_run`, the
dataset units (:mod:`emulator.orchestration.datasetrun`) and the studies.  The constructor checks every
field (:mod:`emulator.playback.checks`) and refuses a bad one with a
:class:`~emulator.errors.PlaybackError` naming it; no other place repeats these checks.  What the
configuration cannot know alone (the recording's levels, its response and noise model) is resolved
by :meth:`RunConfig.response_for` and :meth:`RunConfig.noise_for`, once per run.

Each setting is one field, declared once with its flag, help, ``run.json`` key and resume rule
(:mod:`emulator.playback.settings`).  The ``--resume`` rule lives here too
(:meth:`RunConfig.check_resume`): **the recorded configuration wins, and any value given again
must equal it**; a difference raises and names the keys.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from emulator.autoexposure import DEFAULT_RANGE_MS
from emulator.core.emulate import check_noise_model
from emulator.core.native import DEFAULT_NATIVE_WARP, NATIVE_RATE, RATES, is_native_run
from emulator.errors import PlaybackError
from emulator.io.borealhdr import sequence_response
from emulator.io.noisemodel import noise_model_from_metadata, read_noise_model
from emulator.io.runfolder import SAVE_MODES
from emulator.noise import NoiseModel
from emulator.playback import motion, settings
from emulator.playback.checks import MODES, WORKER_MODES, checked_fields
from emulator.playback.runjson import (blur_json, common_figures, noise_json, recorded_blur, recorded_noise_model,
                                       recorded_response, same_file)
from emulator.playback.settings import parse_option, parse_options, setting

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
#: Per-call limit of a method in a worker when ``--method-timeout-s`` is not given, seconds: far
#: above any built-in's call (under 0.1 s on a 1920x1200 frame), so only a stuck method meets it.
DEFAULT_METHOD_TIMEOUT_S = 120.0


def _plain(value):
    """``value`` as it reads back from JSON (tuples -> lists), for comparing configurations."""
    return json.loads(json.dumps(value, sort_keys=True, default=str))


#: The image provider of each rate; each provider's module declares its own (:func:`provides_rate`), so that
#: this module imports none of them.
PROVIDERS: dict[str, type] = {}


def provides_rate(rate: str):
    """Class decorator: the decorated image provider is the one of ``rate`` (:attr:`RunConfig.provider_class`)."""
    if rate not in RATES:
        raise ValueError(f"rate must be one of {', '.join(RATES)}, got {rate!r}")

    def declare(cls):
        PROVIDERS[rate] = cls
        return cls

    return declare


def _is_native(config) -> bool:
    return config.rate == NATIVE_RATE


_NATIVE = "with --rate native: "


@dataclass(frozen=True)
class RunConfig:
    """The settings of a closed-loop run (not the recording nor the methods).

    Each field is one setting, declared once with its :class:`~emulator.playback.settings.Setting`
    (flag and help of ``exposim run``, ``run.json`` key, resume rule; the help says what it does).
    The constructor checks every field (:class:`PlaybackError` naming it).  Notes:

    * ``initial_ms`` outside ``range_ms`` is clamped (:attr:`start_ms`; ``run.json`` records
      ``initial_ms_clamped``); ``range_ms`` is finite ``0 < low <= high``.
    * ``method_timeout_s`` None: with workers the default limit (:data:`DEFAULT_METHOD_TIMEOUT_S`),
      inline none; :attr:`method_timeout_applied_s` is the limit applied.
    * ``noise_model``: a noise-model JSON, a NoiseModel, or None for the one the recording carries.
    * ``run.json`` records ``skip_partial``, ``native_blur_aware`` only where set, ``rate`` and
      ``latency_frames`` for a native run only, ``native_warp`` where it is not ``rotation`` (a
      folder without it: rotation, as before the setting); ``png_level`` absent reads as 1.
    * ``native_warp`` None: :data:`emulator.core.native.DEFAULT_NATIVE_WARP` at native rate (set so on
      construction), None at cycle rate (nothing is warped: :attr:`warp_mode` says ``rotation``).
    """

    initial_ms: float = setting(
        DEFAULT_INITIAL_MS, flag="--initial-ms", key="initial_ms", resume=True, command=3, cli={"type": float},
        help="initial exposure of every method, ms (default 4.0; clamped to --range-ms, with a warning)")
    range_ms: tuple[float, float] = setting(
        DEFAULT_RANGE_MS, flag="--range-ms", key="range_ms", resume=True, command=13,
        cli={"type": float, "nargs": 2, "metavar": ("LOW", "HIGH")},
        help="clamp of every proposal, ms (default %s %s)" % DEFAULT_RANGE_MS)
    selector: str = setting(
        DEFAULT_SELECTOR, flag="--selector", key="selector", resume=True, command=4,
        cli={"choices": ("higher-no-sat", "closest", "reference")}, help="bracket selector (default higher-no-sat)")
    mode: str = setting(
        "paper", flag="--mode", key="mode", resume=True, command=2, cli={"choices": MODES},
        help="method behaviour: paper (default, reference defects corrected) or borealhdr (reference code)")
    #: per-method options ``{method: {key: value}}`` (``--option METHOD.KEY=VALUE``, ``--seed``: exposim run's own)
    options: Mapping[str, Mapping[str, Any]] = setting(default_factory=dict, key="options", resume=True)
    jobs: int = setting(
        1, flag="--jobs", key="jobs", per_run=True, command=15, shown_unless_default=True,
        cli={"type": int, "default": 1},
        help="how many methods compute at once, each in its own process (same output for any value)")
    #: ``process``: every method in its own worker process, with a limit that interrupts; ``inline``: in the run's
    #: process (debugging; no isolation).  ``run.json`` writes the applied limit beside it (it depends on both).
    workers: str = setting(
        "process", flag="--isolation", key="workers", per_run=True, command=16, shown_unless_default=True,
        cli={"choices": WORKER_MODES},
        encode=lambda c, ctx: {"workers": c.workers, "method_timeout_applied_s": c.method_timeout_applied_s},
        help="process (default): every AE method in its own process, stopped past --method-timeout-s; "
             "inline: in the run's process (debugging only: a method can then stall or change the run)")
    save: str = setting(
        "none", flag="--save", key="save", resume=True, command=1, cli={"choices": SAVE_MODES},
        help="save emulated images: none (default), png16 (12-bit Bayer DN) or png8 (8-bit gray)")
    noise: str = setting(
        "none", flag="--noise", key="noise", resume=True, command=7, cli={"choices": ("none", "consistent")},
        encode=noise_json, decode=lambda j: (j.get("noise") or {"mode": "none"}).get("mode", "none"),
        recorded=lambda j: j.get("noise") or {"mode": "none"}, compare=common_figures,
        help="none (default): exact emulation (eq. 2); consistent: add the noise a capture at the "
             "target exposure would have where the source bracket is cleaner (needs a noise model)")
    noise_model: Any = setting(
        None, flag="--noise-model", command=9, cli={"type": Path, "metavar": "FILE.json"}, decode=recorded_noise_model,
        help="noise model for --noise consistent (`exposim calibrate --noise`); default: the model "
             "a synthetic recording's exposim.json carries")
    noise_seed: int = setting(
        0, flag="--noise-seed", command=10, cli={"type": int}, decode=lambda j: int((j.get("noise") or {}).get("seed", 0)),
        help="seed of the added noise (default 0); the same seed gives the same bytes")
    method_timeout_s: float | None = setting(
        None, flag="--method-timeout-s", aliases=("--method-timeout",), key="method_timeout_s", resume=True,
        command=23, cli={"type": float, "metavar": "S"},
        decode=lambda j: j.get("method_timeout_s", j.get("method_timeout")),
        recorded=lambda j: j.get("method_timeout_s", j.get("method_timeout")),
        help="per-call wall-time limit of a method, s: a call still running then is stopped and the method "
             "fails (its rows stop, the others go on); default 120 (--isolation inline: checked only after the "
             "call returns, no default; --method-timeout: deprecated alias)")
    response_path: str | None = setting(
        None, flag="--response", command=5, cli={"type": Path}, decode=recorded_response,
        help="pcalib file (default: found beside the recording)")
    png_level: int = setting(
        0, flag="--png-level", key="png_level", old=1, command=11, cli={"type": int, "metavar": "0..9"},
        help="zlib level of the saved images (default 0: stored, the fastest; 1..9 smaller files, the "
             "same decoded images)")
    blur: str = setting(
        "none", flag="--blur", key="blur", resume=True, command=8, cli={"choices": ("none", "consistent")},
        encode=blur_json, decode=lambda j: (j.get("blur") or {}).get("mode", "none"), recorded=recorded_blur,
        compare=common_figures,
        help="none (default): exact emulation; consistent: add the gyro's blur of the extra exposure time "
             "where the target is longer than the bracket, and record each image's excess blur in blur.csv "
             "(needs imu/imu.csv and a camera calibration; docs/blur.md)")
    blur_aware: bool = setting(
        False, flag="--blur-aware", command=17, cli={"action": "store_true"},
        decode=lambda j: bool((j.get("blur") or {}).get("blur_aware", False)),
        help="with --blur consistent and --selector higher-no-sat: of the two brackets around the "
             "target, take the shorter one when the longer one's extra motion blur (predicted from the "
             "gyro) costs more than the shorter one's extra noise; one pixel of blur weighs as much as "
             "twice the relative noise of a capture at the target (docs/blur.md)")
    skip_partial: bool = setting(
        False, flag="--skip-partial", key="skip_partial", resume=True, command=18, cli={"action": "store_true"},
        encode=lambda c, ctx: {"skip_partial": True} if c.skip_partial else {},
        help="leave out every cycle missing a bracket on either camera (default: use the brackets that are "
             "there; partial cycles and upward ratios above 8 are flagged in the report either way)")
    rate: str = setting(
        RATES[0], flag="--rate", key="rate", resume=True, command=20, cli={"choices": RATES},
        encode=lambda c, ctx: {"rate": c.rate} if _is_native(c) else {},
        help="cycle (default): each method proposes once per bracket sweep, as in the paper; native: after "
             "every recorded frame, at the recorder's frame rate, each frame emulated from its own bracket "
             "or a nearby frame's, turned to its instant with the gyro (docs/native.md)")
    latency_frames: int = setting(
        1, flag="--latency-frames", key="latency_frames", resume=True, command=21, native_only=True,
        cli={"type": int, "metavar": "N"},
        encode=lambda c, ctx: {"latency_frames": c.latency_frames} if _is_native(c) else {},
        help=_NATIVE + "a proposal made after reading frame k is first used at frame k + 1 + N "
             "(default 1, as a live camera)")
    native_warp: str | None = setting(
        None, flag="--warp", key="native_warp", resume=True, command=12, native_only=True,
        cli={"choices": ("flow-sharp", "rotation", "flow", "none")},
        encode=lambda c, ctx: {"native_warp": c.warp_mode} if c.warp_mode != "rotation" else {},
        # native folders from before the warp modes: rotation; cycle rate has none
        decode=lambda j: j.get("native_warp") or ("rotation" if is_native_run(j) else None),
        help="--rate native: rotation: gyro; flow: then the neighbours' flow; flow-sharp (default): flow unless "
             "under 1 px")
    native_blur_aware: bool = setting(
        False, flag="--native-blur-aware", key="native_blur_aware", resume=True, command=19, native_only=True,
        cli={"action": "store_true"}, encode=lambda c, ctx: {"native_blur_aware": True} if c.native_blur_aware else {},
        help=_NATIVE + "the selector also weighs the motion blur a candidate carries beyond the target's, from "
             "the gyro (docs/native.md)")

    def __post_init__(self) -> None:
        for name, value in checked_fields(self).items():  # every field checked, once (emulator.playback.checks)
            object.__setattr__(self, name, value)

    # ------------------------------------------------------------------ derived values
    @property
    def start_ms(self) -> float:
        """The first exposure actually used: :attr:`initial_ms` clamped to :attr:`range_ms`."""
        return self.clamp(self.initial_ms)

    def clamp(self, value_ms: float) -> float:
        lo, hi = self.range_ms
        return min(max(float(value_ms), lo), hi)

    @property
    def method_timeout_applied_s(self) -> float | None:
        """The per-call limit this run applies: :attr:`method_timeout_s`, else the default with workers
        (:data:`DEFAULT_METHOD_TIMEOUT_S`), none inline."""
        if self.method_timeout_s is not None:
            return float(self.method_timeout_s)
        return DEFAULT_METHOD_TIMEOUT_S if self.workers == WORKER_MODES[0] else None

    @property
    def warp_mode(self) -> str:
        """The native warp this configuration runs: ``native_warp``, or where None the native default
        (:data:`emulator.core.native.DEFAULT_NATIVE_WARP`; ``rotation`` at cycle rate, where nothing is warped)."""
        if self.native_warp is not None:
            return self.native_warp
        return DEFAULT_NATIVE_WARP if _is_native(self) else "rotation"

    @property
    def latency_ticks(self) -> int:
        """Ticks between a proposal and its use beyond the next one: ``latency_frames`` at native rate, else 0."""
        return self.latency_frames if _is_native(self) else 0

    @property
    def provider_class(self):
        """The image provider of this rate (:data:`PROVIDERS`): :class:`~emulator.playback.emulated.EmulatedProvider`
        (a tick per bracket sweep) or :class:`~emulator.playback.native.NativeProvider` (a tick per recorded frame)."""
        return PROVIDERS[self.rate]

    def provider_for(self, sequence, response, *, noise=None, stats=None, blur=None):
        """This run's image provider on ``sequence`` (:attr:`provider_class`, configured by this run)."""
        return self.provider_class.for_run(sequence, self, response, noise=noise, stats=stats, blur=blur)

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
        return check_noise_model(model, response, self.noise, False), source

    def blur_for(self, sequence, response):
        """The run's blur hook (:class:`emulator.playback.motion.BlurHook`), or None for ``blur="none"``."""
        if self.blur == "none":
            return None
        return motion.blur_hook(self.blur, sequence, response, blur_aware=self.blur_aware)

    # ------------------------------------------------------------------ run.json
    def to_json(self, noise_model=None, blur_hook=None) -> dict:
        """The configuration keys of ``run.json``, in field order (``noise`` holds the model's figures
        when given, ``blur`` the hook's description): each setting's :class:`~emulator.playback.settings.Setting`."""
        return _plain(settings.to_json(self, {"noise_model": noise_model, "blur_hook": blur_hook}))

    def per_run_json(self) -> dict:
        """The ``run.json`` keys of how this run computes (``jobs``, ``workers``, the applied limit), written
        again by a resume (results do not depend on them)."""
        return json.loads(json.dumps(settings.to_json(self, per_run=True)))  # in field order: jobs, workers, limit

    @classmethod
    def from_json(cls, run_json: Mapping) -> "RunConfig":
        """The configuration a ``run.json`` (or ``dataset.json``'s ``config``) records."""
        return cls(**settings.values_from_json(cls, run_json))

    def check_resume(self, recorded: Mapping, given: Iterable[str] | None = None, *, where: str = "run.json",
                     noise_model=None, blur_hook=None, identity: Mapping | None = None) -> None:
        """The one ``--resume`` rule: values given must equal the recorded ones; a difference raises.

        ``recorded`` is the ``run.json`` of the folder; ``given`` names the keys of this
        configuration that were set explicitly (default: every key a resume compares,
        :func:`~emulator.playback.settings.resume_keys`, as for a configuration from the library).
        ``identity`` adds what the run is of (``sequence``, ``methods``, ``response``), compared the
        same way (a response path naming the same file as the recorded one agrees).  A difference
        raises :class:`PlaybackError` naming the keys.
        """
        cls = type(self)
        keys = settings.resume_keys(cls)
        given = set(keys if given is None else given)
        mine = self.to_json(noise_model, blur_hook)
        theirs = {key: settings.recorded_value(cls, key, recorded) for key in keys}
        diff = []
        for key in keys:
            if key not in given:
                continue
            a, b = settings.compared(cls, key, mine.get(key), theirs.get(key))
            if _plain(a) != _plain(b):
                diff.append(key)
        for key, a in dict(identity or {}).items():
            b = theirs[key] = recorded.get(key)
            if _plain(a) != _plain(b) and not (key == "response" and same_file(a, b)):
                diff.append(key)
        if diff:
            raise PlaybackError(f"{where}: --resume with a different configuration ({', '.join(diff)}): recorded "
                                + "; ".join(f"{k}={theirs.get(k)!r}" for k in diff))

    def resumed(self, recorded: Mapping, given: Iterable[str] | None = None, **kwargs) -> "RunConfig":
        """:meth:`check_resume`, then the recorded configuration (with this one's per-run settings,
        ``jobs`` and ``workers``, and its response and noise-model files where given)."""
        self.check_resume(recorded, given, **kwargs)
        cls = type(self)
        values = settings.values_from_json(cls, recorded)
        values.update({f.name: getattr(self, f.name) for f, s in settings.settings_of(cls) if s.per_run})
        values.update({k: getattr(self, k) for k in ("response_path", "noise_model") if getattr(self, k) is not None})
        return cls(**values)


#: Keys of ``run.json`` that are the configuration (a resume compares these).
CONFIG_KEYS = settings.resume_keys(RunConfig)

"""Named render presets: samples per pixel, denoiser and the choice of lights, as one setting.

A render's noise is set by three choices made together: the path tracer's samples per pixel,
the denoiser with the samples of its albedo/normal pass (:mod:`scenes.denoise`), and how
next-event estimation picks a light (:meth:`scenes.Scene.with_emitter_weights`).  A preset
names one combination, so that a study, the measurement of render noise and the docs speak of
the same thing.  Each is written as a setting string too::

    DENOISER@SPP[/AUX_SPP][+LIGHT=WEIGHT[,LIGHT=WEIGHT...]][~xFACTOR:PERCENT%[/TILE]]

e.g. ``oidn@8`` (the live study's renders until 2026-12), ``oidn@256/1024``,
``oidn@64/1024+sun=16`` or ``oidn-hq@64+sun=16~x4:25%`` (``FACTOR`` times the samples in the
``PERCENT`` of ``TILE``-pixel tiles whose render noise is worst against their radiance, see
:mod:`scenes.adaptive`).  :func:`parse_setting` reads that form and preset names alike.

Why a weighted sun: Mitsuba picks one light per next-event sample, uniformly by default.
In the daylight scenes the sun is a directional light whose shadow ray either carries half or
more of a sunlit pixel's radiance or nothing, so giving it most of the picks cuts the noise of
sunlit surfaces; the expected radiance is unchanged (docs/results/render.md measures both).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from scenes.adaptive import AdaptiveSampling, parse_adaptive
from scenes.base import EMITTER_KINDS, Scene, check_emitter_weights
from scenes.denoise import DenoiseSettings, resolve_denoise
from scenes.errors import RenderError, SceneError

__all__ = ["RenderPreset", "RENDER_PRESETS", "LEGACY_STUDY_PRESET", "parse_setting"]


@dataclass(frozen=True)
class RenderPreset:
    """One named render setting.

    Attributes
    ----------
    name : str
        The preset's name (a key of :data:`RENDER_PRESETS`, or the setting string itself).
    spp : int
        Samples per pixel of the path tracer.
    denoise : scenes.denoise.DenoiseSettings
        The denoiser and its albedo/normal pass.
    emitter_weights : tuple of (str, float)
        Next-event estimation's relative choice of ``sun``, ``sky`` and ``area`` lights (empty: uniform).
    summary : str
        One line on what it is for.
    adaptive : scenes.adaptive.AdaptiveSampling or None
        More samples where render noise is worst (None: ``spp`` everywhere).
    """

    name: str
    spp: int
    denoise: DenoiseSettings
    emitter_weights: tuple = ()
    summary: str = ""
    adaptive: AdaptiveSampling | None = None

    @property
    def setting(self) -> str:
        """The preset as a setting string (``DENOISER@SPP[/AUX][+LIGHT=W,...][~xF:P%]``), which :func:`parse_setting` reads back."""
        text = f"{self.denoise.name}@{self.spp}"
        default_aux = resolve_denoise(self.denoise.name).aux_spp if self.denoise.enabled else None
        if self.denoise.enabled and self.denoise.aux_spp != default_aux:
            text += f"/{self.denoise.aux_spp}"
        if self.emitter_weights:
            text += "+" + ",".join(f"{k}={v:g}" for k, v in self.emitter_weights)
        if self.adaptive is not None:
            text += "~" + self.adaptive.text
        return text

    def scene(self, scene: Scene) -> Scene:
        """``scene`` with this preset's choice of lights."""
        return scene.with_emitter_weights(dict(self.emitter_weights))

    def record(self) -> dict:
        """JSON-ready: name, setting, spp, denoiser settings, emitter weights (and adaptive sampling when set)."""
        out = {"name": self.name, "setting": self.setting, "spp": int(self.spp),
               "denoise": self.denoise.key_material() if self.denoise.enabled else {"name": "off"},
               "emitter_weights": {k: float(v) for k, v in self.emitter_weights}}
        if self.adaptive is not None:
            out["adaptive"] = self.adaptive.key_material()
        return out


def _weights(text: str, setting: str) -> tuple:
    out = {}
    for part in text.split(","):
        k, eq, v = part.partition("=")
        k = k.strip()
        try:
            check_emitter_weights({k: float(v)})  # the lights and the rule on a weight a Scene applies
        except (ValueError, SceneError):
            valid = False
        else:
            valid = True
        if not eq or not valid or k in out:
            raise RenderError(f"render setting {setting!r}: expected LIGHT=WEIGHT pairs after '+' with LIGHT one of "
                              f"{', '.join(EMITTER_KINDS)} (each once) and WEIGHT > 0, got {part!r}")
        out[k] = float(v)
    return check_emitter_weights(out)


def parse_setting(text: str) -> RenderPreset:
    """A preset name or a setting string -> :class:`RenderPreset`.

    Raises
    ------
    RenderError
        A malformed string (the message shows the form), an unknown denoiser or light, a bad spp.
    """
    text = str(text).strip()
    if text in RENDER_PRESETS:
        return RENDER_PRESETS[text]
    body, tilde, adaptive_text = text.partition("~")
    head, plus, tail = body.partition("+")
    name, at, rest = head.partition("@")
    spp_text, slash, aux_text = rest.partition("/")
    if not at or not spp_text.isdigit() or int(spp_text) < 1 or (slash and not aux_text.isdigit()) or (
            plus and not tail):
        raise RenderError(f"render setting {text!r}: expected a preset ({', '.join(RENDER_PRESETS)}) or "
                          f"DENOISER@SPP[/AUX_SPP][+LIGHT=WEIGHT,...][~xFACTOR:PERCENT%], e.g. oidn@8, "
                          f"oidn@64/1024+sun=16 or oidn-hq@64+sun=16~x4:25%")
    settings = resolve_denoise(name)
    if slash and not settings.enabled:
        raise RenderError(f"render setting {text!r}: an albedo/normal spp needs a denoiser")
    if slash:
        settings = replace(settings, aux_spp=int(aux_text))
    return RenderPreset(name=text, spp=int(spp_text), denoise=settings,
                        emitter_weights=_weights(tail, text) if plus else (),
                        adaptive=parse_adaptive(adaptive_text, text) if tilde else None)


def _preset(name: str, setting: str, summary: str) -> RenderPreset:
    return replace(parse_setting(setting), name=name, summary=summary)


#: The live study's renders until 2026-12: 8 spp, OIDN with a 64-spp albedo/normal pass.
LEGACY_STUDY_PRESET = "study-oidn8"

RENDER_PRESETS: dict[str, RenderPreset] = {}
for _p in (
    _preset(LEGACY_STUDY_PRESET, "oidn@8", "the live study's renders until 2026-12: render noise costs SIFT "
                                           "about 10 points more repeatability than sensor noise"),
    _preset("study-hq", "oidn-hq@256", "render noise no worse for SIFT than sensor noise on forest_winter "
                                          "(docs/results/render.md); about 14x the time of study-oidn8"),
    _preset("study-sun64", "oidn-hq@64+sun=16", "the weighted sun at 64 spp: within 3 points of sensor noise at 8 ms "
                                                 "on the study's scenes, 3-9 points short at 32 ms; about 7x the "
                                                 "time of study-oidn8 (docs/results/render.md)"),
    _preset("study-adaptive", "oidn-hq@64+sun=16~x16:20%@32ms",
            "the weighted sun at 64 spp and 16x the samples where render noise is worst against what 32 ms sees: "
            "render noise within 3 points of sensor noise for SIFT (whole 95 % interval) at 8 and 32 ms on "
            "forest_edge, sun_glare and forest_winter, forest_summer's 32 ms interval reaching -3.9; about 20-29x "
            "the time of study-oidn8 (docs/results/render-clip-2026-12-04.md)"),
    _preset("study-adaptive30", "oidn-hq@64+sun=16~x16:30%@32ms",
            "the live study's default: as study-adaptive with the extra samples on 30 % of the tiles; render noise "
            "within 3 points of sensor noise for SIFT (whole 95 % interval) at 8 and 32 ms on all four study "
            "scenes; about 25-33x the time of study-oidn8 (docs/results/render-clip-2026-12-04.md)"),
):
    RENDER_PRESETS[_p.name] = _p
del _p


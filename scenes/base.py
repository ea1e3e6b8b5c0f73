"""The :class:`Scene` handle, the scene registry and parameter checking.

A :class:`Scene` is cheap: a name, its resolved parameters and a seed.  The
geometry, textures and daylight are built on first use by :meth:`Scene.describe`
(numpy and colour-science) and turned into a Mitsuba dictionary by
:meth:`Scene.mitsuba_dict` (imports Mitsuba).
"""

from __future__ import annotations

import functools
import hashlib
import inspect
import math
import types
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np

from scenes.errors import SceneError

__all__ = ["Scene", "SCENES", "EMITTER_KINDS", "check_emitter_weights", "get_scene", "register_scene", "code_fingerprint"]

#: The lights a scene's emitter weights name (:meth:`Scene.with_emitter_weights`).
EMITTER_KINDS = ("sun", "sky", "area")

#: name -> public builder ``f(seed=0, **params) -> Scene``; filled by scenes.library.
SCENES: dict[str, Callable[..., "Scene"]] = {}

# Modules whose source decides the pixels of a render; their hash is part of the
# render cache key, so editing a scene invalidates its cached renders.
_PIXEL_MODULES = ("textures.py", "texture_base.py", "geometry.py", "lighting.py", "description.py", "library",
                  "mitsuba_objects.py", "camera.py")


@functools.lru_cache(maxsize=1)
def code_fingerprint() -> str:
    """SHA-256 (hex, 16 chars) of the source files that decide a render's pixels."""
    h = hashlib.sha256()
    here = Path(__file__).resolve().parent
    for name in _PIXEL_MODULES:
        paths = sorted((here / name).glob("*.py")) if (here / name).is_dir() else [here / name]
        for path in paths:
            h.update(path.relative_to(here).as_posix().encode())
            h.update(path.read_bytes())
    return h.hexdigest()[:16]


@dataclass(frozen=True, eq=False)
class Scene:
    """A procedural scene: name, parameters, seed.

    Attributes
    ----------
    name : str
        Registry name (a key of :data:`SCENES`).
    params : Mapping
        All parameters, defaults included (JSON-serialisable scalars; read-only,
        ``dict(scene.params)`` for a copy).
    seed : int
        Seed of every random draw of the scene (placement, textures).
    is_static : bool
        True for scenes meant for a fixed camera (``static_lab``).
    start : tuple of float
        (x, y) where the default trajectory starts, metres.
    heading_deg : float
        Default walking direction, degrees from +x towards +y.
    description : str
        One line on what the scene is for.
    emitter_weights : tuple of (str, float)
        How next-event estimation picks a light: relative probabilities of ``"sun"``,
        ``"sky"`` and ``"area"`` (every emitting shape), Mitsuba's ``sampling_weight``;
        empty (the default) is Mitsuba's uniform choice.  They change the render noise, not
        the expected radiance (see :meth:`with_emitter_weights`).
    """

    name: str
    params: Mapping
    seed: int
    is_static: bool
    start: tuple
    heading_deg: float
    description: str = ""
    _describe: Callable = field(default=None, repr=False)
    emitter_weights: tuple = ()

    def __hash__(self) -> int:
        return hash(self.cache_token())

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Scene) and self.cache_token() == other.cache_token()

    def key_material(self) -> dict:
        """Everything about the scene that affects its pixels (JSON-ready).

        ``emitter_weights`` enters only when set, so the keys of uniform sampling are those of
        renders made before the option existed.
        """
        out = {"scene": self.name, "params": dict(sorted(self.params.items())), "seed": int(self.seed),
               "code": code_fingerprint()}
        if self.emitter_weights:
            out["emitter_weights"] = {k: float(v) for k, v in self.emitter_weights}
        return out

    def with_emitter_weights(self, weights: Mapping | None) -> "Scene":
        """This scene with next-event estimation weighted by ``weights`` (None or {}: uniform).

        ``weights`` maps ``"sun"``, ``"sky"`` and ``"area"`` to positive finite numbers (missing
        ones are 1).  Weighting the sun where it dominates the light cuts the noise of sunlit
        surfaces; the expected radiance is the same (an unbiased choice of light).  The built
        description is shared, not built again.

        Raises
        ------
        SceneError
            An unknown emitter name or a weight that is not a positive finite number.
        """
        other = replace(self, emitter_weights=check_emitter_weights(weights, self.name))
        cached = self.__dict__.get("_description")
        if cached is not None:
            object.__setattr__(other, "_description", cached)
        return other

    def cache_token(self) -> str:
        """Short hash of :meth:`key_material`."""
        from scenes.cache import canonical_json

        return hashlib.sha256(canonical_json(self.key_material()).encode()).hexdigest()[:20]

    def describe(self):
        """Build (once) and return the :class:`~scenes.description.SceneDescription`."""
        cached = self.__dict__.get("_description")
        if cached is None:
            cached = self._describe(self.seed, dict(self.params))
            object.__setattr__(self, "_description", cached)
        return cached

    @property
    def reference_radiance(self) -> float:
        """Luminance of a white Lambertian surface facing the main light, W m^-2 sr^-1."""
        return float(self.describe().reference_radiance)

    def mitsuba_dict(self) -> dict:
        """The Mitsuba scene dictionary (imports Mitsuba; a variant must be set)."""
        from scenes.mitsuba_objects import scene_dict

        return scene_dict(self.describe(), dict(self.emitter_weights))

    def default_pose(self, height_m: float = 1.6, pitch_deg: float = -5.0) -> np.ndarray:
        """Camera-to-world pose (4x4, OpenCV camera frame) at the start, looking along the heading."""
        from scenes.trajectory import look_pose

        return look_pose((self.start[0], self.start[1], height_m), self.heading_deg, pitch_deg)

    def trajectory(self, duration_s: float = 30.0, *, seed: int | None = None, walk: str | None = None, **kwargs):
        """Default trajectory: a walk along the heading, or a static camera for static scenes.

        ``walk``: ``"borealhdr"`` (default: turns like the BorealHDR backpack,
        :class:`scenes.walks.GaitWalk`), ``"gentle"`` (:func:`scenes.trajectory.walk`) or
        ``"replay:PATH"`` (a recorded gyro); see :func:`scenes.walks.make_walk`.  Keyword
        arguments go to the walk's builder.  The walk's random stream includes the scene's
        name (``stream``), so two scenes with one seed do not share their motion.
        """
        from scenes import trajectory as tr
        from scenes.walks import DEFAULT_WALK, make_walk

        if self.is_static:
            return tr.static(self.default_pose(), duration_s=duration_s)
        kwargs.setdefault("start", self.start)
        kwargs.setdefault("heading_deg", self.heading_deg)
        kwargs.setdefault("stream", self.name)
        return make_walk(DEFAULT_WALK if walk is None else walk, duration_s,
                         seed=self.seed if seed is None else seed, **kwargs)


def check_emitter_weights(weights: Mapping | None, owner: str = "emitter weights") -> tuple:
    """``weights`` (light -> positive finite number; None or {}: uniform) as the sorted tuple a
    :class:`Scene` holds, weights of 1 left out.

    Raises
    ------
    SceneError
        An unknown light (not in :data:`EMITTER_KINDS`) or a weight that is not a positive finite number;
        the message starts with ``owner``.
    """
    items = []
    for k, v in sorted(dict(weights or {}).items()):
        if k not in EMITTER_KINDS:
            raise SceneError(f"{owner}: unknown emitter {k!r} in emitter weights; valid: {', '.join(EMITTER_KINDS)}")
        if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) or not (
                math.isfinite(float(v)) and float(v) > 0):
            raise SceneError(f"{owner}: emitter weight of {k} must be a positive finite number, got {v!r}")
        if float(v) != 1.0:
            items.append((k, float(v)))
    return tuple(items)


def _check_value(scene: str, key: str, value: Any, default: Any) -> Any:
    if isinstance(default, bool):
        if not isinstance(value, (bool, np.bool_)):
            raise SceneError(f"{scene}: parameter {key} must be a bool, got {value!r}")
        return bool(value)
    if isinstance(default, int):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) and not (
            isinstance(value, float) and value.is_integer()
        ):
            raise SceneError(f"{scene}: parameter {key} must be an integer, got {value!r}")
        return int(value)
    if isinstance(default, float):
        try:
            v = float(value)
        except (TypeError, ValueError):
            raise SceneError(f"{scene}: parameter {key} must be a number, got {value!r}") from None
        if not math.isfinite(v):
            raise SceneError(f"{scene}: parameter {key} must be finite, got {value!r}")
        return v
    return value


def register_scene(
    describe: Callable,
    *,
    is_static: bool = False,
    start: tuple = (0.0, 0.0),
    heading_deg: float = 0.0,
) -> Callable[..., Scene]:
    """Decorator: turn ``_describe(seed, params)`` plus a parameter signature into a builder.

    The decorated function's keyword-only parameters (with defaults) are the
    scene's named parameters; its name is the scene name.  The builder it
    returns validates the parameters and returns a :class:`Scene`.
    """

    def wrap(signature_fn: Callable) -> Callable[..., Scene]:
        name = signature_fn.__name__
        sig = inspect.signature(signature_fn)
        defaults = {k: p.default for k, p in sig.parameters.items() if p.kind is p.KEYWORD_ONLY}

        @functools.wraps(signature_fn)
        def builder(seed: int = 0, **params: Any) -> Scene:
            unknown = sorted(set(params) - set(defaults))
            if unknown:
                raise SceneError(
                    f"{name}: unknown parameter(s) {', '.join(unknown)}; valid: {', '.join(sorted(defaults))}"
                )
            if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
                raise SceneError(f"{name}: seed must be a non-negative integer, got {seed!r}")
            resolved = {k: _check_value(name, k, params.get(k, d), d) for k, d in defaults.items()}
            doc = (signature_fn.__doc__ or "").strip().splitlines()
            return Scene(name=name, params=types.MappingProxyType(resolved), seed=int(seed), is_static=is_static,
                         start=tuple(start), heading_deg=float(heading_deg), description=doc[0] if doc else "",
                         _describe=describe)

        builder.defaults = dict(defaults)
        SCENES[name] = builder
        return builder

    return wrap


def get_scene(name: str, seed: int = 0, **params: Any) -> Scene:
    """Build a :class:`Scene` by name.

    Parameters
    ----------
    name : str
        A key of :data:`SCENES`.
    seed : int
        Seed of the scene's random draws.
    **params
        Named scene parameters (see each builder's docstring).

    Raises
    ------
    SceneError
        Unknown name (the message lists the valid ones) or parameter.
    """
    if name not in SCENES:
        raise SceneError(f"unknown scene {name!r}; valid scenes: {', '.join(sorted(SCENES))}")
    return SCENES[name](seed=seed, **params)

"""The seven built-in AE methods by name: :data:`METHODS`, :func:`make_method`, :func:`accepts_option`."""

from __future__ import annotations

import functools
import inspect
from collections.abc import Callable

import numpy as np

from emulator.autoexposure.base import AutoExposureError, AutoExposureMethod
from emulator.autoexposure.classical import Classical, Fixed
from emulator.autoexposure.kim import Kim2018
from emulator.autoexposure.shim import Shim2014
from emulator.autoexposure.zhang import Zhang2017

__all__ = ["METHODS", "METHOD_NAMES", "make_method", "accepts_option", "seed_option"]


def _classical(percent: int) -> Callable[..., Classical]:
    factory = functools.partial(Classical, percent)
    factory.__doc__ = f"Classical mean-brightness control towards {percent} % of full scale."
    return factory


#: name -> factory(**options) -> method, in the paper's order.
METHODS: dict[str, Callable[..., AutoExposureMethod]] = {
    "fixed": Fixed,
    "classical-30": _classical(30),
    "classical-50": _classical(50),
    "classical-70": _classical(70),
    "shim": Shim2014,
    "zhang": Zhang2017,
    "kim": Kim2018,
}
METHOD_NAMES = tuple(METHODS)


def accepts_option(name: str, option: str) -> bool:
    """Whether the factory of method ``name`` takes the keyword ``option`` (e.g. ``response``)."""
    factory = METHODS[name]
    target = factory.func if isinstance(factory, functools.partial) else factory
    return option in inspect.signature(target).parameters


def seed_option(name: str) -> str | None:
    """The option that seeds the random draws of built-in method ``name`` (its class's ``seed_option``), or None for
    a method that draws no random numbers (or a name that is not a built-in)."""
    factory = METHODS.get(name)
    if factory is None:
        return None
    target = factory.func if isinstance(factory, functools.partial) else factory
    return getattr(target, "seed_option", None)


def make_method(name: str, **options) -> AutoExposureMethod:
    """Build method ``name`` (see ``METHODS``) with keyword options; unknown names are refused."""
    try:
        factory = METHODS[name]
    except KeyError:
        raise AutoExposureError(f"unknown AE method {name!r}; choose one of {', '.join(METHODS)}") from None
    _check_option_types(name, factory, options)
    try:
        return factory(**options)
    except TypeError as exc:
        raise AutoExposureError(f"{name}: bad option ({exc})") from None
    except AutoExposureError as exc:  # a value the method refuses: say which method's option
        text = str(exc)
        raise AutoExposureError(text if text.startswith(f"{name}") else f"{name}: {text}") from None


def _check_option_types(name: str, factory, options) -> None:
    """Options typed by the factory's defaults: an int option takes an int (not 2.9, not true),
    a float option a number (not a bool or text), a bool option a bool, a str option a str."""
    target = factory.func if isinstance(factory, functools.partial) else factory
    try:
        params = inspect.signature(target).parameters
    except (TypeError, ValueError):
        return
    for key, value in options.items():
        p = params.get(key)
        if p is None or p.default is inspect.Parameter.empty:
            continue
        default = p.default
        if default is None:  # typed by the annotation: "float | None", "int | None"
            if value is None:
                continue
            note = str(p.annotation)
            default = 0.0 if "float" in note else 0 if "int" in note else None
            if default is None:
                continue
        is_bool = isinstance(value, (bool, np.bool_))
        if isinstance(default, bool):
            ok, want = is_bool, "true or false"
        elif isinstance(default, int):
            ok, want = isinstance(value, (int, np.integer)) and not is_bool, "an integer"
        elif isinstance(default, float):
            ok, want = isinstance(value, (int, float, np.integer, np.floating)) and not is_bool, "a number"
        elif isinstance(default, str) and key not in ("range_ms",):
            ok, want = isinstance(value, str), "a string"
        else:
            continue
        if not ok:
            raise AutoExposureError(f"{name}.{key} must be {want}, got {value!r}")

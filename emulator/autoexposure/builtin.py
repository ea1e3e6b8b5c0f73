"""The seven built-in AE methods by name: :data:`METHODS`, :func:`make_method`, :func:`accepts_option`."""

from __future__ import annotations

import functools
import inspect
from collections.abc import Callable

from emulator.autoexposure._base import AutoExposureError, AutoExposureMethod
from emulator.autoexposure.classical import Classical, Fixed
from emulator.autoexposure.kim import Kim2018
from emulator.autoexposure.shim import Shim2014
from emulator.autoexposure.zhang import Zhang2017

__all__ = ["METHODS", "METHOD_NAMES", "make_method", "accepts_option"]


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


def make_method(name: str, **options) -> AutoExposureMethod:
    """Build method ``name`` (see ``METHODS``) with keyword options; unknown names are refused."""
    try:
        factory = METHODS[name]
    except KeyError:
        raise AutoExposureError(f"unknown AE method {name!r}; choose one of {', '.join(METHODS)}") from None
    try:
        return factory(**options)
    except TypeError as exc:
        raise AutoExposureError(f"{name}: bad option ({exc})") from None

"""The seven auto-exposure (AE) methods of the BorealHDR benchmark, behind one protocol.

A method has a ``name``, ``reset()`` and ``next_exposure(raw, exposure_ms) -> float``, reading
the raw 12-bit Bayer mosaic (uint16) captured at ``exposure_ms`` and returning the next
exposure in ms (a built-in float).  ``METHODS`` maps each name to a factory taking keyword
options, so ``METHODS["shim"]()`` gives a ready method; :func:`make_method` is the front
function that refuses unknown names.

=================  ==========================  =====================================
name               class                        spec (``specs/ae_methods.md``)
=================  ==========================  =====================================
``fixed``          :class:`Fixed`               section 2
``classical-30``   :class:`Classical` (30 %)    section 1
``classical-50``   :class:`Classical` (50 %)    section 1
``classical-70``   :class:`Classical` (70 %)    section 1
``shim``           :class:`Shim2014`            section 3
``zhang``          :class:`Zhang2017`           section 4 (takes ``response=``)
``kim``            :class:`Kim2018`             section 5 (takes ``seed=``)
=================  ==========================  =====================================

Every factory takes ``mode="paper"`` (default: the method's intent, the reference code's
defects of spec section 7 corrected) or ``mode="borealhdr"`` (the published reference code,
quirks included), and ``range_ms`` (output clamp; off by default in borealhdr mode).

More methods come as plugins (:mod:`emulator.autoexposure.registry`): an import path
``package.module:attr`` or an installed package's entry point in the group
``exposim.methods``; :func:`method_names` lists built-ins and installed plugins.
"""

from __future__ import annotations

import functools
import inspect
from collections.abc import Callable

import numpy as np

from emulator.autoexposure._base import (
    DEFAULT_RANGE_MS,
    MODES,
    AutoExposure,
    AutoExposureError,
    AutoExposureMethod,
    bayer_to_gray_reference,
    to_gray,
)
from emulator.autoexposure.classical import Classical, Fixed
from emulator.autoexposure.hardcases import hard_cases
from emulator.autoexposure.kim import Kim2018
from emulator.autoexposure.shim import Shim2014
from emulator.autoexposure.zhang import Zhang2017

__all__ = [
    "AutoExposure",
    "AutoExposureMethod",
    "AutoExposureError",
    "Classical",
    "Fixed",
    "Shim2014",
    "Zhang2017",
    "Kim2018",
    "METHODS",
    "METHOD_NAMES",
    "MODES",
    "DEFAULT_RANGE_MS",
    "make_method",
    "accepts_option",
    "to_gray",
    "bayer_to_gray_reference",
    "hard_cases",
    "ENTRY_POINT_GROUP",
    "MethodFailed",
    "PluginMethod",
    "installed_methods",
    "method_names",
]


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


from emulator.autoexposure.registry import (  # noqa: E402 - the registry reads METHODS lazily
    ENTRY_POINT_GROUP,
    MethodFailed,
    PluginMethod,
    installed_methods,
)


def method_names(entry_points=None) -> tuple[str, ...]:
    """Built-in method names, then the installed plugins' that load (see :func:`installed_methods`)."""
    plugins = installed_methods(entry_points)
    return METHOD_NAMES + tuple(n for n, p in plugins.items() if p.error is None)

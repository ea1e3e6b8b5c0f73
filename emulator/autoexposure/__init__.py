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

from emulator.autoexposure.base import (
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


from emulator.autoexposure.builtin import METHOD_NAMES, METHODS, accepts_option, make_method
from emulator.autoexposure.registry import (
    ENTRY_POINT_GROUP,
    MethodFailed,
    PluginMethod,
    installed_methods,
)


def method_names(entry_points=None) -> tuple[str, ...]:
    """Built-in method names, then the installed plugins' that load (see :func:`installed_methods`)."""
    plugins = installed_methods(entry_points)
    return METHOD_NAMES + tuple(n for n, p in plugins.items() if p.error is None)

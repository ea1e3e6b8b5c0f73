"""AE method plugins: methods from an import path or from installed packages' entry points.

Besides the seven built-in methods (:data:`emulator.autoexposure.METHODS`), a method is

- an **import path** ``package.module:attr`` (``attr`` may be dotted): a class or factory
  called with keyword options and returning an object with the AE protocol; its name is the
  factory's string attribute ``name`` if it has one, else ``attr``'s last component; or
- an **installed plugin**: an entry point of the group :data:`ENTRY_POINT_GROUP`
  (``exposim.methods``), its name the method's name and its value ``package.module:attr``
  as above.  In ``pyproject.toml``::

      [project.entry-points."exposim.methods"]
      my-ae = "my_pkg.my_module:MyAE"

The protocol (``specs/ae_methods.md`` section 0) is that of the built-ins:
``name``, ``reset()`` and ``next_exposure(raw, exposure_ms) -> float``, ``raw`` an H x W
uint16 12-bit Bayer mosaic (read-only) captured at ``exposure_ms``, the result the next
exposure in ms.  A factory gets, among its keyword parameters (or ``**kwargs``), ``mode``
(``"paper"`` or ``"borealhdr"``), ``range_ms`` (``None``: the closed loop clamps) and
``response`` (the recording's :class:`~emulator.core.response.CameraResponse`) when it takes them,
plus the user's options (``exposim run --option NAME.KEY=VALUE``).  Subclassing
:class:`~emulator.autoexposure.AutoExposureMethod` gives input checks, the gray conversion
and ``config()`` for free, but is not required.

A plugin method runs wrapped in :class:`PluginMethod`: anything it raises, and a result
that is not a finite positive number, raises :class:`MethodFailed`, which the closed loop
(:mod:`emulator.playback`) records as the method's failure at that cycle while the other
methods go on.  Names are checked: a plugin may not take a built-in's name (the error names
both), and names hold only letters, digits, ``-`` and ``_`` (they become folder names and
the ``NAME`` of ``--option NAME.KEY=VALUE``).  A plugin that cannot be imported is kept,
with its error, and reported by name when asked for; it does not affect other methods.
"""

from __future__ import annotations

import functools
import importlib
import inspect
import math
import re
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from importlib import metadata

import numpy as np

from emulator.autoexposure.base import AutoExposureError, MethodFailed
from emulator.autoexposure.builtin import METHODS
from emulator.autoexposure.isolation import call_factory, describe_error as describe, run_isolated
from emulator.autoexposure.probe import probe_entry_points

__all__ = [
    "ENTRY_POINT_GROUP",
    "MethodPlugin",
    "MethodFailed",
    "PluginMethod",
    "installed_methods",
    "load_import_path",
    "is_import_path",
    "check_method_name",
    "takes_option",
    "build_plugin",
]

#: The entry-point group installed packages register AE methods under.
ENTRY_POINT_GROUP = "exposim.methods"
#: What a method name may hold: it names a folder and the NAME of ``--option NAME.KEY=VALUE``.
NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_-]{0,199}$")  # at most 200 characters: a folder name (255 bytes)


@dataclass
class MethodPlugin:
    """One plugin method: its name, where it comes from, its factory or why it cannot load."""

    name: str
    value: str
    factory: Callable | None = None
    error: str | None = None

    @property
    def source(self) -> str:
        return self.value


def is_import_path(text: str) -> bool:
    """Whether a ``--methods`` item is an import path ``module:attr`` (not a method name)."""
    return ":" in text


def check_method_name(name, source: str) -> str:
    """A plugin's name, checked against :data:`NAME_RE` and the built-in names."""
    if not isinstance(name, str) or not NAME_RE.match(name):
        raise AutoExposureError(f"AE method plugin {source}: bad method name {name!r} (letters, digits, '-' and '_' "
                                "only, starting with a letter or digit, at most 200 characters)")
    if name in METHODS:
        builtin = METHODS[name]
        target = builtin.func if isinstance(builtin, functools.partial) else builtin
        raise AutoExposureError(
            f"AE method plugin {source} is named {name!r}, the name of the built-in method {name!r} "
            f"({target.__module__}.{target.__qualname__}); rename the plugin")
    return str.__str__(name)  # its text: a str subclass (an Enum) would print and compare as itself


def load_import_path(path: str) -> Callable:
    """The object at ``package.module:attr`` (``attr`` may be dotted); errors name the path."""
    module_name, _, attr = path.partition(":")
    module_name, attr = module_name.strip(), attr.strip()
    if not module_name or not attr:
        raise AutoExposureError(f"AE method {path!r}: expected an import path package.module:attr")
    try:
        obj = importlib.import_module(module_name)
    except ModuleNotFoundError as exc:
        if exc.name is not None and module_name.split(".")[0] == exc.name.split(".")[0]:  # the plugin itself, not its imports
            raise AutoExposureError(
                f"AE method {path!r}: no module {module_name} on the Python path; run from the folder that holds "
                f"{module_name.split('.')[0]}.py with PYTHONPATH=. (or add its folder to PYTHONPATH), or pip install "
                "its package") from exc
        raise AutoExposureError(f"AE method {path!r}: cannot import {module_name}: {type(exc).__name__}: {exc}") from exc
    except (Exception, SystemExit) as exc:  # report the plugin's own error, by name
        raise AutoExposureError(f"AE method {path!r}: cannot import {module_name}: {type(exc).__name__}: {exc}") from exc
    for part in attr.split("."):
        try:
            obj = getattr(obj, part)
        except AttributeError:
            raise AutoExposureError(f"AE method {path!r}: {module_name} has no attribute {attr!r}") from None
    if not callable(obj):
        raise AutoExposureError(f"AE method {path!r} is not a class or factory (got {type(obj).__name__})")
    return obj


def _default_name(factory: Callable, path: str) -> str:
    name = getattr(factory, "name", None)
    if isinstance(name, str):
        return name
    return path.partition(":")[2].strip().rsplit(".", 1)[-1]


def plugin_from_path(path: str) -> MethodPlugin:
    """A :class:`MethodPlugin` for an import path (raises :class:`AutoExposureError` on failure)."""
    factory = load_import_path(path)
    name = check_method_name(_default_name(factory, path), path)
    return MethodPlugin(name, path, factory)


def _load_entry_points(entry_points: Iterable, *, here: bool = True) -> dict[str, MethodPlugin]:
    """Plugins by name; ``here=False``: their imports checked in another process
    (:mod:`emulator.autoexposure.probe`), none loaded in this one (``factory`` then loads on use)."""
    out: dict[str, MethodPlugin] = {}
    entry_points = list(entry_points)
    probed = {}
    if not here:
        probed = probe_entry_points(list({ep.name: ep for ep in entry_points if NAME_RE.match(ep.name)}.values()))
    for ep in entry_points:
        known = out.get(ep.name)
        if known is not None:
            if known.value != ep.value:
                known.factory = None
                known.error = (f"registered twice, by {known.value} and {ep.value}; uninstall one of the "
                               "packages that provide it")
            continue
        plugin = MethodPlugin(ep.name, ep.value)
        try:
            check_method_name(ep.name, f"{ep.value} (entry point {ep.name!r})")
        except AutoExposureError as exc:
            plugin.error = str(exc)
        else:
            if not here:
                plugin.error = probed.get(ep.name)
            else:
                _load_here(plugin, ep)
        out[ep.name] = plugin
    return out


def _load_here(plugin: MethodPlugin, ep) -> None:
    try:
        plugin.factory = ep.load()
    except (Exception, SystemExit) as exc:  # a broken plugin: keep it, with its error, never swallow it
        plugin.error = f"cannot load {ep.value}: {type(exc).__name__}: {exc}"
    else:
        if not callable(plugin.factory):
            plugin.factory = None
            plugin.error = f"{ep.value} is not a class or factory"


@functools.cache
def _installed() -> dict[str, MethodPlugin]:
    return _load_entry_points(metadata.entry_points(group=ENTRY_POINT_GROUP), here=False)  # imported elsewhere


def installed_methods(entry_points: Iterable | None = None) -> dict[str, MethodPlugin]:
    """Plugin methods by name, broken ones kept with their ``error``.

    ``entry_points`` (e.g. ``[importlib.metadata.EntryPoint(name, value, group)]``) replaces
    the installed ``exposim.methods`` entry points (read once per process otherwise).
    """
    if entry_points is None:
        return dict(_installed())
    return _load_entry_points(entry_points)


def takes_option(factory: Callable, option: str) -> bool:
    """Whether ``factory`` takes the keyword ``option`` (or any keyword, ``**kwargs``)."""
    target = factory.func if isinstance(factory, functools.partial) else factory
    try:
        params = inspect.signature(target).parameters
    except (TypeError, ValueError):  # a builtin without a signature: assume it takes what it is given
        return True
    return option in params or any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values())


def build_plugin(plugin: MethodPlugin, *, mode: str = "paper", response=None,
                 options: Mapping | None = None) -> "PluginMethod":
    """Instantiate a plugin with the user's ``options`` (and ``mode``, ``range_ms=None``,
    ``response`` where its factory takes them), wrapped in :class:`PluginMethod`."""
    if plugin.error is not None:
        raise AutoExposureError(f"AE method plugin {plugin.name!r} is broken: {plugin.error}")
    factory = plugin.factory
    if factory is None:  # listed without being imported here (registry._installed): loaded where it is built
        factory = plugin.factory = load_import_path(plugin.value)
    options = dict(options or {})
    bad = [k for k in options if not takes_option(factory, k)]
    if bad:
        target = factory.func if isinstance(factory, functools.partial) else factory
        try:
            takes = [p for p in inspect.signature(target).parameters if p != "self"]
        except (TypeError, ValueError):
            takes = []
        raise AutoExposureError(f"AE method {plugin.name!r} ({plugin.value}) takes no option "
                                f"{', '.join(map(repr, bad))}; it takes: {', '.join(takes) or 'none'}")
    kwargs = {}
    # a plugin gets its own copy of the response: changing it (its table, levels, LUT cache)
    # cannot change the emulation of the other methods
    for key, value in (("mode", mode), ("range_ms", None), ("response", _private_response(response))):
        if key not in options and _names_param(factory, key):
            kwargs[key] = value
    kwargs.update(options)

    try:
        method = call_factory(factory, plugin.name, plugin.value, **kwargs)  # SystemExit included
    except AutoExposureError as exc:
        raise AutoExposureError(f"{exc} (options {options})") from exc.__cause__
    if not callable(getattr(method, "next_exposure", None)):
        raise AutoExposureError(f"AE method {plugin.name!r} ({plugin.value}) built {type(method).__name__}, which has "
                                "no next_exposure(raw, exposure_ms) method")
    return PluginMethod(method, plugin.name, plugin.value)


def _private_response(response):
    if response is None or not hasattr(response, "g"):
        return response
    import dataclasses

    knots = getattr(response, "knots", None)
    return dataclasses.replace(response, g=np.array(response.g, dtype=np.float64, copy=True),
                               knots=None if knots is None else np.array(knots, copy=True))


def _names_param(factory: Callable, key: str) -> bool:
    """The loop's own keywords (mode, range_ms, response) go only to factories that name them."""
    target = factory.func if isinstance(factory, functools.partial) else factory
    try:
        return key in inspect.signature(target).parameters
    except (TypeError, ValueError):
        return False


def describe_error(exc: BaseException) -> str:
    return describe(exc)


class PluginMethod:
    """A plugin method under the registered name, its results checked.

    ``next_exposure`` raises :class:`MethodFailed` when the plugin raises or returns
    something that is not a finite positive number of milliseconds.  Other attributes
    (``guard_count``, ``last``, ...) are the plugin's.
    """

    #: A plugin gets a private frozen copy of its image at every call (isolation.call_method):
    #: even a write through the data pointer then reaches only its own copy.
    private_images = True

    def __init__(self, method, name: str, source: str) -> None:
        self.method = method
        self.name = name
        self.source = source

    def reset(self) -> None:
        reset = getattr(self.method, "reset", None)
        if callable(reset):
            reset()

    def next_exposure(self, raw: np.ndarray, exposure_ms: float) -> float:
        try:
            value = self.method.next_exposure(raw, exposure_ms)
        except Exception as exc:
            raise MethodFailed(f"raised {type(exc).__name__}: {exc}") from exc
        if isinstance(value, (bool, np.bool_, str, bytes)):  # "12.5" is text, not a number
            raise MethodFailed(f"returned {value!r}, not an exposure in ms")
        try:
            ms = float(value)
        except (TypeError, ValueError):
            raise MethodFailed(f"returned {value!r}, not an exposure in ms") from None
        if math.isnan(ms):
            raise MethodFailed("returned NaN")
        if not math.isfinite(ms):
            raise MethodFailed(f"returned a non-finite exposure ({ms!r} ms)")
        if ms <= 0:
            raise MethodFailed(f"returned a non-positive exposure ({ms!r} ms)")
        return ms

    @property
    def guard_count(self) -> int:
        """The plugin's own fallback count, read isolated: a property that raises or exits
        fails this method alone (MethodFailed), never the run."""
        value = run_isolated(lambda: getattr(self.method, "guard_count", 0), self.name,
                          lambda exc: MethodFailed(f"guard_count: {describe_error(exc)}"))
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
            raise MethodFailed(f"guard_count is {value!r}, not an integer")
        return int(value)

    def config(self) -> dict:
        inner = getattr(type(self.method), "config", None)
        cfg = {}
        if callable(inner):
            try:
                cfg = dict(run_isolated(self.method.config, self.name,
                                     lambda exc: MethodFailed(f"config(): {describe_error(exc)}")))
            except MethodFailed as exc:
                cfg = {"config_error": str(exc)}
            except (TypeError, ValueError) as exc:
                cfg = {"config_error": f"config() returned no mapping: {exc}"}
        cfg["name"] = self.name
        cfg["plugin"] = self.source
        return cfg

    def __getattr__(self, item):
        if item == "method":  # not set yet (copy/pickle): no recursion
            raise AttributeError(item)
        return getattr(self.method, item)

    def __repr__(self) -> str:
        return f"PluginMethod({self.name!r}, {self.source!r})"

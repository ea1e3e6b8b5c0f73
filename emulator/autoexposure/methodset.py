"""Choosing AE methods by name: ``"all"``, built-in names, installed plugins and import paths.

:func:`parse_methods` checks a ``--methods`` value; :func:`build_methods` instantiates the
methods a closed loop runs (:func:`emulator.playback.iter_run`, the live loop of
:mod:`validation.live`).  Plugins are found by :mod:`emulator.autoexposure.registry`.
"""

from __future__ import annotations

from collections.abc import Mapping

from emulator.autoexposure import METHOD_NAMES, AutoExposureMethod, accepts_option, make_method
from emulator.autoexposure.registry import build_plugin, installed_methods, is_import_path, plugin_from_path
from emulator.errors import PlaybackError

__all__ = ["parse_methods", "build_methods", "latency_options"]


def parse_methods(spec, *, plugins: Mapping | None = None) -> list[str]:
    """``"all"``, ``"m1,m2"`` or an iterable of names -> list of method names (checked, no repeats).

    An item is a built-in name (``all``: the seven built-ins), the name of an installed plugin
    (``plugins``: :func:`emulator.autoexposure.registry.installed_methods`, by default the
    installed ones) or an import path ``package.module:attr`` (loaded by :func:`build_methods`).
    """
    if isinstance(spec, str):
        items = [s.strip() for s in spec.split(",") if s.strip()]
        names = [n for item in items for n in (METHOD_NAMES if item == "all" else (item,))]
    else:
        names = list(spec)
    if not names:
        raise PlaybackError("no AE method given; use 'all' or a comma-separated list of: " + ", ".join(METHOD_NAMES))
    asked = [n for n in names if isinstance(n, str) and n not in METHOD_NAMES and not is_import_path(n)]
    if asked:
        plugins = installed_methods() if plugins is None else plugins
        broken = [f"{n!r} ({plugins[n].error})" for n in asked if n in plugins and plugins[n].error is not None]
        if broken:
            raise PlaybackError(f"broken AE method plugin(s): {'; '.join(broken)}")
        bad = [n for n in asked if n not in plugins]
        if bad:
            choices = list(METHOD_NAMES) + [n for n, p in plugins.items() if p.error is None]
            raise PlaybackError(f"unknown AE method(s) {', '.join(map(repr, bad))}; choose from {', '.join(choices)} "
                                "or give an import path package.module:attr")
    dup = {n for n in names if isinstance(n, str) and names.count(n) > 1}
    if dup:
        raise PlaybackError(f"AE method(s) given twice: {', '.join(sorted(dup))}")
    return names


def build_methods(spec, *, mode: str = "paper", response=None, options: Mapping | None = None,
                  plugins: Mapping | None = None) -> dict[str, AutoExposureMethod]:
    """Instantiate methods by name (or pass instances through), keyed by their name.

    ``options`` maps a method name to keyword options for its factory; ``mode`` is the
    default mode; ``response`` goes to the factories that accept it (zhang).  Methods built
    here have no clamp of their own (``range_ms=None``): the loop clamps.  Plugin methods
    (an installed plugin's name from ``plugins``, or an import path ``package.module:attr``;
    see :func:`parse_methods`) come wrapped in
    :class:`~emulator.autoexposure.registry.PluginMethod`, under their plugin name.
    """
    options = dict(options or {})
    if isinstance(spec, str):
        spec = parse_methods(spec, plugins=plugins)
    spec = list(spec)
    resolved: dict[int, object] = {}
    for i, item in enumerate(spec):
        if isinstance(item, str) and item not in METHOD_NAMES:
            if is_import_path(item):
                resolved[i] = plugin_from_path(item)
            else:
                parse_methods([item], plugins=plugins)
                plugins = installed_methods() if plugins is None else plugins
                resolved[i] = plugins[item]
    known = set(METHOD_NAMES) | {p.name for p in resolved.values()}
    unknown = set(options) - known
    if unknown:
        raise PlaybackError(f"options given for unknown method(s): {', '.join(sorted(unknown))}")
    out: dict[str, AutoExposureMethod] = {}
    for i, item in enumerate(spec):
        if i in resolved:
            plugin = resolved[i]
            method = build_plugin(plugin, mode=mode, response=response, options=options.get(plugin.name))
            name = plugin.name
        elif isinstance(item, str):
            parse_methods([item])
            opts = dict(options.get(item, {}))
            opts.setdefault("mode", mode)
            opts.setdefault("range_ms", None)
            if accepts_option(item, "response"):
                opts.setdefault("response", response)
            method = make_method(item, **opts)
            name = item
        else:
            method = item
            name = getattr(item, "name", None)
            if not name or not callable(getattr(item, "next_exposure", None)):
                raise PlaybackError(f"{item!r} is neither a method name nor an AE method (name, next_exposure)")
        if name in out:
            raise PlaybackError(f"two methods are named {name!r}")
        out[name] = method
    return out


def latency_options(options: Mapping | None, latency_frames: int) -> dict:
    """``options`` with the camera's exposure latency (frames) given to the methods that need it.

    At a latency of L > 0 frames (``--rate native``) two or more proposals are in flight when
    ``fixed`` freezes; it gets ``latency_frames=L`` (unless the user set it) so that it freezes one
    exposure (:class:`~emulator.autoexposure.classical.Fixed`).  At L = 0 (cycle rate) the options
    are returned as given.
    """
    out = {name: dict(opts) for name, opts in (options or {}).items()}
    if int(latency_frames) > 0:
        out.setdefault("fixed", {}).setdefault("latency_frames", int(latency_frames))
    return out

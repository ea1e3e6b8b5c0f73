"""Optional extras: which feature needs which, and one-line errors when one is missing.

exposim's core (numpy, OpenCV, scipy, evo, ...) is what emulating real recordings needs.
Two extras add the rest:

* ``synth``: the synthetic layer (Mitsuba 3, Dr.Jit, OpenEXR, colour-science, Open Image
  Denoise) used by ``exposim render``, ``synth``, ``validate`` and ``demo``;
* ``dask``: ``dask[distributed]``, for ``--scheduler local|tcp://...|tls://...`` and
  ``--scheduler-file``.

``pip install 'exposim[all]'`` installs both.  :func:`require` checks that an extra's
modules can be imported without importing them, so a command can refuse before it
creates any output; :func:`missing_extra_message` turns a :class:`ModuleNotFoundError`
raised deep inside a command into the same one line.
"""

from __future__ import annotations

import importlib.util

from emulator.errors import MissingExtraError

__all__ = ["EXTRAS", "MODULE_EXTRA", "require", "missing_modules", "extra_of", "missing_extra_message"]

#: The importable modules each extra provides that the code needs (pyoidn is optional even
#: within ``synth``: without it renders fall back to the raw estimate, with a warning).
EXTRAS: dict[str, tuple[str, ...]] = {
    "synth": ("mitsuba", "drjit", "OpenEXR", "colour"),
    "dask": ("dask", "distributed"),
}

#: Top-level module name -> the extra that installs it.
MODULE_EXTRA: dict[str, str] = {
    "mitsuba": "synth", "drjit": "synth", "OpenEXR": "synth", "Imath": "synth", "colour": "synth",
    "pyoidn": "synth", "dask": "dask", "distributed": "dask",
}


def _importable(name: str) -> bool:
    try:
        return importlib.util.find_spec(name) is not None
    except (ImportError, ValueError):  # a parent package that fails to import, or a broken __spec__
        return False


def missing_modules(extra: str) -> list[str]:
    """The modules of ``extra`` that cannot be imported (empty when the extra is installed)."""
    if extra not in EXTRAS:
        raise ValueError(f"unknown extra {extra!r}; known: {', '.join(EXTRAS)}")
    return [name for name in EXTRAS[extra] if not _importable(name)]


def _message(extra: str, module: str, what: str | None) -> str:
    head = f"{what} needs the '{extra}' extra" if what else f"the '{extra}' extra is not installed"
    return f"{head} (no module {module}): pip install 'exposim[{extra}]'"


def require(extra: str, what: str | None = None) -> None:
    """Raise :class:`MissingExtraError` (one line naming the extra) when ``extra`` is not installed.

    >>> require("no-such-extra")
    Traceback (most recent call last):
    ...
    ValueError: unknown extra 'no-such-extra'; known: synth, dask
    """
    missing = missing_modules(extra)
    if missing:
        raise MissingExtraError(_message(extra, missing[0], what))


def extra_of(exc: BaseException) -> str | None:
    """The extra whose module ``exc`` (a :class:`ModuleNotFoundError`) failed to import, else None."""
    if not isinstance(exc, ModuleNotFoundError) or not exc.name:
        return None
    return MODULE_EXTRA.get(exc.name.split(".", 1)[0])


def missing_extra_message(exc: BaseException, what: str | None = None) -> str | None:
    """The one-line message for a :class:`ModuleNotFoundError` of an extra's module, else None."""
    extra = extra_of(exc)
    if extra is None:
        return None
    return _message(extra, exc.name.split(".", 1)[0], what)

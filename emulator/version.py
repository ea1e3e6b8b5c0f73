"""The installed version of exposim, from the package metadata (pyproject.toml is the one source)."""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

__all__ = ["__version__", "DISTRIBUTION"]

#: The distribution name (``pip install exposim``).
DISTRIBUTION = "exposim"

try:
    __version__ = version(DISTRIBUTION)
except PackageNotFoundError:  # a source tree that was never installed
    __version__ = "0+unknown"

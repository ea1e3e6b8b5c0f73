"""OpenEXR radiance images (float32, linear), reader and writer.

Written with ZIP compression (lossless), scanlines, one channel ``"RGB"`` for (H, W, 3)
radiance or ``"Y"`` for (H, W); the same array and attributes give the same bytes, so a
render cache can compare files.  OpenEXR is imported when a file is read or written.
"""

from __future__ import annotations

import io
import os
from pathlib import Path

import numpy as np

from emulator.errors import DatasetError
from emulator.io.files import atomic_write_bytes

__all__ = ["write_exr", "read_exr", "read_exr_attributes"]


def write_exr(
    path: str | os.PathLike,
    radiance: np.ndarray,
    *,
    overwrite: bool = False,
    attributes: dict | None = None,
) -> Path:
    """Write float32 radiance, (H, W, 3) as ``"RGB"`` or (H, W) as ``"Y"``, atomically.

    ``attributes`` are extra string header attributes (e.g. a render-cache key).
    """
    import OpenEXR

    radiance = np.ascontiguousarray(radiance, dtype=np.float32)
    if not (radiance.ndim == 2 or (radiance.ndim == 3 and radiance.shape[2] == 3)):
        raise DatasetError(f"{path}: radiance must be (H, W) or (H, W, 3), got shape {radiance.shape}")
    channels = {"RGB": radiance} if radiance.ndim == 3 else {"Y": radiance}
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    for key, value in (attributes or {}).items():
        header[str(key)] = str(value)
    buf = io.BytesIO()
    OpenEXR.File(header, channels).write(buf)
    return atomic_write_bytes(path, buf.getvalue(), overwrite=overwrite)


def read_exr(path: str | os.PathLike) -> np.ndarray:
    """Read radiance: float32 (H, W, 3) from ``"RGB"`` or ``"R"``, ``"G"``, ``"B"``, or (H, W) from ``"Y"``.

    Raises FileNotFoundError for a missing file and :class:`DatasetError` naming the file
    for one that is not a readable OpenEXR radiance image.
    """
    import OpenEXR

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: EXR file not found")
    try:
        with OpenEXR.File(str(path)) as f:
            channels = f.channels()
            if "RGB" in channels:
                a = channels["RGB"].pixels
            elif all(c in channels for c in "RGB"):
                a = np.stack([channels[c].pixels for c in "RGB"], axis=-1)
            elif "Y" in channels:
                a = channels["Y"].pixels
            else:
                raise DatasetError(f"{path}: expected an 'RGB' or 'Y' channel, found {', '.join(channels)}")
    except (KeyError, RuntimeError, OSError, ValueError) as exc:
        if isinstance(exc, DatasetError):
            raise
        raise DatasetError(f"{path}: not a readable OpenEXR file ({exc})") from exc
    return np.ascontiguousarray(a, dtype=np.float32)


def read_exr_attributes(path: str | os.PathLike) -> dict:
    """The header attributes of an OpenEXR file (the render cache's key and checksum among them).

    Raises :class:`DatasetError` naming the file for one that is not a readable OpenEXR file.
    """
    import OpenEXR

    path = Path(path)
    try:
        # not as a context manager: its __enter__ gives an empty header in some processes
        return dict(OpenEXR.File(str(path), header_only=True).header())
    except (RuntimeError, OSError, ValueError) as exc:
        raise DatasetError(f"{path}: not a readable OpenEXR file ({exc})") from exc

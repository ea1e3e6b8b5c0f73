"""PNG images: 16-bit Bayer frames (12-bit DN in ``uint16``) and 8-bit viewable images.

* :func:`read_png16` / :func:`decode_png16` / :func:`write_png16`: single-channel 16-bit
  PNGs holding raw DN (BorealHDR frames, calibration stacks, ``--save png16`` run images,
  emulated images).  Reading checks dtype, channels and, when given, the white level.
* :func:`write_png8`: an 8-bit image for viewers (``--save png8``): grey (H, W) or BGR
  (H, W, 3) ``uint8``; the conversion from DN is :func:`emulator.core.gray.bayer_to_gray8`.
* :func:`read_image`: a run image as saved, ``uint16`` mosaic or ``uint8`` grey.

Encoding uses OpenCV with compression level 1 (fast; the same array gives the same bytes),
written atomically (:func:`emulator.io.files.atomic_write_bytes`).
"""

from __future__ import annotations

import os
from pathlib import Path

import cv2
import numpy as np

from emulator.errors import DatasetError
from emulator.io.files import atomic_write_bytes
from emulator.io.crc import crc32

__all__ = ["decode_png16", "read_png16", "write_png16", "write_png8", "read_image", "encode_png", "white_level_message"]


def _read_bytes(path: Path) -> bytes:
    if not path.is_file():
        raise FileNotFoundError(f"{path}: image not found")
    return path.read_bytes()


PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def png_structure_problem(data: bytes) -> str | None:
    """What is wrong with a PNG's chunk structure (lengths, CRCs, IHDR first, image data, IEND last), or None.

    Checked before decoding so that a damaged file is one clear error, without the lines
    libpng prints on stderr.  Costs one CRC pass over the file (zlib-ng's: about 0.02 ms per MB; zlib's: 0.23).
    """
    import struct

    view = memoryview(data)  # slices without copies
    unpack = struct.unpack_from
    pos, n = 8, len(data)
    first, idat = True, False
    while pos + 12 <= n:
        length, ctype = unpack(">I4s", data, pos)
        end = pos + 12 + length
        if end > n:
            return f"chunk {ctype.decode('latin-1')!r} runs past the end of the file"
        if crc32(view[pos + 4:pos + 8 + length]) != unpack(">I", data, end - 4)[0]:
            return f"CRC error in chunk {ctype.decode('latin-1')!r}"
        if first and ctype != b"IHDR":
            return "first chunk is not IHDR"
        first = False
        idat = idat or ctype == b"IDAT"
        if ctype == b"IEND":
            return None if idat else "no IDAT chunk (the image data is missing)"
        pos = end
    return "no IEND chunk (truncated)"


def decode_png16(data: bytes, name: str | os.PathLike, *, white_level: int | None = None) -> np.ndarray:
    """Decode the bytes of a 16-bit single-channel PNG holding 12-bit DN.

    ``name`` (a path or archive member) is used in the messages; raises
    :class:`DatasetError` for corrupt data, an 8-bit or colour image, or a DN above
    ``white_level``.
    """
    buf = np.frombuffer(data, dtype=np.uint8)
    problem = png_structure_problem(data) if data[:8] == PNG_SIGNATURE else None
    if problem is not None:  # refused before libpng sees it: no "libpng error:" line on stderr
        raise DatasetError(f"{name}: cannot decode image (corrupt or truncated PNG: {problem}, {buf.size} bytes)")
    img = cv2.imdecode(buf, cv2.IMREAD_UNCHANGED) if buf.size else None
    if img is None:
        raise DatasetError(f"{name}: cannot decode image (corrupt or truncated PNG, {buf.size} bytes)")
    if img.dtype != np.uint16:
        raise DatasetError(
            f"{name}: expected a 16-bit PNG holding 12-bit DN, got {img.dtype} "
            f"({'8-bit' if img.dtype == np.uint8 else 'other'} image)"
        )
    if img.ndim != 2:
        raise DatasetError(f"{name}: expected a single-channel Bayer mosaic, got shape {img.shape}")
    if white_level is not None:
        top = int(img.max())
        if top > white_level:
            raise DatasetError(white_level_message(name, top, white_level))
    return img


def white_level_message(name, top: int, white_level: int) -> str:
    """Why an image's DN above the white level is refused, and the fix.

    >>> white_level_message("a.png", 4095, 4094)  # doctest: +ELLIPSIS
    'a.png: maximum DN 4095 exceeds the white level 4094 (...--white-level 4095...'
    """
    if top <= 4095:
        return (f"{name}: maximum DN {top} exceeds the white level {white_level} (the default is BorealHDR's 4094, "
                f"where its sensor saturates); for full-range 12-bit data give the camera's white level: "
                f"--white-level 4095 (exposim calibrate) or \"white_level\": 4095 in the recording's or stack's "
                "exposim.json")
    return (f"{name}: maximum DN {top} exceeds 4095: not 12-bit data (exposim reads 12-bit DN in 16-bit PNGs; "
            f"white level {white_level})")


def read_png16(path: str | os.PathLike, *, white_level: int | None = None) -> np.ndarray:
    """Read a 16-bit single-channel PNG holding 12-bit DN (see :func:`decode_png16`)."""
    path = Path(path)
    return decode_png16(_read_bytes(path), path, white_level=white_level)


#: zlib level of written PNGs unless a writer says otherwise.
DEFAULT_PNG_LEVEL = 1


def encode_png(image: np.ndarray, name: str | os.PathLike = "image", *, level: int = DEFAULT_PNG_LEVEL) -> bytes:
    """PNG bytes of a ``uint16`` or ``uint8`` image.

    ``level`` is the zlib level, 0..9: 0 stores the rows unfiltered and uncompressed (about
    40x faster to encode than level 1, files larger: +22 % for a 12-bit Bayer mosaic, +70 %
    for 8-bit grey on the BorealHDR sample); the decoded image is the same for any level.
    """
    if isinstance(level, bool) or not isinstance(level, (int, np.integer)) or not 0 <= level <= 9:
        raise DatasetError(f"{name}: PNG level must be an integer 0..9, got {level!r}")
    params = [cv2.IMWRITE_PNG_COMPRESSION, int(level)]
    if level == 0:
        params += [cv2.IMWRITE_PNG_FILTER, cv2.IMWRITE_PNG_FILTER_NONE]
    ok, buf = cv2.imencode(".png", np.ascontiguousarray(image), params)
    if not ok:  # pragma: no cover - OpenCV failure
        raise DatasetError(f"{name}: PNG encoding failed")
    return buf.tobytes()


def write_png16(path: str | os.PathLike, image: np.ndarray, *, overwrite: bool = False,
                level: int = DEFAULT_PNG_LEVEL) -> Path:
    """Write a 2-D ``uint16`` image (DN) as a 16-bit PNG, atomically."""
    image = np.asarray(image)
    if image.dtype != np.uint16 or image.ndim != 2:
        raise DatasetError(f"{path}: a 16-bit PNG needs a 2-D uint16 image, got {image.dtype} {image.shape}")
    return atomic_write_bytes(path, encode_png(image, path, level=level), overwrite=overwrite)


def write_png8(path: str | os.PathLike, image: np.ndarray, *, overwrite: bool = False,
               level: int = DEFAULT_PNG_LEVEL) -> Path:
    """Write a viewable 8-bit PNG: (H, W) grey or (H, W, 3) BGR ``uint8``, atomically."""
    image = np.asarray(image)
    if image.dtype != np.uint8 or not (image.ndim == 2 or (image.ndim == 3 and image.shape[2] == 3)):
        raise DatasetError(f"{path}: an 8-bit PNG needs a (H, W) or (H, W, 3) uint8 image, got {image.dtype} "
                           f"{image.shape}")
    return atomic_write_bytes(path, encode_png(image, path, level=level), overwrite=overwrite)


def read_image(path: str | os.PathLike) -> np.ndarray:
    """A saved image as stored: (H, W) ``uint16`` mosaic, (H, W) ``uint8`` grey or (H, W, 3) BGR.

    Raises FileNotFoundError for a missing file and :class:`DatasetError` for one that is
    not a decodable image.
    """
    path = Path(path)
    buf = np.frombuffer(_read_bytes(path), dtype=np.uint8)
    img = cv2.imdecode(buf, cv2.IMREAD_UNCHANGED) if buf.size else None
    if img is None:
        raise DatasetError(f"{path}: cannot decode image (corrupt or not a PNG)")
    return img

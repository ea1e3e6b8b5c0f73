"""Where a recording's files are read from: the :class:`FileSource` protocol the BorealHDR scan
(:mod:`emulator.io.borealhdr`) lists folders and reads bytes through, a folder
(:class:`FolderSource`) and a BorealHDR trajectory zip read in place (:class:`ZipSource`: members
are read into memory, nothing is unpacked).  :mod:`emulator.io.borealhdr` re-exports these names.
"""

from __future__ import annotations

import os
import threading
import zipfile
import zlib
from pathlib import Path, PurePosixPath
from typing import Protocol

from emulator.errors import DatasetError

__all__ = [
    "CAMERA_FOLDERS",
    "FileSource",
    "FolderSource",
    "ZipSource",
]

#: Camera name -> folder of the layout.
CAMERA_FOLDERS = {"left": "camera_left", "right": "camera_right"}


class FileSource(Protocol):
    """Where a recording's files are: the scan lists folders and reads bytes through this.

    Paths are full paths under :attr:`root` (for a folder: ordinary paths; an archive
    source maps them to its members), so messages name files the same way for any source.
    """

    root: Path

    def is_dir(self, path: Path) -> bool: ...

    def is_file(self, path: Path) -> bool: ...

    def listdir(self, path: Path) -> list[Path]:
        """Children of a folder, sorted by name."""
        ...

    def read_bytes(self, path: Path) -> bytes: ...

    # Optional: ``read_head(path, n) -> bytes``, the first ``n`` bytes (the scan reads PNG
    # headers through it; a source without it is read whole, see :func:`_read_head`).


class FolderSource:
    """A recording in a folder of the file system."""

    def __init__(self, root: str | os.PathLike) -> None:
        self.root = Path(root)

    def is_dir(self, path: Path) -> bool:
        return Path(path).is_dir()

    def is_file(self, path: Path) -> bool:
        return Path(path).is_file()

    def listdir(self, path: Path) -> list[Path]:
        return sorted(Path(path).iterdir())

    def read_bytes(self, path: Path) -> bytes:
        path = Path(path)
        if path.is_dir():
            raise DatasetError(f"{path}: is a folder, expected an image file <timestamp_ns>.png")
        if not path.is_file():
            raise FileNotFoundError(f"{path}: image not found")
        return path.read_bytes()

    def read_head(self, path: Path, n: int) -> bytes:
        """The first ``n`` bytes of a file (a PNG's signature and IHDR chunk)."""
        try:
            fd = os.open(path, os.O_RDONLY)  # unbuffered: ~2x faster than open() for 24 bytes
            try:
                return os.read(fd, n)
            finally:
                os.close(fd)
        except IsADirectoryError:
            raise DatasetError(f"{path}: is a folder, expected an image file <timestamp_ns>.png") from None

    def __repr__(self) -> str:
        return f"FolderSource({str(self.root)!r})"


class ZipSource:
    """A recording inside a zip archive (a BorealHDR trajectory zip), read without unpacking.

    The recording is the one folder of the archive that holds ``camera_left/`` and/or
    ``camera_right/``, under whatever folder prefix (``backpack_.../camera_left/...`` or
    ``camera_left/...`` at the top); its ``imu/imu.csv`` is read (:mod:`emulator.io.imu`),
    everything else the archive carries (lidar, ...) is ignored, as are ``__MACOSX/`` and hidden members.  Paths are ``<zip>/<relative
    path>`` (:attr:`root` is the zip file), so messages name a member as
    ``/data/backpack.zip/camera_left/8.0/123.png``.  Raises :class:`DatasetError` naming the
    zip for an unreadable (corrupt) archive, an archive without a recording, or one with
    more than one recording.
    """

    def __init__(self, path: str | os.PathLike) -> None:
        self.root = Path(path)
        try:
            self._zip = zipfile.ZipFile(self.root)
            names = self._zip.namelist()
        except (zipfile.BadZipFile, zipfile.LargeZipFile, OSError, EOFError, ValueError) as exc:
            raise DatasetError(f"{self.root}: not a readable zip archive ({exc})") from None
        self._lock = threading.Lock()
        prefixes: set[tuple[str, ...]] = set()
        for name in names:
            parts = tuple(p for p in PurePosixPath(name).parts if p not in ("", "/"))
            if not parts or parts[0] == "__MACOSX" or any(p.startswith(".") for p in parts):
                continue
            for i, part in enumerate(parts[:-1]):
                if part in CAMERA_FOLDERS.values():
                    prefixes.add(parts[:i])
                    break
        if not prefixes:
            raise DatasetError(f"{self.root}: the zip holds no camera_left/ or camera_right/ folder "
                               "(not a BorealHDR trajectory zip)")
        if len(prefixes) > 1:
            shown = ", ".join(sorted("/".join(p) + "/" if p else "(top level)" for p in prefixes))
            raise DatasetError(f"{self.root}: the zip holds {len(prefixes)} recordings ({shown}); expected one "
                               "recording per zip")
        (self.prefix,) = prefixes
        n = len(self.prefix)
        self._members: dict[tuple[str, ...], str] = {}
        self._children: dict[tuple[str, ...], set[str]] = {(): set()}
        for name in names:
            parts = tuple(p for p in PurePosixPath(name).parts if p not in ("", "/"))
            if len(parts) <= n or parts[:n] != self.prefix or parts[0] == "__MACOSX":
                continue
            rel = parts[n:]
            for k in range(len(rel)):
                self._children.setdefault(rel[:k], set()).add(rel[k])
                if k < len(rel) - 1 or name.endswith("/"):
                    self._children.setdefault(rel[:k + 1], set())
            if not name.endswith("/"):
                self._members[rel] = name

    def _rel(self, path) -> tuple[str, ...] | None:
        try:
            return Path(path).relative_to(self.root).parts
        except ValueError:
            return None

    def is_dir(self, path: Path) -> bool:
        rel = self._rel(path)
        return rel is not None and rel in self._children and rel not in self._members

    def is_file(self, path: Path) -> bool:
        return self._rel(path) in self._members

    def listdir(self, path: Path) -> list[Path]:
        rel = self._rel(path)
        return [Path(path) / c for c in sorted(self._children.get(rel, ()))]

    def read_bytes(self, path: Path) -> bytes:
        rel = self._rel(path)
        if rel not in self._members:
            raise FileNotFoundError(f"{path}: not found in {self.root.name}")
        try:
            with self._lock:
                return self._zip.read(self._members[rel])
        except (zipfile.BadZipFile, zlib.error, EOFError, OSError) as exc:
            raise DatasetError(f"{path}: corrupt member of zip {self.root} ({exc})") from None

    def read_head(self, path: Path, n: int) -> bytes:
        """The first ``n`` bytes of a member, or ``b""`` for a damaged one (the size check then
        skips it, and :meth:`read_bytes` names it when the frame is decoded)."""
        rel = self._rel(path)
        if rel not in self._members:
            raise FileNotFoundError(f"{path}: not found in {self.root.name}")
        try:
            with self._lock, self._zip.open(self._members[rel]) as fh:
                return fh.read(n)
        except (zipfile.BadZipFile, zlib.error, EOFError, OSError):
            return b""

    def close(self) -> None:
        self._zip.close()

    def __repr__(self) -> str:
        return f"ZipSource({str(self.root)!r})"

"""TUM trajectory files: ``timestamp_s tx ty tz qx qy qz qw`` per line, as evo reads them.

One convention for every pose exposim writes (VO estimates, synthetic ground truth,
render trajectories):

* poses are 4x4 camera-to-world transforms, metres;
* the timestamp is integer nanoseconds written as exact decimal seconds (9 decimals);
* the quaternion is in (x, y, z, w) order, unit length, with **qw >= 0** (q and -q are the
  same rotation; for qw == 0 the first non-zero of x, y, z is made positive), so one pose
  always gives the same line;
* every number is written at full precision (shortest round-trip ``repr``), ``-0.0`` as
  ``0.0``.

:func:`read_tum` parses a file exactly as ``evo.tools.file_interface`` does (``float`` of
each field, quaternions kept as written) and also gives the timestamps as exact integer
nanoseconds.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from emulator.errors import TrajectoryError
from emulator.io.files import atomic_write_bytes, format_timestamp_s

__all__ = ["TumTrajectory", "rotation_to_quaternion", "format_tum_line", "write_tum", "read_tum",
           "read_tum_comments",
           "parse_timestamp_ns"]


def rotation_to_quaternion(rotation: np.ndarray) -> np.ndarray:
    """(x, y, z, w) unit quaternion of a 3x3 rotation, in the canonical sign (qw >= 0).

    >>> rotation_to_quaternion(np.diag([1.0, -1.0, -1.0])).tolist()   # 180 deg about x
    [1.0, 0.0, 0.0, 0.0]
    >>> rotation_to_quaternion(np.diag([-1.0, 1.0, -1.0])).tolist()   # 180 deg about y
    [0.0, 1.0, 0.0, 0.0]
    """
    from scipy.spatial.transform import Rotation

    q = Rotation.from_matrix(np.asarray(rotation, dtype=np.float64)).as_quat()
    if q[3] < 0 or (q[3] == 0 and q[np.flatnonzero(q[:3])[0]] < 0):
        q = -q
    return q + 0.0  # no negative zeros


def _number(v: float) -> str:
    v = float(v) + 0.0
    if not math.isfinite(v):
        raise TrajectoryError(f"non-finite pose value {v!r}")
    return repr(v)


def format_tum_line(timestamp_ns: int, pose: np.ndarray) -> str:
    """One TUM line (no newline) for a camera-to-world pose at ``timestamp_ns``."""
    pose = np.asarray(pose, dtype=np.float64)
    if pose.shape != (4, 4):
        raise TrajectoryError(f"a pose must be a 4x4 matrix, got shape {pose.shape}")
    q = rotation_to_quaternion(pose[:3, :3])
    return format_timestamp_s(timestamp_ns) + " " + " ".join(_number(v) for v in (*pose[:3, 3], *q))


def write_tum(
    path: str | os.PathLike, timestamps_ns: Sequence[int], poses: np.ndarray, *, overwrite: bool = True,
    header: str | None = None,
) -> Path:
    """Write (N, 4, 4) camera-to-world poses at integer-ns timestamps as a TUM file (atomic).

    ``header``: comment lines written first, each prefixed with ``# `` (evo and
    :func:`read_tum` skip lines that start with ``#``).
    """
    poses = np.asarray(poses, dtype=np.float64)
    if poses.ndim != 3 or poses.shape[1:] != (4, 4) or poses.shape[0] != len(timestamps_ns):
        raise TrajectoryError(f"{path}: need (N, 4, 4) poses for N = {len(timestamps_ns)} timestamps, "
                              f"got {poses.shape}")
    text = "".join(format_tum_line(int(t), p) + "\n" for t, p in zip(timestamps_ns, poses))
    if header:
        text = "".join(f"# {line}\n" for line in header.splitlines()) + text
    return atomic_write_bytes(path, text.encode(), overwrite=overwrite)


def parse_timestamp_ns(token: str) -> int:
    """Decimal seconds to integer nanoseconds, exactly for up to 9 decimals.

    >>> parse_timestamp_ns("1695668703.364771328"), parse_timestamp_ns("2.5"), parse_timestamp_ns("1e-9")
    (1695668703364771328, 2500000000, 1)
    """
    t = token.strip()
    sign = -1 if t.startswith("-") else 1
    body = t.lstrip("+-")
    whole, dot, frac = body.partition(".")
    if whole.isdigit() and (not frac or frac.isdigit()) and len(frac) <= 9 and (whole or frac):
        return sign * (int(whole or "0") * 1_000_000_000 + int((frac or "0").ljust(9, "0")))
    return int(round(float(t) * 1e9))


@dataclass(frozen=True)
class TumTrajectory:
    """The content of a TUM file.

    Attributes
    ----------
    path : pathlib.Path
    timestamps_s : numpy.ndarray
        (N,) float64 seconds (``float`` of the text, as evo reads it).
    timestamps_ns : numpy.ndarray
        (N,) int64 nanoseconds (exact for up to 9 decimals).
    positions : numpy.ndarray
        (N, 3) float64, metres.
    quaternions_xyzw : numpy.ndarray
        (N, 4) float64 as written (not renormalised).
    """

    path: Path
    timestamps_s: np.ndarray
    timestamps_ns: np.ndarray
    positions: np.ndarray
    quaternions_xyzw: np.ndarray

    def __len__(self) -> int:
        return int(self.timestamps_s.size)

    @property
    def poses(self) -> np.ndarray:
        """(N, 4, 4) camera-to-world transforms (quaternions normalised)."""
        from scipy.spatial.transform import Rotation

        out = np.tile(np.eye(4), (len(self), 1, 1))
        if len(self):
            out[:, :3, :3] = Rotation.from_quat(self.quaternions_xyzw).as_matrix()
            out[:, :3, 3] = self.positions
        return out


def read_tum_comments(path: str | os.PathLike) -> list[str]:
    """The comment lines (``#``, prefix removed) at the top of a TUM file; [] if unreadable."""
    out: list[str] = []
    try:
        with Path(path).open(encoding="utf-8-sig") as fh:
            for line in fh:
                if not line.startswith("#"):
                    break
                out.append(line[1:].strip())
    except (OSError, UnicodeDecodeError):
        return []
    return out


def read_tum(path: str | os.PathLike, *, allow_empty: bool = False) -> TumTrajectory:
    """Read a TUM trajectory file.

    Raises
    ------
    FileNotFoundError
        The file does not exist.
    TrajectoryError
        A line without 8 numbers, a non-finite value, a zero quaternion, timestamps that do
        not strictly increase, or (unless ``allow_empty``) no pose at all.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: trajectory file does not exist")
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError:
        raise TrajectoryError(f"{path}: not a text file (TUM: 'timestamp tx ty tz qx qy qz qw')") from None
    stamps_ns, rows = [], []
    for lineno, line in enumerate(text.splitlines(), start=1):
        if not line.strip() or line.startswith("#"):
            continue
        parts = line.split()
        if len(parts) != 8:
            raise TrajectoryError(f"{path}:{lineno}: not a TUM line ('timestamp tx ty tz qx qy qz qw'): {line!r}")
        try:
            values = [float(p) for p in parts]
        except ValueError:
            raise TrajectoryError(f"{path}:{lineno}: not a number in {line!r}") from None
        if not all(math.isfinite(v) for v in values):
            raise TrajectoryError(f"{path}:{lineno}: non-finite value in {line!r}")
        if not any(values[4:]):
            raise TrajectoryError(f"{path}:{lineno}: zero quaternion")
        stamps_ns.append(parse_timestamp_ns(parts[0]))
        rows.append(values)
    if not rows and not allow_empty:
        raise TrajectoryError(f"{path}: trajectory is empty")
    a = np.array(rows, dtype=np.float64).reshape(-1, 8)
    if np.any(np.diff(a[:, 0]) <= 0):
        raise TrajectoryError(f"{path}: timestamps must be strictly increasing")
    return TumTrajectory(path, a[:, 0].copy(), np.array(stamps_ns, dtype=np.int64), a[:, 1:4].copy(),
                         a[:, 4:8].copy())

"""The IMU file of a recording: ``<sequence>/imu/imu.csv`` (BorealHDR), reader and writer.

Format (one header line, then one sample per line)::

    timestamp,ros_time,gyro_x,gyro_y,gyro_z,acc_x,acc_y,acc_z
    1695668703096986112,1695668703192314230,-0.0038,0.0124,-0.0314,-1.595,-0.0867,9.8146

``timestamp`` and ``ros_time`` are integer nanoseconds on the clock of the camera file
names (in the BorealHDR sample ``timestamp`` is the sensor's stamp, ``ros_time`` the
receipt, a median 0.65 ms later; exposim uses ``timestamp``); the gyro is in rad/s and the
accelerometer in m/s^2, in the IMU's own axes.  Samples need not be evenly spaced (the
sample's IMU runs at 100 Hz with gaps from 1 to 30 ms) but must be strictly increasing.

:func:`read_imu` reads the file from a folder or a trajectory zip through the recording's
:class:`~emulator.io.borealhdr.FileSource`; a recording without one is reported once per
process with an :class:`ImuMissingWarning` and nothing else changes.  A malformed file is a
:class:`~emulator.errors.DatasetError` naming the file and the line.
"""

from __future__ import annotations

import io
import math
import os
import threading
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from emulator.errors import DatasetError
from emulator.io.files import atomic_write_bytes

__all__ = ["IMU_FILE", "IMU_COLUMNS", "ImuData", "ImuMissingWarning", "read_imu", "parse_imu", "write_imu",
           "find_imu"]

#: Where a recording keeps its IMU, relative to the sequence folder.
IMU_FILE = ("imu", "imu.csv")
#: The header of the file, in order.
IMU_COLUMNS = ("timestamp", "ros_time", "gyro_x", "gyro_y", "gyro_z", "acc_x", "acc_y", "acc_z")


class ImuMissingWarning(UserWarning):
    """A recording has no ``imu/imu.csv``: blur cannot be predicted from its gyro."""


@dataclass(frozen=True)
class ImuData:
    """The IMU samples of one recording, in the IMU's axes.

    Attributes
    ----------
    timestamp_ns : numpy.ndarray
        (N,) ``int64`` sample times, ns, strictly increasing (camera clock).
    gyro_rad_s : numpy.ndarray
        (N, 3) ``float64`` angular velocity, rad/s.
    acc_m_s2 : numpy.ndarray
        (N, 3) ``float64`` specific force, m/s^2.
    ros_time_ns : numpy.ndarray
        (N,) ``int64`` receipt times, ns (kept, not used).
    path : pathlib.Path or None
        The file it was read from.
    """

    timestamp_ns: np.ndarray
    gyro_rad_s: np.ndarray
    acc_m_s2: np.ndarray
    ros_time_ns: np.ndarray
    path: Path | None = field(default=None, compare=False)

    def __len__(self) -> int:
        return int(self.timestamp_ns.size)

    @property
    def rate_hz(self) -> float:
        """Median sample rate, Hz."""
        if len(self) < 2:
            return math.nan
        return 1e9 / float(np.median(np.diff(self.timestamp_ns)))

    def angular_speed_deg_s(self) -> np.ndarray:
        """(N,) ``float64`` |omega| in deg/s."""
        return np.degrees(np.linalg.norm(self.gyro_rad_s, axis=1))

    def describe(self) -> dict:
        """JSON-ready summary: samples, span, rate, angular speed percentiles."""
        speed = self.angular_speed_deg_s()
        pct = {f"p{q}": float(np.percentile(speed, q)) for q in (50, 90, 99)} if speed.size else {}
        return {
            "path": str(self.path) if self.path is not None else None,
            "n_samples": len(self),
            "start_ns": int(self.timestamp_ns[0]) if len(self) else None,
            "end_ns": int(self.timestamp_ns[-1]) if len(self) else None,
            "rate_hz": self.rate_hz,
            "angular_speed_deg_s": pct,
        }


def parse_imu(data: bytes | str, path: str | os.PathLike = "imu.csv") -> ImuData:
    """Parse the text of an ``imu.csv`` (see the module docstring).

    Raises
    ------
    DatasetError
        Naming ``path`` and the line: a wrong header, a wrong number of fields, a value that
        is not a number (timestamps: not an integer), a non-finite value, a timestamp not
        after the previous one, or a file without samples.
    """
    path = Path(path)
    text = data.decode("utf-8", errors="replace") if isinstance(data, bytes) else data
    lines = text.splitlines()
    if not lines or tuple(h.strip() for h in lines[0].split(",")) != IMU_COLUMNS:
        got = lines[0].strip() if lines else "(empty file)"
        raise DatasetError(f"{path}: line 1: header must be {','.join(IMU_COLUMNS)}, got {got[:120]!r}")
    n = len(lines)
    ts = np.empty(n, dtype=np.int64)
    ros = np.empty(n, dtype=np.int64)
    vals = np.empty((n, 6), dtype=np.float64)
    k = 0
    for lineno, line in enumerate(lines[1:], start=2):
        if not line.strip():
            continue
        fields = line.split(",")
        if len(fields) != len(IMU_COLUMNS):
            raise DatasetError(f"{path}: line {lineno}: expected {len(IMU_COLUMNS)} comma-separated fields, "
                               f"got {len(fields)}")
        try:
            ts[k] = int(fields[0])
            ros[k] = int(fields[1])
        except ValueError:
            raise DatasetError(f"{path}: line {lineno}: timestamp and ros_time must be integer nanoseconds, "
                               f"got {fields[0].strip()!r}, {fields[1].strip()!r}") from None
        try:
            row = [float(f) for f in fields[2:]]
        except ValueError:
            raise DatasetError(f"{path}: line {lineno}: gyro and acc fields must be numbers, got "
                               f"{','.join(f.strip() for f in fields[2:])!r}") from None
        if not all(math.isfinite(v) for v in row):
            raise DatasetError(f"{path}: line {lineno}: non-finite gyro or acc value")
        vals[k] = row
        if k and ts[k] <= ts[k - 1]:
            raise DatasetError(f"{path}: line {lineno}: timestamp {ts[k]} is not after the previous one "
                               f"({ts[k - 1]}); samples must be strictly increasing in time")
        k += 1
    if k == 0:
        raise DatasetError(f"{path}: no IMU samples after the header")
    return ImuData(ts[:k].copy(), vals[:k, :3].copy(), vals[:k, 3:].copy(), ros[:k].copy(), path)


_warned: set[str] = set()
_warn_lock = threading.Lock()


def find_imu(root: str | os.PathLike, source=None) -> Path | None:
    """The recording's ``imu/imu.csv`` if its source has one, else None."""
    root = Path(root)
    path = root.joinpath(*IMU_FILE)
    found = source.is_file(path) if source is not None else path.is_file()  # no source: the file system
    return path if found else None


def read_imu(root: str | os.PathLike, source=None, *, warn: bool = True) -> ImuData | None:
    """Read ``<root>/imu/imu.csv`` (folder or zip source); None when the recording has none.

    A missing file is reported once per recording and process with an
    :class:`ImuMissingWarning` (``warn=False``: silently).  A malformed file raises
    :class:`DatasetError` naming the file and line.
    """
    root = Path(root)
    path = find_imu(root, source)
    if path is None:
        if warn:
            with _warn_lock:
                first = str(root) not in _warned
                _warned.add(str(root))
            if first:
                warnings.warn(f"{root}: no imu/imu.csv; blur cannot be predicted from a gyro for this recording",
                              ImuMissingWarning, stacklevel=2)
        return None
    return parse_imu(path.read_bytes() if source is None else source.read_bytes(path), path)


def write_imu(path: str | os.PathLike, imu: ImuData, *, overwrite: bool = False) -> Path:
    """Write ``imu`` as an ``imu.csv`` at ``path`` (atomic; gyro and acc at full precision)."""
    path = Path(path)
    buf = io.StringIO()
    buf.write(",".join(IMU_COLUMNS) + "\n")
    for t, r, g, a in zip(imu.timestamp_ns, imu.ros_time_ns, imu.gyro_rad_s, imu.acc_m_s2):
        buf.write(f"{int(t)},{int(r)}," + ",".join(repr(float(v)) for v in (*g, *a)) + "\n")
    return atomic_write_bytes(path, buf.getvalue().encode(), overwrite=overwrite)

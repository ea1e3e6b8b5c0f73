"""Export one method's emulated images of a run folder for downstream SLAM pipelines.

Three layouts, each of the left (``cam0``) and right (``cam1``) images of one AE method:

``euroc``
    The EuRoC MAV layout that ORB-SLAM3, VINS-Fusion, OKVIS, Basalt read:
    ``mav0/cam0/data/<timestamp_ns>.png``, ``mav0/cam0/data.csv``
    (``#timestamp [ns],filename``), the same for ``cam1``, and, when the stereo
    calibration is known, ``mav0/cam0/sensor.yaml`` (pinhole, radial-tangential).
``tum``
    TUM RGB-D style lists: ``left/<t>.png`` and ``right/<t>.png`` with ``t`` the
    timestamp in seconds (9 decimals), and ``left.txt``, ``right.txt`` of
    ``timestamp filename`` lines (``# `` header lines, as TUM's ``rgb.txt``).
``rosbag2``
    A ROS 2 bag (sqlite3, written by ``rosbags``) with ``sensor_msgs/msg/Image`` on
    ``/cam0/image_raw`` and ``/cam1/image_raw`` and, when the calibration is known,
    ``sensor_msgs/msg/CameraInfo`` on ``/cam0/camera_info`` and ``/cam1/camera_info`` at
    the same stamps.

Pixels: a ``--save png8`` run is exported as saved (8-bit grey, ROS ``mono8``); a
``--save png16`` run holds 12-bit RGGB mosaics, exported as grey in DN (``cv2.cvtColor``
``COLOR_BayerRG2GRAY``, ``uint16``, values 0..white level, ROS ``mono16``), or with
``mono8=True`` as 8-bit grey by the fixed scale of :func:`emulator.core.gray.bayer_to_gray8`
(what the feature and VO benchmarks see; most SLAM front ends expect 8 bits).

The calibration files (``left.yaml``, ``right.yaml``) are written to ``calibration/`` in
every layout when known: as given, or, where ``exposim export`` refined the extrinsics with
``bench vo``'s check, with the rectification (R, P) of the refined pose.  ``export.json``
records what was exported and which calibration (the caller's ``metadata``).  An existing output folder is never written into: the
export goes to a temporary sibling folder renamed to the output at the end, so a failed
export leaves nothing behind.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import cv2
import numpy as np

from emulator.errors import OutputExistsError, RunFolderError
from emulator.core.gray import bayer_to_gray8
from emulator.io.camera_info import CameraInfo, format_camera_info
from emulator.io.files import atomic_write_bytes
from emulator.io.png import encode_png, read_image
from emulator.io.runfolder import MethodRun, RunFolder

__all__ = ["EXPORT_FORMATS", "EXPORT_FILE", "CAMERA_TOPICS", "export_method", "frame_pixels"]

#: Formats of :func:`export_method`.
EXPORT_FORMATS = ("euroc", "tum", "rosbag2")
#: Camera name -> (EuRoC camera folder, ROS topic namespace).
CAMERA_TOPICS = {"left": ("cam0", "/cam0"), "right": ("cam1", "/cam1")}


def frame_pixels(path: Path, run: RunFolder, mono8: bool) -> tuple[np.ndarray, str]:
    """A saved run image as exported: (image, ROS encoding ``mono8`` or ``mono16``)."""
    try:
        image = read_image(path)
    except (FileNotFoundError, ValueError):
        raise RunFolderError(f"{path}: cannot read image (missing or not a PNG)") from None
    if image.dtype == np.uint16 and image.ndim == 2:
        if mono8:
            return bayer_to_gray8(image, white_level=run.white_level, black_level=run.black_level), "mono8"
        return cv2.cvtColor(image, cv2.COLOR_BayerRG2GRAY), "mono16"
    if image.dtype == np.uint8 and image.ndim == 2:
        return image, "mono8"
    if image.dtype == np.uint8 and image.ndim == 3 and image.shape[2] == 3:
        return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY), "mono8"
    raise RunFolderError(f"{path}: expected a uint16 Bayer mosaic or a uint8 grey image, got {image.dtype} "
                         f"{image.shape}")


def _seconds(ns: int) -> str:
    return f"{ns // 1_000_000_000}.{ns % 1_000_000_000:09d}"


def body_from_camera(calib, cam: str) -> np.ndarray:
    """EuRoC's ``T_BS`` of a camera with the body frame = the left camera's: identity for the left,
    the right camera's pose in the left's frame for the right (the inverse of ``X_r = R X_l + T``)."""
    t = np.eye(4)
    if cam == "right":
        R = np.asarray(calib.R, dtype=np.float64).reshape(3, 3)
        t[:3, :3] = R.T
        t[:3, 3] = -R.T @ np.asarray(calib.T, dtype=np.float64).reshape(3)
    return t


def _sensor_yaml(info: CameraInfo, rate_hz: float, t_bs: np.ndarray) -> str:
    """EuRoC ``sensor.yaml`` of one camera (``t_bs``: :func:`body_from_camera`)."""
    K, D = info.K, np.asarray(info.D, dtype=np.float64).ravel()
    d4 = (list(D[:4]) + [0.0] * 4)[:4]
    return (
        "sensor_type: camera\n"
        f"comment: exported by exposim from {info.path}; body frame = the left camera (cam0)\n"
        f"T_BS:\n  cols: 4\n  rows: 4\n  data: [{', '.join(repr(float(v)) for v in t_bs.ravel())}]\n"
        f"rate_hz: {rate_hz:.6g}\n"
        f"resolution: [{info.width}, {info.height}]\n"
        "camera_model: pinhole\n"
        f"intrinsics: [{', '.join(repr(float(v)) for v in (K[0, 0], K[1, 1], K[0, 2], K[1, 2]))}]\n"
        "distortion_model: radial-tangential\n"
        f"distortion_coefficients: [{', '.join(repr(float(v)) for v in d4)}]\n"
    )


def _frames(method: MethodRun, cameras: tuple[str, ...]):
    for f in method.frames:
        for cam in cameras:
            path = f.left if cam == "left" else f.right
            if path is not None:
                yield cam, f.timestamp_ns, path


def _write(path: Path, data: bytes) -> None:
    atomic_write_bytes(path, data, overwrite=False)


def _export_files(method, run, tmp: Path, fmt: str, cameras, calib, mono8: bool) -> dict:
    lists: dict[str, list[str]] = {cam: [] for cam in cameras}
    encodings: set[str] = set()
    n = 0
    for cam, ns, path in _frames(method, cameras):
        image, enc = frame_pixels(path, run, mono8)
        encodings.add(enc)
        if fmt == "euroc":
            folder = CAMERA_TOPICS[cam][0]
            _write(tmp / "mav0" / folder / "data" / f"{ns}.png", encode_png(image, path))
            lists[cam].append(f"{ns},{ns}.png")
        else:
            name = f"{_seconds(ns)}.png"
            _write(tmp / cam / name, encode_png(image, path))
            lists[cam].append(f"{_seconds(ns)} {cam}/{name}")
        n += 1
    for cam, rows in lists.items():
        if fmt == "euroc":
            folder = CAMERA_TOPICS[cam][0]
            _write(tmp / "mav0" / folder / "data.csv", ("#timestamp [ns],filename\n" + "\n".join(rows) + "\n").encode())
            if calib is not None:
                stamps = [int(r.split(",")[0]) for r in rows]
                rate = (len(stamps) - 1) / ((stamps[-1] - stamps[0]) / 1e9) if len(stamps) > 1 else 0.0
                _write(tmp / "mav0" / folder / "sensor.yaml",
                       _sensor_yaml(calib.left if cam == "left" else calib.right, rate,
                                    body_from_camera(calib, cam)).encode())
        else:
            header = f"# {cam} camera images of method {method.name}, exported by exposim\n# timestamp filename\n"
            _write(tmp / f"{cam}.txt", (header + "\n".join(rows) + "\n").encode())
    return {"n_images": n, "encodings": sorted(encodings)}


def _ros_time(types, ns: int):
    return types["builtin_interfaces/msg/Time"](sec=int(ns // 1_000_000_000), nanosec=int(ns % 1_000_000_000))


def _camera_info_msg(types, info: CameraInfo, header):
    roi = types["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
    return types["sensor_msgs/msg/CameraInfo"](
        header=header, height=int(info.height), width=int(info.width),
        distortion_model=info.distortion_model or "plumb_bob",
        d=np.asarray(info.D, dtype=np.float64).ravel(), k=np.asarray(info.K, dtype=np.float64).ravel(),
        r=np.asarray(info.R, dtype=np.float64).ravel(), p=np.asarray(info.P, dtype=np.float64).ravel(),
        binning_x=0, binning_y=0, roi=roi,
    )


def _export_rosbag2(method, run, bag: Path, cameras, calib, mono8: bool) -> dict:
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    types = store.types
    Image, Header = types["sensor_msgs/msg/Image"], types["std_msgs/msg/Header"]
    encodings: set[str] = set()
    n = 0
    with Writer(bag, version=8) as writer:
        image_conn = {cam: writer.add_connection(f"{CAMERA_TOPICS[cam][1]}/image_raw", Image.__msgtype__,
                                                 typestore=store) for cam in cameras}
        info_conn = {}
        if calib is not None:
            info_conn = {cam: writer.add_connection(f"{CAMERA_TOPICS[cam][1]}/camera_info",
                                                    "sensor_msgs/msg/CameraInfo", typestore=store) for cam in cameras}
        for cam, ns, path in _frames(method, cameras):
            image, enc = frame_pixels(path, run, mono8)
            encodings.add(enc)
            header = Header(stamp=_ros_time(types, ns), frame_id=CAMERA_TOPICS[cam][0])
            data = np.ascontiguousarray(image)
            if data.dtype == np.uint16:
                data = data.astype("<u2")
            msg = Image(header=header, height=int(image.shape[0]), width=int(image.shape[1]), encoding=enc,
                        is_bigendian=0, step=int(image.shape[1] * data.itemsize),
                        data=np.frombuffer(data.tobytes(), dtype=np.uint8))
            writer.write(image_conn[cam], int(ns), store.serialize_cdr(msg, Image.__msgtype__))
            if cam in info_conn:
                info = calib.left if cam == "left" else calib.right
                writer.write(info_conn[cam], int(ns), store.serialize_cdr(_camera_info_msg(types, info, header),
                                                                         "sensor_msgs/msg/CameraInfo"))
            n += 1
    return {"n_images": n, "encodings": sorted(encodings),
            "topics": sorted([f"{CAMERA_TOPICS[c][1]}/image_raw" for c in cameras]
                             + [f"{CAMERA_TOPICS[c][1]}/camera_info" for c in info_conn])}


#: The export's metadata file, in the output folder.
EXPORT_FILE = "export.json"


def export_method(run: RunFolder, method: str, out_dir: str | os.PathLike, fmt: str, *, calibration=None,
                  mono8: bool = False, metadata: dict | None = None) -> dict:
    """Export one method's images of a run folder (module docstring for the layouts).

    Parameters
    ----------
    run : RunFolder
        From :func:`emulator.io.runfolder.read_run_folder`.
    method : str
        One of the run's methods.
    out_dir : path
        Output folder; must not exist (or be an empty folder).
    fmt : {"euroc", "tum", "rosbag2"}
    calibration : emulator.metrics.stereo.StereoCalibration, optional
        Written as ``calibration/left.yaml``, ``right.yaml``, EuRoC ``sensor.yaml`` and ROS
        ``camera_info``; None writes no calibration.
    mono8 : bool
        Export png16 runs as 8-bit grey (default: 16-bit grey in DN).
    metadata : dict, optional
        More keys for ``export.json`` (e.g. ``calibration``: which one was written and why).

    Returns
    -------
    dict
        ``format``, ``method``, ``n_images``, ``encodings``, ``cameras`` and (bag) ``topics``.

    Raises
    ------
    OutputExistsError
        When ``out_dir`` exists and is not an empty folder.
    RunFolderError
        For an unknown method or an unreadable image.
    """
    if fmt not in EXPORT_FORMATS:
        raise RunFolderError(f"export format must be one of {', '.join(EXPORT_FORMATS)}, got {fmt!r}")
    if method not in run.methods:
        raise RunFolderError(f"{run.path}: no method {method!r} in this run (methods: {', '.join(run.methods)})")
    out = Path(out_dir)
    if out.exists() and not (out.is_dir() and not any(out.iterdir())):
        raise OutputExistsError(f"{out}: exists; exports never write into an existing folder (choose a new -o)")
    m = run.methods[method]
    cameras = ("left", "right") if all(f.right is not None for f in m.frames) else ("left",)
    staging = out.parent / f".{out.name}.partial-{os.getpid()}"
    if staging.exists():
        shutil.rmtree(staging)
    staging.mkdir(parents=True)
    tmp = staging / out.name  # the bag's database is named after its folder
    try:
        if fmt == "rosbag2":
            summary = _export_rosbag2(m, run, tmp, cameras, calibration, mono8)
        else:
            summary = _export_files(m, run, tmp, fmt, cameras, calibration, mono8)
        if calibration is not None:
            for cam, info in (("left", calibration.left), ("right", calibration.right)):
                _write(tmp / "calibration" / f"{cam}.yaml", format_camera_info(info).encode())
        result = {"format": fmt, "method": method, "cameras": list(cameras), "output": str(out),
                  "calibration": None if calibration is None else str(calibration.left.path.parent), **summary}
        _write(tmp / EXPORT_FILE, (json.dumps({"run": str(run.path), **result, **(metadata or {}),
                                               "output": str(out)}, indent=1) + "\n").encode())
        if out.exists():
            out.rmdir()  # an empty folder: nothing is overwritten
        tmp.rename(out)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return {**result, **(metadata or {})}

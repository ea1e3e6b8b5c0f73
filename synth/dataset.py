"""The dataset folder of a synthetic recording: its description files and how it is claimed.

* :func:`camera_info`, :func:`recording_metadata`: the calibration and ``exposim.json``
  written beside the frames; :func:`load_camera` reads the camera back.
* :func:`check_target`, :func:`new_staging`, :func:`publish`: a recording is written into a
  hidden staging folder beside ``out_dir`` and renamed into place when complete.  An
  existing dataset is replaced only when asked (``overwrite``), only if it is an exposim
  dataset, and never when it holds a file that synth did not write: ``exposim-files.json``
  (:data:`MANIFEST_FILE`) lists every file synth wrote with its size, and anything else
  (a file a user added, or one changed since) makes :func:`check_target` refuse, naming
  the files.  Nothing is deleted before the check passes.

Folders and files are created with the process umask (0755 / 0644 under umask 0022), like
any file the user creates (:func:`emulator.io.files.make_staging_dir`).
"""

from __future__ import annotations

import os
import re
import shutil
from pathlib import Path

import numpy as np

from emulator.errors import OutputExistsError
from emulator.io.borealhdr import METADATA_FILE, read_recording_metadata
from emulator.io.camera_info import CameraInfo
from emulator.io.files import make_staging_dir, read_metadata, write_metadata
from emulator.io.pcalib import PCALIB_TABLE_TOP, read_response
from emulator.core.response import CameraResponse
from synth.camera import Camera
from synth.errors import SynthError

__all__ = [
    "MANIFEST_FILE",
    "camera_info",
    "load_camera",
    "recording_metadata",
    "foreign_files",
    "missing_files",
    "check_target",
    "new_staging",
    "write_manifest",
    "publish",
]

#: Every file synth wrote into a dataset, with its size in bytes (metadata JSON).
MANIFEST_FILE = "exposim-files.json"
#: Names synth writes, for datasets from before the manifest (relative POSIX paths).
_LAYOUT_RE = re.compile(
    r"^(?:exposim\.json"
    r"|calibration/(?:response\.txt|left\.yaml|right\.yaml)"
    r"|imu/imu\.csv"
    r"|ground_truth/poses_(?:left|right)\.txt"
    r"|camera_(?:left|right)/[0-9.]+/\d+\.png"
    r"|ground_truth/radiance/camera_(?:left|right)/\d+\.exr"
    r"|ground_truth/captures_(?:noiseless|noisy)/camera_(?:left|right)/[0-9.]+/\d+\.png)$"
)
#: Foreign files named in a refusal (the rest are counted).
_NAMED = 8


# ---------------------------------------------------------------------------- description files
def camera_info(camera: Camera, side: str, baseline_m: float) -> CameraInfo:
    """ROS camera_info of a synthetic camera: no distortion, identity rectification.

    The projection matrix carries the stereo baseline as ``P[0, 3] = -fx * baseline_m`` for
    the right camera (0 for the left one), as in the BorealHDR calibration files.
    """
    k = camera.intrinsics()
    fx, fy, cx, cy = k[0, 0], k[1, 1], k[0, 2], k[1, 2]
    tx = -fx * baseline_m if side == "right" else 0.0
    return CameraInfo(
        width=camera.width,
        height=camera.height,
        K=np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1]], dtype=np.float64),
        D=np.zeros(5),
        R=np.eye(3),
        P=np.array([[fx, 0, cx, tx], [0, fy, cy, 0], [0, 0, 1, 0]], dtype=np.float64),
        distortion_model="plumb_bob",
        name=f"exposim_synth/{side}",
    )


def load_camera(sequence_path: str | os.PathLike) -> Camera:
    """The :class:`Camera` of a dataset written by :func:`synth.capture_sequence`.

    Reads ``exposim.json`` and the exact response in ``calibration/response.txt``.
    """
    root = Path(sequence_path)
    meta_path = root / METADATA_FILE
    if not meta_path.is_file():
        raise FileNotFoundError(f"{meta_path}: not found (not a synthetic dataset?)")
    meta = read_recording_metadata(root)
    desc = meta.get("camera")
    if not isinstance(desc, dict) or "white_level" not in desc:
        raise SynthError(f"{meta_path}: no readable camera description ('camera' with a 'white_level')")
    top = max(PCALIB_TABLE_TOP, int(desc["white_level"]))
    table = read_response(root / "calibration" / "response.txt", white_level=top,
                          black_level=int(desc.get("black_level", 0)))
    response = CameraResponse(table.g, top, 0, str(desc.get("response", table.name)))
    return Camera.from_dict(desc, response)


def recording_metadata(camera: Camera, shots, brackets, *, generator: str, gt_captures_kinds, fps, stereo,
                       baseline_m, seed, noise, gt_exposures, save_radiance, start_time_ns, start_bracket_index,
                       source, timestamps_note: str | None = None, gt_cameras=None) -> dict:
    """The ``exposim.json`` of a recording (levels, schedule, seeds, camera, source)."""
    from emulator import __version__

    return {
        "generator": {"name": generator, "version": __version__},
        "white_level": camera.white_level,
        "black_level": camera.black_level,
        "brackets_ms": list(brackets),
        "fps": float(fps),
        "cameras": ["left", "right"] if stereo else ["left"],
        "baseline_m": baseline_m if stereo else None,
        "n_shots": len(shots),
        "n_cycles": shots[-1].cycle + 1,
        "start_bracket_index": int(start_bracket_index),
        "start_time_ns": int(start_time_ns),
        "timestamps": timestamps_note or "trigger instant of each shot; the scene is sampled there (no motion blur)",
        "seed": int(seed),
        "seeds": "bracket: SeedSequence([seed, camera (0 left, 1 right), shot]); noisy ground truth at "
                 "gt_exposures_ms[j]: SeedSequence([seed, camera, shot, 1 + j])",
        "noise": bool(noise),
        "gt_exposures_ms": list(gt_exposures),
        "gt_captures": list(gt_captures_kinds) if gt_exposures else [],
        "gt_cameras": (list(gt_cameras) if gt_cameras is not None else (["left", "right"] if stereo else ["left"]))
        if gt_exposures else [],
        "save_radiance": bool(save_radiance),
        "radiance_units": "W m^-2 sr^-1 (float32, linear)",
        "poses": "ground_truth/poses_<camera>.txt, TUM (timestamp_s tx ty tz qx qy qz qw), camera-to-world, "
                 "camera frame x right, y down, z forward",
        "camera": camera.to_dict(),
        "source": source,
    }


# ---------------------------------------------------------------------------- claiming the folder
def _files(root: Path) -> dict[str, int]:
    """Every file (and symlink) under ``root``: relative POSIX path -> size in bytes."""
    out = {}
    for dirpath, dirnames, filenames in os.walk(root):
        here = Path(dirpath)
        for name in filenames + [d for d in dirnames if (here / d).is_symlink()]:
            p = here / name
            out[p.relative_to(root).as_posix()] = p.lstat().st_size
    return out


def write_manifest(staging: Path) -> None:
    """List every file under ``staging`` with its size in :data:`MANIFEST_FILE` (written last)."""
    write_metadata(staging / MANIFEST_FILE, {"generator": "exposim synth", "files": _files(staging)})


def foreign_files(out_dir: str | os.PathLike) -> list[str]:
    """Files in a dataset folder that synth did not write, or that changed size since (sorted).

    Judged by :data:`MANIFEST_FILE`; a dataset from before the manifest by synth's layout
    (frames, ground truth, calibration and ``exposim.json`` under their own names).
    """
    root = Path(out_dir)
    present = _files(root)
    manifest = read_metadata(root / MANIFEST_FILE, OutputExistsError) if (root / MANIFEST_FILE).is_file() else None
    listed = manifest.get("files") if manifest is not None else None
    if manifest is not None and not isinstance(listed, dict):
        raise OutputExistsError(f"{root / MANIFEST_FILE}: no 'files' table; refusing to replace {root}")
    out = []
    for rel, size in present.items():
        if rel == MANIFEST_FILE:
            continue
        if listed is None:
            if not _LAYOUT_RE.match(rel):
                out.append(rel)
        elif listed.get(rel) != size:
            out.append(rel if rel not in listed else f"{rel} (changed since synth wrote it)")
    return sorted(out)


def missing_files(out_dir: str | os.PathLike) -> list[str]:
    """Files :data:`MANIFEST_FILE` lists that are gone from the dataset (sorted); all if it has none."""
    root = Path(out_dir)
    if not (root / MANIFEST_FILE).is_file():
        return [MANIFEST_FILE]
    listed = read_metadata(root / MANIFEST_FILE).get("files")
    if not isinstance(listed, dict):
        return [MANIFEST_FILE]
    return sorted(rel for rel in listed if not (root / rel).is_file())


def check_target(out_dir: Path, overwrite: bool) -> None:
    """Refuse ``out_dir`` unless it is absent, empty, or an exposim dataset that may be replaced.

    With ``overwrite`` an old dataset is replaced only if every file in it is one synth
    wrote (:func:`foreign_files`); otherwise :class:`OutputExistsError` names what would be
    lost.
    """
    if not (out_dir.exists() or out_dir.is_symlink()):
        return
    if not out_dir.is_dir():
        raise OutputExistsError(f"{out_dir}: exists and is not a folder; refusing to replace it")
    if not any(out_dir.iterdir()):
        return
    if not overwrite:
        raise OutputExistsError(f"{out_dir}: exists; refusing to overwrite (use overwrite=True, --force)")
    if not (out_dir / METADATA_FILE).is_file():
        raise OutputExistsError(
            f"{out_dir}: exists and is not an exposim dataset (no {METADATA_FILE}); refusing to replace it"
        )
    foreign = foreign_files(out_dir)
    if foreign:
        named = ", ".join(foreign[:_NAMED]) + (f" and {len(foreign) - _NAMED} more" if len(foreign) > _NAMED else "")
        raise OutputExistsError(
            f"{out_dir}: holds {len(foreign)} file(s) that exposim synth did not write, which replacing it "
            f"would delete: {named}; move them out (or choose another output folder); nothing was changed"
        )


def new_staging(out_dir: Path) -> Path:
    """The hidden staging folder ``.NAME.partial-XXXXXXXX`` beside ``out_dir`` (umask honoured)."""
    from emulator.orchestration.interrupts import remove_at_forced_exit

    staging = make_staging_dir(out_dir.parent, f".{out_dir.name}.partial-")
    remove_at_forced_exit(staging)  # a process ended seconds after Ctrl-C leaves no partial dataset
    return staging


def publish(staging: Path, out_dir: Path, overwrite: bool) -> None:
    """Rename the finished staging folder to ``out_dir``, replacing an old dataset if allowed.

    :func:`check_target` is applied again first (the folder may have changed while the
    recording was made).
    """
    check_target(out_dir, overwrite)
    old = None
    if out_dir.exists():
        old = make_staging_dir(out_dir.parent, f".{out_dir.name}.old-")
        os.replace(out_dir, old / out_dir.name)
    os.replace(staging, out_dir)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)

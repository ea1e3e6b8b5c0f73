"""One name per thing (issue 11): each format, error, default and conversion exists once.

Each test here would have caught a duplicate the review found: two ``CalibrationError``
classes (stack calibration vs stereo calibration files), results.json written by five
hand-rolled writers, two TUM writers with different quaternion signs, a closed-loop clamp
of 0.02-50 ms beside an AE clamp of 0.02-100 ms, default white levels of 4095 and 4094,
and a png8 conversion that ignored the black level while the feature metrics subtracted it.
"""

from __future__ import annotations

import ast
import inspect
import json
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import emulator.errors
from emulator import playback
from emulator.orchestration import runner
from emulator.autoexposure import DEFAULT_RANGE_MS, METHOD_NAMES, make_method
from emulator.core.gray import bayer_to_gray8
from emulator.io.borealhdr import load_sequence
from emulator.io.runfolder import read_run_folder
from emulator.io.stack import read_stack, write_stack
from emulator.io.tum import read_tum, rotation_to_quaternion, write_tum
from emulator.metrics.features import load_gray8
from emulator.core.response import BOREALHDR_BLACK_LEVEL, BOREALHDR_WHITE_LEVEL, CameraResponse

try:
    from tests.emulator.playback.test_playback import write_static_sequence
except ImportError:  # tests collected as a package
    from tests.test_playback import write_static_sequence

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("emulator", "synth", "scenes", "validation")


def _sources():
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            rel = path.relative_to(ROOT)
            yield rel, ast.parse(path.read_text(encoding="utf-8"), filename=str(rel))


def _module(rel: Path) -> str:
    parts = rel.with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def top_level_definitions(sources) -> dict[str, list[str]]:
    """name -> modules that define it at top level (def, class or assignment)."""
    found: dict[str, list[str]] = {}
    for rel, tree in sources:
        for node in tree.body:
            names = []
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                names = [node.name]
            elif isinstance(node, ast.Assign):
                names = [t.id for t in node.targets if isinstance(t, ast.Name)]
            elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
                names = [node.target.id]
            for name in names:
                found.setdefault(name, []).append(_module(rel))
    return found


#: What must exist exactly once, and where.
OWNED = {
    "CalibrationError": "emulator.errors",
    "MetricsError": "emulator.errors",
    "RunFolderError": "emulator.errors",
    "TrajectoryError": "emulator.errors",
    "write_results": "emulator.io.files",
    "read_results": "emulator.io.files",
    "prepare_output": "emulator.io.files",
    "write_tum": "emulator.io.tum",
    "read_tum": "emulator.io.tum",
    "rotation_to_quaternion": "emulator.io.tum",
    "read_png16": "emulator.io.png",
    "write_png16": "emulator.io.png",
    "write_png8": "emulator.io.png",
    "read_pcalib": "emulator.io.pcalib",
    "write_pcalib": "emulator.io.pcalib",
    "read_response": "emulator.io.pcalib",
    "PCALIB_TABLE_TOP": "emulator.io.pcalib",
    "write_response": "emulator.io.pcalib",
    "read_exr": "emulator.io.exr",
    "write_exr": "emulator.io.exr",
    "read_stack": "emulator.io.stack",
    "write_stack": "emulator.io.stack",
    "read_times": "emulator.io.stack",
    "write_times": "emulator.io.stack",
    "read_camera_info": "emulator.io.camera_info",
    "read_run_folder": "emulator.io.runread",
    "load_sequence": "emulator.io.borealhdr",
    "write_frame": "emulator.io.borealhdr",
    "bayer_to_gray8": "emulator.core.gray",
    "DEFAULT_RANGE_MS": "emulator.autoexposure.base",
    "BOREALHDR_WHITE_LEVEL": "emulator.core.response",
    "BOREALHDR_BLACK_LEVEL": "emulator.core.response",
    "BOREALHDR_LEVELS": "emulator.core.levels",
    "Levels": "emulator.core.levels",
}


def owned_violations(sources, owned=OWNED) -> list[str]:
    defs = top_level_definitions(sources)
    bad = [f"{name}: defined in {defs.get(name, [])}, expected once in {home}"
           for name, home in owned.items() if defs.get(name) != [home]]
    bad += [f"{name}: exception class defined in {where}" for name, where in defs.items()
            if name.endswith("Error") and len(where) > 1]
    return bad


def test_owned_names_are_defined_once_in_their_home():
    assert owned_violations(list(_sources())) == []


def test_owned_check_finds_a_second_definition():
    fake = [(Path("emulator/errors.py"), ast.parse("class CalibrationError(Exception): pass")),
            (Path("emulator/calibrate.py"), ast.parse("class CalibrationError(ValueError): pass")),
            (Path("emulator/metrics/rpe.py"), ast.parse("def write_tum(path, t, p): pass")),
            (Path("emulator/io/tum.py"), ast.parse("def write_tum(path, t, p): pass"))]
    bad = owned_violations(fake, {"CalibrationError": "emulator.errors", "write_tum": "emulator.io.tum"})
    assert any(b.startswith("CalibrationError: defined in ['emulator.errors', 'emulator.calibrate']") for b in bad)
    assert any(b.startswith("write_tum: defined in ['emulator.metrics.rpe', 'emulator.io.tum']") for b in bad)
    assert owned_violations(fake[:1] + fake[3:], {"CalibrationError": "emulator.errors",
                                                  "write_tum": "emulator.io.tum"}) == []


# ------------------------------------------------------------------- one CalibrationError
def test_one_calibration_error_for_stacks_and_stereo_files(tmp_path):
    from emulator.io.camera_info import read_camera_info

    (tmp_path / "left.yaml").write_text("image_width: 4\n")
    with pytest.raises(emulator.errors.CalibrationError, match="left.yaml"):
        read_camera_info(tmp_path / "left.yaml")
    (tmp_path / "st").mkdir()
    (tmp_path / "st" / "times.txt").write_text("a 0.0\n")
    with pytest.raises(emulator.errors.CalibrationError, match="times.txt"):
        read_stack(tmp_path / "st")
    assert issubclass(emulator.errors.CalibrationError, emulator.errors.ExposimError)


# ------------------------------------------------------------------- nothing else opens a file
#: Calls that read or write a file; allowed only inside emulator/io.
FILE_ATTRS = {"write_text", "write_bytes", "read_text", "read_bytes", "savefig", "open"}
MODULE_FILE_CALLS = {
    "np": {"save", "savez", "savez_compressed", "load", "loadtxt", "savetxt", "fromfile"},
    "numpy": {"save", "savez", "savez_compressed", "load", "loadtxt", "savetxt", "fromfile"},
    "json": {"dump", "load"},
    "cv2": {"imread", "imwrite"},
    "OpenEXR": {"File"},
    "shutil": {"copyfile", "copy", "copy2"},
}
#: (file, call) pairs that are not data I/O: a source fingerprint, a descriptor dance on stdout.
ALLOWED = {("scenes/base.py", "read_bytes"), ("emulator/commands/cli.py", "os.open"),
           ("emulator/numpy_dispatch.py", "read_text")}  # /proc/cpuinfo, in the base floor


def file_io_outside_io(sources) -> list[str]:
    bad = []
    for rel, tree in sources:
        if rel.parts[:2] == ("emulator", "io"):
            continue
        for node in ast.walk(tree):
            if not isinstance(node, ast.Call):
                continue
            f = node.func
            call = None
            if isinstance(f, ast.Name) and f.id == "open":
                call = "open"
            elif isinstance(f, ast.Attribute):
                owner = f.value.id if isinstance(f.value, ast.Name) else None
                if owner in MODULE_FILE_CALLS and f.attr in MODULE_FILE_CALLS[owner]:
                    call = f"{owner}.{f.attr}"
                elif f.attr in FILE_ATTRS:
                    call = f"{owner}.{f.attr}" if owner in ("os", "io", "gzip", "tarfile", "zipfile") else f.attr
            if call and (rel.as_posix(), call) not in ALLOWED:
                bad.append(f"{rel.as_posix()}:{node.lineno}: {call}")
    return bad


def test_nothing_outside_emulator_io_reads_or_writes_a_file():
    # results.json, report.md, figures, arrays, PNG, EXR, TUM: all through emulator.io
    assert file_io_outside_io(list(_sources())) == []


def test_file_io_check_finds_hand_rolled_writers():
    code = ("def save(out, results, fig):\n"
            "    (out / 'results.json').write_text(json.dumps(results))\n"
            "    fig.savefig(out / 'a.png')\n"
            "    np.savez_compressed(out / 'a.npz', x=1)\n"
            "    with open(out / 'b.txt', 'w') as fh:\n"
            "        json.dump(results, fh)\n")
    bad = file_io_outside_io([(Path("validation/x.py"), ast.parse(code))])
    assert bad == ["validation/x.py:2: write_text", "validation/x.py:3: savefig",
                   "validation/x.py:4: np.savez_compressed", "validation/x.py:5: open", "validation/x.py:6: json.dump"]
    assert file_io_outside_io([(Path("emulator/io/x.py"), ast.parse(code))]) == []


# ------------------------------------------------------------------- TUM: one convention
def test_tum_quaternions_have_nonnegative_w(tmp_path):
    # rotations whose scipy quaternion comes out with w < 0 (angles above 180 degrees) and
    # the 180-degree cases where w == 0 and the sign must be fixed by x, y, z
    rots = Rotation.from_rotvec(np.random.default_rng(5).normal(size=(200, 3)) * 2.0)
    mats = list(rots.as_matrix())
    mats += [np.diag([1.0, -1.0, -1.0]), np.diag([-1.0, 1.0, -1.0]), np.diag([-1.0, -1.0, 1.0]),
             Rotation.from_rotvec([0.0, -np.pi, 0.0]).as_matrix(), Rotation.from_rotvec([0, 0, -3.0]).as_matrix()]
    poses = np.tile(np.eye(4), (len(mats), 1, 1))
    poses[:, :3, :3] = mats
    poses[:, :3, 3] = np.arange(len(mats) * 3).reshape(-1, 3) * 0.1
    stamps = [1_000_000_000 + 45_454_545 * i for i in range(len(mats))]
    path = write_tum(tmp_path / "p.txt", stamps, poses)
    back = read_tum(path)
    q = back.quaternions_xyzw
    assert np.all(q[:, 3] >= 0)
    w0 = q[:, 3] == 0
    assert w0.sum() == 3  # the three diagonal half-turns
    first_nonzero = [row[np.flatnonzero(row[:3])[0]] for row in q[w0]]
    assert all(v > 0 for v in first_nonzero)
    np.testing.assert_allclose(back.poses, poses, atol=1e-12)
    assert back.timestamps_ns.tolist() == stamps
    # a rotation of more than 180 degrees (w < 0 in the textbook quaternion) is written with w > 0
    q = rotation_to_quaternion(Rotation.from_rotvec([0.0, 0.0, np.radians(200.0)]).as_matrix())
    np.testing.assert_allclose(q, [0.0, 0.0, -np.sin(np.radians(80.0)), np.cos(np.radians(80.0))], atol=1e-15)
    # every writer of poses (VO trajectories, synthetic ground truth, render) is this one:
    # a second TUM writer would be a second top-level definition (OWNED above)


# ------------------------------------------------------------------- one clamp
@pytest.mark.filterwarnings("ignore:zhang .* no camera response given")
def test_one_clamp_default_for_ae_methods_and_the_closed_loop():
    assert DEFAULT_RANGE_MS == (0.02, 50.0)
    # 22 frames/s: one shot every ~45.5 ms, so a 50 ms clamp is the shortest round bound above it
    assert 1000.0 / 22 < DEFAULT_RANGE_MS[1]
    # the loop's clamp default lives in the one run configuration, which every run takes
    assert inspect.signature(playback.RunConfig).parameters["range_ms"].default is DEFAULT_RANGE_MS
    assert playback.RunConfig().range_ms == DEFAULT_RANGE_MS
    for fn in (playback.iter_run, playback.run, runner.run_to_folder):
        assert "range_ms" not in inspect.signature(fn).parameters, fn.__name__
        assert inspect.signature(fn).parameters["config"].default is None, fn.__name__
    for name in METHOD_NAMES:
        assert make_method(name, mode="paper").range_ms == DEFAULT_RANGE_MS, name
        assert make_method(name, mode="borealhdr").range_ms is None, name


def test_exposim_run_records_the_default_clamp(tmp_path, capsys):
    from emulator.commands.cli import main

    root, _ = write_static_sequence(tmp_path / "seq", n_cycles=2, shape=(16, 16))
    assert main(["run", str(root), "--methods", "fixed", "-o", str(tmp_path / "run"), "--no-progress"]) == 0
    info = json.loads((tmp_path / "run" / "run.json").read_text())
    assert info["range_ms"] == list(DEFAULT_RANGE_MS)


def test_no_clamp_literal_outside_the_ae_base():
    bad = []
    for rel, tree in _sources():
        if rel.as_posix() == "emulator/autoexposure/base.py":
            continue
        for node in ast.walk(tree):
            if isinstance(node, (ast.Tuple, ast.List)) and len(node.elts) == 2 and all(
                    isinstance(e, ast.Constant) and isinstance(e.value, (int, float)) for e in node.elts):
                lo, hi = (e.value for e in node.elts)
                if lo == 0.02 and hi in (50, 100):
                    bad.append(f"{rel}:{node.lineno}: ({lo}, {hi})")
    assert bad == []


# ------------------------------------------------------------------- one white level
def test_one_white_level_default(tmp_path):
    assert (BOREALHDR_WHITE_LEVEL, BOREALHDR_BLACK_LEVEL) == (4094, 0)
    assert CameraResponse.linear().white_level == BOREALHDR_WHITE_LEVEL
    assert CameraResponse.gamma(2.2).white_level == BOREALHDR_WHITE_LEVEL
    # a stack without exposim.json
    img = np.full((4, 4), 1000, np.uint16)
    stack = read_stack(write_stack(tmp_path / "st", [img, img], [1.0, 2.0]))
    assert (stack.white_level, stack.black_level) == (BOREALHDR_WHITE_LEVEL, BOREALHDR_BLACK_LEVEL)
    # a recording without exposim.json
    root, _ = write_static_sequence(tmp_path / "seq", n_cycles=1, shape=(8, 8))
    (root / "exposim.json").unlink()
    seq = load_sequence(root)
    assert (seq.white_level, seq.black_level) == (BOREALHDR_WHITE_LEVEL, BOREALHDR_BLACK_LEVEL)
    # a run folder whose run.json records no levels
    run = tmp_path / "run"
    (run / "m" / "images" / "left").mkdir(parents=True)
    (run / "run.json").write_text(json.dumps({"methods": ["m"], "save": "png16"}))
    from emulator.io.png import write_png16

    write_png16(run / "m" / "images" / "left" / "1.png", img)
    folder = read_run_folder(run)
    assert (folder.white_level, folder.black_level) == (BOREALHDR_WHITE_LEVEL, BOREALHDR_BLACK_LEVEL)
    # the synthetic camera and the calibration numerics
    from synth import Camera

    from emulator.calibration import estimate_noise_dn, fit_comparametric, fit_inverse_response

    assert Camera().white_level == BOREALHDR_WHITE_LEVEL
    for fn in (estimate_noise_dn, fit_inverse_response, fit_comparametric):
        assert inspect.signature(fn).parameters["white_level"].default == BOREALHDR_WHITE_LEVEL, fn.__name__


def literal_level_defaults(sources) -> list[str]:
    """Parameters and fields named white_level / black_level whose default is a number literal."""
    bad = []
    for rel, tree in sources:
        for node in ast.walk(tree):
            pairs = []
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                a = node.args
                pos = a.posonlyargs + a.args
                pairs += list(zip(pos[len(pos) - len(a.defaults):], a.defaults))
                pairs += [(k, d) for k, d in zip(a.kwonlyargs, a.kw_defaults) if d is not None]
                pairs = [(p.arg, d) for p, d in pairs]
            elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name) and node.value is not None:
                pairs = [(node.target.id, node.value)]
            for name, default in pairs:
                if name in ("white_level", "black_level") and isinstance(default, ast.Constant) \
                        and isinstance(default.value, int) and default.value != 0:
                    bad.append(f"{rel}:{default.lineno}: {name}={default.value}")
    return bad


def test_no_white_level_literal_defaults():
    assert literal_level_defaults(list(_sources())) == []
    fake = [(Path("emulator/x.py"), ast.parse("def f(raw, *, white_level=4095):\n    pass\n"
                                              "class C:\n    white_level: int = 4095\n"))]
    assert literal_level_defaults(fake) == ["emulator/x.py:1: white_level=4095", "emulator/x.py:4: white_level=4095"]


def test_literal_4094_only_where_the_default_is_defined():
    hits = []
    for rel, tree in _sources():
        for node in ast.walk(tree):
            if isinstance(node, ast.Constant) and type(node.value) is int and node.value == 4094:
                hits.append(rel.as_posix())
    assert hits == ["emulator/core/levels.py"]


# ------------------------------------------------------------------- one gray8 conversion
def test_png8_run_images_are_the_metrics_gray8_with_black_level(tmp_path):
    black, white = 64, 4095
    root, _ = write_static_sequence(tmp_path / "seq", n_cycles=3, shape=(16, 24))
    (root / "exposim.json").write_text(json.dumps({"white_level": white, "black_level": black}))
    seq = load_sequence(root)
    assert seq.black_level == black
    for save in ("png16", "png8"):
        runner.run_to_folder(seq, ["classical-50"], tmp_path / save, save=save, make_report=False)
    r16, r8 = read_run_folder(tmp_path / "png16"), read_run_folder(tmp_path / "png8")
    assert (r8.white_level, r8.black_level) == (white, black)
    compared = 0
    for f16, f8 in zip(r16.methods["classical-50"].frames, r8.methods["classical-50"].frames):
        import cv2

        raw = cv2.imread(str(f16.left), cv2.IMREAD_UNCHANGED)
        png8 = cv2.imread(str(f8.left), cv2.IMREAD_UNCHANGED)
        assert png8.dtype == np.uint8
        gray = bayer_to_gray8(raw, white_level=white, black_level=black)
        np.testing.assert_array_equal(png8, gray)
        # the metrics read either file to the same grey
        np.testing.assert_array_equal(load_gray8(f16.left, white_level=white, black_level=black), png8)
        np.testing.assert_array_equal(load_gray8(f8.left, white_level=white, black_level=black), png8)
        # ignoring the black level (the old png8) gives other values
        assert not np.array_equal(png8, bayer_to_gray8(raw, white_level=white, black_level=0))
        compared += 1
    assert compared == 3

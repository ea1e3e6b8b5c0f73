"""``exposim run``: run folder layout, refusal to overwrite, --resume after an interruption."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from emulator.commands.cli import main
from emulator.errors import PlaybackError
from emulator.io.runfolder import CSV_COLUMNS
from emulator.orchestration.runner import run_to_folder
from tests.emulator.playback.test_playback import write_static_sequence

METHODS = "classical-50,kim,zhang,fixed"


@pytest.fixture(scope="module")
def seq(tmp_path_factory):
    root, _ = write_static_sequence(tmp_path_factory.mktemp("cli") / "seq", n_cycles=6, shape=(32, 48))
    return root


def _files(run_dir):
    return {p.relative_to(run_dir).as_posix(): p.read_bytes() for p in sorted(run_dir.rglob("*"))
            if p.is_file() and p.suffix in (".csv", ".png", ".txt") and p.name != "exposure.png"}


@pytest.fixture(scope="module")
def clean_run(seq, tmp_path_factory):
    out = tmp_path_factory.mktemp("clean") / "run"
    assert main(["run", str(seq), "--methods", METHODS, "-o", str(out), "--save", "png16", "--no-progress"]) == 0
    return out


def test_layout_and_contract(clean_run, seq):
    info = json.loads((clean_run / "run.json").read_text())
    assert info["methods"] == METHODS.split(",") and info["save"] == "png16" and info["status"] == "complete"
    assert info["sequence"] == str(seq.resolve()) and info["white_level"] == 4095
    assert info["command"].startswith("exposim run ") and "--save png16" in info["command"]
    assert info["method_options"]["kim"]["seed"] == 0 and info["method_options"]["zhang"]["mode"] == "paper"
    results = json.loads((clean_run / "results.json").read_text())
    for name in METHODS.split(","):
        header = (clean_run / name / "exposures.csv").read_text().splitlines()[0].split(",")
        assert tuple(header[: len(CSV_COLUMNS)]) == CSV_COLUMNS
        lefts = sorted((clean_run / name / "images" / "left").iterdir())
        rights = sorted((clean_run / name / "images" / "right").iterdir())
        assert [p.name for p in lefts] == [p.name for p in rights] and len(lefts) == 6
        assert cv2.imread(str(lefts[0]), cv2.IMREAD_UNCHANGED).dtype == np.uint16
        times = (clean_run / name / "images" / "times.txt").read_text().splitlines()
        assert [f"{line.split()[0]}.png" for line in times] == [p.name for p in lefts]
        assert results["methods"][name]["cycles"] == 6
    for f in ("exposure.png", "report.md", "results.json"):
        assert (clean_run / f).is_file()


def test_png8_is_rounded_gray(seq, tmp_path):
    out = tmp_path / "run8"
    assert main(["run", str(seq), "--methods", "classical-50", "-o", str(out), "--save", "png8", "--no-progress"]) == 0
    p16 = tmp_path / "run16"
    assert main(["run", str(seq), "--methods", "classical-50", "-o", str(p16), "--save", "png16", "--no-progress"]) == 0
    name = sorted((out / "classical-50" / "images" / "left").iterdir())[2].name
    g8 = cv2.imread(str(out / "classical-50" / "images" / "left" / name), cv2.IMREAD_UNCHANGED)
    raw = cv2.imread(str(p16 / "classical-50" / "images" / "left" / name), cv2.IMREAD_UNCHANGED)
    gray = cv2.cvtColor(raw, cv2.COLOR_BayerRG2GRAY)
    assert g8.dtype == np.uint8 and np.array_equal(g8, np.rint(gray.astype(np.float64) * 255 / 4095).astype(np.uint8))


def test_refuses_to_overwrite(clean_run, seq, capsys):
    assert main(["run", str(seq), "--methods", "fixed", "-o", str(clean_run), "--no-progress"]) == 1
    assert "refusing to overwrite" in capsys.readouterr().err


def test_unknown_method_is_one_line_error(seq, tmp_path, capsys):
    assert main(["run", str(seq), "--methods", "fixed,bogus", "-o", str(tmp_path / "x"), "--no-progress"]) == 1
    err = capsys.readouterr().err
    assert "unknown AE method" in err and "bogus" in err and len(err.strip().splitlines()) == 1


def _interrupted_run(seq, out, after):
    def stop(done, total):
        if done == after:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_to_folder(seq, METHODS.split(","), out, save="png16", progress=stop,
                      command="exposim run (interrupted in a test)")
    info = json.loads((out / "run.json").read_text())
    assert info["status"] == "interrupted" and info["cycles_done"] == after


def test_resume_continues_to_the_same_result(clean_run, seq, tmp_path):
    out = tmp_path / "run"
    _interrupted_run(seq, out, after=3)
    # a torn last line, as if killed while writing a row
    with open(out / "kim" / "exposures.csv", "a") as fh:
        fh.write("3,17000000001363636")
    assert main(["run", str(seq), "-o", str(out), "--resume", "--no-progress"]) == 0
    info = json.loads((out / "run.json").read_text())
    assert info["status"] == "complete" and info["cycles_done"] == 6 and info["resumed"] == 1
    assert _files(out) == _files(clean_run)


def test_resume_detects_a_different_replay(seq, tmp_path, capsys):
    out = tmp_path / "run"
    _interrupted_run(seq, out, after=2)
    path = out / "classical-50" / "exposures.csv"
    lines = path.read_text().splitlines()
    fields = lines[2].split(",")
    fields[2] = "4.5"  # a recorded target that the replay will not produce
    lines[2] = ",".join(fields)
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(PlaybackError, match="differs from the recorded row"):
        run_to_folder(seq, METHODS.split(","), out, save="png16", resume=True)
    assert main(["run", str(seq), "-o", str(out), "--resume", "--mode", "borealhdr", "--no-progress"]) == 1
    assert "different configuration (mode)" in capsys.readouterr().err


def test_resume_without_a_run_folder(seq, tmp_path, capsys):
    assert main(["run", str(seq), "-o", str(tmp_path / "none"), "--resume", "--no-progress"]) == 1
    assert "no run to resume" in capsys.readouterr().err


def test_options_and_jobs(seq, tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    common = ["--methods", "kim,shim", "--option", "kim.window=3", "--seed", "2", "--mode", "borealhdr",
              "--initial-ms", "2.5", "--range-ms", "0.1", "30", "--no-progress"]
    assert main(["run", str(seq), "-o", str(a), *common]) == 0
    assert main(["run", str(seq), "-o", str(b), "--jobs", "2", *common]) == 0
    info = json.loads((a / "run.json").read_text())
    assert info["method_options"]["kim"]["window"] == 3 and info["method_options"]["kim"]["seed"] == 2
    assert info["range_ms"] == [0.1, 30.0] and info["initial_ms"] == 2.5
    for name in ("kim", "shim"):
        assert (a / name / "exposures.csv").read_bytes() == (b / name / "exposures.csv").read_bytes()


# ---------------------------------------------------------------------------- emulate --save
def _black_seq(tmp_path):
    """The static scene with black level 64 (every pixel is >= 100 DN, so none is below black)."""
    root, _ = write_static_sequence(tmp_path / "black", n_cycles=2, shape=(16, 24))
    (root / "exposim.json").write_text(json.dumps({"white_level": 4095, "black_level": 64}))
    return root


def test_emulate_png8_is_viewable_gray_with_the_black_level_subtracted(tmp_path, capsys):
    seq = _black_seq(tmp_path)
    out = tmp_path / "em"
    # ratio 1 from the 8 ms bracket: the png16 is the bracket itself, the png8 its grey
    assert main(["emulate", str(seq), "--exposure-ms", "8", "--cycle", "1", "--selector", "closest",
                 "-o", str(out), "--save", "png8", "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["save"] == "png8" and info["bracket_ms"] == 8.0
    for cam in ("left", "right"):
        g8 = cv2.imread(info["cameras"][cam]["output"], cv2.IMREAD_UNCHANGED)
        raw = cv2.imread(info["cameras"][cam]["source"], cv2.IMREAD_UNCHANGED)
        gray = cv2.cvtColor(raw, cv2.COLOR_BayerRG2GRAY).astype(np.float64)
        want = np.clip(np.rint((gray - 64) * 255 / (4095 - 64)), 0, 255).astype(np.uint8)
        assert g8.dtype == np.uint8 and np.array_equal(g8, want)
        assert 60 < g8.mean() < 200  # viewable: a 16-bit mosaic of ~1600 DN reads as ~2 % grey
    assert main(["emulate", str(seq), "--exposure-ms", "8", "--cycle", "1", "--selector", "closest",
                 "-o", str(tmp_path / "em16")]) == 0
    p16 = cv2.imread(str(tmp_path / "em16" / "left_cycle0001_8ms.png"), cv2.IMREAD_UNCHANGED)
    assert p16.dtype == np.uint16 and np.array_equal(p16, cv2.imread(info["cameras"]["left"]["source"],
                                                                     cv2.IMREAD_UNCHANGED))


def test_emulate_png8_equals_run_png8(tmp_path, capsys):
    """One code path: `emulate --save png8` and `run --save png8` write the same bytes for one target."""
    seq = _black_seq(tmp_path)
    run_dir = tmp_path / "run"
    assert main(["run", str(seq), "--methods", "classical-50", "--initial-ms", "5.5", "-o", str(run_dir),
                 "--save", "png8", "--no-progress"]) == 0
    capsys.readouterr()
    assert main(["emulate", str(seq), "--exposure-ms", "5.5", "--cycle", "0", "-o", str(tmp_path / "em"),
                 "--save", "png8", "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    ts = info["cameras"]["left"]["timestamp_ns"]
    for cam in ("left", "right"):
        a = cv2.imread(str(run_dir / "classical-50" / "images" / cam / f"{ts}.png"), cv2.IMREAD_UNCHANGED)
        b = cv2.imread(info["cameras"][cam]["output"], cv2.IMREAD_UNCHANGED)
        assert a.dtype == b.dtype == np.uint8 and np.array_equal(a, b)


def test_every_emulate_argument_is_documented():
    from emulator.commands.cli import build_parser

    sub = build_parser()._subparsers._group_actions[0].choices  # noqa: SLF001
    for cmd in ("emulate", "run", "info"):
        for action in sub[cmd]._actions:
            if action.dest != "help":
                assert action.help and action.help.strip(), (cmd, action.option_strings or action.dest)
    save = next(a for a in sub["emulate"]._actions if "--save" in a.option_strings)
    assert save.choices == ("png16", "png8") and save.default == "png16"


# ---------------------------------------------------------------------------- --help consistency
def _all_parsers():
    from emulator.commands.cli import build_parser

    stack = [("exposim", build_parser())]
    while stack:
        name, parser = stack.pop()
        yield name, parser
        for action in parser._actions:
            if action.__class__.__name__ == "_SubParsersAction":
                stack += [(f"{name} {k}", v) for k, v in action.choices.items()]


def test_cache_folder_options_render_cache_dir_and_frame_cache(capsys):
    """--cache-dir is the render cache everywhere; --frame-cache the decoded-frame cache (distinct names)."""
    seen, frames = [], []
    for name, parser in _all_parsers():
        help_text = parser.format_help()
        for action in parser._actions:
            for opt in action.option_strings:
                if "cache" in opt and opt != "--no-cache":
                    if opt == "--cache" or (opt == "--cache-dir" and name == "exposim cache"):  # old spellings
                        assert action.help == "==SUPPRESS==" and f"{opt} " not in help_text, name
                    elif opt == "--frame-cache":
                        frames.append(name)
                    else:
                        assert opt == "--cache-dir", (name, opt)
                        assert "render cache" in action.help, name
                        seen.append(name)
    assert {"exposim render", "exposim synth"} <= set(seen)
    assert set(frames) == {"exposim cache", "exposim run", "exposim info", "exposim emulate"}
    from emulator.commands.cli import build_parser

    sub = build_parser()._subparsers._group_actions[0].choices  # noqa: SLF001
    for cmd in ("render", "synth"):
        old = sub[cmd].parse_args(["static_lab", "-o", "x", "--cache", "/tmp/c"])
        new = sub[cmd].parse_args(["static_lab", "-o", "x", "--cache-dir", "/tmp/c"])
        assert str(old.cache) == str(new.cache) == "/tmp/c"


def test_fixed_is_explained_in_help_readme_and_report(clean_run):
    from pathlib import Path

    from emulator.autoexposure import make_method
    from emulator.autoexposure.classical import N_AUTO_FRAMES
    from emulator.commands.cli import build_parser

    n = N_AUTO_FRAMES
    # the documented numbers are the method's: it adjusts on n frames (n + 1 in borealhdr mode)
    for mode, frames in (("paper", n), ("borealhdr", n + 1)):
        m = make_method("fixed", mode=mode)
        assert m.n_adjustments == frames
    sub = build_parser()._subparsers._group_actions[0].choices  # noqa: SLF001
    methods_help = " ".join(next(a for a in sub["run"]._actions if "--methods" in a.option_strings).help.split())
    assert f"'fixed' runs classical-50 for its first {n} frames ({n + 1} with --mode borealhdr) and then freezes" \
        in methods_help
    readme = " ".join((Path(__file__).resolve().parents[3] / "docs" / "commands.md").read_text().split())
    assert f"`fixed` (runs `classical-50` for its first {n} frames, {n + 1} with `--mode borealhdr`, then freezes" \
        in readme
    report = (clean_run / "report.md").read_text()
    assert f"`fixed` runs classical-50 for its first {n} frames and then freezes its exposure" in report


# ---------------------------------------------------------------------------- run --noise (issue 14)
@pytest.fixture(scope="module")
def noise_model_file(seq, tmp_path_factory):
    from emulator.io.borealhdr import load_sequence, sequence_response
    from emulator.io.noisemodel import write_noise_model
    from emulator.noise import NoiseModel

    response = sequence_response(load_sequence(seq))
    path = tmp_path_factory.mktemp("nm") / "noise.json"
    write_noise_model(path, NoiseModel.from_full_well(response, 3000.0, 2.0, name="test-camera"))
    return path


def _noise_run(seq, out, model, seed, *extra):
    return main(["run", str(seq), "--methods", "classical-50", "-o", str(out), "--save", "png16",
                 "--no-progress", "--noise", "consistent", "--noise-model", str(model), "--noise-seed", str(seed),
                 *extra])


def test_noise_consistent_is_seeded_and_recorded(seq, noise_model_file, clean_run, tmp_path, capsys):
    a, b, c, plain = tmp_path / "a", tmp_path / "b", tmp_path / "c", tmp_path / "plain"
    for out, seed in ((a, 5), (b, 5), (c, 6)):
        assert _noise_run(seq, out, noise_model_file, seed, "--initial-ms", "5") == 0
    assert main(["run", str(seq), "--methods", "classical-50", "-o", str(plain), "--save", "png16",
                 "--no-progress", "--initial-ms", "5"]) == 0
    fa, fb, fc = _files(a), _files(b), _files(c)
    assert fa == fb  # same seed: identical CSVs and PNG bytes
    assert len([k for k in fa if k.endswith(".png")]) == 2 * 6
    # another seed changes every image emulated at a ratio other than 1
    rows = [r.split(",") for r in (a / "classical-50" / "exposures.csv").read_text().splitlines()[1:]]
    emulated = [r[1] for r in rows if float(r[4]) != 1.0]
    assert emulated and rows[0][1] in emulated
    for ts in emulated:
        for cam in ("left", "right"):
            assert fa[f"classical-50/images/{cam}/{ts}.png"] != fc[f"classical-50/images/{cam}/{ts}.png"]
    # cycle 0: target 5 ms from the 8 ms bracket in both runs; the consistent image carries added
    # zero-mean noise (the 8 ms source is cleaner than a 5 ms capture), the plain one is eq. 2 exactly
    assert rows[0][2:4] == ["5.0", "8.0"]
    ts = rows[0][1]
    noisy = cv2.imread(str(a / "classical-50" / "images" / "left" / f"{ts}.png"), cv2.IMREAD_UNCHANGED)
    exact = cv2.imread(str(plain / "classical-50" / "images" / "left" / f"{ts}.png"), cv2.IMREAD_UNCHANGED)
    diff = noisy.astype(np.float64) - exact.astype(np.float64)
    assert np.count_nonzero(diff) > diff.size // 2 and abs(diff.mean()) < 0.02 * exact.mean()
    info = json.loads((a / "run.json").read_text())
    assert info["noise"]["mode"] == "consistent" and info["noise"]["seed"] == 5
    assert info["noise"]["model"]["name"] == "test-camera" and info["noise"]["model"]["gain_e_per_h"] > 0
    assert info["noise_model_file"] == str(noise_model_file.resolve())
    assert "--noise consistent" in info["command"] and "--noise-seed 5" in info["command"]
    assert json.loads((plain / "run.json").read_text())["noise"] == {"mode": "none"}


def test_resume_refuses_another_noise_setting(seq, noise_model_file, tmp_path, capsys):
    out = tmp_path / "run"
    assert _noise_run(seq, out, noise_model_file, 5) == 0
    before = _files(out)
    capsys.readouterr()
    for extra in (["--noise", "none"], ["--noise", "consistent", "--noise-seed", "6"]):
        assert main(["run", str(seq), "-o", str(out), "--no-progress", "--resume", *extra]) == 1
        err = capsys.readouterr().err
        assert "different configuration (noise)" in err and len(err.strip().splitlines()) == 1
    assert _files(out) == before
    # the recorded setting (model file found again from run.json) resumes
    assert main(["run", str(seq), "-o", str(out), "--no-progress", "--resume"]) == 0
    assert _files(out) == before


def test_noise_without_a_model_is_one_line_error(seq, tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["run", str(seq), "-o", str(out), "--no-progress", "--noise", "consistent"]) == 1
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "needs a noise model" in err and "--noise-model" in err
    assert not out.exists()
    missing = tmp_path / "none.json"
    assert main(["run", str(seq), "-o", str(out), "--no-progress", "--noise", "consistent",
                 "--noise-model", str(missing)]) == 1
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and f"{missing}: noise model file not found" in err
    bad = tmp_path / "bad.json"
    bad.write_text("{")
    assert main(["run", str(seq), "-o", str(out), "--no-progress", "--noise", "consistent",
                 "--noise-model", str(bad)]) == 1
    assert f"{bad}: malformed JSON" in capsys.readouterr().err
    assert not out.exists()


def test_synthetic_recording_carries_its_noise_model(tmp_path):
    """A synth recording's exposim.json camera gives the model synth.noise_model.noise_model_of would."""
    from emulator.io.borealhdr import load_sequence, sequence_response
    from emulator.io.noisemodel import noise_model_from_metadata
    from synth.camera import Camera
    from synth.noise_model import noise_model_of

    root, _ = write_static_sequence(tmp_path / "synthlike", n_cycles=2, shape=(16, 24))
    camera = Camera(name="lab", width=24, height=16, white_level=4095,
                    full_well_e=3000.0, read_noise_e=2.0)
    (root / "exposim.json").write_text(json.dumps({"white_level": 4095, "black_level": 0,
                                                   "camera": camera.to_dict()}, default=list))
    seq = load_sequence(root)
    response = sequence_response(seq)
    model = noise_model_from_metadata(seq.metadata, response)
    exact = noise_model_of(camera)
    assert model.gain_e_per_h == pytest.approx(exact.gain_e_per_h, rel=1e-12)
    assert model.read_noise_e == exact.read_noise_e and model.name == "synth:lab"
    out = tmp_path / "run"
    assert main(["run", str(root), "--methods", "classical-50", "-o", str(out), "--no-progress",
                 "--noise", "consistent"]) == 0
    info = json.loads((out / "run.json").read_text())
    assert info["noise_model_file"] == str((root / "exposim.json").resolve())
    assert info["noise"]["model"]["name"] == "synth:lab"
    assert main(["run", str(root), "-o", str(out), "--no-progress", "--resume"]) == 0


def test_summary_labels_the_proposal_after_the_last_frame(seq, tmp_path, capsys):
    """The printed exposure beside the mean is the proposal made after the last frame, and says so."""
    out = tmp_path / "run"
    assert main(["run", str(seq), "--methods", "classical-50", "-o", str(out), "--no-progress"]) == 0
    printed = capsys.readouterr().out
    results = json.loads((out / "results.json").read_text())
    m = results["methods"]["classical-50"]
    import csv

    with (out / "classical-50" / "exposures.csv").open() as fh:
        last_next = float(list(csv.DictReader(fh))[-1]["next_ms"])
    assert m["final_exposure_ms"] == last_next
    line = next(ln for ln in printed.splitlines() if ln.strip().startswith("classical-50"))
    assert f"next (after last frame) {last_next:8.3f} ms" in line and "final" not in line

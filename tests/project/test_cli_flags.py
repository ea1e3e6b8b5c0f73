"""One command-line surface: -q/--quiet everywhere bars are drawn, --json where results are printed,
no progress bar outside a terminal, help without issue numbers, one --size WxH, no empty -o after a failure."""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from emulator.commands.cli import build_parser, main
from emulator.commands.progress import bars_enabled, progress_bar

ROOT = Path(__file__).resolve().parents[2]

try:
    from tests.emulator.playback.test_playback import write_static_sequence
except ImportError:  # tests collected as a package
    from tests.test_playback import write_static_sequence


def leaf_parsers(parser=None, prefix=("exposim",)):
    """(command words, parser) of every runnable sub-command."""
    parser = parser or build_parser()
    subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]  # noqa: SLF001
    if not subs:
        yield prefix, parser
        return
    for name, sub in subs[0].choices.items():
        yield from leaf_parsers(sub, (*prefix, name))


LEAVES = dict(leaf_parsers())
#: Commands that draw a progress bar on long work.
WITH_BARS = {"run", "cache", "calibrate", "bench features", "bench vo", "render", "synth", "demo",
             "validate emulation", "validate selectors", "validate motion", "validate speed", "validate ae-study",
             "validate live", "validate render"}
#: Commands that print results (a table, a summary, a figure).
WITH_RESULTS = {"info", "cache", "emulate", "run", "calibrate", "bench features", "bench vo", "bench rpe", "demo",
                "validate emulation", "validate selectors", "validate motion", "validate speed",
                "validate ae-study", "validate live", "validate render"}


def options(parser) -> dict[str, argparse.Action]:
    return {s: a for a in parser._actions for s in a.option_strings}  # noqa: SLF001


def test_every_command_with_a_bar_has_quiet_and_the_hidden_old_spelling():
    names = {" ".join(words[1:]) for words in LEAVES}
    assert WITH_BARS <= names
    for words, parser in LEAVES.items():
        name = " ".join(words[1:])
        if name not in WITH_BARS:
            continue
        opts = options(parser)
        assert opts["-q"] is opts["--quiet"] and opts["-q"].dest == "quiet", name
        assert opts["--no-progress"].dest == "quiet" and opts["--no-progress"].help == argparse.SUPPRESS, name
        assert "--no-progress" not in parser.format_help(), name


def test_every_command_that_prints_results_has_json():
    for words, parser in LEAVES.items():
        if " ".join(words[1:]) in WITH_RESULTS:
            assert "--json" in options(parser), words


def test_help_has_no_issue_numbers_one_size_option_and_explained_options():
    for words, parser in LEAVES.items():
        text = parser.format_help()
        assert not re.search(r"\b[Ii]ssue \d+", text), words
        opts = options(parser)
        if "--size" in opts:
            assert "--width" not in opts and "--height" not in opts, words
    synth_help = " ".join(LEAVES[("exposim", "synth")].format_help().split())
    assert "(pcalib_inside1), or a linear, gamma 2.2 or S-shaped curve (default borealhdr)" in synth_help
    assert "--width" not in options(LEAVES[("exposim", "validate", "emulation")])


def test_help_names_no_module_path_nor_internal_constant():
    """Help speaks to the user: what an option does, not where it lives in the code."""
    for words, parser in LEAVES.items():
        text = " ".join(parser.format_help().split())
        assert not re.search(r"\b(emulator|validation|scenes|synth)\.[a-z_]+", text), (words, text)
        assert "RATIO_TEST" not in text and "earlier exposim" not in text.lower(), words
    for words in (("exposim", "run"), ("exposim", "emulate")):
        action = options(LEAVES[words])["--blur-aware"]
        text = " ".join(action.help.split())
        assert "take the shorter one when the longer one's extra motion blur (predicted from the gyro) costs more " \
               "than the shorter one's extra noise" in text, words
        assert "one pixel of blur weighs as much as twice the relative noise of a capture at the target" in text


def test_bars_only_on_a_terminal(tmp_path):
    class Stream:
        def __init__(self, tty):
            self.tty = tty

        def isatty(self):
            return self.tty

        def write(self, s):
            pass

        def flush(self):
            pass

    assert bars_enabled(False, Stream(True)) and not bars_enabled(True, Stream(True))
    assert not bars_enabled(False, Stream(False)) and not bars_enabled(False, object())
    assert progress_bar(False, total=3, file=Stream(False)).disable is True
    assert progress_bar(False, total=3, file=Stream(True)).disable is False


def test_a_run_with_stderr_in_a_file_draws_no_bar(tmp_path):
    seq = write_static_sequence(tmp_path / "seq", n_cycles=6, shape=(32, 48))[0]
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    with open(tmp_path / "stderr.txt", "w") as err:
        got = subprocess.run([sys.executable, "-c", "import sys; from emulator.commands.cli import main; sys.exit(main())",
                              "run", str(seq), "--methods", "classical-50", "--save", "none", "-o", str(tmp_path / "r")],
                             stdout=subprocess.PIPE, stderr=err, text=True, env=env, timeout=300)
    assert got.returncode == 0
    log = (tmp_path / "stderr.txt").read_text()
    assert "\r" not in log and "cycle/s" not in log and "it/s" not in log and "%|" not in log


def test_a_bad_argument_fails_before_any_bar_or_folder(tmp_path, capsys):
    seq = write_static_sequence(tmp_path / "seq", n_cycles=3, shape=(32, 48))[0]
    assert main(["run", str(seq), "--methods", "no-such-method", "-o", str(tmp_path / "r")]) == 1
    err = capsys.readouterr().err
    assert "no-such-method" in err and "%|" not in err
    assert not (tmp_path / "r").exists()


def test_failed_bench_leaves_no_output_folder_and_json_prints_results(tmp_path, capsys):
    assert main(["bench", "features", str(tmp_path / "missing-run"), "-o", str(tmp_path / "out")]) == 1
    assert "missing-run" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()
    seq = write_static_sequence(tmp_path / "seq", n_cycles=4, shape=(96, 128))[0]
    assert main(["run", str(seq), "--methods", "classical-50", "--save", "png16", "-o", str(tmp_path / "run"), "-q"]) == 0
    capsys.readouterr()
    assert main(["bench", "features", str(tmp_path / "run"), "-o", str(tmp_path / "feat"), "--json", "-q"]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert printed == json.loads((tmp_path / "feat" / "results.json").read_text())
    assert (tmp_path / "feat" / "report.html").is_file()


def test_a_missing_response_names_the_flag(tmp_path, capsys):
    import shutil

    seq = write_static_sequence(tmp_path / "seq", n_cycles=2, shape=(32, 48))[0]
    shutil.rmtree(seq / "calibration")
    assert main(["run", str(seq), "--methods", "classical-50", "-o", str(tmp_path / "r"), "-q"]) == 1
    err = capsys.readouterr().err
    assert "no response file found" in err and "pass the inverse response with --response FILE" in err
    assert not (tmp_path / "r").exists()


def test_a_frame_cache_elsewhere_serves_run_info_and_emulate(tmp_path, capsys):
    seq = write_static_sequence(tmp_path / "seq", n_cycles=3, shape=(32, 48))[0]
    before = sorted(p.relative_to(seq) for p in seq.rglob("*"))
    cache = tmp_path / "frames"
    assert main(["cache", str(seq), "--frame-cache", str(cache), "-q", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["frames"] == summary["written"] == 3 * 6 * 2 and summary["cache_dir"] == str(cache)
    assert len(list(cache.rglob("*.npy.zst"))) == 3 * 6 * 2
    assert main(["run", str(seq), "--methods", "classical-50", "-o", str(tmp_path / "plain"), "-q"]) == 0
    assert main(["run", str(seq), "--methods", "classical-50", "-o", str(tmp_path / "cached"), "-q",
                 "--frame-cache", str(cache)]) == 0
    csv = "classical-50/exposures.csv"
    assert (tmp_path / "cached" / csv).read_bytes() == (tmp_path / "plain" / csv).read_bytes()
    capsys.readouterr()
    assert main(["info", str(seq), "--frame-cache", str(cache), "--json"]) == 0
    assert len(json.loads(capsys.readouterr().out)["cycles"]) == 3
    assert main(["emulate", str(seq), "--exposure-ms", "3", "--cycle", "1", "--frame-cache", str(cache),
                 "-o", str(tmp_path / "emu")]) == 0
    assert sorted(p.relative_to(seq) for p in seq.rglob("*")) == before  # nothing written into the recording
    assert main(["info", str(seq), "--frame-cache", str(tmp_path / "nope")]) == 1
    assert "frame cache folder not found" in capsys.readouterr().err


def test_one_ratio_threshold_for_features_and_vo():
    from emulator.commands.bench import _RATIO_TEST
    from emulator.metrics.features import RATIO_TEST
    from emulator.metrics.vo import VOParameters

    assert _RATIO_TEST == RATIO_TEST == VOParameters().ratio
    for words in (("exposim", "bench", "features"), ("exposim", "bench", "vo")):
        action = options(LEAVES[words])["--ratio"]
        assert action.default is None and f"default {RATIO_TEST}, the same for features and VO" in action.help


def test_a_plugin_shows_as_plugin_not_none_in_the_run_report(tmp_path, monkeypatch):
    from emulator.orchestration.runner import run_to_folder

    (tmp_path / "plain_ae.py").write_text((ROOT / "examples" / "my_ae.py").read_text())
    monkeypatch.syspath_prepend(str(tmp_path))
    seq = write_static_sequence(tmp_path / "seq", n_cycles=3, shape=(32, 48))[0]
    summary = run_to_folder(seq, "classical-50,plain_ae:MyAE", tmp_path / "run")
    assert {n: m["mode"] for n, m in summary["methods"].items()} == {"classical-50": "paper", "my-ae": "plugin"}
    report = (tmp_path / "run" / "report.md").read_text()
    assert "| my-ae | plugin |" in report and "None" not in report
    sys.modules.pop("plain_ae", None)


@pytest.mark.render
def test_validate_json_prints_results_json(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("EXPOSIM_DENOISE", "off")
    out = tmp_path / "emul"
    assert main(["validate", "emulation", "--quick", "-o", str(out), "--exposures", "6", "--responses", "borealhdr",
                 "--scenes", "static_lab", "--size", "32x20", "--spp", "4", "-q", "--json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert printed == json.loads((out / "results.json").read_text())
    command = printed["provenance"]["command"]
    assert "--size 32x20" in command and "--width" not in command
    html = (out / "report.html").read_text()
    assert html.count('<img src="data:image/png;base64,') == len([f for f in printed["figures"] if f.endswith(".png")])

"""The run settings' spine (:mod:`emulator.playback.settings`): a setting declared once, as a field of
:class:`~emulator.playback.RunConfig` with its metadata, reaches the parser's flags, ``run.json``, the
resume check and the rebuilt command line; a dataset run builds its configuration once.
"""

from __future__ import annotations

import argparse
import dataclasses

import pytest

from emulator.commands.cli import main
from emulator.errors import PlaybackError
from emulator.playback import RunConfig, settings
from emulator.playback.config import CONFIG_KEYS, DEFAULT_METHOD_TIMEOUT_S
from emulator.playback.settings import setting
from tests.emulator.playback.test_playback import write_static_sequence


@pytest.fixture
def with_level():
    """RunConfig with one more setting, declared as one field."""
    extra = setting(3, flag="--extra-level", help="an added setting", key="extra_level", resume=True, command=99,
                    cli={"type": int})
    return dataclasses.make_dataclass("WithLevel", [("extra_level", int, extra)], bases=(RunConfig,), frozen=True)


def test_an_added_setting_is_a_flag_of_the_parser(with_level):
    parser = argparse.ArgumentParser()
    settings.add_arguments(parser, with_level)
    args = parser.parse_args(["--extra-level", "5", "--jobs", "2"])
    assert args.extra_level == 5 and args.jobs == 2
    assert parser.parse_args([]).extra_level is None  # not given: the recorded or default value wins
    given = settings.given(args, with_level)
    assert given["extra_level"] == 5 and given["selector"] is None
    assert settings.flag_of(with_level, "extra_level") == "--extra-level"
    assert (99, ["--extra-level", "5"]) in settings.command_words(args, with_level)
    assert with_level(**{k: v for k, v in given.items() if v is not None}).extra_level == 5


def test_an_added_setting_is_written_to_run_json_and_read_back(with_level):
    written = with_level(extra_level=5).to_json()
    assert written["extra_level"] == 5
    assert with_level.from_json(written).extra_level == 5
    old = RunConfig().to_json()  # a folder from before the setting: its default
    assert "extra_level" not in old and with_level.from_json(old).extra_level == 3


def test_an_added_setting_is_compared_on_resume(with_level):
    recorded = with_level(extra_level=5).to_json()
    assert "extra_level" in settings.resume_keys(with_level)
    with_level(extra_level=5).check_resume(recorded)
    with pytest.raises(PlaybackError, match=r"different configuration \(extra_level\): recorded extra_level=5"):
        with_level(extra_level=4).check_resume(recorded)
    with_level(extra_level=4).check_resume(recorded, given=("selector",))  # not given: not compared
    back = with_level(extra_level=5, jobs=3).resumed(recorded)
    assert (back.extra_level, back.jobs) == (5, 3)  # the recorded configuration, this run's jobs


def test_run_config_declares_the_keys_a_resume_compares():
    assert set(CONFIG_KEYS) == {"initial_ms", "range_ms", "selector", "mode", "save", "options", "method_timeout_s",
                                "noise", "blur", "skip_partial", "rate", "latency_frames", "native_warp",
                                "native_blur_aware"}


@pytest.mark.parametrize("kw, applied", [({}, DEFAULT_METHOD_TIMEOUT_S), ({"workers": "inline"}, None),
                                         ({"method_timeout_s": 7}, 7.0),
                                         ({"method_timeout_s": 7, "workers": "inline"}, 7.0)])
def test_the_applied_limit_is_written_once_beside_the_isolation(kw, applied):
    config = RunConfig(**kw)
    assert config.method_timeout_applied_s == applied
    assert config.to_json()["method_timeout_applied_s"] == applied
    assert config.per_run_json() == {"jobs": 1, "workers": kw.get("workers", "process"),
                                     "method_timeout_applied_s": applied}


def test_old_folders_read_with_their_defaults():
    old = {"selector": "closest", "method_timeout": 9, "rate": "native", "noise": None}
    config = RunConfig.from_json(old)
    assert (config.png_level, config.method_timeout_s, config.native_warp, config.noise) == (1, 9.0, "rotation", "none")


def test_a_run_builds_its_configuration_once(tmp_path, monkeypatch, capsys):
    root = tmp_path / "data"
    write_static_sequence(root / "a", n_cycles=3, shape=(16, 24))
    built = []
    real = RunConfig.__post_init__
    monkeypatch.setattr(RunConfig, "__post_init__", lambda self: (built.append(1), real(self))[1])
    common = ["--methods", "classical-50", "--isolation", "inline", "--initial-ms", "2", "-q"]
    assert main(["run", str(root), "--sequences", "all", "--scheduler", "serial", *common,
                 "-o", str(tmp_path / "out")]) == 0
    assert len(built) == 1  # a dataset run, its unit included
    for extra in ([], ["--resume"]):
        built.clear()
        assert main(["run", str(root / "a"), *common, "-o", str(tmp_path / "one"), *extra]) == 0
        assert len(built) == 1


def test_the_older_workers_flag_is_read_with_a_notice(tmp_path, capsys):
    root = tmp_path / "data"
    write_static_sequence(root / "a", n_cycles=2, shape=(16, 24))
    assert main(["run", str(root / "a"), "--methods", "classical-50", "--workers", "inline", "-o",
                 str(tmp_path / "out"), "-q"]) == 0
    err = capsys.readouterr().err.splitlines()
    assert "exposim run: note: --workers inline is now spelled --isolation inline" in err
    text = (tmp_path / "out" / "run.json").read_text()
    assert '"workers": "inline"' in text and "--isolation inline" in text

"""validation.live.portable: a study folder names no path outside the repository and holds every study file."""

import json

from tests.validation.live.test_live_evidence import _records

from validation.live.config import CONDITIONS
from validation.live.portable import ABSOLUTE_PATH, REPOSITORY, outside_paths, relative_command
from validation.verdicts.simulate import Scales, simulate_tables


def test_absolute_paths_are_found_and_nothing_else():
    text = ("speed 2 km/h at tcp://host:8786, emulated / live, walks/<scene>.json, noise/method; "
            "`/tmp/s22/study` and (/home/u/x.json) and C:\\data\\walks")
    assert ABSOLUTE_PATH.findall(text) == ["/tmp/s22/study", "/home/u/x.json", "C:\\data\\walks"]


def test_the_command_is_recorded_relative_to_the_study_folder():
    cmd = "exposim validate live -o /tmp/a/study --cache-dir /tmp/a/cache --quick"
    assert relative_command(cmd, "/tmp/a/study") == "exposim validate live -o . --cache-dir ../cache --quick"
    assert relative_command(None, "/tmp") is None


def test_outside_paths_lists_each_file_and_path(tmp_path):
    (tmp_path / "a").mkdir()
    (tmp_path / "a" / "run.json").write_text(json.dumps({"sequence": "/elsewhere/x/seq", "ok": "../datasets/x"}))
    (tmp_path / "report.md").write_text(f"see {REPOSITORY / 'docs' / 'verdicts.md'} and /elsewhere/x/seq")
    (tmp_path / "figure.png").write_bytes(b"/elsewhere/y/z")  # not a text file: not read
    assert outside_paths(tmp_path) == ["a/run.json: /elsewhere/x/seq", "report.md: /elsewhere/x/seq"]
    assert outside_paths(tmp_path, skip=("report.md",)) == ["a/run.json: /elsewhere/x/seq"]


def test_a_study_folder_is_complete_and_names_no_outside_path(tmp_path):
    from validation.live.experiment import finish_replicated, redraw

    sim = simulate_tables("live-draw", 40, Scales(sd_method=1.0, sd_walk_method=0.3, sd_noise=0.3), seed=7)
    tables = {CONDITIONS["cycle-rate live"]: sim["live"][0], CONDITIONS["emulated"]: sim["emulated"][0],
              CONDITIONS["cycle-rate live re-seeded"]: sim["control"][0]}
    out = tmp_path / "study"
    res = finish_replicated(out, _records(tables, 10), command=f"exposim validate live -o {out} --replicates 10",
                            power_seeds=0)
    assert res["command"] == "exposim validate live -o . --replicates 10"
    assert res["study_folder"] == {"missing_files": [], "files_naming_outside_paths": []}
    assert {"results.json", "report.md", "walks.csv", "power.json"} <= {p.name for p in out.iterdir()}
    assert outside_paths(out) == []
    assert "not ready to be committed" not in (out / "report.md").read_text()
    # a file that names a path outside the repository is found, and the report says so
    (out / "notes.md").write_text("made from /scratch/me/raw")
    again = redraw(out)
    assert again["study_folder"]["files_naming_outside_paths"] == ["notes.md"]
    assert "not ready to be committed" in (out / "report.md").read_text()
    assert "/scratch" not in (out / "results.json").read_text() + (out / "report.md").read_text()

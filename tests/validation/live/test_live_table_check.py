"""validation.live.table_check: a study folder redraws from walks.csv whatever its rows' order, and strictly."""

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from validation.live.config import CONDITIONS, METHODS, SCENES, LiveConfig, LiveError
from validation.verdicts.simulate import Scales, simulate_tables

ROOT = Path(__file__).resolve().parents[3]
COMMITTED = sorted(p.parent for p in (ROOT / "docs" / "results").glob("*/walks.csv"))
OUTPUTS = ("results.json", "report.md", "power.json", "calibration.json")


def _study(tmp_path: Path) -> Path:
    """A 48-walk study folder (12 seeds x 4 scenes) of its walks table and results.json alone."""
    from validation.live.experiment import finish_replicated

    sim = simulate_tables("live-draw", 48, Scales(sd_method=1.0, sd_walk_method=0.3, sd_noise=0.3), seed=7)
    tables = {CONDITIONS["cycle-rate live"]: sim["live"][0], CONDITIONS["emulated"]: sim["emulated"][0]}
    cfg = LiveConfig(scenes=tuple(SCENES), n_cycles=40).to_dict()
    recs = []
    for k in range(12):
        summ = {run: {"per_scene": {s: {m: {"median_uniformity": v, "median_matches": v, "vo": {"n_failed_frames": v}}
                                        for m, v in zip(METHODS, map(float, t[k * len(SCENES) + i]))}
                                    for i, s in enumerate(SCENES)}} for run, t in tables.items()}
        recs.append({"config": {**cfg, "seed": k}, "summaries": summ, "timings": {"total_s": 1.0}})
    finish_replicated(tmp_path, recs, command="test", power_seeds=0, calibration_studies=0)
    return tmp_path


def _redraw(folder: Path) -> dict:
    from validation.live.experiment import redraw

    redraw(folder, calibration_studies=0)
    return {f: (folder / f).read_bytes() for f in OUTPUTS if (folder / f).is_file()}


def test_the_same_rows_in_another_order_redraw_the_same_bytes(tmp_path):
    folder = _study(tmp_path)
    first = _redraw(folder)
    lines = (folder / "walks.csv").read_text().splitlines()
    rng = np.random.default_rng(3)
    shuffled = [lines[0]] + [lines[1 + i] for i in rng.permutation(len(lines) - 1)]
    (folder / "walks.csv").write_text("\n".join(shuffled) + "\n")
    again = _redraw(folder)
    assert set(again) == set(first) and "results.json" in first
    for f in first:
        assert again[f] == first[f], f
    walks = json.loads(first["results.json"])["walks"]
    assert walks[:9] == [f"{s}/seed0" for s in SCENES] + [f"{s}/seed1" for s in SCENES] + [f"{SCENES[0]}/seed10"]


@pytest.mark.parametrize("folder", COMMITTED, ids=lambda p: p.name)
def test_the_committed_tables_are_in_their_key_order(folder):
    """Their bytes do not change: their rows are already in the order the redraw sorts them into."""
    from validation.live.evidence import parse_walks_table
    from validation.live.table_check import canonical_order

    cfg = json.loads((folder / "results.json").read_text())["config"]
    walks, methods, tables = parse_walks_table((folder / "walks.csv").read_text())
    w2, m2, t2 = canonical_order(walks, methods, tables, scenes=cfg["scenes"], method_order=cfg["methods"])
    assert (w2, m2, list(t2)) == (walks, methods, list(tables))
    rows = list(csv.DictReader((folder / "walks.csv").open()))
    assert len(rows) == len(walks) * len(methods) * len(tables)


def _edit(folder: Path, fn) -> None:
    lines = (folder / "walks.csv").read_text().splitlines()
    (folder / "walks.csv").write_text("\n".join(fn(lines)) + "\n")


def _cell(line: str, value: str, field: int = 6) -> str:
    f = line.split(",")
    f[field] = value
    return ",".join(f)


@pytest.mark.parametrize("value", ["nan", "inf", "1.50", "0x10", " 2.0"])
def test_a_cell_the_writer_would_not_write_is_refused_naming_the_line(tmp_path, value):
    folder = _study(tmp_path)
    _edit(folder, lambda ls: ls[:4] + [_cell(ls[4], value)] + ls[5:])
    with pytest.raises(LiveError, match=r"walks.csv: line 5: cell .* not as the writer writes"):
        _redraw(folder)


def test_a_walk_or_method_missing_or_extra_against_the_record_is_refused(tmp_path):
    folder = _study(tmp_path)
    text = (folder / "walks.csv").read_text()
    lines = text.splitlines()
    # an extra walk: a seed the study did not run
    extra = lines[1].replace("/seed0,", "/seed99,").replace(",0,fixed,", ",99,fixed,")
    _edit(folder, lambda ls: ls + [extra])
    with pytest.raises(LiveError, match=rf"line {len(lines) + 1}: walk {SCENES[0]}/seed99 is not one of the study"):
        _redraw(folder)
    # a missing walk: every row of one walk left out
    (folder / "walks.csv").write_text(text)
    _edit(folder, lambda ls: [x for x in ls if not x.startswith(f"{SCENES[1]}/seed3,")])
    with pytest.raises(LiveError, match=rf"no row for walk {SCENES[1]}/seed3, which the study's record holds"):
        _redraw(folder)
    # a missing method, and an extra one
    (folder / "walks.csv").write_text(text)
    _edit(folder, lambda ls: [x for x in ls if ",kim," not in x])
    with pytest.raises(LiveError, match="no row for method kim"):
        _redraw(folder)
    (folder / "walks.csv").write_text(text)
    _edit(folder, lambda ls: ls + [ls[1].replace(",fixed,", ",oracle,")])
    with pytest.raises(LiveError, match=rf"line {len(lines) + 1}: method oracle is not one of the study's methods"):
        _redraw(folder)
    # a scene or seed column that does not match its walk
    (folder / "walks.csv").write_text(text)
    _edit(folder, lambda ls: ls[:2] + [_cell(ls[2], "7", field=2)] + ls[3:])
    with pytest.raises(LiveError, match="line 3: scene .* and seed '7' do not match walk"):
        _redraw(folder)
    # the table as written still redraws
    (folder / "walks.csv").write_text(text)
    assert "results.json" in _redraw(folder)


def test_a_failed_walk_of_the_record_is_not_expected(tmp_path):
    from validation.live.table_check import record_walks

    res = {"config": {"scenes": ["a", "b"], "seed": 3}, "replicates": ["replicates/seed3", "replicates/seed4"],
           "failed_walks": [{"walk": "b/seed3", "error": "x"}]}
    assert record_walks(res) == ["a/seed3", "a/seed4", "b/seed4"]
    assert record_walks({"config": {"scenes": ["a"], "seed": 5}}) == ["a/seed5"]

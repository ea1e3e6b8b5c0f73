"""validation.live.evidence: walk tables from benchmark summaries, the replicated verdicts, results.json's contract."""

import json

import numpy as np
import pytest

from validation.live.config import CONDITIONS, JUDGED_METRICS, METHODS, METRICS, SCENES, LiveConfig
from validation.live.evidence import walk_value, walk_values
from validation.verdicts.simulate import Scales, simulate_tables


def _entry(v: float) -> dict:
    """A per-scene summary entry whose every ranked metric is ``v`` (or a function of it)."""
    return {"median_uniformity": v, "median_matches": v, "sequence_success": {"100": v > 0},
            "segment_success": {"100": {"rate": v}}, "vo": {"n_failed_frames": v, "rpe_trans_pct": v}}


def _records(tables: dict, n_rep: int, scenes=SCENES, n_cycles: int = 40) -> list[dict]:
    """Experiment records (raw.json content) holding ``tables`` (run -> (walks, methods)) over n_rep seeds."""
    cfg = LiveConfig(scenes=tuple(scenes), n_cycles=n_cycles).to_dict()
    recs = []
    for k in range(n_rep):
        summ = {}
        for run, t in tables.items():
            summ[run] = {"per_scene": {s: {m: _entry(float(t[k * len(scenes) + i, j])) for j, m in enumerate(METHODS)}
                                       for i, s in enumerate(scenes)}}
        recs.append({"config": {**cfg, "seed": k}, "summaries": summ, "timings": {"total_s": 1.0}})
    return recs


def test_walk_value_paths_and_missing():
    e = _entry(3.0)
    assert walk_value(e, "rpe_trans_pct") == 3.0 and walk_value(e, "success_rate_tau100") == 1.0
    assert np.isnan(walk_value({"vo": None}, "vo_failed_frames"))
    assert np.isnan(walk_value({"median_matches": float("inf")}, "median_matches"))


def test_walk_values_order_and_shape():
    t = {"live-fixed-instant": np.arange(8 * 7, dtype=float).reshape(8, 7)}
    walks, tables = walk_values(_records(t, 2), METHODS)
    assert walks[:2] == [f"{SCENES[0]}/seed0", f"{SCENES[1]}/seed0"] and walks[4] == f"{SCENES[0]}/seed1"
    np.testing.assert_array_equal(tables["live-fixed-instant"]["median_matches"], t["live-fixed-instant"])


@pytest.mark.parametrize("kind,expected", [("live-draw", "agrees"), ("random", "disagrees")])
def test_replicated_results_contract(tmp_path, kind, expected):
    from validation.live.experiment import finish_replicated

    sim = simulate_tables(kind, 40, Scales(sd_method=1.0, sd_walk_method=0.3, sd_noise=0.3), seed=7)
    tables = {CONDITIONS["cycle-rate live"]: sim["live"][0], CONDITIONS["emulated"]: sim["emulated"][0],
              CONDITIONS["cycle-rate live re-seeded"]: sim["control"][0]}
    res = finish_replicated(tmp_path, _records(tables, 10), command="test", power_seeds=0)
    on_disk = json.loads((tmp_path / "results.json").read_text())
    # the live-live control, like for like: cycle-rate live against itself re-seeded, a comparison of its own
    ctl = on_disk["comparisons"]["cycle-rate live re-seeded vs cycle-rate live"]
    assert ctl["status"] == "run" and ctl["compared"] == "live-fixed-instant-reseeded"
    assert ctl["metrics"]["median_matches"]["verdict"] == "agrees"  # a perfect emulator: one more live draw
    assert on_disk["comparisons"]["emulated vs cycle-rate live"]["control"] == "live-fixed-instant-reseeded"
    assert on_disk["metrics"]["median_matches"]["tau_live_live"] is not None
    assert on_disk["comparisons"]["native-rate live re-seeded vs native-rate live"]["status"] == "not run"
    assert on_disk["conditions"]["cycle-rate live re-seeded"]["status"] == "run"
    assert "re-seeded" in on_disk["conditions"]["native-rate live re-seeded"]["reason"]
    assert on_disk["n_walks"] == 40 == res["n_walks"]
    assert set(on_disk["metrics"]) == set(JUDGED_METRICS)
    for m, r in on_disk["metrics"].items():
        assert set(r) >= {"omega2", "omega2_ci90", "tau_live_emulated", "tau_live_live", "verdict", "reason", "family",
                          "pairs_verdict", "margin_in_ranking_terms", "emulation_bias"}
    # every ranked metric carries the same simulated values (success: the sign only)
    for m in ("median_matches", "median_uniformity", "rpe_trans_pct"):
        assert on_disk["metrics"][m]["verdict"] == expected, on_disk["metrics"][m]
    assert on_disk["conditions"]["native-rate live"]["status"] == "not run"
    assert on_disk["comparisons"]["cycle-rate vs native-rate live"]["status"] == "not run"
    assert on_disk["power"] == {}  # power_seeds 0: not simulated
    assert "## Verdicts per metric" in (tmp_path / "report.md").read_text()
    # the headline: both live references with equal weight, then the cycle-rate benchmark against native-rate live
    assert list(on_disk)[:4] == ["experiment", "command", "n_walks", "headlines"]  # results.json leads with it
    h = on_disk["headlines"]
    assert list(h["comparisons"]) == ["emulated vs cycle-rate live", "emulated native vs native-rate live",
                                      "emulated vs native-rate live"]
    assert h["distinct_metrics"] == ["median_uniformity", "median_matches", "segment_success_rate_tau100",
                                     "vo_failed_frames", "rpe_trans_rank"]
    cyc = h["comparisons"]["emulated vs cycle-rate live"]
    assert cyc["live_live"] == "cycle-rate live re-seeded vs cycle-rate live"
    assert cyc["metrics"]["median_matches"]["live_live"]["verdict"] == "agrees"
    assert h["comparisons"]["emulated native vs native-rate live"]["status"] == "not run"
    assert h["family"]["size"] == 5  # the native-rate comparisons were not run: 5 metrics x 1 comparison
    for m, r in cyc["metrics"].items():  # every verdict with its interval and its family
        assert r["family"] and len(r["omega2_ci90"]) == 2, m
    report = (tmp_path / "report.md").read_text()
    assert report.index("## Headline: emulated against both live references") < report.index("## Verdicts per metric")
    assert "headline, Holm over 5" in report and "own, not corrected" in report


def test_quick_sized_record_is_undetermined(tmp_path):
    from validation.live.experiment import finish_replicated

    sim = simulate_tables("live-draw", 4, Scales(1.0, 0.1, 0.1), seed=8)
    tables = {CONDITIONS["cycle-rate live"]: sim["live"][0], CONDITIONS["emulated"]: sim["emulated"][0]}
    res = finish_replicated(tmp_path, _records(tables, 1), command="test")
    assert res["n_walks"] == 4
    assert {r["verdict"] for r in res["metrics"].values()} == {"undetermined"}
    assert all("fewer than 10" in r["reason"] for r in res["metrics"].values())
    # an undetermined headline verdict says what would decide it; below 10 walks there is nothing to size it from
    for m in ("median_matches", "rpe_trans_rank"):
        assert "fewer than 10" in res["metrics"][m]["walks_to_decide"]["reason"]


def test_quick_walks_decide_nothing_however_many(tmp_path):
    from validation.live.experiment import finish_replicated, redraw

    sim = simulate_tables("random", 40, Scales(sd_method=1.0, sd_walk_method=0.3, sd_noise=0.3), seed=7)
    tables = {CONDITIONS["cycle-rate live"]: sim["live"][0], CONDITIONS["emulated"]: sim["emulated"][0],
              CONDITIONS["cycle-rate live re-seeded"]: sim["control"][0]}
    for res in (finish_replicated(tmp_path, _records(tables, 10, n_cycles=3), command="test", power_seeds=0),
                redraw(tmp_path)):
        assert res["n_walks"] == 40  # enough walks, and a random emulator: it would be judged disagrees
        for c in res["comparisons"].values():
            for r in (c.get("metrics") or {}).values():
                assert r["verdict"] == "undetermined" and "pipeline check" in r["reason"]
                assert r["pairs_verdict"]["verdict"] == "undetermined"
        assert res["headlines"]["comparisons"]["emulated vs cycle-rate live"]["metrics"]["median_matches"][
            "verdict"] == "undetermined"


@pytest.mark.slow
def test_power_per_metric_from_the_walks(tmp_path):
    from validation.live.experiment import finish_replicated

    sim = simulate_tables("live-draw", 40, Scales(sd_method=1.0, sd_walk_method=0.3, sd_noise=0.3), seed=7)
    tables = {CONDITIONS["cycle-rate live"]: sim["live"][0], CONDITIONS["emulated"]: sim["emulated"][0],
              "live-same-instant-reseeded": sim["control"][0]}
    res = finish_replicated(tmp_path, _records(tables, 10), command="test", power_seeds=10)
    p = res["power"]["median_matches"]
    assert p["status"] == "computed" and p["n_walks"] == 40
    assert p["scales"]["sd_method"] == pytest.approx(1.0, rel=0.35)  # the simulated method SD, recovered
    assert p["walks_needed_for_agrees"] is not None and p["walks_needed_for_agrees"] <= 40
    assert "What this size can decide" in (tmp_path / "report.md").read_text()


def test_headline_is_the_verdict_with_its_interval_and_tau_is_secondary():
    from validation.live.report import headline

    res = {"n_walks": 52, "reference_condition": "cycle-rate live", "metrics": {
        "median_matches": {"verdict": "agrees", "omega2": 0.04, "omega2_ci90": [0.0, 0.15],
                           "tau_live_emulated": 0.81, "tau_live_live": 0.9, "tau_live_live_ci95": [0.62, 1.0],
                           "pairs_verdict": {"verdict": "undetermined"}},
        "rpe_trans_pct": {"verdict": "undetermined", "omega2": 0.7, "omega2_ci90": [0.1, None],
                          "tau_live_emulated": None, "tau_live_live": None}}}
    lines = headline(res).splitlines()
    assert lines[0] == ("verdicts over 52 walks, emulated vs cycle-rate live (agrees: omega2's one-sided 95 % upper "
                        "bound <= 0.2; family per metric in results.json):")
    assert lines[1] == "  median_matches: agrees, omega2 0.04 [0, 0.15]; pairwise check undetermined"
    assert lines[2] == "  rpe_trans_pct: undetermined, omega2 0.7 [0.1, inf]"
    assert lines[3].startswith("secondary, not a verdict:") and "median_matches 0.81 vs 0.90 [0.62, 1.00]" in lines[3]
    assert len(lines) == 4 and "0.9:" not in headline(res)


def test_walks_table_round_trip_and_redraw_from_the_table_alone(tmp_path):
    from validation.live.config import LiveError
    from validation.live.evidence import WALKS_TABLE, parse_walks_table, walk_labels
    from validation.live.experiment import finish_replicated, redraw

    sim = simulate_tables("live-draw", 40, Scales(sd_method=1.0, sd_walk_method=0.3, sd_noise=0.3), seed=7)
    sim["live"][0][3, 2] = np.nan  # a missing value stays missing
    tables = {CONDITIONS["cycle-rate live"]: sim["live"][0], CONDITIONS["emulated"]: sim["emulated"][0],
              "live-same-instant-reseeded": sim["control"][0]}
    res = finish_replicated(tmp_path, _records(tables, 10), command="test", power_seeds=0)
    assert res["walks_table"] == WALKS_TABLE
    text = (tmp_path / WALKS_TABLE).read_text()
    assert text.splitlines()[0] == ("walk,scene,seed,method,condition,median_uniformity,median_matches,"
                                    "success_rate_tau100,segment_success_rate_tau100,vo_failed_frames,rpe_trans_pct")
    assert len(text.splitlines()) == 1 + 3 * 40 * len(METHODS)
    walks, methods, back = parse_walks_table(text)
    assert walks == res["walks"] and methods == list(METHODS)
    for run, t in tables.items():  # exact: every value as written, NaN where missing
        np.testing.assert_array_equal(back[run]["median_matches"], t)
    assert walk_labels(walks)[1][:5] == [0, 0, 0, 0, 1]  # 4 scenes per seed: the seed is the cluster
    # only the table (and results.json for the configuration) left: --redraw gives the same verdicts, to the digit
    before = json.loads((tmp_path / "results.json").read_text())
    again = redraw(tmp_path)
    for m in METRICS:
        for k in ("verdict", "omega2", "omega2_ci90", "pairs_verdict", "emulation_bias", "margin_in_ranking_terms"):
            assert again["metrics"][m][k] == before["metrics"][m][k], (m, k)
    for label, c in before["headlines"]["comparisons"].items():  # the headline too, verdicts and family
        for m, r in (c.get("metrics") or {}).items():
            assert {k: again["headlines"]["comparisons"][label]["metrics"][m][k] for k in r} == r, (label, m)
    assert again["headlines"]["family"] == before["headlines"]["family"]
    # a study from before the re-seeded cycle-rate and native-rate live runs: those are 'not run', and no
    # control of another condition stands in for them
    assert again["comparisons"]["cycle-rate live re-seeded vs cycle-rate live"]["status"] == "not run"
    assert again["conditions"]["cycle-rate live re-seeded"]["status"] == "not run"
    assert again["metrics"]["median_matches"]["tau_live_live"] is None
    assert again["comparisons"]["emulated vs cycle-rate live"]["control"] is None
    # a resumed study completes its table (every earlier row kept); a table whose rows differ is never overwritten
    few = "\n".join(text.splitlines()[:50]) + "\n"
    (tmp_path / WALKS_TABLE).write_text(few)
    finish_replicated(tmp_path, _records(tables, 10), command="test", power_seeds=0)
    assert (tmp_path / WALKS_TABLE).read_text() == text
    row = text.splitlines()[1]
    (tmp_path / WALKS_TABLE).write_text(text.replace(row, row[:-3] + "999", 1))
    with pytest.raises(LiveError, match="walks.csv"):
        finish_replicated(tmp_path, _records(tables, 10), command="test", power_seeds=0)
    (tmp_path / WALKS_TABLE).write_text(text.replace("walk,scene", "walk;scene"))
    with pytest.raises(LiveError, match="line 1"):
        parse_walks_table((tmp_path / WALKS_TABLE).read_text())
    # a repeated row (even with another value) or a metric column left out is refused, not read
    lines = text.splitlines()
    with pytest.raises(LiveError, match=r"line 3 repeats walk .*, method .*, condition "):
        parse_walks_table("\n".join(lines[:2] + [lines[1].rsplit(",", 1)[0] + ",0.999"] + lines[2:]) + "\n")
    cut = "\n".join(",".join(line.split(",")[:-1]) for line in lines) + "\n"  # rpe_trans_pct left out
    with pytest.raises(LiveError, match="each metric name once"):
        parse_walks_table(cut)
    twice = "\n".join(line + "," + line.split(",")[-1] for line in lines) + "\n"
    with pytest.raises(LiveError, match="each metric name once"):
        parse_walks_table(twice)


def test_the_seeds_are_the_bootstrap_clusters():
    from validation.live.evidence import judge_metrics

    sim = simulate_tables("live-draw", 40, Scales(sd_method=1.0, sd_walk_method=0.3, sd_noise=0.3), seed=7)
    tables = {CONDITIONS["cycle-rate live"]: {m: sim["live"][0] for m in METRICS},
              CONDITIONS["emulated"]: {m: sim["emulated"][0] for m in METRICS}}
    walks = [f"{s}/seed{k}" for k in range(10) for s in SCENES]
    a = judge_metrics(tables, METHODS, power=False, walks=walks, n_resamples=200)["metrics"]["median_matches"]
    b = judge_metrics(tables, METHODS, power=False, n_resamples=200)["metrics"]["median_matches"]
    assert a["omega2"] == b["omega2"] and a["omega2_ci90"] != b["omega2_ci90"]  # same estimate, other resamples
    # the conditions' intervals too: two seeds of 4 walks, values constant within a seed -> every resample
    # mean is 0, 0.5 or 1 (whole seeds), so are the interval's ends
    from validation.live.evidence import condition_table

    t = np.repeat([[0.0], [1.0]], 4, axis=0)
    ci = condition_table(t, ["a"], n_resamples=200, clusters=[0] * 4 + [1] * 4)["a"]["ci95"]
    assert set(ci) <= {0.0, 0.5, 1.0} and ci[0] < ci[1]


def test_replicated_study_pools_native_emulation_over_every_seed_and_the_table_redraw_keeps_it(tmp_path):
    from validation.live.experiment import finish_replicated, redraw

    sim = simulate_tables("live-draw", 40, Scales(sd_method=1.0, sd_walk_method=0.3, sd_noise=0.3), seed=7)
    tables = {CONDITIONS["cycle-rate live"]: sim["live"][0], CONDITIONS["emulated"]: sim["emulated"][0]}
    recs = _records(tables, 10)
    for k, rec in enumerate(recs):  # every walk: 4 frames per method, one served by a neighbour (offset -1)
        err = 1.0 + 0.1 * k
        ne = {m: {"rmse_percent": [err, err, err, 2 * err], "rmse_percent_unwarped": [err, err, err, 4 * err],
                  "rmse_percent_all": [err] * 4, "rmse_percent_own_bracket": [err] * 4,
                  "source_offset": [0, 0, 0, -1], "warp_deg": [0.0, 0.0, 0.0, 0.5]} for m in METHODS}
        rec["per_scene"] = {s: {"native_emulation": ne} for s in SCENES}
    res = finish_replicated(tmp_path, recs, command="test", power_seeds=0, calibration_studies=0)
    ne = res["native_emulation"]
    assert len(ne["per_walk"]) == 40 and "forest_winter/seed9" in ne["per_walk"]
    assert ne["per_walk"]["sun_glare/seed3"]["kim"]["neighbour_fraction"] == 0.25
    # each walk's median over its frames and methods is its own bracket's error, 1 + 0.1 k: the mean over walks
    assert ne["median_image_rmse_percent"]["estimate"] == pytest.approx(np.mean([1.0 + 0.1 * k for k in range(10)]))
    assert "native" in (tmp_path / "report.md").read_text().lower()
    assert not (tmp_path / "replicates").exists() and not (tmp_path / "raw.json").exists()
    again = redraw(tmp_path)  # from walks.csv alone: the native figures are kept as they were
    assert again["native_emulation"] == json.loads(json.dumps(ne))

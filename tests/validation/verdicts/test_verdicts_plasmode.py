"""validation.verdicts.plasmode: the verdict rule calibrated on a study's own walks tables."""

import json

import numpy as np
import pytest

from validation.verdicts.agreement import judge, omega2_over_plan, omega2_untruncated
from validation.verdicts.plasmode import (
    calibrate,
    calibration_markdown,
    control_pairs,
    draw_study,
    metric_calibration,
    seed_clusters,
)
from validation.verdicts.ranking import cluster_plan, over_plan

METHODS = ["fixed", "classical-30", "classical-50", "classical-70", "shim", "zhang", "kim"]
SCENES = ["forest_winter", "sun_glare", "forest_edge", "forest_summer"]


def _walks(n_seeds):
    """Each walk's seed: ``n_seeds`` seeds of one walk per scene."""
    return [k for k in range(n_seeds) for _ in SCENES]


def _study(n_seeds, *, spread=10.0, noise=1.0, seed=0):
    """(live, re-seeded) walks x methods tables: evenly spaced method effects ``spread`` apart, a walk level,
    and independent run noise of SD ``noise`` in each."""
    rng = np.random.default_rng(seed)
    w = n_seeds * len(SCENES)
    base = np.linspace(0.0, spread * (len(METHODS) - 1), len(METHODS)) + rng.normal(0.0, 5.0, (w, 1))
    return base + rng.normal(0.0, noise, (w, len(METHODS))), base + rng.normal(0.0, noise, (w, len(METHODS)))


@pytest.mark.parametrize("labels", [np.repeat(np.arange(10), 4), None, np.r_[np.repeat(np.arange(10), 4)[:-1], 99]])
def test_omega2_over_a_plan_is_omega2_of_the_resampled_tables(labels):
    live, other = _study(10, spread=1.0, noise=1.0, seed=3)
    live, other = 30 * live + 500, 30 * other + 500  # a level far above the spread: no cancellation
    plan = cluster_plan(40, 300, 1, labels)  # equal clusters: one index array; unequal: a list
    want = over_plan(omega2_untruncated, plan, live, other)
    np.testing.assert_allclose(omega2_over_plan(plan, live, other), want, rtol=1e-10)


def test_control_pairs_and_seed_clusters():
    runs = {"live-native": 0, "live-native-reseeded": 0, "live-same-instant": 0, "live-same-instant-reseeded": 0,
            "live-fixed-instant-reseeded": 0, "emulated-plain": 0}  # a re-seeded run without its reference: no pair
    assert control_pairs(runs) == [("live-native", "live-native-reseeded"),
                                   ("live-same-instant", "live-same-instant-reseeded")]
    cl = seed_clusters(_walks(3))
    assert [c.tolist() for c in cl] == [[0, 1, 2, 3], [4, 5, 6, 7], [8, 9, 10, 11]]
    rows, labels = draw_study(cl, 5, np.random.default_rng(0))
    assert rows.size == 20 and labels.tolist() == np.repeat(np.arange(5), 4).tolist()
    assert all(sorted(rows[4 * k:4 * k + 4] % 4) == [0, 1, 2, 3] for k in range(5))  # every draw keeps each scene


def test_a_perfect_copy_agrees_exactly_when_the_rule_can_decide():
    live, _ = _study(10, seed=1)  # 40 walks, methods 10 noise SDs apart: live separates them in every draw
    cal = metric_calibration(live, live.copy(), _walks(10), METHODS, n_studies=20, seed=2, omega2s=(5.0,))
    # emulated == re-seeded live exactly: omega2 is 0 with both bounds 0 in every draw, so the rule says agrees
    assert cal["rates"]["perfect"] == {"agrees": 1.0, "disagrees": 0.0, "undetermined": 0.0,
                                       "complete_walks_median": 40.0}
    need = cal["walks_needed_for_agrees"]
    assert need["walks"] == 40 and need["seeds"] == 10 and need["extrapolated"] is False  # the rule's 10 seeds
    assert [s["agrees"] for s in need["sizes_tried"] if s["seeds"] < 10] == [0.0] * sum(
        s["seeds"] < 10 for s in need["sizes_tried"])
    # below the rule's 10 seeds nothing is decided, however perfect: 2 seeds (8 walks) and 5 seeds (20 walks)
    for n in (2, 5):
        few, _ = _study(n, seed=1)
        assert metric_calibration(few, few.copy(), _walks(n), METHODS, n_studies=10, seed=2)["rates"]["perfect"][
            "undetermined"] == 1.0


def test_big_interactions_and_a_random_emulator_are_found():
    live, again = _study(10, seed=4)
    cal = metric_calibration(live, again, _walks(10), METHODS, n_studies=40, seed=5, omega2s=(0.0, 3.0))
    assert cal["noisy_method"] == "kim" and cal["residual_sd"]["kim"] == pytest.approx(np.sqrt(2.0), rel=0.35)
    assert cal["rates"]["injected omega2 3"]["disagrees"] >= 0.95
    assert cal["rates"]["random"]["disagrees"] >= 0.9
    assert cal["rates"]["perfect"]["agrees"] >= 0.9  # run noise 0.1 method SD: the perfect emulator is seen
    assert cal["rates"]["injected omega2 0"]["disagrees"] <= 0.05  # noise alone, even t3 and a noisy kim
    sizes = cal["walks_needed_for_agrees"]["sizes_tried"]
    assert [s["extrapolated"] for s in sizes] == [s["seeds"] > 10 for s in sizes]


def test_tied_live_decides_nothing_and_omega2_is_not_injected():
    rng = np.random.default_rng(0)
    live = np.repeat(rng.normal(0, 1, (12, 1)), len(METHODS), axis=1)  # every method tied on every walk
    cal = metric_calibration(live, live + rng.normal(0, 1, live.shape), _walks(3), METHODS, n_studies=10, seed=0)
    assert cal["rates"]["perfect"]["agrees"] == 0.0 and cal["rates"]["random"]["disagrees"] == 0.0
    assert cal["rates"]["injected omega2 0.3"]["status"] == "not computed"
    assert cal["walks_needed_for_agrees"]["walks"] is None


def test_bad_input_and_too_few_seeds():
    live, again = _study(3)
    with pytest.raises(ValueError, match="noisy method 'nope'"):
        metric_calibration(live, again, _walks(3), METHODS, n_studies=2, noisy_method="nope")
    with pytest.raises(ValueError, match="walks x methods"):
        metric_calibration(live[:, :3], again, _walks(3), METHODS, n_studies=2)
    one = metric_calibration(live[:4], again[:4], _walks(1), METHODS, n_studies=2)
    assert one["status"] == "not computed" and "2 seeds" in one["reason"]
    assert calibrate({"live-x": {}}, _walks(1), METHODS)["status"] == "not computed"


def test_same_inputs_same_bytes_and_the_seed_matters():
    live, again = _study(4, noise=6.0, seed=6)
    tables = {"live-same-instant": {"median_matches": live}, "live-same-instant-reseeded": {"median_matches": again}}
    a = json.dumps(calibrate(tables, _walks(4), METHODS, n_studies=15, seed=1))
    assert a == json.dumps(calibrate(tables, _walks(4), METHODS, n_studies=15, seed=1))
    assert a != json.dumps(calibrate(tables, _walks(4), METHODS, n_studies=15, seed=2))
    md = calibration_markdown(json.loads(a))
    assert "| median_matches | 16 of 16 |" in md and "live-same-instant-reseeded" in md


def test_the_verdict_is_the_rules_own():
    """Each plasmode verdict is judge's on the drawn study: the same draws through judge give the same rate."""
    from validation.verdicts.plasmode import _rates

    live, again = _study(5, noise=8.0, seed=8)
    cl = seed_clusters(_walks(5))
    got = _rates(live, again, cl, 5, "perfect", 12, [3, 1])
    rng = np.random.default_rng([3, 1])
    n = 0
    for _ in range(12):
        rows, labels = draw_study(cl, 5, rng)
        n += judge(live[rows], again[rows], detail=False, clusters=labels, seed=rng)["verdict"] == "agrees"
    assert got["agrees"] == n / 12


def _records(tables: dict, n_seeds: int) -> list[dict]:
    """Experiment records (raw.json content) holding walks x methods ``tables`` (every metric the same values)."""
    from validation.live.config import LiveConfig

    cfg = LiveConfig(scenes=tuple(SCENES), n_cycles=3, methods=tuple(METHODS)).to_dict()
    entry = lambda v: {"median_uniformity": v, "median_matches": v, "sequence_success": {"100": v > 0},  # noqa: E731
                       "segment_success": {"100": {"rate": v}}, "vo": {"n_failed_frames": v, "rpe_trans_pct": v}}
    return [{"config": {**cfg, "seed": k}, "timings": {"total_s": 1.0}, "summaries": {
        run: {"per_scene": {s: {m: entry(float(t[k * 4 + i, j])) for j, m in enumerate(METHODS)}
                            for i, s in enumerate(SCENES)}} for run, t in tables.items()}} for k in range(n_seeds)]


def test_the_study_folder_keeps_its_calibration_and_redraw_recomputes_it(tmp_path):
    from validation.live.experiment import finish_replicated, redraw

    live, again = _study(3, noise=2.0, seed=9)
    tables = {"live-fixed-instant": live, "emulated-plain": again + 1.0, "live-same-instant": live,
              "live-same-instant-reseeded": again}
    res = finish_replicated(tmp_path, _records(tables, 3), command="test", power_seeds=0, calibration_studies=6)
    cal = json.loads((tmp_path / "calibration.json").read_text())
    assert cal == json.loads((tmp_path / "results.json").read_text())["calibration"] and cal["n_studies"] == 6
    assert list(cal["pairs"]) == ["live-same-instant vs live-same-instant-reseeded"]
    assert set(cal["pairs"]["live-same-instant vs live-same-instant-reseeded"]["metrics"]) == {
        "median_uniformity", "median_matches", "success_rate_tau100", "segment_success_rate_tau100",
        "vo_failed_frames", "rpe_trans_pct", "rpe_trans_rank"}
    assert res["calibration_file"] == "calibration.json"
    assert "plasmode calibration" in (tmp_path / "report.md").read_text()
    first = (tmp_path / "calibration.json").read_bytes()
    redraw(tmp_path)  # from walks.csv and results.json alone, as many studies as the folder used: the same bytes
    assert (tmp_path / "calibration.json").read_bytes() == first
    assert json.loads((tmp_path / "results.json").read_text())["calibration"] == cal


def test_command_line_reads_the_folder_and_never_overwrites(tmp_path, capsys):
    from validation.live.experiment import finish_replicated
    from emulator.commands.cli import main as exposim

    def main(argv):
        return exposim(["validate", "study-calibration", *argv])

    assert main([str(tmp_path / "nowhere")]) == 1
    assert "walks.csv" in capsys.readouterr().err  # one line naming the file
    live, again = _study(3, noise=2.0, seed=9)
    tables = {"live-fixed-instant": live, "emulated-plain": again, "live-same-instant": live,
              "live-same-instant-reseeded": again}
    finish_replicated(tmp_path, _records(tables, 3), command="test", power_seeds=0, calibration_studies=0)
    assert json.loads((tmp_path / "calibration.json").read_text())["status"] == "not computed"
    out = tmp_path / "cal.json"
    assert main([str(tmp_path), "--studies", "3", "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "| median_matches | 12 of 12 |" in text and "12 walks, 3 plasmode studies" in text
    assert json.loads(out.read_text())["n_studies"] == 3
    assert main([str(tmp_path), "--studies", "3", "--json", str(out)]) == 1
    assert "never overwritten" in capsys.readouterr().err


def test_validate_live_refuses_a_negative_count(tmp_path, capsys):
    from validation.live.cli import main

    assert main(["-o", str(tmp_path), "--redraw", "--calibration-studies", "-1"]) == 1
    assert capsys.readouterr().err.strip() == "live: --calibration-studies must be >= 0, got -1"


def test_the_rule_counts_seeds_where_the_walks_are_clustered():
    live, _ = _study(3, seed=7)  # 12 walks in 3 seeds: enough walks, too few clusters
    alone = judge(live, live.copy(), methods=METHODS, detail=False)
    clustered = judge(live, live.copy(), methods=METHODS, detail=False, clusters=_walks(3))
    assert alone["verdict"] == "agrees" and alone["n_clusters"] is None  # 12 independent walks decide
    assert clustered["verdict"] == "undetermined" and clustered["n_clusters"] == 3
    assert clustered["reason"].startswith("12 complete walks in 3 seeds, fewer than 10 seeds")
    big, _ = _study(10, seed=7)
    assert judge(big, big.copy(), methods=METHODS, detail=False, clusters=_walks(10))["verdict"] == "agrees"


def test_walks_to_decide_never_below_the_rules_seeds():
    from validation.live.evidence import _seed_floor

    r = {"n_walks": 12, "n_clusters": 3, "walks_to_decide": {"walks": 16, "towards": "agrees"}}
    _seed_floor(r, 10)
    assert r["walks_to_decide"]["walks"] == 40 and "10 seeds of 4 walks" in r["walks_to_decide"]["floor"]
    r = {"n_walks": 12, "n_clusters": 3, "walks_to_decide": {"walks": 60, "towards": "agrees"}}
    _seed_floor(r, 10)
    assert r["walks_to_decide"] == {"walks": 60, "towards": "agrees"}  # above the floor: unchanged
    r = {"n_walks": 12, "n_clusters": None, "walks_to_decide": {"walks": 16}}
    _seed_floor(r, 10)
    assert r["walks_to_decide"] == {"walks": 16}  # walks not clustered: the rule counts walks

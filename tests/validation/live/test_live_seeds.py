"""validation.live.seeds: a method that draws random numbers runs k seeds per walk and condition, judged on their mean."""

from __future__ import annotations

import json
import math
from types import SimpleNamespace

import numpy as np
import pytest

from emulator.autoexposure import Kim2018, Shim2014
from emulator.autoexposure.builtin import METHOD_NAMES, seed_option
from validation.live.config import LiveConfig, LiveError
from validation.live.evidence import WALK_METRICS, parse_walks_table, store_walks_table
from validation.live.preregistration import check_preregistration, preregistration, write_preregistration
from validation.live.seeds import (
    SEEDS_TABLE,
    loop_items,
    loop_names,
    recommended_seeds,
    residual_shares,
    seed_noise,
    split_seeds,
    stochastic_methods,
    store_seeds_table,
)


def test_a_method_that_draws_random_numbers_declares_the_option_that_seeds_them():
    assert Kim2018.seed_option == "seed" and Shim2014.seed_option is None
    assert {m: seed_option(m) for m in METHOD_NAMES} == {m: ("seed" if m == "kim" else None) for m in METHOD_NAMES}
    assert seed_option("not-a-method") is None
    assert stochastic_methods(["fixed", "kim", "zhang"]) == ["kim"]


def test_the_declaration_not_the_name_makes_a_method_stochastic(monkeypatch):
    monkeypatch.setattr(Shim2014, "seed_option", "seed")  # a class that declares it is run with seeds
    assert stochastic_methods(["shim", "kim", "fixed"]) == ["shim", "kim"]
    monkeypatch.setattr(Kim2018, "seed_option", None)
    assert stochastic_methods(["shim", "kim"]) == ["shim"]


def test_k_seeds_are_the_method_and_fresh_instances_with_seeds_1_to_k_minus_1():
    assert loop_names(["fixed", "kim"], 1) == ["fixed", "kim"]
    assert loop_names(["fixed", "kim"], 3) == ["fixed", "kim", "kim@seed1", "kim@seed2"]
    a, b = loop_items(["fixed", "kim"], 3), loop_items(["fixed", "kim"], 3)
    assert a[:2] == ["fixed", "kim"]  # seed 0: the method by name, as the study always ran it
    assert [(m.name, m.seed, m.range_ms) for m in a[2:]] == [("kim@seed1", 1, None), ("kim@seed2", 2, None)]
    assert all(x is not y for x, y in zip(a[2:], b[2:]))  # each loop gets instances of its own


def _record_loops(monkeypatch, cfg):
    """What each loop of a walk is given, by condition (the loops themselves replaced by empty ones)."""
    import validation.live.loops as loops
    import validation.live.native as native
    import validation.live.walks as walks

    seen = {}

    def named(items):
        return [(getattr(i, "name", i), getattr(i, "seed", 0 if i == "kim" else None)) for i in items]

    monkeypatch.setattr(loops, "iter_emulated", lambda seq, items, noise, **k: seen.setdefault(
        f"emulated-{noise}", named(items)) and [])
    monkeypatch.setattr(loops, "iter_live", lambda seq, rad, cam, items, timing, seed, **k: seen.setdefault(
        f"live-{timing}-{seed}", named(items)) and [])
    monkeypatch.setattr(native, "native_provider", lambda *a, **k: None)
    monkeypatch.setattr(native, "cycle_picks", lambda provider: {})

    def native_loop(seq, rad, cam, items, seed, **k):
        seen[f"live-native-{seed}"] = named(items)
        return []

    def emulated_native(cfg, seq, response, every, cycles, out, timings, scene, reseeded, items):
        seen["emulated-native"] = named(items())

    monkeypatch.setattr(walks, "_emulated_native", emulated_native)
    seq = SimpleNamespace(cycles=[])
    walks._loops(cfg, seq, lambda t, c: None, None, None, None, native_loop, "t", False, {}, "forest_winter")
    return seen


def test_every_condition_runs_the_same_k_seeds(monkeypatch):
    cfg = LiveConfig(scenes=("forest_winter",), methods=("fixed", "kim"), stochastic_seeds=3)
    seen = _record_loops(monkeypatch, cfg)
    # emulated plain and consistent, live same-instant and cycle-rate with their re-seeded twins, native live and
    # its twin, emulated native
    assert len(seen) == 9
    want = [("fixed", None), ("kim", 0), ("kim@seed1", 1), ("kim@seed2", 2)]
    assert all(v == want for v in seen.values()), seen


def test_the_walk_mean_is_the_mean_of_the_seed_rows_stored_beside_it(tmp_path):
    rng = np.random.default_rng(3)
    names = ["fixed", "kim", "kim@seed1", "kim@seed2"]
    walks = ["forest_winter/seed0", "sun_glare/seed0"]
    tables = {run: {m: rng.normal(10, 3, (2, 4)) for m in WALK_METRICS} for run in ("live-fixed-instant",
                                                                                   "emulated-plain")}
    tables["emulated-plain"]["rpe_trans_pct"][1, 2] = math.nan  # one seed lost its VO on one walk
    means, seed_names, seeds = split_seeds(tables, names, ["fixed", "kim"], 3)
    assert seed_names == ["kim@seed0", "kim@seed1", "kim@seed2"]
    store_walks_table(tmp_path, walks, means, ["fixed", "kim"])
    store_seeds_table(tmp_path, walks, seed_names, seeds)
    w1, m1, t1 = parse_walks_table((tmp_path / "walks.csv").read_text())
    w2, m2, t2 = parse_walks_table((tmp_path / SEEDS_TABLE).read_text())
    assert (w1, m1, w2, m2) == (walks, ["fixed", "kim"], walks, seed_names)
    for run in tables:
        for metric in WALK_METRICS:
            np.testing.assert_array_equal(t1[run][metric][:, 0], tables[run][metric][:, 0])
            np.testing.assert_array_equal(t1[run][metric][:, 1], t2[run][metric].mean(axis=1))
            np.testing.assert_array_equal(t2[run][metric], tables[run][metric][:, 1:])
    assert math.isnan(t1["emulated-plain"]["rpe_trans_pct"][1, 1])  # missing for one seed: missing for the walk
    assert t1["emulated-plain"]["rpe_trans_pct"][0, 1] == pytest.approx(tables["emulated-plain"]["rpe_trans_pct"][0, 1:].mean())


def test_one_seed_leaves_the_config_and_the_plan_as_they_were(tmp_path):
    assert "stochastic_seeds" not in LiveConfig().to_dict()
    assert LiveConfig(stochastic_seeds=4).to_dict()["stochastic_seeds"] == 4
    assert "draws_per_stochastic_method" not in preregistration(LiveConfig(), 12)
    assert preregistration(LiveConfig(stochastic_seeds=4), 12)["draws_per_stochastic_method"] == 4
    for bad in (0, 65, 2.0, True):
        with pytest.raises(LiveError, match="stochastic_seeds"):
            LiveConfig(stochastic_seeds=bad)
    # a plan registered with the key at 1 (before it was left out) is the same plan
    old = {**preregistration(LiveConfig(), 12), "draws_per_stochastic_method": 1}
    write_preregistration(tmp_path, old)
    check_preregistration(tmp_path, preregistration(LiveConfig(), 12))
    with pytest.raises(LiveError, match="draws_per_stochastic_method"):
        check_preregistration(tmp_path, preregistration(LiveConfig(stochastic_seeds=2), 12))
    assert json.loads((tmp_path / "preregistration.json").read_text())["draws_per_stochastic_method"] == 1


def test_the_option_reaches_the_config_and_the_recorded_command():
    from validation.live.cli import build_parser, command_line, config_from_args

    args = build_parser().parse_args(["-o", "x", "--stochastic-seeds", "4"])
    assert config_from_args(args).stochastic_seeds == 4
    assert "--stochastic-seeds 4" in command_line(args, "exposim validate live")
    args = build_parser().parse_args(["-o", "x"])
    assert config_from_args(args).stochastic_seeds == 1 and "stochastic" not in command_line(args, "exposim")


def test_each_methods_share_of_the_residual_on_a_table_where_it_is_known():
    v = np.array([1.0, -1.0, 1.0, -1.0])
    r = np.stack([2 * v, -v, -v], axis=1)  # double-centred: squares 16, 4, 4 -> shares 2/3, 1/6, 1/6
    walk = np.array([[0.0], [5.0], [-2.0], [1.0]])
    live = np.arange(12, dtype=float).reshape(4, 3) ** 1.5
    emulated = live + r + walk + np.array([3.0, -1.0, 0.5])  # walk and method shifts leave the residual alone
    tables = {"live": {"m": live}, "emu": {"m": emulated}}
    got = residual_shares(tables, ["fixed", "shim", "kim"], {"c": ("live", "emu"), "absent": ("live", "nope")})
    e = got["c"]["m"]
    assert set(got) == {"c"} and e["n_walks"] == 4
    assert e["share"] == pytest.approx({"fixed": 2 / 3, "shim": 1 / 6, "kim": 1 / 6})
    assert e["residual_sd"] == pytest.approx(math.sqrt(24 / 12))
    assert e["residual_sd_others"] == pytest.approx(math.sqrt(20 / 8))  # fixed and shim: kim declares its seed
    tables["emu"]["m"][2, 0] = math.nan  # an incomplete walk leaves: the shares of the other three
    assert residual_shares(tables, ["fixed", "shim", "kim"], {"c": ("live", "emu")})["c"]["m"]["n_walks"] == 3


def test_seed_noise_and_the_seeds_it_asks_for():
    t = np.array([[1.0, 3.0], [10.0, 10.0], [5.0, math.nan]])  # variances (ddof 1): 2, 0; the third walk incomplete
    noise = seed_noise({"run": {"m": t}}, ["kim@seed0", "kim@seed1"], ["fixed", "kim"], 2)
    e = noise["kim"]["run"]["m"]
    assert e["n_walks"] == 2 and e["seed_sd"] == pytest.approx(1.0) and e["seed_sd_of_mean"] == pytest.approx(
        1 / math.sqrt(2))
    assert recommended_seeds(3.0, 1.0) == 10  # 3 / sqrt(9) is not below 1; 3 / sqrt(10) is
    assert recommended_seeds(1.0, 2.0) == 1
    assert recommended_seeds(2.0, 1.0) == 5
    assert recommended_seeds(None, 1.0) is None and recommended_seeds(1.0, 0.0) is None
    assert recommended_seeds(100.0, 1.0, k_max=8) == 9


@pytest.mark.filterwarnings("ignore:.*no imu")
def test_every_loop_runs_its_methods_in_worker_processes(tmp_path, monkeypatch):
    import synth
    from emulator.io.borealhdr import load_sequence, sequence_response
    from emulator.playback import RunConfig, workers
    from synth.procedural import hdr_chart
    from synth.sequence import BASELINE_M, load_camera
    from validation.live.loops import DatasetRadiance, iter_emulated, iter_live
    from validation.live.native import emulated_native_loop, native_rate_loop

    chart = hdr_chart(48, 32, seed=3, dynamic_range_db=60.0)
    right = np.eye(4)
    right[0, 3] = BASELINE_M
    cam = synth.Camera.preset("borealhdr", width=48, height=32)
    path = synth.capture_sequence(lambda t, c: (chart, np.eye(4) if c == "left" else right), tmp_path / "s", cam,
                                  n_cycles=3, seed=5, noise=True, save_radiance=True)
    seq, camera, rad = load_sequence(path), load_camera(path), DatasetRadiance(path)
    resp = sequence_response(seq)
    started, real = [], workers.start_methods

    def start(spec, config, response):
        out = real(spec, config, response)
        started.append((config.workers, sorted(out), all(isinstance(m, workers.MethodWorker) for m in out.values())))
        return out

    monkeypatch.setattr(workers, "start_methods", start)
    items = lambda: loop_items(["fixed", "kim"], 2)  # noqa: E731
    names = ["fixed", "kim", "kim@seed1"]
    runs = [list(iter_live(seq, rad, camera, items(), timing="fixed-instant", response=resp)),
            list(iter_emulated(seq, items(), response=resp)),
            list(native_rate_loop(seq, rad, camera, items(), response=resp)),
            emulated_native_loop(seq, items(), resp, RunConfig(rate="native", latency_frames=1))[1]]
    assert started == [("process", sorted(names), True)] * 4
    assert all(sorted(run[-1].steps) == sorted(names) for run in runs)


def test_the_share_with_the_first_j_seeds_ends_at_the_studys_own_table():
    from validation.live.seeds import shares_by_seeds

    rng = np.random.default_rng(5)
    methods, runs = ["fixed", "shim", "kim"], ("live-fixed-instant", "emulated-plain")
    seeds = {r: {"median_matches": rng.normal(0, 5, (6, 3))} for r in runs}  # kim@seed0..2
    tables = {r: {"median_matches": np.column_stack([rng.normal(0, 1, (6, 2)), seeds[r]["median_matches"].mean(1)])}
              for r in runs}
    got = shares_by_seeds(tables, methods, ["kim@seed0", "kim@seed1", "kim@seed2"], seeds, 3)
    by_j = got["kim"]["emulated vs cycle-rate live"]["median_matches"]
    assert len(by_j) == 3
    own = residual_shares(tables, methods, {"c": runs})["c"]["median_matches"]["share"]["kim"]
    assert by_j[2] == pytest.approx(own)
    first = {r: {"median_matches": np.column_stack([tables[r]["median_matches"][:, :2], seeds[r]["median_matches"][:, 0]])}
             for r in runs}
    assert by_j[0] == pytest.approx(residual_shares(first, methods, {"c": runs})["c"]["median_matches"]["share"]["kim"])
    assert by_j[0] > by_j[2]  # independent seeds: their mean carries less of the residual


@pytest.mark.render
@pytest.mark.slow
def test_a_tiny_study_with_two_kim_seeds_judges_their_mean(tmp_path, monkeypatch):
    from validation.live.experiment import run_live_experiment

    monkeypatch.setenv("EXPOSIM_DENOISE", "off")
    cfg = LiveConfig(scenes=("forest_winter",), n_cycles=3, width=64, height=40, spp=2, methods=("fixed", "kim"),
                     noise_repeats=4, render_per="shot", denoise="off", stochastic_seeds=2, emitter_weights=(),
                     adaptive=None)
    res = run_live_experiment(tmp_path / "out", cfg, progress=False, cache_dir=tmp_path / "cache")
    out = tmp_path / "out"
    assert res["config"]["stochastic_seeds"] == 2 and res["method_processes"]["workers"] == "process"
    _, m1, t1 = parse_walks_table((out / "walks.csv").read_text())
    _, m2, t2 = parse_walks_table((out / SEEDS_TABLE).read_text())
    assert (m1, m2) == (["fixed", "kim"], ["kim@seed0", "kim@seed1"]) and len(t1) == 9
    for run in t1:
        for metric in WALK_METRICS:
            np.testing.assert_array_equal(t1[run][metric][:, 1], t2[run][metric].mean(axis=1))
    assert (out / "runs" / "forest_winter" / "live-native" / "kim@seed1" / "exposures.csv").is_file()
    shares = json.loads((out / "residual_shares.json").read_text())
    assert shares["seeds_per_walk"] == 2 and shares["stochastic_methods"] == ["kim"]

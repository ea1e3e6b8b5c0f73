"""The synthetic AE study (issue 7): the smallest end-to-end run, and findings derived from numbers."""

from __future__ import annotations

import copy
import json
import math
import time

import numpy as np
import pytest
from tests.conftest import SynthesizeCalled

from emulator.errors import OutputExistsError
from validation.ae_study import (
    CONFIGS,
    METHODS,
    StudyConfig,
    StudyError,
    evaluate_findings,
    findings_paragraph,
    main,
    run_study,
    segment_success,
)


def _finite(v) -> bool:
    return v is not None and math.isfinite(float(v))


@pytest.fixture(scope="module")
def tiny_study(tmp_path_factory):
    """1 scene, 3 cycles, 64x40, 2 spp, through a private render cache (nothing cached)."""
    root = tmp_path_factory.mktemp("ae_study")
    t0 = time.perf_counter()
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("EXPOSIM_DENOISE", "off")  # not a rendering test: raw renders keep it fast
        results = run_study(root / "out", CONFIGS["tiny"], progress=False, command="pytest",
                            cache_dir=root / "cache")
    return root / "out", results, time.perf_counter() - t0


@pytest.mark.render
@pytest.mark.slow
def test_tiny_study_writes_results(tiny_study):
    out, results, _ = tiny_study
    on_disk = json.loads((out / "results.json").read_text())
    assert on_disk["config"]["n_cycles"] == 3 and on_disk["config"]["scenes"] == ["forest_winter"]
    assert on_disk["config"]["renders"] == 3 * 6 * 2
    for key in ("scene_seed", "camera_seed", "render_seed", "vo_seed", "features_seed", "width", "height", "spp"):
        assert key in on_disk["config"]
    for f in ("report.md", "ae_study_summary.png", "features/results.json", "features/fig4_features.png",
              "vo/forest_winter/results.json", "vo/forest_winter/fig6_rpe.png", "runs/forest_winter/exposure.png"):
        assert (out / f).is_file(), f
    rows = on_disk["summary"]["per_scene"]["forest_winter"]
    assert list(rows) == list(METHODS)
    frun = json.loads((out / "features" / "results.json").read_text())["runs"][0]["methods"]
    for name, e in rows.items():
        assert _finite(e["median_exposure_ms"]) and e["median_exposure_ms"] > 0
        assert 0.0 <= e["median_uniformity"] <= 1.0
        # the summary's match figures are the feature benchmark's pair counts (3 images: 2 pairs), and a
        # pair never has more matches than the query image has keypoints (one match per query keypoint)
        f = frun[name]
        assert len(f["matches"]) == 2 and len(f["n_keypoints"]) == 3
        assert e["median_matches"] == float(np.median(f["matches"]))
        assert e["min_matches"] == min(f["matches"])
        assert all(m <= max(a, b) for m, a, b in zip(f["matches"], f["n_keypoints"], f["n_keypoints"][1:]))
        assert e["sequence_success"] == {t: min(f["matches"]) >= int(t) for t in ("5", "100")}
        assert e["segment_success"]["5"]["segments"] == 1  # 2 pairs, shorter than one segment
        vo = e["vo"]
        assert vo["status"] in ("success", "failed") and vo["n_frames"] == 3
        assert vo["n_failed_frames"] == sum(vo["failure_reasons"].values())
        assert (vo["status"] == "failed") == (vo["n_failed_frames"] > 0)
        for key in ("rpe_trans_pct", "rpe_rot_deg_per_m"):  # a number, or the reason why not
            assert _finite(vo[key]) or vo["rpe_missing_reason"], (name, key)
    for name, o in on_disk["summary"]["overall"].items():
        for tau in ("5", "100"):
            assert 0.0 <= o["sequence_success_rate"][tau] <= 1.0
        assert o["vo_failed_runs"] <= o["n_sequences"] == 1


@pytest.mark.render
@pytest.mark.slow
def test_tiny_study_report_is_generated_from_the_findings(tiny_study):
    out, results, _ = tiny_study
    report = (out / "report.md").read_text()
    assert "## forest_winter" in report and "## Which of the paper's qualitative findings hold" in report
    assert results["findings_paragraph"] == findings_paragraph(results["findings"])
    assert results["findings_paragraph"] in report
    # the findings are a function of the summary alone
    plain = evaluate_findings(results["summary"], results["config"]["taus"])
    assert [{k: f[k] for k in p} for f, p in zip(results["findings"], plain)] == plain
    for f in results["findings"]:
        assert f["holds"] in (True, False, None) and f["detail"]
        # issue 22's contract; one walk decides nothing
        assert set(f) >= {"id", "effect", "ci95", "p_adjusted", "verdict"}
        assert f["verdict"] in ("undetermined", "by-construction")


@pytest.mark.render
@pytest.mark.slow
def test_tiny_study_never_overwrites(tiny_study, capsys):
    out, _, _ = tiny_study
    before = (out / "results.json").read_bytes()
    with pytest.raises(OutputExistsError, match="--force"):
        run_study(out, CONFIGS["tiny"], progress=False)
    assert main([str(out), "--scenes", "forest_winter", "--cycles", "3", "--size", "64x40", "--spp", "2"]) == 1
    assert "exists" in capsys.readouterr().err
    assert (out / "results.json").read_bytes() == before


# ----------------------------------------------------------------------------- no rendering


def _summary(matches: dict, uniformity: dict, rate100: dict, trans: dict, rot: dict, failed: dict | None = None):
    failed = failed or {}
    per_scene = {"s": {}}
    overall = {}
    for m in METHODS:
        status = "failed" if failed.get(m) else "success"
        per_scene["s"][m] = {"vo": {"status": status, "rpe_trans_pct": trans[m], "rpe_rot_deg_per_m": rot[m],
                                    "n_failed_frames": failed.get(m, 0), "n_frames": 10}}
        overall[m] = {
            "n_sequences": 1, "median_matches": matches[m], "median_uniformity": uniformity[m],
            "sequence_success_rate": {"5": 1.0, "100": rate100[m]},
            "segment_success": {"5": {"rate": 1.0}, "100": {"rate": rate100[m]}},
            "vo_failed_runs": int(bool(failed.get(m))), "vo_failed_frames": failed.get(m, 0),
        }
    return {"per_scene": per_scene, "overall": overall}


PAPER_LIKE = dict(
    matches={"fixed": 674, "classical-30": 500, "classical-50": 600, "classical-70": 450, "shim": 550, "zhang": 560,
             "kim": 400},
    uniformity={"fixed": 0.8, "classical-30": 0.78, "classical-50": 0.8, "classical-70": 0.67, "shim": 0.79,
                "zhang": 0.8, "kim": 0.66},
    rate100={"fixed": 0.44, "classical-30": 0.2, "classical-50": 0.3, "classical-70": 0.2, "shim": 0.3, "zhang": 0.35,
             "kim": 0.2},
    trans={"fixed": 5.1, "classical-30": 5.0, "classical-50": 4.21, "classical-70": 5.2, "shim": 4.3, "zhang": 4.25,
           "kim": 5.75},
    rot={"fixed": 0.09, "classical-30": 0.08, "classical-50": 0.07, "classical-70": 0.085, "shim": 0.08,
         "zhang": 0.07, "kim": 0.1},
)


def _by_id(findings):
    return {f["id"]: f for f in findings}


def test_paper_numbers_satisfy_every_finding_except_vo_failures():
    f = _by_id(evaluate_findings(_summary(**PAPER_LIKE)))
    assert {k for k, v in f.items() if v["holds"] is not True} == {"vo_fails_on_some_runs",
                                                                    "gradient_fewer_vo_failures"}
    assert f["vo_fails_on_some_runs"]["holds"] is False  # no failed run in this summary
    assert f["gradient_fewer_vo_failures"]["holds"] is None  # no failure anywhere: no ranking
    assert "converged" in f["rpe_trans_best_50"]["vo_basis"]
    assert json.loads(json.dumps(list(f.values()))) == list(f.values())  # plain JSON types


def test_vo_findings_use_the_scenes_with_an_rpe():
    summary = _summary(**PAPER_LIKE, failed={"kim": 2})
    hard = copy.deepcopy(summary["per_scene"]["s"])  # a second scene where no method has an RPE
    for e in hard.values():
        e["vo"].update(status="failed", rpe_trans_pct=None, rpe_rot_deg_per_m=None, n_failed_frames=9)
    summary["per_scene"]["hard"] = hard
    f = _by_id(evaluate_findings(summary))
    assert "every method has an RPE (s)" in f["rpe_trans_best_50"]["vo_basis"]
    assert f["rpe_trans_best_50"]["holds"] is True and f["rpe_trans_worst_kim"]["holds"] is True


def test_findings_follow_the_numbers():
    numbers = copy.deepcopy(PAPER_LIKE)
    numbers["matches"]["shim"] = 700  # fixed no longer tracks the most
    numbers["trans"]["kim"] = 4.0  # kim becomes the best in translation
    f = _by_id(evaluate_findings(_summary(**numbers, failed={"zhang": 3})))
    assert f["fixed_most_matches"]["holds"] is False
    assert f["rpe_trans_worst_kim"]["holds"] is False and f["rpe_trans_best_50"]["holds"] is False
    assert f["vo_fails_on_some_runs"]["holds"] is True
    # zhang failed on the only scene: the RPE findings fall back to all runs, and say so
    assert "failed VO runs included" in f["rpe_trans_best_50"]["vo_basis"]
    paragraph = findings_paragraph(list(f.values()))
    assert "Do not hold: M_fixed tracks the most features" in paragraph
    assert "M_Shim 700" in paragraph


def test_equal_values_are_undecided_not_held():
    numbers = copy.deepcopy(PAPER_LIKE)
    numbers["rate100"] = {m: 0.0 for m in METHODS}
    f = _by_id(evaluate_findings(_summary(**numbers)))
    assert f["fixed_best_success_sequences"]["holds"] is None
    assert f["poorest_success_30_70_kim_segments"]["holds"] is None
    assert "all methods equal" in f["fixed_best_success_sequences"]["detail"]


def test_missing_rpe_is_undecided():
    numbers = copy.deepcopy(PAPER_LIKE)
    numbers["trans"] = {m: None for m in METHODS}
    f = _by_id(evaluate_findings(_summary(**numbers)))
    for key in ("rpe_trans_best_50", "rpe_trans_worst_kim", "gradient_ahead_vo", "vo_similar", "fixed_not_best_vo"):
        assert f[key]["holds"] is None, key


def test_segment_success():
    assert segment_success([120, 130, 90, 200, 150, 160], 2, 100) == (2, 3)
    assert segment_success([120, 130, 90, 200, 150, 160, 10], 2, 100) == (2, 3)  # tail dropped
    assert segment_success([120, 30], 10, 5) == (1, 1)  # shorter than a segment: one segment
    assert segment_success([], 10, 5) == (0, 0)


def test_config_is_checked():
    with pytest.raises(StudyError, match="unknown"):
        StudyConfig(scenes=("forest_autumn",))
    with pytest.raises(StudyError, match="n_cycles"):
        StudyConfig(n_cycles=2)
    with pytest.raises(StudyError, match="vo_ratio"):
        StudyConfig(vo_ratio=1.5)
    cfg = StudyConfig(n_cycles=80)
    assert cfg.n_renders == 80 * 6 * 2 * 3
    exit_x = cfg.scene_parameters("forest_edge")["exit_x_m"]
    walked = 80 * 6 / 22 * 2 / 3.6
    assert 0.4 * walked < exit_x < 0.6 * walked  # the exit is on the walk


@pytest.mark.render
@pytest.mark.slow
def test_tiny_study_report_gives_a_verdict_per_result(tiny_study):
    out, results, _ = tiny_study
    report = (out / "report.md").read_text()
    overall = results["summary"]["overall"]
    max_matches = max(o["max_matches"] for o in overall.values())
    keypoints = max(o["median_keypoints"] for o in overall.values())
    # 64x40 images: a few dozen keypoints, so no pair can reach tau = 100
    assert max_matches <= 2 * keypoints and max_matches < 100
    verdicts = report.split("## Verdicts beside the paper's numbers")[1].split("\n## ")[0]
    assert ("Success at tau = 100 is 0 % for every method, as expected: no consecutive pair of these 64x40 images "
            f"reached 100 matches (at most {max_matches}), while the paper's 1920x1200 images (900x the pixels)") in verdicts
    assert verdicts.count("\n- ") == 5  # uniformity, matches, success, VO failures, RPE
    # uniformity in percent, with the unit in the header; "n/a" explained under each table
    row = next(line for line in report.splitlines() if line.startswith("| M_Shim |"))
    assert f"| {100 * results['summary']['per_scene']['forest_winter']['shim']['median_uniformity']:.1f} |" in row
    assert report.count('A "n/a" cell means') == 2
    assert "RPE trans. (% of delta; minimal median @ its pair length delta)" in report


@pytest.mark.render
@pytest.mark.slow
def test_exposim_validate_ae_study_refuses_an_existing_study(tiny_study, capsys):
    from emulator.commands.cli import main as exposim

    out, _, _ = tiny_study
    before = (out / "results.json").read_bytes()
    assert exposim(["validate", "ae-study", "-o", str(out), "--scenes", "forest_winter", "--cycles", "3",
                    "--size", "64x40", "--spp", "2", "--no-progress"]) == 1
    err = capsys.readouterr().err
    assert "exists" in err and len(err.strip().splitlines()) == 1
    assert (out / "results.json").read_bytes() == before


def _help(capsys, monkeypatch, *argv) -> str:
    from emulator.commands.cli import main as exposim

    monkeypatch.setenv("COLUMNS", "250")  # one line per option
    with pytest.raises(SystemExit) as exc:
        exposim([*argv, "--help"])
    assert exc.value.code == 0
    return capsys.readouterr().out


def test_validate_help_shows_the_defaults(capsys, monkeypatch):
    from validation.emulation import EmulationConfig

    assert "ae-study" in _help(capsys, monkeypatch, "validate")
    text = _help(capsys, monkeypatch, "validate", "ae-study")
    full, quick = CONFIGS["full"], CONFIGS["quick"]
    assert f"(default: {full.n_cycles}; {quick.n_cycles} with --quick)" in text
    assert f"(default: {full.width}x{full.height})" in text and f"(default: {full.spp})" in text
    text = _help(capsys, monkeypatch, "validate", "emulation")
    full, quick = EmulationConfig(), EmulationConfig.quick()
    assert (f"render size in pixels, WIDTHxHEIGHT (default: {full.width}x{full.height}; with --quick: "
            f"{quick.width}x{quick.height})") in text
    assert "--width" not in text and "--height" not in text
    assert f"(default: {full.n_exposures}; with --quick: {quick.n_exposures})" in text



def test_scheduler_reaches_the_renders_and_a_bad_one_creates_nothing(tmp_path, stop_at_synthesize, capsys):
    with pytest.raises(SynthesizeCalled):
        main([str(tmp_path / "run"), "--quick", "--no-progress", "--scheduler", "local"])
    assert stop_at_synthesize["scheduler"] == "local"
    assert main([str(tmp_path / "bad"), "--quick", "--scheduler", "tcp:/x"]) == 1
    assert "--scheduler must be 'local' or tcp://HOST:PORT, got 'tcp:/x'" in capsys.readouterr().err
    assert not (tmp_path / "bad").exists()


def test_ae_study_replicates_shift_every_seed(tmp_path, stop_at_synthesize):
    from tests.conftest import SynthesizeCalled

    from validation.ae_study.cli import main as ae_main

    with pytest.raises(SynthesizeCalled):
        ae_main([str(tmp_path / "rep"), "--quick", "--no-progress", "--replicates", "3"])
    assert stop_at_synthesize["seed"] == 0 and stop_at_synthesize["render_seed"] == 0
    assert (tmp_path / "rep" / "replicates" / "seed0").is_dir()
    assert ae_main([str(tmp_path / "bad"), "--quick", "--replicates", "0"]) == 1

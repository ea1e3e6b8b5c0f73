"""Reports say in words whether each result is expected beside the paper, units are in the headers,
"-" cells are explained, and the figures carry no unexplained styles or empty ranges (issue 11)."""

from __future__ import annotations

import numpy as np
import pytest

from emulator.report import bench as report
from emulator.report.verdicts import (
    DASH_NOTE,
    PAPER_IMAGE_WH,
    matches_verdict,
    success_verdict,
    uniformity_verdict,
)


def _features_results(matches: dict, keypoints: int = 50, shape=(160, 256), uniformity=0.25) -> dict:
    """A feature-benchmark results.json with one run; ``matches``: method -> pair match counts."""
    methods, runs = {}, {}
    for name, m in matches.items():
        runs[name] = {"n_images": len(m) + 1, "image_shape": list(shape), "matches": list(m),
                      "n_keypoints": [keypoints] * (len(m) + 1), "uniformity": [uniformity] * (len(m) + 1)}
        methods[name] = {"n_runs": 1, "n_images": len(m) + 1, "median_uniformity": uniformity if m else None,
                         "median_matches": float(np.median(m)) if m else None,
                         "min_matches": int(min(m)) if m else None,
                         "success_at_100": float(min(m) >= 100) if m else None}
    return {"parameters": {"grid": [20, 20], "ratio": 0.8, "n_features": 0, "matcher": "flann", "scale": 1.0,
                           "conversion": "x"},
            "runs": [{"run_dir": "run", "methods": runs}], "methods": methods, "command": "test"}


def _table_and_after(md: str, header_start: str) -> tuple[list[str], list[str]]:
    lines = md.splitlines()
    i = next(k for k, line in enumerate(lines) if line.startswith(header_start))
    j = i
    while j < len(lines) and lines[j].startswith("|"):
        j += 1
    return lines[i:j], lines[j:]


# ----------------------------------------------------------------------------- verdicts


def test_success_at_100_is_explained_by_the_largest_match_count():
    md = report.features_report(_features_results({"fixed": [61, 40, 55], "kim": [30, 12]}), "fig4.png")
    # the largest count of any pair (61) is below tau: 0 % is expected, with the image sizes named
    assert "Success at tau = 100 is 0 % for every method, as expected" in md
    assert "at most 61" in md and "256x160" in md and f"{PAPER_IMAGE_WH[0]}x{PAPER_IMAGE_WH[1]}" in md
    # 1920x1200 has 2304000 / 40960 = 56.25 times the pixels of 256x160
    assert "(56x the pixels)" in md


def test_success_below_the_paper_names_the_weakest_pair():
    text = success_verdict(100, {"fixed": 0.0, "kim": 10.0}, 180, 42, (640, 400))
    assert text.startswith("Success at tau = 100 is 0..10 % (paper at tau = 100: 20-44 %).")
    assert "Lower than the paper" in text and "42 matches against at most 180" in text
    assert "Overlaps the paper's range" in success_verdict(100, {"fixed": 44.0, "kim": 20.0}, 900, 50, (1920, 1200))


def test_matches_verdict_scales_the_papers_median_by_image_area():
    # 674 * (256 * 160) / (1920 * 1200) = 11.98: 12 matches is in line with the size
    text = matches_verdict(12.0, (256, 160))
    assert "the paper's figure is 12;" in text and "1.0x that" in text and "in line with it" in text
    assert "below even that" in matches_verdict(3.0, (256, 160))  # 0.25x
    assert "above it" in matches_verdict(571.0, (160, 120))


def test_uniformity_verdict_caps_the_fraction_by_the_keypoint_count():
    # 50 keypoints can occupy at most 50 of 400 cells: 12.5 %
    text = uniformity_verdict({"fixed": 10.0, "kim": 12.0}, 50, (20, 20))
    assert "10.0..12.0 %" in text and "at most 50 of the 400 cells (12.5 %) can hold one." in text
    # 237 keypoints could fill 59.2 % of the cells; 24.8..31.9 % is below that cap: clustering as well
    text = uniformity_verdict({"fixed": 24.8, "kim": 31.9}, 237, (20, 20))
    assert "(59.2 %) can hold one, and the measurement is below that cap too" in text
    assert "although the images have enough keypoints" in uniformity_verdict({"kim": 30.0}, 900, (20, 20))
    assert "Comparable with the paper" in uniformity_verdict({"kim": 66.0}, 800, (20, 20))


def test_features_report_units_and_dash_note():
    md = report.features_report(_features_results({"fixed": [61, 40], "shim": []}), "fig4.png")
    table, after = _table_and_after(md, "| method |")
    assert table[0].endswith("| median uniformity (%) | median matches | min matches | success at tau=100 (%) |")
    fixed = next(row for row in table if row.startswith("| fixed"))
    assert "| 25.0 |" in fixed  # uniformity 0.25 shown in percent
    shim = next(row for row in table if row.startswith("| shim"))
    assert shim.count("| - ") >= 3  # no pair: no figure
    assert after[1] == report.FEATURES_DASH_NOTE and "RPE" not in after[1]  # the note directly under the table
    assert "## Verdicts" in md


# ----------------------------------------------------------------------------- VO report and figures


def _vo_results() -> dict:
    def rpe(scale):
        return {"scale": 1.0, "deltas": [
            {"delta_m": 0.5, "n_pairs": 4, "trans_pct": {"median": 2.0 * scale}, "rot_deg_per_m": {"median": 0.2 * scale}},
            {"delta_m": 1.0, "n_pairs": 2, "trans_pct": {"median": 1.0 * scale}, "rot_deg_per_m": {"median": 0.1 * scale}},
        ]}

    return {
        "run_dir": "run", "reference": "ref.txt", "failure_policy": "constant velocity", "command": "test",
        "calibration": {"folder": "cal", "baseline_m": 0.18, "rectified_fx_px": 150.0},
        "parameters": {"scale": 1.0, "vo": {"pnp_reprojection_px": 2.0}, "align_scale": True, "rel_delta_tol": 0.1},
        "methods": {
            "fixed": {"status": "success", "n_frames": 5, "n_tracked": 5, "failures": [], "rpe": rpe(1.0)},
            "kim": {"status": "failed", "n_frames": 5, "n_tracked": 3, "rpe": rpe(2.0),
                    "failures": [{"reason": "too_few_matches"}, {"reason": "too_few_matches"}]},
            "shim": {"status": "failed", "n_frames": 5, "n_tracked": 4, "rpe": None, "rpe_skipped": None,
                     "failures": [{"reason": "pnp_failed"}]},
        },
    }


def test_vo_report_gives_the_delta_explains_dashes_and_judges():
    md = report.vo_report(_vo_results(), {"fig6": "fig6_rpe.png"})
    table, after = _table_and_after(md, "| method |")
    assert ("relative pose error, translation: median over pose pairs (% of the pair length), per pair length (m)"
            in table[0])
    assert "RPE trans." not in md and "delta" not in table[0]
    assert "0.50 m: 2.00, 1.00 m: 1.00" in table[2]  # each value with its delta
    shim = next(row for row in table if row.startswith("| shim"))
    assert shim.endswith("| - | - | - |")
    assert after[1].startswith(DASH_NOTE) and "dotted line" in after[1]
    assert "VO failed on 2 of 3 runs (67 %; paper: 11 of 55, 20 %)" in md
    assert "too_few_matches 2, pnp_failed 1" in md
    # minimal medians 1.00 (fixed) and 2.00 (kim): below the paper's 4.21 %
    assert "Minimal median RPE 1.00..2.00 % in translation, 0.100..0.200 deg/m" in md
    assert "Below the paper's translation range" in md and "0.5..1 m long" in md
    assert "1 of the RPEs come from runs whose VO failed" in md


def test_rpe_figure_names_the_dotted_line():
    fig = report.rpe_figure(_vo_results())
    for ax in fig.axes:
        lines = {line.get_label(): line.get_linestyle() for line in ax.get_lines()}
        assert lines == {"fixed": "-", "kim (VO failed on 2 frames)": report.FAILED_STYLE}
    first, last = fig.axes
    assert first.get_legend() is None  # one legend for both panels, beside the second, outside its data
    legend = last.get_legend()
    assert {t.get_text() for t in legend.get_texts()} == set(lines)
    assert "dotted" in legend.get_title().get_text()
    fig.canvas.draw()
    box = legend.get_window_extent().transformed(last.transAxes.inverted())
    assert box.x0 >= 1.0  # to the right of the axes


def _span(lim) -> float:
    return float(lim[1] - lim[0])


@pytest.mark.parametrize("lateral_m", [0.4, 4.0])
def test_trajectory_limits_follow_the_data(lateral_m):
    """A 12 m walk with ``lateral_m`` of sideways drift: each axis spans at most 1.2x its data."""
    t = np.linspace(0.0, 1.0, 40)
    xyz = np.column_stack([lateral_m * np.sin(3 * t), 0.01 * t, 12.0 * t])  # camera axes: x right, y down, z forward
    ref = np.column_stack([np.zeros_like(t), np.zeros_like(t), 12.0 * t])
    fig = report.trajectories_figure({"fixed": xyz}, ref)
    fig.canvas.draw()  # apply the aspect
    (ax,) = fig.axes
    data_x = np.ptp(np.concatenate([xyz[:, 0], ref[:, 0]]))
    data_z = np.ptp(np.concatenate([xyz[:, 2], ref[:, 2]]))
    assert ax.get_xlabel() == "x (m)" and ax.get_ylabel() == "z (m)"
    assert data_x < _span(ax.get_xlim()) <= 1.2 * data_x
    assert data_z < _span(ax.get_ylim()) <= 1.2 * data_z
    to_scale = bool(data_z / data_x <= report.MAX_EQUAL_ASPECT)
    assert (ax.get_aspect() == 1.0) is to_scale
    assert ("not to scale" in ax.get_title()) is (not to_scale)


# ----------------------------------------------------------------------------- run report


@pytest.mark.parametrize("mode, adjusted", [("paper", 3), ("borealhdr", 4)])
def test_run_report_units_dashes_and_fixed(mode, adjusted):
    from emulator.report.run import run_markdown

    method = {"mode": mode, "cycles": 5, "mean_exposure_ms": 2.0, "median_exposure_ms": 2.0, "min_exposure_ms": 1.0,
              "max_exposure_ms": 3.0, "mean_saturated_fraction": 0.0125, "mean_valid_fraction": 0.98,
              "non_finite_proposals": 0, "method_ms_per_frame": None}
    info = {"sequence": "seq", "method_options": {"fixed": {"name": "fixed", "mode": mode, "n_auto_frames": 3}}}
    md = run_markdown(info, {"methods": {"fixed": method, "shim": dict(method, mode=mode)}})
    table, after = _table_and_after(md, "| method |")
    assert "| mean saturated (%) | mean valid (%) |" in table[0]
    assert "| 1.25 | 98.00 | 0 | - |" in table[2]  # fractions shown in percent, no timing: "-"
    assert '"-": no cycle of that method (or no timing recorded)' in after[1]
    assert f"`fixed` runs classical-50 for its first {adjusted} frames and then freezes" in md


def test_features_report_compares_methods_with_intervals():
    res = _features_results({"fixed": [61, 40, 55, 58, 60, 52], "kim": [30, 12, 20, 25, 22, 18]})
    iv = report.features_intervals(res)
    m = iv["median_matches"]
    assert m["best"] == "fixed" and m["methods"]["fixed"]["estimate"] == 56.5
    d = m["methods"]["kim"]["difference_to_best"]
    assert d["estimate"] == 21.0 - 56.5 and d["excludes_zero"] is True
    md = report.features_report(res, "fig4.png")
    assert "| method | median matches | 95 % interval | difference from the best (fixed) |" in md
    assert "| kim | 21.0 |" in md and "| differs |" in md


# ----------------------------------------------------------------------------- Fig. 4 (c)


def _legend_texts(ax) -> list[str]:
    legend = ax.get_legend()
    return [t.get_text() for t in legend.get_texts()] if legend else []


def test_fig4c_over_one_run_shows_each_methods_weakest_pair():
    res = _features_results({"fixed": [4100, 4033], "shim": [3900, 3833], "zhang": [3864, 3990], "kim": [84, 190]})
    fig = report.features_figure(res)
    c = fig.axes[2]
    heights = [round(p.get_height()) for p in c.patches]
    assert heights == [4033, 3833, 3864, 84]
    assert [t.get_text() for t in c.get_xticklabels()] == ["fixed", "shim", "zhang", "kim"]
    written = sorted(t.get_text() for t in c.texts)
    assert written == ["3833", "3864", "4033", "84"]
    assert _legend_texts(c) == [] and "weakest pair" in c.get_title()


def _two_runs(first: dict, second: dict) -> dict:
    """A features results.json over two runs, with the success curve at coarse taus."""
    from emulator.metrics.features import success_curve

    a, b = _features_results(first), _features_results(second)
    res = dict(a, runs=a["runs"] + b["runs"], n_runs=2)
    taus = list(range(0, 5000, 500))
    res["success_curve"] = {"taus": taus, "rate": {m: success_curve([first[m], second[m]], taus).tolist()
                                                   for m in first}}
    return res


def test_fig4c_tags_methods_equal_only_when_their_weakest_pairs_are_equal():
    # zhang's weakest pairs (3864, 2000) differ from shim's (3833, 2000) but fall in the same
    # 500-match tau steps: the curves coincide on the grid, the methods are not equal
    res = _two_runs({"shim": [3833, 3900], "zhang": [3864, 4000], "classical-30": [3833, 3950]},
                    {"shim": [2000], "zhang": [2000], "classical-30": [2000]})
    assert report.weakest_pairs(res) == {"shim": [3833, 2000], "zhang": [3864, 2000], "classical-30": [3833, 2000]}
    legend = _legend_texts(report.features_figure(res).axes[2])
    assert legend == ["shim", "zhang (hides shim's curve)", "classical-30 (= shim)"]
    # curves that differ on the grid: no tag at all
    res = _two_runs({"shim": [3833], "zhang": [600]}, {"shim": [2000], "zhang": [2000]})
    assert _legend_texts(report.features_figure(res).axes[2]) == ["shim", "zhang"]


# ----------------------------------------------------------------------------- exposure plot and run report


def _exposure_tables(series: dict) -> dict:
    return {name: {"timestamp_ns": np.arange(len(v), dtype=np.int64) * 274_000_000, "target_ms": np.array(v, float)}
            for name, v in series.items()}


def _tick_labels(ax) -> list[str]:
    lo, hi = ax.get_ylim()
    return [ax.yaxis.get_major_formatter()(t, 0) for t in ax.get_yticks() if lo <= t <= hi]


@pytest.mark.parametrize("low, expected_lowest", [(0.5, "0.5"), (0.6, "0.5"), (0.26, "0.25"), (1.3, "1")])
def test_exposure_axis_is_labelled_down_to_the_datas_minimum(low, expected_lowest):
    from emulator.report.run import exposure_figure

    info = {"brackets_ms": [1, 2, 4, 8, 16, 32], "mode": "paper", "initial_ms": 4.0}
    fig = exposure_figure(info, _exposure_tables({"classical-50": [4, 6, 8], "kim": [4, low, 20]}))
    ax = fig.axes[0]
    labels = _tick_labels(ax)
    assert labels[0] == expected_lowest and float(labels[0]) <= low  # a labelled tick at or below the minimum
    assert labels[-5:] == ["2", "4", "8", "16", "32"][-5:]
    assert ax.get_ylim()[0] < float(expected_lowest)  # the lowest tick is inside the axis


def test_exposure_legend_tags_only_identical_sequences():
    from emulator.report.run import exposure_figure

    info = {"brackets_ms": [1, 2, 4], "mode": "paper", "initial_ms": 4.0}
    fig = exposure_figure(info, _exposure_tables({"fixed": [4, 6, 8], "classical-50": [4, 6, 8],
                                                  "classical-30": [4, 6, 8.000001]}))
    assert [t.get_text() for t in fig.axes[0].get_legend().get_texts()] == [
        "fixed", "classical-50 (= fixed)", "classical-30"]
    title = fig.axes[0].get_title()
    assert "the paper's methods with the published code's defects corrected" in title and "paper mode" not in title


def test_run_report_names_mode_and_selector_in_words():
    from emulator.report.run import run_markdown

    info = {"sequence": "/data/seq", "mode": "paper", "selector": "higher-no-sat", "method_options": {}}
    md = run_markdown(info, {"methods": {}})
    assert ("- methods: the paper's methods with the published code's defects corrected (`--mode paper`)" in md)
    assert "- brackets chosen by the paper's bracket selector (higher bracket unless saturated)" in md
    assert "M_fixed" not in md and "paper mode" not in md and "emulator." not in md


# ----------------------------------------------------------------------------- VO report wording


def test_vo_report_speaks_of_the_extrinsics_in_sentences():
    res = _vo_results()
    res["calibration"]["extrinsics"] = {
        "mode": "auto", "epipolar_residual_px": 0.1432, "refined": False,
        "reason": "the given calibration fits the images",
        "criterion": "median epipolar distance of left-right SIFT matches > 1 px"}
    md = report.vo_report(res, {})
    assert ("Stereo extrinsics (auto): the given calibration fits the images. Measured 0.14 px. Refinement rule: "
            "median epipolar distance of left-right SIFT matches > 1 px.") in md
    assert "px. the" not in md
    res["calibration"]["extrinsics"].update(epipolar_residual_px=17.2, refined=True,
                                            estimate={"epipolar_residual_after_px": 0.324},
                                            reason="re-estimated, as the residual exceeds 1 px")
    md = report.vo_report(res, {})
    assert ("Stereo extrinsics (auto): re-estimated, as the residual exceeds 1 px. Measured 17.20 px, 0.32 px "
            "after refinement. Refinement rule:") in md


def test_vo_report_gives_no_recording_date_to_a_synthetic_recording(tmp_path):
    from emulator.io.borealhdr import write_recording_metadata
    from emulator.io.layout import CalibrationChoice
    from emulator.metrics.vo_bench import _choice_record

    # synth's timestamps start at 1.7e18 ns, which decodes to 2023-11-14: not a recording date
    choice = CalibrationChoice(tmp_path / "calibration", "the recording's own calibration/ folder", "2023-11-14",
                               "first timestamp 1700000000000000000 ns (UTC)")
    real = _choice_record(choice, tmp_path)
    assert real["recording_date"] == "2023-11-14" and "synthetic" not in real
    write_recording_metadata(tmp_path, {"generator": {"name": "exposim.synth.capture_sequence", "version": "0"}})
    synthetic = _choice_record(choice, tmp_path)
    assert synthetic["recording_date"] is None and synthetic["synthetic"] is True
    res = _vo_results()
    res["calibration"]["choice"] = synthetic
    md = report.vo_report(res, {})
    assert ("Calibration choice: the recording's own calibration/ folder (a synthetic recording, written by "
            "exposim synth: it has no recording date).") in md
    assert "2023-11-14" not in md
    res["calibration"]["choice"] = real
    assert "(recording date 2023-11-14)." in report.vo_report(res, {})


def test_paper_figures_name_methods_as_the_command_line_does():
    names = " ".join(list(report.PAPER_FEATURES) + list(report.PAPER_VO))
    assert "M_" not in names
    assert "worst (classical-30, classical-70, kim)" in names and "best (classical-50)" in names
    md = report.features_report(_features_results({"fixed": [61, 40, 55], "kim": [30, 12]}), "fig4.png")
    assert "M_fixed" not in md and "Median matches of fixed:" in md and "emulator." not in md


def test_trajectories_without_a_reference_are_a_top_view_named_by_its_plane():
    """Issue 46: a walk that bobs 0.3 m vertically (y) and drifts 0.1 m sideways (x) was drawn as y against z."""
    t = np.linspace(0.0, 1.0, 30)
    xyz = np.column_stack([0.1 * t, 0.3 * np.sin(20 * t), 2.0 * t])
    fig = report.trajectories_figure({"fixed": xyz}, None)
    (ax,) = fig.axes
    assert ax.get_xlabel() == "x (m)" and ax.get_ylabel() == "z (m)"
    assert "top view (plane x-z" in ax.get_title()


def _vo_entry(tracked, stereo, inliers, rows):
    from emulator.metrics.vo_table import vo_summary

    frames = {"tracked": tracked, "n_stereo_points": stereo, "n_inliers": inliers, "row_offset_px": rows}
    xyz = np.column_stack([np.zeros(len(tracked)), np.zeros(len(tracked)), 0.1 * np.arange(len(tracked))])
    return {"status": "success" if all(tracked) else "failed", "n_frames": len(tracked), "n_tracked": sum(tracked),
            "failures": [], "rpe": None, "rpe_skipped": "no reference", "summary": vo_summary(frames, xyz)}


def test_vo_without_a_reference_ranks_methods_on_their_vo_table():
    from emulator.metrics.vo_table import vo_ranking

    methods = {"fixed": _vo_entry([True] * 4, [800, 1500, 1900, 1700], [0, 650, 1240, 1330], [0.0, 0.01, None, -0.01]),
               "kim": _vo_entry([True, False, True, True], [800, 27, 1700, 2700], [0, 21, 21, 1020], [0, 0.08, 0, 0]),
               "shim": _vo_entry([True] * 4, [790, 850, 970, 800], [0, 630, 650, 660], [0, 0, 0, 0])}
    s = methods["fixed"]["summary"]
    assert s == {"n_tracked": 4, "n_frames": 4, "median_stereo_points": 1600.0, "median_inliers": 1240.0,
                 "median_row_offset_px": 0.0, "path_length_m": pytest.approx(0.3)}
    assert vo_ranking(methods) == ["fixed", "shim", "kim"]  # kim lost a frame; fixed has more inliers than shim
    results = {**_vo_results(), "reference": None, "methods": methods, "ranking_without_reference": vo_ranking(methods)}
    md = report.vo_report(results, {"trajectories": "trajectories.png"})
    table, _ = _table_and_after(md, "| rank | method |")
    assert table[2] == "| 1 | fixed | 4/4 | 1600 | 1240 | 0.00 | 0.300 |"
    assert table[4].startswith("| 3 | kim | 3/4 | 1250 | 21 |")
    assert "fig6" not in md and "## VO by method, without a reference" in md


def test_features_report_marks_methods_that_had_not_settled():
    """Issue 46: on a short clip a method still climbing at the end is marked beside its "best"/"differs"."""
    res = _features_results({"fixed": [61, 40, 55, 70], "kim": [30, 12, 20, 25]})
    res["runs"][0]["still_trending"] = {"kim": {"direction": "rising", "change_fraction": 0.4, "steps": 3}}
    md = report.features_report(res, "fig4.png")
    table, _ = _table_and_after(md, "| method | median matches |")
    assert table[3].startswith("| kim (still rising) | 22.5 |")
    assert "**Too short to settle:**" in md
    assert "still rising" not in report.features_report(_features_results({"fixed": [61, 40], "kim": [30, 12]}),
                                                        "fig4.png")


def test_bench_features_records_the_methods_still_trending(tmp_path):
    from emulator.metrics.bench import _still_trending

    run = tmp_path / "run"
    for name, ms in (("kim", [1.0, 2.0, 4.0, 8.0]), ("fixed", [4.0, 4.0, 4.0, 4.0])):
        (run / name).mkdir(parents=True)
        rows = "".join(f"{k},{k},{t},4,1,0,1\n" for k, t in enumerate(ms))
        (run / name / "exposures.csv").write_text(
            "cycle,timestamp_ns,target_ms,bracket_ms,ratio,saturated_fraction,valid_fraction\n" + rows)
    got = _still_trending(run, ["kim", "fixed"])
    assert got == {"still_trending": {"kim": {"direction": "rising", "change_fraction": 7.0, "steps": 3}}}
    assert _still_trending(tmp_path / "nothing", ["kim"]) == {}

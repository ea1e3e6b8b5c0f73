"""Verdicts in words beside the paper's numbers: is each measured result expected, and why.

Every sentence is derived from the measured figures passed in (image size, largest match
count, keypoints per image, pair lengths, failure reasons) and the paper's figures below;
nothing is written by hand for one particular run.  The paper's images were 1920x1200
(BorealHDR), and most of the differences of small synthetic images follow from that.
"""

from __future__ import annotations

from collections.abc import Mapping

from emulator.cells import DASH, format_number

__all__ = [
    "PAPER_IMAGE_WH",
    "PAPER_MEDIAN_MATCHES_FIXED",
    "PAPER_SUCCESS_TAU100_PCT",
    "PAPER_UNIFORMITY_PCT",
    "PAPER_RPE_TRANS_PCT",
    "PAPER_RPE_ROT_DEG_PER_M",
    "PAPER_VO_FAILED",
    "DASH_NOTE",
    "dash_note",
    "dash_cell",
    "success_verdict",
    "matches_verdict",
    "uniformity_verdict",
    "rpe_verdict",
    "vo_failure_verdict",
]

#: Image size of the paper's benchmarks (BorealHDR, width x height).
PAPER_IMAGE_WH = (1920, 1200)
#: The paper's median matches between consecutive images of M_fixed (Fig. 4b), the highest.
PAPER_MEDIAN_MATCHES_FIXED = 674
#: The paper's success rate at tau = 100 (Fig. 4c): worst (M_30%, M_70%, M_Kim) and best (M_fixed), %.
PAPER_SUCCESS_TAU100_PCT = (20.0, 44.0)
#: The paper's median uniformity of M_Kim and M_70% (the lowest), % of the 20x20 grid cells.
PAPER_UNIFORMITY_PCT = (66.0, 67.3)
#: The paper's minimal median translation RPE, best (M_50%) and worst (M_Kim), %.
PAPER_RPE_TRANS_PCT = (4.21, 5.75)
#: The paper's minimal median rotation RPE, best (M_Zhang, M_50%) and M_fixed, deg/m.
PAPER_RPE_ROT_DEG_PER_M = (0.07, 0.09)
#: VO failures in the paper: (failed, trajectories).
PAPER_VO_FAILED = (11, 55)



def dash_note(symbol: str = "-") -> str:
    """The note under every table that may hold a ``symbol`` cell (a figure that does not exist)."""
    return (f"A \"{symbol}\" cell means the figure does not exist for that row: no image pair (matches, success), "
            "no image (uniformity) or no RPE (no reference, no pose pair of that length, or VO failed and "
            "the RPE was not requested); the reason is given beside the table where known.")


#: The note under every table that may hold a "-" cell.
DASH_NOTE = dash_note(DASH)


def dash_cell(value, spec: str = ".1f") -> str:
    """A table cell: ``value`` formatted by ``spec``, or ``-`` where it is missing (None; :data:`DASH_NOTE`):
    :func:`emulator.cells.format_number` with ``missing=DASH``."""
    return format_number(value, spec, missing=DASH)


def _pixels(wh) -> int:
    return int(wh[0]) * int(wh[1])


def _size(wh) -> str:
    return f"{int(wh[0])}x{int(wh[1])}"


def _range(values) -> tuple[float, float] | None:
    vals = [float(v) for v in values if v is not None]
    return (min(vals), max(vals)) if vals else None


def _span(lo: float, hi: float, spec: str) -> str:
    return format(lo, spec) if format(lo, spec) == format(hi, spec) else f"{lo:{spec}}..{hi:{spec}}"


def success_verdict(tau: int, rates_percent: Mapping[str, float | None], max_matches: int | None,
                    min_matches: int | None, image_wh) -> str:
    """Verdict on the success rate at ``tau`` (rates in %, one per method), from the match counts.

    ``max_matches`` / ``min_matches``: the largest and smallest match count of any
    consecutive pair of any method; ``image_wh``: the analysed image size.

    Examples
    --------
    >>> success_verdict(100, {"fixed": 0.0}, 61, 3, (256, 160)).split(":")[0]
    'Success at tau = 100 is 0 % for every method, as expected'
    """
    r = _range(rates_percent.values())
    if r is None or max_matches is None:
        return f"Success at tau = {tau}: cannot be judged, no image pair was analysed."
    lo, hi = r
    paper = f"{PAPER_SUCCESS_TAU100_PCT[0]:.0f}-{PAPER_SUCCESS_TAU100_PCT[1]:.0f} %"
    area = _pixels(PAPER_IMAGE_WH) / _pixels(image_wh)
    if max_matches < tau:
        head = ("is 0 % for every method, as expected" if hi == 0 else
                f"is {_span(lo, hi, '.0f')} %, which cannot be (no pair reaches tau)")
        return (f"Success at tau = {tau} {head}: no consecutive pair of these {_size(image_wh)} images reached "
                f"{tau} matches (at most {max_matches}), while the paper's {_size(PAPER_IMAGE_WH)} images "
                f"({area:.0f}x the pixels) gave fixed a median of {PAPER_MEDIAN_MATCHES_FIXED} matches; "
                f"the paper's tau = 100 success rates ({paper}) are not comparable at this size.")
    text = f"Success at tau = {tau} is {_span(lo, hi, '.0f')} % (paper at tau = 100: {paper}). "
    if tau != 100:
        return text + "Not the paper's threshold: no comparison."
    if hi < PAPER_SUCCESS_TAU100_PCT[0]:
        return text + (f"Lower than the paper: a run fails on its weakest pair, and the weakest pairs here have "
                       f"{min_matches} matches against at most {max_matches} ({_size(image_wh)} images, "
                       f"1/{area:.0f} of the paper's pixels).")
    if lo > PAPER_SUCCESS_TAU100_PCT[1]:
        return text + "Higher than the paper: these runs have no pair as weak as the paper's hardest trajectories."
    return text + "Overlaps the paper's range."


def matches_verdict(median_matches: float | None, image_wh, method: str = "fixed") -> str:
    """Verdict on the median matches of ``method`` against the paper's 674, scaled by image area.

    Examples
    --------
    >>> "in line with" in matches_verdict(12.0, (192, 120))
    True
    """
    if median_matches is None:
        return f"Median matches of {method}: cannot be judged, no image pair was analysed."
    scale = _pixels(image_wh) / _pixels(PAPER_IMAGE_WH)
    expected = PAPER_MEDIAN_MATCHES_FIXED * scale
    ratio = median_matches / expected if expected > 0 else float("inf")
    if 0.5 <= ratio <= 2.0:
        verdict = "in line with it: the difference from the paper is the image size, as expected"
    elif ratio < 0.5:
        verdict = "below even that: the image size alone does not explain the difference"
    else:
        verdict = "above it: the image size does not limit the matches here"
    shown = f"{ratio:.1f}" if ratio < 10 else f"{ratio:.0f}"
    return (f"Median matches of {method}: {median_matches:.0f} against the paper's {PAPER_MEDIAN_MATCHES_FIXED} "
            f"at {_size(PAPER_IMAGE_WH)}. Scaled by the image area to {_size(image_wh)} (x{scale:.4f}) the "
            f"paper's figure is {expected:.0f}; the measurement is {shown}x that, {verdict}.")


def uniformity_verdict(median_uniformity_percent: Mapping[str, float | None], median_keypoints: float | None,
                       grid) -> str:
    """Verdict on the median uniformity (%, one per method) against the paper's 66-67 %.

    ``median_keypoints``: median SIFT keypoints per image (all methods); ``grid``: (rows, cols).

    Examples
    --------
    >>> "at most" in uniformity_verdict({"kim": 20.0}, 50, (20, 20))
    True
    """
    r = _range(median_uniformity_percent.values())
    if r is None:
        return "Uniformity: cannot be judged, no image was analysed."
    lo, hi = r
    cells = int(grid[0]) * int(grid[1])
    paper = f"{PAPER_UNIFORMITY_PCT[0]:.1f}-{PAPER_UNIFORMITY_PCT[1]:.1f} %"
    text = f"Median uniformity {_span(lo, hi, '.1f')} % of the {grid[0]}x{grid[1]} cells (paper: {paper} for the lowest methods). "
    if hi < PAPER_UNIFORMITY_PCT[0] - 5:
        k = "n/a" if median_keypoints is None else f"{median_keypoints:.0f}"
        cap = None if median_keypoints is None else 100.0 * min(median_keypoints, cells) / cells
        if cap is not None and cap < PAPER_UNIFORMITY_PCT[0]:
            return text + (f"Lower, as expected: with a median of {k} keypoints per image at most {k} of the "
                           f"{cells} cells ({cap:.1f} %) can hold one"
                           + (", and the measurement is below that cap too: the keypoints also cluster."
                              if hi < cap - 5 else "."))
        return text + (f"Lower than the paper although the images have enough keypoints to reach it ({k} for "
                       f"{cells} cells): the keypoints cluster (e.g. on the textured parts of the scene).")
    if lo > PAPER_UNIFORMITY_PCT[1] + 5:
        return text + "Higher than the paper's lowest methods."
    return text + "Comparable with the paper."


def rpe_verdict(trans_percent: Mapping[str, float | None], rot_deg_per_m: Mapping[str, float | None],
                deltas_m, n_on_failed_runs: int = 0) -> str:
    """Verdict on the minimal median RPE (per method) against the paper's 4.21-5.75 % and 0.07-0.09 deg/m.

    ``deltas_m``: the pair lengths the minima were taken over, metres.
    """
    t, r = _range(trans_percent.values()), _range(rot_deg_per_m.values())
    if t is None:
        return "RPE: cannot be judged, no RPE was computed (see the reasons beside the table)."
    d = _range(deltas_m)
    pt, pr = PAPER_RPE_TRANS_PCT, PAPER_RPE_ROT_DEG_PER_M
    parts = [f"Minimal median RPE {_span(t[0], t[1], '.2f')} % in translation"
             + (f", {_span(r[0], r[1], '.3f')} deg/m in rotation" if r else "")
             + f" (paper: {pt[0]}-{pt[1]} %, {pr[0]}-{pr[1]} deg/m)."]
    if t[1] < pt[0]:
        parts.append("Below the paper's")
    elif t[0] > pt[1]:
        parts.append("Above the paper's")
    else:
        parts.append("Overlapping the paper's")
    parts[-1] += (f" translation range; not directly comparable: here the pairs are {_span(d[0], d[1], '.2g')} m long "
                  "(on a short synthetic walk, exact reference) against the paper's lidar reference over 55 real "
                  "trajectories." if d else
                  " translation range.")
    if n_on_failed_runs:
        parts.append(f"{n_on_failed_runs} of the RPEs come from runs whose VO failed on some frames "
                     "(the paper leaves those out).")
    return " ".join(parts)


def vo_failure_verdict(n_failed: int, n_runs: int, reasons: Mapping[str, int]) -> str:
    """Verdict on the VO failures (runs with at least one failed frame) against the paper's 11 of 55.

    Examples
    --------
    >>> vo_failure_verdict(0, 7, {}).startswith("VO failed on 0 of 7 runs")
    True
    """
    f, n = PAPER_VO_FAILED
    pct = 100.0 * n_failed / n_runs if n_runs else 0.0
    text = f"VO failed on {n_failed} of {n_runs} runs ({pct:.0f} %; paper: {f} of {n}, {100 * f / n:.0f} %). "
    if not n_failed:
        return text + "None failed; the paper attributes its failures to sun glares and illumination changes."
    top = ", ".join(f"{k} {v}" for k, v in sorted(reasons.items(), key=lambda kv: -kv[1]))
    return text + f"Failed frames by reason: {top or 'n/a'}."

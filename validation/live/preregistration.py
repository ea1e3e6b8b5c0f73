"""The pre-registration of a live study: what it will decide, fixed before its first walk.

:func:`preregistration` states the study's plan from its configuration: the headline's metrics and
comparisons, the margin (omega2 0.2), the level (5 %, Holm across the family), the number of walks
``N`` (scenes x seeds), the scenes, the seeds, the methods, the render preset, the draws per stochastic
method ``k``, the bootstrap resamples with the Monte Carlo rule, the level-shift margin, and the
metrics that leave the headline before any data (:func:`headline_exclusions`: the segment success rate
when a walk has fewer than :data:`MIN_SEGMENTS` segments, where it is the sequence success under
another name).  :func:`write_preregistration` writes it into the study folder (:data:`PREREG_FILE`)
before the first walk; ``--resume`` checks it with :func:`check_preregistration` and refuses a plan that
differs.  A folder with the file is a study of :data:`FORMAT` (verdicts v3): its verdicts are drawn at
``N`` walks only; at fewer, every look is an interim look, recorded in results.json as futility-only
(:func:`interim_reason`: no ``agrees`` or ``disagrees``).  A study stopped before its planned walks by a rule
that does not read the data (a budget) keeps a stop record (:data:`STOP_FILE`, :func:`stop_record`): the seeds
whose every walk was finished then, the time and the reason; its one look, at those walks, is its final look.
Folders without a plan (every study committed before 2026-12) are judged and redrawn as before.
"""

from __future__ import annotations

from pathlib import Path

from validation.live.config import (
    EQUIVALENCE_MARGINS,
    HEADLINE_COMPARISONS,
    HEADLINE_METRICS,
    PREREG_FILE,
    STOP_FILE,
    LiveConfig,
    LiveError,
)
from validation.live.level_shift import LEVEL_MARGIN
from validation.live.walks import walk_record_path
from validation.verdicts.agreement import ALPHA, OMEGA2_MAX

__all__ = ["PREREG_FILE", "STOP_FILE", "FORMAT", "MIN_SEGMENTS", "PLANNED_RESAMPLES", "segments_per_walk", "headline_exclusions",
           "preregistration", "write_preregistration", "read_preregistration", "check_preregistration",
           "interim_reason", "complete_seeds", "stop_record", "read_stop"]

#: The pre-registration's file in the study folder.
#: The plan's draws per stochastic method (k), present only when k is not 1.
DRAWS_KEY = "draws_per_stochastic_method"
#: The study format a pre-registered folder is judged by.
FORMAT = 3
#: Fewest segments per walk for the segment success rate to stay in the headline.
MIN_SEGMENTS = 3
#: Bootstrap resamples of a pre-registered study's verdicts: at 1000 no verdict of a 15-member family can be sure
#: of its Holm step (docs/verdicts.md, "Monte Carlo error of the headline").
PLANNED_RESAMPLES = 4000


def segments_per_walk(cfg: LiveConfig) -> int:
    """Segments of ``segment_pairs`` consecutive image pairs in one walk (one image per cycle; a walk shorter than a
    segment counts as one, as :func:`validation.ae_study.summary.segment_success` counts it)."""
    return max(1, (int(cfg.n_cycles) - 1) // int(cfg.segment_pairs))


def headline_exclusions(cfg: LiveConfig) -> dict[str, str]:
    """Headline metrics that leave the family for this configuration, with the reason."""
    n = segments_per_walk(cfg)
    if n >= MIN_SEGMENTS:
        return {}
    return {"segment_success_rate_tau100": (
        f"{n} segment(s) of {cfg.segment_pairs} pairs per walk of {cfg.n_cycles} cycles, fewer than {MIN_SEGMENTS}: "
        "the segment success rate is (nearly) the sequence success rate; it leaves the headline, reported outside "
        "the family")}


def preregistration(cfg: LiveConfig, replicates: int, *, draws: int | None = None,
                    n_resamples: int = PLANNED_RESAMPLES) -> dict:
    """The study's plan (see the module); ``draws``: seeds per walk and condition of a method that draws random
    numbers (``k``; None: the configuration's ``stochastic_seeds``), recorded only when it is not 1."""
    draws = int(cfg.stochastic_seeds if draws is None else draws)
    if replicates < 1 or draws < 1:
        raise LiveError(f"replicates and draws must be >= 1, got {replicates} and {draws}")
    excluded = headline_exclusions(cfg)
    metrics = [m for m in HEADLINE_METRICS if m not in excluded]
    return {"format": FORMAT, "metrics": metrics, "excluded_from_headline": excluded,
            "comparisons": list(HEADLINE_COMPARISONS),
            "family": f"Holm across {len(metrics)} metrics x {len(HEADLINE_COMPARISONS)} comparisons, each direction",
            "omega2_margin": OMEGA2_MAX, "level": ALPHA,
            "equivalence_margins": {m: EQUIVALENCE_MARGINS[m] for m in metrics if m in EQUIVALENCE_MARGINS},
            "level_shift_margin": LEVEL_MARGIN, "n_walks": len(cfg.scenes) * int(replicates),
            "scenes": list(cfg.scenes), "seeds": [int(cfg.seed) + k for k in range(int(replicates))],
            "methods": list(cfg.methods),
            "render": {**{k: getattr(cfg, k) for k in ("n_cycles", "width", "height", "spp", "denoise", "render_per",
                                                       "frame_rate_hz", "latency_frames")},
                       **({"emitter_weights": {k: float(v) for k, v in cfg.emitter_weights}}
                          if cfg.emitter_weights else {}),
                       **({"adaptive": cfg.adaptive} if cfg.adaptive else {})},
            **({DRAWS_KEY: draws} if draws != 1 else {}), "bootstrap_resamples": int(n_resamples),
            "monte_carlo": "each p's 99 % Monte Carlo interval (Wilson); a verdict whose Holm-adjusted p's interval "
                           "holds the level is undetermined",
            "looks": f"verdicts at {len(cfg.scenes) * int(replicates)} walks only; an earlier look is futility-only "
                     "(no agrees or disagrees)"}


def read_preregistration(out) -> dict | None:
    """The pre-registration of the study folder ``out``, or None (a study from before them)."""
    from emulator.io.files import read_results

    path = Path(out) / PREREG_FILE
    return read_results(path) if path.is_file() else None


def write_preregistration(out, prereg: dict) -> Path:
    """Write ``prereg`` into the study folder ``out`` before its first walk; an existing one is never overwritten
    (:func:`check_preregistration` says whether it is the same)."""
    from emulator.io.files import write_results

    path = Path(out) / PREREG_FILE
    if path.exists():
        check_preregistration(out, prereg)
        return path
    write_results(path, prereg, overwrite=False)
    return path


def check_preregistration(out, prereg: dict) -> None:
    """Refuse (:class:`~validation.live.config.LiveError`) a plan that differs from the one registered in ``out``,
    naming what differs; a folder without one (a study from before them) has nothing to check."""
    before = read_preregistration(out)
    if before is None:
        return
    def get(plan, k):  # a plan without the draws per stochastic method has one
        return plan.get(k, 1 if k == DRAWS_KEY else None)

    diff = sorted(k for k in set(before) | set(prereg) if get(before, k) != get(prereg, k))
    if diff:
        raise LiveError(f"{Path(out) / PREREG_FILE}: the study was pre-registered with other "
                        f"{', '.join(diff)}; a pre-registered plan is not changed (start a new study folder)")


def interim_reason(prereg: dict | None, n_walks: int, stop: dict | None = None, seeds=None) -> str | None:
    """Why a look at ``n_walks`` walks of a pre-registered study decides nothing (an interim look: futility only),
    or None (the planned walks are there, the walks the study was stopped at (``stop``, :func:`read_stop`), or the
    study was not pre-registered).  A stopped study is judged on the walks its record names only: other walks
    (their count, or ``seeds``, the seeds of the walks judged, where given) are refused, the planned size too."""
    if prereg is None:
        return None
    if stop is not None:
        if n_walks != int(stop["n_walks"]):
            raise LiveError(f"{STOP_FILE}: the study was stopped at {stop['n_walks']} walks, but {n_walks} are judged")
        if seeds is not None and sorted({int(s) for s in seeds}) != sorted(int(s) for s in stop["seeds"]):
            raise LiveError(f"{STOP_FILE}: the study was stopped with seeds {list(stop['seeds'])} judged, but the "
                            f"walks judged are of seeds {sorted({int(s) for s in seeds})}")
        return None
    if n_walks >= int(prereg["n_walks"]):
        return None
    return (f"interim look at {n_walks} of the {prereg['n_walks']} pre-registered walks: futility only, verdicts are "
            "drawn at the planned size")


def complete_seeds(out, prereg: dict) -> tuple[list[int], dict[int, list[str]]]:
    """(seeds whose every scene has a walk record, {seed: its finished scenes} of the seeds begun but not complete)
    of the pre-registered study in ``out`` (``replicates/seed<S>/walks/<scene>.json``)."""
    done, partial = [], {}
    for seed in prereg["seeds"]:
        exp = Path(out) / "replicates" / f"seed{int(seed)}"
        have = [s for s in prereg["scenes"] if walk_record_path(exp, s).is_file()]
        if len(have) == len(prereg["scenes"]):
            done.append(int(seed))
        elif have:
            partial[int(seed)] = have
    return done, partial


def stop_record(out, reason: str, *, when: str) -> dict:
    """The stop record of the pre-registered study in ``out``, stopped now (``when``: UTC, ISO 8601) for ``reason``
    (a rule that does not read the data): its final look judges the complete seeds (:func:`complete_seeds`); the
    walks of a seed begun but not complete are left out and named.  Refused (:class:`LiveError`) without a plan,
    without a reason, without a complete seed, or with every planned seed complete (the study is then judged at its
    planned size, no stop needed)."""
    prereg = read_preregistration(out)
    if prereg is None:
        raise LiveError(f"{Path(out) / PREREG_FILE}: not found; only a pre-registered study is stopped")
    if not str(reason).strip():
        raise LiveError("a stop needs its reason (the rule that stopped the study, e.g. its budget)")
    seeds, partial = complete_seeds(out, prereg)
    if not seeds:
        raise LiveError(f"{out}: no seed has every walk finished; nothing to judge")
    if len(seeds) == len(prereg["seeds"]):
        raise LiveError(f"{out}: every one of the {prereg['n_walks']} pre-registered walks is finished; the study is "
                        "judged at its planned size (--resume or --redraw), not stopped")
    n = len(seeds) * len(prereg["scenes"])
    return {"stopped": when, "reason": str(reason).strip(), "n_walks": n, "n_walks_planned": int(prereg["n_walks"]),
            "seeds": seeds, "left_out": {f"seed{k}": v for k, v in partial.items()},
            "look": f"final: {n} of the {prereg['n_walks']} pre-registered walks, the seeds complete at the stop"}


def read_stop(out) -> dict | None:
    """The stop record of the study folder ``out`` (:func:`stop_record`), or None (not stopped)."""
    from emulator.io.files import read_results

    path = Path(out) / STOP_FILE
    return read_results(path) if path.is_file() else None

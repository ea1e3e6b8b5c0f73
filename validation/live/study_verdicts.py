"""The verdicts of a study over its walks, and what a study folder keeps of them.

:func:`evidence` pools the walks of one experiment or of the replicates into the per-walk tables
(:func:`validation.live.evidence.walk_values`, in the walks' key order), stores them (``walks.csv``, and the
seeds' table of a stochastic method) and judges them with :func:`judge_study`: the verdicts
(:func:`validation.live.evidence.judge_metrics`), read against a pre-registration where the folder has one,
and with a folder the calibration, the power analysis (:func:`store_power`) and the methods' shares of the
residual.  :mod:`validation.live.experiment` calls it when it finishes or redraws a study.
"""

from __future__ import annotations

from pathlib import Path

from emulator.io.files import write_results
from validation.live.config import LiveConfig
from validation.live.evidence import (
    WALKS_TABLE,
    judge_metrics,
    pilot_reason,
    store_calibration,
    store_walks_table,
    table_refusal,
    walk_labels,
    walk_values,
    walks_table_csv,
)
from validation.live.final_checks import final_checks
from validation.live.preregistration import PREREG_FILE, STOP_FILE, interim_reason, read_preregistration, read_stop
from validation.live.seeds import SEEDS_TABLE, loop_names, split_seeds, store_seeds_table, store_shares
from validation.live.table_check import canonical_order
from validation.verdicts.plasmode import STUDIES

__all__ = ["POWER_FILE", "evidence", "table_refusals", "judge_study", "store_power"]


def evidence(cfg: LiveConfig, records: list[dict], power_seeds: int = 100, folder=None,
             calibration_studies: int | None = None) -> dict:
    """results.json's replicated verdicts (:func:`validation.live.evidence.judge_metrics`) over the walks of
    ``records`` (one experiment, or the replicates of :func:`validation.live.experiment.run_replicated`); with ``folder``, the per-walk
    table is stored there (:func:`validation.live.evidence.store_walks_table`; the walks in their key's order,
    :func:`validation.live.table_check.canonical_order`, whatever the records' order), and the calibration
    (``calibration_studies`` plasmode studies; :func:`validation.live.evidence.store_calibration`)."""
    walks, tables, per_seed = _walk_tables(cfg, records)
    out = {"walks": walks, "n_walks": len(walks)}
    if per_seed is not None:
        out["seeds_table"] = None if folder is None else store_seeds_table(folder, walks, *per_seed)
    if tables and folder is not None:
        out["walks_table"] = store_walks_table(folder, walks, tables, cfg.methods)
    if tables:
        out.update(judge_study(cfg, tables, cfg.methods, walks, folder, power_seeds, calibration_studies))
        out["n_walks"] = len(walks)
    else:
        out.update({"metrics": {}, "reason": "no benchmark metrics in this experiment (metrics off)"})
    return out


def _walk_tables(cfg: LiveConfig, records: list[dict]) -> tuple[list[str], dict, tuple | None]:
    """(walks, tables, (seed names, seed tables) or None): the per-walk tables of ``records`` in the walks' key
    order, a stochastic method's k seeds (k > 1) split off into their own tables."""
    names = loop_names(cfg.methods, cfg.stochastic_seeds)  # k > 1: each seed of a stochastic method, then the mean
    walks, tables = walk_values(records, names)
    walks, _, tables = canonical_order(walks, names, tables, scenes=cfg.scenes, method_order=names)
    if tables and cfg.stochastic_seeds > 1:
        tables, seed_names, seed_tables = split_seeds(tables, names, cfg.methods, cfg.stochastic_seeds)
        return walks, tables, (seed_names, seed_tables)
    return walks, tables, None


def table_refusals(folder, cfg: LiveConfig, records: list[dict]) -> list[str]:
    """Why :func:`evidence` would refuse to store the tables of ``records`` in ``folder`` (a ``walks.csv`` or seeds
    table there whose rows differ, :func:`validation.live.evidence.table_refusal`), computed without writing: a
    step that must not half-happen (a study's stop) checks it first."""
    walks, tables, per_seed = _walk_tables(cfg, records)
    texts = {} if not tables else {WALKS_TABLE: walks_table_csv(walks, tables, cfg.methods)}
    if per_seed is not None:
        texts[SEEDS_TABLE] = walks_table_csv(walks, per_seed[1], per_seed[0])
    return [r for name, text in texts.items() if (r := table_refusal(Path(folder) / name, text)) is not None]


def judge_study(cfg: LiveConfig, tables: dict, methods, walks, folder, power_seeds: int,
                calibration_studies: int | None) -> dict:
    """The verdicts over ``walks`` (:func:`validation.live.evidence.judge_metrics`); with ``folder``, the
    calibration and the power analysis are also stored there (their file names in the result).  A pre-registered
    folder is judged by its plan: at its final look (the planned walks, or those its stop record names) with the
    Monte Carlo rule and the final look's checks (:func:`validation.live.final_checks.final_checks`, results.json's
    ``final_checks``), at any other look for futility only."""
    prereg = None if folder is None else read_preregistration(folder)
    stop = None if prereg is None else read_stop(folder)
    interim = interim_reason(prereg, len(walks), stop, seeds=walk_labels(walks)[1])
    kw = {} if prereg is None else {"n_resamples": int(prereg["bootstrap_resamples"]),
                                    "headline_exclusions": prereg["excluded_from_headline"], "monte_carlo_rule": True}
    out = judge_metrics(tables, methods, seed=cfg.seed, power=power_seeds > 0, power_seeds=power_seeds, walks=walks,
                        pilot=pilot_reason(cfg) or interim, calibration_studies=calibration_studies, **kw)
    if prereg is not None:  # a pre-registered study (format 3): verdicts at the planned walks only
        look = "interim: futility only" if interim is not None else "final" if stop is None else stop["look"]
        out["preregistration"] = {"file": PREREG_FILE, "format": prereg["format"], "n_walks_planned": prereg["n_walks"],
                                  "look": look, "reason": interim,
                                  **({} if stop is None else {"stop": {"file": STOP_FILE, "stopped": stop["stopped"],
                                                                       "reason": stop["reason"]}})}
        if interim is None and not pilot_reason(cfg):
            out["final_checks"] = final_checks(tables, walks, methods, prereg=prereg, seed=cfg.seed,
                                               calibration_studies=calibration_studies, plasmode_default=STUDIES)
    if folder is not None:
        out["calibration_file"] = store_calibration(folder, out["calibration"])
        out["power_file"] = store_power(folder, out)
        if prereg is not None or cfg.stochastic_seeds > 1:  # new folders: the methods' shares of the residual
            out["residual_shares_file"] = store_shares(folder, cfg, tables, methods)
    return out


#: The power analysis of a study folder (per metric what the study's size decides, per undetermined headline
#: verdict the walks that would decide it).
POWER_FILE = "power.json"


def store_power(folder, results: dict) -> str:
    """Write :data:`POWER_FILE` into ``folder`` from results.json's ``power`` and the headline's walks to decide;
    returns its name (recomputed from the same walks, it is the same bytes)."""
    walks_to_decide = {label: {m: r["walks_to_decide"] for m, r in (c.get("metrics") or {}).items()
                               if "walks_to_decide" in r}
                       for label, c in (results.get("headlines") or {}).get("comparisons", {}).items()}
    write_results(Path(folder) / POWER_FILE, {"n_walks": results.get("n_walks"), "power": results.get("power", {}),
                                              "walks_to_decide": walks_to_decide})
    return POWER_FILE

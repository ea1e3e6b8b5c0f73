"""Methods that draw random numbers, judged as distributions: k seeds per walk and condition.

A method whose class declares a ``seed_option`` (:func:`emulator.autoexposure.builtin.seed_option`; Kim, whose
GP restarts are random draws) is one draw of a distribution per run.  With ``stochastic_seeds`` k > 1
(:class:`~validation.live.config.LiveConfig`, ``--stochastic-seeds``), every loop of a walk (every live and
emulated condition) runs, beside the method itself (its default seed 0), k - 1 more instances of it named
``<method>@seed<s>`` (:func:`seeded_name`) with seeds s = 1 .. k - 1: the same k seeds in every condition.  Each
instance has its own camera in its loop, so the other methods' runs are what they are without them.

The verdicts' per-walk table (``walks.csv``) holds, under the method's own name, the mean over its k seeds per
walk and metric (:func:`split_seeds`; a metric missing for one seed is missing for the walk); the per-seed rows
are kept in :data:`SEEDS_TABLE` (the seed-0 run named ``<method>@seed0``), from which :func:`seed_noise` and
the residual shares (:func:`residual_shares`) are recomputed.  The per-cycle comparisons, trajectories and
contact sheets show the seed-0 run.  k = 1 is the study as it was (no key, no file).
"""

from __future__ import annotations

import math

import numpy as np
from validation.live.config import COMPARISONS, LiveError
from validation.live.evidence import parse_walks_table, store_walks_table
from validation.live.headline import with_derived

__all__ = ["SEEDS_TABLE", "SEED_MARK", "stochastic_methods", "seeded_name", "loop_names", "loop_items",
           "split_seeds", "residual_shares", "seed_noise", "recommended_seeds", "SHARES_FILE", "store_seeds_table",
           "read_seeds_table", "shares_summary", "shares_by_seeds", "store_shares"]

#: The per-seed rows of the stochastic methods in a study folder (the layout of ``walks.csv``).
SEEDS_TABLE = "walks_seeds.csv"
#: Between a method's name and its seed in the name of one of its seeded instances.
SEED_MARK = "@seed"


def stochastic_methods(methods) -> list[str]:
    """The methods of ``methods`` that declare the option seeding their random draws."""
    from emulator.autoexposure.builtin import seed_option

    return [m for m in methods if isinstance(m, str) and seed_option(m) is not None]


def seeded_name(method: str, seed: int) -> str:
    """The name of ``method``'s instance with seed ``seed`` in a walk's loops (``kim@seed2``)."""
    return f"{method}{SEED_MARK}{int(seed)}"


def loop_names(methods, k: int) -> list[str]:
    """Every method a walk's loops run: ``methods``, then each stochastic one's seeds 1 .. k - 1."""
    return list(methods) + [seeded_name(m, s) for m in stochastic_methods(methods) for s in range(1, int(k))]


def loop_items(methods, k: int, mode: str = "paper") -> list:
    """What the loops are given for :func:`loop_names`: the names of ``methods`` (the stochastic ones at their
    default seed, 0) and a fresh instance of each stochastic method per seed 1 .. k - 1 (built like a method
    by name, ``range_ms=None``: the loop clamps), named :func:`seeded_name`.  Call it once per loop."""
    from emulator.autoexposure.builtin import make_method, seed_option

    items: list = list(methods)
    for m in stochastic_methods(methods):
        for s in range(1, int(k)):
            inst = make_method(m, mode=mode, range_ms=None, **{seed_option(m): s})
            inst.name = seeded_name(m, s)
            items.append(inst)
    return items


def split_seeds(tables: dict, names, methods, k: int) -> tuple[dict, list[str], dict]:
    """``(mean tables, seed names, seed tables)`` of ``tables`` ({run: {metric: (walks, len(names))}} over the
    loops' :func:`loop_names`): the mean tables over ``methods`` (a stochastic method's column the mean over its k
    seeds, NaN where one seed has none), and its per-seed columns named ``<method>@seed<s>``, s = 0 .. k - 1."""
    names = list(names)
    groups = {m: [names.index(m)] + [names.index(seeded_name(m, s)) for s in range(1, int(k))]
              for m in stochastic_methods(methods)}
    seed_names = [seeded_name(m, s) for m in groups for s in range(int(k))]
    seed_cols = [c for cols in groups.values() for c in cols]
    means, seeds = {}, {}
    for run, per in tables.items():
        means[run], seeds[run] = {}, {}
        for metric, t in per.items():
            t = np.asarray(t, dtype=np.float64)
            cols = [t[:, groups[m]].mean(axis=1) if m in groups else t[:, names.index(m)] for m in methods]
            means[run][metric] = np.stack(cols, axis=1) if cols else np.zeros((t.shape[0], 0))
            seeds[run][metric] = t[:, seed_cols]
    return means, seed_names, seeds


def residual_shares(tables: dict, methods, comparisons: dict, metrics=None) -> dict:
    """Per comparison (label -> (reference run, compared run)) and metric, each method's share of the residual
    (walk x method interaction) variance of compared minus reference: ``d`` = compared - reference over the
    walks complete in both, double-centred (walk and method means removed), and per method its sum of squares
    over the total; with the residual SD (root mean square of the residual) of all methods and of the
    non-stochastic ones.  A comparison whose runs are missing is left out; a total of 0 gives None."""
    stoch = set(stochastic_methods(methods))
    others = [k for k, m in enumerate(methods) if m not in stoch]
    out: dict = {}
    for label, (ref, cmp_) in comparisons.items():
        if ref not in tables or cmp_ not in tables:
            continue
        for metric in (metrics or tables[ref]):
            if metric not in tables[ref] or metric not in tables[cmp_]:
                continue
            L, E = np.asarray(tables[ref][metric], float), np.asarray(tables[cmp_][metric], float)
            ok = np.all(np.isfinite(L) & np.isfinite(E), axis=1)
            d = (E - L)[ok]
            entry = {"n_walks": int(ok.sum()), "share": {m: None for m in methods}, "residual_sd": None,
                     "residual_sd_others": None}
            if d.shape[0] >= 2 and d.shape[1] >= 2:
                r = d - d.mean(axis=0) - d.mean(axis=1, keepdims=True) + d.mean()
                ss = (r ** 2).sum(axis=0)
                tot = float(ss.sum())
                if tot > 0:
                    entry["share"] = {m: float(ss[k] / tot) for k, m in enumerate(methods)}
                entry["residual_sd"] = float(math.sqrt((r ** 2).mean()))
                if others:
                    entry["residual_sd_others"] = float(math.sqrt((r[:, others] ** 2).mean()))
            out.setdefault(label, {})[metric] = entry
    return out


def seed_noise(seed_tables: dict, seed_names, methods, k: int) -> dict:
    """Per stochastic method, run and metric: the seed-to-seed SD (pooled within walks: the root of the mean over
    the walks complete in every seed of the variance over the k seeds, ddof 1) and its SD in the per-walk mean of k
    seeds (divided by sqrt(k)); None with fewer than 2 seeds or no complete walk."""
    seed_names = list(seed_names)
    out: dict = {}
    for m in stochastic_methods(methods):
        cols = [seed_names.index(seeded_name(m, s)) for s in range(int(k))]
        for run, per in seed_tables.items():
            for metric, t in per.items():
                x = np.asarray(t, float)[:, cols]
                x = x[np.all(np.isfinite(x), axis=1)]
                sd = float(math.sqrt(x.var(axis=1, ddof=1).mean())) if x.shape[0] and int(k) >= 2 else None
                out.setdefault(m, {}).setdefault(run, {})[metric] = {
                    "n_walks": int(x.shape[0]), "seed_sd": sd,
                    "seed_sd_of_mean": None if sd is None else sd / math.sqrt(int(k))}
    return out


def recommended_seeds(seed_sd: float | None, residual_sd_others: float | None, k_max: int = 64) -> int | None:
    """The smallest k whose seed noise in the per-walk mean (``seed_sd / sqrt(k)``) is below the other methods'
    residual SD; None where either is unknown or the other methods have no residual, ``k_max + 1`` past ``k_max``."""
    if seed_sd is None or residual_sd_others is None or residual_sd_others <= 0:
        return None
    k = math.floor((seed_sd / residual_sd_others) ** 2) + 1  # k > (sd / residual)^2, then the rounding checked
    while k > 1 and seed_sd / math.sqrt(k - 1) < residual_sd_others:
        k -= 1
    while seed_sd / math.sqrt(k) >= residual_sd_others:
        k += 1
    return min(k, int(k_max) + 1)


#: The residual shares of a study folder (new folders only: pre-registered, or with k > 1).
SHARES_FILE = "residual_shares.json"


def store_seeds_table(folder, walks, seed_names, seed_tables) -> str:
    """Write the per-seed rows (:data:`SEEDS_TABLE`, the layout of ``walks.csv``); returns its name."""
    return store_walks_table(folder, walks, seed_tables, seed_names, name=SEEDS_TABLE)


def read_seeds_table(folder) -> tuple[list[str], list[str], dict] | None:
    """(walks, seed names, seed tables) of a folder's :data:`SEEDS_TABLE`, or None where it has none."""
    from pathlib import Path

    from emulator.io.files import read_text

    path = Path(folder) / SEEDS_TABLE
    if not path.is_file():
        return None
    return parse_walks_table(read_text(path, LiveError), str(path))


def shares_summary(cfg, tables: dict, methods, folder=None) -> dict:
    """What :data:`SHARES_FILE` holds: per comparison and metric each method's share of the residual variance
    (:func:`residual_shares`, RPE rank derived), and with k > 1 (the folder's :data:`SEEDS_TABLE`) each stochastic
    method's seed noise (:func:`seed_noise`) and per comparison and metric the k that brings its seed noise in
    the per-walk mean below the other methods' residual SD (:func:`recommended_seeds`; the seed SD of a comparison
    is the root mean square of its two runs')."""
    k = int(cfg.stochastic_seeds)
    out = {"stochastic_methods": stochastic_methods(methods), "seeds_per_walk": k,
           "definition": "share: a method's sum of squares of the double-centred (walk x method) residual of "
                         "compared minus reference over the total, walks complete in both; residual_sd: its root "
                         "mean square (of all methods, and of the non-stochastic ones)",
           "shares": residual_shares(with_derived(tables), list(methods), COMPARISONS)}
    seeds = read_seeds_table(folder) if folder is not None and k > 1 else None
    if seeds is None:
        return out
    _, seed_names, seed_tables = seeds
    noise = seed_noise(seed_tables, seed_names, methods, k)
    out["seeds_table"] = SEEDS_TABLE
    out["seed_noise"] = noise
    rec: dict = {}
    for m, per_run in noise.items():
        for label, (ref, cmp_) in COMPARISONS.items():
            for metric, entry in out["shares"].get(label, {}).items():
                sds = [per_run.get(r, {}).get(metric, {}).get("seed_sd") for r in (ref, cmp_)]
                sd = math.sqrt(sum(s * s for s in sds) / 2) if all(s is not None for s in sds) else None
                rec.setdefault(m, {}).setdefault(label, {})[metric] = {
                    "seed_sd": sd, "residual_sd_others": entry["residual_sd_others"],
                    "k": recommended_seeds(sd, entry["residual_sd_others"])}
    out["recommended_seeds"] = rec
    out["share_by_seeds"] = shares_by_seeds(tables, methods, seed_names, seed_tables, k)
    return out


def shares_by_seeds(tables: dict, methods, seed_names, seed_tables: dict, k: int) -> dict:
    """Per stochastic method, comparison and metric: its residual share (:func:`residual_shares`, RPE rank derived)
    when its per-walk value is the mean of its first j seeds, j = 1 .. k (j = k: the study's own table)."""
    methods, seed_names = list(methods), list(seed_names)
    out: dict = {}
    for m in stochastic_methods(methods):
        col = methods.index(m)
        for j in range(1, int(k) + 1):
            cols = [seed_names.index(seeded_name(m, s)) for s in range(j)]
            part = {run: {metric: t.copy() for metric, t in per.items()} for run, per in tables.items()}
            for run, per in part.items():
                for metric, t in per.items():
                    if run in seed_tables and metric in seed_tables[run]:
                        t[:, col] = np.asarray(seed_tables[run][metric], float)[:, cols].mean(axis=1)
            for label, per in residual_shares(with_derived(part), methods, COMPARISONS).items():
                for metric, e in per.items():
                    out.setdefault(m, {}).setdefault(label, {}).setdefault(metric, []).append(e["share"][m])
    return out


def store_shares(folder, cfg, tables: dict, methods) -> str:
    """Write :func:`shares_summary` as :data:`SHARES_FILE` into ``folder``; returns its name."""
    from pathlib import Path

    from emulator.io.files import to_jsonable, write_results

    write_results(Path(folder) / SHARES_FILE, to_jsonable(shares_summary(cfg, tables, methods, folder)))
    return SHARES_FILE

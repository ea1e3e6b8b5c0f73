"""The walks table read strictly, in one order whatever its rows' order.

``--redraw`` recomputes a study's verdicts from ``walks.csv`` alone; these helpers make that
recomputation a function of the table's *content*:

* :func:`check_walks_table` refuses what :func:`validation.live.evidence.walks_table_csv` would
  not write: a header in another order, a cell that is not the shortest round-trip text of a
  finite float (``nan``, ``inf``, ``1.50``) or empty, a scene or seed column that does not
  match its walk's name, and a walk or a method missing from or extra to the study's record
  (``results.json``'s configuration, replicates and failed walks), naming the line;
* :func:`canonical_order` puts the walks in their key's order (the seed as text, then the
  scene's place in the configuration: the order the committed studies hold them in) and the methods in the
  configuration's order, before any resampling, so that the same rows in another order give
  the same bytes.
"""

from __future__ import annotations

import math

import numpy as np
from validation.live.config import PREREG_FILE, LiveError
from validation.live.evidence import WALKS_TABLE, parse_walks_table

__all__ = ["record_walks", "check_walks_table", "walk_key", "canonical_order", "read_folder_table"]

_HEAD = ("walk", "scene", "seed", "method", "condition")


def record_walks(results: dict) -> list[str]:
    """The walks a study folder's record says it judged: every scene of the configuration on every replicate's
    seed (``replicates/seed<S>``; the configuration's seed without replicates), less its failed walks."""
    cfg = results["config"]
    reps = results.get("replicates") or []
    seeds = [int(str(r).rpartition("seed")[2]) for r in reps] if reps else [int(cfg["seed"])]
    failed = {f.get("walk") for f in results.get("failed_walks") or []}
    return [w for s in seeds for w in (f"{scene}/seed{s}" for scene in cfg["scenes"]) if w not in failed]


def _writer_cell(v: str) -> bool:
    """Whether ``v`` is a cell the writer writes: empty, or the shortest round-trip text of a finite float."""
    if v == "":
        return True
    try:
        x = float(v)
    except ValueError:
        return False
    return math.isfinite(x) and repr(x) == v


def check_walks_table(text: str, name: str, *, metrics, methods=None, walks=None) -> None:
    """Refuse (:class:`~validation.live.config.LiveError`, naming ``name`` and the line) a walks table that the
    writer would not have written for this study.

    Parameters
    ----------
    text : str
        The table's text.
    name : str
        Its name in messages.
    metrics : sequence of str
        The metric columns, in the writer's order.
    methods, walks : sequence of str, optional
        The study's record: every method of the configuration and every walk it judged; the table must
        hold exactly these (an extra one names its first line, a missing one is named).
    """
    rows = text.splitlines()
    head = ",".join(_HEAD + tuple(metrics))
    if not rows or rows[0] != head:
        raise LiveError(f"{name}: line 1 must be {head}, got {rows[0] if rows else 'an empty file'!r}")
    seen_walks, seen_methods = set(), set()
    for n, row in enumerate(rows[1:], start=2):
        f = row.split(",")
        if len(f) != len(_HEAD) + len(metrics):
            raise LiveError(f"{name}: line {n} has {len(f)} fields, the header {len(_HEAD) + len(metrics)}")
        bad = [c for c in f[len(_HEAD):] if not _writer_cell(c)]
        if bad:
            raise LiveError(f"{name}: line {n}: cell {bad[0]!r} is not as the writer writes a value (the shortest "
                            "round-trip text of a finite number, or empty where there is none)")
        scene, _, seed = f[0].rpartition("/seed")
        if f[1] != scene or f[2] != seed or not seed.isdigit() or str(int(seed)) != seed:
            raise LiveError(f"{name}: line {n}: scene {f[1]!r} and seed {f[2]!r} do not match walk {f[0]!r}")
        if walks is not None and f[0] not in walks:
            raise LiveError(f"{name}: line {n}: walk {f[0]} is not one of the study's walks (its record: results.json)")
        if methods is not None and f[3] not in methods:
            raise LiveError(f"{name}: line {n}: method {f[3]} is not one of the study's methods "
                            f"({', '.join(methods)})")
        seen_walks.add(f[0])
        seen_methods.add(f[3])
    for label, want, seen in (("walk", walks, seen_walks), ("method", methods, seen_methods)):
        missing = [x for x in (want or ()) if x not in seen]
        if missing:
            raise LiveError(f"{name}: no row for {label} {missing[0]}, which the study's record holds"
                            + (f" ({len(missing)} missing)" if len(missing) > 1 else ""))


def walk_key(walk: str, scenes=()) -> tuple:
    """The sort key of a walk name ``<scene>/seed<S>``: its seed as text (as the replicate folders sort, ``seed10``
    before ``seed2``: the order of every study written so far), then its scene's place in ``scenes`` (scenes not
    there after them, by name)."""
    scene, _, seed = str(walk).rpartition("/seed")
    order = list(scenes)
    return seed, (order.index(scene) if scene in order else len(order)), scene


def canonical_order(walks, methods, tables: dict, *, scenes=(), method_order=None):
    """``(walks, methods, tables)`` with the walks sorted by :func:`walk_key` and the methods in ``method_order``
    (the configuration's; sorted by name where None); every table's rows and columns follow, the runs by name."""
    walks, methods = list(walks), list(methods)
    w = sorted(range(len(walks)), key=lambda i: walk_key(walks[i], scenes))
    if method_order is None:
        m = sorted(range(len(methods)), key=lambda k: methods[k])
    else:
        rank = {x: i for i, x in enumerate(method_order)}
        m = sorted(range(len(methods)), key=lambda k: (rank.get(methods[k], len(rank)), methods[k]))
    wi, mi = np.asarray(w, dtype=np.intp), np.asarray(m, dtype=np.intp)
    out = {run: {metric: np.asarray(t)[np.ix_(wi, mi)] for metric, t in tables[run].items()} for run in sorted(tables)}
    return [walks[i] for i in w], [methods[k] for k in m], out


def read_folder_table(folder) -> tuple[list[str], list[str], dict]:
    """(walks, methods, ``{run: {metric: (walks, methods)}}``) of a study folder's ``walks.csv``, as written (the
    analyses that read a folder without writing into it); a pre-registered folder is refused (those analyses do
    not apply its plan yet)."""
    from pathlib import Path

    from emulator.io.files import read_text

    if (Path(folder) / PREREG_FILE).is_file():  # its family leaves metrics out and resamples 4000 times
        raise LiveError(f"{folder}: a pre-registered study ({PREREG_FILE}); these analyses judge the headline family "
                        f"as the studies before pre-registration did and would not match its results.json, whose "
                        f"final look holds them by its plan (final_checks, report.md)")
    path = Path(folder) / WALKS_TABLE
    return parse_walks_table(read_text(path, LiveError), str(path))

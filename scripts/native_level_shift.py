"""Where native emulation's matches go: the emulated-native minus native-live matches of each (walk,
method), split by how often a neighbour frame served the benchmarked frames.

    python scripts/native_level_shift.py STUDY_DIR [STUDY_DIR ...]

Reads every walk record an ``exposim validate live`` study wrote (``STUDY_DIR/walks/*.json``, and
``STUDY_DIR/replicates/*/walks/*.json`` for a study of replicates).  A walk's benchmarked frames are the
first shot of each recorder cycle (the frames ``bench features`` reads at native rate); for each
(walk, method) it takes the share of those frames a neighbour served (``native_emulation``
``source_offset`` not 0), the difference in median matches and in mean SIFT keypoints per image between
the emulated-native and the live-native runs (``benchmarks.features``).  Printed: the mean differences
over all pairs, by neighbour share (none, some, most) and by scene, with a bootstrap 95 % interval over
pairs (``emulator.core.stats.statistic_interval``, 2000 resamples, seed 0), and the correlation of the
matches difference with the share.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from emulator.core.stats import statistic_interval

SHOTS_PER_CYCLE = 6


def walk_files(folders) -> list[Path]:
    files = []
    for folder in folders:
        folder = Path(folder)
        found = sorted(folder.glob("walks/*.json")) + sorted(folder.glob("replicates/*/walks/*.json"))
        if not found:
            raise SystemExit(f"native_level_shift: no walk records under {folder} (walks/*.json)")
        files += found
    return files


def pairs(files) -> list[dict]:
    out = []
    for path in files:
        d = json.loads(path.read_text())
        feats = d.get("benchmarks", {}).get("features", {})
        if "emulated-native" not in feats or "live-native" not in feats:
            raise SystemExit(f"native_level_shift: {path} has no emulated-native and live-native features")
        for method, ne in d["native_emulation"].items():
            offsets = ne["source_offset"]
            bench = offsets[::SHOTS_PER_CYCLE]
            em, live = feats["emulated-native"]["methods"][method], feats["live-native"]["methods"][method]
            out.append({"scene": d["scene"], "method": method,
                        "neighbour_share": float(np.mean([o != 0 for o in bench])),
                        "matches": float(em["median_matches"]) - float(live["median_matches"]),
                        "keypoints": float(np.mean(em["n_keypoints"])) - float(np.mean(live["n_keypoints"]))})
    return out


def mean_ci(values) -> str:
    """The mean with its bootstrap 95 % interval over the pairs (:func:`emulator.core.stats.statistic_interval`)."""
    r = statistic_interval(values, "mean", n_resamples=2000, seed=0)
    if r["estimate"] is None:
        return "-"
    ci = "[-]" if r["ci95"] is None else f"[{r['ci95'][0]:.1f}, {r['ci95'][1]:.1f}]"
    return f"{r['estimate']:.1f} {ci} (n {r['n']})"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("studies", nargs="+", type=Path)
    args = ap.parse_args(argv)
    rows = pairs(walk_files(args.studies))
    share = np.array([r["neighbour_share"] for r in rows])
    matches = np.array([r["matches"] for r in rows])
    print(f"{len(rows)} (walk, method) pairs; emulated native minus native live, mean [95 %]")
    print(f"  all: matches {mean_ci(matches)}; keypoints per image "
          f"{mean_ci([r['keypoints'] for r in rows])}")
    for label, sel in (("no benchmarked frame from a neighbour", share == 0),
                       ("some (under half)", (share > 0) & (share < 0.5)),
                       ("half or more", share >= 0.5)):
        sub = [r for r, s in zip(rows, sel) if s]
        print(f"  {label}: matches {mean_ci([r['matches'] for r in sub])}; keypoints "
              f"{mean_ci([r['keypoints'] for r in sub])}")
    for scene in sorted({r["scene"] for r in rows}):
        sub = [r for r in rows if r["scene"] == scene]
        print(f"  {scene}: matches {mean_ci([r['matches'] for r in sub])}; neighbour share "
              f"{np.mean([r['neighbour_share'] for r in sub]):.2f}")
    if share.std() > 0 and matches.std() > 0:
        r = np.corrcoef(matches, share)[0, 1]
        print(f"  correlation of the matches difference with the neighbour share: {r:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

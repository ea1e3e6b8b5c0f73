"""What holds native emulation's image error back, on walks ``exposim validate live`` recorded.

    python scripts/native_terms.py STUDY_DIR [--weights 0,0.25,0.5,1,2,4] [--limits 0.01,0.05]

For every walk of the study (``STUDY_DIR/datasets/<scene>``, renders from the cache), the native
live loop is run again (every frame, the study's seed and noise), and each frame is emulated at the
exposure the live camera applied (open loop), for each weight of the native selector's motion
term, with and without the warp.  Printed per weight: the median RMSE (% of the DN range) over
frames and methods, the share of frames a neighbour served; over the frames a neighbour served, the
median with the warp, without it, and of the frame's own bracket at the same exposure over the pixels
both can give (the error of that instant with no motion to undo); and the median error split by
source offset (0: the frame's own bracket).  The noise floor is the median over frames served by their
own bracket at ratio 1 (two captures of one instant differing only by their noise).
"""

from __future__ import annotations

import argparse
import json
from collections import defaultdict
from pathlib import Path

import numpy as np


def main(argv=None) -> int:
    import scenes
    from emulator.io.borealhdr import load_sequence, sequence_response
    from emulator.playback import RunConfig
    from scenes.walkshots import walk_radiance
    from synth.sequence import load_camera
    from validation.live.config import config_from_dict
    from validation.live.loops import DatasetRadiance
    from validation.live.native import native_emulation_summary, native_image_errors, native_rate_loop

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("study", type=Path)
    p.add_argument("--weights", default="0,0.25,0.5,1,2,4")
    p.add_argument("--limits", default="0.01", help="the selector's clipping margins to try (fractions)")
    args = p.parse_args(argv)
    study = json.loads((args.study / "study.json").read_text())
    cfg = config_from_dict(study.get("config", study))
    weights = [(float(w), float(s)) for w in args.weights.split(",") for s in args.limits.split(",")]
    names = list(cfg.methods)
    pooled: dict = defaultdict(lambda: defaultdict(list))
    per_walk: dict = defaultdict(dict)
    for scene_name in cfg.scenes:
        ds = args.study / "datasets" / scene_name
        seq = load_sequence(ds)
        response = sequence_response(seq)
        camera = load_camera(ds)
        scene = scenes.get_scene(scene_name, seed=cfg.seed, **cfg.scene_parameters(scene_name))
        radiance = walk_radiance(ds, scene) or DatasetRadiance(ds)
        every = list(native_rate_loop(seq, radiance, camera, names, seed=cfg.seed, noise=cfg.capture_noise,
                                      initial_ms=cfg.initial_ms, response=response, every_frame=True,
                                      latency_frames=cfg.latency_frames))
        config = RunConfig(initial_ms=cfg.initial_ms, rate="native", latency_frames=cfg.latency_frames)
        for w in weights:
            errs = native_image_errors(seq, every, response, config, names, motion_stops_per_frame=w[0],
                                       saturation_limit=w[1])
            per_walk[w][scene_name] = errs
            for m in names:
                d = errs[m]
                for rw, ro, ru, ra, off in zip(d["rmse_percent"], d["rmse_percent_own_bracket"],
                                               d["rmse_percent_unwarped"], d["rmse_percent_all"], d["source_offset"]):
                    if off != 0:
                        pooled[w]["nb warped"].append(rw)
                        pooled[w]["nb own"].append(ro)
                        pooled[w]["nb unwarped"].append(ru)
                    pooled[w]["warped"].append(rw)
                    pooled[w]["all"].append(ra)
                    pooled[w]["unwarped"].append(ru)
                    pooled[w][f"offset {off:+d}"].append(rw)
                    pooled[w]["neighbour"].append(off != 0)
    print(f"study {args.study} ({cfg.width}x{cfg.height}, {len(cfg.scenes)} walk(s), noise {cfg.capture_noise})")
    for w in weights:
        d = pooled[w]
        by_offset = ", ".join(f"{k[7:]}: {np.median(v):.2f} (n={len(v)})" for k, v in sorted(
            d.items(), key=lambda kv: kv[0]) if k.startswith("offset"))
        nb = (f"{np.median(d['nb warped']):.2f} / {np.median(d['nb unwarped']):.2f} / {np.median(d['nb own']):.2f}"
              if d["nb warped"] else "-")
        print(f"weight {w[0]:g}, clipping margin {w[1]:g}: median error {np.median(d['warped']):.2f} % warped, "
              f"{np.median(d['unwarped']):.2f} % unwarped, {np.median(d['all']):.2f} % over every pixel in view, "
              f"neighbour served {np.mean(d['neighbour']):.2f} (on those frames warped / unwarped / own bracket: "
              f"{nb} %); by offset {by_offset}")
        summary = native_emulation_summary(per_walk[w], names, seed=cfg.seed)
        nbf = summary["neighbour_frames"]
        print("  over walks, mean of each walk's median [bootstrap 95 %]: " + "; ".join(
            f"{label} {_iv(summary_d)}" for label, summary_d in (
                ("error %", summary["median_image_rmse_percent"]),
                ("unwarped %", summary["median_image_rmse_percent_unwarped"]),
                ("warp's share, every frame", summary["warp_cut_fraction"]),
                ("a perfect warp's share, every frame", summary["warp_cut_fraction_perfect_warp"]),
                ("neighbour frames: error %", nbf["median_image_rmse_percent"]),
                ("unwarped %", nbf["median_image_rmse_percent_unwarped"]),
                ("own bracket %", nbf["median_image_rmse_percent_own_bracket"]),
                ("warp's share", summary["warp_cut_fraction_neighbour_frames"]),
                ("warp's share of the excess over the own bracket",
                 summary["warp_cut_fraction_of_excess_neighbour_frames"]))))
    return 0


def _iv(d: dict) -> str:
    if d["estimate"] is None:
        return "-"
    return f"{d['estimate']:.2f}" + (f" [{d['ci95'][0]:.2f}, {d['ci95'][1]:.2f}]" if d["ci95"] else "")


if __name__ == "__main__":
    raise SystemExit(main())

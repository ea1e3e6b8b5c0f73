"""Issue 21 item 6: the in-situ noise fit on a synthetic recording with the realistic walk and blur.

Usage::

    python scripts/noise_fit_synthetic.py OUT_DIR [--size 320x200] [--cycles 6] [--spp 4]
        [--render-per cycle|shot] [--scene forest_summer] [--still-px 2.5] [--boot 200]

Synthesises a one-camera recording of ``scene`` on the ``borealhdr`` walk with exposure-time
blur (:func:`scenes.synthesize.synthesize`, known camera: synth's BorealHDR preset), fits the
in-situ noise model on its bracket triples (:func:`emulator.noise.estimate_noise_model`), and
prints as JSON the true gain, the pooled fit and the fit per exposure stratum and Bayer phase
(:func:`emulator.noise.insitu.noise_strata`: formal and bootstrap SE over groups), each as a
ratio to the truth; then the same on the groups the gyro calls still (``--still-px``).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path


def _ratios(strata: dict, truth: float) -> dict:
    def one(s):
        return {"gain_e_per_h": s["gain_e_per_h"], "ratio": s["gain_e_per_h"] / truth,
                "se_formal": s["gain_std"], "se_bootstrap": s["gain_std_bootstrap"], "n_groups": s["n_groups"]}

    return {"pooled": one(strata["pooled"]), "exposure": {k: one(v) for k, v in strata["exposure"].items()},
            "phase": {k: one(v) for k, v in strata["phase"].items()}}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("out", type=Path)
    p.add_argument("--size", default="320x200")
    p.add_argument("--cycles", type=int, default=6)
    p.add_argument("--spp", type=int, default=4)
    p.add_argument("--render-per", default="cycle", choices=("cycle", "shot"))
    p.add_argument("--scene", default="forest_summer")
    p.add_argument("--still-px", type=float, default=2.5)
    p.add_argument("--boot", type=int, default=200)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--walk", default="borealhdr",
                   help="walk preset; replay:ZERO_GYRO.csv with --speed-mps 1e-9: at rest")
    p.add_argument("--speed-mps", type=float, default=None)
    p.add_argument("--tag", default="", help="name suffix of the synthesised dataset")
    a = p.parse_args(argv)
    from emulator.io.borealhdr import load_sequence, sequence_response
    from emulator.playback.motion import recording_motion
    from emulator.noise import bracket_groups, estimate_noise_model
    from emulator.noise.insitu import noise_strata
    from scenes.synthesize import synthesize
    from synth.noise_model import noise_model_of
    from synth.sequence import load_camera

    w, h = (int(x) for x in a.size.split("x"))
    ds = a.out / f"{a.scene}-{a.size}-{a.cycles}c-{a.spp}spp-{a.render_per}-seed{a.seed}{a.tag}"
    if not (ds / "exposim.json").is_file():
        synthesize(a.scene, ds, n_cycles=a.cycles, width=w, height=h, spp=a.spp, stereo=False, seed=a.seed,
                   render_seed=a.seed, walk=a.walk, speed_mps=a.speed_mps, blur=True, render_per=a.render_per,
                   denoise="oidn-fast")
    seq = load_sequence(ds)
    resp = sequence_response(seq)
    truth = noise_model_of(load_camera(ds)).gain_e_per_h
    out = {"dataset": str(ds), "truth_gain_e_per_h": truth}
    motion = recording_motion(seq, stamp="start", remove_bias=False)
    for label, kw in (("all", {}), (f"still<={a.still_px:g}px", {"motion": motion, "max_motion_px": a.still_px})):
        groups = bracket_groups(seq, size=3, **kw)
        if len(groups) < 2:
            out[label] = {"n_groups": len(groups)}
            continue
        est = estimate_noise_model(groups, resp)
        out[label] = _ratios(noise_strata(est, n_boot=a.boot, seed=a.seed), truth)
    json.dump(out, sys.stdout, indent=1)
    print()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

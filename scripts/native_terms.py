"""What holds native emulation's image error back, on walks ``exposim validate live`` recorded.

    python scripts/native_terms.py STUDY_DIR [--weights 0,0.25,0.5,1,2,4] [--limits 0.01,0.05] [--attribution]

For every walk of the study (``STUDY_DIR/datasets/<scene>``, renders from the cache), the native
live loop is run again (every frame, the study's seed and noise), and each frame is emulated at the
exposure the live camera applied (open loop), for each weight of the native selector's motion
term, with and without the warp.  Printed per weight: the median RMSE (% of the DN range) over
frames and methods, the share of frames a neighbour served; over the frames a neighbour served, the
median with the warp, without it, and of the frame's own bracket at the same exposure over the pixels
both can give (the error of that instant with no motion to undo); and the median error split by
source offset (0: the frame's own bracket).  The noise floor is the median over frames served by their
own bracket at ratio 1 (two captures of one instant differing only by their noise).  Over walks, the
figures of ``results.json`` ``native_emulation`` with their bootstrap intervals.

``--attribution`` adds, on the frames a neighbour served (default selector), what the rotation warp
leaves and why: the error with the rotation of the walk's true trajectory instead of the gyro's (the
gyro path and its timing), with the warped neighbour moved onto the live frame itself by a dense
optical flow (an oracle: what a perfect geometric warp could leave, translation parallax included),
with it moved onto the frame's own bracket emulated at the same exposure (what an image-based
translation term could do on a real recording), split by whether the neighbour is of the same
bracket sweep (on walks rendered once per sweep: the same render).
"""

from __future__ import annotations

import argparse
import json
from collections import defaultdict
from pathlib import Path

import numpy as np


def _pool(errs: dict, names: list[str], into: dict) -> None:
    """Each method's per-frame errors of one walk added to the pooled lists ``into`` (warped, unwarped, every
    pixel, by source offset, and on the frames a neighbour bracket served)."""
    for m in names:
        d = errs[m]
        for rw, ro, ru, ra, off in zip(d["rmse_percent"], d["rmse_percent_own_bracket"],
                                       d["rmse_percent_unwarped"], d["rmse_percent_all"], d["source_offset"]):
            if off != 0:
                into["nb warped"].append(rw)
                into["nb own"].append(ro)
                into["nb unwarped"].append(ru)
            into["warped"].append(rw)
            into["all"].append(ra)
            into["unwarped"].append(ru)
            into[f"offset {off:+d}"].append(rw)
            into["neighbour"].append(off != 0)


def _print_weight(w: tuple[float, float], d: dict, per_walk: dict, names: list[str], seed: int) -> None:
    """The pooled errors ``d`` of one (motion weight, clipping margin) and, over the walks ``per_walk``, each
    walk's median with a bootstrap interval."""
    from validation.live.native import native_emulation_summary

    by_offset = ", ".join(f"{k[7:]}: {np.median(v):.2f} (n={len(v)})" for k, v in sorted(
        d.items(), key=lambda kv: kv[0]) if k.startswith("offset"))
    nb = (f"{np.median(d['nb warped']):.2f} / {np.median(d['nb unwarped']):.2f} / {np.median(d['nb own']):.2f}"
          if d["nb warped"] else "-")
    print(f"weight {w[0]:g}, clipping margin {w[1]:g}: median error {np.median(d['warped']):.2f} % warped, "
          f"{np.median(d['unwarped']):.2f} % unwarped, {np.median(d['all']):.2f} % over every pixel in view, "
          f"neighbour served {np.mean(d['neighbour']):.2f} (on those frames warped / unwarped / own bracket: "
          f"{nb} %); by offset {by_offset}")
    summary = native_emulation_summary(per_walk, names, seed=seed)
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


def main(argv=None) -> int:
    import scenes
    from emulator.io.borealhdr import load_sequence, sequence_response
    from emulator.playback import RunConfig
    from scenes.walkshots import walk_radiance
    from synth.sequence import load_camera
    from validation.live.config import config_from_dict
    from validation.live.loops import DatasetRadiance
    from validation.live.native import native_image_errors, native_rate_loop

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("study", type=Path)
    p.add_argument("--weights", default="0,0.25,0.5,1,2,4")
    p.add_argument("--limits", default="0.01", help="the selector's clipping margins to try (fractions)")
    p.add_argument("--attribution", action="store_true", help="what the rotation warp leaves, term by term")
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
        config = RunConfig(initial_ms=cfg.initial_ms, rate="native", latency_frames=cfg.latency_frames,
                           native_warp="rotation")
        if args.attribution and not hasattr(radiance, "shots"):
            raise SystemExit(f"native_terms: --attribution: {ds} has no walk to take the true rotation from "
                             "(written without exposure integration)")
        if args.attribution:
            attribution(seq, every, response, config, names, radiance.shots.traj, pooled["attribution"])
        for w in weights:
            errs = native_image_errors(seq, every, response, config, names, motion_stops_per_frame=w[0],
                                       saturation_limit=w[1])
            per_walk[w][scene_name] = errs
            _pool(errs, names, pooled[w])
    print(f"study {args.study} ({cfg.width}x{cfg.height}, {len(cfg.scenes)} walk(s), noise {cfg.capture_noise})")
    att = pooled.pop("attribution", None)
    if att:
        same = np.asarray(att.pop("same sweep"), dtype=bool)
        print(f"attribution on {same.size} neighbour frames x methods (median RMSE %, all / same sweep / other sweep): "
              + "; ".join(f"{k} {np.median(v):.2f} / {np.median(np.asarray(v)[same]):.2f} / "
                          f"{np.median(np.asarray(v)[~same]):.2f}" for k, v in att.items()))
    for w in weights:
        _print_weight(w, pooled[w], per_walk[w], names, cfg.seed)
    return 0


def _flow_warp(src_dn, ref_dn, H, response):
    """``src_dn`` moved by ``H`` and then onto ``ref_dn`` by a dense flow (DIS on the RGGB quads' log gray)."""
    import cv2

    from emulator.core.lut import forward_dn
    from emulator.core.native import plane_homography

    ls, lr = (response.inverse(x).astype(np.float32) for x in (src_dn, ref_dn))
    quad = lambda a: 0.25 * (a[0::2, 0::2] + a[1::2, 0::2] + a[0::2, 1::2] + a[1::2, 1::2])  # noqa: E731
    h, w = ls.shape
    moved = cv2.warpPerspective(quad(ls), plane_homography(H, 0.5, 0.5), (w // 2, h // 2), flags=cv2.INTER_LINEAR,
                                borderMode=cv2.BORDER_REPLICATE)
    logs = [np.log(np.maximum(x, 1e-6)) for x in (quad(lr), moved)]
    lo, hi = np.percentile(np.concatenate([x.ravel() for x in logs]), [1, 99])
    a8, b8 = (np.clip((x - lo) * 255.0 / max(hi - lo, 1e-6), 0, 255).astype(np.uint8) for x in logs)
    flow = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM).calc(a8, b8, None)
    ys, xs = np.mgrid[0 : h // 2, 0 : w // 2].astype(np.float64)
    mx, my = xs + flow[..., 0], ys + flow[..., 1]
    out = np.empty_like(ls)
    for px, py in ((0, 0), (1, 0), (0, 1), (1, 1)):
        Hi = np.linalg.inv(plane_homography(H, px, py))
        den = Hi[2, 0] * mx + Hi[2, 1] * my + Hi[2, 2]
        sx, sy = (((Hi[i, 0] * mx + Hi[i, 1] * my + Hi[i, 2]) / den).astype(np.float32) for i in (0, 1))
        out[py::2, px::2] = cv2.remap(np.ascontiguousarray(ls[py::2, px::2]), sx, sy, cv2.INTER_LINEAR,
                                      borderMode=cv2.BORDER_REPLICATE)
    return forward_dn(response, out, 1 << 20)


def attribution(seq, live_frames, response, config, names, traj, into) -> None:
    """Per neighbour frame and method, the errors ``--attribution`` prints (see the module notes), into ``into``."""
    import cv2

    from emulator.core.blur import rotation_homography
    from emulator.core.emulate import validity_mask
    from emulator.core.native import warp_to_instant
    from validation.live.native import native_provider

    pw, pp = native_provider(seq, response, config), native_provider(seq, response, config, warp=False)
    fr, span = pw.frames, 1.0 / (seq.white_level - seq.black_level)
    t0 = fr.timestamps[0]
    live_by = {cs.cycle: cs for cs in live_frames}
    for tw, tp in zip(pw.ticks(), pp.ticks()):
        cs = live_by.get(tw.index)
        for m in names if cs is not None and not tw.skipped else ():
            lv = cs.steps.get(m)
            a = tw.shot(float(lv.target_ms)) if lv is not None else None
            if a is None or a.native.source_offset == 0 or not np.isfinite(a.native.warp_deg):
                continue
            target, k = float(lv.target_ms), tw.index
            j = k + a.native.source_offset
            src = fr.cycles[j].frames["left"][a.bracket_ms].load()
            size = (src.shape[1], src.shape[0])
            K, _ = pw.motion.K("left", size)
            H = rotation_homography(K, pw.rotation(j, k, a.bracket_ms, target))
            mask = cv2.warpPerspective(validity_mask(src, a.ratio, response).astype(np.uint8), H, size,
                                       flags=cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT, borderValue=0) > 0
            live = lv.left.astype(np.float64)[mask]

            def err(img):
                return 100.0 * span * float(np.sqrt(np.mean((img.astype(np.float64)[mask] - live) ** 2)))

            # the true rotation between the same two instants (window middles), from the walk's trajectory
            mids = np.array([(fr.timestamps[j] - t0) * 1e-9 + a.bracket_ms * 5e-4,
                             (fr.timestamps[k] - t0) * 1e-9 + target * 5e-4])
            P = np.asarray(traj.poses(mids))
            true_H = rotation_homography(K, P[0][:3, :3].T @ P[1][:3, :3])
            emu = np.asarray(pw.images(j).emulated("left", a.bracket_ms, a.ratio, response.lut(a.ratio)[0], pw.stats))
            ek = fr.exposures[k]
            own = np.asarray(pw.images(k).emulated("left", ek, target / ek, response.lut(target / ek)[0], pw.stats))
            for key, img in (("unwarped", tp.shot(target).left), ("gyro rotation (the warp)", a.left),
                             ("true rotation", warp_to_instant(emu, true_H, response)[0]),
                             ("aligned to the frame's own bracket", _flow_warp(emu, own, H, response)),
                             ("aligned to the live frame (oracle)", _flow_warp(emu, lv.left, H, response))):
                into[key].append(err(img))
            into["same sweep"].append(fr.cycles[j].index == fr.cycles[k].index)


def _iv(d: dict) -> str:
    if d["estimate"] is None:
        return "-"
    return f"{d['estimate']:.2f}" + (f" [{d['ci95'][0]:.2f}, {d['ci95'][1]:.2f}]" if d["ci95"] else "")


if __name__ == "__main__":
    raise SystemExit(main())

"""Measurements behind docs/blur.md on a BorealHDR recording with an IMU (default: the shared sample).

    python scripts/blur_sample_checks.py [SEQUENCE] [stamp|rest|sharpness|noise|all]

stamp      image shift between consecutive shots (phase correlation of the log exposure-normalised
           green planes) against the gyro's rotation between the shots' mid-exposures, for stamp
           positions 0 (start) .. 1.5 of the exposure window, with and without the gyro offset; and an
           unconstrained least-squares map from the gyro's rotation (IMU axes) to the image shift
rest       per emulated image: RMS change of --blur consistent against plain emulation, over the
           noise of a capture at the target and over the emulated image's own noise (full well
           2005 e- in situ and 10 500 e- synth preset)
sharpness  real 32 ms frame against 32 ms emulated from 4/8/16 ms, plain and consistent (p95 of the
           green-plane gradient over the median level, as issue 21)
imu        the IMU-to-camera rotation from the image shifts: the axis fit of ``stamp`` turned into the
           camera x and y axes in IMU coordinates, their angles to the assumed ROS convention and,
           by Monte Carlo over the fit's standard errors, the 95 % interval of each angle
noise      in-situ noise fit: pooled, per exposure stratum, per Bayer phase, formal and bootstrap SE,
           all groups and still groups only
"""

from __future__ import annotations

import json
import sys

import cv2
import numpy as np

from emulator.core.blur import integrate_rotation, rotation_homography
from emulator.core.emulate import emulate
from emulator.io.borealhdr import load_sequence, sequence_response
from emulator.playback.motion import blur_hook, recording_motion
from validation.blur.measure import sharpness as sharpness_of

SAMPLE = "/work/shared/data/borealhdr_sample/backpack_2023-09-25-15-05-03"


def _centre_shift(motion, cam, ta, tb):
    K, _ = motion.K(cam)
    _, R = integrate_rotation(motion.omega, ta, tb)
    H = rotation_homography(K, R[-1])
    c = np.array([K[0, 2], K[1, 2], 1.0])
    q = H @ c
    return q[:2] / q[2] - c[:2]


def stamp(seq, resp):
    win = cv2.createHanningWindow((seq_w(seq) // 2, seq_h(seq) // 2), cv2.CV_64F)
    pairs = []
    for cam in seq.cameras:
        frames = sorted([f for c in seq.cycles for f in c.frames.get(cam, {}).values()], key=lambda f: f.timestamp_ns)
        for a, b in zip(frames[:-1], frames[1:]):
            ra, rb = a.load()[0::2, 1::2], b.load()[0::2, 1::2]
            la = np.log(np.maximum(resp.g[ra] / a.exposure_ms, 1e-3))
            lb = np.log(np.maximum(resp.g[rb] / b.exposure_ms, 1e-3))
            (dx, dy), _ = cv2.phaseCorrelate(la, lb, win)
            pairs.append((cam, a, b, np.array([2 * dx, 2 * dy])))
    out = {"n_pairs": len(pairs), "rms_image_shift_px": float(np.sqrt(np.mean([p[3] ** 2 for p in pairs]))), "fits": [],
           "axis_fit": _axis_fit(seq, pairs)}
    for bias in (True, False):
        motion = recording_motion(seq, remove_bias=bias)
        for alpha in (0.0, 0.25, 0.5, 0.75, 1.0, 1.25, 1.5):
            res = []
            for cam, a, b, s in pairs:
                ta = motion.t_s(a.timestamp_ns) + (0.5 - alpha) * a.exposure_ms * 1e-3
                tb = motion.t_s(b.timestamp_ns) + (0.5 - alpha) * b.exposure_ms * 1e-3
                res.append(s - _centre_shift(motion, cam, ta, tb))
            out["fits"].append({"gyro_offset_removed": bias, "stamp_fraction": alpha,
                                "rms_residual_px": float(np.sqrt(np.mean(np.square(res))))})
    return out


def _axis_fit(seq, pairs):
    """Least squares image shift (x, y) = A theta_imu over the pairs (gyro in IMU axes, offset removed,
    stamp at the end), against the assumed A = [[0, -f, 0], [f, 0, 0]] @ R_CAM_IMU_FLU."""
    from emulator.core.blur import R_CAM_IMU_FLU, exposure_window_s

    motion = recording_motion(seq, R_cam_imu=np.eye(3))
    X, Y = [], []
    for cam, a, b, s in pairs:
        ta = np.mean(exposure_window_s(motion.t_s(a.timestamp_ns), a.exposure_ms, "end"))
        tb = np.mean(exposure_window_s(motion.t_s(b.timestamp_ns), b.exposure_ms, "end"))
        _, R = integrate_rotation(motion.omega, ta, tb)
        X.append(cv2.Rodrigues(R[-1])[0].ravel())
        Y.append(s)
    X, Y = np.array(X), np.array(Y)
    A = np.linalg.lstsq(X, Y, rcond=None)[0]
    f = float(motion.K("left")[0][0, 0])
    M = np.array([[0.0, -f, 0.0], [f, 0.0, 0.0]]) @ R_CAM_IMU_FLU
    sig = np.sqrt(np.sum((Y - X @ A) ** 2, axis=0) / (len(Y) - 3))
    se = np.outer(sig, np.sqrt(np.diag(np.linalg.inv(X.T @ X))))
    return {"fitted_px_per_rad": A.T.tolist(), "fitted_se_px_per_rad": se.tolist(), "assumed_px_per_rad": M.tolist(),
            "rms_residual_fitted_px": float(np.sqrt(np.mean((Y - X @ A) ** 2))),
            "rms_residual_assumed_px": float(np.sqrt(np.mean((Y - X @ M.T) ** 2)))}


def imu_rotation(seq, resp, draws: int = 2000, seed: int = 0):
    """Camera x and y axes in IMU coordinates from the image shifts (roll about the optical axis moves
    the centre by nothing, so it is not seen: the third axis follows from the two by orthogonality)."""
    from emulator.core.blur import R_CAM_IMU_FLU

    fit = stamp(seq, resp)["axis_fit"]
    A, se = np.array(fit["fitted_px_per_rad"]), np.array(fit["fitted_se_px_per_rad"])
    f = float(recording_motion(seq).K("left")[0][0, 0])
    rng = np.random.default_rng(seed)

    def axes(a):  # shift x = -f (y_cam . theta), shift y = f (x_cam . theta): the assumed map of _axis_fit
        return a[1] / f, -a[0] / f

    def angle_deg(u, v):
        return float(np.degrees(np.arccos(np.clip(abs(u @ v) / np.linalg.norm(u) / np.linalg.norm(v), -1, 1))))

    x_true, y_true = R_CAM_IMU_FLU[0], R_CAM_IMU_FLU[1]
    out = {"axis_fit": fit, "focal_px": f}
    x_fit, y_fit = axes(A)
    out["x_cam_in_imu"] = (x_fit / np.linalg.norm(x_fit)).tolist()
    out["y_cam_in_imu"] = (y_fit / np.linalg.norm(y_fit)).tolist()
    out["scale_x"], out["scale_y"] = float(np.linalg.norm(x_fit)), float(np.linalg.norm(y_fit))  # 1 when f is right
    out["angle_to_assumed_deg"] = {"x": angle_deg(x_fit, x_true), "y": angle_deg(y_fit, y_true)}
    sims = {"x": [], "y": []}
    for _ in range(draws):
        xs, ys = axes(A + rng.standard_normal(A.shape) * se)
        sims["x"].append(angle_deg(xs, x_true))
        sims["y"].append(angle_deg(ys, y_true))
    out["angle_to_assumed_p95_deg"] = {k: float(np.percentile(v, 95)) for k, v in sims.items()}
    out["angle_spread_p95_deg"] = {  # how far the estimate itself wanders: the resolution of this sample
        k: float(np.percentile([angle_deg(a, b) for a, b in zip(
            [axes(A + rng.standard_normal(A.shape) * se)[i] for _ in range(draws)], [v] * draws)], 95))
        for k, v, i in (("x", x_fit, 0), ("y", y_fit, 1))}
    return out


def seq_w(seq):
    return next(iter(next(iter(seq.cycles[1].frames.values())).values())).load().shape[1]


def seq_h(seq):
    return next(iter(next(iter(seq.cycles[1].frames.values())).values())).load().shape[0]


def rest(seq, resp):
    from emulator.noise import NoiseModel
    from emulator.noise.tables import response_slope

    hook = blur_hook("consistent", seq, resp)
    dfdh = 1.0 / np.maximum(response_slope(resp)[: resp.white_level + 1], 1e-12)
    dn = np.arange(resp.white_level + 1)
    sig = {fw: np.sqrt(NoiseModel.from_full_well(resp, fw).variance_e(dn)) / (fw / resp.g[resp.white_level])
           for fw in (2005.0, 10500.0)}
    rows = []
    for c in seq.cycles:
        for cam in seq.cameras:
            fr = c.frames.get(cam, {})
            for src in sorted(fr):
                raw = fr[src].load()
                for tgt in sorted({2 * src, 32.0}):
                    if not src < tgt <= 32.0:
                        continue
                    img, _ = hook.emulate(cam, fr[src].timestamp_ns, raw, src, tgt)
                    plain, valid = emulate(raw, src, tgt, resp, return_mask=True)
                    m = valid & (plain < resp.white_level) & (plain > resp.black_level)
                    change = float(np.sqrt(np.mean((img[m].astype(np.float64) - plain[m]) ** 2)))
                    row = {"cycle": c.index, "camera": cam, "source_ms": src, "target_ms": tgt, "rms_change_dn": change,
                           "added_blur_px": hook.motion.frame_blur(cam, fr[src].timestamp_ns, tgt).max_px}
                    for fw, s in sig.items():
                        tgt_noise = np.sqrt(np.mean((s[plain[m]] * dfdh[plain[m]]) ** 2))
                        own_noise = np.sqrt(np.mean((tgt / src * s[raw[m]] * dfdh[plain[m]]) ** 2))
                        row[f"over_capture_noise_fw{fw:.0f}"] = change / tgt_noise
                        row[f"over_own_noise_fw{fw:.0f}"] = change / own_noise
                    rows.append(row)
    summary = {}
    for r in rows:
        k = f"{r['source_ms']:g}->{r['target_ms']:g}"
        s = summary.setdefault(k, {"n": 0})
        s["n"] += 1
        for key in ("rms_change_dn", "over_capture_noise_fw2005", "over_capture_noise_fw10500", "over_own_noise_fw2005",
                    "over_own_noise_fw10500"):
            s[f"max_{key}"] = max(s.get(f"max_{key}", 0.0), r[key])
    return {"summary": summary, "rows": rows}


def sharpness(seq, resp):
    hook = blur_hook("consistent", seq, resp)

    rows = []
    for c in seq.cycles:
        for cam in seq.cameras:
            fr = c.frames.get(cam, {})
            if 32.0 not in fr:
                continue
            real = sharpness_of(fr[32.0].load())
            for src in (4.0, 8.0, 16.0):
                if src not in fr:
                    continue
                raw = fr[src].load()
                plain = sharpness_of(emulate(raw, src, 32.0, resp))
                cons = sharpness_of(hook.emulate(cam, fr[src].timestamp_ns, raw, src, 32.0)[0])
                rows.append({"cycle": c.index, "camera": cam, "source_ms": src, "real": real,
                             "plain_error_percent": 100 * (plain / real - 1),
                             "consistent_error_percent": 100 * (cons / real - 1)})
    return rows


def noise(seq, resp):
    from emulator.noise import bracket_groups, estimate_noise_model
    from emulator.noise.insitu import noise_strata

    motion = recording_motion(seq)
    out = {}
    for tag, kw in (("all", {}), ("still_le_2.5px", {"motion": motion, "max_motion_px": 2.5})):
        groups = bracket_groups(seq, size=3, **kw)
        est = estimate_noise_model(groups, resp)
        out[tag] = {"n_groups": len(groups), "gain_e_per_h": est.gain_e_per_h, "gain_std": est.gain_std,
                    "full_well_e": est.full_well_e, "read_noise_e": est.read_noise_e,
                    "strata": noise_strata(est, n_boot=300)}
    return out


def main(argv):
    path = argv[1] if len(argv) > 1 else SAMPLE
    what = argv[2] if len(argv) > 2 else "all"
    seq = load_sequence(path)
    resp = sequence_response(seq)
    jobs = {"stamp": stamp, "rest": rest, "sharpness": sharpness, "noise": noise, "imu": imu_rotation}
    todo = list(jobs) if what == "all" else [what]
    print(json.dumps({k: jobs[k](seq, resp) for k in todo}, indent=1, default=float))


if __name__ == "__main__":
    main(sys.argv)

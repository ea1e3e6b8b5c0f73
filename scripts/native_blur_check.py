"""Does the blur-aware native selector ever emulate from a window that blurs over 1 px beyond the target's?

    python scripts/native_blur_check.py SEQ [--targets 0.5,1,1.5,2,3,4,6,8,12,16,24,32]

On a recording with a gyro (and a camera calibration it can find), the native selector as runs use it
and the blur-aware one (``exposim run --rate native --native-blur-aware``) are asked for every frame
and target.  Among the (frame, target) pairs where some candidate's predicted blur is within
:data:`emulator.core.native.BLUR_LIMIT_PX` of the target's, it prints how often each selector took a source
more than that beyond, by motion class (validation.native_loo's), and how often the blur-aware one did
so from a longer window (emulating down).  Full resolution, as runs.
"""

from __future__ import annotations

import argparse

import numpy as np


def main(argv=None) -> int:
    from emulator.core.blur import exposure_window_s
    from emulator.io.borealhdr import load_sequence
    from emulator.playback.motion import recording_motion
    from emulator.core.native import BLUR_LIMIT_PX, BLUR_STOPS_PER_PX
    from emulator.playback import NativeProvider, RunConfig
    from emulator.playback.native import recording_stamp
    from validation.native_loo.measure import frame_rate_deg_s, motion_class

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sequence")
    ap.add_argument("--targets", default="0.5,1,1.5,2,3,4,6,8,12,16,24,32", help="target exposures, ms")
    args = ap.parse_args(argv)
    targets = [float(t) for t in args.targets.split(",")]
    seq = load_sequence(args.sequence, imu_warning=False)
    motion = recording_motion(seq, stamp=recording_stamp(seq))
    response = RunConfig().response_for(seq)
    plain, aware = (NativeProvider(seq, RunConfig(rate="native"), response, motion=motion, blur_stops_per_px=w)
                    for w in (None, BLUR_STOPS_PER_PX))
    fr = aware.frames
    interval = float(np.median(np.diff(fr.timestamps))) * 1e-9
    counts: dict = {}
    largest = 0.0
    for k in range(len(fr)):
        window = exposure_window_s(motion.t_s(fr.timestamps[k]), fr.exposures[k], motion.stamp)
        c = counts.setdefault(motion_class(frame_rate_deg_s(motion, 0.5 * sum(window), interval)), [0, 0, 0, 0])
        tp, ta = plain.tick(k), aware.tick(k)
        for t in targets:
            excess = {j: aware.excess_blur_px(j, k, t) for j in ta.sources}
            largest = max(largest, *excess.values())
            if min(excess.values()) > BLUR_LIMIT_PX:
                continue
            jp, ja = tp.select(t), ta.select(t)
            over = excess[ja] > BLUR_LIMIT_PX
            c[0] += 1
            c[1] += int(excess[jp] > BLUR_LIMIT_PX)
            c[2] += int(over)
            c[3] += int(over and fr.exposures[ja] > t)
    print(f"{len(fr)} frames x {len(targets)} targets; the largest excess blur of a candidate: {largest:.1f} px")
    print("class: pairs with a candidate within 1 px, over 1 px beyond as runs select, blur-aware, "
          "blur-aware emulating down")
    for name, c in counts.items():
        print(f"{name}: {c[0]}, {c[1]}, {c[2]}, {c[3]}")
    total = np.sum(list(counts.values()), axis=0)
    print(f"all: {total[0]}, {total[1]}, {total[2]}, {total[3]}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

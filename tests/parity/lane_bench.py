#!/usr/bin/env python3
"""OpenCV's time for the same lane stages as rccar, single-threaded, on the same frames.

Called by `cargo bench --bench lane` (benches/lane.rs), which passes the frames, the
bird's-eye -> camera matrix and the repetition count, and reads one JSON object from stdout:
{stage: [seconds per frame, one value per repetition]}.
"""
import json
import sys
import time
import tomllib

import cv2
import numpy as np


def main():
    args = json.loads(sys.argv[1])
    cv2.setNumThreads(1)
    cfg = tomllib.loads(open(args["config"]).read())
    lane, warp = cfg["lane"], cfg["warp"]
    W, H = warp["out_width"], warp["out_height"]
    M = np.array(args["bird_to_camera"], dtype=np.float64).reshape(3, 3)
    band = args["band_rows"]
    frames = [cv2.cvtColor(cv2.imread(p, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB) for p in args["frames"]]
    stages = {k: [] for k in ["warp", "gray", "blur", "canny", "threshold", "histogram", "total", "adaptive"]}
    flags = cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP
    for _ in range(args["reps"]):
        acc = {k: 0.0 for k in stages}
        for rgb in frames:
            t0 = time.perf_counter()
            bird_rgb = cv2.warpPerspective(rgb, M, (W, H), flags=flags)
            t1 = time.perf_counter()
            bird = cv2.cvtColor(bird_rgb, cv2.COLOR_RGB2GRAY)
            t2 = time.perf_counter()
            blur = cv2.GaussianBlur(bird, (5, 5), 0)
            t3 = time.perf_counter()
            edges = cv2.Canny(blur, lane["canny_low"], lane["canny_high"], L2gradient=False)
            t4 = time.perf_counter()
            _, thr = cv2.threshold(bird, lane["threshold"], 255, cv2.THRESH_BINARY)
            binary = cv2.bitwise_or(thr, edges)
            t5 = time.perf_counter()
            # countNonZero per column of the band: cv2.reduce on the 0/1 image, as the
            # tutorial's per-column sum does.
            hist = cv2.reduce((binary[H - band:] > 0).view(np.uint8), 0, cv2.REDUCE_SUM, dtype=cv2.CV_32S)
            t6 = time.perf_counter()
            for k, v in zip(["warp", "gray", "blur", "canny", "threshold", "histogram"],
                            [t1 - t0, t2 - t1, t3 - t2, t4 - t3, t5 - t4, t6 - t5]):
                acc[k] += v
            acc["total"] += t6 - t0
            # lane.threshold_mode = "adaptive" instead of the fixed level (not in the total).
            t7 = time.perf_counter()
            thr = cv2.adaptiveThreshold(bird, 255, cv2.ADAPTIVE_THRESH_MEAN_C, cv2.THRESH_BINARY,
                                        lane.get("adaptive_block", 41), lane.get("adaptive_c", -5))
            binary = cv2.bitwise_or(thr, edges)
            acc["adaptive"] += time.perf_counter() - t7
        for k in stages:
            stages[k].append(acc[k] / len(frames))
    json.dump({"opencv": cv2.__version__, "stages": stages}, sys.stdout)


if __name__ == "__main__":
    main()

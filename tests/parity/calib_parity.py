#!/usr/bin/env python3
"""Parity of `rccar calibrate camera|stereo` with OpenCV 4.x on OpenCV's own stereo sample
(issue 12): the 13 chessboard pairs left01..14.jpg / right01..14.jpg (9x6 inner corners) that
Debian's opencv-doc package installs (never copied into the repository).

OpenCV side, as its stereo_calib sample does it: cv2.findChessboardCorners + cv2.cornerSubPix
(window 11x11, 30 iterations or 0.001 px), cv2.calibrateCamera per camera on the pairs found
in both images, cv2.stereoCalibrate with CALIB_FIX_INTRINSIC, cv2.stereoRectify.
Our side: `rccar calibrate stereo` (and `rccar calibrate camera` on the left images), read
from the JSON results file it writes.

Checks (targets of issue 12): fx, fy, cx, cy of both cameras within 0.5 %; baseline
direction within 0.5 deg; |T| within 0.5 %; RMS (left, right, stereo) within 0.05 px; the
same pairs found; the single-camera command agrees with the stereo one's left camera.
Distortion, rectifying rotations and per-image errors are printed for information.
Prints "N passed, N failed" and exits non-zero on a failure.

    RCCAR_BIN=target/release/rccar python3 tests/parity/calib_parity.py
"""
import glob
import json
import math
import os
import subprocess
import sys
import tempfile

import cv2
import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
BIN = os.environ.get("RCCAR_BIN", os.path.join(ROOT, "target", "release", "rccar"))
DATA = os.environ.get("RCCAR_OPENCV_SAMPLES", "/usr/share/doc/opencv-doc/examples/data")
BOARD = (9, 6)
SQUARE = 0.025

passed = failed = 0


def check(name, ok, detail):
    global passed, failed
    if ok:
        passed += 1
    else:
        failed += 1
    print(f"{'ok  ' if ok else 'FAIL'} {name}: {detail}")


def main():
    lefts = sorted(glob.glob(os.path.join(DATA, "left[0-9][0-9].jpg")))
    rights = [p.replace("left", "right") for p in lefts]
    if not lefts or not all(os.path.exists(p) for p in rights):
        print(f"no stereo sample pairs in {DATA} (install Debian's opencv-doc)")
        print("0 passed, 1 failed")
        return 1
    # OpenCV.
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.001)
    objp = np.zeros((BOARD[0] * BOARD[1], 3), np.float32)
    objp[:, :2] = np.mgrid[0:BOARD[0], 0:BOARD[1]].T.reshape(-1, 2) * SQUARE
    lp, rp, used = [], [], []
    size = None
    for l, r in zip(lefts, rights):
        il, ir = cv2.imread(l, 0), cv2.imread(r, 0)
        size = il.shape[::-1]
        okl, cl = cv2.findChessboardCorners(il, BOARD)
        okr, cr = cv2.findChessboardCorners(ir, BOARD)
        if not (okl and okr):
            continue
        cl = cv2.cornerSubPix(il, cl, (11, 11), (-1, -1), crit)
        cr = cv2.cornerSubPix(ir, cr, (11, 11), (-1, -1), crit)
        lp.append(cl)
        rp.append(cr)
        used.append(os.path.basename(l))
    objs = [objp] * len(lp)
    rms_l, kl, dl, _, _ = cv2.calibrateCamera(objs, lp, size, None, None)
    rms_r, kr, dr, _, _ = cv2.calibrateCamera(objs, rp, size, None, None)
    rms_s, _, _, _, _, R, T, _, _ = cv2.stereoCalibrate(
        objs, lp, rp, kl, dl, kr, dr, size, flags=cv2.CALIB_FIX_INTRINSIC,
        criteria=(cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 100, 1e-6))
    R1, R2, P1, P2, _, _, _ = cv2.stereoRectify(kl, dl, kr, dr, size, R, T, flags=cv2.CALIB_ZERO_DISPARITY, alpha=-1)
    # Ours.
    tmp = tempfile.mkdtemp()
    out = os.path.join(tmp, "stereo.json")
    cmd = [BIN, "calibrate", "stereo", "--board", "9x6", "--square", str(SQUARE), "--out", out,
           "--left", *lefts, "--right", *rights]
    res = subprocess.run(cmd, capture_output=True, text=True, cwd=tmp)
    if res.returncode != 0:
        print(res.stdout, res.stderr)
        check("rccar calibrate stereo runs", False, f"exit {res.returncode}")
        print(f"{passed} passed, {failed} failed")
        return 1
    st = json.load(open(out))["stereo"]
    ours_used = [os.path.basename(p[0]) for p in st["per_pair_rms_px"]]
    check("same pairs used", ours_used == used, f"OpenCV {len(used)}, ours {len(ours_used)} {st['pairs_not_used']}")
    for side, k, d, rms in (("left", kl, dl, rms_l), ("right", kr, dr, rms_r)):
        c = st[side]
        ki = c["intrinsics"]
        for name, ours, cv in (("fx", ki["fx"], k[0, 0]), ("fy", ki["fy"], k[1, 1]),
                               ("cx", ki["cx"], k[0, 2]), ("cy", ki["cy"], k[1, 2])):
            rel = abs(ours - cv) / cv
            check(f"{side} {name}", rel <= 0.005, f"ours {ours:.3f}, OpenCV {cv:.3f} ({100 * rel:.3f} %)")
        check(f"{side} RMS", abs(c["rms_px"] - rms) <= 0.05, f"ours {c['rms_px']:.4f} px, OpenCV {rms:.4f} px")
        print(f"     {side} distortion ours   {np.round(c['distortion'], 5).tolist()}")
        print(f"     {side} distortion OpenCV {np.round(d.ravel(), 5).tolist()}")
    t_ours = np.array(st["t"])
    t_cv = T.ravel()
    ang = math.degrees(math.acos(np.clip(t_ours @ t_cv / np.linalg.norm(t_ours) / np.linalg.norm(t_cv), -1, 1)))
    check("baseline direction", ang <= 0.5, f"{ang:.3f} deg (ours {np.round(t_ours, 5).tolist()}, OpenCV {np.round(t_cv, 5).tolist()})")
    rel_b = abs(np.linalg.norm(t_ours) - np.linalg.norm(t_cv)) / np.linalg.norm(t_cv)
    check("baseline length", rel_b <= 0.005, f"ours {np.linalg.norm(t_ours):.5f} m, OpenCV {np.linalg.norm(t_cv):.5f} m ({100 * rel_b:.3f} %)")
    r_ours = np.array(st["r"])
    dr_ang = math.degrees(np.linalg.norm(cv2.Rodrigues(r_ours @ R.T)[0]))
    check("rotation R", dr_ang <= 0.5, f"{dr_ang:.3f} deg apart")
    check("stereo RMS", abs(st["rms_px"] - rms_s) <= 0.05, f"ours {st['rms_px']:.4f} px, OpenCV {rms_s:.4f} px")
    rect = st["rectification"]
    for name, ours, cv in (("R1", np.array(rect["r1"]), R1), ("R2", np.array(rect["r2"]), R2)):
        a = math.degrees(np.linalg.norm(cv2.Rodrigues(ours @ cv.T)[0]))
        check(f"rectification {name}", a <= 0.5, f"{a:.3f} deg apart")
    print(f"     rectified f ours {rect['f']:.2f}, OpenCV {P1[0, 0]:.2f}; c ours {np.round(rect['c'], 2).tolist()}, "
          f"OpenCV {[round(P1[0, 2], 2), round(P1[1, 2], 2)]}; P2 tx ours {rect['f'] * rect['tx']:.3f}, OpenCV {P2[0, 3]:.3f}")
    # The single-camera command on the left images agrees with the stereo command's left camera.
    out1 = os.path.join(tmp, "left.json")
    res = subprocess.run([BIN, "calibrate", "camera", "--board", "9x6", "--out", out1, *lefts],
                         capture_output=True, text=True, cwd=tmp)
    if res.returncode != 0:
        check("rccar calibrate camera runs", False, res.stderr.strip())
    else:
        c1 = json.load(open(out1))["camera"]
        rel = abs(c1["intrinsics"]["fx"] - kl[0, 0]) / kl[0, 0]
        check("calibrate camera fx (left images)", rel <= 0.005 and abs(c1["rms_px"] - rms_l) <= 0.05,
              f"ours {c1['intrinsics']['fx']:.3f} px RMS {c1['rms_px']:.4f}, OpenCV {kl[0, 0]:.3f} px RMS {rms_l:.4f}")
    print(f"{passed} passed, {failed} failed")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())

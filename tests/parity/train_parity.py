#!/usr/bin/env python3
"""Shipped cascades (config/cascades/*.xml, trained by rccar-train) in OpenCV 4 and in rccar.

For each model: cv2.CascadeClassifier loads the XML, and on held-out simulator frames
(rendered by `rccar-train gen --split eval --seed 1001`, seeds never used in training) its
detectMultiScale boxes are compared with `rccar detect`'s: every OpenCV box must have an rccar
box with IoU >= 0.9 (>= 99% of them), and the recall against the ground truth is printed for
both. Prints "N passed, N failed" (one check per model and parameter set).

    python3 tests/parity/train_parity.py [--quick] [stop_sign traffic_light obstacle yield_sign turn_sign]
Env: RCCAR_BIN (default target/release/rccar), RCCAR_TRAIN_BIN (target/release/rccar-train),
RCCAR_TRAIN_OUT (default out/training: where the held-out frames are, made if missing).
"""
import json
import os
import subprocess
import sys

import cv2

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
KINDS = ["stop_sign", "traffic_light", "obstacle", "yield_sign", "turn_sign"]
# The lighting's change of each kind's held-out frames (as training/models/train_all.sh).
LIGHT_VARIATION = {"yield_sign": "0.3", "turn_sign": "0.3"}


def iou(a, b):
    ax, ay, aw, ah = a
    bx, by, bw, bh = b
    ix = max(0, min(ax + aw, bx + bw) - max(ax, bx))
    iy = max(0, min(ay + ah, by + bh) - max(ay, by))
    i = ix * iy
    u = aw * ah + bw * bh - i
    return i / u if u > 0 else 0.0


def main():
    quick = "--quick" in sys.argv
    kinds = [a for a in sys.argv[1:] if not a.startswith("--")] or KINDS
    rccar = os.environ.get("RCCAR_BIN", os.path.join(ROOT, "target/release/rccar"))
    trainer = os.environ.get("RCCAR_TRAIN_BIN", os.path.join(ROOT, "target/release/rccar-train"))
    out = os.environ.get("RCCAR_TRAIN_OUT", os.path.join(ROOT, "out/training"))
    for b in (rccar, trainer):
        if not os.path.exists(b):
            subprocess.run(["cargo", "build", "--release", "--workspace"], cwd=ROOT, check=True)
    cv2.setNumThreads(1)
    passed = failed = 0
    count = 60 if quick else 300
    for kind in kinds:
        xml = os.path.join(ROOT, "config/cascades", kind + ".xml")
        c = cv2.CascadeClassifier(xml)
        if c.empty():
            print(f"{kind}: cv2.CascadeClassifier could not load {xml}")
            failed += 1
            continue
        info = os.path.join(out, kind, "eval", "info.dat")
        if not os.path.exists(info) or sum(1 for _ in open(info)) < count:
            subprocess.run([trainer, "gen", "--kind", kind, "--split", "eval", "--count", "300",
                            "--seed", "1001", "--light-variation", LIGHT_VARIATION.get(kind, "0"),
                            "--out", os.path.dirname(info)], cwd=ROOT, check=True)
        lines = [l.split() for l in open(info) if l.strip()][:count]
        paths = [os.path.join(os.path.dirname(info), l[0]) for l in lines]
        truth = {p: [tuple(map(int, l[2 + 4 * k:6 + 4 * k])) for k in range(int(l[1]))] for p, l in zip(paths, lines)}
        for sf, mn in [(1.1, 3), (1.1, 0)]:
            r = subprocess.run([rccar, "detect", "--cascade", xml, "--no-annotate", "--scale-factor", str(sf),
                                "--min-neighbors", str(mn)] + paths, cwd=ROOT, check=True,
                               capture_output=True, text=True)
            ours = {}
            for line in r.stdout.splitlines():
                j = json.loads(line)
                ours[j["image"]] = [(b["x"], b["y"], b["width"], b["height"]) for b in j["boxes"]]
            total = matched = extra = same_count = 0
            rec_cv = rec_rs = 0
            for p in paths:
                g = cv2.imread(p, cv2.IMREAD_GRAYSCALE)
                theirs = [tuple(map(int, b)) for b in c.detectMultiScale(g, scaleFactor=sf, minNeighbors=mn)]
                mine = ours.get(p, [])
                total += len(theirs)
                matched += sum(1 for t in theirs if any(iou(t, m) >= 0.9 for m in mine))
                extra += sum(1 for m in mine if not any(iou(t, m) >= 0.9 for t in theirs))
                same_count += len(theirs) == len(mine)
                for t in truth[p]:
                    rec_cv += any(iou(t, b) >= 0.5 for b in theirs)
                    rec_rs += any(iou(t, b) >= 0.5 for b in mine)
            frac = matched / total if total else 1.0
            ok = frac >= 0.99 and extra <= 0.01 * max(total, 1)
            nbox = sum(len(v) for v in truth.values())
            print(f"{kind:14s} sf={sf} mn={mn}: OpenCV boxes matched {matched}/{total} ({100 * frac:.2f}%), "
                  f"rccar-only {extra}, same count {same_count}/{len(paths)} frames; "
                  f"recall vs truth OpenCV {rec_cv}/{nbox}, rccar {rec_rs}/{nbox}  {'ok' if ok else 'FAIL'}")
            passed += ok
            failed += not ok
    print(f"{passed} passed, {failed} failed")
    return 0 if failed == 0 else 1


if __name__ == "__main__":
    sys.exit(main())

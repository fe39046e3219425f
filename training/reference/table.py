#!/usr/bin/env python3
"""The table of compare.sh: the cascades' evaluate reports and /usr/bin/time -v figures.

    table.py OUT W H NVEC NPOS NNEG
"""
import json
import os
import re
import sys
import xml.etree.ElementTree as ET

NAMES = {
    "rccar": "rccar-train",
    "rccar-holdout": "rccar-train, early stop on the calibration frames (--holdout)",
    "opencv": "opencv_traincascade",
}


def run_cost(out, t):
    s = open(f"{out}/{t}.time").read()

    def g(k):
        return re.search(k + r": (.*)", s).group(1).strip()

    cpu = float(g(r"User time \(seconds\)")) + float(g(r"System time \(seconds\)"))
    return g(r"Elapsed \(wall clock\) time \(h:mm:ss or m:ss\)"), cpu, int(g(r"Maximum resident set size \(kbytes\)"))


def fmt(p):
    found = p["true_positives"]
    return (f"{p['recall']:.3f} ({found}/{found + p['misses']}) / "
            f"{p['fp_per_negative_frame']:.3f} ({p['fp_negative_frames']})")


def main(out, w, h, nvec, npos, nneg):
    res = {}
    for t in NAMES:
        if t == "rccar-holdout" and not os.path.exists(f"{out}/eval-{t}/report.json"):
            continue  # optional: compare.sh trains it with HOLDOUT=1
        rep = json.load(open(f"{out}/eval-{t}/report.json"))
        pts = {p["min_neighbors"]: p for p in rep["points"]}
        stages = len(list(ET.parse(f"{out}/{t}/cascade.xml").getroot().find(".//stages")))
        # The minNeighbors chosen on the calibration frames (never on these test frames).
        chosen = json.load(open(f"{out}/calib-{t}/report.json"))["chosen_min_neighbors"]
        res[t] = (rep, pts, stages, chosen, run_cost(out, t))
    rep = res["rccar"][0]
    print(f"\nwindow {w}x{h}; {nvec} positives in the .vec; opencv_traincascade -numPos {npos} -numNeg {nneg}")
    print(f"test: {rep['boxes']} stop signs on {rep['sign_frames']} photos, "
          f"{rep['negative_frames']} frames without the sign")
    print("\n| trainer | stages | recall / FP per negative frame at minNeighbors 3 | "
          "at the minNeighbors chosen on the calibration frames | wall | CPU | peak RSS |")
    print("|---|---|---|---|---|---|---|")
    for t, (rep, pts, stages, chosen, (wall, cpu, rss)) in res.items():
        b = f"mn {chosen}: {fmt(pts[chosen])}" if chosen is not None else "none chosen"
        print(f"| {NAMES[t]} | {stages} | {fmt(pts[3])} | {b} | {wall} | {cpu / 60:.1f} min | {rss / 1024:.0f} MiB |")
    print("\n| minNeighbors | " + " | ".join(NAMES[t] + ": recall / FP per negative frame" for t in res) + " |")
    print("|---" * (len(res) + 1) + "|")
    for mn in range(0, 11):
        print(f"| {mn} | " + " | ".join(fmt(res[t][1][mn]) for t in res) + " |")
    def verdict(what, r, o):
        met = r["recall"] >= o["recall"] and r["fp_per_negative_frame"] <= o["fp_per_negative_frame"] + 0.01
        print(f"issue 28, {what}: recall {r['recall']:.3f} >= {o['recall']:.3f} and FP per negative frame "
              f"{r['fp_per_negative_frame']:.3f} <= {o['fp_per_negative_frame']:.3f} + 0.01: {'met' if met else 'NOT met'}")

    oo = res["opencv"]
    for t in [t for t in res if t != "opencv"]:
        rr = res[t]
        print(f"\n{NAMES[t]}:")
        verdict("both at minNeighbors 3", rr[1][3], oo[1][3])
        if rr[3] is not None and oo[3] is not None:
            verdict(f"each at its chosen minNeighbors ({rr[3]} and {oo[3]})", rr[1][rr[3]], oo[1][oo[3]])
        if rr[3] is not None:
            verdict(f"rccar-train at its chosen {rr[3]}, opencv_traincascade at 3", rr[1][rr[3]], oo[1][3])

if __name__ == "__main__":
    if len(sys.argv) != 7:
        sys.exit("usage: table.py OUT W H NVEC NPOS NNEG")
    main(*sys.argv[1:7])

#!/usr/bin/env python3
"""Chooses `[colour_template]` options on a tuning list, by grid search (run by hand; the
chosen values are in config/car.toml and docs/detect.md).

  tune_colour.py RCCAR LIST PREFIX... > table

Runs `RCCAR detect --method colour-template --explain` on the photos of LIST (an info.dat)
whose paths start with one of the PREFIXes, for every combination of the grid below with
min_score -1 (so every template score is printed), then scores each min_score threshold
afterwards. Prints recall and false boxes per photo for every combination, best first:
highest recall at <= 0.05 false boxes per photo. Tune on photos you will not score on.
"""
import itertools
import json
import os
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from score import match, read_list  # noqa: E402

GRID = {
    "hue_low_max": [6, 8, 10],
    "sat_min": [90, 110, 130, 150],
    "merge_px": [0, 1],
    "rim_value_ratio": [0.0, 0.6, 0.8],
    "min_size_px": [6, 8, 10],
}
SCORES = [0.3, 0.4, 0.5, 0.6, 0.7]


def main():
    rccar, lst, prefixes = sys.argv[1], sys.argv[2], sys.argv[3:]
    items = [x for x in read_list(lst) if any(x[0].startswith(p) for p in prefixes)]
    base = items[0][2]
    rows = []
    for values in itertools.product(*GRID.values()):
        opts = dict(zip(GRID, values))
        sets = [f"--set=colour_template.{k}={v}" for k, v in opts.items()] + ["--set=colour_template.min_score=-1"]
        out = subprocess.run(
            [rccar, "detect", "--no-annotate", "--no-local", "--method", "colour-template", "--explain", *sets]
            + [p for p, _, _ in items],
            cwd=base, capture_output=True, text=True, check=True,
        ).stdout
        cands = {}
        for line in out.splitlines():
            r = json.loads(line)
            cands[r["image"]] = r["candidates"]
        for s in SCORES:
            tp = fp = n = 0
            for p, truth, _ in items:
                k = opts_face(cands[p], s)
                t, f = match(k, truth)
                tp, fp, n = tp + t, fp + f, n + len(truth)
            rows.append((tp / n, fp / len(items), dict(opts, min_score=s), tp, n, fp))
    ok = sorted((r for r in rows if r[1] <= 0.05), key=lambda r: (-r[0], r[1]))
    print(f"{len(items)} photos; best at <= 0.05 false boxes per photo:")
    for r in ok[:15]:
        print(f"recall {r[3]}/{r[4]} = {r[0]:.3f}  false {r[5]} = {r[1]:.3f}/photo  {r[2]}")


def opts_face(cands, min_score):
    """The face boxes of the candidates that pass `min_score` (the red box grown by the
    default face_per_red, as the detector does)."""
    out = []
    for c in cands:
        if c["verdict"] in ("sign", "low_score") and c["score"] is not None and c["score"] >= min_score:
            out.append(grow(c, FACE_PER_RED))
    return out


FACE_PER_RED = 1.1  # [colour_template] face_per_red


def grow(c, k):
    x0, y0 = c["x"], c["y"]
    x1, y1 = x0 + c["width"] - 1, y0 + c["height"] - 1
    cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
    fw, fh = round(c["width"] * k), round(c["height"] * k)
    return (round(cx - (fw - 1) / 2), round(cy - (fh - 1) / 2), fw, fh)


if __name__ == "__main__":
    main()

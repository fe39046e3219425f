#!/usr/bin/env python3
"""Scores detector boxes against a labelled photo list (an info.dat; a line with 0 boxes is a
photo without the object) and optional lists of frames without it (bg.txt).

  score.py --info LIST [--bg LIST ...] [--rccar JSONL ...] [--opencv CASCADE] [--name TEXT]

--rccar    `rccar detect --no-annotate` output (one JSON line per image, boxes of one
           detector), run from the list's folder on the list's paths; one file per list,
           in the order --info, then each --bg.
--opencv   also run OpenCV's CascadeClassifier.detectMultiScale with the car's parameters
           (scale factor 1.1, minNeighbors 3, no size limits: `[detect]` of config/car.toml and
           `rccar detect`'s defaults) on the same PNGs, score it, and count the images where
           rccar's boxes are OpenCV's exactly.
A detection matches a labelled box when IoU >= 0.5 (greedy, best first, one to one, as
rccar-train evaluate). Prints recall, false boxes per photo of the --info list, and false boxes
per frame of each --bg list.
"""
import argparse
import json
import os


def read_list(path):
    base = os.path.dirname(os.path.abspath(path))
    out = []
    for line in open(path):
        t = line.split()
        if not t or t[0].startswith("#"):
            continue
        n = int(t[1]) if len(t) > 1 else 0
        out.append((t[0], [tuple(map(int, t[2 + 4 * i : 6 + 4 * i])) for i in range(n)], base))
    return out


def iou(a, b):
    ix = max(0, min(a[0] + a[2], b[0] + b[2]) - max(a[0], b[0]))
    iy = max(0, min(a[1] + a[3], b[1] + b[3]) - max(a[1], b[1]))
    i = ix * iy
    u = a[2] * a[3] + b[2] * b[3] - i
    return i / u if u > 0 else 0.0


def matched(dets, truth, thr=0.5):
    """For each true box, the detection matched to it (greedy one-to-one, best IoU first), or None."""
    pairs = sorted(((iou(d, t), i, j) for i, d in enumerate(dets) for j, t in enumerate(truth)), reverse=True)
    du, res = set(), [None] * len(truth)
    for v, i, j in pairs:
        if v >= thr and i not in du and res[j] is None:
            du.add(i)
            res[j] = dets[i]
    return res


def match(dets, truth, thr=0.5):
    tp = sum(m is not None for m in matched(dets, truth, thr))
    return tp, len(dets) - tp


def read_rccar(path):
    out = {}
    for line in open(path):
        r = json.loads(line)
        out[r["image"]] = [(b["x"], b["y"], b["width"], b["height"]) for b in r["boxes"]]
    return out


def opencv_boxes(cascade, lst):
    import cv2

    c = cv2.CascadeClassifier(cascade)
    if c.empty():
        raise SystemExit(f"{cascade}: OpenCV cannot load it")
    out = {}
    for p, _, base in lst:
        g = cv2.cvtColor(cv2.imread(os.path.join(base, p)), cv2.COLOR_BGR2GRAY)
        out[p] = [tuple(int(v) for v in r) for r in c.detectMultiScale(g, 1.1, 3)]
    return out


def score(lst, boxes):
    tp = fp = n = 0
    for p, truth, _ in lst:
        t, f = match(boxes.get(p, []), truth)
        tp, fp, n = tp + t, fp + f, n + len(truth)
    return tp, n, fp, len(lst)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--info", required=True)
    ap.add_argument("--bg", action="append", default=[])
    ap.add_argument("--rccar", action="append", default=[])
    ap.add_argument("--opencv")
    ap.add_argument("--name", default="")
    a = ap.parse_args()
    lists = [read_list(a.info)] + [read_list(b) for b in a.bg]
    rows = []
    if a.rccar:
        if len(a.rccar) != len(lists):
            raise SystemExit("give one --rccar file per list (--info first, then each --bg)")
        rows.append(("rccar", [read_rccar(f) for f in a.rccar]))
    if a.opencv:
        rows.append(("OpenCV", [opencv_boxes(a.opencv, l) for l in lists]))
    for who, per in rows:
        tp, n, fp, photos = score(lists[0], per[0])
        s = f"{a.name:<28} {who:<7} recall {tp:>3}/{n:<3} = {tp / max(n, 1):.3f}   false boxes {fp:>4} on {photos} photos = {fp / max(photos, 1):.3f}/photo"
        for b, l, boxes in zip(a.bg, lists[1:], per[1:]):
            _, _, f, frames = score(l, boxes)
            s += f"   {os.path.basename(b)}: {f} on {frames} = {f / max(frames, 1):.3f}/frame"
        print(s)
    if len(rows) == 2:
        same = sum(sorted(rows[0][1][k].get(p, [])) == sorted(rows[1][1][k].get(p, [])) for k, l in enumerate(lists) for p, _, _ in l)
        total = sum(len(l) for l in lists)
        print(f"{'':<28} rccar's boxes are OpenCV's exactly on {same} of {total} images")


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""Writes an OpenCV .vec file (opencv_traincascade's -vec) from info.dat files (run by compare.sh).

    vec.py OUT.vec WxH INFO.dat...

Every box of every info.dat line (`path count x y w h ...`, paths relative to the info.dat
or absolute) is cut out and resized to W x H with OpenCV's bit-exact bilinear resize
(INTER_LINEAR_EXACT), as rccar-train's loader does (training/src/samples.rs), so both trainers
are given the same pixels. Boxes smaller than the window or outside the image are skipped, as
rccar-train skips them. Prints the number of samples written.

The .vec format: a header of int32 count, int32 w*h, int16 0, int16 0; then per sample one
zero byte and w*h int16 grey values, row by row.
"""
import os
import struct
import sys

import cv2
import numpy as np


def main(out, window, infos):
    w, h = (int(v) for v in window.lower().split("x"))
    samples = []
    skipped = 0
    for info in infos:
        base = os.path.dirname(os.path.abspath(info))
        for line in open(info, encoding="utf-8"):
            f = line.split()
            if len(f) < 2 or f[0].startswith("#"):
                continue
            n = int(f[1])
            if n == 0:
                continue
            img = cv2.imread(os.path.join(base, f[0]), cv2.IMREAD_GRAYSCALE)
            if img is None:
                sys.exit(f"{info}: cannot read {f[0]}")
            for i in range(n):
                x, y, bw, bh = (int(v) for v in f[2 + 4 * i: 6 + 4 * i])
                if bw < w or bh < h or x < 0 or y < 0 or x + bw > img.shape[1] or y + bh > img.shape[0]:
                    skipped += 1
                    continue
                crop = img[y:y + bh, x:x + bw]
                samples.append(cv2.resize(crop, (w, h), interpolation=cv2.INTER_LINEAR_EXACT))
    with open(out, "wb") as o:
        o.write(struct.pack("<iihh", len(samples), w * h, 0, 0))
        for s in samples:
            o.write(b"\0")
            o.write(s.astype("<i2").tobytes())
    print(f"{out}: {len(samples)} samples of {w}x{h} ({skipped} boxes skipped: smaller than the window or outside)")


if __name__ == "__main__":
    if len(sys.argv) < 4:
        sys.exit("usage: vec.py OUT.vec WxH INFO.dat...")
    main(sys.argv[1], sys.argv[2], sys.argv[3:])

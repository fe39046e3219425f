#!/usr/bin/env python3
"""Sign by sign: which of two cascades finds each labelled box (issue 28, compare.sh).

Recall alone hides how two detectors differ: 40 against 41 of 48 may be one sign apart or
ten each way. This runs `rccar detect` with each cascade at its own minNeighbors on the same
labelled frames, matches boxes as `rccar-train evaluate` does (greedy, one-to-one, best IoU
first, IoU >= 0.5) and prints, per pair of minNeighbors, how many signs both found, only one
found, or neither, with the exact two-sided sign test on the signs only one found (McNemar's
exact test: under "the two are equally good", each such sign is a coin toss). It also prints
how many raw hits each cascade's box on a found sign merges (the `neighbors` of the matched box
at minNeighbors 1): a cascade whose true signs get fewer hits is at a stricter point of its
curve at the same minNeighbors.

    python3 paired.py RCCAR INFO NAME_A CASCADE_A NAME_B CASCADE_B MN_A:MN_B [MN_A:MN_B ...]

RCCAR   the rccar binary; INFO  an info.dat of the test frames with boxes (x y w h, absolute
paths or relative to INFO); MN_A:MN_B  minNeighbors of A and of B for one comparison.
Standard library and training/realsets/score.py.
"""
import json
import math
import os
import subprocess
import sys

# The one IoU and greedy matching of the real-photo scripts (training/realsets/score.py).
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "realsets"))
from score import matched  # noqa: E402


def read_info(path):
    frames = []
    base = os.path.dirname(os.path.abspath(path))
    with open(path) as f:
        for no, line in enumerate(f, 1):
            p = line.split()
            if not p:
                continue
            try:
                n = int(p[1]) if len(p) > 1 else 0
                v = [int(x) for x in p[2:2 + 4 * n]]
            except ValueError:
                sys.exit(f"{path}:{no}: expected `file n x y w h ...`")
            if len(v) != 4 * n:
                sys.exit(f"{path}:{no}: {n} boxes need {4 * n} numbers, found {len(v)}")
            img = p[0] if os.path.isabs(p[0]) else os.path.join(base, p[0])
            frames.append((img, [tuple(v[i:i + 4]) for i in range(0, len(v), 4)]))
    return frames


def detect(rccar, cascade, mn, images):
    """{image: [(x, y, w, h, neighbors)]} from one `rccar detect` run."""
    out = subprocess.run(
        [rccar, "detect", "--no-annotate", "--no-local", "--cascade", cascade, "--min-neighbors", str(mn), *images],
        capture_output=True, text=True)
    if out.returncode != 0:
        sys.exit(f"rccar detect {cascade} failed ({out.returncode}): {out.stderr.strip()}")
    found = {}
    for line in out.stdout.splitlines():
        r = json.loads(line)
        found[r["image"]] = [(b["x"], b["y"], b["width"], b["height"], b["neighbors"]) for b in r["boxes"]]
    return found


def sign_test(b, c):
    """Exact two-sided binomial p-value of b against c successes at p = 1/2."""
    n = b + c
    if n == 0:
        return 1.0
    k = min(b, c)
    p = sum(math.comb(n, i) for i in range(k + 1)) / 2 ** n
    return min(1.0, 2 * p)


def main(argv):
    if len(argv) < 8:
        sys.exit(__doc__)
    rccar, info, na, ca, nb, cb = argv[1:7]
    pairs = []
    for s in argv[7:]:
        try:
            a, b = s.split(":")
            pairs.append((int(a), int(b)))
        except ValueError:
            sys.exit(f"{s}: expected MN_A:MN_B, e.g. 3:3")
    frames = [f for f in read_info(info) if f[1]]
    images = [f[0] for f in frames]
    total = sum(len(t) for _, t in frames)
    cache = {}

    def run(name, cascade, mn):
        if (name, mn) not in cache:
            cache[(name, mn)] = detect(rccar, cascade, mn, images)
        return cache[(name, mn)]

    print(f"{total} signs on {len(frames)} frames ({info})")
    for mna, mnb in pairs:
        da, db = run(na, ca, mna), run(nb, cb, mnb)
        both = only_a = only_b = neither = 0
        for img, truth in frames:
            ma = matched(da.get(img, []), truth)
            mb = matched(db.get(img, []), truth)
            for x, y in zip(ma, mb):
                if x and y:
                    both += 1
                elif x:
                    only_a += 1
                elif y:
                    only_b += 1
                else:
                    neither += 1
        print(f"{na} at minNeighbors {mna}, {nb} at {mnb}: both {both}, only {na} {only_a}, "
              f"only {nb} {only_b}, neither {neither}; recall {(both + only_a) / total:.3f} / "
              f"{(both + only_b) / total:.3f}; sign test on the {only_a + only_b} signs only one found: "
              f"p = {sign_test(only_a, only_b):.3f}")
    for name, cascade in ((na, ca), (nb, cb)):
        d = run(name, cascade, 1)
        hits = sorted(m[4] for img, truth in frames for m in matched(d.get(img, []), truth) if m)
        if hits:
            med = hits[len(hits) // 2]
            print(f"{name}: raw hits merged into the box of a found sign (minNeighbors 1, {len(hits)} signs): "
                  f"median {med}, quartiles {hits[len(hits) // 4]}..{hits[3 * len(hits) // 4]}, "
                  f"at most 3: {sum(h <= 3 for h in hits)}")


if __name__ == "__main__":
    main(sys.argv)

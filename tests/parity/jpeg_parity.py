#!/usr/bin/env python3
"""JPEG decoded like OpenCV (issue 13): `rccar::imageio` against `cv2.imread`.

Files: OpenCV's sample JPEGs (Debian opencv-doc, /usr/share/doc/opencv-doc/examples/data/*.jpg,
never copied into the repository) and frames of rccar's own simulated track (`rccar synth`)
written by cv2.imwrite at qualities 50, 75, 95 with 4:4:4, 4:2:2 and 4:2:0 chroma subsampling,
plus a grey JPEG.

Checks per file: (1) the decoded pixels are identical to cv2.imread(IMREAD_COLOR) (grey files:
IMREAD_GRAYSCALE); (2) `rccar detect` on the JPEG gives the boxes cv2.CascadeClassifier gives on
cv2's decoding (stock frontalface_default and the shipped stop-sign cascade, (1.1, 3)).
The Rust side is rccar's default features (issue 28: `jpeg-turbo`, libjpeg-turbo's code via the
mozjpeg crate, is a default feature), built with the target selection of tests/all.sh's first
stage so nothing is compiled again; RCCAR_JPEG_CARGO adds cargo flags. tests/all.sh sets it to
its `--features` (the car's hardware features on top of the defaults: they touch no decoding,
and the decode example reports that JPEG goes through libjpeg-turbo). With
RCCAR_JPEG_CARGO="--no-default-features --features parallel" (the build without a C compiler:
JPEG through the pure-Rust decoder; only the binaries and the example are built) it reports how
far that decoder is from OpenCV. The decode example must say whether JPEG goes through
libjpeg-turbo: with the default features it must. Prints "N passed, N failed" and exits
non-zero on a failure.

    RCCAR_PYTHON=... python3 tests/parity/jpeg_parity.py
"""
import glob
import json
import os
import subprocess
import sys
import tempfile

import cv2
import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CARGO_FLAGS = os.environ.get("RCCAR_JPEG_CARGO", "").split()
DOC = "/usr/share/doc/opencv-doc/examples/data/"
CASCADES = ["/usr/share/opencv4/haarcascades/haarcascade_frontalface_default.xml",
            os.path.join(ROOT, "config", "cascades", "stop_sign.xml")]


def cargo(*args):
    return subprocess.run(["cargo", *args[:1], "--release", "--quiet", *CARGO_FLAGS, *args[1:]], cwd=ROOT,
                          capture_output=True, text=True)


def main():
    tmp = tempfile.mkdtemp(prefix="rccar_jpeg_")
    files = sorted(glob.glob(DOC + "*.jpg"))
    if not files:
        print("opencv-doc sample JPEGs not installed (apt-get install opencv-doc)")
    # The project's own frames, written as JPEG at several qualities and subsamplings.
    # With the default features: the target selection of tests/all.sh's first stage (nothing
    # recompiled); without them: the binaries and the example only.
    no_defaults = "--no-default-features" in CARGO_FLAGS
    b = cargo("build", *(["--bins", "--example", "decode"] if no_defaults else ["--workspace", "--all-targets"]))
    if b.returncode != 0:
        print("FAIL build:", b.stderr[-2000:])
        print("0 passed, 1 failed")
        return 1
    synth = os.path.join(tmp, "synth")
    subprocess.run([os.path.join(ROOT, "target", "release", "rccar"), "synth", synth], cwd=ROOT,
                   capture_output=True)
    frames = sorted(glob.glob(os.path.join(synth, "*.png")))[::20][:3]
    samp = {"444": cv2.IMWRITE_JPEG_SAMPLING_FACTOR_444, "422": cv2.IMWRITE_JPEG_SAMPLING_FACTOR_422,
            "420": cv2.IMWRITE_JPEG_SAMPLING_FACTOR_420}
    for k, f in enumerate(frames):
        im = cv2.imread(f, cv2.IMREAD_COLOR)
        for q in (50, 75, 95):
            for sname, sv in samp.items():
                p = os.path.join(tmp, f"frame{k}_q{q}_{sname}.jpg")
                cv2.imwrite(p, im, [cv2.IMWRITE_JPEG_QUALITY, q, cv2.IMWRITE_JPEG_SAMPLING_FACTOR, sv])
                files.append(p)
        g = os.path.join(tmp, f"frame{k}_grey.jpg")
        cv2.imwrite(g, cv2.cvtColor(im, cv2.COLOR_BGR2GRAY), [cv2.IMWRITE_JPEG_QUALITY, 80])
        files.append(g)
    out = os.path.join(tmp, "decoded")
    r = subprocess.run([os.path.join(ROOT, "target", "release", "examples", "decode"), out, *files], cwd=ROOT,
                       capture_output=True, text=True)
    head = r.stdout.strip().splitlines()[0] if r.stdout.strip() else "decode printed nothing"
    print(head, r.stderr.strip()[-500:])
    passed = failed = 0
    # The default features decode JPEG with libjpeg-turbo (issue 28).
    if not no_defaults:
        if head == "jpeg_like_opencv true":
            passed += 1
        else:
            failed += 1
            print("FAIL the default build does not decode JPEG with libjpeg-turbo (feature jpeg-turbo)")
    worst = []
    same = 0
    for f in files:
        stem = os.path.splitext(os.path.basename(f))[0]
        ref = cv2.imread(f, cv2.IMREAD_UNCHANGED)
        ours = cv2.imread(os.path.join(out, stem + ".png"), cv2.IMREAD_UNCHANGED)
        if ours is None or ref is None or ours.shape != ref.shape:
            print(f"FAIL {stem}: shapes {None if ref is None else ref.shape} vs {None if ours is None else ours.shape}")
            failed += 1
            continue
        if ref.ndim == 3:
            ref = cv2.imread(f, cv2.IMREAD_COLOR)
        d = np.abs(ref.astype(int) - ours.astype(int))
        n = int((d > 0).sum())
        if n == 0:
            passed += 1
            same += 1
        else:
            failed += 1
            worst.append((stem, n, int(d.max())))
    print(f"pixels: {same}/{len(files)} files identical to cv2.imread"
          + (f"; differing: " + ", ".join(f"{s} ({n} values, max {m})" for s, n, m in worst[:12]) if worst else ""))
    # Boxes: rccar detect on the JPEGs against OpenCV on its own decoding.
    box_pass = box_fail = 0
    for casc in CASCADES:
        if not os.path.isfile(casc):
            continue
        run = subprocess.run([os.path.join(ROOT, "target", "release", "rccar"), "detect", "--no-annotate",
                              "--cascade", casc, *files], capture_output=True, text=True)
        lines = [json.loads(l) for l in run.stdout.splitlines() if l.strip()]
        cc = cv2.CascadeClassifier(casc)
        for f, res in zip(files, lines):
            im = cv2.imread(f, cv2.IMREAD_COLOR)
            g = cv2.cvtColor(im, cv2.COLOR_BGR2GRAY)
            ref = sorted(tuple(int(v) for v in b) for b in cc.detectMultiScale(g, 1.1, 3))
            got = sorted((b["x"], b["y"], b["width"], b["height"]) for b in res["boxes"])
            if ref == got:
                box_pass += 1
            else:
                box_fail += 1
                print(f"  boxes differ: {os.path.basename(casc)} on {os.path.basename(f)}: cv2 {ref} ours {got}")
    print(f"boxes: {box_pass}/{box_pass + box_fail} image x cascade runs identical to cv2")
    passed += box_pass
    failed += box_fail
    print(f"{passed} passed, {failed} failed")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())

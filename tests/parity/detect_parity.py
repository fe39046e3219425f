#!/usr/bin/env python3
"""Parity of `rccar detect` with OpenCV 4.x `cv2.CascadeClassifier.detectMultiScale` (issue 4).

Both run on the same greyscale images with the cascades Debian's opencv-data installs
(/usr/share/opencv4/{haar,lbp}cascades; never copied into the repository):

  * real photos from scikit-image's sample data (pip package), some resized to 320x240 and
    640x480, and images this script generates (textured scenes with pasted, scaled, brightened
    face crops and noise, seeded; small face crops from 24x24 up, odd sizes and thin strips),
    and frames of rccar's own simulated track (`rccar synth`);
  * cascades: frontalface_default (stumps), frontalface_alt (stumps) and the same cascade
    converted here to the old `opencv-haar-classifier` format (Debian ships none of the face
    cascades in that format; the file is written to a temp dir and never committed),
    fullbody (tilted features), lbpcascade_frontalface (LBP), eye_tree_eyeglasses (trees),
    licence_plate_rus_16stages (old format as shipped), lbpcascade_frontalface_improved;
  * parameter sets: OpenCV's defaults (1.1, 3), (1.2, 5, minSize 30x30), raw hits (1.1, 0);
    the full run adds (1.05, 2, maxSize 150x150) and (1.3, 1, minSize = maxSize = 50x50).

A box of OpenCV's is matched by one of ours at IoU >= 0.9 (greedy, best first). Checks per
cascade: >= 99% of OpenCV's boxes matched and the same box count in >= 95% of images. Every
difference is listed. Prints "N passed, N failed" (checks) and exits non-zero on a failure.

    RCCAR_BIN=target/release/rccar python3 tests/parity/detect_parity.py [--quick]
"""
import json
import os
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ET

import cv2
import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
BIN = os.environ.get("RCCAR_BIN", os.path.join(ROOT, "target", "release", "rccar"))
HAAR = "/usr/share/opencv4/haarcascades/"
LBP = "/usr/share/opencv4/lbpcascades/"
QUICK = "--quick" in sys.argv


def to_old_format(src, dst):
    """Writes the current-format Haar cascade `src` in the old opencv-haar-classifier format."""
    root = ET.parse(src).getroot()
    c = root[0]
    w, h = c.find("width").text.strip(), c.find("height").text.strip()
    feats = c.find("features").findall("_")
    out = ['<?xml version="1.0"?>', "<opencv_storage>",
           '<converted_cascade type_id="opencv-haar-classifier">', f"  <size>{w} {h}</size>", "  <stages>"]
    for si, st in enumerate(c.find("stages").findall("_")):
        out.append("    <_>")
        out.append("      <trees>")
        for wc in st.find("weakClassifiers").findall("_"):
            nodes = wc.find("internalNodes").text.split()
            leaves = wc.find("leafValues").text.split()
            out.append("        <_>")
            for k in range(0, len(nodes), 4):
                left, right, fi, thr = int(nodes[k]), int(nodes[k + 1]), int(nodes[k + 2]), nodes[k + 3]
                f = feats[fi]
                rects = "".join(f"<_>{r.text.strip()}</_>" for r in f.find("rects").findall("_"))
                tilted = f.find("tilted").text.strip() if f.find("tilted") is not None else "0"
                out.append(f"          <_><feature><rects>{rects}</rects><tilted>{tilted}</tilted></feature>")
                out.append(f"            <threshold>{thr}</threshold>")
                out.append(f"            <left_val>{leaves[-left]}</left_val>" if left <= 0 else f"            <left_node>{left}</left_node>")
                out.append(f"            <right_val>{leaves[-right]}</right_val></_>" if right <= 0 else f"            <right_node>{right}</right_node></_>")
            out.append("        </_>")
        out.append("      </trees>")
        out.append(f"      <stage_threshold>{st.find('stageThreshold').text.strip()}</stage_threshold>")
        out.append(f"      <parent>{si - 1}</parent><next>-1</next></_>")
    out += ["  </stages>", "</converted_cascade>", "</opencv_storage>"]
    with open(dst, "w") as fh:
        fh.write("\n".join(out) + "\n")


def photos():
    """(name, grey image) pairs from scikit-image's sample data, plus resized variants."""
    import skimage.data as d
    names = ["astronaut", "camera", "coffee", "chelsea", "rocket", "immunohistochemistry", "page", "text",
             "moon", "coins", "brick", "grass", "gravel", "horse", "cat", "logo", "colorwheel", "hubble_deep_field"]
    if QUICK:
        names = names[:6]
    out = []
    for n in names:
        try:
            im = getattr(d, n)()
        except Exception as e:  # a missing sample is reported, not fatal
            print(f"  (skipping skimage.data.{n}: {e})")
            continue
        if im.dtype != np.uint8:
            im = (im * 255).astype(np.uint8) if im.max() <= 1 else im.astype(np.uint8)
        if im.ndim == 3:
            im = cv2.cvtColor(np.ascontiguousarray(im[..., :3]), cv2.COLOR_RGB2GRAY)
        out.append((n, im))
    for n, im in list(out[:4]):
        for (w, h) in [(320, 240), (640, 480)]:
            out.append((f"{n}_{w}x{h}", cv2.resize(im, (w, h), interpolation=cv2.INTER_AREA)))
    return out


def generated(count):
    """Seeded synthetic scenes: gradients, shapes, noise and pasted face crops."""
    import skimage.data as d
    face = cv2.cvtColor(d.astronaut(), cv2.COLOR_RGB2GRAY)[30:250, 130:330]
    body = cv2.cvtColor(d.astronaut(), cv2.COLOR_RGB2GRAY)
    out = []
    for i in range(count):
        rng = np.random.default_rng(1000 + i)
        w, h = [(320, 240), (640, 480)][i % 2]
        yy, xx = np.mgrid[0:h, 0:w]
        img = (rng.uniform(40, 200) + rng.uniform(-0.2, 0.2) * xx + rng.uniform(-0.2, 0.2) * yy).astype(np.float64)
        for _ in range(rng.integers(3, 12)):
            x0, y0 = rng.integers(0, w), rng.integers(0, h)
            col = float(rng.uniform(0, 255))
            if rng.random() < 0.5:
                cv2.rectangle(img, (int(x0), int(y0)), (int(x0 + rng.integers(5, 120)), int(y0 + rng.integers(5, 120))), col, -1)
            else:
                cv2.circle(img, (int(x0), int(y0)), int(rng.integers(3, 60)), col, -1)
        src = face if i % 3 else body
        for _ in range(rng.integers(1, 4)):
            s = rng.uniform(0.2, 0.9) * min(w / src.shape[1], h / src.shape[0])
            f = cv2.resize(src, None, fx=s, fy=s, interpolation=cv2.INTER_AREA).astype(np.float64)
            f = f * rng.uniform(0.6, 1.3) + rng.uniform(-30, 30)
            fh, fw = f.shape
            if fw >= w or fh >= h:
                continue
            x0, y0 = rng.integers(0, w - fw), rng.integers(0, h - fh)
            img[y0:y0 + fh, x0:x0 + fw] = f
        img += rng.normal(0, rng.uniform(0, 12), img.shape)
        out.append((f"gen{i:02d}_{w}x{h}", np.clip(img, 0, 255).astype(np.uint8)))
    return out


def tiny():
    """Small crops around the astronaut's face: sizes at and just above the 24x24 window, odd
    sizes and thin strips, where the scale list and the level sizes have their edge cases."""
    import skimage.data as d
    g = cv2.cvtColor(d.astronaut(), cv2.COLOR_RGB2GRAY)
    out = []
    for (w, h) in [(24, 24), (25, 26), (31, 40), (48, 48), (61, 37), (99, 24), (24, 99), (120, 90)]:
        face = cv2.resize(g[40:240, 140:320], (w, h), interpolation=cv2.INTER_AREA)
        out.append((f"tiny_{w}x{h}", face))
    return out


def lane_frames(tmp, count):
    """Frames of rccar's own simulated track (`rccar synth`, the lane tests' data), grey."""
    out_dir = os.path.join(tmp, "synth")
    run = subprocess.run([BIN, "synth", out_dir], cwd=ROOT, capture_output=True, text=True)
    if run.returncode != 0:
        print(f"  (rccar synth failed, using tests/data/lane_sample: {run.stderr.strip()[:200]})")
        out_dir = os.path.join(ROOT, "tests", "data", "lane_sample")
    names = sorted(n for n in os.listdir(out_dir) if n.endswith(".png"))
    step = max(1, len(names) // count)
    out = []
    for n in names[::step][:count]:
        im = cv2.imread(os.path.join(out_dir, n), cv2.IMREAD_COLOR)
        out.append((f"synth_{n[:-4]}", cv2.cvtColor(im, cv2.COLOR_BGR2GRAY)))
    return out


def match(ref, ours):
    """Greedy IoU matching; returns (matched pairs, unmatched ref, unmatched ours)."""
    def iou(a, b):
        x0, y0 = max(a[0], b[0]), max(a[1], b[1])
        x1, y1 = min(a[0] + a[2], b[0] + b[2]), min(a[1] + a[3], b[1] + b[3])
        i = max(0, x1 - x0) * max(0, y1 - y0)
        u = a[2] * a[3] + b[2] * b[3] - i
        return i / u if u > 0 else 0.0
    pairs = sorted(((iou(a, b), i, j) for i, a in enumerate(ref) for j, b in enumerate(ours)), reverse=True)
    used_r, used_o, got = set(), set(), []
    for v, i, j in pairs:
        if v < 0.9:
            break
        if i in used_r or j in used_o:
            continue
        used_r.add(i), used_o.add(j), got.append((i, j, v))
    return got, [ref[i] for i in range(len(ref)) if i not in used_r], [ours[j] for j in range(len(ours)) if j not in used_o]


def main():
    cv2.setNumThreads(1)
    if not os.path.exists(BIN):
        print(f"{BIN} is missing: run `cargo build --release` first\n0 passed, 1 failed")
        return 1
    tmp = tempfile.mkdtemp(prefix="rccar_detect_parity_")
    old_alt = os.path.join(tmp, "haarcascade_frontalface_alt_oldformat.xml")
    to_old_format(HAAR + "haarcascade_frontalface_alt.xml", old_alt)
    cascades = [HAAR + "haarcascade_frontalface_default.xml", HAAR + "haarcascade_frontalface_alt.xml", old_alt,
                HAAR + "haarcascade_fullbody.xml", LBP + "lbpcascade_frontalface.xml",
                HAAR + "haarcascade_eye_tree_eyeglasses.xml", HAAR + "haarcascade_licence_plate_rus_16stages.xml",
                LBP + "lbpcascade_frontalface_improved.xml"]
    if QUICK:
        cascades = cascades[:5]
    images = photos() + generated(6 if QUICK else 20) + tiny() + lane_frames(tmp, 3 if QUICK else 10)
    paths = []
    for name, im in images:
        p = os.path.join(tmp, name + ".png")
        cv2.imwrite(p, im)
        paths.append(p)
    # (scaleFactor, minNeighbors, minSize, maxSize); maxSize (0, 0) = the image size.
    param_sets = [(1.1, 3, (0, 0), (0, 0)), (1.2, 5, (30, 30), (0, 0)), (1.1, 0, (0, 0), (0, 0))]
    if not QUICK:  # a finer pyramid capped by maxSize, and minSize == maxSize (one scale)
        param_sets += [(1.05, 2, (0, 0), (150, 150)), (1.3, 1, (50, 50), (50, 50))]
    print(f"{len(images)} images x {len(cascades)} cascades x {len(param_sets)} parameter sets, OpenCV {cv2.__version__}")

    passed = failed = 0
    totals = {}
    for casc in cascades:
        cname = os.path.basename(casc)
        cc = cv2.CascadeClassifier(casc)
        assert not cc.empty(), casc
        n_ref = n_match = n_img = n_same = n_exact = n_nb = n_nb_img = 0
        diffs = []
        for sf, mn, ms, mx in param_sets:
            args = [BIN, "detect", "--no-annotate", "--cascade", casc, "--scale-factor", str(sf),
                    "--min-neighbors", str(mn), "--min-size", f"{ms[0]}x{ms[1]}", "--max-size", f"{mx[0]}x{mx[1]}"] + paths
            run = subprocess.run(args, capture_output=True, text=True)
            if run.returncode != 0:
                print(f"FAIL {cname}: rccar exited {run.returncode}: {run.stderr.strip()}")
                failed += 1
                continue
            lines = [json.loads(l) for l in run.stdout.splitlines() if l.strip()]
            for (name, im), res in zip(images, lines):
                r, nb = cc.detectMultiScale2(im, scaleFactor=sf, minNeighbors=mn, minSize=ms, maxSize=mx)
                ref = [tuple(int(v) for v in b) for b in (r.tolist() if len(r) else [])]
                ours = [(b["x"], b["y"], b["width"], b["height"]) for b in res["boxes"]]
                got, only_ref, only_ours = match(ref, ours)
                n_exact += sum(1 for _, _, v in got if v == 1.0)
                if mn > 0:
                    ref_nb = sorted(zip(ref, (int(v) for v in np.ravel(nb))))
                    n_nb += ref_nb == sorted(zip(ours, (b["neighbors"] for b in res["boxes"])))
                    n_nb_img += 1
                n_ref += len(ref)
                n_match += len(got)
                n_img += 1
                n_same += len(ref) == len(ours)
                if only_ref or only_ours:
                    diffs.append(f"    {name} (sf {sf}, mn {mn}, min {ms}, max {mx}): OpenCV {len(ref)} ours {len(ours)};"
                                 f" OpenCV only {only_ref[:6]}; ours only {only_ours[:6]}")
        frac = n_match / n_ref if n_ref else 1.0
        same = n_same / n_img if n_img else 1.0
        ok = frac >= 0.99 and same >= 0.95
        passed += ok
        failed += not ok
        totals[cname] = (n_match, n_ref, n_same, n_img)
        print(f"{'ok  ' if ok else 'FAIL'} {cname}: {n_match}/{n_ref} OpenCV boxes matched at IoU>=0.9 ({100 * frac:.2f}%),"
              f" same count in {n_same}/{n_img} images ({100 * same:.1f}%), {len(diffs)} differing;"
              f" {n_exact} boxes identical to the pixel, neighbour counts equal in {n_nb}/{n_nb_img} grouped runs")
        for d in diffs:
            print(d)
    m = sum(v[0] for v in totals.values())
    r = sum(v[1] for v in totals.values())
    s = sum(v[2] for v in totals.values())
    i = sum(v[3] for v in totals.values())
    print(f"overall: {m}/{r} boxes matched ({100 * m / max(r, 1):.2f}%), same count in {s}/{i} image runs ({100 * s / max(i, 1):.1f}%)")
    print(f"{passed} passed, {failed} failed")
    return 0 if failed == 0 else 1


if __name__ == "__main__":
    sys.exit(main())

#!/usr/bin/env python3
"""Turns DeepPiCar's published photo set into rccar-train lists (run by deeppicar.sh).

Input: a folder holding DeepPiCar's `models/object_detection/data/images/{train,test,ver1}`
(JPEG/PNG photos of miniature road signs on a floor track, each with a labelImg/PASCAL VOC
XML file) and `models/lane_navigation/data/images/*.png` (the car's camera driving the same
track, no signs). Nothing of it is in this repository.

Output, in OUT:
  full/<split>/<name>.png   every photo decoded by OpenCV (cv2.imread) and saved as PNG, so
                            rccar and OpenCV read the same pixels whatever JPEG decoder rccar
                            was built with;
  320/<split>/<name>.png    the same at 320x240, the car's frame size (INTER_AREA; the ver1
                            photos already are 320x240);
  <res>/stop_sign.info.dat  every sign photo with its stop-sign boxes (0 boxes: a photo with
                            none, where every detection is a false box);
  <res>/traffic_light.info.dat  the same for the traffic lights (red and green labels);
  320/track.bg.txt          the lane-navigation frames: the track without signs.
Boxes are the source's own labels (VOC xmin..xmax inclusive -> x, y, w, h), scaled by 1/2 at
320 for the 640x480 photos.
"""
import glob
import os
import re
import sys

import cv2

STOP = {"Stop Sign"}
LIGHT = {"Red Traffic Light", "Green Traffic Light"}


def boxes_of(xml, names, k):
    out = []
    for obj in re.findall(r"<object>(.*?)</object>", xml, re.S):
        name = re.search(r"<name>(.*?)</name>", obj).group(1).strip()
        if name not in names:
            continue
        x0, y0, x1, y1 = (int(re.search(rf"<{t}>\s*(-?\d+)", obj).group(1)) for t in ("xmin", "ymin", "xmax", "ymax"))
        out.append((round(x0 * k), round(y0 * k), round((x1 - x0 + 1) * k), round((y1 - y0 + 1) * k)))
    return out


def line(path, boxes):
    return " ".join([path, str(len(boxes))] + [" ".join(map(str, b)) for b in boxes])


def main(src, out):
    det = os.path.join(src, "models/object_detection/data/images")
    xmls = sorted(glob.glob(os.path.join(det, "*/*.xml")))
    if len(xmls) != 91:
        sys.exit(f"{det}: expected 91 labelled photos, found {len(xmls)}")
    lists = {res: {"stop_sign": [], "traffic_light": []} for res in ("full", "320")}
    for x in xmls:
        split, stem = os.path.basename(os.path.dirname(x)), os.path.splitext(os.path.basename(x))[0]
        pic = next(p for p in (os.path.join(det, split, stem + e) for e in (".jpg", ".png")) if os.path.exists(p))
        img = cv2.imread(pic)
        xml = open(x, encoding="utf-8").read()
        h, w = img.shape[:2]
        for res in ("full", "320"):
            k = 1.0 if res == "full" else 320.0 / w
            im = img if k == 1.0 else cv2.resize(img, (320, 240), interpolation=cv2.INTER_AREA)
            rel = f"{split}/{stem}.png"
            os.makedirs(os.path.join(out, res, split), exist_ok=True)
            cv2.imwrite(os.path.join(out, res, rel), im)
            lists[res]["stop_sign"].append(line(rel, boxes_of(xml, STOP, k)))
            lists[res]["traffic_light"].append(line(rel, boxes_of(xml, LIGHT, k)))
    for res, by in lists.items():
        for cls, lines in by.items():
            with open(os.path.join(out, res, f"{cls}.info.dat"), "w") as f:
                f.write("\n".join(lines) + "\n")
    lane = sorted(glob.glob(os.path.join(src, "models/lane_navigation/data/images/*.png")))
    os.makedirs(os.path.join(out, "320", "track"), exist_ok=True)
    names = []
    for p in lane:
        img = cv2.imread(p)
        rel = "track/" + os.path.basename(p)
        cv2.imwrite(os.path.join(out, "320", rel), img)
        names.append(rel)
    with open(os.path.join(out, "320", "track.bg.txt"), "w") as f:
        f.write("\n".join(names) + "\n")
    n_stop = sum(int(l.split()[1]) for l in lists["full"]["stop_sign"])
    n_light = sum(int(l.split()[1]) for l in lists["full"]["traffic_light"])
    print(f"{out}: {len(xmls)} sign photos ({n_stop} stop signs, {n_light} traffic lights), {len(names)} track frames")


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit("usage: deeppicar.py DEEPPICAR_CHECKOUT OUT")
    main(sys.argv[1], sys.argv[2])

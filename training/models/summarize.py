#!/usr/bin/env python3
"""Prints the per-stage tables of the shipped models (from training/models/<kind>/stages.json
and report.json) as Markdown, for training/models/README.md."""
import json
import os

HERE = os.path.dirname(os.path.abspath(__file__))
total = 0.0
for kind in ["stop_sign", "traffic_light", "obstacle", "yield_sign", "turn_sign", "obstacle_light"]:
    d = os.path.join(HERE, kind)
    s = json.load(open(os.path.join(d, "stages.json")))
    r = json.load(open(os.path.join(d, "report.json")))
    t = sum(l["seconds"] for l in s["log"])
    total += t
    o = s["options"]
    p = o["params"]
    print(f"### {kind} ({p['width']}x{p['height']}, {p['mode']}, {p['boost']}, depth {p['max_depth']})\n")
    print(f"{len(s['stages'])} stages, {sum(len(x['weaks']) for x in s['stages'])} weak classifiers, "
          f"trained in {t:.1f} s; ended: {s['finished']}\n")
    print("| stage | weak | hit rate | false alarm | pos | neg | acceptance before | features | matrix MB | mine s | precompute s | boost s | total s |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for l in s["log"]:
        print(f"| {l['stage']} | {l['weak_count']} | {l['hit_rate']:.4f} | {l['false_alarm']:.4f} | {l['num_pos']} | "
              f"{l['num_neg']} | {l['acceptance_ratio']:.2e} | {l['features_used']} | {l['matrix_bytes'] / 2**20:.0f} | "
              f"{l['seconds_mining']:.1f} | {l['seconds_precompute']:.1f} | {l['seconds_boost']:.1f} | {l['seconds']:.1f} |")
    print(f"\nHeld-out ({r['frames']} frames, {r['boxes']} objects, IoU ≥ {r['iou']}), time per "
          f"{r['frame_size'][0]}x{r['frame_size'][1]} frame median {r['ms_median']:.2f} ms:\n")
    print("| minNeighbors | recall | precision | FP / frame |")
    print("|---|---|---|---|")
    for q in r["points"]:
        print(f"| {q['min_neighbors']} | {q['recall']:.4f} | {q['precision']:.4f} | {q['fp_per_frame']:.4f} |")
    print(f"\n![{kind} recall vs FP per frame]({kind}/curve.png)\n")
print(f"All three: {total:.0f} s of training (stage times summed).")

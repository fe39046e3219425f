#!/usr/bin/env python3
"""Compare the telemetry of a cross-built rccar (run under qemu-aarch64) with the native run.

    compare.py NAME NATIVE.jsonl CROSS.jsonl [--summary NATIVE.json CROSS.json]

Every frame record must have the same keys and the same values: the decisions (steer,
throttle, status, behaviour, transitions) and the lane measurement (p_left, p_right,
lane_center, error_px, error, ...) bit for bit, as serde_json prints them (shortest
round-trip form, so equal text means equal f64). Values under a `truth` object (the
simulator's ground truth: offsets in metres, headings in radians, line columns in pixels)
may differ by at most 1e-9 in absolute value: the world is moved with libm's sin/cos/atan2,
and aarch64's glibc rounds a few of those differently from x86_64's (measured ~1e-13).
Timing fields (keys ending in _us or _ms, or naming latency/wall time) are ignored: they
are wall-clock measurements, not decisions.

Prints one line per check and exits non-zero on any difference. Standard library only.
"""
import json
import re
import sys

TRUTH_TOL = 1e-9
TIMING_KEY = re.compile(r"(_us|_ms)$|latency|wall", re.IGNORECASE)
# Which run it was (the run folder's id, a time stamp): differs between any two runs.
IDENTITY_KEYS = {"run_id"}


class Diff:
    def __init__(self):
        self.count = 0
        self.first = []
        self.truth_max = 0.0
        self.truth_values = 0
        self.exact_values = 0

    def add(self, where, a, b):
        self.count += 1
        if len(self.first) < 5:
            self.first.append(f"{where}: native {a!r}, aarch64 {b!r}")


def walk(a, b, path, in_truth, d):
    """Compares two decoded JSON values; `path` names the place for messages."""
    if isinstance(a, dict) and isinstance(b, dict):
        keys = set(a) | set(b)
        for k in sorted(keys):
            if TIMING_KEY.search(k) or k in IDENTITY_KEYS:
                continue
            if k not in a or k not in b:
                d.add(f"{path}.{k}", a.get(k, "<missing>"), b.get(k, "<missing>"))
                continue
            walk(a[k], b[k], f"{path}.{k}", in_truth or k == "truth", d)
    elif isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            d.add(f"{path} (length)", len(a), len(b))
            return
        for i, (x, y) in enumerate(zip(a, b)):
            walk(x, y, f"{path}[{i}]", in_truth, d)
    elif (
        in_truth
        and isinstance(a, (int, float))
        and isinstance(b, (int, float))
        and not isinstance(a, bool)
        and not isinstance(b, bool)
    ):
        d.truth_values += 1
        err = abs(float(a) - float(b))
        d.truth_max = max(d.truth_max, err)
        if not err <= TRUTH_TOL:
            d.add(path + f" (|diff| {err:.3g} > {TRUTH_TOL})", a, b)
    else:
        d.exact_values += 1
        if type(a) is not type(b) or a != b:
            d.add(path, a, b)


def load_jsonl(path):
    out = []
    with open(path, encoding="utf-8") as f:
        for n, line in enumerate(f, 1):
            if not line.strip():
                continue
            try:
                out.append(json.loads(line))
            except json.JSONDecodeError as e:
                sys.exit(f"{path}:{n}: not JSON: {e}")
    return out


def main(argv):
    if len(argv) not in (4, 7) or (len(argv) == 7 and argv[4] != "--summary"):
        sys.exit(__doc__.strip().splitlines()[2])
    name, native_path, cross_path = argv[1], argv[2], argv[3]
    failed = 0
    try:
        native, cross = load_jsonl(native_path), load_jsonl(cross_path)
    except OSError as e:
        print(f"FAIL {name}: {e}")
        return 1
    d = Diff()
    if len(native) == 0:
        d.add("frames", 0, len(cross))
    if len(native) != len(cross):
        d.add("frames (count)", len(native), len(cross))
    for i, (a, b) in enumerate(zip(native, cross)):
        walk(a, b, f"frame {a.get('frame', i)}", False, d)
    steer_n = sum(1 for r in native if "steer" in r)
    if d.count == 0:
        msg = (
            f"ok   {name}: {len(native)} frames, {d.exact_values} decision/lane values identical"
            f" ({steer_n} steer + throttle)"
        )
        if d.truth_values:
            msg += f", {d.truth_values} truth values, max |diff| {d.truth_max:.3g} (tolerance {TRUTH_TOL})"
        print(msg)
    else:
        failed += 1
        print(f"FAIL {name}: {d.count} differences over {len(native)} native / {len(cross)} aarch64 frames")
        for line in d.first:
            print(f"     {line}")
    if len(argv) == 7:
        s = Diff()
        try:
            with open(argv[5], encoding="utf-8") as f:
                a = json.load(f)
            with open(argv[6], encoding="utf-8") as f:
                b = json.load(f)
        except (OSError, json.JSONDecodeError) as e:
            print(f"FAIL {name} summary: {e}")
            return 1
        # The score is computed from the truth: same tolerance as the truth.
        walk(a, b, "summary", True, s)
        if s.count == 0:
            print(f"ok   {name} summary: {s.exact_values + s.truth_values} values, max |diff| {s.truth_max:.3g}")
        else:
            failed += 1
            print(f"FAIL {name} summary: {s.count} differences")
            for line in s.first:
                print(f"     {line}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))

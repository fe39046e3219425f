#!/usr/bin/env python3
"""Load benchmark of the dashboard (issue 11, must-show 2). Not a test: it prints numbers.

Runs `rccar sim --dashboard` (armed through the API, heartbeats included in the load) and
measures the loop from its own telemetry (period_ms, latency_ms = capture -> command) in two
windows of the same run:

  A. no viewers, no requests            (--seconds each, default 60)
  B. 20 MJPEG viewers + 50 API requests/s, half of them bad (malformed JSON, NaN, unknown
     keys, out-of-range values, unknown paths, oversized bodies, a cross-origin arm) and half
     good (state, heartbeat, valid gains)

and prints the medians and their change, the sim process's RSS over time, the frames every
viewer received and the status codes the requests got.

Usage: python3 tests/dashboard/load_bench.py [--rccar target/release/rccar] [--seconds 60]
Build first: cargo build --release --features dashboard
"""

import argparse
import json
import os
import shutil
import socket
import statistics
import subprocess
import tempfile
import threading
import time
import urllib.error
import urllib.request

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def free_port():
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    p = s.getsockname()[1]
    s.close()
    return p


def state(base):
    with urllib.request.urlopen(base + "/api/state?since=1e300", timeout=5) as r:
        return json.loads(r.read())


def rss_kb(pid):
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    return 0


def viewer(host, port, stop, counts, i):
    try:
        s = socket.create_connection((host, port), timeout=10)
        s.sendall(b"GET /stream.mjpg HTTP/1.1\r\nHost: " + f"{host}:{port}".encode() + b"\r\n\r\n")
        tail = b""
        while not stop.is_set():
            d = s.recv(65536)
            if not d:
                break
            buf = tail + d
            counts[i] += buf.count(b"--rccarframe\r\n")
            tail = buf[-16:]
            if b"--rccarframe\r\n" in tail:
                tail = b""
        s.close()
    except OSError as e:
        counts[i] = -abs(counts[i]) - 1 if counts[i] == 0 else counts[i]
        print(f"viewer {i}: {e}")


def raw(host, port, data):
    # One request per connection (the server keeps connections alive otherwise).
    line, rest = data.split(b"\r\n", 1)
    data = line + b"\r\nConnection: close\r\n" + rest
    s = socket.create_connection((host, port), timeout=5)
    s.sendall(data)
    buf = b""
    try:
        while True:
            d = s.recv(4096)
            if not d:
                break
            buf += d
    except OSError:
        pass
    s.close()
    try:
        return int(buf.split(b" ")[1])
    except (IndexError, ValueError):
        return 0


# The page's secret (read from the page in main): controls need it, JSON and the right Host.
SECRET = ""


def post(host, port, path, body):
    b = body.encode()
    head = (f"POST {path} HTTP/1.1\r\nHost: {host}:{port}\r\nContent-Type: application/json\r\n"
            f"X-Rccar-Secret: {SECRET}\r\nContent-Length: {len(b)}\r\n\r\n")
    return raw(host, port, head.encode() + b)


def get(host, port, path):
    return raw(host, port, f"GET {path} HTTP/1.1\r\nHost: {host}:{port}\r\n\r\n".encode())


REQUESTS = [
    ("good state", lambda h, p: get(h, p, "/api/state?since=1e300")),
    ("good heartbeat", lambda h, p: post(h, p, "/api/heartbeat", "")),
    ("good kd", lambda h, p: post(h, p, "/api/set", '{"key":"steering.kd","value":0.05}')),
    ("good state", lambda h, p: get(h, p, "/api/state")),
    ("good heartbeat", lambda h, p: post(h, p, "/api/heartbeat", "")),
    ("bad json", lambda h, p: post(h, p, "/api/set", '{"key":"steering.kp","value":')),
    ("bad nan", lambda h, p: post(h, p, "/api/set", '{"key":"steering.kp","value":NaN}')),
    ("bad key", lambda h, p: post(h, p, "/api/set", '{"key":"camera.fps","value":5}')),
    ("bad range", lambda h, p: post(h, p, "/api/set", '{"key":"steering.kp","value":99}')),
    ("bad path", lambda h, p: get(h, p, "/../../etc/passwd")),
    ("bad huge", lambda h, p: raw(h, p, f"POST /api/set HTTP/1.1\r\nHost: {h}:{p}\r\nContent-Type: application/json\r\n"
                                        f"X-Rccar-Secret: {SECRET}\r\nContent-Length: 99999999\r\n\r\n".encode())),
    ("bad origin", lambda h, p: raw(h, p, f"POST /api/arm HTTP/1.1\r\nHost: {h}:{p}\r\nOrigin: http://evil.example\r\n"
                                          "Content-Type: text/plain\r\nContent-Length: 0\r\n\r\n".encode())),
]


def requester(host, port, stop, rate, tally):
    k = 0
    t0 = time.time()
    while not stop.is_set():
        name, fn = REQUESTS[k % len(REQUESTS)]
        try:
            code = fn(host, port)
        except OSError:
            code = -1
        key = f"{name} -> {code}"
        tally[key] = tally.get(key, 0) + 1
        k += 1
        nxt = t0 + k / rate
        d = nxt - time.time()
        if d > 0:
            time.sleep(d)


def window(telemetry, f0, f1):
    per, lat = [], []
    with open(telemetry) as f:
        for line in f:
            r = json.loads(line)
            if f0 <= r["frame"] < f1:
                if r.get("period_ms") is not None:
                    per.append(r["period_ms"])
                if r.get("latency_ms") is not None:
                    lat.append(r["latency_ms"])
    return per, lat


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--rccar", default=os.path.join(ROOT, "target/release/rccar"))
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--viewers", type=int, default=20)
    ap.add_argument("--rate", type=float, default=50.0)
    a = ap.parse_args()
    tmp = tempfile.mkdtemp(prefix="rccar-dash-load-")
    src = os.path.join(ROOT, "config")
    shutil.copy2(os.path.join(src, "car.toml"), os.path.join(tmp, "car.toml"))
    for name in os.listdir(src):  # tracks, cascades: resolved relative to the config file
        if name not in ("car.toml", "local.toml") and not name.endswith(".local.toml"):
            os.symlink(os.path.join(src, name), os.path.join(tmp, name))
    with open(os.path.join(tmp, "local.toml"), "w") as f:  # --local must exist
        f.write("# load bench\n")
    port = free_port()
    host = "127.0.0.1"
    base = f"http://{host}:{port}"
    out = os.path.join(tmp, "out")
    sim = subprocess.Popen(
        [a.rccar, "sim", "--dashboard", "--truth-boxes", "--listen", f"{host}:{port}",
         "--config", os.path.join(tmp, "car.toml"), "--local", os.path.join(tmp, "local.toml"),
         "--seconds", str(3 * a.seconds + 60), "--laps", "1000", "-o", out],
        cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        for _ in range(300):
            try:
                state(base)
                break
            except (OSError, ValueError, urllib.error.URLError):
                time.sleep(0.1)
        global SECRET
        with urllib.request.urlopen(base + "/", timeout=5) as r:
            page = r.read().decode()
        SECRET = page.split('name="rccar-secret" content="')[1].split('"')[0]
        # Arm, with a heartbeat thread in phase A too (phase B's load sends them as well).
        post(host, port, "/api/arm", "")
        hb_stop = threading.Event()

        def hb():
            while not hb_stop.is_set():
                post(host, port, "/api/heartbeat", "")
                time.sleep(0.25)
        threading.Thread(target=hb, daemon=True).start()
        time.sleep(5)
        mem = []
        # Phase A.
        fa0 = state(base)["frame"]
        t_end = time.time() + a.seconds
        while time.time() < t_end:
            mem.append(("A", rss_kb(sim.pid)))
            time.sleep(5)
        fa1 = state(base)["frame"]
        # Phase B.
        stop = threading.Event()
        counts = [0] * a.viewers
        tally = {}
        threads = [threading.Thread(target=viewer, args=(host, port, stop, counts, i), daemon=True)
                   for i in range(a.viewers)]
        threads.append(threading.Thread(target=requester, args=(host, port, stop, a.rate, tally), daemon=True))
        for t in threads:
            t.start()
        time.sleep(2)
        fb0 = state(base)["frame"]
        c0 = list(counts)
        t_end = time.time() + a.seconds
        while time.time() < t_end:
            mem.append(("B", rss_kb(sim.pid)))
            time.sleep(5)
        fb1 = state(base)["frame"]
        c1 = list(counts)
        st = state(base)
        stop.set()
        hb_stop.set()
        mem.append(("after", rss_kb(sim.pid)))
        time.sleep(1)
    finally:
        sim.terminate()
        sim.wait(20)
    tel = os.path.join(out, "telemetry.jsonl")
    pa, la = window(tel, fa0, fa1)
    pb, lb = window(tel, fb0, fb1)

    def row(name, x, y):
        mx, my = statistics.median(x), statistics.median(y)
        print(f"{name:<28} no viewers: median {mx:7.2f} ms min {min(x):7.2f}   "
              f"20 viewers+{a.rate:.0f} req/s: median {my:7.2f} ms min {min(y):7.2f}   change {100 * (my - mx) / mx:+.1f} %")
    print(f"windows: A frames {fa0}..{fa1} ({fa1 - fa0}), B frames {fb0}..{fb1} ({fb1 - fb0}), {a.seconds:.0f} s each")
    row("loop period", pa, pb)
    row("capture->command latency", la, lb)
    got = [c1[i] - c0[i] for i in range(a.viewers)]
    print(f"frames per viewer in B: min {min(got)}, median {statistics.median(got)}, max {max(got)} "
          f"({min(got) / a.seconds:.1f}..{max(got) / a.seconds:.1f} fps); viewers with none: {sum(1 for g in got if g <= 0)}")
    print(f"server: {st['viewers']} viewers connected at the end, {st['stream_frames']} stream frames sent in all")
    print("RSS (kB) every 5 s: " + " ".join(f"{p}:{m}" for p, m in mem))
    total = sum(tally.values())
    print(f"requests in B: {total} ({total / (a.seconds + 2):.1f}/s)")
    for k in sorted(tally):
        print(f"  {k}: {tally[k]}")
    shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""Bounded loopback load on hemibake-server (not run in CI): while N event streams watch a large job
and P clients keep asking for previews, /healthz is asked every 20 ms; prints its latency
percentiles, every status seen, and the server's RSS (VmRSS and VmHWM from /proc).

  bench/load.py [--server build/bin/hemibake-server] [--streams 64] [--previews 4] [--seconds 60]
                [--scene-mb 36]

The large job: data/cornell-box.gltf with an unused buffer of SCENE_MB bytes added (the scene is
stored, read by the worker and counted against the budgets like any other) and long shots
(resolution 1024, no reuse), so that it runs through the test. At most streams + previews + 2
connections, for at most --seconds (under 2 minutes by default limits)."""
import argparse, base64, json, os, socket, statistics, subprocess, sys, tempfile, threading, time

ap = argparse.ArgumentParser()
ap.add_argument("--server", default="build/bin/hemibake-server")
ap.add_argument("--streams", type=int, default=64)
ap.add_argument("--previews", type=int, default=4)
ap.add_argument("--seconds", type=float, default=60)
ap.add_argument("--scene-mb", type=float, default=36)
a = ap.parse_args()
assert a.streams + a.previews + 2 <= 300 and a.seconds <= 120, "bounded: <= 300 connections, <= 2 minutes"

root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
data = tempfile.mkdtemp(prefix="hemibake-load-")
proc = subprocess.Popen([a.server, "--listen", "127.0.0.1:0", "--data", data, "--workers", "1"],
                        stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
line = proc.stdout.readline()
port = int(line.split("127.0.0.1:")[1].split("/")[0])

def rss():
    out = {}
    with open(f"/proc/{proc.pid}/status") as f:
        for l in f:
            if l.startswith(("VmRSS", "VmHWM")):
                k, v = l.split(":")
                out[k] = int(v.split()[0]) / 1024
    return out

def http(method, target, body=b"", headers=None, timeout=30):
    s = socket.create_connection(("127.0.0.1", port), timeout=timeout)
    h = f"{method} {target} HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\nContent-Length: {len(body)}\r\n"
    for k, v in (headers or {}).items():
        h += f"{k}: {v}\r\n"
    s.sendall(h.encode() + b"\r\n" + body)
    chunks = []
    while True:
        c = s.recv(1 << 16)
        if not c:
            break
        chunks.append(c)
    s.close()
    raw = b"".join(chunks)
    head, _, rest = raw.partition(b"\r\n\r\n")
    return int(head.split()[1]), rest

gltf = json.load(open(os.path.join(root, "data", "cornell-box.gltf")))
pad = int(a.scene_mb * (1 << 20))
gltf["buffers"].append({"byteLength": pad, "uri": "data:application/octet-stream;base64," + base64.b64encode(bytes(pad)).decode()})
scene = json.dumps(gltf).encode()
status, body = http("POST", "/v1/jobs?resolution=1024&reuse=false&convergence=0.00001", scene,
                    {"Content-Type": "model/gltf+json"}, timeout=120)
assert status == 202, (status, body[:300])
job = json.loads(body)["id"]
print(f"job {job}: scene {len(scene) / 1e6:.1f} MB")
while json.loads(http("GET", f"/v1/jobs/{job}")[1])["state"] != "running":
    time.sleep(0.1)

stop = threading.Event()
statuses = {}
lock = threading.Lock()
def count(s):
    with lock:
        statuses[s] = statuses.get(s, 0) + 1
stream_events = [0] * a.streams

def stream(i):
    s = socket.create_connection(("127.0.0.1", port), timeout=a.seconds + 30)
    s.sendall(f"GET /v1/jobs/{job}/events HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n".encode())
    first = True
    while not stop.is_set():
        c = s.recv(1 << 16)
        if not c:
            break
        if first:
            count(int(c.split()[1]))
            first = False
        stream_events[i] += c.count(b"\nevent: ")
    s.close()

def previews():
    while not stop.is_set():
        try:
            st, _ = http("GET", f"/v1/jobs/{job}/preview", timeout=60)
            count(st)
        except OSError:
            count("error")

threads = [threading.Thread(target=stream, args=(i,)) for i in range(a.streams)]
threads += [threading.Thread(target=previews) for _ in range(a.previews)]
for t in threads:
    t.start()
time.sleep(1)
lat = []
peak = {}
end = time.time() + a.seconds
while time.time() < end:
    t0 = time.perf_counter()
    try:
        st, _ = http("GET", "/healthz", timeout=30)
    except OSError:
        st = "error"
    lat.append((time.perf_counter() - t0) * 1000)
    count(("healthz", st))
    r = rss()
    for k, v in r.items():
        peak[k] = max(peak.get(k, 0), v)
    time.sleep(0.02)
stop.set()
state = json.loads(http("GET", f"/v1/jobs/{job}")[1])["state"]
http("DELETE", f"/v1/jobs/{job}")
for t in threads:
    t.join(timeout=90)
proc.terminate()
proc.wait()
lat.sort()
q = lambda p: lat[min(len(lat) - 1, int(p * len(lat)))]
print(f"{a.streams} streams, {a.previews} preview clients, {a.seconds:.0f} s; job still {state}")
print(f"/healthz: {len(lat)} requests, p50 {q(0.5):.1f} ms, p99 {q(0.99):.1f} ms, max {lat[-1]:.1f} ms")
print(f"statuses: {statuses}")
print(f"streams: {sum(1 for e in stream_events if e)} of {a.streams} got events, {sum(stream_events)} events")
print(f"server RSS at the end {rss_end if (rss_end := peak.get('VmRSS')) else 0:.0f} MB (largest sample), peak (VmHWM) {peak.get('VmHWM', 0):.0f} MB")
fives = sum(n for k, n in statuses.items() if (k[1] if isinstance(k, tuple) else k) in range(500, 600))
print(f"5xx: {fives}")
sys.exit(1 if fives or q(0.99) >= 100 else 0)

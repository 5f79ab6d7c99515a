#!/usr/bin/env python3
"""Hostile and unlucky clients against a running `portico serve`, with /healthz watched.

    python3 bench/attacks.py --server http://127.0.0.1:7878 --pid PID [--attack all]

Attacks (each for --seconds, one after the other):
  flood         2 WebSocket clients send ~142 KB of Observer messages each, then leave
  never-read    200 WebSocket clients ask for everything and never read (server RSS reported)
  slow-headers  300 sockets send half a request head and wait
  held          4 loops of prefetch requests whose held set lists 400,000 ids (0.8 MB)
  reload        a slow reader of a large batch, then SIGHUP to --pid
  wide-paged    2 paged WebSocket sessions with the wide policy move every 50 ms while a normal
                client asks for prefetch answers (their statuses reported)
  huge-frame    a Hello of the wide policy whose frame_time_s is 1e20, an observer, then leaves (open sessions
                that /metrics still counts afterwards reported)
  zero-rate     a Hello at 0 bytes/s, an observer, then a Hello at full rate (segments pushed
                in the 2 s after it reported)
  stale         a stream naming another database (close code and segments pushed reported)
  batch-never-read  192 clients ask for --batch and never read
  wasm-never-read   130 clients ask for the viewer's wasm module and never read
  range416      a range past the wasm module's end with Accept-Encoding: gzip (whether the
                error body decodes)
  evicted-flood 2 WebSocket clients send ~0.9 MB Evicted lists as fast as the server takes them
For each: /healthz latency (p50, p99, max; a request that fails counts as 5 s) polled every 20 ms
on fresh connections from its own thread, and the server's RSS (VmRSS) at the end.
Standard library only; figures in docs/performance.md come from this script.
"""
import argparse, base64, json, os, signal, socket, struct, threading, time
from urllib.parse import urlparse

OBS = {"eye": [3.0, 1.5, 3.0], "dir": [1.0, 0.0, 0.0], "up": [0.0, 1.0, 0.0],
       "velocity": [0.0, 0.0, 0.0], "half_fov_x": 0.6, "half_fov_y": 0.45,
       "max_speed": 1.5, "max_turn": 1.0}
DEFAULT = {"depth_frames": 16, "frame_time_s": 0.05, "range_cull": "direction",
           "lookahead_cull": "predicted", "granularity": "object", "size_threshold_px": 16.0,
           "screen": [640, 480], "read_bytes": 4 << 20, "cache_bytes": 64 << 20,
           "impostors": False}
WIDE = {"depth_frames": 10000, "frame_time_s": 0.05, "range_cull": "any",
        "lookahead_cull": "any", "granularity": "cell", "size_threshold_px": 0.0,
        "screen": [640, 480], "read_bytes": 1 << 30, "cache_bytes": 1 << 30,
        "impostors": False}


def rss_mb(pid):
    try:
        for line in open(f"/proc/{pid}/status"):
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    except OSError:
        pass
    return float("nan")


class Health(threading.Thread):
    def __init__(self, host, port):
        super().__init__(daemon=True)
        self.host, self.port, self.stop, self.ms = host, port, False, []

    def run(self):
        while not self.stop:
            t0 = time.monotonic()
            try:
                s = socket.create_connection((self.host, self.port), timeout=5)
                s.settimeout(5)
                s.sendall(b"GET /healthz HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n")
                ok = s.recv(12).startswith(b"HTTP/1.1 200")
                s.close()
            except OSError:
                ok = False
            self.ms.append((time.monotonic() - t0) * 1e3 if ok else 5000.0)
            time.sleep(0.02)

    def summary(self):
        v = sorted(self.ms) or [float("nan")]
        return v[len(v) // 2], v[min(len(v) - 1, int(len(v) * 0.99))], v[-1], len(v)


def ws_connect(host, port, rcvbuf=None, path="/v1/stream"):
    s = socket.socket()
    if rcvbuf:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf)
    s.settimeout(10)
    s.connect((host, port))
    key = base64.b64encode(os.urandom(16)).decode()
    s.sendall((f"GET {path} HTTP/1.1\r\nHost: {host}\r\nUpgrade: websocket\r\n"
               f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
               "Sec-WebSocket-Version: 13\r\n\r\n").encode())
    head = b""
    while b"\r\n\r\n" not in head:
        chunk = s.recv(1)
        if not chunk:
            raise OSError("closed during the handshake")
        head += chunk
    if not head.startswith(b"HTTP/1.1 101"):
        raise OSError(head.split(b"\r\n")[0].decode())
    return s


def ws_text(payload):
    data = payload.encode()
    mask = os.urandom(4)
    n = len(data)
    head = bytes([0x81]) + (bytes([0x80 | n]) if n < 126 else bytes([0x80 | 126]) + struct.pack(">H", n))
    return head + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(data))


def ws_bytes(opcode, data):
    mask = os.urandom(4)
    n = len(data)
    if n < 126:
        head = bytes([0x80 | opcode, 0x80 | n])
    elif n < 65536:
        head = bytes([0x80 | opcode, 0x80 | 126]) + struct.pack(">H", n)
    else:
        head = bytes([0x80 | opcode, 0x80 | 127]) + struct.pack(">Q", n)
    m = (mask * (n // 4 + 1))[:n]
    return head + mask + (int.from_bytes(data, "big") ^ int.from_bytes(m, "big")).to_bytes(n, "big")


def ws_read(s):
    """One frame from the server: (opcode, payload)."""
    def exact(n):
        b = b""
        while len(b) < n:
            c = s.recv(n - len(b))
            if not c:
                raise OSError("closed")
            b += c
        return b
    h = exact(2)
    n = h[1] & 0x7F
    if n == 126:
        n = struct.unpack(">H", exact(2))[0]
    elif n == 127:
        n = struct.unpack(">Q", exact(8))[0]
    return h[0] & 0x0F, exact(n)


def hello(policy=None, rate=1 << 40, pages=False):
    return json.dumps({"Hello": {"version": 5, "policy": policy or WIDE, "rate_bytes_per_s": rate,
                                 "rtt_ms": 0}})


def get(host, port, path, headers=""):
    s = socket.create_connection((host, port), timeout=10)
    s.sendall(f"GET {path} HTTP/1.1\r\nHost: x\r\n{headers}Connection: close\r\n\r\n".encode())
    got = b""
    while True:
        c = s.recv(1 << 16)
        if not c:
            break
        got += c
    s.close()
    head, _, body = got.partition(b"\r\n\r\n")
    return head.decode(errors="replace"), body


def prefetch_status(host, port):
    body = json.dumps({"version": 5, "observer": OBS,
                       "policy": {"depth_frames": 16, "frame_time_s": 0.05, "range_cull": "direction",
                                  "lookahead_cull": "any", "granularity": "object",
                                  "size_threshold_px": 1.0, "screen": [640, 480],
                                  "read_bytes": 4 << 20, "cache_bytes": 64 << 20, "impostors": False},
                       "held": []}).encode()
    try:
        s = socket.create_connection((host, port), timeout=30)
        s.sendall((f"POST /v1/prefetch HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n"
                   f"Content-Length: {len(body)}\r\nConnection: close\r\n\r\n").encode() + body)
        st = s.recv(12)[9:12].decode(errors="replace")
        s.close()
        return st
    except OSError:
        return "err"


def wide_paged(host, port, seconds):
    end = time.monotonic() + seconds
    def one():
        try:
            s = ws_connect(host, port, rcvbuf=1 << 20)
            s.sendall(ws_text(hello()))
            s.sendall(ws_text(json.dumps("Pages")))
            i = 0
            while time.monotonic() < end:
                o = dict(OBS, eye=[OBS["eye"][0] + (i % 40) * 0.25, OBS["eye"][1], OBS["eye"][2]])
                s.sendall(ws_text(json.dumps({"Observer": o})))
                i += 1
                time.sleep(0.05)
            s.close()
        except OSError as e:
            print("  wide paged client:", e)
    ts = [threading.Thread(target=one) for _ in range(2)]
    [t.start() for t in ts]
    statuses = []
    while time.monotonic() < end:
        statuses.append(prefetch_status(host, port))
        time.sleep(0.1)
    [t.join() for t in ts]
    counts = {k: statuses.count(k) for k in sorted(set(statuses))}
    print(f"  prefetch answers beside them: {counts}")


def metric(host, port, name):
    _, body = get(host, port, "/metrics")
    for line in body.decode(errors="replace").splitlines():
        if line.startswith(name + " "):
            return float(line.split()[1])
    return float("nan")


def huge_frame(host, port, seconds):
    s = ws_connect(host, port)
    s.sendall(ws_text(hello(dict(WIDE, frame_time_s=1e20))))
    s.sendall(ws_text(json.dumps({"Observer": OBS})))
    time.sleep(3.0)
    s.close()
    time.sleep(seconds)
    print(f"  stream sessions /metrics counts after the client left: "
          f"{metric(host, port, 'portico_sessions'):.0f}")


def segments_within(s, seconds):
    s.settimeout(0.2)
    end, n = time.monotonic() + seconds, 0
    while time.monotonic() < end:
        try:
            op, data = ws_read(s)
        except socket.timeout:
            continue
        except OSError:
            break
        n += op == 2 and data[:1] == b"\x01"
    return n


def zero_rate(host, port, seconds):
    s = ws_connect(host, port)
    s.sendall(ws_text(hello(rate=0)))
    s.sendall(ws_text(json.dumps({"Observer": OBS})))
    slow = segments_within(s, 1.0)
    s.sendall(ws_text(hello()))
    fast = segments_within(s, 2.0)
    s.close()
    print(f"  segments pushed: {slow} in 1 s at 0 B/s, then {fast} in the 2 s after a full-rate Hello")
    time.sleep(seconds)


def stale(host, port, seconds):
    try:
        s = ws_connect(host, port, path="/v1/db/0123456789abcdef0123456789abcdef/stream")
    except OSError as e:
        print(f"  refused at the handshake: {e}")
        return
    s.sendall(ws_text(hello()))
    s.sendall(ws_text(json.dumps({"Observer": OBS})))
    s.settimeout(2)
    segs, code = 0, None
    try:
        while True:
            op, data = ws_read(s)
            if op == 8:
                code = struct.unpack(">H", data[:2])[0] if len(data) >= 2 else None
                print(f"  closed with {code}: {data[2:].decode(errors='replace')}")
                break
            segs += op == 2
    except OSError:
        pass
    print(f"  {segs} frames pushed, close code {code}")
    time.sleep(seconds)


def never_reading(host, port, seconds, request, count):
    def one():
        s = socket.socket()
        s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        s.settimeout(5)
        s.connect((host, port))
        s.sendall(request)
        return s
    return hold_open(count, one, "request", seconds)


def range416(host, port, seconds):
    head, body = get(host, port, "/portico_web_bg.wasm",
                     "Range: bytes=99999999-\r\nAccept-Encoding: gzip\r\n")
    status = head.split("\r\n")[0]
    coded = "content-encoding: gzip" in head.lower()
    try:
        json.loads(body)
        ok = True
    except ValueError:
        ok = False
    print(f"  {status}; Content-Encoding gzip: {coded}; body decodes as sent: {ok and not coded}")
    time.sleep(seconds)


def evicted_flood(host, port, seconds):
    msg = json.dumps({"Evicted": [i % 10000 for i in range(150_000)]}, separators=(",", ":"))
    frame = ws_bytes(1, msg.encode())
    end = time.monotonic() + seconds
    taken = []
    def one():
        n = 0
        try:
            s = ws_connect(host, port)
            while time.monotonic() < end:
                s.sendall(frame)
                n += 1
            s.close()
        except OSError as e:
            print("  flood client:", e)
        taken.append(n)
    ts = [threading.Thread(target=one) for _ in range(2)]
    [t.start() for t in ts]
    [t.join() for t in ts]
    print(f"  messages of {len(msg)} bytes taken in {seconds} s: {taken}")


def flood(host, port, seconds):
    def one():
        try:
            s = ws_connect(host, port)
            s.sendall(ws_text(hello()))
            for i in range(2500):
                o = dict(OBS, eye=[OBS["eye"][0] + (i % 50) * 0.01, OBS["eye"][1], OBS["eye"][2]])
                s.sendall(ws_text(json.dumps({"Observer": o})))
            s.close()
        except OSError as e:
            print("  flood client:", e)
    ts = [threading.Thread(target=one) for _ in range(2)]
    [t.start() for t in ts]
    [t.join() for t in ts]
    time.sleep(seconds)


def hold_open(count, open_one, what, seconds):
    """Opens up to `count` connections with `open_one()` that then never read; keeps them for
    `seconds` and returns them."""
    held = []
    for _ in range(count):
        try:
            held.append(open_one())
        except OSError as e:
            print(f"  {what}:", e)
            break
    print(f"  {len(held)} {what}s, never read")
    time.sleep(seconds)
    return held


def never_read(host, port, seconds):
    def one():
        s = ws_connect(host, port, rcvbuf=4096)
        s.sendall(ws_text(hello()))
        s.sendall(ws_text(json.dumps({"Observer": OBS})))
        return s
    return hold_open(200, one, "stream session", seconds)


def slow_headers(host, port, seconds):
    held = []
    for _ in range(300):
        try:
            s = socket.create_connection((host, port), timeout=5)
            s.sendall(b"GET /healthz HTTP/1.1\r\nHost: x\r\n")
            held.append(s)
        except OSError as e:
            print("  slow socket:", e)
            break
    time.sleep(seconds)
    return held


def held(host, port, seconds):
    body = json.dumps({"version": 5, "observer": OBS,
                       "policy": dict(WIDE, depth_frames=16, range_cull="direction",
                                      granularity="object", read_bytes=4 << 20),
                       "held": [0] + [1] * 399_999}, separators=(",", ":")).encode()
    req = (f"POST /v1/prefetch HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n"
           f"Content-Length: {len(body)}\r\nConnection: close\r\n\r\n").encode() + body
    end = time.monotonic() + seconds
    sizes = []

    def loop():
        while time.monotonic() < end:
            try:
                s = socket.create_connection((host, port), timeout=30)
                s.sendall(req)
                got = b""
                while True:
                    c = s.recv(1 << 16)
                    if not c:
                        break
                    got += c
                sizes.append((got[9:12].decode(errors="replace"), len(got)))
                s.close()
            except OSError:
                sizes.append(("err", 0))
    ts = [threading.Thread(target=loop) for _ in range(4)]
    [t.start() for t in ts]
    [t.join() for t in ts]
    statuses = sorted({st for st, _ in sizes})
    print(f"  {len(sizes)} requests, statuses {statuses}, largest answer {max(n for _, n in sizes)} bytes")


def reload(host, port, seconds, pid, batch):
    s = socket.socket()
    s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    s.connect((host, port))
    s.sendall(f"GET /v1/batch?ids={batch} HTTP/1.1\r\nHost: x\r\n\r\n".encode())
    time.sleep(0.5)
    os.kill(pid, signal.SIGHUP)
    time.sleep(seconds)
    return s


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--server", default="http://127.0.0.1:7878")
    ap.add_argument("--pid", type=int, required=True)
    ap.add_argument("--attack", default="all")
    ap.add_argument("--seconds", type=float, default=5.0)
    ap.add_argument("--batch", default=",".join(["1"] * 1000),
                    help="ids of the slow reader's batch (reload)")
    ap.add_argument("--eye", default="3,1.5,3", help="an eye inside a room: x,y,z")
    a = ap.parse_args()
    OBS["eye"] = [float(x) for x in a.eye.split(",")]
    u = urlparse(a.server)
    host, port = u.hostname, u.port
    names = ["flood", "never-read", "slow-headers", "held", "reload"] if a.attack == "all" else a.attack.split(",")
    batch_req = f"GET /v1/batch?ids={a.batch} HTTP/1.1\r\nHost: x\r\n\r\n".encode()
    wasm_req = b"GET /portico_web_bg.wasm HTTP/1.1\r\nHost: x\r\n\r\n"
    for name in names:
        h = Health(host, port)
        h.start()
        keep = None
        if name == "flood":
            flood(host, port, a.seconds)
        elif name == "never-read":
            keep = never_read(host, port, a.seconds)
        elif name == "slow-headers":
            keep = slow_headers(host, port, a.seconds)
        elif name == "held":
            held(host, port, a.seconds)
        elif name == "reload":
            keep = reload(host, port, a.seconds, a.pid, a.batch)
        elif name == "wide-paged":
            wide_paged(host, port, a.seconds)
        elif name == "huge-frame":
            huge_frame(host, port, a.seconds)
        elif name == "zero-rate":
            zero_rate(host, port, a.seconds)
        elif name == "stale":
            stale(host, port, a.seconds)
        elif name == "batch-never-read":
            keep = never_reading(host, port, a.seconds, batch_req, 192)
        elif name == "wasm-never-read":
            keep = never_reading(host, port, a.seconds, wasm_req, 130)
        elif name == "range416":
            range416(host, port, a.seconds)
        elif name == "evicted-flood":
            evicted_flood(host, port, a.seconds)
        h.stop = True
        h.join()
        p50, p99, mx, n = h.summary()
        print(f"{name}: /healthz p50 {p50:.1f} ms, p99 {p99:.1f} ms, max {mx:.1f} ms over {n} checks; "
              f"server RSS {rss_mb(a.pid):.0f} MB")
        if keep:
            for s in keep if isinstance(keep, list) else [keep]:
                s.close()
        time.sleep(1.0)


if __name__ == "__main__":
    main()

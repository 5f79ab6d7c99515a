#!/usr/bin/env python3
"""The browser viewer's figures in headless Chromium (WebGL2 through SwiftShader).

Against a running `portico serve MODEL` that serves the viewer (`bash web/build.sh` first):

    python3 bench/browser.py --server http://127.0.0.1:7878 [--link 50ms,10mbit] [--seconds 20]

starts chromedriver, opens the page (with Chromium's own network emulation when `--link` is
given: latency added to every request, download and upload throttled), and prints as JSON:
the time from the start of page load to the first complete frame (every visible object drawn),
the segment bytes received until then and everything fetched over HTTP until then (the page,
the bundle, the manifest or the core and its pages), and the mean frame interval while the standard tour plays for
`--seconds`. Only the standard library: it speaks WebDriver's JSON over HTTP itself.
"""

import argparse
import base64
import json
import os
import signal
import socket
import subprocess
import sys
import time
import urllib.error
import urllib.request


def call(base, method, path, body=None):
    data = None if body is None else json.dumps(body).encode()
    req = urllib.request.Request(base + path, data=data, method=method,
                                 headers={"content-type": "application/json"})
    try:
        with urllib.request.urlopen(req, timeout=120) as r:
            return json.loads(r.read() or b"null").get("value")
    except urllib.error.HTTPError as e:
        detail = json.loads(e.read() or b"{}").get("value", {})
        raise RuntimeError(f"{method} {path}: {detail.get('message', e)}") from None


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def parse_link(spec):
    """'50ms,10mbit' or loadtest's 'rtt=50ms,rate=10mbit' -> (latency ms, bytes per second)."""
    try:
        latency, rate = (p.split("=")[-1].strip().lower() for p in spec.split(","))
        ms = float(latency.removesuffix("ms"))
        units = {"kbit": 1e3, "mbit": 1e6, "gbit": 1e9}
        unit = next(u for u in units if rate.endswith(u))
        return ms, float(rate.removesuffix(unit)) * units[unit] / 8
    except (ValueError, StopIteration):
        sys.exit(f"--link {spec!r}: expected LATENCYms,RATE(k|m|g)bit, e.g. 50ms,10mbit")


def chromium(w, h, link):
    """Starts chromedriver and a headless Chromium session (WebGL2 on SwiftShader, a window
    for a `w`×`h` canvas, `link` emulated if given). Returns the driver process (its own
    process group: `os.killpg` ends every Chromium it started), its URL and the session path."""
    port = free_port()
    driver = subprocess.Popen(["chromedriver", f"--port={port}"], process_group=0,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    base = f"http://127.0.0.1:{port}"
    try:
        for _ in range(100):
            try:
                call(base, "GET", "/status")
                break
            except OSError:
                time.sleep(0.1)
        caps = {"capabilities": {"alwaysMatch": {"goog:chromeOptions": {
            "binary": "/usr/bin/chromium",
            "args": ["--headless=new", "--no-sandbox", "--disable-dev-shm-usage",
                     "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
                     f"--window-size={w + 100},{h + 300}", "--force-device-scale-factor=1"]}}}}
        sid = call(base, "POST", "/session", caps)["sessionId"]
        s = f"/session/{sid}"
        if link:
            ms, rate = parse_link(link)
            call(base, "POST", f"{s}/chromium/network_conditions", {"network_conditions": {
                "offline": False, "latency": ms, "download_throughput": rate,
                "upload_throughput": rate}})
        return driver, base, s
    except BaseException:
        os.killpg(driver.pid, signal.SIGKILL)
        raise


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--server", default="http://127.0.0.1:7878")
    ap.add_argument("--link", help="emulated link, e.g. 50ms,10mbit")
    ap.add_argument("--seconds", type=float, default=20.0, help="how long the tour plays")
    ap.add_argument("--size", default="640x480", help="the canvas's size in CSS pixels")
    ap.add_argument("--query", default="backend=webgl", help="the page's query string")
    ap.add_argument("--screenshot", help="save the canvas (with the overlay) at the end of the tour here (PNG)")
    a = ap.parse_args()
    w, h = (int(v) for v in a.size.split("x"))
    driver, base, s = chromium(w, h, a.link)
    try:
        # The page fills its window; the canvas is then set to the asked size (the viewer
        # follows its canvas's size every frame).
        call(base, "POST", f"{s}/url", {"url": f"{a.server}/?{a.query}"})

        def run(script):
            return call(base, "POST", f"{s}/execute/sync", {"script": script, "args": []})

        run(f"document.getElementById('view').style.width='{w}px';"
            f"document.getElementById('view').style.height='{h}px';")
        run("performance.setResourceTimingBufferSize(100000)")
        t0 = time.time()
        stats = None
        while time.time() - t0 < 300:
            err = run("return window.porticoError || null")
            if err:
                sys.exit(f"the page failed: {err}")
            try:
                raw = run("return window.portico ? window.portico.stats() : null")
            except RuntimeError as e:
                sys.exit(f"{e}\nthe page's errors: {run('return window.porticoErrors')}")
            stats = json.loads(raw) if raw else None
            if stats and stats.get("first_complete_ms") is not None:
                break
            time.sleep(0.1)
        first = dict(stats or {})
        # Everything fetched over HTTP until then (the page, the bundle, the manifest or the core
        # and pages, the tour; pulled segments too), as Chromium counts it on the wire.
        http_bytes = run("return performance.getEntriesByType('navigation')"
                         ".concat(performance.getEntriesByType('resource'))"
                         ".reduce((s, e) => s + (e.transferSize || 0), 0)")
        run("window.portico.tour(true)")
        samples = []
        t1 = time.time()
        frames0 = first.get("frames", 0)
        while time.time() - t1 < a.seconds:
            time.sleep(0.5)
            samples.append(json.loads(run("return window.portico.stats()")))
        elapsed = time.time() - t1
        last = samples[-1] if samples else first
        # Every byte of the run: HTTP as Chromium counts it on the wire, and the segments
        # the stream pushed over its WebSocket (which resource timing does not see).
        http_total = run("return performance.getEntriesByType('navigation')"
                         ".concat(performance.getEntriesByType('resource'))"
                         ".reduce((s, e) => s + (e.transferSize || 0), 0)")
        pushed = last.get("bytes_received", 0) if last.get("transport") == "stream" else 0
        out = {
            "server": a.server,
            "link": a.link or "loopback",
            "canvas": [w, h],
            "backend": first.get("backend"),
            "first_complete_ms": first.get("first_complete_ms"),
            "first_complete_frame": first.get("first_complete_frame"),
            "bytes_at_first_complete": first.get("bytes_received"),
            "http_bytes_at_first_complete": http_bytes,
            "manifest": first.get("manifest", "whole"),
            "tour_seconds": a.seconds,
            "tour_frames": last.get("frames", 0) - frames0,
            "mean_frame_ms": (elapsed * 1e3 / max(1, last.get("frames", 0) - frames0)),
            "objects_skipped_mean": sum(x["objects_skipped"] for x in samples) / max(1, len(samples)),
            "visible_objects_mean": sum(x["visible_objects"] for x in samples) / max(1, len(samples)),
            "resident_mb": last.get("resident_bytes", 0) / 2**20,
            "cache_budget_mb": last.get("cache_budget", 0) / 2**20,
            "received_mb": last.get("bytes_received", 0) / 1e6,
            "total_mb": (http_total + pushed) / 1e6,
            # Over pull (`--query transport=pull`): the prefetch requests and answers the tour
            # cost, beside the segment bytes it received.
            "tour_answers": last.get("answers", 0) - first.get("answers", 0),
            "tour_prefetch_mb": (last.get("prefetch_bytes", 0) - first.get("prefetch_bytes", 0)) / 1e6,
            "tour_segment_mb": (last.get("bytes_received", 0) - first.get("bytes_received", 0)) / 1e6,
            "failures": last.get("failures"),
            "errors": run("return window.porticoErrors || []"),
        }
        if a.screenshot:
            view = call(base, "POST", f"{s}/element",
                        {"using": "css selector", "value": "#view"})
            eid = next(iter(view.values()))
            with open(a.screenshot, "wb") as f:
                f.write(base64.b64decode(call(base, "GET", f"{s}/element/{eid}/screenshot")))
        print(json.dumps(out, indent=2))
        call(base, "DELETE", s)
    finally:
        os.killpg(driver.pid, signal.SIGKILL)


if __name__ == "__main__":
    try:
        main()
    except (RuntimeError, OSError) as e:
        sys.exit(f"bench/browser.py: {e}")

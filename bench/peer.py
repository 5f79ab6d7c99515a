#!/usr/bin/env python3
"""The peer's figures, as bench/browser.py measures Portico's viewer: NASA-AMMOS 3DTilesRenderer
(three.js) streaming a 3D Tiles export of the same building, in the same headless Chromium, on
the same path and emulated link.

    portico export-3dtiles soda.portico -o soda-tiles          # the tileset
    (cd bench/peer && npm ci)                                  # 3DTilesRenderer, three, gltfpack
    curl -s http://127.0.0.1:7878/v1/tour > tour.json          # the page's tour, from its server
    python3 bench/peer.py --tileset soda-tiles --path tour.json [--link 50ms,10mbit] [--gltfpack]

`--gltfpack` compresses every tile first (`gltfpack -cc`: meshopt, quantised: the peer's best
case) into a copy. It serves the page, the tileset and the path from a static server of its own
(gzip where the browser asks, as `portico serve` does) and prints JSON: page load to the first
frame with every tile the view wants loaded, every HTTP byte until then, and over `--seconds`
of the path: the frame interval and the tile bytes fetched. Standard library only.
"""

import argparse
import functools
import gzip
import http.server
import io
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from browser import call, chromium, free_port  # noqa: E402

HERE = os.path.join(os.path.dirname(os.path.abspath(__file__)), "peer")


class Handler(http.server.SimpleHTTPRequestHandler):
    """Static files; text gzip-coded when asked (as a production server would)."""

    zipped = {}

    def log_message(self, *args):
        pass

    def send_head(self):
        path = self.translate_path(self.path.split("?")[0])
        text = path.endswith((".js", ".json", ".html", ".mjs"))
        if not text or "gzip" not in self.headers.get("Accept-Encoding", "") or not os.path.isfile(path):
            return super().send_head()
        body = Handler.zipped.get(path)
        if body is None:
            with open(path, "rb") as f:
                body = Handler.zipped[path] = gzip.compress(f.read(), 6)
        self.send_response(200)
        self.send_header("Content-Type", self.guess_type(path))
        self.send_header("Content-Encoding", "gzip")
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        return io.BytesIO(body)


def compress(src, dst):
    """Copies the tileset `src` to `dst`, every tile through `gltfpack -cc`."""
    gltfpack = os.path.join(HERE, "node_modules", ".bin", "gltfpack")
    if not os.path.exists(gltfpack):
        sys.exit("--gltfpack: run `npm ci` in bench/peer first")
    shutil.copytree(src, dst)
    tiles = [f for f in os.listdir(os.path.join(dst, "tiles")) if f.endswith(".glb")]
    for f in tiles:
        p = os.path.join(dst, "tiles", f)
        subprocess.run([gltfpack, "-i", p, "-o", p + ".tmp.glb", "-cc"],
                       check=True, stdout=subprocess.DEVNULL)
        os.replace(p + ".tmp.glb", p)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tileset", required=True, help="a `portico export-3dtiles` folder")
    ap.add_argument("--path", required=True, help="the camera path (Portico's JSON)")
    ap.add_argument("--link", help="emulated link, e.g. 50ms,10mbit")
    ap.add_argument("--seconds", type=float, default=20.0, help="how long the path plays")
    ap.add_argument("--size", default="640x480", help="the canvas's size in CSS pixels")
    ap.add_argument("--gltfpack", action="store_true", help="compress the tiles with gltfpack -cc first")
    ap.add_argument("--error-target", default="6", help="3DTilesRenderer's errorTarget (pixels)")
    a = ap.parse_args()
    if not os.path.isdir(os.path.join(HERE, "node_modules", "3d-tiles-renderer")):
        sys.exit("run `npm ci` in bench/peer first")
    w, h = (int(v) for v in a.size.split("x"))
    root = tempfile.mkdtemp(prefix="portico-peer-")
    try:
        shutil.copy(os.path.join(HERE, "index.html"), root)
        os.symlink(os.path.join(HERE, "node_modules"), os.path.join(root, "node_modules"))
        if a.gltfpack:
            compress(a.tileset, os.path.join(root, "tileset"))
        else:
            os.symlink(os.path.abspath(a.tileset), os.path.join(root, "tileset"))
        shutil.copy(a.path, os.path.join(root, "path.json"))
        port = free_port()
        httpd = http.server.ThreadingHTTPServer(
            ("127.0.0.1", port), functools.partial(Handler, directory=root))
        threading.Thread(target=httpd.serve_forever, daemon=True).start()
        out = measure(a, f"http://127.0.0.1:{port}", w, h)
        tiles_dir = os.path.join(root, "tileset", "tiles")
        out["tileset_mb"] = sum(os.path.getsize(os.path.join(tiles_dir, f))
                                for f in os.listdir(tiles_dir)) / 1e6
        out["gltfpack"] = a.gltfpack
        print(json.dumps(out, indent=2))
        httpd.shutdown()
    finally:
        shutil.rmtree(root, ignore_errors=True)


def measure(a, server, w, h):
    driver, base, s = chromium(w, h, a.link)
    try:
        call(base, "POST", f"{s}/url",
             {"url": f"{server}/index.html?size={w}x{h}&error_target={a.error_target}"})

        def run(script):
            return call(base, "POST", f"{s}/execute/sync", {"script": script, "args": []})

        run("performance.setResourceTimingBufferSize(100000)")
        t0 = time.time()
        stats = None
        while time.time() - t0 < 300:
            raw = run("return window.peer ? window.peer.stats() : null")
            stats = json.loads(raw) if raw else None
            if stats and stats.get("first_complete_ms") is not None:
                break
            time.sleep(0.1)
        first = dict(stats or {})
        entries = ("return performance.getEntriesByType('navigation')"
                   ".concat(performance.getEntriesByType('resource'))")
        http_bytes = run(entries + ".reduce((s, e) => s + (e.transferSize || 0), 0)")
        tile_bytes = entries + (".filter(e => e.name.includes('/tileset/tiles/'))"
                                ".reduce((s, e) => s + (e.transferSize || 0), 0)")
        tiles_at_first = run(tile_bytes)
        run("window.peer.tour(true)")
        t1 = time.time()
        frames0 = first.get("frames", 0)
        time.sleep(a.seconds)
        elapsed = time.time() - t1
        last = json.loads(run("return window.peer.stats()"))
        total = run(entries + ".reduce((s, e) => s + (e.transferSize || 0), 0)")
        return {
            "peer": "3DTilesRenderer 0.5.3, three.js 0.187.0",
            "link": a.link or "loopback",
            "canvas": [w, h],
            "first_complete_ms": first.get("first_complete_ms"),
            "http_bytes_at_first_complete": http_bytes,
            "tile_bytes_at_first_complete": tiles_at_first,
            "tour_seconds": a.seconds,
            "mean_frame_ms": elapsed * 1e3 / max(1, last.get("frames", 0) - frames0),
            "tour_tile_mb": (run(tile_bytes) - tiles_at_first) / 1e6,
            "total_mb": total / 1e6,
            "errors": run("return window.porticoErrors || []"),
        }
    finally:
        os.killpg(driver.pid, signal.SIGKILL)


if __name__ == "__main__":
    main()

"""The live viewer's frame rate from a freshly started server, and where each millisecond goes.

1. Server side, in this process, on the ``wax`` scene: the band render of one frame with planeray's
   O(pixels) renderer against the dense weighted sum over offsets (``np.matmul``, the baseline), and
   the frame's encoding as raw float32 bytes against a PNG of its 8-bit display image (Pillow,
   fastest compression, the baseline), at each size.
2. A **freshly started** ``planeray view wax --size N`` (a new process, as a user starts it) driven
   over its WebSocket as a drag with one request in flight: the round trip and the server's render +
   encode time of each of its first 50 frames and of the 100 after them (the first drag against the
   hundredth), with the server's page faults per frame (Linux).
3. In the browser, again against a freshly started ``planeray view`` for every measurement: the page
   is opened in the system's headless Chromium (no debugging protocol attached, see
   :mod:`planeray.viewer.browser`); it moves its delay slider once per displayed frame (as a hand
   dragging it) for ``--seconds`` and reports the frames it painted per second -- counted in
   ``requestAnimationFrame`` -- and the median milliseconds of each step: render and encode
   (server), queue (waiting behind the previous render), transfer (server send to page receive),
   decode and paint (page: colour table + ``putImageData``), and the latency from request to
   painted frame.  At the display's refresh rate (what a user sees: at most one new frame per
   refresh) and, where that rate was the limit, again with vsync off and the slider moved 250 times
   a second (what the pipeline delivers beyond the display; on two cores the uncapped compositor
   competes with everything else).

``--load N`` keeps N other processes busy (``while True: pass``, one core each) during parts 2 and 3;
``--repeat R`` measures part 3 R times (each with a fresh server) and prints every run.

Run: ``make bench-viewer`` or ``.venv/bin/python benchmarks/bench_viewer.py [--sizes 128 512 --seconds 5 --load 1]``.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import re
import subprocess
import sys
import time
import urllib.request

import numpy as np

from planeray.timing import PAPER_LINES_PER_SECOND, Band
from planeray.viewer.browser import find_chromium, measure_painted_fps
from planeray.viewer.display import auto_white, to_rgb
from planeray.viewer.server import decode_frame, encode_frame
from planeray.viewer.session import ViewSettings, open_source


def _median_ms(fn, n):
    times = []
    for i in range(n):
        t0 = time.perf_counter()
        fn(i)
        times.append(time.perf_counter() - t0)
    return float(np.median(times)) * 1e3


def server_side(source, n: int = 15) -> dict:
    T = source.transport
    delays = np.linspace(-1500.0, 1500.0, n)

    def render(i):
        with source.frame(ViewSettings(delay_us=float(delays[i]))):  # the server's path: reused buffers
            pass

    render = _median_ms(render, n)

    def dense(i):
        w = T.illumination_weights(Band(float(delays[i]), 600.0, PAPER_LINES_PER_SECOND, 5.0)).astype(np.float32)
        return np.matmul(T.dense, w[:, :, None])[..., 0]

    dense_ms = _median_ms(dense, min(n, 5))
    image, info = source.render(ViewSettings(delay_us=375.0))
    header = {"type": "frame", "panel": 0, "id": 1, "settings": ViewSettings().to_dict(), **info}
    raw = _median_ms(lambda i: encode_frame(image, {**header, "auto_white": auto_white(image)}), n)

    def png(i):
        from PIL import Image

        buf = io.BytesIO()
        Image.fromarray(to_rgb(image, white=auto_white(image))[..., 0]).save(buf, format="PNG", compress_level=1)
        return buf.getvalue()

    png_ms = _median_ms(png, n)
    noisy = _median_ms(lambda i: source.render(ViewSettings(delay_us=float(delays[i]), noise=True)), min(n, 7))
    return {"render": render, "dense": dense_ms, "raw": raw, "png": png_ms, "noisy": noisy,
            "bytes": image.size * 4, "png_bytes": len(png(0))}  # fmt: skip


class FreshServer:
    """``planeray view SCENE --size N`` started in a new process (as a user starts it): its URL and the
    page's frame-rate reports (``GET /api/reports``)."""

    def __init__(self, scene: str | None, size: int | None, timeout_s: float = 300.0, *, args: list[str] | None = None):
        view = args if args is not None else [scene, "--size", str(size)]  # args: any `planeray view` arguments
        cmd = [sys.executable, "-m", "planeray.cli", "view", *view, "--port", "0", "--no-browser"]
        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        self.url = None
        deadline = time.monotonic() + timeout_s
        for line in self.proc.stdout:
            found = re.search(r"http://\S+\?token=\S+", line)
            if found:
                self.url = found.group(0)
                break
            if time.monotonic() > deadline:
                break
        if self.url is None:
            self.close()
            raise RuntimeError(f"`{' '.join(cmd[2:])}` printed no URL")
        self.base, self.token = self.url.split("/?token=")

    @property
    def reports(self) -> list:
        with urllib.request.urlopen(f"{self.base}/api/reports?token={self.token}", timeout=10) as r:
            return json.loads(r.read())

    def page_faults(self) -> int | None:
        """Minor page faults of the server process so far (Linux), else None."""
        try:
            with open(f"/proc/{self.proc.pid}/stat") as f:
                return int(f.read().rsplit(")", 1)[1].split()[7])
        except OSError:
            return None

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def drag_frames(server: FreshServer, n: int = 150) -> dict:
    """Ask a fresh server for ``n`` frames of a delay sweep, one at a time; per-frame round trip (ms),
    server render + encode (ms) and server page faults."""
    from websockets.sync.client import connect

    host = server.base.split("//", 1)[1]
    delays = np.linspace(-1500.0, 1500.0, 50)
    trip, work, faults = [], [], []
    with connect(f"ws://{host}/ws?token={server.token}", max_size=None, compression=None) as ws:
        ws.recv()  # hello
        for i in range(n):
            f0 = server.page_faults()
            t0 = time.perf_counter()
            ws.send(
                json.dumps({"type": "render", "panel": 0, "id": i, "settings": {"delay_us": float(delays[i % 50])}})
            )
            header, _ = decode_frame(ws.recv())
            trip.append((time.perf_counter() - t0) * 1e3)
            work.append(header["render_ms"] + header["encode_ms"])
            faults.append(None if f0 is None else server.page_faults() - f0)
    return {"trip": np.array(trip), "work": np.array(work), "faults": faults}


@contextlib.contextmanager
def busy_cores(n: int):
    """``n`` other processes spinning (one core each) for the duration."""
    procs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(n)]
    try:
        yield
    finally:
        for p in procs:
            p.kill()
            p.wait()


def _spread(a) -> str:
    return f"{np.median(a):5.1f} ms (10-90 %: {np.percentile(a, 10):.1f}-{np.percentile(a, 90):.1f})"


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[128, 512])
    parser.add_argument("--scene", default="wax")
    parser.add_argument("--seconds", type=float, default=5.0)
    parser.add_argument("--load", type=int, default=0, help="Other processes keeping one core busy each.")
    parser.add_argument("--repeat", type=int, default=1, help="Browser measurements per size (fresh server each).")
    parser.add_argument("--no-browser", action="store_true", help="Only the server-side parts.")
    parser.add_argument("--no-inprocess", action="store_true", help="Skip part 1 (render and encode in this process).")
    args = parser.parse_args()
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(
        f"machine: {os.cpu_count()} cores, load average {load:.2f} at start, {args.load} busy process(es) added "
        f"for the fresh-server parts; chromium: {find_chromium()}"
    )

    rows = []
    for size in args.sizes:
        print(f"\n{args.scene} {size}x{size}")
        if not args.no_inprocess:
            t0 = time.perf_counter()
            source = open_source(args.scene, size=size)
            print(f"  opened in {time.perf_counter() - t0:.1f} s (this process)")
            s = server_side(source)
            print(
                f"  render (band, O(pixels))   {s['render']:7.2f} ms   dense matmul baseline {s['dense']:7.2f} ms "
                f"-> {s['dense'] / s['render']:.1f}x faster"
            )
            print(
                f"  encode (raw float32, {s['bytes'] // 1024} KiB) {s['raw']:6.2f} ms   PNG of the 8-bit image "
                f"({s['png_bytes'] // 1024} KiB) {s['png']:6.2f} ms -> {s['png'] / s['raw']:.1f}x faster"
            )
            print(f"  render with camera noise   {s['noisy']:7.2f} ms")
            del source
        with busy_cores(args.load):
            with FreshServer(args.scene, size) as srv:
                d = drag_frames(srv)
            for lo, hi in ((0, 50), (50, len(d["trip"]))):
                f = [x for x in d["faults"][lo:hi] if x is not None]
                print(
                    f"  fresh server, frames {lo + 1}-{hi}: round trip {_spread(d['trip'][lo:hi])}, "
                    f"server render+encode {_spread(d['work'][lo:hi])}"
                    + (f", {np.mean(f):.0f} page faults/frame" if f else "")
                )
            if args.no_browser:
                continue
            for uncapped in (False, True):
                if uncapped and rows[-1][2]["fps"] < 0.9 * rows[-1][2]["display_hz"]:
                    break  # not limited by the display: nothing more to see with vsync off
                for _ in range(args.repeat):
                    with FreshServer(args.scene, size) as srv:
                        r = measure_painted_fps(srv, seconds=args.seconds, uncapped=uncapped)
                    mode = "vsync off, slider moved 250/s" if uncapped else f"display {r['display_hz']:.0f} Hz"
                    print(
                        f"  browser ({mode}): {r['fps']:.1f} frames painted/s; median ms: "
                        f"render {r['render_ms']:.2f}, encode {r['encode_ms']:.2f}, queue {r['queue_ms']:.2f}, "
                        f"transfer {r['transfer_ms']:.2f}, decode {r['decode_ms']:.2f}, paint {r['paint_ms']:.2f}; "
                        f"latency {r['latency_ms']:.1f}"
                    )
                    rows.append((size, mode, r))
    if rows:
        print("\n| size | browser | frames painted/s | render | encode | queue | transfer | decode | paint | latency |")
        print("|---|---|---|---|---|---|---|---|---|---|")
        for size, mode, r in rows:
            print(
                f"| {size}x{size} | {mode} | **{r['fps']:.1f}** | {r['render_ms']:.1f} ms | "
                f"{r['encode_ms']:.2f} ms | {r['queue_ms']:.1f} ms | {r['transfer_ms']:.1f} ms | "
                f"{r['decode_ms']:.2f} ms | {r['paint_ms']:.2f} ms | {r['latency_ms']:.0f} ms |"
            )
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"\nload average {load:.2f} at the end")


if __name__ == "__main__":
    main()

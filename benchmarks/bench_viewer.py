"""The live viewer's frame rate, and where each millisecond goes (render, encode, transfer, paint).

1. Server side, in this process, on the ``wax`` scene: the band render of one frame with planeray's
   O(pixels) renderer against the dense weighted sum over offsets (``np.matmul``, the baseline), and
   the frame's encoding as raw float32 bytes against a PNG of its 8-bit display image (Pillow,
   fastest compression, the baseline), at each size.
2. In the browser: ``planeray view wax`` is served on 127.0.0.1 and opened in the system's headless
   Chromium (no debugging protocol attached, see :mod:`planeray.viewer.browser`); the page moves its
   delay slider once per displayed frame (as a hand dragging it) for ``--seconds`` and reports the
   frames it painted per second -- counted in ``requestAnimationFrame`` -- and the median
   milliseconds of each step: render and encode (server), queue (waiting behind the previous
   render), transfer (server send to page receive), decode and paint (page: colour table +
   ``putImageData``), and the latency from request to painted frame.  At the display's refresh
   rate (what a user sees: at most one new frame per refresh) and, where that rate was the limit,
   again with vsync off and the slider moved 250 times a second (what the pipeline delivers
   beyond the display; on two cores the uncapped compositor competes with everything else).

Run: ``make bench-viewer`` or ``.venv/bin/python benchmarks/bench_viewer.py [--sizes 128 512 --seconds 5]``.
"""

from __future__ import annotations

import argparse
import io
import os
import time

import numpy as np

from planeray.timing import PAPER_LINES_PER_SECOND, Band
from planeray.viewer.browser import find_chromium, measure_painted_fps
from planeray.viewer.display import auto_white, to_rgb
from planeray.viewer.server import ViewerServer, encode_frame
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
    render = _median_ms(lambda i: source.render(ViewSettings(delay_us=float(delays[i]))), n)

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


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[128, 512])
    parser.add_argument("--scene", default="wax")
    parser.add_argument("--seconds", type=float, default=5.0)
    parser.add_argument("--no-browser", action="store_true", help="Only the server-side part.")
    args = parser.parse_args()
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"machine: {os.cpu_count()} cores, load average {load:.2f} at start; chromium: {find_chromium()}")

    rows = []
    for size in args.sizes:
        t0 = time.perf_counter()
        source = open_source(args.scene, size=size)
        print(f"\n{args.scene} {size}x{size}: opened in {time.perf_counter() - t0:.1f} s")
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
        if args.no_browser:
            continue
        for uncapped in (False, True):
            if uncapped and rows[-1][2]["fps"] < 0.9 * rows[-1][2]["display_hz"]:
                break  # not limited by the display: nothing more to see with vsync off
            with ViewerServer(source) as srv:
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

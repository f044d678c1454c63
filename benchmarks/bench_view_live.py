"""``planeray view --device sim`` in chromium: frames painted per second, and a slider move to the frame that shows it.

A freshly started ``planeray view --device sim -O size=[N, N]`` (the simulated pulsing skin, one
frame per image, as a user starts it) is opened in the system's headless Chromium (no debugging
protocol attached, :func:`planeray.viewer.browser.measure_painted_fps`); the page moves its delay
slider once per displayed frame for ``--seconds`` and reports:

* the frames it painted per second (counted in ``requestAnimationFrame``) and the camera's capture rate;
* **slider to frame**: for each slider value that was shown, the milliseconds from the input event to
  the painting of the first frame *captured at that delay* (median and 90th percentile);
* request to paint, and where the time goes (render, queue, transfer, decode, paint);
* the same with ``-O noise=false``: the capture without the simulated camera's noise model (at 512 x 512
  most of a frame's capture), to tell the pipeline's cost from the simulation's.

Baseline, measured in the same run on the same machine: ``planeray view skin --size N`` (the scene
explorer, which renders each frame on request and captures nothing), through the same page and
measurement: the live path's cost is printed as a ratio to it.  The machine's load average (and its
cores) is printed before and after: the machine is shared.

Run: ``.venv/bin/python benchmarks/bench_view_live.py [--size 512 --seconds 6 --repeat 2]``.
"""

from __future__ import annotations

import argparse
import os
import time

from bench_viewer import FreshServer

from planeray.viewer.browser import find_chromium, measure_painted_fps


def FreshView(args: list[str]) -> FreshServer:
    """``planeray view ARGS --port 0 --no-browser`` in a new process (:class:`bench_viewer.FreshServer`)."""
    return FreshServer(None, None, timeout_s=600.0, args=args)


def _load() -> str:
    one, five, _ = os.getloadavg()
    return f"load average {one:.2f} (1 min), {five:.2f} (5 min) on {os.cpu_count()} cores"


def _fmt(r: dict) -> str:
    def ms(key):
        v = r.get(key)
        return "n/a" if v is None else f"{v:.1f}"

    return (
        f"{r['fps']:.1f} frames painted/s (display {r['display_hz']:.0f} Hz); slider to frame: median "
        f"{ms('slider_ms')} ms, 90 % {ms('slider_p90_ms')} ms over {r.get('slider_n', 0)} values shown; request to "
        f"paint {ms('latency_ms')} ms (render {ms('render_ms')}, queue {ms('queue_ms')}, transfer {ms('transfer_ms')}, "
        f"decode {ms('decode_ms')}, paint {ms('paint_ms')})"
    )


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--seconds", type=float, default=6.0)
    parser.add_argument("--repeat", type=int, default=1)
    args = parser.parse_args()
    n = args.size
    print(f"machine: {_load()} at start; chromium: {find_chromium()}")
    rows = []
    for _ in range(args.repeat):
        for label, view_args in (
            ("live: view --device sim", ["--device", "sim", "-O", f"size=[{n}, {n}]"]),
            ("live, camera noise off (the pipeline without the noise model)",
             ["--device", "sim", "-O", f"size=[{n}, {n}]", "-O", "noise=false"]),
            ("baseline: view skin (no capture)", ["skin", "--size", str(n)]),
        ):  # fmt: skip
            t0 = time.perf_counter()
            with FreshView(view_args) as srv:
                started = time.perf_counter() - t0
                r = measure_painted_fps(srv, seconds=args.seconds)
            rows.append((label, r))
            print(f"{label} {n}x{n} (started in {started:.0f} s): {_fmt(r)}; {_load()}")
    live = [r for label, r in rows if label.startswith("live:")]
    base = [r for label, r in rows if label.startswith("baseline")]
    fps = sorted(r["fps"] for r in live)[len(live) // 2]
    slider = sorted(r["slider_ms"] for r in live if r.get("slider_ms") is not None)
    print(
        f"\nlive {n}x{n}: {fps:.1f} frames painted/s (target >= 30), slider to frame median "
        f"{slider[len(slider) // 2] if slider else float('nan'):.1f} ms (target <= 100); "
        f"frames painted: {fps / sorted(r['fps'] for r in base)[len(base) // 2]:.2f}x the scene explorer's"
    )
    print(f"machine: {_load()} at the end")


if __name__ == "__main__":
    main()

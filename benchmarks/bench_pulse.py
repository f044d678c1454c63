"""Eulerian magnification throughput (frames per second) at 128x128 and 640x480, against a per-frame loop.

planeray's :func:`planeray.pulse.evm.magnify` (the paper's settings: Gaussian pyramid of 4 levels,
ideal band-pass 0.5-2 Hz, alpha 50) calls OpenCV's ``pyrDown``/``pyrUp`` once per frame into
preallocated arrays and filters in time with one real FFT along the frame axis of the whole
level.  The baselines, measured in the same run on the same frames: the structure of Wu et
al.'s reference code written with naive loops: the pyramid frame by frame and each pixel's time
series band-passed on its own (a loop over pixels); and the frames stacked as the channels of one
OpenCV image (up to 512 per call), the other way to vectorize the pyramid.  The outputs are
compared (max abs difference).

Run: ``.venv/bin/python benchmarks/bench_pulse.py [--frames 300 --repeat 3]``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from planeray.pulse.evm import magnify


def _chain(g, levels):
    import cv2

    sizes = [g.shape[:2]]
    for _ in range(levels):
        g = cv2.pyrDown(g)
        sizes.append(g.shape[:2])
    return g, sizes


def _unchain(g, sizes):
    import cv2

    for h, w in reversed(sizes[:-1]):
        g = cv2.pyrUp(g, dstsize=(w, h))
    return g


def per_pixel_magnify(frames, fps, *, levels=4, band_hz=(0.5, 2.0), alpha=50.0):
    """Baseline 1, the naive loops: pyramid frame by frame, then each pixel's time series filtered on its own."""
    small = []
    for f in frames:
        g, sizes = _chain(f, levels)
        small.append(g)
    small = np.stack(small)
    n = small.shape[0]
    freq = np.fft.rfftfreq(n, 1.0 / fps)
    keep = (freq >= band_hz[0]) & (freq <= band_hz[1])
    filt = np.empty_like(small)
    for i in range(small.shape[1]):
        for j in range(small.shape[2]):
            spec = np.fft.rfft(small[:, i, j])
            filt[:, i, j] = np.fft.irfft(spec * keep, n) * alpha
    return np.stack([f + _unchain(g, sizes) for f, g in zip(frames, filt)])


def channels_magnify(frames, fps, *, levels=4, band_hz=(0.5, 2.0), alpha=50.0):
    """Baseline 2, "vectorized" the other way: the frames as the channels of one OpenCV image (<= 512 at a time)."""
    from planeray.pulse.evm import ideal_bandpass

    def by_channels(x, fn):
        out = []
        for s in range(0, x.shape[0], 512):
            r = fn(np.ascontiguousarray(np.moveaxis(x[s : s + 512], 0, -1)))
            out.append(np.moveaxis(r if r.ndim == 3 else r[:, :, None], -1, 0))
        return np.concatenate(out)

    _, sizes = _chain(frames[0], levels)
    g = frames
    for _ in range(levels):
        import cv2

        g = by_channels(g, cv2.pyrDown)
    filt = ideal_bandpass(g, fps, band_hz) * np.float32(alpha)
    return frames + by_channels(filt, lambda b: _unchain(b, sizes))


def bench(shape, n_frames, repeat, fps=30.0):
    rng = np.random.default_rng(0)
    t = np.arange(n_frames) / fps
    frames = (0.5 + 0.05 * rng.random((1, *shape)) + 0.005 * np.sin(2 * np.pi * 1.2 * t)[:, None, None]).astype(
        np.float32
    )
    frames += 0.01 * rng.standard_normal(frames.shape).astype(np.float32)

    def best(fn):
        times = []
        for _ in range(repeat):
            t0 = time.perf_counter()
            res = fn()
            times.append(time.perf_counter() - t0)
        return min(times), res

    t_fast, a = best(lambda: magnify(frames, fps))
    t_pix, b = best(lambda: per_pixel_magnify(frames, fps))
    t_ch, c = best(lambda: channels_magnify(frames, fps))
    return {
        "fast_fps": n_frames / t_fast,
        "pixel_fps": n_frames / t_pix,
        "channels_fps": n_frames / t_ch,
        "max_diff": float(max(np.abs(a - b).max(), np.abs(a - c).max())),
    }


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--frames", type=int, default=300, help="frames per video (10 s at 30 fps)")
    p.add_argument("--repeat", type=int, default=3)
    args = p.parse_args(argv)
    print(f"Eulerian magnification (4 levels, 0.5-2 Hz, alpha 50), {args.frames} frames, best of {args.repeat}")
    print(f"{'size':>10} {'planeray':>10} {'per-pixel loops':>22} {'frames as channels':>24} {'max diff':>9}")
    for shape in ((128, 128), (480, 640)):
        r = bench(shape, args.frames, args.repeat)
        f = r["fast_fps"]
        print(
            f"{shape[1]:>4}x{shape[0]:<5} {f:>6.0f} fps {r['pixel_fps']:>8.0f} fps ({f / r['pixel_fps']:>5.1f}x) "
            f"{r['channels_fps']:>10.0f} fps ({f / r['channels_fps']:>5.1f}x) {r['max_diff']:>9.1e}"
        )


if __name__ == "__main__":
    main()

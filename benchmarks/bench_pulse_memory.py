"""Peak memory of ``planeray skin pulse`` on a 30 s 1080p 30 fps video, against the in-memory path on a short one.

A synthetic recording -- a patch of skin (a smooth texture) whose middle pulses with a PPG waveform
(:func:`planeray.pulse.waveform.cardiac_signal`, 1.5 % of the light) plus camera noise, 8-bit -- is
written into a temporary folder as H.264 mp4 (``crf 18``; ``--tiff`` also as an 8-bit multi-page TIFF)
and analysed by ``planeray skin pulse VIDEO --out DIR --json`` in a fresh process, the region found
automatically (the search keeps the magnified video: the largest thing the analysis keeps;
``--laplacian`` also with ``--pyramid laplacian``, whose full-resolution bands are kept too). Each
process's peak resident memory is its own (``os.wait4``'s ``ru_maxrss``), reported with the bytes per
pixel-frame and the wall time. The baseline, in the same run: a short video (``--short``, 200x200 x 600
frames) analysed by ``skin pulse`` and by the in-memory path of the Python API
(``analyze_pulse(read_video(...))``, which holds the video), whose rates must agree; ``--compare-src
PATH`` also runs ``skin pulse`` of another planeray source tree (e.g. the main branch's) on it.

Target (issue 40): the 1080p video within 2 GB of peak memory.

The temporary files of the analysis (7.5 GB for the magnified 1080p video, ~18 GB with
``--laplacian``) go beside each result, in ``--folder`` (default: the system's temporary folder).

Run: ``make bench-pulse-memory`` (= ``.venv/bin/python benchmarks/bench_pulse_memory.py``; options
``--seconds 30 --size 1080 1920 --tiff --laplacian --compare-src PATH``).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

BPM = 72.0


def synthetic_frames(n_frames: int, shape, fps: float, *, seed: int = 0):
    """8-bit frames of a pulsing skin patch with noise, one at a time (the truth: ``BPM``)."""
    import cv2

    from planeray.pulse.waveform import cardiac_signal

    rng = np.random.default_rng(seed)
    H, W = shape
    small = rng.random((max(H // 32, 2), max(W // 32, 2))).astype(np.float32)
    texture = 120.0 + 40.0 * cv2.resize(small, (W, H), interpolation=cv2.INTER_CUBIC)
    patch = np.zeros((H, W), np.float32)
    patch[H // 3 : 2 * H // 3, W // 3 : 2 * W // 3] = 1.0
    patch = cv2.GaussianBlur(patch, (0, 0), max(H, W) / 100)
    pulse = cardiac_signal(n_frames, fps, bpm=BPM, seed=seed).volume
    pulse = (pulse - pulse.mean()) / np.ptp(pulse)
    noise = [rng.normal(0.0, 2.0, (H, W)).astype(np.float32) for _ in range(16)]  # a pool: cheap, drawn at random
    for t in range(n_frames):
        frame = texture * (1.0 - 0.015 * pulse[t] * patch) + noise[rng.integers(16)]
        yield np.clip(frame + 0.5, 0, 255).astype(np.uint8)


def write_mp4(path: Path, n_frames: int, shape, fps: float) -> None:
    import imageio_ffmpeg

    H, W = shape
    writer = imageio_ffmpeg.write_frames(
        str(path),
        (W, H),
        pix_fmt_in="gray",
        fps=fps,
        codec="libx264",
        macro_block_size=1,
        quality=None,
        ffmpeg_log_level="error",
        output_params=["-crf", "18", "-preset", "ultrafast"],
    )
    writer.send(None)
    for frame in synthetic_frames(n_frames, shape, fps):
        writer.send(frame)
    writer.close()


def write_tiff(path: Path, n_frames: int, shape, fps: float) -> None:
    import tifffile

    tifffile.imwrite(
        path,
        synthetic_frames(n_frames, shape, fps),
        shape=(n_frames, *shape),
        dtype=np.uint8,
        imagej=True,
        metadata={"axes": "TYX", "finterval": 1.0 / fps},
    )


def measure(args, env=None) -> dict:
    """Run ``args`` in a fresh process: its wall and CPU time, its own peak resident memory (bytes), its stdout."""
    t0 = time.perf_counter()
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        proc = subprocess.Popen(args, stdout=out, stderr=err, env=env)
        _, status, usage = os.wait4(proc.pid, 0)
        proc.returncode = os.waitstatus_to_exitcode(status)
        wall = time.perf_counter() - t0
        out.seek(0)
        err.seek(0)
        stdout, stderr = out.read().decode(), err.read().decode()
    if proc.returncode:
        raise SystemExit(f"{' '.join(map(str, args))} failed ({proc.returncode}):\n{stderr[-3000:]}")
    cpu = usage.ru_utime + usage.ru_stime
    return {"wall_s": wall, "cpu_s": cpu, "peak_bytes": usage.ru_maxrss * 1024, "stdout": stdout}


def skin_pulse(video: Path, out: Path, *options, env=None) -> dict:
    words = [sys.executable, "-m", "planeray.cli", "skin", "pulse", str(video), "--out", str(out), "--json", *options]
    r = measure(words, env)
    r["rate_bpm"] = json.loads(r["stdout"])["rate_bpm"]
    return r


IN_MEMORY = """
import json, sys
from planeray.pulse.analysis import analyze_pulse
from planeray.pulse.video_io import read_video
print(json.dumps({"rate_bpm": analyze_pulse(read_video(sys.argv[1])).estimate.rate_bpm}))
"""


def in_memory(video: Path) -> dict:
    r = measure([sys.executable, "-c", IN_MEMORY, str(video)])
    r["rate_bpm"] = json.loads(r["stdout"])["rate_bpm"]
    return r


def row(name: str, n_frames: int, shape, r: dict) -> str:
    px = n_frames * shape[0] * shape[1]
    rate = "none" if r["rate_bpm"] is None else f"{r['rate_bpm']:.2f}"
    return (
        f"{name:<46} {n_frames:>6} {shape[1]:>5}x{shape[0]:<5} {r['peak_bytes'] / 2**20:>8.0f} MiB "
        f"{r['peak_bytes'] / px:>8.2f} {r['wall_s']:>8.1f} s {r['cpu_s']:>8.1f} s {rate:>8}"
    )


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seconds", type=float, default=30.0, help="length of the large video (s)")
    p.add_argument("--fps", type=float, default=30.0)
    p.add_argument("--size", type=int, nargs=2, default=(1080, 1920), metavar=("H", "W"), help="large video's size")
    p.add_argument("--short", type=int, nargs=3, default=(600, 200, 200), metavar=("T", "H", "W"), help="the baseline")
    p.add_argument("--tiff", action="store_true", help="also the large video as an 8-bit multi-page TIFF")
    p.add_argument("--laplacian", action="store_true", help="also the large mp4 with --pyramid laplacian")
    p.add_argument("--compare-src", type=Path, help="also run skin pulse of this planeray source tree (short video)")
    p.add_argument("--folder", type=Path, help="where the videos and results go (default: a temporary folder)")
    args = p.parse_args(argv)
    big_n, big_shape = int(round(args.seconds * args.fps)), tuple(args.size)
    short_n, short_shape = args.short[0], tuple(args.short[1:])
    with tempfile.TemporaryDirectory(dir=args.folder) as d:
        d = Path(d)
        print(f"true rate {BPM:g} bpm; peak resident memory and CPU time of each process (os.wait4), fresh processes")
        print(
            f"{'what':<46} {'frames':>6} {'size':>11} {'peak':>12} {'B/px-fr':>8} {'wall':>10} {'CPU':>10} {'bpm':>8}"
        )
        write_tiff(d / "short.tif", short_n, short_shape, args.fps)
        ref = in_memory(d / "short.tif")
        print(row("in memory: analyze_pulse(read_video(...))", short_n, short_shape, ref))
        r = skin_pulse(d / "short.tif", d / "short_out")
        print(row("streamed: planeray skin pulse", short_n, short_shape, r))
        if r["rate_bpm"] != ref["rate_bpm"]:
            raise SystemExit(f"the streamed rate {r['rate_bpm']} differs from the in-memory rate {ref['rate_bpm']}")
        if args.compare_src is not None:
            env = {**os.environ, "PYTHONPATH": str(args.compare_src.resolve())}
            r = skin_pulse(d / "short.tif", d / "short_cmp", env=env)
            print(row(f"skin pulse of {args.compare_src}", short_n, short_shape, r))
        t0 = time.perf_counter()
        write_mp4(d / "large.mp4", big_n, big_shape, args.fps)
        made = f"(mp4 written in {time.perf_counter() - t0:.0f} s, {(d / 'large.mp4').stat().st_size / 2**20:.0f} MiB)"
        r = skin_pulse(d / "large.mp4", d / "large_out")
        print(row("streamed: planeray skin pulse, mp4", big_n, big_shape, r), made)
        if args.laplacian:
            r = skin_pulse(d / "large.mp4", d / "large_lap_out", "--pyramid", "laplacian")
            print(row("streamed: ... --pyramid laplacian, mp4", big_n, big_shape, r))
        if args.tiff:
            write_tiff(d / "large.tif", big_n, big_shape, args.fps)
            (d / "large.mp4").unlink()
            r = skin_pulse(d / "large.tif", d / "large_tif_out")
            print(row("streamed: planeray skin pulse, 8-bit TIFF", big_n, big_shape, r))


if __name__ == "__main__":
    main()

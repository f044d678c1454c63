"""How exactly a rendered transport places light inside its offset bins: windows against per-row renders.

Renders a wall above a floor (the scene of ``tests/test_render.py``) in one pass with ``planeray.render`` and,
independently, one Mitsuba ``path`` image per projector row; then compares sharpened epipolar windows of the
rendered transport (0.5, 1, 1.5 and 3 rows centred on each camera row) with the exact integral of the same
windows over the per-row images (each projector row lit evenly over its cell).  Prints, per P/H, the ratio of
the two sums over all lit pixels -- the numbers quoted in README ("Conventions", binning rule).

    python tools/render_binning.py [--spp 256] [--geometry 96/64 --geometry 360/64]
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

SCENE = """<scene version="3.0.0">
    <default name="planeray_baseline" value="1.0"/>
    <sensor type="perspective">
        <float name="fov" value="40"/>
        <transform name="to_world"><lookat origin="0, -8, 6" target="0, 0, 1" up="0, 0, 1"/></transform>
        <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="16"/></film>
    </sensor>
    <shape type="rectangle"><transform name="to_world"><scale x="6" y="6"/></transform>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.6"/></bsdf></shape>
    <shape type="rectangle">
        <transform name="to_world"><scale x="6" y="3"/><rotate x="1" angle="90"/><translate y="2" z="3"/></transform>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.8"/></bsdf></shape>
</scene>
"""


def window_from_rows(per_row, P, H, lo, hi):
    out = np.zeros(per_row.shape[1:])
    v = np.arange(P)
    for t in range(H):
        p_t = (t + 0.5) * P / H - 0.5
        w = np.clip(np.minimum(v + 0.5, p_t + hi) - np.maximum(v - 0.5, p_t + lo), 0.0, None)
        out[t] = w @ per_row[:, t, :]
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--spp", type=int, default=256)
    ap.add_argument(
        "--geometry", action="append", help="P/H: projector rows / camera rows (default 96/64 and 360/64 = 720/128)"
    )
    args = ap.parse_args()
    import mitsuba as mi

    from planeray.render import render_transport
    from planeray.render._mitsuba import choose_variant
    from planeray.render.reference import render_rows
    from planeray.render.rig import Rig
    from planeray.render.scene_file import load_scene_file
    from planeray.synthesis import sharpened_epipolar

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "wall_floor.xml"
        path.write_text(SCENE)
        print(f"wall above a floor, {args.spp} spp; sums over lit pixels, rendered / per-row integral")
        print("| P / H | 0.5 row | 1 row | 1.5 rows | 3 rows |")
        print("|---|---|---|---|---|")
        for geometry in args.geometry or ["96/64", "360/64"]:
            P, H = (int(x) for x in geometry.split("/"))
            r = render_transport(path, shape=(H, H), projector_rows=P, spp=args.spp, seed=1, band_rows=16)
            choose_variant()
            mi.set_log_level(mi.LogLevel.Error)
            loaded = load_scene_file(path)
            rig = Rig.from_sensor(loaded.sensor, baseline=1.0, projector_rows=P)
            per_row = render_rows(loaded, rig, (H, H), range(P), spp=args.spp, seed=7)[..., 0]
            per_row = per_row / r.attrs["white_radiance"]
            lit = r.transport.full_image() > 0.05 * r.transport.full_image().max()
            ratios = []
            for w in (0.5, 1.0, 1.5, 3.0):
                est = sharpened_epipolar(r.transport, width_rows=w)[lit].sum()
                ref = window_from_rows(per_row, P, H, -w / 2, w / 2)[lit].sum()
                ratios.append(est / ref)
            print(f"| {P}/{H} ({P / H:g}) | " + " | ".join(f"{x:.3f}" for x in ratios) + " |")


if __name__ == "__main__":
    main()

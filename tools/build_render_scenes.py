"""Write the meshes of the example Mitsuba scenes (src/planeray/render/scenes/*.obj).

* ``disco_ball.obj``: a faceted ball -- a latitude-longitude sphere whose quads
  are flat (the scene renders it with ``face_normals``), radius 1, 16 x 32 facets.
* ``candle.obj``: a closed cylinder (side + caps), radius 1, height 1 (z in [0, 1]),
  64 segments, outward normals: a watertight boundary for the wax medium.

Run: ``.venv/bin/python tools/build_render_scenes.py``.
"""

from __future__ import annotations

import math
from pathlib import Path

OUT = Path(__file__).resolve().parents[1] / "src" / "planeray" / "render" / "scenes"


def _write(path: Path, vertices, faces, header: str) -> None:
    lines = [f"# {header}"]
    lines += [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in vertices]
    lines += ["f " + " ".join(str(i + 1) for i in face) for face in faces]
    path.write_text("\n".join(lines) + "\n")


def disco_ball(n_lat=16, n_lon=32):
    vertices, faces = [], []
    for i in range(n_lat + 1):
        theta = math.pi * i / n_lat
        for j in range(n_lon):
            phi = 2 * math.pi * j / n_lon
            vertices.append((math.sin(theta) * math.cos(phi), math.sin(theta) * math.sin(phi), math.cos(theta)))
    for i in range(n_lat):
        for j in range(n_lon):
            a, b = i * n_lon + j, i * n_lon + (j + 1) % n_lon
            c, d = (i + 1) * n_lon + (j + 1) % n_lon, (i + 1) * n_lon + j
            if i == 0:
                faces.append((a, d, c))
            elif i == n_lat - 1:
                faces.append((a, d, b))
            else:
                faces.append((a, d, c, b))
    return vertices, faces


def candle(n=64):
    vertices, faces = [], []
    for z in (0.0, 1.0):
        for j in range(n):
            phi = 2 * math.pi * j / n
            vertices.append((math.cos(phi), math.sin(phi), z))
    vertices += [(0.0, 0.0, 0.0), (0.0, 0.0, 1.0)]
    bottom, top = 2 * n, 2 * n + 1
    for j in range(n):
        k = (j + 1) % n
        faces.append((j, k, n + k, n + j))  # side, outward
        faces.append((bottom, k, j))  # bottom cap, facing -z
        faces.append((top, n + j, n + k))  # top cap, facing +z
    return vertices, faces


def main():
    _write(OUT / "disco_ball.obj", *disco_ball(), "planeray example: faceted disco ball (tools/build_render_scenes.py)")
    _write(OUT / "candle.obj", *candle(), "planeray example: closed cylinder (tools/build_render_scenes.py)")


if __name__ == "__main__":
    main()

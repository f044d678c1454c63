"""
Demultiplexing against the ground truth (Sec. 4)
================================================

``pr.demultiplex`` solves, pixel by pixel, the regularized non-negative least-squares problem of
Sec. 4 and returns the 3D transport ``T(u)`` of every pixel. On the simulated device the exact
transport is known, so the estimate can be drawn over the truth.

Command line: ``planeray demux STACK --out T.zarr``.
"""

import planeray as pr
from planeray.figures import transport_profiles_figure
from planeray.scenes import representative_pixels
from planeray.timing import sweep_support_rows

scene = pr.make_scene("mirror_ball", (64, 64), projector_rows=720, seed=0)
stack = pr.simulate_stack(scene, pr.paper_sweep(), seed=0)
result = pr.demultiplex(stack, alpha=0.01, beta=0.01)
T = result.transport
print("epipolar resolution:", result.attrs["epipolar_resolution_rows"], "rows")

support = sweep_support_rows(pr.paper_sweep(), pr.PAPER_LINES_PER_SECOND)
pixels, names = representative_pixels(scene, support)
fig = transport_profiles_figure(
    T,
    pixels,
    truth=scene.transport,
    truth_scale=float(stack.metadata["signal_scale"]),
    names=names,
    resolution_rows=result.attrs["epipolar_resolution_rows"],
)

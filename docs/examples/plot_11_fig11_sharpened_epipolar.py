"""
Fig. 11: sharpened epipolar imaging
===================================

The captured epipolar image of a wax candle (exposure 600 µs, a 32-row band) still holds the
glow of its subsurface light. From the demultiplexed transport, a band as narrow as the sweep
resolves, or one row, keeps only the direct light: the edges sharpen (paper Fig. 11).

Command line: ``planeray figure fig11 --out figs``.
"""

import matplotlib.pyplot as plt
import numpy as np

import planeray as pr

scene = pr.make_scene("wax", (64, 64), projector_rows=720, seed=0)
stack = pr.simulate_stack(scene, pr.paper_sweep(), seed=0)
result = pr.demultiplex(stack)
res = result.attrs["epipolar_resolution_rows"]
images = {
    "ground-truth direct": scene.direct,
    "captured, $t_e$ = 600 µs": stack.image(stack.index_of(0.0, 600.0)),
    f"sharpened, {2 * res:.1f} rows": pr.sharpened_epipolar(result.transport, width_rows=2 * res),
    "sharpened, 1 row": pr.sharpened_epipolar(result.transport, width_rows=1.0),
}
wax = scene.labels == 2
row = int(np.argmax(wax.sum(axis=1)))
cols = np.flatnonzero(wax[row])

fig = plt.figure(figsize=(10, 5.5))
grid = fig.add_gridspec(2, 4, height_ratios=[1.1, 1])
for i, (name, image) in enumerate(images.items()):
    ax = fig.add_subplot(grid[0, i])
    ax.imshow(image, cmap="gray", vmin=0, vmax=np.percentile(image, 99.7))
    ax.axhline(row, color="tab:red", lw=0.6)
    ax.set_title(name, fontsize=8)
    ax.set_axis_off()
ax = fig.add_subplot(grid[1, :])
for name, image in images.items():
    line = image[row, cols]
    contrast = (line.max() - line.min()) / (line.max() + line.min())
    ax.plot(cols, line / line.mean(), label=f"{name}: Michelson contrast {contrast:.2f}")
ax.set_xlabel(f"column (scan line at row {row}, wax only)")
ax.set_ylabel("value / mean")
ax.legend(fontsize=7)
fig.tight_layout()

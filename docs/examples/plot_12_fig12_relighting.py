"""
Fig. 12: relighting with a virtual projector line
=================================================

Once the transport is known, any projector pattern can be lit afterwards (Eq. 4 with a new
illumination): here a single projector row through the wax, from the demultiplexed transport,
beside the ground truth (paper Fig. 12).

Command line: ``planeray figure fig12 --out figs``; the explorer's pattern menu (``planeray view``).
"""

import matplotlib.pyplot as plt
import numpy as np

import planeray as pr

scene = pr.make_scene("wax", (64, 64), projector_rows=720, seed=0)
stack = pr.simulate_stack(scene, pr.paper_sweep(), seed=0)
T = pr.demultiplex(stack).transport
scale = float(stack.metadata["signal_scale"])

wax = scene.labels == 2
v = int(round(np.flatnonzero(wax.any(axis=1)).mean() * 720 / 64))  # a projector row through the wax
pattern = np.zeros(720)
pattern[v] = 1.0
truth = pr.relight(scene.transport, pattern)
relit = pr.relight(T, pattern) / scale
stripes = pr.relight(T, (np.arange(720) // 36 % 2).astype(float)) / scale  # any pattern: stripes

fig, axes = plt.subplots(1, 3, figsize=(9, 3.2))
for ax, (name, image) in zip(
    axes,
    [(f"ground truth, row {v}", truth), (f"from the stack, row {v}", relit), ("from the stack, stripes", stripes)],
):
    ax.imshow(image, cmap="gray", vmin=0, vmax=np.percentile(image, 99.8))
    ax.set_title(name, fontsize=9)
    ax.set_axis_off()
fig.tight_layout()

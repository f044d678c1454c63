"""
Epipolar, non-epipolar, short- and long-range images (Eqs. 5, 6)
================================================================

A transport splits into the light of the camera row's own epipolar plane (Eq. 5) and the light of
every other plane (Eq. 6); the non-epipolar light splits again by how far it travelled in
projector rows: short-range (subsurface scattering, near the plane) and long-range
(interreflections). Here from the exact transport of the disco ball and from the one
demultiplexed from its sweep.
"""

import matplotlib.pyplot as plt
import numpy as np

import planeray as pr

scene = pr.make_scene("disco_ball", (64, 64), projector_rows=720, seed=0)
stack = pr.simulate_stack(scene, pr.paper_sweep(), seed=0)
T = pr.demultiplex(stack).transport
scale = float(stack.metadata["signal_scale"])

rows = []
for name, t, k in [("ground truth", scene.transport, 1.0), ("demultiplexed", T, 1.0 / scale)]:
    short, long = pr.short_long_range(t, 20.0)
    rows.append(
        (
            name,
            {
                "epipolar (Eq. 5)": pr.epipolar_image(t) * k,
                "non-epipolar (Eq. 6)": pr.non_epipolar_image(t) * k,
                "short range, |u| <= 20": short * k,
                "long range, |u| > 20": long * k,
            },
        )
    )

fig, axes = plt.subplots(2, 4, figsize=(10, 5.4))
for r, (name, images) in enumerate(rows):
    for c, (title, image) in enumerate(images.items()):
        axes[r, c].imshow(image, cmap="gray", vmin=0, vmax=np.percentile(image, 99.5) + 1e-12)
        axes[r, c].set_title(f"{name}\n{title}", fontsize=8)
        axes[r, c].set_axis_off()
fig.tight_layout()

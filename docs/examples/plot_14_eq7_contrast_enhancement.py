"""
Eq. 7, Fig. 14: contrast enhancement over delays
================================================

A deep vein shows best at a longer delay than a shallow one. Eq. 7 composes one image from a
sweep of delay images: each pixel takes the delay whose image has the largest local gradient
there, ``I(s,t) = I_{t_d*}(s,t)``, ``t_d* = argmax ||grad I_{t_d}||`` (Sec. 10, paper Fig. 14).
The delay map says which delay each pixel took.

Command line: ``planeray skin enhance STACK --out DIR``.
"""

import matplotlib.pyplot as plt

import planeray as pr
from planeray.experiments.skin import (
    ROOM_LIGHT,
    SWEEP_DELAYS_US,
    SWEEP_EXPOSURE_US,
    camera_at,
    capture_delay_sweep,
    measure,
    valid_rows,
)
from planeray.skin.enhance import enhance_contrast

# the study's sweep (``planeray skin compare``): 300 us exposures, delays 250 to 1000 us, office light
scene = pr.make_scene("skin", (128, 128), projector_rows=720, seed=0)
delays_us = SWEEP_DELAYS_US[::2]
sweep = capture_delay_sweep(scene, camera_at(ROOM_LIGHT, 638.0), delays_us, exposure_us=SWEEP_EXPOSURE_US, seed=50)
result = enhance_contrast(sweep, delays_us)
valid = valid_rows(scene, float(delays_us[-1]), SWEEP_EXPOSURE_US)  # rows whose bands stay on the skin

cnr = {k: v["cnr"] for k, v in measure({f"{d:g} us": im for d, im in zip(delays_us, sweep)}, scene, valid).items()}
best = max(cnr, key=cnr.get)
enhanced_cnr = measure({"enhanced": result.image}, scene, valid)["enhanced"]["cnr"]
print("vein CNR per delay:", {k: round(v, 2) for k, v in cnr.items()})
print(f"best single delay {best}: CNR {cnr[best]:.2f}; Eq. 7 composite: CNR {enhanced_cnr:.2f}")

fig, axes = plt.subplots(1, 3, figsize=(10, 3.4))
single = sweep[list(cnr).index(best)]
axes[0].imshow(single, cmap="gray")
axes[0].set_title(f"best single delay ({best}), CNR {cnr[best]:.2f}", fontsize=8)
axes[1].imshow(result.image, cmap="gray")
axes[1].set_title(f"Eq. 7 composite, CNR {enhanced_cnr:.2f}", fontsize=8)
im = axes[2].imshow(result.delay_map_us, cmap="viridis")
axes[2].set_title("delay each pixel took (µs)", fontsize=8)
fig.colorbar(im, ax=axes[2], fraction=0.046)
for ax in axes:
    ax.set_axis_off()
fig.tight_layout()

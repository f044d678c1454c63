import matplotlib.pyplot as plt
import numpy as np

import planeray as pr

fig, axes = plt.subplots(1, 4, figsize=(11, 2.8), gridspec_kw={"width_ratios": [2.2, 1, 1, 1]})
ax = axes[0]
for name, label in [
    ("wax", "wax: subsurface"),
    ("mirror_ball", "mirror ball: specular"),
    ("corner", "corner: diffuse interreflection"),
]:
    scene = pr.make_scene(name, (64, 64), projector_rows=720, seed=0)
    T = scene.transport
    kind = {"wax": 2, "mirror_ball": 4, "corner": 3}[name]
    rows, cols = np.nonzero(scene.labels == kind)
    i = len(rows) // 2
    profile = T.dense[rows[i], cols[i]]
    ax.plot(T.offsets_rows, profile / profile.max(), lw=1.2, label=label)
ax.axvspan(-3, 3, color="tab:green", alpha=0.12, label="epipolar")
ax.axvspan(3, 20, color="tab:orange", alpha=0.12, label="short range")
ax.axvspan(-20, -3, color="tab:orange", alpha=0.12)
ax.set_xlim(-70, 70)
ax.set_xlabel("offset u (projector rows)")
ax.set_ylabel("T(u) / max")
ax.legend(fontsize=6)
disco = pr.make_scene("disco_ball", (64, 64), projector_rows=720, seed=0).transport
short, long = pr.short_long_range(disco, 20.0)
for ax, (title, image) in zip(
    axes[1:], [("epipolar (Eq. 5)", pr.epipolar_image(disco)), ("short range, |u| <= 20", short), ("long range", long)]
):
    ax.imshow(image, cmap="gray", vmin=0, vmax=np.percentile(image, 99.5))
    ax.set_title(title, fontsize=8)
    ax.set_axis_off()

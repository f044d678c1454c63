"""
A first sweep on the simulated device
=====================================

Simulate the paper's 85-image delay-exposure sweep (Sec. 4) of a translucent wax object on the
built-in device, and look at four of its images. Only the delay and the exposure change from
image to image: they decide which light paths reach the camera.

Command line: ``planeray simulate wax --out wax.zarr --size 64 64``.
"""

import matplotlib.pyplot as plt

import planeray as pr

scene = pr.make_scene("wax", (64, 64), projector_rows=720, seed=0)
stack = pr.simulate_stack(scene, pr.paper_sweep(), seed=0)
print(len(stack), "images of", stack.shape, "pixels")
print("delays (us):", sorted(set(stack.delays().tolist())))
print("exposures (us):", sorted(set(stack.exposures().tolist())))

# %%
# The epipolar image (delay 0) shows direct light and the light that stays close; delays of a
# few hundred microseconds move the band off the epipolar plane and keep only light that
# travelled under the surface (short-range indirect light).

settings = [(0.0, 600.0), (375.0, 600.0), (-375.0, 600.0), (1125.0, 600.0)]
fig, axes = plt.subplots(1, 4, figsize=(10, 2.9))
for ax, (delay, exposure) in zip(axes, settings):
    image = stack.image(stack.index_of(delay, exposure))
    ax.imshow(image, cmap="gray", vmin=0, vmax=stack.image(stack.index_of(0.0, 600.0)).max())
    ax.set_title(f"$t_d$ = {delay:g} µs, $t_e$ = {exposure:g} µs", fontsize=8)
    ax.set_axis_off()
fig.tight_layout()

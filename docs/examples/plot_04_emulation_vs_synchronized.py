"""
Fig. 4: with and without synchronization
========================================

Without a synchronized camera, a delay image can be emulated from conventional captures: light
the band a synchronized device would light for one camera row, take a full frame, keep that row,
and repeat for every row (Sec. 5.1, paper Fig. 4). The result matches the synchronized image, at
the cost of one capture per row instead of one. Nayar et al.'s high-frequency patterns (2006)
separate direct from global light with a few captures instead, under assumptions on the scene.

Command line: ``planeray emulate wax --delay-us 0 --exposure-us 600 --out DIR``;
``planeray separate direct-global wax --out DIR``.
"""

import matplotlib.pyplot as plt
import numpy as np

import planeray as pr
from planeray.baselines.emulation import emulate_delay_image
from planeray.baselines.nayar import capture_direct_global

scene = pr.make_scene("wax", (64, 64), projector_rows=720, seed=0)
camera = pr.CameraModel(ambient_e_per_us=0.0)
device = pr.SimulatedEpiscan(scene, camera, seed=0)
lps = pr.PAPER_LINES_PER_SECOND

truth = scene.transport.render(pr.Band(delay_us=0.0, exposure_us=600.0, lines_per_second=lps))
emulated = emulate_delay_image(device, 0.0, 600.0)
stack = pr.simulate_stack(scene, pr.paper_sweep(), camera=camera, seed=0)
synchronized = stack.image(stack.index_of(0.0, 600.0)) / camera.signal_scale
nayar = capture_direct_global(pr.SimulatedEpiscan(scene, camera, seed=0))

images = {
    "noise-free epipolar band": truth,
    f"emulated ({emulated.n_captures} captures)": emulated.image,
    "synchronized (1 capture)": synchronized,
    "Nayar et al.: direct": nayar.direct,
}
for name, image in list(images.items())[1:3]:
    print(f"{name}: RMSE against the noise-free band {np.sqrt(np.mean((image - truth) ** 2)):.5f}")
fig, axes = plt.subplots(1, 4, figsize=(10, 2.9))
for ax, (name, image) in zip(axes, images.items()):
    ax.imshow(image, cmap="gray", vmin=0, vmax=np.percentile(truth, 99.5))
    ax.set_title(name, fontsize=8)
    ax.set_axis_off()
fig.tight_layout()

"""
Figs. 13, 16: veins through skin
================================

Under a forearm's skin, blood absorbs the red light that scatters a few millimetres through the
tissue. A band of delays off the epipolar plane keeps only that short-range indirect light and
drops the direct reflection of the surface, so veins stand out (Sec. 10, paper Figs. 13, 16).
Each image is titled with the contrast-to-noise ratio (CNR) of the scene's veins, measured on
their ground-truth mask.

Command line: ``planeray skin simulate --out arm.zarr``, ``planeray skin veins arm.zarr --delay-us 500 --out veins``;
``planeray skin compare`` runs Figs. 13, 14 and 16.
"""

import planeray as pr
from planeray.experiments.skin import measure
from planeray.figures.skin import headline_figure
from planeray.skin.imaging import device_images

scene = pr.make_scene("skin", (96, 96), projector_rows=720, seed=0, tone="fair", wavelength_nm=638)
for vein in pr.skin_veins(scene):
    print(f"vein {vein.id}: {vein.depth_mm:.1f} mm deep, {vein.diameter_mm:.1f} mm wide")

images, _ = device_images(
    scene, pr.CameraModel(), delay_us=500.0, exposure_us=600.0, methods=("photo", "direct", "delay")
)
metrics = measure(images, scene)
labels = {"photo": "photo (all light)", "direct": "epipolar (direct)", "delay": "delay 500 µs (short-range indirect)"}
fig = headline_figure(images, labels=labels, metrics=metrics)

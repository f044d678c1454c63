"""
Your own capture: export and import
===================================

A capture from any camera is a folder of 16-bit images with ``manifest.csv`` and
``acquisition.json`` (the import folder format). ``pr.export_folder`` writes one from a stack,
``pr.read_stack`` reads it back (as does every command that takes a stack).

Command line: ``planeray export STACK --out folder``; ``planeray import folder --out stack.zarr``.
"""

import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

import planeray as pr

scene = pr.make_scene("corner", (48, 48), projector_rows=720, seed=0)
stack = pr.simulate_stack(scene, pr.quick_sweep(), seed=0)
folder = Path(tempfile.mkdtemp()) / "my_capture"
pr.export_folder(stack, folder)
print(sorted(p.name for p in folder.iterdir())[:5], "...")
print((folder / "manifest.csv").read_text().splitlines()[:3])

again = pr.read_stack(folder)
error = max(float(np.abs(again.image(i) - stack.image(i)).max()) for i in range(len(stack)))
print(f"{len(again)} images read back; largest difference {error:.1e} (16-bit quantization)")

fig, axes = plt.subplots(1, 2, figsize=(6, 3))
for ax, (name, s) in zip(axes, [("simulated", stack), ("exported and read back", again)]):
    ax.imshow(s.image(0), cmap="gray")
    ax.set_title(name, fontsize=9)
    ax.set_axis_off()
fig.tight_layout()

import matplotlib.pyplot as plt
import numpy as np

import planeray as pr

geometry = pr.RowGeometry(camera_rows=128, projector_rows=720)
band = pr.Band(delay_us=0.0, exposure_us=600.0, lines_per_second=pr.PAPER_LINES_PER_SECOND)
u = np.arange(-25, 26)
fig, axes = plt.subplots(1, 2, figsize=(8, 2.5), sharey=True)
for ax, row in zip(axes, [0, 64]):
    ax.bar(u, geometry.coverage(row, u), width=1.0, color="0.85", label="coverage of the bin")
    ax.step(u, band.weights(geometry, row, u), where="mid", color="tab:blue", label="band weight (edge rule)")
    ax.set_title(f"camera row {row} (p_t = {geometry.projector_row_of(row):.2f})", fontsize=9)
    ax.set_xlabel("offset u (projector rows)")
axes[0].legend(fontsize=7)

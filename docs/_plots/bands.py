import matplotlib.pyplot as plt
import numpy as np

import planeray as pr

lps = pr.PAPER_LINES_PER_SECOND
u = np.arange(-90, 91)
fig, ax = plt.subplots(figsize=(7, 2.6))
for delay, exposure in [(0.0, 600.0), (750.0, 600.0), (-750.0, 1200.0)]:
    band = pr.Band(delay_us=delay, exposure_us=exposure, lines_per_second=lps)
    ax.fill_between(
        u,
        band.profile(u),
        step="mid",
        alpha=0.45,
        label=f"$t_d$ = {delay:g} µs, $t_e$ = {exposure:g} µs: centre {band.centre_rows:.1f}, width {band.width_rows:.1f} rows",
    )
ax.set_xlabel("offset u = v - p_t (projector rows)")
ax.set_ylabel("weight of the bin")
ax.legend(fontsize=7, loc="upper left")
ax.set_ylim(0, 1.6)

"""
Band, delay and exposure (Eqs. 1-3)
===================================

The camera exposes a band of rows that follows the projector's line. The delay ``t_d`` moves the
band's centre to the offset ``I_d = v_p t_d`` (Eq. 2) and the exposure ``t_e`` sets its width
``I_w = v_p t_e``; the weights of a band over the 1-row offset bins of ``u = v - p_t`` are exact
integrals of the band (Eq. 3), so they sum to ``I_w``.
"""

import matplotlib.pyplot as plt
import numpy as np

import planeray as pr

lps = pr.PAPER_LINES_PER_SECOND  # 54,000 lines per second
offsets = np.arange(-100, 101)  # u, in projector rows
fig, ax = plt.subplots(figsize=(8, 3.2))
for delay, exposure in [(0.0, 600.0), (375.0, 600.0), (-750.0, 1200.0)]:
    band = pr.Band(delay_us=delay, exposure_us=exposure, lines_per_second=lps)
    w = band.profile(offsets)  # the weight of each whole 1-row bin (Band.weights adds the edge rule)
    centre, width = band.centre_rows, band.width_rows
    print(
        f"t_d={delay:7.1f} us  t_e={exposure:6.1f} us: centre {centre:6.2f} rows, width {width:5.2f} rows, sum {w.sum():.2f}"
    )
    ax.step(offsets, w, where="mid", label=f"$t_d$={delay:g} µs, $t_e$={exposure:g} µs")
ax.set_xlabel("offset u = v - p_t (projector rows)")
ax.set_ylabel("illumination weight of the bin")
ax.legend(fontsize=8)
ax.grid(alpha=0.3)
fig.tight_layout()

"""
The live explorer's frames, and a delay-sweep video
===================================================

``planeray view`` opens a page in the browser with a delay and an exposure slider; each frame it
shows is a band image rendered on demand from a transport (or the nearest captured image of a
stack). ``planeray video`` writes the same frames over a sweep as an MP4. Here a few frames of a
delay sweep of the disco ball, rendered by the explorer's own code, and the video written.

Command line: ``planeray view disco_ball``; ``planeray video disco_ball --sweep delay --out sweep.mp4``.
"""

import tempfile
from pathlib import Path

import matplotlib.pyplot as plt

from planeray.viewer.session import ViewSettings, open_source
from planeray.viewer.video import write_sweep_video

source = open_source("disco_ball", size=64)
delays = [-1500.0, -750.0, 0.0, 375.0, 750.0, 1500.0]
fig, axes = plt.subplots(1, len(delays), figsize=(11, 2.3))
for ax, delay in zip(axes, delays):
    image, info = source.render(ViewSettings(delay_us=delay, exposure_us=600.0))
    ax.imshow(image, cmap="gray", vmin=0, vmax=float(image.max()) or 1.0)
    ax.set_title(f"$t_d$ = {delay:g} µs", fontsize=8)
    ax.set_axis_off()
fig.tight_layout()

# %%
# The video of the whole sweep (31 frames here; 121 by default).

video = write_sweep_video(source, Path(tempfile.mkdtemp()) / "sweep.mp4", frames=31)
print(video.name, video.stat().st_size, "bytes")

"""
Fig. 9: delay profiles
======================

A pixel's delay profile (its value against delay, normalized by its area) tells the effect that
lights it: a narrow peak for direct light, a broad one for subsurface scattering, a one-sided
ramp for diffuse interreflection, two peaks for a specular interreflection (paper Fig. 9, Sec. 8).
The pixels are picked from the scene's ground truth.

Command line: ``planeray profiles STACK --pixel 60 64 --out fig9.png``; ``planeray figure fig9``.
"""

import planeray as pr
from planeray.figures import delay_profiles_figure
from planeray.scenes import representative_pixels
from planeray.timing import sweep_support_rows

scene = pr.make_scene("mirror_ball", (64, 64), projector_rows=720, seed=0)
stack = pr.simulate_stack(scene, pr.paper_sweep(), seed=0)
support = sweep_support_rows(pr.paper_sweep(), pr.PAPER_LINES_PER_SECOND)
pixels, names = representative_pixels(scene, support)
print(dict(zip(names, [tuple(int(x) for x in p) for p in pixels])))
profiles = pr.measured_delay_profiles(stack, pixels)
fig = delay_profiles_figure(stack, profiles, names=names)

"""
Fig. 8: the delay x exposure contact sheet
==========================================

The disco ball's specular interreflections move vertically with the delay, and a longer
exposure widens the band of light paths each image gathers (paper Fig. 8).

Command line: ``planeray figure fig8 --out figs`` (or ``planeray contact-sheet STACK --out fig8.png``).
"""

import planeray as pr
from planeray.figures import contact_sheet_figure

scene = pr.make_scene("disco_ball", (64, 64), projector_rows=720, seed=0)
stack = pr.simulate_stack(scene, pr.paper_sweep(), seed=0)
fig = contact_sheet_figure(stack, max_delays=9)

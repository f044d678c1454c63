"""
Beyond Fig. 10: measuring the media, not only naming them
==========================================================

The delay profile of a scattering medium is its line kernel: how far light travels under the
surface before it comes back. ``planeray materials fit`` fits the kernel of a homogeneous medium
(a Monte Carlo table under a Fresnel face, the diffusion dipole beyond it, the containers' clear
walls from diffusion theory) and returns the reduced scattering ``mu_s'`` and the absorption
``mu_a`` in 1/mm, with standard errors and the reason wherever one is not identifiable. Here the
five Fig. 10 media of the ``materials`` scene (its ground-truth transport, 64x64; each tray's
pixels at least 3 mm from its walls fitted as one region, the walls modelled) against their
published constants -- what the paper calls "an interesting avenue of future research" (Sec. 8).

Command line: ``planeray materials fit STACK|TRANSPORT --labels TRAYS.png --out DIR``; the full
``planeray materials report`` adds this figure (``fig10e_measured_media.png``).
"""

from planeray.experiments.materials import media_fit_numbers
from planeray.figures.materials import measured_media_figure
from planeray.scenes import make_scene

scene = make_scene("materials", (64, 64), projector_rows=720, seed=0)
numbers = media_fit_numbers(scene, {"ground-truth transport": scene.transport})
for name, medium in numbers["media"].items():
    got = medium["ground-truth transport"]
    cells = [
        "not identified" if got[key] is None else f"{got[key]:+.1%}" for key in ("mu_s_prime_rel_err", "mu_a_rel_err")
    ]
    print(f"{name:14s} mu_s' {cells[0]:>15s}   mu_a {cells[1]:>15s}")
fig = measured_media_figure(numbers["media"])

# %%
# The liquid soap misses: its transport mean free path (5 mm) is as long as the distances to its
# walls, where the walls' diffusion model overstates the light they take (see the user guide,
# "Measuring the medium"). From a noisy capture, ``materials fit`` fits the stack's images themselves
# (``planeray.materials.stackfit.fit_stack``: no demultiplexing noise in the kernel's tail); a white
# target captured with the same sweep fixes the magnitude and tightens ``mu_a``.

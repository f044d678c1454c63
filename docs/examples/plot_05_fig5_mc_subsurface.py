"""
Figs. 5, 6: subsurface scattering by Monte Carlo, and demultiplexing it
=======================================================================

A projector row lights a line on a scattering medium; the light that comes out beside it is the
short-range indirect light the plane-to-ray camera separates by delay. planeray traces photon
packets through a homogeneous slab with Henyey-Greenstein scattering and Fresnel boundaries
(MCML's scheme) and compares the profile with the diffusion dipole (Sec. 5.2).

Command line: ``planeray mc profile --sigma-s 1 --sigma-a 0.01 --g 0.9 --out p.csv --plot p.png``;
``planeray study demux`` runs the Sec. 5.2 study.
"""

import numpy as np

import planeray as pr
from planeray import study
from planeray.figures.mc import mc_profile_figure
from planeray.figures.study import plot_reconstruction

medium = pr.Medium(sigma_s=1.0, sigma_a=0.01, g=0.9, n=1.4)
print(medium, f"transport mean free path {medium.transport_mfp_mm:.1f} mm")
profile = pr.mc_line_profile(medium, n_photons=40_000, offsets_rows=np.arange(-40, 41), mm_per_row=1.0, seed=0)
print(
    f"diffuse reflectance {profile.total_reflectance:.3f} +- {profile.total_reflectance_stderr:.3f}, energy balance {profile.energy_balance}"
)
fig = mc_profile_figure(profile)

# %%
# Fig. 5a: demultiplexing such a profile
# --------------------------------------
# The Sec. 5.2 study takes a Monte Carlo profile (here ``sigma_s = 1``, ``sigma_a = 0``,
# ``g = 0.9``, the paper's defaults) as a pixel's true transport, observes it through the paper's
# 85-image sweep with noise ``eta = 0.05``, and reconstructs it with the pseudo-inverse, plain
# non-negative least squares and the paper's regularized problem (Sec. 4).


setup = study.study_setup()
provider = study.mc_provider(setup.offsets, n_photons=40_000, cache=False)
example = study.reconstruction_example(setup, provider, noise=0.05)
print("MSE per method:", {k: f"{v:.2e}" for k, v in example["mse"].items()})
fig = plot_reconstruction(example, noise=0.05)

"""Monte Carlo photon transport in homogeneous slabs (compiled MCML-style engine).

See :mod:`planeray.mc.engine` (photon transport), :mod:`planeray.mc.physics` (Fresnel, HG),
:mod:`planeray.mc.diffusion` (the dipole and the diffusion hand-off); :mod:`planeray.mc.mitsuba_ref` renders the same
profile with Mitsuba 3 as an independent check (optional extra ``mitsuba``).
"""

from .diffusion import diffusion_exit, diffusion_normal_radiance_ratio
from .engine import (
    ROULETTE_CHANCE,
    ROULETTE_THRESHOLD,
    MCProfile,
    cache_dir,
    default_cutoff_mm,
    mc_line_profile,
    mc_point_profile,
)
from .physics import fresnel_unpolarized, hg_phase, sample_hg_cos

__all__ = [
    "MCProfile",
    "mc_line_profile",
    "mc_point_profile",
    "default_cutoff_mm",
    "diffusion_exit",
    "diffusion_normal_radiance_ratio",
    "fresnel_unpolarized",
    "sample_hg_cos",
    "hg_phase",
    "cache_dir",
    "ROULETTE_THRESHOLD",
    "ROULETTE_CHANCE",
]

"""Monte Carlo photon transport in homogeneous slabs (compiled MCML-style engine).

* :mod:`planeray.mc.engine`: photon transport (the compiled kernel and the entry points);
* :mod:`planeray.mc.result`: :class:`MCProfile`, what a run returns;
* :mod:`planeray.mc.cache`: the disk cache and the tables shipped with the package;
* :mod:`planeray.mc.physics`: Fresnel reflectance and the Henyey-Greenstein phase function;
* :mod:`planeray.mc.diffusion`: the diffusion dipole and the hybrid hand-off to diffusion;
* :mod:`planeray.mc.report`: CSV/JSON output of a profile;
* :mod:`planeray.mc.mitsuba_ref`: the same profile rendered by Mitsuba 3, the independent
  check (optional extra ``mitsuba``).
"""

from .cache import cache_dir
from .diffusion import diffusion_exit, diffusion_normal_radiance_ratio
from .engine import ROULETTE_CHANCE, ROULETTE_THRESHOLD, default_cutoff_mm, mc_line_profile, mc_point_profile
from .physics import fresnel_unpolarized, hg_phase, sample_hg_cos
from .result import MCProfile

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

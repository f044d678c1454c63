"""Monte Carlo photon transport: photons only (the forward models built on it are :mod:`planeray.kernels`).

* :mod:`planeray.mc.engine`: a homogeneous slab (the compiled kernel and the entry points);
* :mod:`planeray.mc.wall`: beside a container wall (Sec. 8);
* :mod:`planeray.mc.layered`: layered media with a blood cylinder (skin and veins);
* :mod:`planeray.mc.events`: the event helpers the three kernels share (launch, Fresnel escape,
  collision, Russian roulette, cutoff) and their batches;
* :mod:`planeray.mc.result`: :class:`MCProfile`, what every run returns, and its assembly;
* :mod:`planeray.mc.cache`: the one table store (shipped tables, else the user cache, else
  built and saved) and the tables shipped with the package;
* :mod:`planeray.mc.physics`: Fresnel reflectance and the Henyey-Greenstein phase function;
* :mod:`planeray.mc.diffusion`: all diffusion theory -- the dipole, its one K1 line law, the
  hybrid hand-off and the quarter space beside a wall;
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

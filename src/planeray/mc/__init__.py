"""Monte Carlo photon transport in homogeneous slabs (vectorized MCML-style engine).

See :mod:`planeray.mc.engine`.
"""

from planeray.mc.engine import (
    ROULETTE_CHANCE,
    ROULETTE_THRESHOLD,
    MCProfile,
    cache_dir,
    fresnel_unpolarized,
    mc_line_profile,
    sample_hg_cos,
)

__all__ = [
    "MCProfile",
    "mc_line_profile",
    "fresnel_unpolarized",
    "sample_hg_cos",
    "cache_dir",
    "ROULETTE_THRESHOLD",
    "ROULETTE_CHANCE",
]

"""Forward models: what scenes render with and fits invert, built on the photon transport of :mod:`planeray.mc`.

* :mod:`planeray.kernels.line`: the scene kernels of a medium by model name
  (:func:`line_kernel`: ``"mc"`` or ``"dipole"``);
* :mod:`planeray.kernels.store`: the one table store (shipped, else cached, else built and saved);
* :mod:`planeray.kernels.footprint`: a camera row's footprint on the projector's rows;
* :mod:`planeray.kernels.wall`: wall-kernel tables (pixels near a container wall);
* :mod:`planeray.kernels.vein`: vein tables (the kernel of a layered skin beside a vein);
* :mod:`planeray.kernels.forward`: the forward table of the transport fit and its kernel at a
  capture's geometry (:func:`~planeray.kernels.forward.forward_kernel`);
* :mod:`planeray.kernels.walls`: the relative effect of container walls and a layer's bottom in
  diffusion theory (the image sources the fit applies to the forward table);
* :mod:`planeray.kernels.anisotropy`: how a medium's anisotropy ``g`` changes the forward table's
  kernel (traced at 0.8; the fits take ``g`` as a nuisance parameter, or as stated).

The diffusion theory itself (the dipole, its one line law) is :mod:`planeray.mc.diffusion`.
"""

from .line import (
    KERNEL_MODELS,
    MC_KERNEL_PHOTONS,
    MC_KERNEL_REACH_ROWS,
    boundary_mismatch_A,
    dipole_line_kernel,
    dipole_reflectance,
    dipole_total_reflectance,
    line_kernel,
    mc_line_kernel,
)

__all__ = [
    "boundary_mismatch_A",
    "dipole_reflectance",
    "dipole_total_reflectance",
    "dipole_line_kernel",
    "mc_line_kernel",
    "line_kernel",
    "KERNEL_MODELS",
    "MC_KERNEL_PHOTONS",
    "MC_KERNEL_REACH_ROWS",
]

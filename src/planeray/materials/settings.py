"""How a materials capture was taken, and what is assumed of its medium: one options object.

The fit (``planeray materials fit``), the recognition (``recognize``) and a library's new entries
(``library-add``) read a capture with the same settings; :class:`CaptureSettings` holds them once,
checked when it is made.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from .._validate import check_number
from ..camera import CameraModel
from ..errors import InputError
from ..kernels.anisotropy import check_g
from .fit import DEFAULT_N

__all__ = ["CaptureSettings"]


@dataclass(frozen=True)
class CaptureSettings:
    """The capture's scale and camera, its white reference, and the medium's index and depth.

    Parameters
    ----------
    mm_per_row : float, optional
        Size of one projector row on the surface, mm, in (0, 100]; default: what the capture records
        (its ``acquisition.json``, or its scene's ``mm_per_row``); neither is refused where it is needed.
    n : float, optional
        Refractive index of the medium against air, 1.0-1.6 (1 for an index-matched surface); default:
        :data:`planeray.materials.fit.DEFAULT_N` (1.33, water-based media), *assumed* and said so: a wrong index biases
        mu_s' by tens of percent and does not show in a fit's chi-square.
    depth_mm : float, optional
        Depth of the medium's layer, mm, in (0, 10000], on a support that returns no light;
        default: semi-infinite.
    g : float, optional
        The medium's Henyey-Greenstein anisotropy, 0-0.95 (:data:`planeray.kernels.anisotropy.G_PRIOR`);
        default: unknown -- fitted with ``mu_s'`` and ``mu_a``, its uncertainty carried into theirs.
    white_reference : str or os.PathLike, optional
        Capture (stack, or transport for the transport fit) of a white Lambertian target with the same
        sweep and camera: calibrates the magnitude (absolute reflectance); without it only the
        profiles' shape is used.
    white_albedo : float
        Albedo of the white reference, in (0, 1].
    camera : CameraModel, optional
        The camera's noise model; default: the capture's record (:meth:`CameraModel.from_metadata`).

    Examples
    --------
    >>> s = CaptureSettings(mm_per_row=0.3)
    >>> s.refractive_index, s.n_stated
    (1.33, False)
    >>> CaptureSettings(n=1.8)
    Traceback (most recent call last):
    ...
    planeray.errors.InputError: n must be in 1.0-1.6 (a liquid or tissue against air), got 1.8
    """

    mm_per_row: float | None = None
    n: float | None = None
    depth_mm: float | None = None
    g: float | None = None
    white_reference: str | Path | None = None
    white_albedo: float = 0.99
    camera: CameraModel | None = None

    def __post_init__(self):
        if not 0.0 < self.white_albedo <= 1.0:
            raise InputError(f"white_albedo must be in (0, 1], got {self.white_albedo:g}")
        if self.n is not None and not 1.0 <= self.n <= 1.6:
            raise InputError(f"n must be in 1.0-1.6 (a liquid or tissue against air), got {self.n:g}")
        if self.mm_per_row is not None:
            check_number(self.mm_per_row, "mm_per_row", minimum=0.0, maximum=100.0, min_inclusive=False)
        if self.depth_mm is not None and not (math.isfinite(self.depth_mm) and 0.0 < self.depth_mm <= 10_000.0):
            raise InputError(f"depth_mm must be a depth in (0, 10000] mm, got {self.depth_mm:g}")
        check_g(self.g)

    @property
    def refractive_index(self) -> float:
        """``n``, or :data:`~planeray.materials.fit.DEFAULT_N` where it is not stated."""
        return DEFAULT_N if self.n is None else float(self.n)

    @property
    def n_stated(self) -> bool:
        """Whether the index was stated (else :data:`~planeray.materials.fit.DEFAULT_N` is assumed)."""
        return self.n is not None

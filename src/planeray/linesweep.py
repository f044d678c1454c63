"""The line-velocity calibration capture: global-shutter images of a swept comb of projector rows (Sec. 6).

A :class:`LineSweep` is what a device captures for :func:`planeray.calibration.calibrate_lines_per_second`
(see :mod:`planeray.calibration` for the design of the comb).  It sits beside
:class:`planeray.stack.Stack`, the other capture container, so that devices can
produce it without depending on the calibration code.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ._validate import check_integer, check_nonnegative, check_positive
from .errors import InputError

__all__ = ["PAPER_CALIBRATION_EXPOSURE_US", "LineSweep"]

#: Global-shutter exposure of the paper's line-velocity calibration (Sec. 6).
PAPER_CALIBRATION_EXPOSURE_US = 500.0


@dataclass
class LineSweep:
    """Global-shutter images of a swept line comb, the input of the ``v_p`` calibration.

    Parameters
    ----------
    images : array_like, shape (n, H, W) or (H, W)
        One image per comb phase (any linear units; normalized images of the
        camera model, raw codes...).
    exposure_us : float
        Global-shutter exposure ``t_e`` of every image (the paper: 500 us).
    line_step_rows : int
        ``k``: the lit projector rows of one image are ``k`` rows apart
        (1: every row, the paper's single image).
    phases : sequence of int, optional
        Comb phase (lit rows ``v = phase mod k``) of each image.  ``None``: the
        images are the ``k`` distinct phases if there are ``k`` of them.
    dark : array_like (H, W), optional
        Laser off, same exposure: the ambient background to subtract.
    flat : array_like (H, W), optional
        Every projector row lit, exposure ``flat_exposure_us`` covering the
        lines' window with margins: the per-pixel response to one full line.
    flat_exposure_us : float, optional
        Exposure of ``flat``; its ambient background is ``dark`` scaled by
        ``flat_exposure_us / exposure_us``.
    saturated : array_like of bool (n, H, W), optional
    timing_jitter_us : float
        RMS error of the exposure window's position in one (frame-averaged)
        image, e.g. trigger jitter / sqrt(frames averaged); enters the uncertainty.
    metadata : dict
        Free-form, JSON-serializable (device description, truth of a simulation).

    See Also
    --------
    planeray.calibrate_lines_per_second : reads it.
    planeray.calibration.write_line_sweep : stores it.

    Examples
    --------
    >>> import planeray as pr
    >>> target = pr.make_scene("diffuse_plane", (288, 32), projector_rows=96, seed=0)
    >>> sweep = pr.SimulatedEpiscan(target, seed=5).capture_line_sweep(500.0)
    >>> type(sweep).__name__, sweep.images.shape, sweep.exposure_us, sweep.line_step_rows
    ('LineSweep', (2, 288, 32), 500.0, 2)
    """

    images: np.ndarray
    exposure_us: float = PAPER_CALIBRATION_EXPOSURE_US
    line_step_rows: int = 1
    phases: tuple | None = None
    dark: np.ndarray | None = None
    flat: np.ndarray | None = None
    flat_exposure_us: float | None = None
    saturated: np.ndarray | None = None
    timing_jitter_us: float = 0.0
    metadata: dict = field(default_factory=dict)

    def __post_init__(self):
        images = np.asarray(self.images)
        if images.ndim == 2:
            images = images[None]
        if images.ndim != 3 or images.shape[0] < 1:
            raise InputError(f"line-sweep images must be (H, W) or (n, H, W), got shape {images.shape}")
        self.images = images
        self.exposure_us = check_positive(self.exposure_us, "exposure_us")
        self.line_step_rows = check_integer(self.line_step_rows, "line_step_rows", minimum=1)
        if self.phases is not None:
            phases = tuple(int(p) for p in self.phases)
            if len(phases) != images.shape[0]:
                raise InputError(f"{len(phases)} phases for {images.shape[0]} images")
            self.phases = phases
        if self.flat is not None and self.flat_exposure_us is None:
            raise InputError("flat needs flat_exposure_us (to scale the dark frame to it)")
        check_nonnegative(self.timing_jitter_us, "timing_jitter_us")

    @property
    def complete(self) -> bool:
        """True when the images are all ``k`` phases of the comb, each once."""
        k = self.line_step_rows
        if self.phases is None:
            return self.images.shape[0] == k
        return sorted(p % k for p in self.phases) == list(range(k))

    def flat_field(self) -> np.ndarray | None:
        """The flat frame minus its ambient background (the dark frame scaled to its exposure)."""
        if self.flat is None:
            return None
        flat = np.asarray(self.flat, dtype=np.float64)
        if self.dark is None:
            return flat - np.percentile(flat, 5, axis=0)[None, :]
        return flat - np.asarray(self.dark, dtype=np.float64) * (self.flat_exposure_us / self.exposure_us)

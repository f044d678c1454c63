"""The settings a design chooses from: (delay, exposure) pairs the camera can realize, and their bands.

Candidates lie on a grid of the camera's steps (:class:`~planeray.design.camera.DesignCamera`:
exposure and trigger-delay steps; a delay moves with the trigger delay, Eq. 1), within its exposure
range and the bounds asked for, with every band inside the support ``|I_d| + I_w / 2 <= K``
(Eq. 2).  The paper's **boundary images** -- a band edge within ``boundary_margin_us`` of the
epipolar plane, ``||t_d| - t_e/2| <= 75 us``, where the row jitter of the trigger leaves horizontal
artifacts (Sec. 4) -- are not candidates: a design avoids them instead of modelling them.  Each
candidate's row of the illumination matrix is its band on the support's offset bins, blurred by the
synchronization jitter (:func:`planeray.timing.band_weights_at_row`, an interior camera row: the
rows of the largest row group of a stack).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..timing import (
    PAPER_BOUNDARY_MARGIN_US,
    Band,
    RowGeometry,
    band_centre_rows,
    band_weights_at_row,
    band_width_rows,
    boundary_images,
)
from .camera import DesignCamera

__all__ = ["Candidates", "candidate_settings", "band_rows", "DEFAULT_EXPOSURE_RANGE_US", "LIT"]

#: Exposures a design considers by default (us): from twice the boundary margin (a shorter band
#: cannot hold the epipolar plane off its edges) to 1.25 times the paper's longest.
DEFAULT_EXPOSURE_RANGE_US = (2.0 * PAPER_BOUNDARY_MARGIN_US, 1500.0)
#: An offset counts as seen by an image whose band lights at least this fraction of its bin.
LIT = 0.5


def band_rows(delay_us, exposure_us, offsets_rows, *, lines_per_second, jitter_us=0.0) -> np.ndarray:
    """Rows of the illumination matrix of settings ``(delay_us, exposure_us)`` over ``offsets_rows``, (C, U).

    The bands of an interior camera row (every offset bin whole on the projector): Eq. 3 on 1-row
    bins, the edges blurred by ``jitter_us`` (as the demultiplexer's matrix is).

    Parameters
    ----------
    delay_us, exposure_us : array_like (C,)
        The settings, microseconds.
    offsets_rows : array_like (U,) of int
        Offsets ``u``, projector rows.
    lines_per_second : float
        Projector scan rate, rows per second.
    jitter_us : float
        Synchronization jitter blurring the band edges, microseconds.

    Returns
    -------
    ndarray (C, U)
        The fraction of each offset bin each band lights.

    See Also
    --------
    planeray.timing.band_bin_weights : Eq. 3 on bins.

    Examples
    --------
    >>> import numpy as np
    >>> rows = band_rows([0.0, 375.0], [600.0, 600.0], np.arange(-40, 41), lines_per_second=54000.0)
    >>> rows.shape, round(float(rows[0].sum()), 1)  # each band 32.4 projector rows wide
    ((2, 81), 32.4)
    """
    offsets = np.asarray(offsets_rows)
    K = int(np.abs(offsets).max(initial=0))
    geometry = RowGeometry(1, 4 * K + 3)  # camera row 0 at projector row 2K + 1: the whole support inside
    bands = [
        Band(float(d), float(e), float(lines_per_second), float(jitter_us))
        for d, e in zip(np.atleast_1d(delay_us), np.atleast_1d(exposure_us))
    ]
    return band_weights_at_row(bands, geometry, 0, offsets)


@dataclass(frozen=True)
class Candidates:
    """Candidate settings and their rows of the illumination matrix.

    Attributes
    ----------
    delay_us, exposure_us : ndarray (C,)
    offsets_rows : ndarray (U,)
        The support's offsets ``-K .. K``.
    rows : ndarray (C, U) float64
        Each candidate's band over the offsets (:func:`band_rows`).
    description : dict
        JSON record: bounds, steps, margin, count.

    See Also
    --------
    candidate_settings : builds them.

    Examples
    --------
    >>> from planeray.design import candidate_settings
    >>> cands = candidate_settings(support_rows=20, exposure_range_us=(300, 600))
    >>> type(cands).__name__, cands.rows.shape[1], len(cands) == cands.rows.shape[0]
    ('Candidates', 41, True)
    """

    delay_us: np.ndarray
    exposure_us: np.ndarray
    offsets_rows: np.ndarray
    rows: np.ndarray
    description: dict

    def __len__(self) -> int:
        return self.delay_us.size

    @property
    def lit(self) -> np.ndarray:
        """``(C, U)`` bool: the offsets each candidate sees (its band lights at least half the bin)."""
        return self.rows >= LIT


def _grid(lo: float, hi: float, step: float, origin: float = 0.0) -> np.ndarray:
    """Multiples ``origin + k step`` within ``[lo, hi]``."""
    k0 = np.ceil((lo - origin) / step - 1e-9)
    k1 = np.floor((hi - origin) / step + 1e-9)
    return origin + np.arange(k0, k1 + 1) * step


def _on_steps(step_wanted: float, camera_step: float) -> float:
    """The grid step: ``step_wanted`` rounded to a whole number of the camera's steps (at least one)."""
    if camera_step <= 0:
        return float(step_wanted)
    return float(camera_step * max(1, round(step_wanted / camera_step)))


def candidate_settings(
    camera: DesignCamera | None = None,
    *,
    support_rows: int = 114,
    exposure_range_us=DEFAULT_EXPOSURE_RANGE_US,
    delay_range_us=None,
    exposure_step_us: float | None = None,
    delay_step_us: float | None = None,
    boundary_margin_us: float = PAPER_BOUNDARY_MARGIN_US,
) -> Candidates:
    """The settings a design chooses from.

    Parameters
    ----------
    camera : DesignCamera, optional
        Scanline velocity, jitter, exposure range and steps (default: the simulated Episcan).
    support_rows : int
        Half-width ``K`` of the support: every band lies inside ``-K .. K``.
    exposure_range_us : (float, float)
        Exposures considered (us), within the camera's range.
    delay_range_us : (float, float), optional
        Delays considered (us); default: all whose band fits the support.
    exposure_step_us, delay_step_us : float, optional
        Grid steps (us); default one projector row of each (18.5 us at 54,000 lines/s: band edges on
        a half-row grid), each rounded to a whole number of the camera's steps.
    boundary_margin_us : float
        Settings with ``||t_d| - t_e/2| <= margin`` (the paper's boundary images) are left out.

    Returns
    -------
    Candidates

    See Also
    --------
    design_sweep : chooses among them.

    Examples
    --------
    >>> c = candidate_settings(support_rows=40, exposure_range_us=(300, 600))
    >>> len(c) > 0, c.rows.shape[1], bool(c.lit.any(axis=0).all())
    (True, 81, True)
    """
    camera = camera or DesignCamera()
    lps = camera.lines_per_second
    K = int(support_rows)
    row_us = 1e6 / lps
    e_lo = max(float(exposure_range_us[0]), camera.exposure_range_us[0])
    e_hi = min(float(exposure_range_us[1]), camera.exposure_range_us[1])
    if not e_lo <= e_hi:
        raise InputError(
            f"no exposure both in {exposure_range_us[0]:g}..{exposure_range_us[1]:g} us and in the camera's "
            f"{camera.exposure_range_us[0]:g}..{camera.exposure_range_us[1]:g} us"
        )
    e_step = _on_steps(row_us if exposure_step_us is None else float(exposure_step_us), camera.exposure_step_us)
    d_step = _on_steps(row_us if delay_step_us is None else float(delay_step_us), camera.delay_step_us)
    if not (e_step > 0 and d_step > 0):
        raise InputError("the candidates' exposure and delay steps must be positive")
    # exposures on the camera's grid from the bottom of its range; delays on multiples of the step
    origin = camera.exposure_range_us[0] if camera.exposure_step_us > 0 else 0.0
    exposures = _grid(e_lo, e_hi, e_step, origin)
    reach_us = K * row_us
    d_lo, d_hi = (
        (-reach_us, reach_us) if delay_range_us is None else (float(delay_range_us[0]), float(delay_range_us[1]))
    )
    delays = _grid(d_lo, d_hi, d_step)
    if exposures.size == 0 or delays.size == 0:
        raise InputError("no candidate settings: widen the exposure or delay range, or shorten the steps")
    E, D = np.meshgrid(exposures, delays, indexing="ij")
    D, E = D.ravel(), E.ravel()
    reach = np.abs(band_centre_rows(D, lps)) + 0.5 * band_width_rows(E, lps)
    keep = (reach <= K + 1e-9) & ~boundary_images(D, E, margin_us=boundary_margin_us)
    D, E = D[keep], E[keep]
    if D.size == 0:
        raise InputError(f"no candidate band fits the support of +-{K} rows outside the boundary images")
    offsets = np.arange(-K, K + 1)
    rows = band_rows(D, E, offsets, lines_per_second=lps, jitter_us=camera.model.jitter_us)
    description = {
        "count": int(D.size),
        "support_rows": K,
        "exposure_range_us": [float(e_lo), float(e_hi)],
        "exposure_step_us": e_step,
        "delay_range_us": [float(max(d_lo, delays[0])), float(min(d_hi, delays[-1]))],
        "delay_step_us": d_step,
        "boundary_margin_us": float(boundary_margin_us),
    }
    return Candidates(D, E, offsets, rows, description)

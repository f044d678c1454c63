"""Delay profiles: a pixel's intensity as a function of delay (Sec. 8, Fig. 9).

A delay profile tells what kind of light reaches a pixel: a narrow unimodal
peak at ``t_d = 0`` for direct diffuse reflection, a broadened one for
subsurface scattering, a steep one-sided one for diffuse interreflection and a
second, displaced peak for specular interreflection.  Profiles are normalized by
their area to cancel albedo (Sec. 8).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .errors import InputError
from .io import atomic_file
from .stack import Stack
from .timing import PAPER_LINES_PER_SECOND

__all__ = ["DelayProfiles", "measured_delay_profiles", "area_normalize", "write_profiles_csv"]


@dataclass
class DelayProfiles:
    """Delay profiles of a few pixels at each exposure of a stack.

    Attributes
    ----------
    pixels : ndarray (P, 2) int
        ``(row, col)`` of each pixel.
    delay_us : ndarray (D,)
        Sorted delays.
    exposure_us : ndarray (E,)
        Sorted exposures.
    values : ndarray (P, E, D) float32
        Area-normalized intensities (NaN where the sweep has no image).
    raw : ndarray (P, E, D) float32
        Intensities before normalization.

    See Also
    --------
    measured_delay_profiles : the profiles of a stack.
    write_profiles_csv : as a CSV file.

    Examples
    --------
    >>> import planeray as pr
    >>> stack = pr.simulate_stack(pr.make_scene("corner", (8, 8), seed=0), pr.quick_sweep(), seed=0)
    >>> profiles = pr.measured_delay_profiles(stack, [(4, 4)])
    >>> type(profiles).__name__, profiles.values.shape  # pixel x exposure x delay
    ('DelayProfiles', (1, 3, 9))
    """

    pixels: np.ndarray
    delay_us: np.ndarray
    exposure_us: np.ndarray
    values: np.ndarray
    raw: np.ndarray


def area_normalize(values, delay_us):
    """Divide each profile (last axis) by its area over delay in milliseconds.

    Missing samples (NaN) are skipped; a profile with no positive area is left at 0.

    Parameters
    ----------
    values : array_like (..., D)
        Profiles over delay (last axis).
    delay_us : array_like (D,)
        The delays, microseconds (sorted).

    Returns
    -------
    ndarray (..., D)
        The profiles divided by their areas (1/ms).

    See Also
    --------
    measured_delay_profiles : profiles so normalized.

    Examples
    --------
    Profiles over delay (us) divided by their area over delay in milliseconds:

    >>> import numpy as np
    >>> p = area_normalize(np.array([[1.0, 1.0, 1.0]]), np.array([-500.0, 0.0, 500.0]))
    >>> p.round(3).tolist()
    [[1.0, 1.0, 1.0]]
    """
    values = np.asarray(values, dtype=np.float64)
    x = np.asarray(delay_us, dtype=np.float64) * 1e-3
    out = np.zeros_like(values)
    flat = values.reshape(-1, values.shape[-1])
    res = out.reshape(-1, values.shape[-1])
    for i, v in enumerate(flat):  # a handful of profiles, each vectorized
        ok = np.isfinite(v)
        area = np.trapezoid(np.clip(v[ok], 0, None), x[ok]) if ok.sum() > 1 else 0.0
        res[i] = np.where(ok, v / area, np.nan) if area > 0 else np.where(ok, 0.0, np.nan)
    return out.astype(np.float32)


def measured_delay_profiles(stack: Stack, pixels) -> DelayProfiles:
    """Read the delay profiles of ``pixels`` from a stack, one curve per exposure.

    Parameters
    ----------
    stack : Stack
        The captured (or simulated) images with their delays and exposures (us).
    pixels : array_like (P, 2)
        ``(row, col)`` pixel coordinates.

    Returns
    -------
    DelayProfiles
        ``values`` (P, exposures, delays): each profile area-normalized over delay in
        milliseconds (1/ms; NaN where the stack has no image), ``raw`` the image values,
        ``delay_us`` and ``exposure_us`` the grid.

    See Also
    --------
    transport_delay_profiles : the same from a transport, at any delay.

    References
    ----------
    .. [1] H. Kubo, S. Jayasuriya, T. Iwaguchi, T. Funatomi, Y. Mukaigawa, S. G. Narasimhan,
       "Programmable Non-Epipolar Indirect Light Transport: Capture and Analysis",
       IEEE TVCG 27(4), 2019, doi:10.1109/TVCG.2019.2946812, Fig. 9.

    Examples
    --------
    >>> from planeray.acquire import simulate_stack
    >>> from planeray.scenes import make_scene
    >>> from planeray.timing import paper_sweep
    >>> stack = simulate_stack(make_scene("wax", (16, 16), projector_rows=90, seed=0), paper_sweep(), seed=0)
    >>> prof = measured_delay_profiles(stack, [(8, 8)])
    >>> prof.values.shape  # (pixels, exposures, delays)
    (1, 5, 17)
    """
    px = _check_pixels(pixels, stack.shape)
    delays, exposures = stack.delays(), stack.exposures()
    raw = np.full((len(px), exposures.size, delays.size), np.nan, np.float32)
    di = np.searchsorted(delays, stack.delay_us)
    ei = np.searchsorted(exposures, stack.exposure_us)
    for n in range(len(stack)):  # one image at a time: works on lazy stacks
        raw[:, ei[n], di[n]] = stack.image(n)[px[:, 0], px[:, 1]]
    return DelayProfiles(px, delays, exposures, area_normalize(raw, delays), raw)


def write_profiles_csv(profiles: DelayProfiles, path) -> Path:
    """Write measured delay profiles as CSV (``row,col,exposure_us,delay_us,raw,normalized``), atomically.

    One line per pixel, exposure and delay with a measurement (missing ones are skipped).
    The first line is planeray's mark, a comment (``# planeray_mark: planeray:table:VERSION``;
    pandas: ``read_csv(path, comment="#")``), then the header.

    Parameters
    ----------
    profiles : DelayProfiles
        From :func:`measured_delay_profiles`.
    path : str or path
        The CSV file to write (replaced if it exists).

    Returns
    -------
    pathlib.Path
        The file written.

    See Also
    --------
    measured_delay_profiles : the profiles.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> import planeray as pr
    >>> stack = pr.simulate_stack(pr.make_scene("corner", (8, 8), seed=0), pr.quick_sweep(), seed=0)
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     path = write_profiles_csv(pr.measured_delay_profiles(stack, [(4, 4)]), pathlib.Path(tmp) / "p.csv")
    ...     path.read_text().splitlines()[1]
    'row,col,exposure_us,delay_us,raw,normalized'
    """
    from .io.marks import MARK_KEY, mark_text

    prof = profiles
    rows = [f"# {MARK_KEY}: {mark_text('table')}", "row,col,exposure_us,delay_us,raw,normalized"]
    for p, (r, c) in enumerate(prof.pixels):
        for e_i, e in enumerate(prof.exposure_us):
            for d_i, d in enumerate(prof.delay_us):
                if np.isfinite(prof.raw[p, e_i, d_i]):
                    rows.append(f"{r},{c},{e:g},{d:g},{prof.raw[p, e_i, d_i]:.7g},{prof.values[p, e_i, d_i]:.7g}")
    path = Path(path)
    with atomic_file(path) as tmp:
        tmp.write_text("\n".join(rows) + "\n")
    return path


# ============================================================================
# Continuous delay profiles of a transport (effect labels: planeray.classify)
# ============================================================================
__all__ += ["TransportDelayProfiles", "transport_delay_profiles"]


@dataclass
class TransportDelayProfiles:
    """Continuous delay profiles read from a transport.

    Attributes
    ----------
    pixels : ndarray (P, 2) int or None
        ``(row, col)`` of each profile, or None when the profiles cover the whole
        image (``values`` is then ``(H, W, D)``).
    delay_us : ndarray (D,)
        Delays of the samples, increasing.
    exposure_us : float or None
        Exposure of the rendered bands, or None for the transport itself
        (``T(u)`` at ``d = u / v_p``).
    values : ndarray (P, D) or (H, W, D) float32
        Area-normalized profiles (area 1 over delay in milliseconds, as
        :func:`area_normalize`).
    raw : ndarray, same shape as ``values``, float32
        Profiles before normalization.

    See Also
    --------
    transport_delay_profiles : the profiles of a transport.

    Examples
    --------
    >>> import planeray as pr
    >>> T = pr.make_scene("corner", (8, 8), seed=0).transport
    >>> pr.transport_delay_profiles(T, [(4, 4)], exposure_us=600.0).values.shape[0]
    1
    """

    pixels: np.ndarray | None
    delay_us: np.ndarray
    exposure_us: float | None
    values: np.ndarray
    raw: np.ndarray


def _area_normalize_dense(values, delay_us) -> np.ndarray:
    """Vectorized :func:`area_normalize` for NaN-free profiles (last axis): divide by the
    trapezoidal area of the positive part over delay in ms; profiles with no positive
    area become 0."""
    values = np.asarray(values, dtype=np.float64)
    x = np.asarray(delay_us, dtype=np.float64) * 1e-3
    area = np.trapezoid(np.clip(values, 0.0, None), x, axis=-1) if x.size > 1 else np.zeros(values.shape[:-1])
    safe = np.where(area > 0, area, 1.0)[..., None]
    return np.where(area[..., None] > 0, values / safe, 0.0).astype(np.float32)


def _check_pixels(pixels, shape) -> np.ndarray:
    px = np.atleast_2d(np.asarray(pixels, dtype=np.int64))
    if px.ndim != 2 or px.shape[1] != 2:
        raise InputError(f"pixels must be (row, col) pairs, got shape {px.shape}")
    H, W = shape
    bad = (px[:, 0] < 0) | (px[:, 0] >= H) | (px[:, 1] < 0) | (px[:, 1] >= W)
    if bad.any():
        raise InputError(f"pixel {tuple(int(v) for v in px[bad][0])} outside the {H}x{W} image")
    return px


def transport_delay_profiles(
    transport, pixels=None, *, exposure_us=None, delays_us=None, lines_per_second=PAPER_LINES_PER_SECOND
) -> TransportDelayProfiles:
    """Continuous delay profiles of a transport (Sec. 8 on an estimated or true ``T``).

    Parameters
    ----------
    transport : Transport
        Ground-truth or demultiplexed transport.
    pixels : array_like (P, 2), optional
        ``(row, col)`` pixels; None (default) for every pixel.
    exposure_us : float, optional
        None (default): the profile is ``T(u)`` itself over the dense band, at the
        delays ``d = u / v_p`` (the band that delay centres on ``u``; an
        infinitely short exposure).  Otherwise the image of each band
        ``Band(d, exposure_us, lines_per_second)`` (Eq. 4, sparse long-range
        entries included) over a fine delay grid: the delay profile a
        continuous sweep at that exposure would measure, without noise.
    delays_us : array_like, optional
        Delays of the rendered bands (only with ``exposure_us``); default
        -1500 .. 1500 us in steps of one scanline ``1e6 / v_p`` (18.5 us at
        54,000 lines/s), the paper's delay range.
    lines_per_second : float
        Projector scanline velocity ``v_p``.

    Returns
    -------
    TransportDelayProfiles
        ``values`` is ``(H, W, D)`` for ``pixels=None``, else ``(P, D)``;
        area-normalized over delay in milliseconds like :func:`area_normalize`.

    See Also
    --------
    measured_delay_profiles : the profiles of a captured stack (Fig. 9).

    Notes
    -----
    Without an exposure only the dense band is used: sparse long-range entries
    have no place on the band's offset grid.

    References
    ----------
    .. [1] H. Kubo, S. Jayasuriya, T. Iwaguchi, T. Funatomi, Y. Mukaigawa, S. G. Narasimhan,
       "Programmable Non-Epipolar Indirect Light Transport: Capture and Analysis",
       IEEE TVCG 27(4), 2019, doi:10.1109/TVCG.2019.2946812, Sec. 4, Fig. 9.

    Examples
    --------
    >>> import planeray as pr
    >>> T = pr.make_scene("corner", (8, 8), seed=0).transport
    >>> profiles = pr.transport_delay_profiles(T, [(4, 4)], exposure_us=600.0)
    >>> profiles.values.shape[0], profiles.exposure_us
    (1, 600.0)
    """
    from .timing import Band

    lps = float(lines_per_second)
    if not np.isfinite(lps) or lps <= 0:
        raise InputError(f"lines_per_second must be positive, got {lines_per_second!r}")
    px = None if pixels is None else _check_pixels(pixels, transport.shape)
    if exposure_us is None:
        if delays_us is not None:
            raise InputError("delays_us needs an exposure_us: without one the delays are the transport's offsets / v_p")
        delays = transport.offsets_rows.astype(np.float64) * 1e6 / lps
        raw = transport.dense if px is None else transport.dense[px[:, 0], px[:, 1]]
        raw = np.array(raw, dtype=np.float32)
        exposure = None
    else:
        exposure = float(exposure_us)
        if not np.isfinite(exposure) or exposure <= 0:
            raise InputError(f"exposure_us must be positive, got {exposure_us!r}")
        if delays_us is None:
            step = 1e6 / lps
            n = int(np.floor(1500.0 / step + 1e-9))
            delays = np.arange(-n, n + 1) * step
        else:
            delays = np.sort(np.asarray(delays_us, dtype=np.float64).ravel())
            if delays.size == 0 or not np.all(np.isfinite(delays)):
                raise InputError("delays_us must be a non-empty list of finite delays")
        shape = transport.shape if px is None else (len(px),)
        raw = np.empty((*shape, delays.size), np.float32)
        for i, d in enumerate(delays):  # one O(pixels) band render per delay
            img = transport.render(Band(float(d), exposure, lps))
            raw[..., i] = img if px is None else img[px[:, 0], px[:, 1]]
    return TransportDelayProfiles(px, delays, exposure, _area_normalize_dense(raw, delays), raw)

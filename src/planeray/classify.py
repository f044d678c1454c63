"""Effect labels from delay profiles (Sec. 8): characterize each transport profile and label it.

:func:`characterize` measures a transport profile (peak count, FWHM of the main
peak, width of its core, asymmetry and share of the light outside the cell the
sweep cannot split, offset of a displaced peak) after removing the ambient
floor, and labels it: specular interreflection (a displaced peak), diffuse
interreflection (indirect light, one-sided), subsurface scattering (indirect
light, symmetric or broadened, or a core wider than a direct peak's), else
direct/diffuse.  :func:`classify_transport` does it for every
pixel of a transport, :func:`visible_effect_mask` and :func:`label_agreement`
score labels against a scene's ground truth.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import InputError

__all__ = [
    "CLASSIFY_THRESHOLDS",
    "ProfileCharacter",
    "characterize",
    "classify_transport",
    "visible_effect_mask",
    "label_agreement",
]

#: Rule thresholds of :func:`characterize` and :func:`classify_transport`, by
#: keyword (tuned on demultiplexed transports of the built-in scenes: 64x64
#: camera rows of a 360-row projector, the paper's sweep, the default camera,
#: four seeds; the strong-peak contrast, the displaced share and the core
#: broadening re-tuned with the edge rule on every built-in scene at 64, 128 and 256
#: camera rows of 720, seeds 0 and 1; checked on the ground truth).
CLASSIFY_THRESHOLDS = {
    "smooth_bins": 5,  # box smoothing over offsets before floor and peak finding
    "peak_prominence": 0.15,  # a peak counts if its prominence >= this x the main peak's height
    "strong_peak_prominence": 0.3,  # a displaced peak this prominent is specular ...
    "strong_peak_contrast": 1.5,  # ... if its prominence is also >= this x the level beside it
    "peak_contrast": 6.0,  # else its prominence must be >= this x the level beside it
    "indirect_fraction_min": 0.07,  # significant light outside the unresolved cell
    "asymmetry_min": 0.75,  # |asymmetry| at or above: one-sided (diffuse interreflection)
    "broadening": 1.3,  # main peak this many times wider than a direct one: broadened
    "core_broadening": 1.25,  # core (cell + resolution) this many times wider than a direct one: subsurface
    "displaced_share_min": 0.04,  # a displaced peak must add this share of the pixel's light
}


@dataclass
class ProfileCharacter:
    """Shape of transport profiles (one entry per profile; arrays of the input's leading shape).

    Attributes
    ----------
    peak_count : ndarray int16
        Peaks of the smoothed, floor-subtracted profile whose prominence is at
        least ``peak_prominence`` x the main peak's height (the main peak included).
    fwhm_rows : ndarray float32
        Full width at half maximum of the main (highest) peak, in rows.
    asymmetry : ndarray float32
        ``(E+ - E-) / (E+ + E-)`` of the light outside the unresolved cell
        (``E+``: offsets ``u > cell``, ``E-``: ``u < -cell``); 0 without such light.
    indirect_fraction : ndarray float32
        Share of the profile's energy outside the cell.
    second_peak_offset_rows : ndarray float32
        Offset of the most prominent counted peak other than the main one (NaN if none).
    displaced_peak_offset_rows : ndarray float32
        Offset of the highest *displaced* peak -- beyond the cell and standing
        out (see :func:`characterize`) -- or NaN; may be the main peak itself.
    spread_rows : ndarray float32
        RMS width of the profile about its centroid, in rows.
    core_spread_rows : ndarray float32
        RMS distance from ``u = 0`` of the light near the epipolar plane (within
        the unresolved cell and one more resolution width), in rows; NaN where
        the projector's end cuts both sides (see :func:`characterize`).
    peak_offset_rows : ndarray float32
        Offset of the main peak.
    label : ndarray uint8
        Effect label (keys of :data:`planeray.scenes.EFFECTS`).
    cell_rows : float
        Half-width of the unresolved cell used.

    See Also
    --------
    characterize : computes it.

    Examples
    --------
    >>> import numpy as np
    >>> u = np.arange(-20, 21)
    >>> peak = np.exp(-0.5 * (u / 1.5) ** 2)  # one narrow peak on the epipolar plane
    >>> c = characterize(peak[None], u)
    >>> type(c).__name__, int(c.peak_count[0])
    ('ProfileCharacter', 1)
    """

    peak_count: np.ndarray
    fwhm_rows: np.ndarray
    asymmetry: np.ndarray
    indirect_fraction: np.ndarray
    second_peak_offset_rows: np.ndarray
    displaced_peak_offset_rows: np.ndarray
    spread_rows: np.ndarray
    core_spread_rows: np.ndarray
    peak_offset_rows: np.ndarray
    label: np.ndarray
    cell_rows: float


def _smooth_valid(P, valid, bins):
    """Box average over ``bins`` offsets of the valid samples only (normalized convolution)."""
    from scipy.ndimage import uniform_filter1d

    if bins <= 1:
        return np.where(valid, P, 0.0)
    w = valid.astype(np.float64)
    num = uniform_filter1d(P * w, bins, axis=-1, mode="constant")
    den = uniform_filter1d(w, bins, axis=-1, mode="constant")
    return np.where(valid & (den > 0), num / np.where(den > 0, den, 1.0), 0.0)


def _core_width(W, valid, offsets, half_rows):
    """RMS distance from ``u = 0`` of the light within ``|u| <= half_rows`` (``W`` non-negative).

    Over both sides where both lie on the projector, else over the side that
    does (a camera row near the end of the projector sees a cut profile); NaN
    where neither does or there is no light.
    """
    out = np.full(W.shape[0], np.nan)
    sides = {}
    for name, side in (
        ("neg", (offsets <= 0) & (offsets >= -half_rows)),
        ("pos", (offsets >= 0) & (offsets <= half_rows)),
    ):
        ok = valid[:, side].all(axis=1)
        m = W[:, side].sum(axis=1)
        m2 = (W[:, side] * offsets[side] ** 2).sum(axis=1)
        sides[name] = (ok, m, m2)
    (okn, mn, m2n), (okp, mp, m2p) = sides["neg"], sides["pos"]
    both = okn & okp
    for sel, m, m2 in ((okp & ~okn, mp, m2p), (okn & ~okp, mn, m2n), (both, mn + mp, m2n + m2p)):
        good = sel & (m > 0)
        out[good] = np.sqrt(m2[good] / m[good])
    return out


def _tail_floor(S, valid, offsets, tail_rows, clip=5.0):
    """Per-profile floor: the smaller of the robust mean levels of the two tails ``|u| >= tail_rows``.

    A tail's level is its mean with values above ``clip`` x its median clipped
    there: noise averages out, while a specular spot covering less than half
    the tail barely moves it.  The smaller side ignores one-sided light that
    fills a tail.  A tail that the end of the projector cuts to less than half
    the valid samples of the other one does not count: a few samples of a
    sparse estimate are often all zero, and a floor of 0 turned the whole
    ambient floor into "indirect light" (two camera rows near each end of the
    projector read as subsurface).
    """
    N = S.shape[0]
    levels, counts = [], []
    for side in (offsets <= -tail_rows, offsets >= tail_rows):
        level = np.full(N, np.inf)
        count = valid[:, side].sum(axis=1) if side.any() else np.zeros(N, np.int64)
        has = count > 0
        if has.any():
            v = np.where(valid[:, side], S[:, side], np.nan)[has]
            med = np.nanmedian(v, axis=1)
            cap = np.where(med > 0, clip * med, 0.0)[:, None]
            level[has] = np.nanmean(np.minimum(v, cap), axis=1)
        levels.append(level)
        counts.append(count)
    most = np.maximum(counts[0], counts[1])
    floor = np.full(N, np.inf)
    for level, count in zip(levels, counts):
        floor = np.where((count > 0) & (2 * count >= most), np.minimum(floor, level), floor)
    return np.where(np.isfinite(floor), floor, 0.0)


def _peak_table(S, valid):
    """All local maxima of all profiles at once, with scipy's prominence.

    Every profile is padded with one sample at its lowest level on each side
    (so a peak cut by the end of the offsets still counts) and separated from
    the next by a sentinel higher than any sample: ``scipy.signal.find_peaks``
    then runs once over the concatenation, and a peak's bases -- hence its
    prominence -- never leave its own profile.

    Returns ``(pix, k, prominence, height)`` sorted by profile, then height
    (the last entry of each profile is its main peak).
    """
    from scipy.signal import find_peaks, peak_prominences

    N, U = S.shape
    X = np.where(valid, S, 0.0)
    low = np.minimum(X.min(axis=1), 0.0)
    sentinel = 10.0 * (np.abs(X).max() + 1.0)
    cat = np.empty((N, U + 3))
    cat[:, 0] = sentinel
    cat[:, 1] = low
    cat[:, 2 : U + 2] = X
    cat[:, U + 2] = low
    flat = np.concatenate([cat.ravel(), [sentinel]])
    idx, _ = find_peaks(flat)
    idx = idx[flat[idx] < sentinel]  # sentinels are no peaks (and would search the whole array)
    prom = peak_prominences(flat, idx)[0]
    pix, pos = np.divmod(idx, U + 3)
    k = np.clip(pos - 2, 0, U - 1)  # padding samples map to the end offsets
    height = flat[idx]
    order = np.lexsort((prom, height, pix))
    return pix[order], k[order], prom[order], height[order]


def _local_level(S, valid, pix, k, core, window):
    """Background level beside each peak: the mean positive level of the valid
    offsets ``core < |j - k| <= window`` on both sides of it (``valid`` may
    exclude offsets, e.g. the main peak's cell); 0 if there are none."""
    N, U = S.shape
    pos = np.where(valid, np.clip(S, 0.0, None), 0.0)
    cs = np.zeros((N, U + 1))
    cs[:, 1:] = np.cumsum(pos, axis=1)
    cn = np.zeros((N, U + 1))
    cn[:, 1:] = np.cumsum(valid, axis=1)
    total = np.zeros(pix.size)
    count = np.zeros(pix.size)
    for lo, hi in ((k - window, k - core), (k + core + 1, k + window + 1)):
        lo = np.clip(lo, 0, U)
        hi = np.clip(hi, 0, U)
        total += cs[pix, hi] - cs[pix, lo]
        count += cn[pix, hi] - cn[pix, lo]
    return np.where(count > 0, total / np.maximum(count, 1), 0.0)


def _fwhm(S, main_k, main_h):
    """Width of the main peak at half its height, linear interpolation between samples.

    Returns the width and the left and right crossing positions (in samples).
    """
    N, U = S.shape
    cols = np.arange(U)[None, :]
    ok = main_k >= 0
    mk = np.where(ok, main_k, 0)[:, None]
    half = (0.5 * main_h)[:, None]
    below = S < half
    left_idx = np.where(below & (cols < mk), cols, -1).max(axis=1)
    right_idx = np.where(below & (cols > mk), cols, U).min(axis=1)
    rows = np.arange(N)

    def cross(i0, i1):  # position where S crosses half between samples i0 and i1
        a, b = S[rows, i0], S[rows, i1]
        t = (half[:, 0] - a) / np.where(b != a, b - a, 1.0)
        return i0 + np.clip(t, 0.0, 1.0) * (i1 - i0)

    li = np.clip(left_idx, 0, U - 1)
    ri = np.clip(right_idx, 0, U - 1)
    left = np.where(left_idx >= 0, cross(li, np.minimum(li + 1, U - 1)), -0.5)
    right = np.where(right_idx < U, cross(np.maximum(ri - 1, 0), ri), U - 0.5)
    good = ok & (main_h > 0)
    return np.where(good, right - left, np.nan), np.where(good, left, np.nan), np.where(good, right, np.nan)


def characterize(
    T_profiles,
    offsets_rows,
    *,
    resolution_rows=0.0,
    footprint_rows=0.0,
    valid=None,
    direct_fwhm_rows=None,
    direct_core_rows=None,
    subtract_floor=True,
    **thresholds,
) -> ProfileCharacter:
    """Characterize transport profiles and label the light transport effect each shows.

    Parameters
    ----------
    T_profiles : array_like (..., U)
        Transport profiles over ``offsets_rows`` (e.g. ``transport.dense``); need
        not be normalized (every quantity is scale-free).
    offsets_rows : array_like (U,)
        Consecutive integer offsets ``u = v - t``.
    resolution_rows : float
        Half-width of the cell around ``u = 0`` that the data cannot split (the
        demultiplexing result's ``epipolar_resolution_rows``; 0 for an exact transport).
    footprint_rows : float
        Projector rows spanned by one camera row (``P / H``); direct light
        covers that footprint.  The **unresolved cell** is
        ``|u| <= cell = resolution_rows + footprint_rows / 2 + 1/2`` (the half bin:
        a bin ``[k - 1/2, k + 1/2)`` belongs to the cell if it overlaps it).
    valid : array_like of bool, broadcastable to (..., U), optional
        Offsets that exist (e.g. on the projector); the others are ignored.
    direct_fwhm_rows : float, optional
        FWHM of a direct (diffuse) peak in these profiles.  When given, a
        one-sided profile whose main peak is ``broadening`` times wider is
        subsurface, not diffuse interreflection (see :func:`classify_transport`,
        which measures it on a reference or the image).
    direct_core_rows : float, optional
        ``core_spread_rows`` of a direct (diffuse) peak in these profiles.  When
        given, a profile otherwise labelled diffuse whose core is
        ``core_broadening`` times wider is subsurface: scattering that stays
        within a few rows of the cell (skin, whole milk) widens the peak
        without putting light beyond it.
    subtract_floor : bool
        Subtract a per-profile floor (ambient light spreads a constant over all
        offsets of a demultiplexed transport) before anything else.
    **thresholds
        Any key of :data:`CLASSIFY_THRESHOLDS` to override its default.

    Returns
    -------
    ProfileCharacter
        Arrays of the input's leading shape ``(...)``.

    Raises
    ------
    InputError
        Profiles and offsets of different lengths, or an unknown threshold.

    See Also
    --------
    classify_transport : the labels of a whole transport.
    ProfileCharacter : what it returns.

    Notes
    -----
    Per profile, vectorized over profiles (defaults in brackets):

    1. **Floor.**  The profile is box-smoothed over ``smooth_bins`` [5] offsets
       (the demultiplexer's L1 term turns an ambient floor and noise into
       isolated spikes; smoothing spreads them).  Its floor is the smaller of
       the levels of its two tails ``0.5 K <= |u| <= 0.85 K`` (``K`` the largest
       offset; a demultiplexed floor sags in the outermost offsets, which fewer
       images constrain), a tail's level being its mean after clipping values
       above 5x its median: ambient light is the same at every offset, a
       specular spot covers less than half a tail, and one-sided indirect light
       leaves one tail clean.  The floor is subtracted from the raw and the
       smoothed profile.
    2. **Energies** of the raw, floor-subtracted profile: ``E0`` inside the
       cell, ``E+`` (``u > cell``) and ``E-`` (``u < -cell``) clipped at 0.
       ``indirect_fraction = (E+ + E-) / (E0 + E+ + E-)``, ``asymmetry = (E+ -
       E-) / (E+ + E-)`` (0 without light outside the cell), ``spread_rows`` the
       RMS width of the positive part about its centroid, ``core_spread_rows``
       the RMS distance from ``u = 0`` of the positive part within ``|u| <= cell
       + resolution_rows`` (the cell and one more resolution width, where the
       shoulders of a demultiplexed peak lie), over one side only where the
       projector's end cuts the other (NaN where it cuts both).
    3. **Peaks** of the smoothed profile, with scipy's prominence (bases within
       the profile, a peak at the end of the offsets included).  The main peak
       is the highest; another counts if its prominence is at least
       ``peak_prominence`` [0.15] x the main peak's height.  ``fwhm_rows``:
       width of the main peak at half its height (linear interpolation).  A
       counted peak beyond the cell is *displaced* if it is the main peak, or
       its prominence is at least ``strong_peak_prominence`` [0.3] x the main
       peak's height and ``strong_peak_contrast`` [1.5] x the mean level beside
       it (offsets ``core``..``4 core`` away on both sides, outside the main
       peak's flanks, floor included; ``core = smooth_bins // 2 +
       footprint_rows / 2 + 1``), or its prominence is at least
       ``peak_contrast`` [6] x that level: a sparse estimate of a broad
       subsurface skirt is spiky, and its spikes stand only a few times above
       their surroundings, a specular spot far more.  A displaced peak that is
       not the main one must also *add* ``displaced_share_min`` [0.04] of the
       pixel's light within ``core`` of it, above the level beside it (a
       visible effect holds 5 %, :func:`visible_effect_mask`; a spike on a
       broad skirt adds little to the skirt's own light).
    4. **Label**, first rule that applies:

       * 0 ``none``: no light above the floor;
       * 4 ``specular_interreflection``: a displaced peak (a second peak beyond
         the cell, or a dominant displaced one);
       * 3 ``diffuse_interreflection``: ``indirect_fraction >=
         indirect_fraction_min`` [0.07] and ``|asymmetry| >= asymmetry_min``
         [0.75] (steep, one-sided), unless the main peak is broadened
         (``fwhm_rows >= broadening`` [1.3] ``x direct_fwhm_rows``, only when
         ``direct_fwhm_rows`` is given);
       * 2 ``subsurface``: ``indirect_fraction >= indirect_fraction_min``,
         symmetric or broadened; or a core broadened to ``core_spread_rows >=
         core_broadening`` [1.25] ``x direct_core_rows`` (only when
         ``direct_core_rows`` is given);
       * 1 ``diffuse``: otherwise (narrow, unimodal).

    On demultiplexed transports of the built-in scenes, noise gives diffuse
    pixels an apparent indirect fraction up to ~0.06 and noise peaks up to
    ~0.15 of the main peak; the thresholds sit just above.

    References
    ----------
    .. [1] H. Kubo, S. Jayasuriya, T. Iwaguchi, T. Funatomi, Y. Mukaigawa, S. G. Narasimhan,
       "Programmable Non-Epipolar Indirect Light Transport: Capture and Analysis",
       IEEE TVCG 27(4), 2019, doi:10.1109/TVCG.2019.2946812, Sec. 7, Fig. 9.

    Examples
    --------
    A second, displaced peak is a specular interreflection:

    >>> import numpy as np
    >>> from planeray.scenes import EFFECTS
    >>> u = np.arange(-60, 61)
    >>> two = np.exp(-0.5 * (u / 1.5) ** 2) + 0.8 * np.exp(-0.5 * ((u - 40) / 1.5) ** 2)
    >>> c = characterize(two[None], u)
    >>> int(c.peak_count[0]), EFFECTS[int(c.label[0])]
    (2, 'specular_interreflection')
    """
    unknown = set(thresholds) - set(CLASSIFY_THRESHOLDS)
    if unknown:
        raise InputError(f"unknown threshold(s) {sorted(unknown)}; choose from {sorted(CLASSIFY_THRESHOLDS)}")
    th = {**CLASSIFY_THRESHOLDS, **{key: val for key, val in thresholds.items() if val is not None}}
    T = np.asarray(T_profiles, dtype=np.float64)
    offsets = np.asarray(offsets_rows, dtype=np.float64).ravel()
    if T.ndim < 1 or T.shape[-1] != offsets.size:
        raise InputError(f"profiles over {T.shape[-1] if T.ndim else 0} offsets but {offsets.size} offsets_rows given")
    lead = T.shape[:-1]
    U = offsets.size
    P = T.reshape(-1, U)
    N = P.shape[0]
    V = (
        np.ones_like(P, dtype=bool)
        if valid is None
        else np.broadcast_to(np.asarray(valid, bool), T.shape).reshape(N, U)
    )
    P = np.where(V & np.isfinite(P), P, 0.0)
    cell = float(resolution_rows) + 0.5 * float(footprint_rows) + 0.5
    bins = int(th["smooth_bins"])
    S = _smooth_valid(P, V, bins)
    S_raw = S
    if subtract_floor and U > 0:
        reach = np.abs(offsets).max()
        tails = (np.abs(offsets) >= max(cell + 1.0, 0.5 * reach)) & (np.abs(offsets) <= max(cell + 2.0, 0.85 * reach))
        floor = _tail_floor(S, V & tails[None, :], offsets, max(cell + 1.0, 0.5 * reach))
        S = np.where(V, S - floor[:, None], 0.0)
        R = np.where(V, P - floor[:, None], 0.0)
    else:
        R = P
    inside = np.abs(offsets) <= cell
    e0 = R[:, inside].sum(axis=1)
    ep = np.clip(R[:, offsets > cell].sum(axis=1), 0.0, None)
    em = np.clip(R[:, offsets < -cell].sum(axis=1), 0.0, None)
    total = e0 + ep + em
    has_light = (total > 0) & (S.max(axis=1, initial=0.0) > 0)
    frac = np.where(has_light, (ep + em) / np.where(total > 0, total, 1.0), 0.0)
    asym = np.where(ep + em > 0, (ep - em) / np.where(ep + em > 0, ep + em, 1.0), 0.0)
    pos = np.clip(R, 0.0, None)
    mass = pos.sum(axis=1)
    safe = np.where(mass > 0, mass, 1.0)
    mean = (pos * offsets).sum(axis=1) / safe
    spread = np.where(mass > 0, np.sqrt(np.clip((pos * offsets**2).sum(axis=1) / safe - mean**2, 0.0, None)), np.nan)
    core_spread = _core_width(pos, V, offsets, cell + float(resolution_rows))
    # Peaks: the main one is the highest of each profile; others count when
    # prominent enough; a counted peak beyond the cell is specular when it is
    # strong or stands out of its own surroundings (``contrast``): the spikes a
    # sparse estimate makes of a broad subsurface skirt do neither.
    pix, k, prom, height = _peak_table(S, V)
    is_main = np.r_[pix[1:] != pix[:-1], True] if pix.size else np.zeros(0, bool)
    main_k = np.full(N, -1)
    main_h = np.zeros(N)
    main_k[pix[is_main]] = k[is_main]
    main_h[pix[is_main]] = height[is_main]
    lit = main_h[pix] > 0
    counted = lit & (is_main | (prom >= float(th["peak_prominence"]) * main_h[pix]))
    core = int(np.ceil(bins // 2 + 0.5 * float(footprint_rows) + 1.0))
    beside = V & (np.abs(offsets) > cell + core)[None, :]  # not the main peak's flanks
    level = _local_level(S_raw, beside, pix, k, core, 4 * core)  # floor included: noise scales with it
    contrast = np.where(level > 0, prom / np.where(level > 0, level, 1.0), np.inf)
    strong = prom >= float(th["strong_peak_prominence"]) * main_h[pix]
    # A main peak beyond the cell is displaced if a separate peak remains in the
    # cell or its half-maximum interval leaves out u = 0 (a direct peak merged
    # with a one-sided shoulder can have its maximum just beyond the cell).
    fwhm, left, right = _fwhm(S, main_k, main_h)
    zero = np.interp(0.0, offsets, np.arange(U)) if U > 1 else 0.0
    in_cell = counted & (np.abs(offsets[k]) <= cell)
    direct_peak = np.bincount(pix[in_cell], minlength=N) > 0
    apart = direct_peak | ~((left <= zero) & (right >= zero))
    beyond = (np.abs(offsets[k]) > cell) & (~is_main | apart[pix])
    # The light a displaced peak adds within +-core of it, above the level around it,
    # must be a real share of the pixel's (a visible specular effect holds >= 5 %, see
    # visible_effect_mask): the comb of spikes a sparse estimate makes of a broad
    # subsurface skirt stands on the skirt, whose own light is not the spike's.
    csum = np.concatenate([np.zeros((N, 1)), np.cumsum(pos, axis=1)], axis=1)
    lo_k = np.clip(k - core, 0, U)
    hi_k = np.clip(k + core + 1, 0, U)
    if pix.size:
        under = _local_level(np.clip(S, 0.0, None), beside, pix, k, core, 4 * core) * (hi_k - lo_k)
        share = (csum[pix, hi_k] - csum[pix, lo_k] - under) / safe[pix]
    else:
        share = np.zeros(0)
    strong &= contrast >= float(th["strong_peak_contrast"])
    far = counted & beyond & (is_main | strong | (contrast >= float(th["peak_contrast"])))
    far &= is_main | (share >= float(th["displaced_share_min"]))
    count = np.bincount(pix[counted], minlength=N).astype(np.int16)
    second = np.full(N, np.nan)
    other = np.flatnonzero(counted & ~is_main)
    if other.size:
        other = other[np.lexsort((prom[other], pix[other]))]  # most prominent last per profile
        last = np.r_[pix[other][1:] != pix[other][:-1], True]
        second[pix[other][last]] = offsets[k[other][last]]
    displaced = np.full(N, np.nan)
    f = np.flatnonzero(far)  # sorted by (profile, height): the highest last
    if f.size:
        last = np.r_[pix[f][1:] != pix[f][:-1], True]
        displaced[pix[f][last]] = offsets[k[f][last]]
    peak_at = np.where(main_k >= 0, offsets[np.clip(main_k, 0, U - 1)], np.nan)

    label = np.ones(N, np.uint8)
    sig = frac >= float(th["indirect_fraction_min"])
    label[sig] = 2
    one_sided = sig & (np.abs(asym) >= float(th["asymmetry_min"]))
    if direct_fwhm_rows is not None:  # a broadened main peak is subsurface even if one-sided
        one_sided &= ~(fwhm >= float(th["broadening"]) * float(direct_fwhm_rows))
    label[one_sided] = 3
    if direct_core_rows is not None:  # scattering within a few rows: a broadened core
        label[(label == 1) & (core_spread >= float(th["core_broadening"]) * float(direct_core_rows))] = 2
    label[np.isfinite(displaced)] = 4
    label[~has_light] = 0

    def out(a, dtype=np.float32):
        return np.asarray(a).astype(dtype).reshape(lead)

    return ProfileCharacter(
        peak_count=out(count, np.int16),
        fwhm_rows=out(fwhm),
        asymmetry=out(asym),
        indirect_fraction=out(frac),
        second_peak_offset_rows=out(second),
        displaced_peak_offset_rows=out(displaced),
        spread_rows=out(spread),
        core_spread_rows=out(core_spread),
        peak_offset_rows=out(peak_at),
        label=out(label, np.uint8),
        cell_rows=cell,
    )


#: Offsets this close to the end of the projector are left out of the analysis.
EDGE_MARGIN_BINS = 2
#: Diffuse pixels needed to measure the width of a direct peak in an image.
MIN_DIRECT_PIXELS = 16


def _inside_projector(geometry, rows, offsets, margin=EDGE_MARGIN_BINS) -> np.ndarray:
    """Offsets ``(r, U)`` whose bin and ``margin`` bins on each side lie fully on the projector.

    A demultiplexed estimate spikes at the projector's end (light from beyond
    it has nowhere else to go), so the bins there are not part of the profile.
    """
    full = geometry.coverage(np.asarray(rows)[:, None], np.asarray(offsets)[None, :]) >= 1.0 - 1e-6
    if margin > 0:
        from scipy.ndimage import binary_erosion

        full = binary_erosion(full, structure=np.ones((1, 2 * margin + 1), bool), border_value=1)
    return full


def _characterize_transport(transport, resolution_rows, support_rows, chunk_rows, thresholds) -> ProfileCharacter:
    """:func:`characterize` of every pixel of a transport, ``chunk_rows`` camera rows at a time."""
    offsets = transport.offsets_rows
    keep = np.ones(offsets.size, bool) if support_rows is None else np.abs(offsets) <= float(support_rows)
    offsets = offsets[keep]
    geometry = transport.geometry
    H, W = transport.shape
    step = max(1, int(chunk_rows))
    parts = []
    for r0 in range(0, H, step):
        rows = np.arange(r0, min(H, r0 + step))
        valid = _inside_projector(geometry, rows, offsets)
        parts.append(
            characterize(
                transport.dense[rows][:, :, keep],
                offsets,
                resolution_rows=resolution_rows,
                footprint_rows=geometry.rows_per_camera_row,
                valid=valid[:, None, :],
                **thresholds,
            )
        )
    fields = [f for f in ProfileCharacter.__dataclass_fields__ if f != "cell_rows"]
    return ProfileCharacter(
        **{f: np.concatenate([getattr(p, f) for p in parts]) for f in fields}, cell_rows=parts[0].cell_rows
    )


def _direct_width(character: ProfileCharacter, field: str) -> float | None:
    """Median ``field`` of the pixels labelled diffuse (None if fewer than :data:`MIN_DIRECT_PIXELS`)."""
    values = getattr(character, field)
    direct = (character.label == 1) & np.isfinite(values)
    return float(np.median(values[direct])) if direct.sum() >= MIN_DIRECT_PIXELS else None


def _reference_widths(reference, resolution_rows, support_rows, chunk_rows, thresholds, th) -> tuple:
    """The direct-peak widths (FWHM, core) of a ``direct_reference``, measured once per settings.

    They are kept on the reference transport (as it keeps its prefix sums, see
    :class:`planeray.transport.Transport`): one white target classifies every
    scene of a figure, and characterizing it again for each was half the work.
    """
    key = (float(resolution_rows), None if support_rows is None else float(support_rows), tuple(sorted(th.items())))
    memo = reference.__dict__.setdefault("_direct_widths", {})
    if key not in memo:
        character = _characterize_transport(reference, resolution_rows, support_rows, chunk_rows, thresholds)
        memo[key] = (_direct_width(character, "fwhm_rows"), _direct_width(character, "core_spread_rows"))
    return memo[key]


def classify_transport(
    transport,
    *,
    resolution_rows=0.0,
    support_rows=None,
    direct_reference=None,
    chunk_rows=32,
    return_character=False,
    **thresholds,
):
    """Effect label of every pixel of a transport from its profile ``T(u)``.

    Parameters
    ----------
    transport : Transport
        Ground-truth or demultiplexed transport (dense band; sparse long-range
        entries lie beyond it and are not used).
    resolution_rows : float
        Half-width of the cell the data cannot split: a demultiplexing result's
        ``attrs["epipolar_resolution_rows"]`` (6.075 for the paper's sweep), 0
        for an exact transport.
    support_rows : int, optional
        Use only offsets ``|u| <= support_rows`` (e.g. the sweep's support, 114
        rows for the paper's sweep, to see a ground truth as the sweep does).
    direct_reference : Transport, optional
        A transport of a diffuse target (a white plane) obtained the same way:
        same sweep, camera, image height and projector (so the same
        ``rows_per_camera_row`` and offsets), demultiplexed alike.  The width of
        a direct peak is measured on it; by default it is measured on the
        image's own pixels first labelled diffuse, which fails when there are
        none (a close-up of skin: every pixel is broadened alike).
    chunk_rows : int
        Camera rows processed at once (bounds memory).
    return_character : bool
        Also return the :class:`ProfileCharacter` of every pixel.
    **thresholds
        Any key of :data:`CLASSIFY_THRESHOLDS`, passed to :func:`characterize`.

    Returns
    -------
    labels : ndarray (H, W) uint8
        Keys of :data:`planeray.scenes.EFFECTS`.
    character : ProfileCharacter
        Only with ``return_character``; arrays of shape (H, W).

    Raises
    ------
    InputError
        A ``direct_reference`` of another geometry or other offsets.

    See Also
    --------
    planeray.scenes.EFFECTS : the label names.
    characterize : the per-pixel numbers the rules read.

    Notes
    -----
    The camera-row footprint ``P / H`` is part of the unresolved cell; offsets
    off the projector (and the :data:`EDGE_MARGIN_BINS` bins at its ends) are
    ignored.  The widths of a direct peak -- its main-peak FWHM and its
    ``core_spread_rows``, medians over the pixels of ``direct_reference`` (or of
    the image) first labelled diffuse; a rule is skipped when fewer than
    :data:`MIN_DIRECT_PIXELS` are -- decide two labels: one-sided pixels whose
    main peak is ``broadening`` (1.3) times wider are subsurface (light
    scattered inside an object whose boundary cuts the kernel on one side), not
    diffuse interreflection; pixels first labelled diffuse whose core is
    ``core_broadening`` (1.25) times wider are subsurface (scattering within a
    few rows of the epipolar plane: skin, whole milk).

    References
    ----------
    .. [1] H. Kubo, S. Jayasuriya, T. Iwaguchi, T. Funatomi, Y. Mukaigawa, S. G. Narasimhan,
       "Programmable Non-Epipolar Indirect Light Transport: Capture and Analysis",
       IEEE TVCG 27(4), 2019, doi:10.1109/TVCG.2019.2946812, Sec. 7, Fig. 9.

    Examples
    --------
    The effects found in a concave corner's ground-truth transport (8 x 8 pixels):

    >>> import numpy as np
    >>> import planeray as pr
    >>> from planeray.scenes import EFFECTS
    >>> labels = pr.classify_transport(pr.make_scene("corner", (8, 8), seed=0).transport)
    >>> labels.shape, [EFFECTS[int(k)] for k in np.unique(labels)]
    ((8, 8), ['diffuse_interreflection', 'specular_interreflection'])
    """
    ch = _characterize_transport(transport, resolution_rows, support_rows, chunk_rows, thresholds)
    if direct_reference is not None:
        same = (
            direct_reference.geometry.rows_per_camera_row == transport.geometry.rows_per_camera_row
            and np.array_equal(direct_reference.offsets_rows, transport.offsets_rows)
        )
        if not same:
            raise InputError(
                "direct_reference must be a transport of the same geometry and offsets "
                f"({transport.geometry.rows_per_camera_row:g} projector rows per camera row, "
                f"{transport.offsets_rows.size} offsets); got "
                f"{direct_reference.geometry.rows_per_camera_row:g} and {direct_reference.offsets_rows.size}"
            )
    th = {**CLASSIFY_THRESHOLDS, **{key: val for key, val in thresholds.items() if val is not None}}
    if direct_reference is None:
        fwhm, core = _direct_width(ch, "fwhm_rows"), _direct_width(ch, "core_spread_rows")
    else:
        fwhm, core = _reference_widths(direct_reference, resolution_rows, support_rows, chunk_rows, thresholds, th)
    first = ch.label.copy()
    if fwhm is not None:
        ch.label[(first == 3) & (ch.fwhm_rows >= float(th["broadening"]) * fwhm)] = 2
    if core is not None:
        ch.label[(first == 1) & (ch.core_spread_rows >= float(th["core_broadening"]) * core)] = 2
    return (ch.label, ch) if return_character else ch.label


def visible_effect_mask(scene, *, support_rows=114, resolution_rows=6.075, min_fraction=0.05) -> np.ndarray:
    """Pixels whose ground-truth effect a sweep can show.

    A labelled pixel's effect is *visible* when, in its ground-truth transport,
    the light that the sweep can split from the direct peak -- offsets
    ``resolution_rows + P/H < |u| <= support_rows``: beyond the unresolved cell
    widened by one camera-row footprint, inside the sweep's support -- is at
    least ``min_fraction`` of its light within the support.  Subsurface
    scattering is also visible as a *broadened* peak: a subsurface pixel is
    visible when the light beyond the camera-row footprint by half the
    resolution -- ``P/(2H) + 1/2 + resolution_rows / 2 < |u| <= support_rows``,
    the outer half of the cell, where it widens the shoulders of the
    demultiplexed peak -- holds ``min_fraction``.  Diffuse pixels (label 1,
    nothing to see) are always visible; label 0 never.

    This excludes, e.g., mirror-ball page pixels whose specular light is a few
    percent of their direct light (below the noise of a demultiplexed profile),
    disco-ball pixels whose reflection lies beyond the support or next to the
    epipolar plane, toothpaste (its light leaves within the camera row's
    footprint: 1-2 % beyond it), and pixels labelled from light the sweep never
    reaches.

    Parameters
    ----------
    scene : Scene
        Built-in scene (``transport``, ``labels``).
    support_rows : float
        Half-width of the sweep's offset support (114 rows for the paper's sweep).
    resolution_rows : float
        Unresolved half-width around ``u = 0`` (6.075 rows for the paper's sweep).
    min_fraction : float
        Share of the in-support light the effect must hold.

    Returns
    -------
    mask : ndarray (H, W) bool

    See Also
    --------
    label_agreement : scores labels on these pixels.

    Examples
    --------
    >>> import planeray as pr
    >>> scene = pr.make_scene("mirror_ball", (16, 16), seed=0)
    >>> visible_effect_mask(scene).shape
    (16, 16)
    """
    T = scene.transport
    u = np.abs(T.offsets_rows)
    F = T.geometry.rows_per_camera_row
    support = u <= float(support_rows)
    total = T.dense[:, :, support].sum(axis=2, dtype=np.float64)
    floor = float(min_fraction) * np.where(total > 0, total, np.inf)

    def holds(zone):
        return T.dense[:, :, zone].sum(axis=2, dtype=np.float64) >= floor

    labels = np.asarray(scene.labels)
    split = holds(support & (u > float(resolution_rows) + F))
    broadened = holds(support & (u > 0.5 * F + 0.5 + 0.5 * float(resolution_rows)))
    return (labels == 1) | ((labels > 1) & split) | ((labels == 2) & broadened)


def label_agreement(pred, truth_labels, *, mask=None, n_labels=5) -> dict:
    """Agreement of predicted effect labels with ground-truth labels.

    Parameters
    ----------
    pred, truth_labels : array_like of int, same shape
        Predicted and true labels (keys of :data:`planeray.scenes.EFFECTS`).
    mask : array_like of bool, optional
        Pixels to evaluate (e.g. :func:`visible_effect_mask`); pixels with true
        label 0 are always ignored.
    n_labels : int
        Number of label values (5: ``EFFECTS``).

    Returns
    -------
    dict
        ``recall``: ``{k: fraction of the evaluated pixels with true label k
        predicted k}`` for each label ``1..n_labels-1`` present; ``counts``:
        ``{k: number of evaluated pixels with true label k}``; ``confusion``:
        ``(n_labels, n_labels)`` int64 array, rows true label, columns predicted;
        ``overall``: fraction of all evaluated pixels predicted right (NaN if none);
        ``n``: number of evaluated pixels.

    See Also
    --------
    classify_transport : the predicted labels.
    visible_effect_mask : the pixels worth scoring.

    Examples
    --------
    >>> import numpy as np
    >>> truth = np.array([[1, 1, 4, 4]])
    >>> out = label_agreement(np.array([[1, 1, 4, 1]]), truth)
    >>> out["overall"], out["recall"][4]
    (0.75, 0.5)
    """
    pred = np.asarray(pred).astype(np.int64)
    truth = np.asarray(truth_labels).astype(np.int64)
    if pred.shape != truth.shape:
        raise InputError(f"predicted labels {pred.shape} and truth {truth.shape} differ in shape")
    sel = truth > 0
    if mask is not None:
        sel &= np.broadcast_to(np.asarray(mask, bool), truth.shape)
    t, p = truth[sel], np.clip(pred[sel], 0, n_labels - 1)
    confusion = np.bincount(t * n_labels + p, minlength=n_labels * n_labels).reshape(n_labels, n_labels)
    counts = confusion.sum(axis=1)
    recall = {k: float(confusion[k, k] / counts[k]) for k in range(1, n_labels) if counts[k] > 0}
    n = int(counts.sum())
    overall = float(np.trace(confusion[1:, 1:]) / n) if n else float("nan")
    return {
        "recall": recall,
        "counts": {k: int(counts[k]) for k in range(1, n_labels) if counts[k] > 0},
        "confusion": confusion,
        "overall": overall,
        "n": n,
    }

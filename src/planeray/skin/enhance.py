"""Contrast enhancement from a sweep of delay images (Sec. 10, Eq. 7, Fig. 14).

The paper's algorithm: take local patches (200 x 200 pixels), filter each with a bilateral
filter, compute the gradient magnitude of every delay image, and keep per pixel the delay of
maximum gradient (Eq. 7); blur that delay ("heat") map to avoid sharp transitions, and form
the composite ``I(s, t) = I_{t_d*}(s, t)``.

What this module makes explicit (the paper leaves it open):

* **Patch size.**  200 x 200 at the paper's resolution; the rectified camera's rows advance
  with the projector's 720 rows, so a patch is ``200 / 720`` of the image height:
  :func:`paper_patch_px` (36 pixels at 128 rows).
* **Local contrast, not brightness.**  Delay images get darker as the delay grows, so raw
  gradients would always pick the shortest delay.  Each delay image is divided by its local
  mean over the patch (a Gaussian of sigma ``patch_px / 2``: a patch without seams), so its
  gradient is a *relative* (Weber-like) contrast; the composite is built from these
  normalized images as well, so switching delay does not switch brightness.
* **Bilateral filter** (OpenCV ``cv2.bilateralFilter``) on the normalized images: range sigma
  ``bilateral_sigma_range`` (relative units; default twice each image's noise level from
  :func:`noise_sigma`, so that noise is smoothed and edges above the noise are kept), spatial
  sigma ``bilateral_sigma_px`` (default ``patch_px / 24``, 1.5 px at 128 rows).
* **Gradient magnitude** with Sobel derivatives (``scipy.ndimage.sobel``), averaged over a
  small neighbourhood (Gaussian, ``gradient_sigma_px``, default ``patch_px / 12``) before the
  per-pixel argmax: a vein's centre has no gradient of its own, its edges do.
* **Gradient against noise** (``noise_normalize=True``, our addition): a long delay collects
  few photons, and after normalization its noise alone has the largest gradients, so the plain
  argmax picks the noisiest image.  Each patch's gradient is divided by the noise level of
  that patch (Immerkaer's estimator, :func:`noise_sigma`, on the normalized image before
  filtering): the argmax then picks the delay whose edges stand out most from its noise.
  Each delay's score is then standardized over the image (median and MAD: most pixels hold no
  edge, so they give the score of noise alone), the argmax is taken over these z-scores, and
  a pixel whose best z stays below ``min_significance`` (3) -- no significant edge at any
  delay -- takes the least noisy delay instead of one its noise picked.
  ``noise_normalize=False`` is the paper's plain Eq. 7.
* **Too-dark delays left out** (``max_relative_noise``, our addition): a delay image whose
  relative noise exceeds 25 % carries no usable contrast; it is dropped before the argmax.
* **Blurred delay map** (Gaussian, ``map_sigma_px``, default ``patch_px / 6``), and the
  composite at a fractional delay by linear interpolation between the two nearest delay
  images (:func:`compose`, Eq. 7).

References
----------
.. [1] Kubo et al., "Programmable Non-Epipolar Indirect Light Transport: Capture and
   Analysis", IEEE TVCG 2019, Sec. 10 ("Contrast-Enhancement"), Eq. 7, Fig. 14.
.. [2] C. Tomasi, R. Manduchi, "Bilateral filtering for gray and color images", ICCV 1998.
.. [3] J. Immerkaer, "Fast noise variance estimation", Computer Vision and Image Understanding
   64(2), 300-302, 1996.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage

from .._extras import import_extra

__all__ = [
    "PAPER_PATCH_PX",
    "paper_patch_px",
    "local_normalize",
    "bilateral",
    "gradient_magnitude",
    "noise_sigma",
    "patch_noise_map",
    "best_delay_map",
    "compose",
    "EnhanceResult",
    "enhance_contrast",
    "enhance_steps",
]

#: The paper's patch: 200 x 200 pixels of images whose rows follow the projector's 720 rows.
PAPER_PATCH_PX = 200
_PAPER_ROWS = 720


def paper_patch_px(shape) -> int:
    """The paper's 200-pixel patch scaled to an image of ``shape``: ``round(200 H / 720)``, at least 8.

    Parameters
    ----------
    shape : (int, int)
        The image size ``(H, W)``.

    Returns
    -------
    int
        Patch size, pixels.

    See Also
    --------
    enhance_contrast : its ``patch_px``.

    Examples
    --------
    >>> paper_patch_px((128, 128)), paper_patch_px((720, 1280))
    (36, 200)
    """
    return max(8, int(round(PAPER_PATCH_PX * float(shape[0]) / _PAPER_ROWS)))


def local_normalize(image, sigma_px: float) -> np.ndarray:
    """``image / local mean`` (Gaussian of ``sigma_px``): relative contrast around 1."""
    img = np.asarray(image, np.float64)
    mean = ndimage.gaussian_filter(img, sigma_px, mode="reflect")
    # a floor at a tenth of the typical local mean: noise-only regions must not explode
    floor = max(1e-12, 0.1 * float(np.median(np.abs(mean))))
    return img / np.maximum(mean, floor)


def bilateral(image, *, sigma_range: float = 0.05, sigma_px: float = 1.5) -> np.ndarray:
    """Edge-preserving smoothing (Tomasi & Manduchi 1998) with OpenCV's ``bilateralFilter``."""
    cv2 = import_extra("cv2", "Eq. 7's bilateral filter")

    img = np.ascontiguousarray(image, np.float32)
    d = int(2 * np.ceil(2 * sigma_px) + 1)
    return cv2.bilateralFilter(img, d, float(sigma_range), float(sigma_px)).astype(np.float64)


def gradient_magnitude(image) -> np.ndarray:
    """``||grad I||`` from Sobel derivatives (per pixel, not normalized by the kernel weight 8)."""
    img = np.asarray(image, np.float64)
    return np.hypot(ndimage.sobel(img, axis=0, mode="reflect"), ndimage.sobel(img, axis=1, mode="reflect"))


def noise_sigma(image) -> float:
    """Gaussian noise sigma of an image, Immerkaer (1996): ``sqrt(pi/2) / (6 (W-2)(H-2)) sum |I * N|``.

    ``N`` is the difference of two Laplacians, blind to a locally linear image, so smooth
    structure barely counts.

    >>> rng = np.random.default_rng(0)
    >>> round(noise_sigma(0.1 * rng.standard_normal((200, 200)) + np.linspace(0, 5, 200)), 2)
    0.1
    """
    img = np.asarray(image, np.float64)
    if min(img.shape) < 3:
        return float(np.std(img))
    k = np.array([[1.0, -2.0, 1.0], [-2.0, 4.0, -2.0], [1.0, -2.0, 1.0]])
    conv = ndimage.convolve(img, k, mode="reflect")[1:-1, 1:-1]
    h, w = img.shape
    return float(np.sqrt(np.pi / 2.0) * np.abs(conv).sum() / (6.0 * (w - 2) * (h - 2)))


def patch_noise_map(image, patch_px: int) -> np.ndarray:
    """:func:`noise_sigma` of each ``patch_px`` tile, as an image (H, W) (the last tiles flush with the border)."""
    img = np.asarray(image, np.float64)
    H, W = img.shape
    out = np.empty_like(img)
    starts = lambda n: sorted({*range(0, max(n - patch_px, 0) + 1, patch_px), max(n - patch_px, 0)})  # noqa: E731
    for r in starts(H):
        for c in starts(W):
            out[r : r + patch_px, c : c + patch_px] = noise_sigma(img[r : r + patch_px, c : c + patch_px])
    return out


def best_delay_map(gradients, delays_us) -> np.ndarray:
    """Eq. 7: ``t_d*(s, t) = argmax_{t_d} ||grad I_{t_d}(s, t)||`` (the delay, not its index).

    >>> g = np.zeros((3, 1, 2))
    >>> g[2, 0, 0] = 1
    >>> g[0, 0, 1] = 1
    >>> best_delay_map(g, [100, 200, 300]).tolist()
    [[300.0, 100.0]]
    """
    d = np.asarray(delays_us, np.float64)
    return d[np.argmax(np.asarray(gradients), axis=0)]


def compose(images, delays_us, delay_map_us) -> np.ndarray:
    """The composite ``I(s, t) = I_{t_d*(s, t)}(s, t)`` of Eq. 7 (Kubo et al. 2019, Sec. 10).

    ``delay_map_us`` may hold fractional delays (a blurred map); the composite then
    interpolates linearly between the two delay images around ``t_d*`` (``delays_us`` sorted
    ascending).  On the delays themselves it is exactly ``I_{t_d*}``.

    Parameters
    ----------
    images : ndarray (D, H, W)
        The delay images.
    delays_us : array_like (D,)
        Their delays, microseconds, ascending.
    delay_map_us : ndarray (H, W)
        The chosen delay ``t_d*`` of each pixel, microseconds.

    Returns
    -------
    ndarray (H, W)

    See Also
    --------
    enhance_contrast : chooses the map.

    Examples
    --------
    >>> imgs = np.stack([np.zeros((1, 2)), np.ones((1, 2))])
    >>> compose(imgs, [0, 100], np.array([[0.0, 25.0]])).tolist()
    [[0.0, 0.25]]
    """
    imgs = np.asarray(images, np.float64)
    d = np.asarray(delays_us, np.float64)
    if imgs.ndim != 3 or imgs.shape[0] != d.size:
        raise ValueError(f"{d.size} delays for images of shape {imgs.shape}")
    if d.size > 1 and np.any(np.diff(d) <= 0):
        raise ValueError("delays must be strictly increasing")
    m = np.clip(np.asarray(delay_map_us, np.float64), d[0], d[-1])
    if d.size == 1:
        return imgs[0].copy()
    j = np.clip(np.searchsorted(d, m, side="right") - 1, 0, d.size - 2)
    w = (m - d[j]) / (d[j + 1] - d[j])
    lo = np.take_along_axis(imgs, j[None], axis=0)[0]
    hi = np.take_along_axis(imgs, (j + 1)[None], axis=0)[0]
    return (1.0 - w) * lo + w * hi


@dataclass
class EnhanceResult:
    """Result of :func:`enhance_contrast`.

    Attributes
    ----------
    image : ndarray (H, W)
        The contrast-enhanced composite (normalized, filtered delay images; ~1 on skin).
    delay_map_us : ndarray (H, W)
        The blurred map of ``t_d*`` (microseconds).
    raw_delay_map_us : ndarray (H, W)
        Eq. 7's per-pixel argmax before blurring.
    normalized : ndarray (N, H, W)
        The locally normalized, bilateral-filtered delay images the composite is made of.
    delays_us : ndarray (N,)
    params : dict
        The patch and filter sizes used.

    See Also
    --------
    enhance_contrast : returns it.

    References
    ----------
    .. [1] H. Kubo, S. Jayasuriya, T. Iwaguchi, T. Funatomi, Y. Mukaigawa, S. G. Narasimhan,
       "Programmable Non-Epipolar Indirect Light Transport: Capture and Analysis",
       IEEE TVCG 27(4), 2019, doi:10.1109/TVCG.2019.2946812, Eq. 7, Sec. 10.

    Examples
    --------
    >>> import numpy as np
    >>> images = np.stack([np.full((16, 16), v, np.float32) for v in (0.2, 0.4)])
    >>> result = enhance_contrast(images, [375.0, 750.0], patch_px=8)
    >>> type(result).__name__, result.image.shape
    ('EnhanceResult', (16, 16))
    """

    image: np.ndarray
    delay_map_us: np.ndarray
    raw_delay_map_us: np.ndarray
    normalized: np.ndarray = field(repr=False)
    delays_us: np.ndarray
    params: dict


def enhance_steps(n_images: int, *, noise_normalize: bool = True) -> int:
    """Progress steps :func:`enhance_contrast` reports for ``n_images`` delay images (an upper bound:
    images too noisy to use are left out after the first step, and the remaining steps skipped)."""
    return int(n_images) * (4 if noise_normalize else 3) + 1


def enhance_contrast(
    images,
    delays_us,
    *,
    patch_px: int | None = None,
    bilateral_sigma_range: float | None = None,
    bilateral_sigma_px: float | None = None,
    gradient_sigma_px: float | None = None,
    map_sigma_px: float | None = None,
    noise_normalize: bool = True,
    min_significance: float = 3.0,
    max_relative_noise: float | None = 0.25,
    progress=None,
) -> EnhanceResult:
    """Contrast-enhanced image from a sweep of delay images (Sec. 10, Eq. 7, Fig. 14).

    Parameters
    ----------
    images : array_like (N, H, W)
        Delay images (one exposure), any linear units.
    delays_us : array_like (N,)
        Their delays; sorted internally.
    patch_px : int, optional
        Patch size; default :func:`paper_patch_px` (200 at the paper's 720 rows).
    bilateral_sigma_range, bilateral_sigma_px, gradient_sigma_px, map_sigma_px : float
        See the module notes; pixel sizes default to fractions of ``patch_px``.
    noise_normalize : bool
        Divide each patch's gradient by its noise level (see the module notes); False is the
        paper's plain argmax of the gradient.
    min_significance : float
        With ``noise_normalize``: the standardized score (robust z over the image) a pixel's
        best delay must reach; below it the pixel takes the least noisy delay.
    max_relative_noise : float or None
        Delay images whose noise (Immerkaer, relative to the local mean) exceeds this are left
        out (0.25: a vein of 25 % contrast would sit at one sigma); None keeps them all.
    progress : callable, optional
        Called with a number of steps done, :func:`enhance_steps` in all (each delay image
        normalized, filtered, differentiated and weighed by its noise; the composite).

    Returns
    -------
    EnhanceResult

    See Also
    --------
    compose : the composite of Eq. 7.

    Examples
    --------
    Two stripes, each visible at one delay only; the composite shows both:

    >>> rng = np.random.default_rng(1)
    >>> imgs = 1.0 + 0.01 * rng.standard_normal((2, 64, 64))
    >>> imgs[0, :, 10:13] -= 0.1
    >>> imgs[1, :, 50:53] -= 0.1
    >>> r = enhance_contrast(imgs, [300.0, 600.0])
    >>> float(r.delay_map_us[32, 11]) < 400 < float(r.delay_map_us[32, 51])
    True
    """
    imgs = np.asarray(images, np.float64)
    d = np.asarray(delays_us, np.float64).ravel()
    if imgs.ndim != 3 or imgs.shape[0] != d.size or d.size < 1:
        raise ValueError(f"need a stack of delay images (N, H, W) and N delays, got {imgs.shape} and {d.size}")
    if not np.all(np.isfinite(d)) or np.unique(d).size != d.size:
        raise ValueError("delays must be finite and distinct")
    order = np.argsort(d)
    imgs, d = imgs[order], d[order]
    patch = paper_patch_px(imgs.shape[1:]) if patch_px is None else int(patch_px)
    if patch < 2:
        raise ValueError(f"patch_px must be at least 2, got {patch_px}")
    if patch_px is not None and patch > min(imgs.shape[1:]):
        raise ValueError(
            f"patch_px must be at most the image's smaller side ({min(imgs.shape[1:])} px), got {patch_px}"
        )
    n_in = d.size

    def step(k=1):
        if progress is not None:
            progress(k)

    s_bil = patch / 24.0 if bilateral_sigma_px is None else float(bilateral_sigma_px)
    s_grad = patch / 12.0 if gradient_sigma_px is None else float(gradient_sigma_px)
    s_map = patch / 6.0 if map_sigma_px is None else float(map_sigma_px)
    relative, noise = [], []
    for im in imgs:
        relative.append(local_normalize(im, patch / 2.0))
        noise.append(noise_sigma(relative[-1]))
        step()
    all_delays, all_noise = d.copy(), list(noise)
    if max_relative_noise is not None:  # delays too dark to carry any contrast are left out
        keep = np.flatnonzero(np.asarray(noise) <= float(max_relative_noise))
        keep = keep if keep.size else np.array([int(np.argmin(noise))])
        imgs, d = imgs[keep], d[keep]
        relative, noise = [relative[i] for i in keep], [noise[i] for i in keep]
        step((n_in - d.size) * (enhance_steps(1, noise_normalize=noise_normalize) - 2))  # the steps left out
    ranges = [2.0 * n if bilateral_sigma_range is None else float(bilateral_sigma_range) for n in noise]
    normalized, grads = [], []
    for r, sr in zip(relative, ranges):
        normalized.append(bilateral(r, sigma_range=sr, sigma_px=s_bil))
        step()
    normalized = np.stack(normalized)
    for n in normalized:
        grads.append(ndimage.gaussian_filter(gradient_magnitude(n), s_grad))
        step()
    grads = np.stack(grads)
    if noise_normalize:
        noise_maps = []
        for r in relative:
            noise_maps.append(np.maximum(patch_noise_map(r, patch), 1e-12))
            step()
        grads = grads / np.stack(noise_maps)
        # standardize each delay's score over the image: most pixels carry no edge, so the median
        # and MAD give the score of noise alone; a pixel without a significant edge in any delay
        # (z < min_significance) takes the least noisy delay instead of a noise-picked one.
        med = np.median(grads, axis=(1, 2), keepdims=True)
        mad = 1.4826 * np.median(np.abs(grads - med), axis=(1, 2), keepdims=True)
        z = (grads - med) / np.maximum(mad, 1e-12)
        quiet = int(np.argmin(noise))
        raw = np.where(z.max(axis=0) >= min_significance, best_delay_map(z, d), d[quiet])
    else:
        raw = best_delay_map(grads, d)
    smooth = ndimage.gaussian_filter(raw, s_map, mode="reflect") if s_map > 0 else raw
    image = compose(normalized, d, smooth)
    step()
    params = {
        "patch_px": patch,
        "normalize_sigma_px": patch / 2.0,
        "bilateral_sigma_range": [float(x) for x in ranges],
        "noise_sigma": [float(x) for x in noise],
        "bilateral_sigma_px": s_bil,
        "gradient_sigma_px": s_grad,
        "map_sigma_px": s_map,
        "noise_normalize": bool(noise_normalize),
        "min_significance": float(min_significance),
        "max_relative_noise": None if max_relative_noise is None else float(max_relative_noise),
        "delays_in_us": [float(x) for x in all_delays],
        "noise_sigma_in": [float(x) for x in all_noise],
        "delays_used_us": [float(x) for x in d],
    }
    return EnhanceResult(image, smooth, raw, normalized, d, params)

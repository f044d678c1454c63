"""The demultiplexing study of Sec. 5.2 (Figs. 5 and 6) in simulation.

A 1-D scattering profile ``T`` over the paper sweep's offsets ``u = -K..K``
(``K = sweep_support_rows(paper_sweep(), 54000)`` = 114, 229 offsets) is imaged
through the used bands (``A[i, u] = L_i(u)``, ``(75, 229)``), scaled so that
``max(A T) = 1`` (images normalized to [0, 1], the range the paper's
``alpha = beta = 0.01`` refer to), and corrupted with ``eta ~ N(0, noise^2)``:
``I = A T + eta``.  Three reconstructions are compared by their MSE against the
true ``T`` (mean over the 229 offsets):

* ``pinv`` -- pseudo-inverse (minimum-norm least squares);
* ``nnls`` -- non-negative least squares without regularization;
* ``full`` -- the paper's method (non-negativity + ``alpha ||dT/dv||^2 +
  beta ||T||_1``), solved by :func:`planeray.demux.solve_fast`.

The profile comes from a *provider* ``profile(sigma_s, sigma_a, g) -> T`` over
the offsets (the swept coordinates; the built-in providers make a
:class:`~planeray.medium.Medium` of them with their own index ``n``): the Monte
Carlo engine :func:`planeray.mc.mc_line_profile` (``provider='mc'``, the
default, what the paper did with Mitsuba) or the
diffusion-dipole line kernel :func:`planeray.kernels.dipole_line_kernel` with
the similarity relation ``sigma_s' = sigma_s (1 - g)`` (``'dipole'``, instant) --
with the dipole, ``g`` enters *only* through ``sigma_s'`` (no single-scattering,
no phase-function shape), so its g-sweep measures the profile's width alone.

Every noise realization is shared by the three methods (paired comparison), and
every realization is seeded from ``(seed, point)`` so results are reproducible.

The sweeps take ``progress=``, called as ``progress(1)`` after each swept point
(each ``alpha x beta`` cell of :func:`regularization_sweep`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .demux import RowGroup, solve_fast, solve_nnls, solve_pinv
from .medium import Medium
from .timing import PAPER_LINES_PER_SECOND, paper_sweep, sweep_support_rows

__all__ = [
    "DEFAULT_PARAMS",
    "DEFAULT_NOISE",
    "DEFAULT_MM_PER_ROW",
    "METHODS",
    "StudySetup",
    "study_setup",
    "dipole_provider",
    "mc_provider",
    "default_provider",
    "resolve_provider",
    "cached_provider",
    "grids",
    "scaled_truth",
    "reconstruct",
    "mse_trials",
    "reconstruction_example",
    "noise_sweep",
    "parameter_sweep",
    "regularization_sweep",
    "auto_weights",
    "FIXED_ALPHAS",
    "FIXED_BETAS",
]

#: The paper's default configuration (Figs. 5, 6): sigma_s = 1, sigma_a = 0, g = 0.9 (mm^-1).
DEFAULT_PARAMS = {"sigma_s": 1.0, "sigma_a": 0.0, "g": 0.9}
#: The paper's default noise level eta.
DEFAULT_NOISE = 0.05
#: Size of one projector row on the surface (mm).  With the defaults the transport
#: mean free path 1 / sigma_s' is 10 mm = 10 rows: the profile spans tens of rows
#: of the 229-offset support.
DEFAULT_MM_PER_ROW = 1.0
#: Reconstruction methods compared.
METHODS = ("pinv", "nnls", "full")

Provider = Callable[[float, float, float], np.ndarray]


# ---------------------------------------------------------------------------- setup
@dataclass
class StudySetup:
    """Offsets ``u`` (U,), the band matrix ``A`` (N, U) and its :class:`RowGroup`.

    Parameters
    ----------
    offsets : ndarray (U,) of int
        Offsets ``u``, projector rows.
    A : ndarray (N, U)
        The used images' bands.
    group : RowGroup
        ``A`` as the solvers take it.

    See Also
    --------
    study_setup : builds it.

    References
    ----------
    .. [1] H. Kubo, S. Jayasuriya, T. Iwaguchi, T. Funatomi, Y. Mukaigawa, S. G. Narasimhan,
       "Programmable Non-Epipolar Indirect Light Transport: Capture and Analysis",
       IEEE TVCG 27(4), 2019, doi:10.1109/TVCG.2019.2946812, Sec. 5.2.

    Examples
    --------
    >>> from planeray.timing import quick_sweep
    >>> setup = study_setup(quick_sweep())
    >>> setup.A.shape, setup.offsets.size  # 23 used images x 229 offsets
    ((23, 229), 229)
    """

    offsets: np.ndarray
    A: np.ndarray
    group: RowGroup


def study_setup(sweep=None, lines_per_second: float = PAPER_LINES_PER_SECOND) -> StudySetup:
    """The paper sweep's used bands over ``u = -K..K`` (75 x 229 for the paper sweep).

    Parameters
    ----------
    sweep : Sweep, optional
        Default: the paper's.
    lines_per_second : float
        Projector scan rate, rows per second.

    Returns
    -------
    StudySetup

    See Also
    --------
    reconstruct : solves with it.

    References
    ----------
    .. [1] H. Kubo, S. Jayasuriya, T. Iwaguchi, T. Funatomi, Y. Mukaigawa, S. G. Narasimhan,
       "Programmable Non-Epipolar Indirect Light Transport: Capture and Analysis",
       IEEE TVCG 27(4), 2019, doi:10.1109/TVCG.2019.2946812, Sec. 5.2.

    Examples
    --------
    >>> setup = study_setup()  # the paper's sweep
    >>> setup.A.shape
    (75, 229)
    """
    sweep = paper_sweep() if sweep is None else sweep
    K = sweep_support_rows(sweep, lines_per_second)
    u = np.arange(-K, K + 1)
    bands = [b for b, x in zip(sweep.bands(lines_per_second), sweep.excluded) if not x]
    A = np.stack([b.profile(u) for b in bands]).astype(np.float64)
    return StudySetup(u, A, RowGroup(rows=np.array([0]), A=A, valid=slice(0, u.size)))


# ---------------------------------------------------------------------------- providers
def dipole_provider(offsets, mm_per_row: float = DEFAULT_MM_PER_ROW, eta: float = 1.0) -> Provider:
    """Profile from the diffusion dipole with ``sigma_s' = sigma_s (1 - g)``.

    ``g`` enters only through the similarity relation.  ``eta = 1`` (index-matched
    boundary) matches the Monte Carlo engine's default ``n = 1``.

    Parameters
    ----------
    offsets : array_like of int
        Offsets ``u``, projector rows.
    mm_per_row : float
        Size of a projector row on the surface, mm.
    eta : float
        Relative refractive index of the medium.

    Returns
    -------
    callable
        ``profile(sigma_s, sigma_a, g)`` (1/mm) -> ndarray (U,).

    See Also
    --------
    mc_provider : by Monte Carlo.

    Examples
    --------
    >>> from planeray.timing import quick_sweep
    >>> setup = study_setup(quick_sweep())
    >>> profile = dipole_provider(setup.offsets, mm_per_row=1.0)
    >>> profile(1.0, 0.01, 0.9).shape  # sigma_s, sigma_a (1/mm), g
    (229,)
    """
    from .mc.diffusion import dipole_line_kernel

    offsets = np.asarray(offsets)

    def profile(sigma_s, sigma_a, g):
        return dipole_line_kernel(Medium(sigma_s=sigma_s, sigma_a=sigma_a, g=g, n=eta), offsets, mm_per_row=mm_per_row)

    profile.name = f"dipole (sigma_s' = sigma_s (1 - g), {mm_per_row} mm/row, eta {eta})"
    return profile


def mc_provider(
    offsets,
    mm_per_row: float = DEFAULT_MM_PER_ROW,
    n_photons: int = 200_000,
    seed: int = 0,
    n: float = 1.0,
    cache: bool = True,
) -> Provider:
    """Profile from :func:`planeray.mc.mc_line_profile`: exitance of a semi-infinite HG medium.

    Results are cached on disk (:func:`planeray.mc.cache_dir`), so a second run of
    the study reuses them.  Cost grows with the number of collisions per photon:
    with ``sigma_a = 0`` a photon scatters until it leaves or is handed to
    diffusion theory 10 transport mean free paths deep (~250 collisions at the
    defaults; see :func:`planeray.mc.mc_line_profile`).

    Parameters
    ----------
    offsets : array_like of int
        Offsets ``u``, projector rows.
    mm_per_row : float
        Size of a projector row on the surface, mm.
    n_photons : int
        Photons per profile.
    seed : int
        Seed of the tracing.
    n : float
        Relative refractive index of the medium.
    cache : bool
        Keep profiles on disk.

    Returns
    -------
    callable
        ``profile(sigma_s, sigma_a, g)`` (1/mm) -> ndarray (U,).

    See Also
    --------
    dipole_provider : the diffusion dipole.

    Examples
    --------
    >>> from planeray.timing import quick_sweep
    >>> setup = study_setup(quick_sweep())
    >>> profile = mc_provider(setup.offsets, n_photons=2_000, cache=False)
    >>> profile(1.0, 0.1, 0.9).shape
    (229,)
    """
    from .mc import mc_line_profile

    offsets = np.asarray(offsets)

    def profile(sigma_s, sigma_a, g):
        res = mc_line_profile(
            Medium(sigma_s=sigma_s, sigma_a=sigma_a, g=g, n=n),
            n_photons=int(n_photons),
            offsets_rows=offsets,
            mm_per_row=mm_per_row,
            seed=seed,
            cache=cache,
        )
        return np.asarray(res.values, np.float64)

    profile.name = f"Monte Carlo ({n_photons:.0e} photons, {mm_per_row} mm/row, n {n})"
    return profile


def default_provider(
    offsets, mm_per_row: float = DEFAULT_MM_PER_ROW, n_photons: int = 200_000, use_mc: bool = True
) -> Provider:
    """The provider :func:`run_study` uses unless told otherwise: :func:`mc_provider`
    (``use_mc=False``: :func:`dipole_provider`).

    Monte Carlo gives the real single-scattering peak and phase-function shape
    (what the paper's Mitsuba profiles had); the full study's 33 profiles take
    ~50 s on 2 cores the first time, then come from the disk cache.  The dipole
    is instant and smooth.

    Parameters
    ----------
    offsets : array_like of int
        Offsets ``u``, projector rows.
    mm_per_row : float
        Size of a projector row on the surface, mm.
    n_photons : int
        Photons per profile (Monte Carlo).
    use_mc : bool
        Monte Carlo (True) or the dipole.

    Returns
    -------
    callable

    See Also
    --------
    resolve_provider : by name.

    Examples
    --------
    >>> from planeray.timing import quick_sweep
    >>> setup = study_setup(quick_sweep())
    >>> default_provider(setup.offsets, use_mc=False).name.startswith("dipole")
    True
    """
    if use_mc:
        return mc_provider(offsets, mm_per_row, n_photons)
    return dipole_provider(offsets, mm_per_row)


def resolve_provider(provider, offsets) -> Provider:
    """The provider named by ``provider``: None or ``"mc"`` (Monte Carlo), ``"dipole"``, or a callable as it is.

    Parameters
    ----------
    provider : None, {"mc", "dipole"} or callable
        ``profile(sigma_s, sigma_a, g) -> T`` over ``offsets`` (1/mm; T per projector row).
    offsets : ndarray of int
        Offsets ``u`` of the profiles, projector rows.

    Returns
    -------
    callable
        ``profile(sigma_s, sigma_a, g)``.

    See Also
    --------
    default_provider : the default.

    Examples
    --------
    >>> from planeray.timing import quick_sweep
    >>> setup = study_setup(quick_sweep())
    >>> resolve_provider("dipole", setup.offsets).name.startswith("dipole")
    True
    """
    if provider is None or provider in ("mc", "dipole"):
        return default_provider(offsets, use_mc=provider != "dipole")
    if callable(provider):
        return provider
    raise ValueError(f"provider must be None, 'dipole', 'mc' or a callable, got {provider!r}")


def cached_provider(provider: Provider) -> Provider:
    """``provider`` remembering each profile it made (the sweeps ask for the same profiles again).

    Parameters
    ----------
    provider : callable
        ``profile(sigma_s, sigma_a, g)`` (1/mm).

    Returns
    -------
    callable
        The same profiles, each computed once.

    See Also
    --------
    resolve_provider : a provider by name.

    Examples
    --------
    >>> from planeray.timing import quick_sweep
    >>> setup = study_setup(quick_sweep())
    >>> profile = cached_provider(dipole_provider(setup.offsets))
    >>> profile(1.0, 0.01, 0.9) is profile(1.0, 0.01, 0.9)  # computed once
    True
    """
    cache = {}

    def profile(sigma_s, sigma_a, g):
        key = (float(sigma_s), float(sigma_a), float(g))
        if key not in cache:
            cache[key] = np.asarray(provider(*key), np.float64)
        return cache[key]

    profile.name = getattr(provider, "name", getattr(provider, "__name__", "custom"))
    return profile


def scaled_truth(A, T) -> np.ndarray:
    """``T`` scaled so that ``max(A T) = 1`` (normalized images).

    Parameters
    ----------
    A : ndarray (N, U)
        The bands.
    T : array_like (U,)
        A profile.

    Returns
    -------
    ndarray (U,)

    See Also
    --------
    mse_trials : uses it.

    Examples
    --------
    >>> from planeray.timing import quick_sweep
    >>> setup = study_setup(quick_sweep())
    >>> T = scaled_truth(setup.A, dipole_provider(setup.offsets)(1.0, 0.01, 0.9))
    >>> round(float((setup.A @ T).max()), 6)
    1.0
    """
    T = np.clip(np.asarray(T, np.float64), 0.0, None)
    peak = float(np.max(A @ T))
    if not peak > 0:
        raise ValueError("the profile gives no light in any image")
    return T / peak


# ---------------------------------------------------------------------------- core
def reconstruct(setup: StudySetup, B, methods=METHODS, alpha=0.01, beta=0.01) -> dict:
    """Reconstructions ``{method: X (P, U)}`` of observations ``B`` (P, N).

    Parameters
    ----------
    setup : StudySetup
        The band matrix (:func:`study_setup`).
    B : array_like (P, N)
        Observations.
    methods : tuple of {"pinv", "nnls", "full"}
        The reconstructions.
    alpha, beta : float
        Weights of the full method.

    Returns
    -------
    dict of str to ndarray (P, U)

    See Also
    --------
    mse_trials : their errors.

    Examples
    --------
    >>> from planeray.timing import quick_sweep
    >>> setup = study_setup(quick_sweep())
    >>> T = scaled_truth(setup.A, dipole_provider(setup.offsets)(1.0, 0.01, 0.9))
    >>> X = reconstruct(setup, setup.A @ T, methods=("pinv", "full"))
    >>> sorted(X), X["full"].shape
    (['full', 'pinv'], (1, 229))
    """
    B = np.atleast_2d(np.asarray(B, np.float64))
    out = {}
    for m in methods:
        if m == "pinv":
            out[m] = solve_pinv(setup.group, B).X
        elif m == "nnls":
            out[m] = solve_nnls(setup.group, B).X
        elif m == "full":
            out[m] = solve_fast(setup.group, B, alpha, beta).X
        else:
            raise ValueError(f"unknown method {m!r}; choose from {METHODS}")
    return out


def _observations(setup: StudySetup, T, noise, seeds, point=0):
    clean = setup.A @ T
    rows = [clean + noise * np.random.default_rng([s, point]).standard_normal(clean.size) for s in range(seeds)]
    return np.stack(rows)


def mse_trials(setup: StudySetup, T, noise, seeds=5, methods=METHODS, alpha=0.01, beta=0.01, point=0, return_x=False):
    """MSE against ``T`` of each method for ``seeds`` noise realizations: ``{method: (seeds,)}``.

    Parameters
    ----------
    setup : StudySetup
        The band matrix (:func:`study_setup`).
    T : ndarray (U,)
        The true profile (:func:`scaled_truth`).
    noise : float
        Standard deviation of the image noise, normalized units.
    seeds : int
        Noise realizations.
    methods : tuple of str
        The reconstructions.
    alpha, beta : float
        Weights of the full method.
    point : int
        Seeds the noise per grid point.
    return_x : bool
        Also return the reconstructions.

    Returns
    -------
    dict of str to ndarray (seeds,)
        (and the reconstructions with ``return_x``).

    See Also
    --------
    reconstruct : one reconstruction.

    Examples
    --------
    >>> from planeray.timing import quick_sweep
    >>> setup = study_setup(quick_sweep())
    >>> T = scaled_truth(setup.A, dipole_provider(setup.offsets)(1.0, 0.01, 0.9))
    >>> mse = mse_trials(setup, T, noise=0.05, seeds=2, methods=("nnls", "full"))
    >>> mse["full"].shape, bool(mse["full"].mean() < mse["nnls"].mean())
    ((2,), True)
    """
    B = _observations(setup, T, noise, seeds, point)
    X = reconstruct(setup, B, methods, alpha, beta)
    mse = {m: ((x - T[None]) ** 2).mean(axis=1) for m, x in X.items()}
    return (mse, X) if return_x else mse


def _truth(setup, provider, sigma_s, sigma_a, g):
    return scaled_truth(setup.A, provider(sigma_s, sigma_a, g))


def reconstruction_example(setup: StudySetup, provider: Provider, noise=DEFAULT_NOISE, seed=0, **params) -> dict:
    """Fig. 5a/b: truth and one reconstruction per method (noise realization ``seed``).

    Parameters
    ----------
    setup : StudySetup
        The band matrix (:func:`study_setup`).

    provider : callable
        ``profile(sigma_s, sigma_a, g)`` (1/mm) over ``setup.offsets``.
    noise : float
        Image noise, normalized units.
    seed : int
        The noise realization.
    **params
        ``sigma_s``, ``sigma_a``, ``g`` (1/mm), ``alpha``, ``beta``.

    Returns
    -------
    dict
        ``truth`` and each method's reconstruction, with their MSE.

    See Also
    --------
    noise_sweep : over noise levels.

    Examples
    --------
    >>> from planeray.timing import quick_sweep
    >>> setup = study_setup(quick_sweep())
    >>> example = reconstruction_example(setup, dipole_provider(setup.offsets))
    >>> example["full"].shape == example["truth"].shape
    True
    """
    p = {**DEFAULT_PARAMS, **params}
    T = _truth(setup, provider, p["sigma_s"], p["sigma_a"], p["g"])
    B = _observations(setup, T, noise, seed + 1)[seed : seed + 1]
    X = reconstruct(setup, B)
    return {
        "offsets": setup.offsets,
        "truth": T,
        **{m: x[0] for m, x in X.items()},
        "mse": {m: float(((x[0] - T) ** 2).mean()) for m, x in X.items()},
    }


def noise_sweep(setup: StudySetup, provider: Provider, noises, seeds=5, *, progress=None, **params) -> dict:
    """Fig. 5c: ``mse[method]`` of shape ``(len(noises), seeds)``; ``progress(1)`` after each noise level.

    Parameters
    ----------
    setup : StudySetup
        The band matrix (:func:`study_setup`).

    provider : callable
        ``profile(sigma_s, sigma_a, g)`` (1/mm) over ``setup.offsets``.
    noises : array_like
        Noise levels, normalized units.
    seeds : int
        Realizations per level.
    progress : callable, optional
        ``progress(1)`` after each level.
    **params
        ``sigma_s``, ``sigma_a``, ``g`` (1/mm), ``alpha``, ``beta``.

    Returns
    -------
    dict
        ``mse[method]`` (len(noises), seeds).

    See Also
    --------
    parameter_sweep : over the medium.

    Examples
    --------
    >>> from planeray.timing import quick_sweep
    >>> setup = study_setup(quick_sweep())
    >>> out = noise_sweep(setup, dipole_provider(setup.offsets), [0.01, 0.1], seeds=2)
    >>> out["mse"]["full"].shape
    (2, 2)
    """
    p = {**DEFAULT_PARAMS, **params}
    T = _truth(setup, provider, p["sigma_s"], p["sigma_a"], p["g"])
    mse = {m: np.zeros((len(noises), seeds)) for m in METHODS}
    for i, eta in enumerate(noises):
        r = mse_trials(setup, T, float(eta), seeds, point=i)
        for m in METHODS:
            mse[m][i] = r[m]
        if progress is not None:
            progress(1)
    return {"noise": np.asarray(noises, float), "mse": mse}


#: Grid of the best fixed weights per profile (whole decades), against which the automatic choice is held.
FIXED_ALPHAS = tuple(float(10.0**e) for e in range(-3, 5))
FIXED_BETAS = tuple(float(10.0**e) for e in range(-4, 2))


def auto_weights(setup: StudySetup, B, *, criterion: str | None = None) -> tuple[float, float]:
    """``alpha, beta`` chosen from observations ``B`` (P, N) alone, as ``planeray demux --alpha auto --beta auto``.

    The criterion of :mod:`planeray.demux.auto` (generalized cross-validation by default;
    ``criterion="cv-images"``: 5-fold cross-validation over the images, seed 0), the
    observations of the ``P`` noise realizations pooled like the pixels of a stack, weighted
    alike (the study's noise is the same for every image).

    Parameters
    ----------
    setup : StudySetup
        The band matrix (:func:`study_setup`).
    B : array_like (P, N)
        Observations (noise realizations pooled).
    criterion : str, optional
        ``"gcv"`` (default) or ``"cv-images"``.

    Returns
    -------
    alpha, beta : float

    See Also
    --------
    planeray.demux.choose_weights : the same for a stack.

    Examples
    --------
    >>> from planeray.timing import quick_sweep
    >>> setup = study_setup(quick_sweep())
    >>> T = scaled_truth(setup.A, dipole_provider(setup.offsets)(1.0, 0.01, 0.9))
    >>> import numpy as np
    >>> B = setup.A @ T + 0.02 * np.random.default_rng(0).standard_normal((20, setup.A.shape[0]))
    >>> alpha, beta = auto_weights(setup, B)
    >>> alpha > 0 and beta > 0
    True
    """
    from .demux.auto import (
        CV_CRITERION,
        DEFAULT_ALPHAS,
        DEFAULT_BETAS,
        DEFAULT_CRITERION,
        cv_score,
        fold_indices,
        risk_score,
        search,
        summarize,
    )

    criterion = DEFAULT_CRITERION if criterion is None else criterion
    if criterion not in ("gcv", CV_CRITERION):  # SURE needs the noise level, which these weights do not carry
        raise ValueError(f"criterion must be 'gcv' or {CV_CRITERION!r} here, got {criterion!r}")
    B = np.atleast_2d(np.asarray(B, np.float64))
    ones = np.ones_like(B)
    if criterion == CV_CRITERION:
        split = fold_indices(B.shape[1], 5, 0)
        score = lambda a, b: cv_score([setup.group], [B], [None], [ones], split, a, b, threads=1)  # noqa: E731
    else:
        warm: dict = {}
        score = lambda a, b: risk_score(  # noqa: E731
            [setup.group], [B], [None], [ones], a, b, threads=1, gcv=criterion == "gcv", warm=warm
        )
    curve = search(score, {"alpha": "auto", "beta": "auto"}, DEFAULT_ALPHAS, DEFAULT_BETAS)
    return summarize(curve)[3]


def _auto_vs_fixed(setup: StudySetup, T, noise, seeds, point):
    """MSE per seed at the automatic weights, and the best fixed pair of the decade grid (mean MSE)."""
    from threadpoolctl import threadpool_limits

    B = _observations(setup, T, noise, seeds, point)
    # a few pixels at a time: one thread, and BLAS held to one too (its spinning threads
    # cost ~10x on a busy machine)
    with threadpool_limits(1, user_api="blas"):
        a, b = auto_weights(setup, B)
        auto = ((solve_fast(setup.group, B, a, b, threads=1).X - T[None]) ** 2).mean(axis=1)
        best = (np.inf, 0.0, 0.0)
        for fa in FIXED_ALPHAS:
            for fb in FIXED_BETAS:
                m = float(((solve_fast(setup.group, B, fa, fb, threads=1).X - T[None]) ** 2).mean())
                best = min(best, (m, fa, fb))
    return (a, b, auto), best


def parameter_sweep(
    setup: StudySetup,
    provider: Provider,
    name: str,
    values,
    seeds=5,
    noise=DEFAULT_NOISE,
    *,
    progress=None,
    auto: bool = False,
    **params,
) -> dict:
    """Fig. 6: ``mse[method]`` of shape ``(len(values), seeds)`` as ``name`` in
    {'sigma_s', 'sigma_a', 'g'} varies, the others at their defaults; ``progress(1)``
    after each value (its profile included: a Monte Carlo provider traces it then).

    With ``auto``, also ``auto`` (the full method at the weights chosen from each
    profile's observations by :func:`auto_weights`: ``alpha``, ``beta`` ``(len(values),)``,
    ``mse`` ``(len(values), seeds)``) and ``best_fixed`` (the pair of
    :data:`FIXED_ALPHAS` x :data:`FIXED_BETAS` with the lowest mean MSE for that profile,
    found with knowledge of the truth: ``alpha``, ``beta``, ``mse`` ``(len(values),)``),
    on the same noise realizations.

    Parameters
    ----------
    setup : StudySetup
        The band matrix (:func:`study_setup`).

    provider : callable
        ``profile(sigma_s, sigma_a, g)`` (1/mm) over ``setup.offsets``.
    name : {"sigma_s", "sigma_a", "g"}
        The parameter swept.
    values : array_like
        Its values.
    seeds : int
        Realizations per value.
    noise : float
        Image noise, normalized units.
    progress : callable, optional
        ``progress(1)`` after each value.
    auto : bool
        Also the automatic weights and the best fixed pair.
    **params
        The other parameters.

    Returns
    -------
    dict
        ``mse[method]`` (len(values), seeds), and with ``auto`` ``auto`` and ``best_fixed``.

    See Also
    --------
    regularization_sweep : over the weights.

    Examples
    --------
    >>> from planeray.timing import quick_sweep
    >>> setup = study_setup(quick_sweep())
    >>> out = parameter_sweep(setup, dipole_provider(setup.offsets), "sigma_a", [0.0, 0.1], seeds=2)
    >>> out["mse"]["full"].shape
    (2, 2)
    """
    if name not in DEFAULT_PARAMS:
        raise ValueError(f"unknown parameter {name!r}")
    mse = {m: np.zeros((len(values), seeds)) for m in METHODS}
    width = np.zeros(len(values))
    n = len(values)
    chosen = {"alpha": np.zeros(n), "beta": np.zeros(n), "mse": np.zeros((n, seeds))}
    fixed = {"alpha": np.zeros(n), "beta": np.zeros(n), "mse": np.zeros(n)}
    for i, v in enumerate(values):
        p = {**DEFAULT_PARAMS, **params, name: float(v)}
        T = _truth(setup, provider, p["sigma_s"], p["sigma_a"], p["g"])
        width[i] = np.sum(T * np.abs(setup.offsets)) / np.sum(T)  # mean |u| of the profile (rows)
        r = mse_trials(setup, T, noise, seeds, point=i)
        for m in METHODS:
            mse[m][i] = r[m]
        if auto:
            (chosen["alpha"][i], chosen["beta"][i], chosen["mse"][i]), best = _auto_vs_fixed(setup, T, noise, seeds, i)
            fixed["mse"][i], fixed["alpha"][i], fixed["beta"][i] = best
        if progress is not None:
            progress(1)
    out = {"name": name, "values": np.asarray(values, float), "mse": mse, "mean_abs_offset": width}
    if auto:
        out |= {"auto": chosen, "best_fixed": fixed}
    return out


def regularization_sweep(
    setup: StudySetup, provider: Provider, alphas, betas, seeds=5, noise=DEFAULT_NOISE, *, progress=None, **params
) -> dict:
    """MSE, squared bias and variance of the full method over an ``alpha x beta`` grid.

    Returns ``mse``, ``bias2`` (mean over offsets of the squared mean error over
    seeds) and ``variance`` (``mse - bias2``), each ``(len(alphas), len(betas))``;
    the same noise realizations are used at every grid point.  ``progress(1)``
    after each grid point.

    Parameters
    ----------
    setup : StudySetup
        The band matrix (:func:`study_setup`).

    provider : callable
        ``profile(sigma_s, sigma_a, g)`` (1/mm) over ``setup.offsets``.
    alphas, betas : array_like
        The grid of weights.
    seeds : int
        Realizations.
    noise : float
        Image noise, normalized units.
    progress : callable, optional
        ``progress(1)`` after each grid point.
    **params
        ``sigma_s``, ``sigma_a``, ``g`` (1/mm).

    Returns
    -------
    dict
        ``mse``, ``bias2`` and ``variance``, each (len(alphas), len(betas)).

    See Also
    --------
    auto_weights : the weights chosen from the data.

    Examples
    --------
    >>> from planeray.timing import quick_sweep
    >>> setup = study_setup(quick_sweep())
    >>> out = regularization_sweep(setup, dipole_provider(setup.offsets), [0.01, 0.1], [0.01], seeds=2)
    >>> out["mse"].shape, out["variance"].shape
    ((2, 1), (2, 1))
    """
    p = {**DEFAULT_PARAMS, **params}
    T = _truth(setup, provider, p["sigma_s"], p["sigma_a"], p["g"])
    B = _observations(setup, T, noise, seeds)
    shape = (len(alphas), len(betas))
    mse, bias2 = np.zeros(shape), np.zeros(shape)
    for i, a in enumerate(alphas):
        for j, b in enumerate(betas):
            X = solve_fast(setup.group, B, float(a), float(b)).X
            err = X - T[None]
            mse[i, j] = (err**2).mean()
            bias2[i, j] = (err.mean(axis=0) ** 2).mean()
            if progress is not None:
                progress(1)
    return {
        "alphas": np.asarray(alphas, float),
        "betas": np.asarray(betas, float),
        "mse": mse,
        "bias2": bias2,
        "variance": mse - bias2,
    }


def grids(quick: bool = False) -> dict:
    """The swept values (full, or reduced for tests).

    Parameters
    ----------
    quick : bool
        The reduced grids of the tests and ``--quick``.

    Returns
    -------
    dict of str to ndarray
        ``noise``, ``sigma_s``, ``sigma_a``, ``g``, ``alpha``, ``beta``.

    See Also
    --------
    noise_sweep, parameter_sweep, regularization_sweep : sweep them.

    Examples
    --------
    >>> sorted(grids(quick=True))
    ['alpha', 'beta', 'g', 'noise', 'sigma_a', 'sigma_s']
    """
    if quick:
        return {
            "noise": np.array([0.005, 0.05, 0.3]),
            "sigma_s": np.array([0.5, 2.0]),
            "sigma_a": np.array([0.0, 0.1]),
            "g": np.array([-0.5, 0.0, 0.9]),
            "alpha": np.array([1e-3, 1e-2, 1e-1]),
            "beta": np.array([1e-3, 1e-2, 1e-1]),
        }
    return {
        "noise": np.geomspace(1e-3, 0.3, 11),
        "sigma_s": np.geomspace(0.25, 8.0, 11),
        "sigma_a": np.array([0.0, 0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0]),
        "g": np.round(np.arange(-0.9, 0.91, 0.15), 2),
        "alpha": np.geomspace(1e-4, 1e4, 17),
        "beta": np.geomspace(1e-4, 100.0, 13),
    }

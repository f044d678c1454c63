"""Choosing the images: greedy selection, full coverage of the support, then exchanges.

:func:`design_sweep` picks ``n_images`` of the candidate settings
(:func:`~planeray.design.candidates.candidate_settings`) minimizing the criterion
(:class:`~planeray.design.criterion.ExpectedError`):

1. **Greedy**: the candidate that lowers the criterion most, one image at a time (every
   candidate's change in one matrix product).
2. **Coverage**: every offset of the support must be seen by some image (its band lighting at
   least half the bin), or the demultiplexer has nothing but the regularization there (and refuses a
   sweep that leaves an offset inside its support unlit).  While offsets are unseen, the image whose
   removal unsees nothing is exchanged for the candidate that sees the most of them, the pair
   chosen by the criterion; a number of images that cannot cover the support is refused.
3. **Exchanges** (Fedorov's, one image at a time): each image in turn is taken out and the best
   candidate that keeps the support covered put in its place, while the criterion falls by more
   than 0.1 % a pass.

Greedy selection and exchange were measured against a convex relaxation and against the
Bayesian criteria on simulated stacks (see the demultiplexing guide); the whole design is a
function of its inputs (no randomness but the prior's seeded pixels), so the same inputs give the
same sweep.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..demux.fast import blas_one_thread, solver_threads
from ..errors import InputError
from ..timing import Sweep, paper_sweep
from .camera import DesignCamera
from .candidates import DEFAULT_EXPOSURE_RANGE_US, Candidates, band_rows, candidate_settings
from .criterion import CRITERIA, ExpectedError
from .prior import TransportPrior, transport_prior

__all__ = ["SweepDesign", "design_sweep", "expected_error", "image_variance", "MAX_PASSES", "MIN_IMAGES"]

#: Most exchange passes (each tries every image once).
MAX_PASSES = 10
#: A pass that lowers the criterion by less than this fraction is the last.
PASS_GAIN = 1e-3
#: Fewest images a design may have (the demultiplexer needs at least 4).
MIN_IMAGES = 4


@dataclass(frozen=True)
class SweepDesign:
    """A designed sweep and how it was chosen.

    Attributes
    ----------
    sweep : Sweep
        The images, exposure-major (its ``record`` is :attr:`record`).
    expected_error : float
        The expected relative transport error ``sqrt(E / E||x||^2)`` of the criterion ``mse``
        (NaN for the Bayesian criteria).
    criterion_value : float
        The criterion's value.
    history : list of float
        The criterion after the greedy phase, the coverage repair and each exchange pass.
    seconds : float
    record : dict
        What the sweep file records (``record``): prior, camera, criterion, candidates, seed.

    See Also
    --------
    design_sweep : returns it.

    Examples
    --------
    >>> from planeray.design import transport_prior
    >>> prior = transport_prior(["diffuse_plane"], shape=(32, 32), projector_rows=180, support_rows=20, pixels=50)
    >>> d = design_sweep(4, prior=prior)
    >>> type(d).__name__, len(d.sweep), d.expected_error > 0
    ('SweepDesign', 4, True)
    """

    sweep: Sweep
    expected_error: float
    criterion_value: float
    history: list
    seconds: float
    record: dict


def image_variance(rows, exposure_us, prior: TransportPrior, camera: DesignCamera) -> np.ndarray:
    """The noise variance of images with illumination ``rows`` at the prior's mean transport (normalized units).

    Parameters
    ----------
    rows : ndarray (C, U)
        Rows of the illumination matrix.
    exposure_us : array_like (C,)
        Their exposures, microseconds.
    prior : TransportPrior
        Gives the mean transport.
    camera : DesignCamera
        The noise model.

    Returns
    -------
    ndarray (C,)
        Variances in normalized image units squared.

    See Also
    --------
    planeray.CameraModel : its noise model.

    Examples
    --------
    >>> from planeray.design import transport_prior
    >>> prior = transport_prior(["diffuse_plane"], shape=(32, 32), projector_rows=180, support_rows=20, pixels=50)
    >>> from planeray.design import candidate_settings
    >>> cands = candidate_settings(support_rows=20, exposure_range_us=(300, 600))
    >>> from planeray.design import DesignCamera
    >>> variance = image_variance(cands.rows, cands.exposure_us, prior, DesignCamera())
    >>> variance.shape == (len(cands),), bool((variance > 0).all())
    (True, True)
    """
    model = camera.model
    signal = (np.asarray(rows) @ prior.mean) / model.signal_scale  # the mean in transport units (Eq. 4)
    return model.image_variance(signal, np.asarray(exposure_us, np.float64), ambient_albedo=prior.ambient_albedo)


def _covered(lit, chosen) -> np.ndarray:
    return lit[list(chosen)].any(axis=0) if len(chosen) else np.zeros(lit.shape[1], bool)


def _select(crit: ExpectedError, lit: np.ndarray, n: int, max_passes: int, progress=None):
    """Greedy, coverage repair, exchanges; returns the chosen indices and the history of values."""
    need = lit.any(axis=0)
    chosen: list[int] = []
    for _ in range(n):
        chosen.append(int(np.argmin(crit.deltas(chosen))))
        if progress is not None:
            progress(1)
    history = [crit.value(chosen)]
    # every offset seen
    while (need & ~_covered(lit, chosen)).any():
        holes = need & ~_covered(lit, chosen)
        gain = lit[:, holes].sum(axis=1).astype(float)
        gain[chosen] = -1.0
        top = np.flatnonzero(gain >= gain.max())
        best = None
        for j in chosen:
            rest = [c for c in chosen if c != j]
            if (need & ~_covered(lit, rest) & ~holes).any():
                continue  # taking j out would unsee an offset
            d = crit.deltas(rest)
            c = int(top[np.argmin(d[top])])
            total = crit.value(rest) + float(d[c])
            if best is None or total < best[0]:
                best = (total, j, c)
        if best is None:
            raise InputError(
                f"{n} images cannot see every offset of the support: give more images, wider exposures or a "
                "smaller support"
            )
        _, j, c = best
        chosen = [x for x in chosen if x != j] + [c]
    value = crit.value(chosen)
    history.append(value)
    # exchanges that keep every offset seen
    for _ in range(max_passes):
        start = value
        for j in list(chosen):
            rest = [c for c in chosen if c != j]
            missing = need & ~_covered(lit, rest)
            d = crit.deltas(rest)
            if missing.any():
                d[~lit[:, missing].all(axis=1)] = np.inf
            c = int(np.argmin(d))
            if c != j:
                new = crit.value(rest + [c])
                if new < value * (1.0 - 1e-12) if value > 0 else new < value:
                    chosen, value = rest + [c], new
        history.append(value)
        if progress is not None:
            progress(0)
        if not start - value > PASS_GAIN * abs(start):
            break
    return chosen, history


def design_sweep(
    n_images: int,
    *,
    prior: TransportPrior | None = None,
    camera: DesignCamera | None = None,
    candidates: Candidates | None = None,
    criterion: str = "mse",
    alpha: float = 0.01,
    beta: float = 0.01,
    max_passes: int = MAX_PASSES,
    name: str | None = None,
    progress: Callable[[int], None] | None = None,
) -> SweepDesign:
    """Choose ``n_images`` delay-exposure settings that demultiplex the prior's transports best.

    Parameters
    ----------
    n_images : int
        Images of the sweep (at least 4).
    prior : TransportPrior, optional
        What the scenes' transports are like (:func:`~planeray.design.prior.transport_prior`;
        default: every built-in scene with a little of the smoothness prior, seed 0).
    camera : DesignCamera, optional
        Noise model, frames per image, scanline velocity, range and steps (default: the
        simulated Episcan's camera).
    candidates : Candidates, optional
        The settings to choose from (default: :func:`~planeray.design.candidates.candidate_settings`
        of the camera over the prior's support).
    criterion : {"mse", "bayes-a", "bayes-d"}
        What is minimized (:data:`~planeray.design.criterion.CRITERIA`; ``mse``: the expected
        transport error of the regularized problem).
    alpha, beta : float
        The demultiplexing weights the sweep is for (``beta`` is recorded; the criterion's linear
        estimator has no sparsity term).
    max_passes : int
        Most exchange passes.
    name : str, optional
        The sweep's name (default ``design-N``).
    progress : callable, optional
        Called with 1 after each greedy image and 0 after each exchange pass.

    Returns
    -------
    SweepDesign

    See Also
    --------
    transport_prior : the prior.
    planeray.io.write_sweep : store the result as a sweep file.

    Examples
    --------
    >>> from planeray.design import transport_prior
    >>> prior = transport_prior(["wax"], shape=(32, 32), projector_rows=180, support_rows=30, pixels=200)
    >>> d = design_sweep(6, prior=prior)
    >>> len(d.sweep), bool(d.sweep.excluded.any()), d.expected_error < 1
    (6, False, True)
    """
    from ..io import planeray_version

    t0 = time.perf_counter()
    n = int(n_images)
    if isinstance(n_images, bool) or n != n_images or n < MIN_IMAGES:
        raise InputError(f"a design needs at least {MIN_IMAGES} images, got {n_images!r}")
    if criterion not in CRITERIA:
        raise InputError(f"unknown criterion {criterion!r}; choose one of {', '.join(CRITERIA)}")
    if not (np.isfinite(alpha) and alpha > 0):
        raise InputError(f"alpha must be a positive number, got {alpha!r}")
    camera = camera or DesignCamera()
    prior = prior or transport_prior(signal_scale=camera.model.signal_scale)
    K = int(np.abs(prior.offsets_rows).max())
    if candidates is None:
        candidates = candidate_settings(camera, support_rows=K, exposure_range_us=DEFAULT_EXPOSURE_RANGE_US)
    if not np.array_equal(candidates.offsets_rows, prior.offsets_rows):
        raise InputError(
            f"the candidates' support (+-{int(np.abs(candidates.offsets_rows).max())} rows) is not the prior's "
            f"(+-{K} rows)"
        )
    if n > len(candidates):
        raise InputError(f"{n} images asked for, but only {len(candidates)} candidate settings")
    var = image_variance(candidates.rows, candidates.exposure_us, prior, camera)
    with blas_one_thread():
        crit = ExpectedError(
            candidates.rows, var, prior.second_moment, alpha=alpha, criterion=criterion, threads=solver_threads()
        )
        try:
            chosen, history = _select(crit, candidates.lit, n, int(max_passes), progress)
        finally:
            crit.close()
    chosen = np.asarray(chosen)
    d, e = candidates.delay_us[chosen], candidates.exposure_us[chosen]
    order = np.lexsort((d, e))
    value = history[-1]
    paper = expected_error(paper_sweep(), prior=prior, camera=camera, alpha=alpha, criterion=criterion)
    seconds = time.perf_counter() - t0
    record = {
        "kind": "design",
        "planeray_version": planeray_version(),
        "images": n,
        "criterion": {
            "name": criterion,
            "description": CRITERIA[criterion],
            "alpha": float(alpha),
            "beta": float(beta),
            "value": value,
            "expected_relative_error": crit.relative(value),
            "paper_sweep_expected_relative_error": paper if criterion == "mse" else None,
        },
        "method": {
            "name": "greedy, coverage repair, exchanges",
            "history": [float(h) for h in history],
            "passes": len(history) - 2,
        },
        "prior": prior.description,
        "camera": camera.to_dict(),
        "candidates": candidates.description,
        "seed": int(prior.description.get("seed", 0)),
        "seconds": round(seconds, 2),
    }
    sweep = Sweep(d[order], e[order], np.zeros(n, bool), name=name or f"design-{n}", record=record)
    return SweepDesign(sweep, crit.relative(value), value, [float(h) for h in history], seconds, record)


def expected_error(
    sweep: Sweep,
    *,
    prior: TransportPrior,
    camera: DesignCamera | None = None,
    alpha: float = 0.01,
    criterion: str = "mse",
) -> float:
    """The criterion of any sweep (its used images) for a prior and camera: for ``mse`` the expected
    relative transport error ``sqrt(E / E||x||^2)``, for the Bayesian criteria their value.

    Bands beyond the prior's support are cut to it (that light is not in the prior).

    Parameters
    ----------
    sweep : Sweep
        Any sweep (its used images count).
    prior : TransportPrior
        The transports to expect.
    camera : DesignCamera, optional
        The camera's noise and timing (default: the simulated Episcan's).
    alpha : float
        The smoothness weight of the demultiplexing.
    criterion : {"mse", "bayes-a", "bayes-d"}

    Returns
    -------
    float

    See Also
    --------
    design_sweep : a sweep that minimizes it.

    Examples
    --------
    >>> from planeray.design import transport_prior
    >>> prior = transport_prior(["diffuse_plane"], shape=(32, 32), projector_rows=180, support_rows=20, pixels=50)
    >>> from planeray.timing import quick_sweep
    >>> 0 < expected_error(quick_sweep(), prior=prior) < 1  # relative transport error of the quick sweep
    True
    """
    camera = camera or DesignCamera()
    used = ~sweep.excluded
    rows = band_rows(
        sweep.delay_us[used],
        sweep.exposure_us[used],
        prior.offsets_rows,
        lines_per_second=camera.lines_per_second,
        jitter_us=camera.model.jitter_us,
    )
    var = image_variance(rows, sweep.exposure_us[used], prior, camera)
    crit = ExpectedError(rows, var, prior.second_moment, alpha=alpha, criterion=criterion)
    with blas_one_thread():
        value = crit.value(range(rows.shape[0]))
    return crit.relative(value) if criterion == "mse" else value

"""Regularization weights chosen by the data: generalized cross-validation of the noise-weighted fit.

The weights ``alpha`` (smoothness) and ``beta`` (sparsity) of the Sec. 4 problem
(:mod:`planeray.demux.problem`) decide the recovered transport, and no pair serves
every scene (the paper's 0.01 / 0.01 is ~24x worse than alpha ~ 300 on smooth
subsurface profiles, and alpha ~ 300 is 4x worse than 0.01 on mirrors).  Every image of a
stack is a measurement the transport must predict; the default criterion scores
each pair of weights by **generalized cross-validation** of every sampled pixel's fit,

.. math::

    \\mathrm{GCV}(\\alpha, \\beta) = \\frac{1}{P} \\sum_p
        \\frac{n_p \\sum_i w_{p,i} (I_{p,i} - A_i \\hat T_p - \\hat a_p I_{w,i})^2}{(n_p - \\mathrm{df}_p)^2},
    \\qquad w = 1 / \\sigma^2,

``sigma^2`` the variance of an observation under the stack's camera model (shot noise of its
signal plus read and quantization noise, averaged frames; equal weights for a stack without
one), ``n_p`` the pixel's usable observations (saturated ones are neither fitted nor scored),
``a`` its ambient when it is estimated (Eq. 6a of :mod:`planeray.demux.problem`, the default of
an automatic run) and ``df_p`` the degrees of freedom of its fit -- the trace of the influence
matrix on its free unknowns (:mod:`planeray.demux.risk`).  GCV estimates the error of predicting
a new image at the same settings with the noise *level* taken from the residuals: the camera
model gives the observations' relative noise, but not the row jitter and other unmodelled noise
that scale it by 1.5-4x.  ``"sure"`` (Stein's unbiased risk estimate at the camera model's
level) and ``"cv-images"`` (K-fold cross-validation over images, the earlier criterion) remain
as options; all three were measured on 46 transports nobody tuned them on (the demultiplexing
guide), where K-fold CV chose too much smoothing on mirrors (a fold left out makes the
underdetermined problem more so) and SURE too little on wax (the unmodelled noise).  Among the
pairs whose score lies within one standard error of their paired difference (over pixels) to the
lowest score, the one nearest the paper's 0.01 / 0.01 is chosen (:func:`summarize`); that range
is how sure the choice is.

Accuracy.  Every solve behind the curve is certified to the plain demultiplexer's relative
objective gap (1e-4; the worst is recorded): at a looser 1e-3 the curves at small ``alpha``
measured where ADMM stopped rather than the weights (``tests/test_demux_risk.py``).

Search.  The score is evaluated on a sample of the stack's pixels (2 %, at least 256 and at
most 4096, spread over the camera rows of the largest row groups, so that a few illumination
matrices serve them all); each pair's factorization is shared by the sampled pixels of its row
group.  ``alpha`` is scanned on a log grid (half decades, 1e-3 ... 1e4) at the current
``beta``, then ``beta`` (1e-4 ... 10) at the best ``alpha``, then ``alpha`` again around its best
at the chosen ``beta``; a scan stops when the score has risen for two grid points in a row above
the best plus two standard errors.  While the best pair lies on an end of what was tried, the
search goes on past it in half-decade steps, up to ``alpha`` 1e-5 ... 1e6 and ``beta``
1e-6 ... 100; a best still on an end there is recorded (:attr:`WeightChoice.edge`) and said.
"""

from __future__ import annotations

import threading
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError, PlanerayError
from ..stack import Stack
from .fast import DEFAULT_TOL, AdmmRowSolver, blas_one_thread, solver_threads
from .problem import AMBIENT_MODES, DemuxProblem, read_observations
from .risk import pixel_scores

__all__ = [
    "AUTO",
    "WeightChoice",
    "choose_weights",
    "cv_score",
    "risk_score",
    "edges",
    "CRITERIA",
    "observation_variance",
    "is_auto",
    "DEFAULT_ALPHAS",
    "DEFAULT_BETAS",
    "search",
    "summarize",
    "resolve_ambient",
]

#: The value of ``alpha``/``beta`` that asks for the data's choice.
AUTO = "auto"
#: Log grids of the scans (half decades).
DEFAULT_ALPHAS = tuple(float(10.0**e) for e in np.arange(-3.0, 4.01, 0.5))
DEFAULT_BETAS = tuple(float(10.0**e) for e in np.arange(-4.0, 1.01, 0.5))
#: Folds of images.
DEFAULT_FOLDS = 5
#: Pixels scored: this fraction of the image, within [MIN_PIXELS, MAX_PIXELS].
SAMPLE_FRACTION = 0.02
MIN_PIXELS = 256
MAX_PIXELS = 4096
#: Most row groups the sample is drawn from (the largest first, only as many as the sample needs:
#: each costs its own factorizations).
MAX_GROUPS = 8
#: Certified relative gap of the criterion's solves: the plain demultiplexer's (every solve behind the
#: curve reaches the accuracy of the final one; a looser 1e-3 let early stopping shape CV's curve).
CRITERION_TOL = DEFAULT_TOL
CV_TOL = CRITERION_TOL
#: Weight of the paper (the start of a scan when the other weight is automatic).
PAPER_WEIGHT = 0.01
#: The criteria: generalized cross-validation (noise-weighted; the default), Stein's unbiased risk
#: estimate with the camera's noise level, K-fold cross-validation over images (the earlier criterion).
CV_CRITERION = "cv-images"
CRITERIA = ("gcv", "sure", CV_CRITERION)
DEFAULT_CRITERION = "gcv"
CRITERION = DEFAULT_CRITERION
#: Observations weighted by their camera-noise variance ("noise") or alike ("equal").
DEFAULT_WEIGHTING = "noise"


def is_auto(value) -> bool:
    """Whether a weight asks for the automatic choice (the string ``"auto"``, any case)."""
    return isinstance(value, str) and value.strip().lower() == AUTO


def resolve_ambient(ambient, alpha="auto", beta="auto") -> str:
    """The ambient mode of a run: ``"none"`` (the paper's problem) or ``"estimate"`` (Eq. 6a).

    ``None`` is the default: ``"estimate"`` when a weight is ``"auto"`` (the data choose
    the weights; the ambient light is then modelled instead of kept in ``T`` as a flat
    floor that every image predicts) and ``beta`` is not an explicit 0 (which cannot
    split a flat transport from the ambient), otherwise ``"none"``, so that explicit
    weights mean exactly the paper's problem.

    Raises
    ------
    InputError
        Anything but None, ``"none"`` or ``"estimate"``.
    """
    if ambient is None:
        beta_zero = not is_auto(beta) and _is_zero(beta)
        return "estimate" if (is_auto(alpha) or is_auto(beta)) and not beta_zero else "none"
    if isinstance(ambient, str) and ambient.strip().lower() in AMBIENT_MODES:
        return ambient.strip().lower()
    raise InputError(f"ambient must be one of {', '.join(AMBIENT_MODES)}, got {ambient!r}")


def _is_zero(value) -> bool:
    try:
        return float(value) == 0.0
    except (TypeError, ValueError):
        return False


def _weight(value, name: str) -> float:
    if isinstance(value, str):
        try:
            value = float(value)
        except ValueError:
            raise InputError(f"{name} must be a non-negative number or 'auto', got {value!r}") from None
    return value


@dataclass
class WeightChoice:
    """The weights chosen by cross-validation and the curve they were chosen from.

    Attributes
    ----------
    alpha, beta : float
        The chosen weights.
    requested : dict
        ``{"alpha": "auto" or number, "beta": ...}`` as asked.
    criterion : str
        ``"gcv"``, ``"sure"`` or ``"cv-images"`` (:func:`choose_weights`).
    weighting : str
        ``"camera-noise"`` (observations weighted by their variance under the stack's
        camera model) or ``"equal"`` (no camera model in the stack's metadata).
    folds, n_pixels : int
        Folds of images; pixels scored.
    rows : list of int
        Camera rows the sampled pixels lie on.
    alphas, betas, scores, score_se : ndarray
        Every pair tried, in order, with its score (mean noise-weighted squared
        prediction error of left-out observations; 1 is the noise level) and the
        score's standard error over pixels.
    alpha_range, beta_range : tuple of float
        Smallest and largest tried weight (the other at its chosen value) whose score
        exceeds the best by at most one standard error of the paired difference over
        pixels: how sure the choice is.
    ambient : str
        ``"estimate"`` (each pixel's ambient is an unknown of the solves, Eq. 6a, and part
        of every prediction) or ``"none"`` (the paper's problem).
    edge : dict
        ``{name: "low" or "high"}`` for each automatic weight whose best value is the
        smallest or largest the search could try (the grid was extended to its limit first,
        :data:`ALPHA_LIMITS`, :data:`BETA_LIMITS`): the best may lie beyond it.  Empty when
        every automatic weight has a worse value on both sides.
    worst_gap : float
        The largest certified relative objective gap of all the solves behind the curve
        (each at most the solves' tolerance where all converged).
    lowest : tuple of float
        The pair with the lowest score; the chosen pair is the one nearest the paper's 0.01 /
        0.01 among those within one standard error of it (:func:`summarize`).

    See Also
    --------
    choose_weights : returns it.

    Examples
    --------
    >>> import planeray as pr
    >>> stack = pr.simulate_stack(pr.make_scene("wax", (8, 8), seed=0), pr.quick_sweep(), seed=0)
    >>> choice = choose_weights(stack)
    >>> type(choice).__name__, choice.criterion, choice.alpha > 0
    ('WeightChoice', 'gcv', True)
    """

    alpha: float
    beta: float
    requested: dict
    criterion: str = CRITERION
    weighting: str = "equal"
    folds: int = DEFAULT_FOLDS
    n_pixels: int = 0
    rows: list = field(default_factory=list)
    alphas: np.ndarray = field(default_factory=lambda: np.zeros(0))
    betas: np.ndarray = field(default_factory=lambda: np.zeros(0))
    scores: np.ndarray = field(default_factory=lambda: np.zeros(0))
    score_se: np.ndarray = field(default_factory=lambda: np.zeros(0))
    alpha_range: tuple = (0.0, 0.0)
    beta_range: tuple = (0.0, 0.0)
    ambient: str = "none"
    edge: dict = field(default_factory=dict)
    worst_gap: float = 0.0
    lowest: tuple = (0.0, 0.0)
    #: (P, 2) camera (row, column) of the scored pixels, in the order of the scores (not stored)
    pixels: np.ndarray | None = None

    def to_attrs(self) -> dict:
        """JSON-serializable record (the transport store's ``weights_choice`` attribute)."""
        return {
            "alpha": float(self.alpha),
            "beta": float(self.beta),
            "requested": dict(self.requested),
            "criterion": self.criterion,
            "weighting": self.weighting,
            "folds": int(self.folds),
            "n_pixels": int(self.n_pixels),
            "rows": [int(r) for r in self.rows],
            "curve": {
                "alpha": [float(a) for a in self.alphas],
                "beta": [float(b) for b in self.betas],
                "score": [float(s) for s in self.scores],
                "score_se": [float(s) for s in self.score_se],
            },
            "alpha_range": [float(v) for v in self.alpha_range],
            "beta_range": [float(v) for v in self.beta_range],
            "ambient": self.ambient,
            "edge": dict(self.edge),
            "worst_gap": float(self.worst_gap),
            "lowest": [float(v) for v in self.lowest],
        }

    @classmethod
    def from_attrs(cls, d: dict) -> WeightChoice:
        """The choice recorded by :meth:`to_attrs`."""
        c = d["curve"]
        return cls(
            alpha=float(d["alpha"]),
            beta=float(d["beta"]),
            requested=dict(d["requested"]),
            criterion=d["criterion"],
            weighting=d["weighting"],
            folds=int(d["folds"]),
            n_pixels=int(d["n_pixels"]),
            rows=list(d["rows"]),
            alphas=np.asarray(c["alpha"], float),
            betas=np.asarray(c["beta"], float),
            scores=np.asarray(c["score"], float),
            score_se=np.asarray(c["score_se"], float),
            alpha_range=tuple(d["alpha_range"]),
            beta_range=tuple(d["beta_range"]),
            ambient=d.get("ambient", "none"),
            edge=dict(d.get("edge", {})),
            worst_gap=float(d.get("worst_gap", 0.0)),
            lowest=tuple(d.get("lowest", (d["alpha"], d["beta"]))),
        )

    def summary(self) -> str:
        """One line: the chosen weights and how sure the choice is."""
        parts = []
        for name in ("alpha", "beta"):
            value = getattr(self, name)
            if is_auto(self.requested.get(name)):
                lo, hi = getattr(self, f"{name}_range")
                parts.append(f"{name} = {value:.3g} (auto; {lo:.3g}-{hi:.3g} within 1 SE)")
            else:
                parts.append(f"{name} = {value:.3g}")
        amb = "; ambient light estimated per pixel" if self.ambient == "estimate" else ""
        return (
            f"weights: {', '.join(parts)}; {self.criterion_label()} "
            f"({self.weighting} weighting, {self.n_pixels} pixels, {len(self.scores)} pairs tried){amb}"
        )

    def criterion_label(self) -> str:
        """The criterion in words."""
        if self.criterion == CV_CRITERION:
            return f"{self.folds}-fold cross-validation over images"
        if self.criterion == "gcv":
            return "generalized cross-validation"
        return "Stein's unbiased risk estimate"

    def edge_warning(self) -> str | None:
        """One line when the best of an automatic weight lies on an end of the search (None otherwise)."""
        if not self.edge:
            return None
        parts = []
        for name, side in self.edge.items():
            tried = self.alphas if name == "alpha" else self.betas
            value = getattr(self, name)
            bound = "smallest" if side == "low" else "largest"
            where = "below" if side == "low" else "above"
            parts.append(
                f"{name} = {value:.3g} is the {bound} value the search tried ({tried.min():.3g}-{tried.max():.3g}): "
                f"its best may lie {where} it"
            )
        return "warning: " + "; ".join(parts) + " (the store's weights_choice.edge says so)"


def observation_variance(stack: Stack, B) -> np.ndarray | None:
    """Variance of normalized observations ``B`` under the stack's camera model (None: no model).

    A normalized value ``b`` holds ``b * full_well_e`` electrons per frame (signal plus
    ambient); its average over ``n`` frames has the variance
    ``(e + read_noise^2 + 1 / (12 gain^2)) / (n full_well^2)`` (shot noise, read noise,
    the ADC's rounding), see :class:`planeray.camera.CameraModel`.
    """
    cam = stack.metadata.get("camera") if isinstance(stack.metadata, dict) else None
    if not isinstance(cam, dict):
        return None
    try:
        from ..camera import CameraModel

        model = CameraModel(**{k: v for k, v in cam.items() if k in CameraModel.__dataclass_fields__})
    except (ValueError, TypeError, PlanerayError):  # an invalid record: equal weights
        return None
    fw = model.full_well_e
    e = np.maximum(np.asarray(B, np.float64), 0.0) * fw
    g = model.gain_adu_per_e
    return (e + model.read_noise_e**2 + 1.0 / (12.0 * g * g)) / (model.frames_averaged * fw * fw)


# ------------------------------------------------------------------ the sample
@dataclass
class _Sample:
    """Pixels scored by the criterion, grouped by row group."""

    groups: list  # RowGroup per part
    B: list  # (P_g, N) observations
    mask: list  # (P_g, N) bool usable or None
    weight: list  # (P_g, N) 1/variance
    rows: list
    n_pixels: int
    weighting: str = "equal"
    pixels: list = field(default_factory=list)  # (P_g, 2) camera (row, column) per part


def _sample(
    stack: Stack, problem: DemuxProblem, *, seed: int, n_pixels: int | None, weighting: str = "noise"
) -> _Sample:
    H, W = stack.shape
    target = n_pixels or int(np.clip(round(SAMPLE_FRACTION * H * W), MIN_PIXELS, MAX_PIXELS))
    target = min(target, H * W)
    sizes = np.bincount(problem.row_group, minlength=len(problem.groups))
    order = np.argsort(-sizes, kind="stable")
    rng = np.random.default_rng(seed)
    chosen, rows_total = [], 0
    for g in order[:MAX_GROUPS]:
        if problem.groups[g].A.shape[1] == 0:
            continue
        chosen.append(int(g))
        rows_total += sizes[g]
        if rows_total * W >= target:
            break
    if not chosen:
        raise InputError("no camera row has an offset on the projector: nothing to demultiplex")
    cand = np.sort(np.concatenate([np.flatnonzero(problem.row_group == g) for g in chosen]))
    n_rows = int(min(cand.size, max(4, min(64, -(-target // W) * 4))))
    rows = cand[np.unique(np.round(np.linspace(0, cand.size - 1, n_rows)).astype(int))]
    per_row = int(min(W, -(-target // rows.size)))
    parts = _Sample([], [], [], [], [int(r) for r in rows], 0)
    imgs_all, sat_all, cols_all = {}, {}, {}
    # rows read a stored block at a time (a lazily read stack decodes each of its chunks once)
    chunks = getattr(stack.images, "chunks", None)
    block = int(chunks[1]) if chunks is not None and len(chunks) == 3 else 1
    for b in np.unique(rows // block):
        lo, hi = int(b * block), int(min(H, (b + 1) * block))
        imgs, sat = read_observations(stack, problem, slice(lo, hi))
        for r in rows[(rows >= lo) & (rows < hi)]:
            cols = np.sort(rng.choice(W, per_row, replace=False))
            cols_all[int(r)] = cols
            imgs_all[int(r)] = imgs[:, r - lo, cols].T  # (P, N)
            sat_all[int(r)] = None if sat is None else sat[:, r - lo, cols].T
    for g in chosen:
        rs = [int(r) for r in rows if problem.row_group[r] == g]
        if not rs:
            continue
        B = np.concatenate([imgs_all[r] for r in rs])
        sats = [sat_all[r] if sat_all[r] is not None else np.zeros_like(imgs_all[r], bool) for r in rs]
        usable = ~np.concatenate(sats)
        var = observation_variance(stack, B) if weighting == "noise" else None
        w = np.ones_like(B) if var is None else 1.0 / var
        parts.groups.append(problem.groups[g])
        parts.B.append(B)
        parts.mask.append(None if usable.all() else usable)
        parts.weight.append(np.where(usable, w, 0.0))
        parts.pixels.append(np.concatenate([np.stack([np.full(cols_all[r].size, r), cols_all[r]], 1) for r in rs]))
        parts.n_pixels += B.shape[0]
    noise = weighting == "noise" and observation_variance(stack, np.zeros(1)) is not None
    parts.weighting = "camera-noise" if noise else "equal"
    return parts


def fold_indices(n_images: int, folds: int, seed: int) -> list[np.ndarray]:
    """Left-out image indices (into the used images) of each fold: a seeded, balanced split."""
    perm = np.random.default_rng(seed).permutation(n_images)
    return [np.sort(perm[k::folds]) for k in range(folds)]


def cv_score(
    groups,
    Bs,
    masks,
    weights,
    folds,
    alpha: float,
    beta: float,
    *,
    tol: float = CV_TOL,
    threads=None,
    ambient=None,
    record: dict | None = None,
):
    """Noise-weighted K-fold prediction error of every pixel at ``(alpha, beta)``.

    Parameters
    ----------
    groups : list of RowGroup
    Bs, masks, weights : list of ndarray (P_g, N)
        Observations, usable observations (None: all) and inverse variances, per group.
    folds : list of ndarray of int
        Left-out observations (columns of ``B``) of each fold.
    alpha, beta : float
    ambient : ndarray (N,), optional
        The ambient column ``I_w`` of Eq. 6a: each pixel's ambient is solved with its
        transport and the left-out images are predicted with it (``A T + a I_w``).
    record : dict, optional
        Updated with ``worst_gap``: the largest certified relative gap of these solves.

    Returns
    -------
    ndarray (P,)
        Per pixel: sum of ``w (b - A x^{(-F)})^2`` over its left-out observations
        divided by their number (1 at the noise level).
    """
    # each fold's pixels in as many parts as threads (5 folds on 2 threads would leave one idle
    # for a third of the time); a fold's factorization is made once and shared by its parts
    pool = _Tasks(Bs, threads)
    tasks = [(g, f, k) for k in range(pool.n_parts) for g in range(len(groups)) for f in range(len(folds))]

    def run(task):
        g, f, k = task
        group, B, mask, w = groups[g], Bs[g], masks[g], weights[g]
        test = folds[f]
        train = np.setdiff1d(np.arange(B.shape[1]), test)
        e = None if ambient is None else np.asarray(ambient, np.float64)[train]
        solver = pool.solver((g, f), lambda: AdmmRowSolver(group.A[train], alpha, beta, ambient=e))
        part = pool.part(B.shape[0], k)
        Bp = B[part]
        X, worst = _solve_part(solver, Bp[:, train], None if mask is None else mask[part][:, train], tol)
        # the prediction of the left-out images (with the ambient: its scaled column, the solver's a')
        A_test = group.A[test] if ambient is None else _test_columns(solver, group.A[test], np.asarray(ambient)[test])
        R = Bp[:, test] - X @ A_test.T
        wt = w[part][:, test]
        return (g, part), (wt * R * R).sum(axis=1), (wt > 0).sum(axis=1), worst

    ss = [np.zeros(B.shape[0]) for B in Bs]
    n = [np.zeros(B.shape[0]) for B in Bs]
    for (g, part), s_, n_, worst in pool.map(run, tasks):
        ss[g][part] += s_
        n[g][part] += n_
        _record(record, worst)
    out = [a / np.maximum(b, 1) for a, b in zip(ss, n)]
    return np.concatenate(out)


def risk_score(
    groups,
    Bs,
    masks,
    weights,
    alpha: float,
    beta: float,
    *,
    tol: float = DEFAULT_TOL,
    threads=None,
    ambient=None,
    gcv: bool = False,
    record: dict | None = None,
    warm: dict | None = None,
):
    """GCV or Stein's unbiased risk estimate (``C_p``) of every pixel at ``(alpha, beta)`` (:mod:`planeray.demux.risk`).

    One solve of each pixel on all its observations (the fast solver, certified to ``tol``: the
    plain demultiplexer's accuracy), then, with ``df`` the trace of the influence matrix on the
    pixel's free set, ``n sum w r^2 / (n - df)^2`` (``gcv``, the default criterion) or
    ``(sum w r^2 + 2 df) / n``.

    Parameters
    ----------
    groups : list of RowGroup
    Bs, masks, weights : list of ndarray (P_g, N)
        Observations, usable observations (None: all) and inverse variances, per group.
    alpha, beta : float
    ambient : ndarray (N,), optional
        The ambient column ``I_w`` of Eq. 6a (each pixel's ambient is an unknown of its solve).
    record : dict, optional
        Updated with ``worst_gap``: the largest certified relative gap of these solves.
    warm : dict, optional
        Warm starts across calls (the search's pairs, in order): the solves start from the
        solutions of the previous call with the same dict (1.5-2x fewer iterations between
        neighbouring pairs; each still certified to ``tol``).

    Returns
    -------
    ndarray (P,)
        Per pixel: the expected noise-weighted squared error of a new image at the same settings
        (1 at the camera model's noise level; GCV's noise level is the residuals').
    """
    pool = _Tasks(Bs, threads)
    tasks = [(g, k) for k in range(pool.n_parts) for g in range(len(groups))]

    def run(task):
        g, k = task
        B, mask, w = Bs[g], masks[g], weights[g]
        solver = pool.solver(g, lambda: AdmmRowSolver(groups[g].A, alpha, beta, ambient=ambient))
        part = pool.part(B.shape[0], k)
        mp = None if mask is None else mask[part]
        X0 = None if warm is None else warm.get((g, k))
        X, worst = _solve_part(solver, B[part], mp, tol, start=X0)
        if warm is not None:
            warm[(g, k)] = X
        return (g, part), pixel_scores(solver.A, X, B[part], w[part], alpha, solver.n_x, mask=mp, gcv=gcv), worst

    out = [np.zeros(B.shape[0]) for B in Bs]
    for (g, part), s_, worst in pool.map(run, tasks):
        out[g][part] = s_
        _record(record, worst)
    return np.concatenate(out)


class _Tasks:
    """The criterion's solves on the solver threads: each row group's pixels in as many parts as
    threads, one factorization per key shared by the parts (made by the first that needs it)."""

    def __init__(self, Bs, threads):
        self.n_threads = solver_threads() if threads is None else threads
        self.n_parts = self.n_threads if min(B.shape[0] for B in Bs) >= 64 * self.n_threads else 1
        self._solvers: dict = {}
        self._lock = threading.Lock()

    def solver(self, key, make):
        with self._lock:
            entry = self._solvers.setdefault(key, [threading.Lock(), None])
        with entry[0]:
            if entry[1] is None:
                entry[1] = make()
        return entry[1]

    def part(self, P: int, k: int) -> slice:
        return slice(k * P // self.n_parts, (k + 1) * P // self.n_parts)

    def map(self, run, tasks) -> list:
        with blas_one_thread():
            if self.n_threads > 1 and len(tasks) > 1:
                with ThreadPoolExecutor(self.n_threads) as pool:
                    return list(pool.map(run, tasks))
            return [run(t) for t in tasks]


def _solve_part(solver: AdmmRowSolver, B, mask, tol, *, start=None):
    """``X`` of pixels ``B`` (P, N) in batches of 512 and the worst certified relative gap."""
    X = np.zeros((B.shape[0], solver.A.shape[1]))
    worst = 0.0
    for s in range(0, B.shape[0], 512):
        sl = slice(s, min(s + 512, B.shape[0]))
        m = None if mask is None else mask[sl]
        if m is not None and m.all():
            m = None
        X[sl], _, _, gap, *_ = solver.solve(B[sl], tol, mask=m, start=None if start is None else start[sl])
        worst = max(worst, float(gap.max(initial=0.0)))
    return X, worst


def _record(record: dict | None, worst: float) -> None:
    if record is not None:
        record["worst_gap"] = max(record.get("worst_gap", 0.0), worst)


def _test_columns(solver: AdmmRowSolver, A_test, e_test) -> np.ndarray:
    """``[A, I_w / s]`` of left-out images in the solver's variables (``a' = s a``).

    Where the solver took the ambient column as ``A 1`` (bands inside the projector), so do
    the predictions.
    """
    e = A_test.sum(axis=1) if solver.null is not None else np.asarray(e_test, np.float64)
    return np.column_stack([A_test, e / solver.ambient_scale])


#: Pairs within this fraction of the lowest score (and one paired standard error of it) count as ties.
TIE_RELATIVE = 0.01
#: How far the search goes past the grid's ends when the best pair lies on one (half-decade steps):
#: alpha 1e-5 ... 1e6 (the command's largest weight), beta 1e-6 ... 100.
ALPHA_LIMITS = (1e-5, 1e6)
BETA_LIMITS = (1e-6, 100.0)
_STEP = float(np.sqrt(10.0))


def search(score, requested: dict, alphas, betas, *, limits=None) -> dict:
    """The coordinate search over the log grids: ``{(alpha, beta): per-pixel scores}`` of every pair tried.

    ``score(alpha, beta)`` returns the per-pixel scores (lower is better).  ``alpha`` is
    scanned (ascending) at ``beta`` (the paper's 0.01 when it is automatic too), then
    ``beta`` at the best ``alpha``, then ``alpha`` within two grid steps of its best at
    the chosen ``beta``; a scan stops once the mean score has risen twice in a row above
    the best plus two standard errors.  A weight that is not ``"auto"`` in ``requested``
    is held at its value.

    **The grid's ends are not a wall**: while the best pair's automatic weight is the
    smallest (largest) value tried at the other weight, the search goes on past it in
    half-decade steps until a point scores worse or the weight reaches its limit
    (``limits = {"alpha": (lo, hi), "beta": (lo, hi)}``, default :data:`ALPHA_LIMITS`,
    :data:`BETA_LIMITS`); :func:`edges` then says whether the best is still on an end.
    """
    curve: dict[tuple, np.ndarray] = {}
    limits = {"alpha": ALPHA_LIMITS, "beta": BETA_LIMITS} | dict(limits or {})

    def mean_se(a, b):
        key = (float(a), float(b))
        if key not in curve:
            curve[key] = np.asarray(score(*key), np.float64)
        v = curve[key]
        return float(v.mean()), float(v.std(ddof=1) / np.sqrt(v.size)) if v.size > 1 else 0.0

    def scan(grid, fixed, which, indices=None):
        best, best_s, best_se, rising, last = None, np.inf, 0.0, 0, None
        for i in range(len(grid)) if indices is None else indices:
            v = grid[i]
            s, se = mean_se(v, fixed) if which == "alpha" else mean_se(fixed, v)
            if s < best_s:
                best, best_s, best_se = v, s, se
            rising = rising + 1 if (last is not None and s > last and s > best_s + 2 * best_se) else 0
            last = s
            if rising >= 2:
                break
        return best

    a = PAPER_WEIGHT if requested["alpha"] == AUTO else requested["alpha"]
    b = PAPER_WEIGHT if requested["beta"] == AUTO else requested["beta"]
    alphas = sorted(float(x) for x in alphas)
    betas = sorted(float(x) for x in betas)
    if requested["alpha"] == AUTO:
        a = scan(alphas, b, "alpha")
    if requested["beta"] == AUTO:
        b = scan(betas, a, "beta")
        if requested["alpha"] == AUTO:  # alpha again, around its best, at the chosen beta
            i = alphas.index(a)
            scan(alphas, b, "alpha", indices=range(max(0, i - 2), min(len(alphas), i + 3)))
    if not curve:  # nothing automatic: the one pair asked for
        mean_se(a, b)
    # past the grid's ends while the best lies on one
    automatic = [n for n in ("alpha", "beta") if requested[n] == AUTO]
    moved = True
    while moved:
        moved = False
        best = _best(curve)
        for name in automatic:
            side = _end(curve, best, name)
            if side is None:
                continue
            lo, hi = limits[name]
            value = best[0 if name == "alpha" else 1]
            step = _snap(
                value / _STEP if side == "low" else value * _STEP, [k[0 if name == "alpha" else 1] for k in curve]
            )
            if not (lo * (1 - 1e-9) <= step <= hi * (1 + 1e-9)) or value <= 0:
                continue
            pair = (step, best[1]) if name == "alpha" else (best[0], step)
            mean_se(*pair)
            if _best(curve) == (float(pair[0]), float(pair[1])):
                moved = True
                break
    return curve


def _snap(value: float, known) -> float:
    """``value``, or the weight already tried that it equals to rounding (one key per weight)."""
    for k in known:
        if abs(k - value) <= 1e-9 * abs(value):
            return float(k)
    return float(10.0 ** (np.round(np.log10(value) * 2.0) / 2.0)) if value > 0 else float(value)


def _best(curve: dict) -> tuple:
    keys = list(curve)
    return keys[int(np.argmin([curve[k].mean() for k in keys]))]


def _end(curve: dict, pair: tuple, name: str):
    """``"low"``/``"high"`` when ``pair``'s weight ``name`` is the smallest/largest tried at its other weight.

    (Against every value of the weight tried when no other was tried at that other weight.)
    """
    i, j = (0, 1) if name == "alpha" else (1, 0)
    values = [k[i] for k in curve if k[j] == pair[j]]
    if len(values) < 2:  # nothing else tried at this other weight: against everything tried
        values = [k[i] for k in curve]
    if len(set(values)) < 2:
        return None
    if pair[i] == min(values):
        return "low"
    if pair[i] == max(values):
        return "high"
    return None


def edges(curve: dict, requested: dict, *, pair=None) -> dict:
    """The automatic weights whose chosen value lies on an end of what was searched: ``{name: "low"/"high"}``.

    ``pair``: the chosen pair (default: the lowest score); an end is the smallest (largest) value
    of the weight tried anywhere.  After :func:`search` the lowest score lies on one only at the
    weight's limit (or a value the search could not go past, such as 0): the best may lie
    beyond it.
    """
    best = _best(curve) if pair is None else (float(pair[0]), float(pair[1]))
    out = {}
    for i, name in enumerate(("alpha", "beta")):
        if requested.get(name) != AUTO:
            continue
        values = {k[i] for k in curve}
        if len(values) < 2:
            continue
        if best[i] == min(values):
            out[name] = "low"
        elif best[i] == max(values):
            out[name] = "high"
    return out


def summarize(curve: dict, *, anchor=(PAPER_WEIGHT, PAPER_WEIGHT)):
    """``keys, means, standard errors, chosen pair, (alpha range, beta range), lowest-score pair`` of a curve.

    The lowest-score pair has the smallest mean score over everything tried.  The pairs the
    data cannot tell from it are those whose mean exceeds its mean by at most one standard error
    of the *paired* difference over pixels and at most :data:`TIE_RELATIVE` (1 %) of it (a small
    sample's standard error alone admits pairs whose scores differ by far more than the solves'
    tolerance moves them: the Sec. 5.2 study pools 5 pixels); among them the **chosen** pair is the one nearest
    ``anchor`` (the paper's 0.01 / 0.01; distance in decades, ``|log10 alpha / 0.01| + |log10 beta
    / 0.01|``, the lower score breaking ties): move away from the paper's weights only as far as
    the data demand (the one-standard-error rule, towards the weights the paper validated).  A
    criterion's curve can be flat over decades -- where the images cannot tell the weights apart
    and the solves' own tolerance shapes its last digits -- and there its lowest point is noise;
    measured on the stacks of the guide, the rule turned the one miss of the lowest-score choice
    (1.16x the best, 9 % worse than 0.01 / 0.01) into 1.09x / 2.4 % and cost nothing elsewhere.
    The ranges hold the tried weights (the other at its chosen value) within that standard error.
    """
    keys = list(curve)
    means = np.array([curve[k].mean() for k in keys])
    ses = np.array([curve[k].std(ddof=1) / np.sqrt(curve[k].size) if curve[k].size > 1 else 0.0 for k in keys])
    lowest = int(np.argmin(means))
    ref = curve[keys[lowest]]
    diff_se = np.array([np.std(curve[k] - ref, ddof=1) / np.sqrt(ref.size) if ref.size > 1 else 0.0 for k in keys])
    near = (means - means[lowest] <= diff_se) & (means - means[lowest] <= TIE_RELATIVE * abs(means[lowest]))
    la, lb = (np.log10(max(v, 1e-300)) for v in anchor)

    def distance(k):
        return abs(np.log10(max(k[0], 1e-300)) - la) + abs(np.log10(max(k[1], 1e-300)) - lb)

    chosen = min(np.flatnonzero(near), key=lambda i: (distance(keys[i]), means[i]))
    a, b = keys[chosen]
    arr_a = np.array([k[0] for k in keys])
    arr_b = np.array([k[1] for k in keys])
    in_a = near & (arr_b == b)
    in_b = near & (arr_a == a)
    ranges = (
        (float(arr_a[in_a].min()), float(arr_a[in_a].max())),
        (float(arr_b[in_b].min()), float(arr_b[in_b].max())),
    )
    return keys, means, ses, (float(a), float(b)), ranges, (float(keys[lowest][0]), float(keys[lowest][1]))


def choose_weights(
    stack: Stack,
    *,
    alpha="auto",
    beta="auto",
    alphas=None,
    betas=None,
    criterion: str | None = None,
    folds: int | None = None,
    n_pixels: int | None = None,
    seed: int = 0,
    tol: float = CRITERION_TOL,
    problem: DemuxProblem | None = None,
    weighting: str | None = None,
    ambient: str | None = None,
) -> WeightChoice:
    """Choose ``alpha`` and/or ``beta`` from the stack's own images.

    Parameters
    ----------
    stack : Stack
    alpha, beta : float or "auto"
        A number is kept as it is; ``"auto"`` is chosen (the grid, extended past its ends
        while the best lies on one).
    alphas, betas : sequence of float, optional
        Log grids scanned (default :data:`DEFAULT_ALPHAS`, :data:`DEFAULT_BETAS`: half
        decades, 1e-3 ... 1e4 and 1e-4 ... 10).
    criterion : {"gcv", "sure", "cv-images"}, optional
        ``"gcv"`` (default): generalized cross-validation of the noise-weighted fit
        (:mod:`planeray.demux.risk`: the camera model's relative noise, its level estimated
        from the residuals); ``"sure"``: Stein's unbiased risk estimate at the camera model's
        noise level (needs one); ``"cv-images"``: K-fold cross-validation over the images
        (the earlier criterion).  All three were measured on the same transports (the
        demultiplexing guide); the other two are kept for comparison.
    folds : int, optional
        Folds of images of ``"cv-images"`` (default :data:`DEFAULT_FOLDS`, 5).
    n_pixels : int, optional
        Pixels scored (default: 2 % of the image, 256 ... 4096).
    seed : int
        Seed of the pixel sample (and of the folds): the choice is a function of the stack
        and these settings.
    tol : float
        Certified relative objective gap of the criterion's solves (default: the plain
        demultiplexer's, 1e-4).
    ambient : {'none', 'estimate'}, optional
        Whether each pixel's ambient light is an unknown of the solves (Eq. 6a); default
        ``"estimate"`` (:func:`resolve_ambient`).

    Returns
    -------
    WeightChoice

    See Also
    --------
    demultiplex : ``alpha="auto"``, ``beta="auto"`` call it.
    WeightChoice : what it returns.

    References
    ----------
    .. [1] H. Kubo, S. Jayasuriya, T. Iwaguchi, T. Funatomi, Y. Mukaigawa, S. G. Narasimhan,
       "Programmable Non-Epipolar Indirect Light Transport: Capture and Analysis",
       IEEE TVCG 27(4), 2019, doi:10.1109/TVCG.2019.2946812, Sec. 4 (alpha = beta = 0.01 there).

    Examples
    --------
    >>> import planeray as pr
    >>> stack = pr.simulate_stack(pr.make_scene("wax", (8, 8), seed=0), pr.quick_sweep(), seed=0)
    >>> choice = choose_weights(stack)
    >>> choice.alpha > 0 and choice.beta > 0
    True
    """
    requested = {
        "alpha": AUTO if is_auto(alpha) else float(_weight(alpha, "alpha")),
        "beta": AUTO if is_auto(beta) else float(_weight(beta, "beta")),
    }
    for name in ("alpha", "beta"):
        v = requested[name]
        if v != AUTO and (not np.isfinite(v) or v < 0):
            raise InputError(f"{name} must be a non-negative number or 'auto', got {v!r}")
    ambient = resolve_ambient(ambient, alpha, beta)
    if ambient == "estimate" and requested["beta"] == 0:
        raise InputError("ambient estimation needs beta > 0 (with beta = 0 the split is not identifiable)")
    criterion = DEFAULT_CRITERION if criterion is None else str(criterion)
    if criterion not in CRITERIA:
        raise InputError(f"criterion must be one of {', '.join(CRITERIA)}, got {criterion!r}")
    alphas = DEFAULT_ALPHAS if alphas is None else alphas
    betas = DEFAULT_BETAS if betas is None else betas
    folds = DEFAULT_FOLDS if folds is None else int(folds)
    if criterion == CV_CRITERION and folds < 2:
        raise InputError(f"folds must be at least 2, got {folds}")
    if problem is None:
        problem = DemuxProblem.from_stack(stack)
    if criterion == CV_CRITERION and problem.n_images < 2 * folds:
        raise InputError(
            f"alpha/beta 'auto' needs at least {2 * folds} usable images for {folds}-fold cross-validation, "
            f"the stack has {problem.n_images}"
        )
    weighting = DEFAULT_WEIGHTING if weighting is None else weighting
    if weighting not in ("noise", "equal"):
        raise InputError(f"weighting must be 'noise' or 'equal', got {weighting!r}")
    sample = _sample(stack, problem, seed=seed, n_pixels=n_pixels, weighting=weighting)
    column = problem.exposure_rows if ambient == "estimate" else None
    record: dict = {"worst_gap": 0.0}
    if criterion == CV_CRITERION:
        split = fold_indices(problem.n_images, folds, seed)

        def score(a, b):
            return cv_score(
                sample.groups, sample.B, sample.mask, sample.weight, split, a, b, tol=tol, ambient=column, record=record
            )

        name = CV_CRITERION
    else:
        if criterion == "sure" and sample.weighting != "camera-noise":
            raise InputError(
                "criterion 'sure' needs the noise level of the stack's camera model, and the stack has none "
                "(or weighting is 'equal'): use 'gcv', which estimates it"
            )
        gcv = criterion == "gcv"
        warm: dict = {}

        def score(a, b):
            S = sample
            return risk_score(
                S.groups, S.B, S.mask, S.weight, a, b, tol=tol, ambient=column, gcv=gcv, record=record, warm=warm
            )

        name = criterion
    curve = search(score, requested, alphas, betas)
    keys, means, ses, (a, b), (alpha_range, beta_range), lowest = summarize(curve)
    arr_a = np.array([k[0] for k in keys])
    arr_b = np.array([k[1] for k in keys])
    return WeightChoice(
        alpha=float(a),
        beta=float(b),
        requested=requested,
        criterion=name,
        weighting=sample.weighting,
        folds=folds if criterion == CV_CRITERION else 0,
        n_pixels=sample.n_pixels,
        rows=sample.rows,
        alphas=arr_a,
        betas=arr_b,
        scores=means,
        score_se=ses,
        alpha_range=alpha_range,
        beta_range=beta_range,
        pixels=np.concatenate(sample.pixels),
        ambient=ambient,
        edge=edges(curve, requested, pair=(a, b)),
        worst_gap=float(record["worst_gap"]),
        lowest=lowest,
    )

"""The anisotropy the fit does not know: how a medium's ``g`` changes its line kernel at a given ``mu_s'``.

The forward table (:mod:`planeray.kernels.forward`) is traced at one Henyey-Greenstein anisotropy,
``g = 0.8`` (:data:`~planeray.kernels.forward.DEFAULT_G`).  By the similarity relation the diffuse
kernel depends on ``mu_s' = mu_s (1 - g)`` alone, but near the line it does not: measured here with the
project's Monte Carlo (:func:`planeray.mc.mc_line_profile`, the same medium at ``g`` from 0 to 0.95),
a medium of ``g = 0`` sends up to 5.8 times the light of the table's into the line's own bin (1.3 times
at ``mu_s' h`` = 1 per row) and up to 34 % less into the next few rows.  A user rarely knows ``g`` (milk 0.8-0.93, Intralipid 0.6-0.8, tissues 0.8-0.95, scattering paints
and powders lower), so the fits take it as a **nuisance parameter**: fitted with ``mu_s'`` and ``mu_a``
within :data:`G_PRIOR`, the kernel ``K_g = K_0.8 (1 + d_g)`` with ``d_g`` the traced deviation, a monotone
cubic (PCHIP) in ``g`` between the nodes :data:`G_NODES` (:func:`g_kernel_change`, :func:`kernel_at_g`).  Its uncertainty enters the standard
errors of ``mu_s'`` and ``mu_a`` through their correlation with it (the fit's covariance), and the
chi-square counts it as one more parameter -- one physical direction of the kernel's shape, not a free
band of shapes, so a model whose geometry is wrong (a thin layer fitted as semi-infinite) still fails it.
A user who knows ``g`` states it (``--g``; the kernel then is ``K_g`` at that ``g``).

The deviations are stored as ratios ``K_g / K_0.8 - 1`` per offset bin (:class:`AnisotropyTable`), over
a grid of the dimensionless per-row coefficients (``mu_s' h``, ``mu_a / mu_s'``) and the index ``n``:
radiative transfer has no length scale of its own (see :mod:`planeray.kernels.forward`).
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..mc.cache import save_table, stored, where
from ..mc.engine import mc_line_profile
from ..medium import Medium
from .footprint import footprint_average

__all__ = [
    "G_NODES",
    "G_PRIOR",
    "G_TABLE_S_PER_ROW",
    "G_TABLE_A_OVER_S",
    "G_TABLE_N",
    "G_TABLE_PHOTONS",
    "AnisotropyTable",
    "anisotropy_table",
    "anisotropy_table_stored",
    "check_g",
    "g_kernel_change",
    "kernel_at_g",
]

#: Anisotropies traced (the table's own ``g = 0.8`` among them: its deviation is zero).
G_NODES = (0.0, 0.3, 0.5, 0.65, 0.8, 0.9, 0.95)
#: The range of ``g`` the fits cover (an unstated ``g`` is fitted within it): isotropic scatterers to strongly
#: forward scattering tissues and milks ( Jacques 2013, Phys. Med. Biol. 58, R37, Table 2: tissues 0.8-0.95;
#: Intralipid 0.6-0.8, van Staveren et al. 1991, Appl. Opt. 30, 4507).
G_PRIOR = (0.0, 0.95)
#: The table's grid: ``mu_s' h`` (per row; one transport mean free path is ``1 / (mu_s' h)`` rows).
G_TABLE_S_PER_ROW = (0.03, 0.1, 0.3, 1.0, 3.0, 10.0)
#: ... ``mu_a / mu_s'`` (the deviation barely depends on it; two values span the media of interest).
G_TABLE_A_OVER_S = (0.003, 0.1)
#: ... and the relative index (1: an index-matched surface).
G_TABLE_N = (1.0, 1.33, 1.45)
#: Photons per medium and ``g``.
G_TABLE_PHOTONS = 1_000_000
#: Offsets of the table, rows ``0 .. reach`` (symmetric kernels: both sides averaged).
G_TABLE_REACH_ROWS = 128

_VERSION = 1
_TABLE_G = 0.8
_LOADED: dict = {}  # the table read once per process
_KERNEL_FLOOR = 1e-5  # of the kernel's peak: below it the traced ratios are not used (g_kernel_change)


@dataclass(frozen=True)
class AnisotropyTable:
    """Ratios ``K_g / K_0.8 - 1`` of Monte Carlo line kernels at equal ``mu_s'`` and ``mu_a``.

    Attributes
    ----------
    s_per_row, a_over_s, n : ndarray
        The grid: ``mu_s' h``, ``mu_a / mu_s'``, the relative index.
    g : ndarray (G,)
        The traced anisotropies (:data:`G_NODES`).
    deviation : ndarray (N, A, S, G, U)
        ``K_g / K_0.8 - 1`` per offset bin ``0 .. reach`` (zero at ``g = 0.8``).
    params : dict
        Photons, seed, version.
    """

    s_per_row: np.ndarray
    a_over_s: np.ndarray
    n: np.ndarray
    g: np.ndarray
    deviation: np.ndarray
    params: dict = field(default_factory=dict)

    def save(self, path) -> Path:
        """Write the table as one compressed ``.npz`` (no pickle), atomically."""
        return save_table(
            path, meta=np.array(json.dumps(self.params, sort_keys=True)), s_per_row=self.s_per_row,
            a_over_s=self.a_over_s, n=self.n, g=self.g, deviation=self.deviation,
        )  # fmt: skip

    @classmethod
    def load(cls, path) -> AnisotropyTable:
        """Read a table written by :meth:`save`."""
        with np.load(path, allow_pickle=False) as z:
            return cls(
                **{k: z[k] for k in ("s_per_row", "a_over_s", "n", "g", "deviation")}, params=json.loads(str(z["meta"]))
            )

    def at(self, s_per_row, a_per_row, n) -> np.ndarray:
        """``(G, U)``: the deviations at a medium, interpolated linearly in ``log s``, ``log(a / s)`` and
        ``n`` (held at the grid's ends beyond it)."""

        def weights(grid, x):
            grid = np.asarray(grid, np.float64)
            if grid.size == 1:
                return [(0, 1.0)]
            x = float(np.clip(x, grid[0], grid[-1]))
            i = int(np.clip(np.searchsorted(grid, x) - 1, 0, grid.size - 2))
            t = (x - grid[i]) / (grid[i + 1] - grid[i])
            return [(i, 1.0 - t), (i + 1, t)]

        s = float(s_per_row)
        ws = weights(np.log(self.s_per_row), math.log(s))
        wa = weights(np.log(self.a_over_s), math.log(max(float(a_per_row), 1e-12) / s))
        wn = weights(self.n, float(n))
        out = np.zeros(self.deviation.shape[-2:])
        for i, a in wn:
            for j, b in wa:
                for k, c in ws:
                    out += a * b * c * self.deviation[i, j, k]
        return out


def _name(s, a_over_s, n, g, reach, n_photons, seed) -> str:
    blob = json.dumps(
        dict(v=_VERSION, s=list(map(float, s)), a=list(map(float, a_over_s)), n=list(map(float, n)),
             g=list(map(float, g)), reach=int(reach), n_photons=int(n_photons), seed=int(seed)),
        sort_keys=True,
    )  # fmt: skip
    return "anisotropy-" + hashlib.sha256(blob.encode()).hexdigest()[:32] + ".npz"


def _build(s_grid, a_grid, n_grid, g_nodes, reach, n_photons, seed, progress) -> AnisotropyTable:
    off = np.arange(-reach, reach + 1)
    dev = np.zeros((len(n_grid), len(a_grid), len(s_grid), len(g_nodes), reach + 1))
    for i, n in enumerate(n_grid):
        for j, r in enumerate(a_grid):
            for k, s in enumerate(s_grid):
                kern = {}
                for g in g_nodes:
                    med = Medium.from_reduced(float(s), float(r) * float(s), g=float(g), n=float(n))
                    p = mc_line_profile(med, n_photons=int(n_photons), offsets_rows=off, mm_per_row=1.0, seed=seed)
                    rad = np.asarray(p.radiance, np.float64)
                    kern[g] = 0.5 * (rad[reach:] + rad[reach::-1])  # the two sides of the line averaged
                    if progress is not None:
                        progress(1)
                ref = kern[_TABLE_G]
                seen = ref > 1e-300  # bins the table's g reaches (a ratio over an underflow means nothing)
                for m, g in enumerate(g_nodes):
                    dev[i, j, k, m] = np.where(seen, kern[g] / np.where(seen, ref, 1.0) - 1.0, 0.0)
    params = dict(version=_VERSION, n_photons=int(n_photons), seed=int(seed), table_g=_TABLE_G, reach=int(reach))
    return AnisotropyTable(
        s_per_row=np.asarray(s_grid, np.float64), a_over_s=np.asarray(a_grid, np.float64),
        n=np.asarray(n_grid, np.float64), g=np.asarray(g_nodes, np.float64), deviation=dev, params=params,
    )  # fmt: skip


def _args():
    return (G_TABLE_S_PER_ROW, G_TABLE_A_OVER_S, G_TABLE_N, G_NODES, G_TABLE_REACH_ROWS, G_TABLE_PHOTONS, 0)


def anisotropy_table(*, progress=None, cache=True) -> AnisotropyTable:
    """The shipped (else cached, else traced: about 40 minutes on two cores) :class:`AnisotropyTable`.

    Parameters
    ----------
    progress : callable, optional
        Called with 1 after each Monte Carlo run (``len(G_NODES)`` per grid point).
    cache : bool
        Look in the shipped tables and the disk cache, and store a traced table there.
    """
    args = _args()
    name = _name(*args)
    if cache and name in _LOADED:
        return _LOADED[name]
    table = stored(
        name, load=AnisotropyTable.load, build=lambda: _build(*args, progress), save=lambda path, t: t.save(path),
        cache=cache,
    )  # fmt: skip
    if cache:
        _LOADED[name] = table
    return table


def anisotropy_table_stored() -> bool:
    """Whether :func:`anisotropy_table` is shipped or cached (no Monte Carlo to run)."""
    return where(_name(*_args())) is not None


def _pchip(x, y, xq: float) -> np.ndarray:
    """Monotone piecewise-cubic Hermite interpolation (Fritsch & Carlson 1980, SIAM J. Numer. Anal. 17, 238; the
    slopes of :class:`scipy.interpolate.PchipInterpolator`) of the rows ``y`` ``(G, U)`` over the increasing ``x``
    at one ``xq``: ``(U,)``.  Written out because the fits call it at every trial (scipy's builds an object:
    6x the time)."""
    x = np.asarray(x, np.float64)
    h = np.diff(x)
    m = np.diff(y, axis=0) / h[:, None]  # (G - 1, U) secants
    d = np.zeros_like(y)
    w1 = (2.0 * h[1:] + h[:-1])[:, None]
    w2 = (h[1:] + 2.0 * h[:-1])[:, None]
    same = (np.sign(m[1:]) == np.sign(m[:-1])) & (m[1:] != 0) & (m[:-1] != 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        whmean = (w1 / m[:-1] + w2 / m[1:]) / (w1 + w2)
        d[1:-1] = np.where(same, 1.0 / whmean, 0.0)

    def edge(h0, h1, m0, m1):
        e = ((2.0 * h0 + h1) * m0 - h0 * m1) / (h0 + h1)
        e = np.where(np.sign(e) != np.sign(m0), 0.0, e)
        return np.where((np.sign(m0) != np.sign(m1)) & (np.abs(e) > np.abs(3.0 * m0)), 3.0 * m0, e)

    d[0] = edge(h[0], h[1], m[0], m[1])
    d[-1] = edge(h[-1], h[-2], m[-1], m[-2])
    i = int(np.clip(np.searchsorted(x, xq) - 1, 0, x.size - 2))
    t = (xq - x[i]) / h[i]
    h00, h10, h01, h11 = 2 * t**3 - 3 * t**2 + 1, t**3 - 2 * t**2 + t, -2 * t**3 + 3 * t**2, t**3 - t**2
    return h00 * y[i] + h10 * h[i] * d[i] + h01 * y[i + 1] + h11 * h[i] * d[i + 1]


def check_g(g) -> float | None:
    """A stated anisotropy, checked: None (unknown: fitted within :data:`G_PRIOR`) or a value in that range."""
    from ..errors import InputError, parameter_name

    if g is None:
        return None
    try:
        v = float(g)
    except (TypeError, ValueError):
        raise InputError(f"{parameter_name('g')} must be a number, got {g!r}") from None
    lo, hi = G_PRIOR
    if not lo <= v <= hi:
        raise InputError(
            f"{parameter_name('g')} must lie within {lo}-{hi} (the anisotropies the forward model covers), got {v:g}"
        )
    return v


def g_kernel_change(kernel_row, s_per_row, a_per_row, n, g, offsets_rows, foot, *, table=None) -> np.ndarray:
    """``(U,)``: how the footprint-averaged kernel changes when the medium's anisotropy is ``g`` instead of 0.8.

    ``K_g - K_0.8 = K_0.8 d_g``, ``d_g`` the table's deviation at the medium (:meth:`AnisotropyTable.at`),
    a monotone cubic (PCHIP) in ``g`` between :data:`G_NODES`; zero at ``g = 0.8``.

    Parameters
    ----------
    kernel_row : ndarray (R + 1,)
        The model's kernel per projector-row offset ``0 .. R`` (symmetric), before the camera row's footprint
        (:func:`planeray.kernels.forward.table_kernel`).
    s_per_row, a_per_row : float
        The medium's ``mu_s' h`` and ``mu_a h`` (dimensionless).
    n : float
        Relative refractive index.
    g : float
        Henyey-Greenstein anisotropy, within :data:`G_PRIOR`.
    offsets_rows : array_like of int (U,)
        The fit's signed offsets, projector rows.
    foot : tuple of ndarray
        The camera row's footprint ``(offsets, weights)`` (:func:`planeray.kernels.footprint.camera_row_footprint`).
    table : AnisotropyTable, optional
        Default :func:`anisotropy_table`.

    Returns
    -------
    ndarray (U,)
        The change of the kernel, in its unit.

    Examples
    --------
    >>> import numpy as np
    >>> k = np.exp(-0.3 * np.arange(129.0))  # a kernel per row offset
    >>> foot = (np.array([0]), np.array([1.0]))  # one projector row per camera row
    >>> d = g_kernel_change(k, 0.3, 0.003, 1.33, 0.0, np.arange(-3, 4), foot)
    >>> bool(d[3] > 0 and d[2] < 0)  # isotropic scattering: more light in the line's bin, less beside it
    True
    >>> float(np.abs(g_kernel_change(k, 0.3, 0.003, 1.33, 0.8, np.arange(-3, 4), foot)).max())
    0.0
    """
    t = anisotropy_table() if table is None else table
    nodes = np.asarray(t.g, np.float64)
    g = float(np.clip(g, nodes[0], nodes[-1]))
    # monotone cubic in g between the traced values (PCHIP): smooth, so the fit's cost is smooth in g (a linear
    # interpolation's kinks at the nodes stall a trust-region step there), and it does not overshoot them
    dev = _pchip(nodes, t.at(s_per_row, a_per_row, n), g)
    k = np.asarray(kernel_row, np.float64)
    reach = min(k.size, dev.size) - 1
    k = k[: reach + 1]
    # where the kernel is below _KERNEL_FLOOR of its peak the traced ratios are Monte Carlo noise (a handful of
    # photons, or none): no change is taken there
    change_row = dev[: reach + 1] * np.where(k > _KERNEL_FLOOR * k.max(), k, 0.0)
    return footprint_average(change_row, offsets_rows, foot)


def kernel_at_g(kernel, kernel_row, log_s, log_a, n, g, offsets_rows, foot, *, table=None) -> np.ndarray:
    """The footprint-averaged kernel ``kernel`` of the forward table (``g = 0.8``) for a medium of anisotropy ``g``:
    ``max(kernel + change, 0)`` (:func:`g_kernel_change`); ``kernel`` itself at the table's ``g``.

    Parameters
    ----------
    kernel : ndarray (U,)
        The table's kernel at the fit's offsets (walls included where the fit has them).
    kernel_row : ndarray (R + 1,)
        :func:`planeray.kernels.forward.table_kernel` at the same medium (offsets ``0 .. R``).
    log_s, log_a : float
        ``log(mu_s' h)``, ``log(mu_a h)``: the fits' per-row log-coefficients.
    n, g, offsets_rows, foot, table
        As :func:`g_kernel_change`.

    Returns
    -------
    ndarray (U,)

    Examples
    --------
    >>> import numpy as np
    >>> k_row = np.exp(-0.3 * np.arange(129.0))
    >>> foot = (np.array([0]), np.array([1.0]))
    >>> k = k_row[np.abs(np.arange(-3, 4))]
    >>> kernel_at_g(k, k_row, np.log(0.3), np.log(0.003), 1.33, 0.8, np.arange(-3, 4), foot) is k
    True
    """
    if g == _TABLE_G:
        return kernel
    change = g_kernel_change(
        kernel_row, math.exp(log_s), math.exp(log_a), n, g, offsets_rows, foot, table=table
    )  # fmt: skip
    return np.maximum(kernel + change, 0.0)

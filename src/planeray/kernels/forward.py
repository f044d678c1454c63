"""The forward model of the transport fit: the line kernel of a medium ``(mu_s', mu_a)`` at a capture's geometry.

Forward model
-------------
``K`` is the project's own Monte Carlo (:func:`planeray.mc.mc_line_profile`: MCML
weights, Henyey-Greenstein scattering, a Fresnel top face of relative index ``n``,
diffusion hand-off deep in the medium), in the scenes' unit -- Lambertian-equivalent
reflectance per offset bin, ``pi`` x normal-view radiance x bin width (a white
Lambertian surface sums to 1) -- precomputed on a grid (:class:`ForwardTable`) and
interpolated smoothly (cubic) in ``log K`` over ``(log mu_s', sqrt(mu_a))``.

* **Units and the row size.**  Radiative transfer has no length scale of its own: the
  kernel of a medium ``(mu_s', mu_a)`` binned in rows of ``h`` mm equals the kernel of
  ``(mu_s' h / h0, mu_a h / h0)`` binned in rows of ``h0`` (every length scaled by
  ``h / h0``; the binned fractions are dimensionless).  The table is therefore stored in
  **per-row** coefficients ``mu h``; built over ``mu_s'`` 0.126-8 /mm and ``mu_a``
  0.0005-0.2 /mm at the materials scene's 0.3 mm per row (:data:`TABLE_MM_PER_ROW`), it
  serves any ``mm_per_row`` whose per-row coefficients fall inside it.
* **Anisotropy ``g``: the table's is 0.8** (:data:`DEFAULT_G`).  By the similarity relation the diffuse
  part of the kernel depends on ``mu_s' = mu_s (1 - g)`` alone, but near the line it does not (a medium
  of ``g = 0`` puts up to several times the table's light into the line's own bin and up to a third less
  into the next few transport mean free paths), so the fits take a medium's ``g`` as a **nuisance
  parameter**, fitted within 0-0.95 (or stated), by changing this kernel
  (:mod:`planeray.kernels.anisotropy`); a single line kernel barely separates it from ``mu_s'``.
* **Refractive index** ``n``: the table's (:data:`DEFAULT_N` = 1.33, water-based media);
  the user states another by building a table with it (:func:`build_forward_table`).
* **Camera rows.**  A camera row spans ``rows_per_camera_row`` projector rows; its kernel
  is ``K`` averaged over them (:func:`planeray.timing.band_bin_weights`, the scenes'
  footprint).

Beyond the table and container walls
------------------------------------
* **Beyond the table's** ``mu_s'`` (to :data:`DIPOLE_MU_S_PRIME_MAX_PER_ROW`) the kernel is the
  diffusion dipole's line kernel (closed form), times the table's kernel over the dipole's at
  the table's edge, per offset: a continuous hand-off where the dipole is accurate (the first
  bin beside the line lies more than a transport mean free path away).
* **Container walls** (:func:`container_wall_distances`, ``walls=`` of :func:`fit_profiles`,
  ``containers=`` of :func:`fit_transport`): a clear wall loses the light that reaches it.  The
  walls' *relative* effect comes from diffusion theory -- the dipole and its mirror images across
  the wall's extrapolated boundary, opposite sign (Haskell et al. 1994; the method of
  :mod:`planeray.mc.wall`'s continuation) -- applied to the table's kernel,
  ``K_wall = K L_wall / L``; it carries 78-99 % of the brute-force Monte Carlo wall effect
  (tested against the materials scene's shipped wall tables).

:func:`forward_kernel` is that kernel (the fit's forward model, :mod:`planeray.materials.fit`
inverts it); :func:`forward_table` the shipped, cached or traced table it interpolates (the one
table store, :func:`planeray.kernels.store.stored`).  Not to be confused with
:func:`planeray.kernels.line_kernel`, a scene's kernel of a :class:`~planeray.medium.Medium` by
model name.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.interpolate import NdBSpline, make_interp_spline

from ..errors import InputError
from ..mc.cache import save_table, stored, where
from ..mc.engine import mc_line_profile
from ..medium import Medium
from .footprint import camera_row_footprint, footprint_average
from .walls import BOTTOM_ANGLE_DEG, WALL_ANGLES_DEG, check_wall_kind, dipole_line, dipole_per_row, wall_term

__all__ = [
    "DEFAULT_G",
    "DEFAULT_N",
    "TABLE_MM_PER_ROW",
    "TABLE_MU_S_PRIME_PER_MM",
    "TABLE_MU_A_PER_MM",
    "TABLE_REACH_ROWS",
    "TABLE_PHOTONS",
    "TABLE_RUNS",
    "DIPOLE_MU_S_PRIME_MAX_PER_ROW",
    "ForwardTable",
    "build_forward_table",
    "forward_table",
    "forward_table_stored",
    "forward_table_seconds",
    "forward_table_name",
    "forward_kernel",
    "table_kernel",
    "kernel_per_row",
    "model_kernel",
]


#: Henyey-Greenstein anisotropy of the table (fixed; see the module docstring).
DEFAULT_G = 0.8


#: Relative refractive index of the table's media against air.
DEFAULT_N = 1.33


#: Row size (mm) at which the table's mm^-1 ranges are stated.
TABLE_MM_PER_ROW = 0.3


#: Grid of the shipped table, mm^-1 at :data:`TABLE_MM_PER_ROW` (log spaced).
TABLE_MU_S_PRIME_PER_MM = np.geomspace(0.2 / 40.0 ** (1 / 8), 8.0, 10)  # 0.126-8: the soap's 0.2 inside


TABLE_MU_A_PER_MM = np.geomspace(0.0005, 0.2, 9)


#: Offsets of the table, projector rows (the kernel is symmetric: 0 .. reach).
TABLE_REACH_ROWS = 128


#: Photons per grid point of the shipped table.
TABLE_PHOTONS = 100_000


#: Largest per-row ``mu_s' h`` of the fit (``100 /mm`` at 0.3 mm per row): beyond the table's (2.4 per
#: row, 8 /mm at 0.3 mm per row) the kernel is the diffusion dipole's, handed off at the table's edge
#: (times the table's kernel over the dipole's there, per offset).
DIPOLE_MU_S_PRIME_MAX_PER_ROW = 30.0


_LOG_FLOOR = 1e-30  # kernel values below this fraction of the kernel's peak are clamped (log interpolation)


_TABLE_VERSION = 1


@dataclass(frozen=True)
class ForwardTable:
    """Monte Carlo line kernels over a log grid of per-row coefficients.

    Attributes
    ----------
    mu_s_prime_per_row, mu_a_per_row : ndarray (S,), (A,)
        Grid of ``mu_s' h`` and ``mu_a h`` (dimensionless: coefficient x row size).
    offsets_rows : ndarray (U,) of int
        ``0 .. reach``; the kernel is symmetric in the offset.
    kernel, kernel_stderr : ndarray (S, A, U)
        Lambertian-equivalent reflectance per offset bin and its Monte Carlo standard
        error (the two sides of the line averaged).
    g, n : float
        Anisotropy and relative index of the media.
    params : dict
        Photons, seed, versions.
    """

    mu_s_prime_per_row: np.ndarray
    mu_a_per_row: np.ndarray
    offsets_rows: np.ndarray
    kernel: np.ndarray
    kernel_stderr: np.ndarray
    g: float
    n: float
    params: dict = field(default_factory=dict)

    def __post_init__(self):
        k = np.asarray(self.kernel, np.float64)
        floor = _LOG_FLOOR * k.max(axis=-1, keepdims=True)
        logk = np.log(np.maximum(k, floor))
        # Tensor-product cubic (not-a-knot) interpolating spline, built once: interpolate along
        # log mu_s', then the coefficients along sqrt(mu_a) -- the far tail falls as
        # exp(-sigma_tr x), sigma_tr ~ sqrt(3 mu_a mu_s'), so log K is nearly linear in sqrt(mu_a)
        # (in log mu_a it is exponential, and a cubic through it missed the tail by up to 50 %).
        xs, xa = np.log(self.mu_s_prime_per_row), np.sqrt(self.mu_a_per_row)
        bs = make_interp_spline(xs, logk, k=3, axis=0)
        ba = make_interp_spline(xa, bs.c, k=3, axis=1)
        object.__setattr__(self, "_interp", NdBSpline((bs.t, ba.t), np.moveaxis(ba.c, 0, 1), k=3))

    @property
    def bounds_per_row(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """``((s_min, s_max), (a_min, a_max))`` of the per-row coefficients."""
        s, a = self.mu_s_prime_per_row, self.mu_a_per_row
        return (float(s[0]), float(s[-1])), (float(a[0]), float(a[-1]))

    def log_kernel_per_row(self, log_s, log_a) -> np.ndarray:
        """``log K`` at per-row log-coefficients (broadcast), ``(..., U)``; inside the grid only."""
        pts = np.stack(np.broadcast_arrays(np.asarray(log_s, float), np.exp(0.5 * np.asarray(log_a, float))), axis=-1)
        return self._interp(pts)

    def save(self, path) -> Path:
        """Write the table as one compressed ``.npz`` (no pickle), atomically."""
        meta = {"g": self.g, "n": self.n, "params": self.params}
        return save_table(
            path,
            meta=np.array(json.dumps(meta, sort_keys=True)),
            mu_s_prime_per_row=self.mu_s_prime_per_row,
            mu_a_per_row=self.mu_a_per_row,
            offsets_rows=self.offsets_rows,
            kernel=self.kernel,
            kernel_stderr=self.kernel_stderr,
        )

    @classmethod
    def load(cls, path) -> ForwardTable:
        """Read a table written by :meth:`save`."""
        with np.load(path, allow_pickle=False) as z:
            meta = json.loads(str(z["meta"]))
            arrays = {
                k: z[k] for k in ("mu_s_prime_per_row", "mu_a_per_row", "offsets_rows", "kernel", "kernel_stderr")
            }
        return cls(**arrays, g=float(meta["g"]), n=float(meta["n"]), params=meta["params"])


def _table_name(mu_s_prime_per_row, mu_a_per_row, reach, g, n, n_photons, seed) -> str:
    blob = json.dumps(
        dict(
            v=_TABLE_VERSION,
            s=[round(float(v), 12) for v in mu_s_prime_per_row],
            a=[round(float(v), 12) for v in mu_a_per_row],
            reach=int(reach),
            g=float(g),
            n=float(n),
            n_photons=int(n_photons),
            seed=int(seed),
        ),
        sort_keys=True,
    )
    return "fit-" + hashlib.sha256(blob.encode()).hexdigest()[:32] + ".npz"


def build_forward_table(
    *,
    mu_s_prime_per_mm=TABLE_MU_S_PRIME_PER_MM,
    mu_a_per_mm=TABLE_MU_A_PER_MM,
    mm_per_row=TABLE_MM_PER_ROW,
    reach_rows=TABLE_REACH_ROWS,
    g=DEFAULT_G,
    n=DEFAULT_N,
    n_photons=TABLE_PHOTONS,
    seed=0,
    progress=None,
) -> ForwardTable:
    """Trace the forward table: one :func:`planeray.mc.mc_line_profile` per grid point.

    Parameters
    ----------
    mu_s_prime_per_mm, mu_a_per_mm : array_like of float
        Increasing grids (at least 4 points each: cubic interpolation), mm^-1 at ``mm_per_row``.
    mm_per_row : float
        Row size the grids are stated at (the table itself is per row).
    reach_rows : int
        Largest offset tabulated, projector rows.
    g, n : float
        Henyey-Greenstein anisotropy and relative refractive index of the media.
    n_photons : int
        Photons per grid point.
    seed : int
    progress : callable, optional
        Called with 1 after each grid point.

    Returns
    -------
    ForwardTable
    """
    s = np.asarray(mu_s_prime_per_mm, float) * float(mm_per_row)
    a = np.asarray(mu_a_per_mm, float) * float(mm_per_row)
    for name, v in (("mu_s_prime_per_mm", s), ("mu_a_per_mm", a)):
        if v.size < 4 or np.any(np.diff(v) <= 0) or v[0] <= 0:
            raise InputError(f"{name} must be >= 4 increasing positive values")
    K = np.empty((s.size, a.size, int(reach_rows) + 1))
    E = np.empty_like(K)
    for i, si in enumerate(s):
        for j, aj in enumerate(a):
            K[i, j], E[i, j] = _trace_point(si, aj, reach_rows=reach_rows, g=g, n=n, n_photons=n_photons, seed=seed)
            if progress is not None:
                progress(1)
    params = dict(n_photons=int(n_photons), seed=int(seed), table_version=_TABLE_VERSION, source="mc_line_profile")
    return ForwardTable(s, a, np.arange(int(reach_rows) + 1), K, E, float(g), float(n), params)


def _trace_point(s_per_row, a_per_row, *, reach_rows, g, n, n_photons, seed):
    """One grid point of the table: the kernel on offsets ``0 .. reach`` (sides averaged) and its error."""
    offsets = np.arange(-int(reach_rows), int(reach_rows) + 1)
    mid = int(reach_rows)
    # Per-row coefficients are mm^-1 in rows of 1 mm: trace at mm_per_row = 1.
    med = Medium.from_reduced(float(s_per_row), float(a_per_row), g=float(g), n=float(n))
    p = mc_line_profile(med, n_photons=int(n_photons), offsets_rows=offsets, mm_per_row=1.0, seed=seed)
    r, e = p.radiance, p.radiance_stderr
    k = np.pi * 0.5 * (r[mid:] + r[mid::-1])
    err = np.pi * 0.5 * np.hypot(e[mid:], e[mid::-1])
    k[0], err[0] = np.pi * r[mid], np.pi * e[mid]
    return k, err


_LOADED: dict = {}


#: Monte Carlo runs of a forward table (one per grid point).
TABLE_RUNS = TABLE_MU_S_PRIME_PER_MM.size * TABLE_MU_A_PER_MM.size


def forward_table_name(g, n, n_photons, seed) -> str:
    """File name of :func:`forward_table`'s table of these media in the table store (shipped or cached)."""
    s = TABLE_MU_S_PRIME_PER_MM * TABLE_MM_PER_ROW
    a = TABLE_MU_A_PER_MM * TABLE_MM_PER_ROW
    return _table_name(s, a, TABLE_REACH_ROWS, g, n, n_photons, seed)


def forward_table_stored(*, g=DEFAULT_G, n=DEFAULT_N, n_photons=TABLE_PHOTONS, seed=0) -> bool:
    """Whether :func:`forward_table` of these media is shipped, cached or loaded (no tracing needed)."""
    name = forward_table_name(g, n, n_photons, seed)
    return name in _LOADED or where(name) is not None


def forward_table_seconds(*, g=DEFAULT_G, n=DEFAULT_N, n_photons=TABLE_PHOTONS, fraction=0.1, sample=9) -> float:
    """Estimated seconds to trace :func:`forward_table` on this machine, from a pilot run.

    A run's fixed cost is measured on a run of a few photons (after one that compiles the kernels);
    then ``sample`` grid points spread over the table (every ``TABLE_RUNS // sample``-th) are traced with
    ``fraction`` of the photons, and their cost beyond the fixed one is scaled to every point and every
    photon (the pilot takes about ``fraction * sample / TABLE_RUNS`` of the table's time).
    """
    import time

    s = TABLE_MU_S_PRIME_PER_MM * TABLE_MM_PER_ROW
    a = TABLE_MU_A_PER_MM * TABLE_MM_PER_ROW
    points = [(si, aj) for si in s for aj in a][:: max(TABLE_RUNS // int(sample), 1)]
    kw = dict(reach_rows=TABLE_REACH_ROWS, g=g, n=n, seed=1)
    _trace_point(s[0], a[0], n_photons=64, **kw)  # compiles the kernels
    t0 = time.perf_counter()
    _trace_point(s[0], a[0], n_photons=64, **kw)
    fixed = time.perf_counter() - t0
    photons = max(int(n_photons * fraction), 64)
    t0 = time.perf_counter()
    for si, aj in points:
        _trace_point(si, aj, n_photons=photons, **kw)
    per_point = max((time.perf_counter() - t0) / len(points) - fixed, 0.0) * n_photons / photons
    return TABLE_RUNS * (fixed + per_point)


def forward_table(*, g=DEFAULT_G, n=DEFAULT_N, n_photons=TABLE_PHOTONS, seed=0, progress=None) -> ForwardTable:
    """The default forward table: shipped (:data:`planeray.mc.cache.TABLES_DIR`), cached, or traced once.

    Other ``g`` or ``n`` than the shipped ones trace the table (:data:`TABLE_RUNS` Monte Carlo
    runs, minutes: :func:`forward_table_seconds` estimates it, :func:`forward_table_stored` says
    whether it is needed) and cache it under :func:`planeray.mc.cache.cache_dir`; ``progress`` is
    called with 1 after each run (never on a cache hit).
    """
    name = forward_table_name(g, n, n_photons, seed)
    if name not in _LOADED:
        _LOADED[name] = stored(
            name,
            load=ForwardTable.load,
            build=lambda: build_forward_table(g=g, n=n, n_photons=n_photons, seed=seed, progress=progress),
            save=lambda path, table: table.save(path),
        )
    return _LOADED[name]


def _dipole_binned(s, a, n, offsets):
    """The dipole's line kernel binned to offsets ``0 .. reach`` (rows), per-row coefficients."""
    t, wt = np.polynomial.legendre.leggauss(16)
    x = np.asarray(offsets, np.float64)[:, None] + 0.5 * t[None, :]
    return (dipole_line(np.abs(x), dipole_per_row(s, a, n)) * (0.5 * wt)).sum(axis=1)


def table_kernel(table: ForwardTable, log_s, log_a):
    """``K`` on the table's offsets at per-row log-coefficients; beyond the table's largest ``mu_s'``
    the dipole, handed off at the edge (:data:`DIPOLE_MU_S_PRIME_MAX_PER_ROW`)."""
    ls1 = math.log(table.mu_s_prime_per_row[-1])
    if np.ndim(log_s) == 0 and float(log_s) > ls1:
        k1 = np.exp(table.log_kernel_per_row(ls1, log_a))
        a = math.exp(float(log_a))
        off = table.offsets_rows
        d_s = _dipole_binned(math.exp(float(log_s)), a, table.n, off)
        d_1 = _dipole_binned(math.exp(ls1), a, table.n, off)
        return k1 * d_s / np.maximum(d_1, 1e-300)
    return np.exp(table.log_kernel_per_row(log_s, log_a))


def kernel_per_row(table: ForwardTable, log_s, log_a, offsets_rows, foot, *, k=None):
    """``K`` (not log) at per-row log-coefficients for the given signed offsets, footprint-averaged (``k``: the
    :func:`table_kernel` at them, when the caller has it)."""
    k = table_kernel(table, log_s, log_a) if k is None else k  # (..., U_table)
    return footprint_average(k, offsets_rows, foot)


def model_kernel(table: ForwardTable, log_s, log_a, offsets_rows, foot, walls=None, wall_kind="clear", *, k=None):
    """The pixel's (or block's) kernel at per-row log-coefficients: the table's, changed by the walls (``k``: the
    :func:`table_kernel` at them, when the caller has it)."""
    k = table_kernel(table, log_s, log_a) if k is None else k
    base = kernel_per_row(table, log_s, log_a, offsets_rows, foot, k=k)
    if walls is None or not len(walls):
        return base
    term = wall_term(k, log_s, log_a, table.n, offsets_rows, foot, np.asarray(walls, float), wall_kind)
    return np.maximum(base + term, 0.0)


def forward_kernel(
    mu_s_prime_per_mm,
    mu_a_per_mm,
    *,
    offsets_rows,
    mm_per_row,
    rows_per_camera_row=1.0,
    table: ForwardTable | None = None,
    walls=None,
    wall_kind: str = "clear",
) -> np.ndarray:
    """The forward model: line kernel of a semi-infinite medium at the capture's geometry.

    Parameters
    ----------
    mu_s_prime_per_mm, mu_a_per_mm : float
        Reduced scattering and absorption coefficients, mm^-1.
    offsets_rows : array_like of int
        Offsets of the profile, projector rows (``|u| <=`` the table's reach; beyond, 0).
    mm_per_row : float
        Size of one projector row on the surface, mm.
    rows_per_camera_row : float
        Projector rows one camera row spans (the kernel is averaged over them).
    table : ForwardTable, optional
        Default :func:`forward_table`.
    walls : array_like (M, 4), optional
        Clear container walls near the pixel, rows ``[distance_rows, angle_deg, side,
        weight]`` (:func:`fit_profiles`, :func:`container_wall_distances`): the kernel is the table's times
        the walls' relative effect in diffusion theory (the dipole and its mirror images
        across the wall's extrapolated boundary, Haskell et al. 1994), ``K L_wall / L``.  A row
        of angle :data:`BOTTOM_ANGLE_DEG` is a layer's bottom ``distance_rows`` deep that loses
        the light (the slab's image series, Contini et al. 1997), its effect added likewise.
    wall_kind : {"clear", "black"}
        The walls' kind (:data:`WALL_KINDS`).

    Returns
    -------
    ndarray (U,)
        Lambertian-equivalent reflectance per offset bin (the scenes' transport unit).
    """
    table = table or forward_table()
    h = float(mm_per_row)
    (s0, s1), (a0, a1) = table.bounds_per_row
    s1 = max(s1, DIPOLE_MU_S_PRIME_MAX_PER_ROW)
    s, a = float(mu_s_prime_per_mm) * h, float(mu_a_per_mm) * h
    if not (s0 <= s <= s1 and a0 <= a <= a1):
        raise InputError(
            f"mu_s' {mu_s_prime_per_mm:g} /mm, mu_a {mu_a_per_mm:g} /mm at {h:g} mm per row lie outside the "
            f"forward model (mu_s' {s0 / h:g}-{s1 / h:g} /mm, mu_a {a0 / h:g}-{a1 / h:g} /mm at this row size)"
        )
    w = None if walls is None else np.atleast_2d(np.asarray(walls, np.float64))
    angles = (*WALL_ANGLES_DEG, BOTTOM_ANGLE_DEG)
    if w is not None and (w.shape[1] != 4 or not np.all(np.isin(w[:, 1], angles)) or np.any(w[:, 0] < 0)):
        raise InputError("walls must be rows of [distance_rows >= 0, angle_deg 0, 90 or 180 (a bottom), side, weight]")
    offsets = np.asarray(offsets_rows)
    return model_kernel(
        table,
        math.log(s),
        math.log(a),
        offsets,
        camera_row_footprint(rows_per_camera_row),
        w,
        check_wall_kind(wall_kind),
    )

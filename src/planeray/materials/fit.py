"""Measuring a medium: reduced scattering ``mu_s'`` and absorption ``mu_a`` from its line kernel.

The paper recognizes materials by the shape of their delay profiles (Sec. 8); this module
*measures* them.  A pixel of a homogeneous, semi-infinite scattering medium seen from
above receives from the projector's line at offset ``u`` (projector rows) the light of
the medium's **line kernel** ``K(u; mu_s', mu_a)`` -- the demultiplexed transport
profile ``T(u)`` of that pixel (Sec. 4).  Fitting ``K`` to a measured profile gives the
two coefficients, in 1/mm.

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
* **Anisotropy ``g``: fixed** (:data:`DEFAULT_G` = 0.8, the table's ``g``), not fitted
  or marginalized.  By the similarity relation the diffuse part of the kernel depends on
  ``mu_s' = mu_s (1 - g)`` alone; ``g`` changes only the first transport mean free
  path around the line (offsets below ``1 / mu_s'``), which at the capture's sampling
  carries little of the profile and cannot be separated from ``mu_s'`` with a single
  line kernel.  The bias this costs for a medium of another ``g`` is measured
  (docs/user_guide/materials_fit.md).
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

Calibration
-----------
``K`` is an **absolute** reflectance.  A measured profile is in the camera's units; to
compare magnitudes, divide it by the capture of a white reference (a Lambertian target
of known albedo -- Spectralon, or a region of known albedo in the field -- imaged with
the same sweep: its direct light per unit albedo) before fitting, and pass
``calibrated=True``.  Without it (``calibrated=False``, the default) the fit also
estimates a free scale ``c`` and uses **only the shape**: ``mu_s'`` is still set by the
profile's width near the line, but ``mu_a`` only by how the far tail falls, so it is
less identifiable (larger standard errors; NaN where they exceed the threshold).  The
output says which was used.

Fit and uncertainties
---------------------
Weighted least squares (:func:`scipy.optimize.least_squares`, trust region) in the
log-parameters ``(log mu_s', log mu_a[, log c])``, with per-sample standard deviations
``sigma`` (the camera noise model, or the demultiplexing residual); without them the
samples are weighted equally and the covariance is scaled by the residual variance.
Standard errors come from the Jacobian at the optimum, ``(J^T J)^-1``; that they match
the spread over noise seeds is tested.

Identifiability
---------------
A parameter is **NaN, with the reason in a bit mask, not a guess**, where the data do not
constrain it (:data:`REASONS`): no usable signal, the optimum at the edge of the table,
a relative standard error above :data:`MAX_RELATIVE_SE` (a flat likelihood: e.g.
``mu_a << mu_s'`` leaves the profile's shape nearly independent of ``mu_a`` within the
sampled offsets), or a profile narrower than a bin (``mu_s'`` leaves no trace in the
shape when nearly all of the light returns within the line's own bin).
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.interpolate import NdBSpline, make_interp_spline
from scipy.optimize import least_squares
from scipy.special import k1e

from ..errors import InputError
from ..goodness import (
    DEFAULT_P_MISFIT,
    FLAG_EDGE,
    FLAG_MISFIT,
    FLAG_NOT_FITTED,
    FLAG_RANGE,
    describe_flags,
    fit_quality,
)
from ..mc.cache import TABLES_DIR, cache_dir, save_table, write_or_warn
from ..mc.diffusion import boundary_mismatch_A
from ..mc.engine import mc_line_profile
from ..medium import Medium
from ..timing import band_bin_weights

__all__ = [
    "DEFAULT_G",
    "DEFAULT_N",
    "TABLE_MM_PER_ROW",
    "TABLE_MU_S_PRIME_PER_MM",
    "TABLE_MU_A_PER_MM",
    "TABLE_REACH_ROWS",
    "MAX_RELATIVE_SE",
    "DIPOLE_MU_S_PRIME_MAX_PER_ROW",
    "REASONS",
    "ForwardTable",
    "FitResult",
    "TABLE_RUNS",
    "build_forward_table",
    "forward_table",
    "forward_table_stored",
    "forward_table_seconds",
    "line_kernel",
    "WALL_ANGLES_DEG",
    "WALL_KINDS",
    "BOTTOM_ANGLE_DEG",
    "container_wall_distances",
    "fit_profiles",
    "describe_reasons",
    "TransportFit",
    "white_reference_scale",
    "fit_transport",
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
#: A parameter whose relative standard error exceeds this is not identifiable (NaN).
MAX_RELATIVE_SE = 0.5
#: Walls or a bottom closer than this many transport mean free paths (1 / mu_s') lie outside the range where
#: diffusion theory's method of images -- the walls' and the bottom's models -- is trusted: the fit is flagged.
DIFFUSION_RANGE_MFP = 5.0
#: Relative uncertainty of the forward model (table noise and interpolation; the forward-model
#: test allows 3 % against direct Monte Carlo), added in quadrature to the data's noise.
MODEL_RELATIVE_SD = 0.02
#: Reasons for a NaN, as bits of the identifiability mask.
REASONS = {
    1: "no signal: too few positive samples",
    2: "mu_s' at the edge of the forward table",
    4: "mu_a at the edge of the forward table",
    8: f"mu_s' not constrained (relative standard error > {MAX_RELATIVE_SE:g})",
    16: f"mu_a not constrained (relative standard error > {MAX_RELATIVE_SE:g})",
    32: "profile narrower than a bin: shape carries no mu_s'",
    64: "fit did not converge",
}
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


def _default_table_name(g, n, n_photons, seed) -> str:
    s = TABLE_MU_S_PRIME_PER_MM * TABLE_MM_PER_ROW
    a = TABLE_MU_A_PER_MM * TABLE_MM_PER_ROW
    return _table_name(s, a, TABLE_REACH_ROWS, g, n, n_photons, seed)


def forward_table_stored(*, g=DEFAULT_G, n=DEFAULT_N, n_photons=TABLE_PHOTONS, seed=0) -> bool:
    """Whether :func:`forward_table` of these media is shipped, cached or loaded (no tracing needed)."""
    name = _default_table_name(g, n, n_photons, seed)
    return name in _LOADED or (TABLES_DIR / name).exists() or (cache_dir() / name).exists()


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
    name = _default_table_name(g, n, n_photons, seed)
    if name in _LOADED:
        return _LOADED[name]
    for path in (TABLES_DIR / name, cache_dir() / name):
        if path.exists():
            try:
                _LOADED[name] = ForwardTable.load(path)
                return _LOADED[name]
            except (OSError, ValueError, KeyError):
                continue
    table = build_forward_table(g=g, n=n, n_photons=n_photons, seed=seed, progress=progress)
    write_or_warn(table.save, cache_dir() / name)
    _LOADED[name] = table
    return table


def _footprint(rows_per_camera_row):
    rpc = float(rows_per_camera_row)
    if rpc <= 1.0 + 1e-12:
        return np.zeros(1, np.int64), np.ones(1)
    half = int(np.ceil(0.5 * rpc + 0.5))
    f = np.arange(-half, half + 1)
    w = band_bin_weights(f, 0.0, rpc)
    return f, w / w.sum()


def _dipole_binned(s, a, n, offsets):
    """The dipole's line kernel binned to offsets ``0 .. reach`` (rows), per-row coefficients."""
    t, wt = np.polynomial.legendre.leggauss(16)
    x = np.asarray(offsets, np.float64)[:, None] + 0.5 * t[None, :]
    return (_dipole_line(np.abs(x), _dipole_per_row(s, a, n)) * (0.5 * wt)).sum(axis=1)


def _table_kernel(table: ForwardTable, log_s, log_a):
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


def _kernel_per_row(table: ForwardTable, log_s, log_a, offsets_rows, foot):
    """``K`` (not log) at per-row log-coefficients for the given signed offsets, footprint-averaged."""
    f, w = foot
    u = np.abs(np.asarray(offsets_rows, np.int64)[:, None] + f[None, :])  # (U, F)
    reach = table.offsets_rows[-1]
    k = _table_kernel(table, log_s, log_a)  # (..., U_table)
    inside = u <= reach
    vals = np.where(inside, k[..., np.minimum(u, reach)], 0.0)
    return (vals * w).sum(axis=-1)


# ------------------------------------------------------------------ container walls
# A pixel near a clear container wall loses the light that reaches the wall (Fresnel reflection
# back, the rest lost): the materials scene's Monte Carlo wall kernels (planeray.mc.wall).  The fit
# cannot trace a wall table for every trial medium, so it takes the *relative* wall effect from
# diffusion theory -- the dipole of the half-space (Farrell et al. 1992; the engine's hand-off)
# with its mirror images across the wall's extrapolated boundary, opposite sign (Haskell et al.
# 1994; the same method of images as planeray.mc.wall's continuation) -- and applies it to the
# Monte Carlo table kernel: K_wall(u) = K(u) * L_wall(u) / L(u), L the dipole's line kernels.
# Against the scene's Monte Carlo wall tables this ratio carries 78-99 % of the wall's effect (L1).

#: Wall angles the fit models: parallel to the projector's lines (0) and across them (90 degrees).
WALL_ANGLES_DEG = (0.0, 90.0)
#: Kinds of container wall: ``"clear"`` (air behind a thin clear wall: the medium's own index mismatch against air,
#: the extrapolated boundary ``2 A(n) D`` behind it, Haskell et al. 1994) or ``"black"`` (nothing returns: ``A = 1``;
#: also a clear wall of an index-matched medium).
WALL_KINDS = ("clear", "black")
#: The ``angle_deg`` of a ``walls`` row that is a layer's **bottom** (``distance_rows``: the layer's depth):
#: light that reaches it is lost (a layer on a dark or clear support, e.g. the 30 mm of liquid soap).
BOTTOM_ANGLE_DEG = 180.0
_Y_GRID = 200  # points of the along-line grid of the half-line integrals (sinh spaced)
_GL_X = (-0.25, 0.25)  # midpoints across an offset bin (the ratio of two binned kernels), parallel walls
_WALL_BINS_PER_E_FOLD = 20  # wall distances of a group pooled within 5 % (1 + d)
_WALL_PASSES = 12  # at most, of the fixed point of the walls' effect (fit_profiles)
_L_STEP = 0.125  # rows: the dipole's line kernel is interpolated from this grid (parallel walls)


def _dipole_per_row(s, a, n, wall_kind="clear"):
    """Dipole constants of a medium of per-row coefficients ``s = mu_s' h``, ``a = mu_a h``.

    ``z`` (the real and image sources under the top face) and ``z_b`` (the extrapolated boundary behind a container
    wall, :data:`WALL_KINDS`: the top's mismatch ``A(n)`` for a clear wall, ``A = 1`` for a black one).
    """
    st = s + a
    A = boundary_mismatch_A(n)
    A_wall = A if wall_kind == "clear" else 1.0
    z_r = 1.0 / st
    return dict(
        albedo=s / st, sigma_tr=math.sqrt(3.0 * a * st), z=(z_r, z_r * (1.0 + 4.0 * A / 3.0)),
        z_b=2.0 * A_wall / (3.0 * st), z_b_top=2.0 * A / (3.0 * st),
    )  # fmt: skip


def _source_line(x, z, st):
    """One diffusion source's term of a line kernel: ``z sigma_tr K1(sigma_tr rho) / rho``, ``rho = sqrt(x^2 + z^2)``.

    Half the line integral of ``z (sigma_tr r + 1) exp(-sigma_tr r) / r^3`` (the source's reflectance at
    depth ``z``, signed), ``x`` the lateral distance to the line (rows).
    """
    rho = np.sqrt(x * x + z * z)
    if st > 0:
        return z * st * k1e(st * rho) * np.exp(-st * rho) / rho
    return z / (rho * rho)


def _dipole_line(x, d):
    """Line integral of the dipole's reflectance at lateral distance ``x`` (rows): closed form.

    ``int R(sqrt(x^2 + y^2)) dy`` with ``z (sigma_tr r + 1) exp(-sigma_tr r) / r^3`` per source,
    whose line integral is ``2 z sigma_tr K1(sigma_tr rho) / rho`` (:func:`_source_line`).
    """
    x = np.asarray(x, np.float64)
    out = np.zeros_like(x)
    for z in d["z"]:
        out += _source_line(x, z, d["sigma_tr"])
    return d["albedo"] / (2.0 * np.pi) * out


def _layer_line(x, d, depth_rows, images=4):
    """Line integral of the reflectance of a layer ``depth_rows`` deep whose bottom loses the light.

    The dipole's image series for a slab (Contini et al. 1997, Appl. Opt. 36, 4587): the
    top's extrapolated boundary ``z_b`` above the surface (its Fresnel mismatch), the bottom's
    ``2 / (3 sigma_t')`` below the bottom (index-matched: nothing returns); sources ``z_r + m P``
    and images ``-2 z_b - z_r + m P``, period ``P = 2 (t + z_b + z_b')``, ``|m| <= images``.
    Each source's line integral is :func:`_source_line` with its signed depth ``z``; ``images = 0``
    of a deep layer is the semi-infinite dipole.
    """
    x = np.asarray(x, np.float64)
    z_r, z_b = d["z"][0], d["z_b_top"]
    z_b2 = 2.0 * z_r / 3.0  # 2 / (3 sigma_t'), A = 1
    period = 2.0 * (float(depth_rows) + z_b + z_b2)
    out = np.zeros_like(x)
    for m in range(-images, images + 1):
        for z, sign in ((z_r + m * period, 1.0), (-2.0 * z_b - z_r + m * period, -1.0)):
            out += sign * _source_line(x, z, d["sigma_tr"])
    return d["albedo"] / (2.0 * np.pi) * out


def _half_lines(x_abs, d, b_values):
    """``int_b^inf R(sqrt(x^2 + y^2)) dy`` for every ``x`` (rows, >= 0) and every ``b >= 0``: ``(X, B)``."""
    st = d["sigma_tr"]
    y_max = float(np.max(b_values)) + 40.0 / max(st, 1e-3) + 50.0
    c = 0.25
    y = c * np.sinh(np.linspace(0.0, math.asinh(y_max / c), _Y_GRID))
    r = np.sqrt(x_abs[:, None] ** 2 + y[None, :] ** 2)
    R = np.zeros_like(r)
    for z in d["z"]:
        rr = np.sqrt(r * r + z * z)
        R += z * (st * rr + 1.0) * np.exp(-st * rr) / rr**3
    R *= d["albedo"] / (4.0 * np.pi)
    seg = 0.5 * (R[:, 1:] + R[:, :-1]) * np.diff(y)[None, :]
    tail = np.concatenate(
        [np.cumsum(seg[:, ::-1], axis=1)[:, ::-1], np.zeros((x_abs.size, 1))], axis=1
    )  # int_{y_k}^{y_max}
    b = np.asarray(b_values, np.float64)
    k = np.clip(np.searchsorted(y, b) - 1, 0, y.size - 2)
    w = np.clip((b - y[k]) / (y[k + 1] - y[k]), 0.0, 1.0)
    return tail[:, k] * (1.0 - w) + tail[:, k + 1] * w


def _on_grid(t, values):
    """Linear interpolation of ``values`` (on a uniform grid) at fractional indices ``t >= 0``: ``np.interp``
    without its search (the grid is uniform), exact at the grid's points."""
    i = np.minimum(t.astype(np.int64), values.size - 2)
    return values[i] + (values[i + 1] - values[i]) * (t - i)


def _wall_term(k_table, log_s, log_a, n, offsets, foot, walls, wall_kind="clear"):
    """The walls' change of the footprint-averaged kernel (``(U,)``), to add to the wall-free kernel.

    ``walls``: array ``(M, 4)`` of ``[distance_rows, angle_deg (0 or 90; 180: a bottom), side (+1/-1), weight]``;
    each pixel's walls weigh ``1 / pixels`` of the profile (a block's mean profile: the mean of
    its pixels' kernels), the effects of several walls add (as in the scene).
    """
    reach = k_table.size - 1
    f, w = foot
    d = _dipole_per_row(math.exp(log_s), math.exp(log_a), n, wall_kind)
    x = np.asarray(offsets, np.float64)[:, None] - f[None, :]  # line offset seen by the pencil at f: (U, F)
    kk = np.where(np.abs(x) <= reach, k_table[np.minimum(np.abs(x), reach).astype(np.int64)], 0.0)
    term = np.zeros(x.shape[0])
    sub = np.asarray(_GL_X)
    par = walls[walls[:, 1] == 0.0]
    if par.size:
        dist, side, wt = par[:, 0], par[:, 2], par[:, 3]
        # In the wall's frame (wall on the positive side): offset side * x, the pencil at f is side * f closer.
        xx = side[:, None, None] * x[None] + sub[:, None, None, None]  # (S, M, U, F)
        aa = dist[:, None, None] - side[:, None, None] * f[None, None, :]  # (M, 1, F)
        img = 2.0 * (aa + d["z_b"]) - xx
        grid = np.arange(0.0, max(float(np.abs(xx).max()), float(np.abs(img).max())) + 2 * _L_STEP, _L_STEP)
        Lg = _dipole_line(grid, d)  # smooth in x; |xx| lies on the grid, the images between its points
        L = _on_grid(np.abs(xx) / _L_STEP, Lg)
        Lw = np.where(xx < aa, L - _on_grid(np.abs(img) / _L_STEP, Lg), 0.0)
        ratio = Lw.sum(axis=0) / np.maximum(L.sum(axis=0), 1e-300)
        term += (wt[:, None] * ((ratio - 1.0) * kk[None] * w).sum(axis=-1)).sum(axis=0)
    per = walls[walls[:, 1] == 90.0]
    if per.size:
        dist, wt = per[:, 0], per[:, 3]
        u = np.asarray(offsets, np.float64)
        xs, back = np.unique(np.abs(u), return_inverse=True)  # the kernel is symmetric in x
        M = dist.size
        H = _half_lines(xs, d, np.concatenate([dist, dist + 2.0 * d["z_b"]]))
        L = _dipole_line(xs, d)
        ratio = ((L[:, None] - H[:, :M] - H[:, M:]) / np.maximum(L, 1e-300)[:, None])[back]  # (U, M)
        term += ((ratio - 1.0) * wt[None, :]).sum(axis=1) * (kk * w).sum(axis=-1)
    bottom = walls[walls[:, 1] == BOTTOM_ANGLE_DEG]
    if bottom.size:
        u = np.abs(np.asarray(offsets, np.float64))
        L = _dipole_line(u, d)
        for depth, wt in bottom[:, [0, 3]]:
            ratio = _layer_line(u, d, depth) / np.maximum(L, 1e-300)
            term += wt * (ratio - 1.0) * (kk * w).sum(axis=-1)
    return term


def _model_kernel(table: ForwardTable, log_s, log_a, offsets_rows, foot, walls=None, wall_kind="clear"):
    """The pixel's (or block's) kernel at per-row log-coefficients: the table's, changed by the walls."""
    base = _kernel_per_row(table, log_s, log_a, offsets_rows, foot)
    if walls is None or not len(walls):
        return base
    k = _table_kernel(table, log_s, log_a)
    term = _wall_term(k, log_s, log_a, table.n, offsets_rows, foot, np.asarray(walls, float), wall_kind)
    return np.maximum(base + term, 0.0)


def _check_wall_kind(wall_kind) -> str:
    if wall_kind not in WALL_KINDS:
        raise InputError(f"wall_kind must be one of {', '.join(WALL_KINDS)}, got {wall_kind!r}")
    return wall_kind


def line_kernel(
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
    return _model_kernel(
        table, math.log(s), math.log(a), offsets, _footprint(rows_per_camera_row), w, _check_wall_kind(wall_kind)
    )


def container_wall_distances(containers, *, rows_per_camera_row) -> np.ndarray:
    """Distance from each pixel's centre to its container's walls, down, up, right and left.

    A container is a connected run of one label; the wall lies halfway between its last
    pixel and the first pixel of another label (a pixel's resolution); where the run
    reaches the image's border there is no wall (``inf``: the medium goes on beyond the
    field of view).  Camera pixels are square, ``rows_per_camera_row`` projector rows wide.

    Parameters
    ----------
    containers : ndarray (H, W) of int
        Container labels (0: not a container).
    rows_per_camera_row : float
        Projector rows one camera row spans.

    Returns
    -------
    ndarray (H, W, 4) of float
        Projector rows to the wall below (toward positive offsets), above, right and left of
        the pixel; NaN outside the containers.
    """
    lab = np.asarray(containers)
    if lab.ndim != 2:
        raise InputError(f"containers must be a 2-D label image, got shape {lab.shape}")
    rpc = float(rows_per_camera_row)

    def forward(a):  # (N, L): pixels to the first other label after each pixel, along axis 1
        n, m = a.shape
        out = np.full(a.shape, np.inf)
        idx = np.arange(m)
        for i in range(n):
            change = np.flatnonzero(a[i, 1:] != a[i, :-1]) + 1  # first pixel of each new run
            if not change.size:
                continue
            j = np.searchsorted(change, idx, side="right")
            has = j < change.size
            out[i, has] = change[np.minimum(j, change.size - 1)][has] - idx[has]
        return (out - 0.5) * rpc

    down = forward(lab.T).T
    up = forward(lab[::-1].T).T[::-1]
    right = forward(lab)
    left = forward(lab[:, ::-1])[:, ::-1]
    d = np.stack([down, up, right, left], axis=-1)
    d[lab == 0] = np.nan
    return d


# (angle_deg, side) of the four directions of :func:`container_wall_distances`.
_WALL_DIRECTIONS = ((0.0, 1.0), (0.0, -1.0), (90.0, 1.0), (90.0, -1.0))


def _group_walls(distances, per_e_fold=_WALL_BINS_PER_E_FOLD):
    """The walls of a group of pixels (their mean kernel): ``(M, 4)`` rows of :func:`fit_profiles`' ``walls``.

    Distances are pooled in bins of ``1 / per_e_fold`` in ``log(1 + d)`` (their weighted mean kept), so
    a large region costs a few dozen walls per direction, not one per pixel row or column.
    """
    d = np.asarray(distances, np.float64).reshape(-1, 4)
    n = d.shape[0]
    rows = []
    for k, (ang, side) in enumerate(_WALL_DIRECTIONS):
        v = d[:, k][np.isfinite(d[:, k])]
        if v.size:
            key, inv = np.unique(np.round(np.log1p(v) * per_e_fold), return_inverse=True)
            cnt = np.bincount(inv, minlength=key.size)
            mean = np.bincount(inv, weights=v, minlength=key.size) / cnt
            rows.append(np.stack([mean, np.full(key.size, ang), np.full(key.size, side), cnt / n], axis=1))
    return np.concatenate(rows) if rows else np.zeros((0, 4))


@dataclass(frozen=True)
class FitResult:
    """Fitted coefficients of a set of profiles (one per pixel or region).

    Attributes
    ----------
    mu_s_prime_per_mm, mu_a_per_mm : ndarray (P,)
        Estimates, mm^-1; NaN where not identifiable (see ``mask``).
    mu_s_prime_se_per_mm, mu_a_se_per_mm : ndarray (P,)
        Standard errors, mm^-1 (NaN with the estimate).
    scale : ndarray (P,)
        Fitted calibration scale ``c`` (1 when ``calibrated``).
    mask : ndarray (P,) uint8
        Bits of :data:`REASONS`; 0 = both parameters identified.
    chi2_per_dof : ndarray (P,)
        Reduced chi-square at the optimum (``sigma`` given) or the residual variance (not given).
    model : ndarray (P, U)
        The fitted kernels ``c K`` (for plots).
    calibrated : bool
        Whether the magnitude was used (absolute reflectance) or only the shape.
    log_estimate_per_mm, log_se : ndarray (P, 2) or None
        ``ln mu_s'``, ``ln mu_a`` (mm^-1) at the optimum and their standard errors, *before*
        the identifiability NaNs (NaN only where no fit ran): for recognition, which weighs
        a poorly constrained estimate by its error (:mod:`planeray.materials.library`).
    dof : ndarray (P,) of int or None
        Degrees of freedom of each fit (samples minus parameters; 0 where no fit ran).
    flags : ndarray (P,) uint8 or None
        Bits of :data:`planeray.goodness.FLAGS`: the model does not fit (chi-square past the
        threshold at ``dof``; the standard errors are then inflated by ``sqrt(chi2 / dof)``), a
        parameter at the forward model's edge, not fitted.
    """

    mu_s_prime_per_mm: np.ndarray
    mu_a_per_mm: np.ndarray
    mu_s_prime_se_per_mm: np.ndarray
    mu_a_se_per_mm: np.ndarray
    scale: np.ndarray
    mask: np.ndarray
    chi2_per_dof: np.ndarray
    model: np.ndarray
    calibrated: bool
    log_estimate_per_mm: np.ndarray | None = None
    log_se: np.ndarray | None = None
    dof: np.ndarray | None = None
    flags: np.ndarray | None = None

    def quality(self, i: int = 0):
        """:class:`planeray.goodness.FitQuality` of profile ``i`` (None where no fit ran)."""
        if self.dof is None or not np.isfinite(self.chi2_per_dof[i]) or self.dof[i] <= 0:
            return None
        return fit_quality(self.chi2_per_dof[i] * self.dof[i], int(self.dof[i]))


def _cell_rel(table_rel, gs, ga, log_s, log_a):
    """Largest table relative error per offset over the grid cell that holds ``(log_s, log_a)``."""
    i = int(np.clip(np.searchsorted(gs, log_s) - 1, 0, gs.size - 2))
    j = int(np.clip(np.searchsorted(ga, log_a) - 1, 0, ga.size - 2))
    return table_rel[i : i + 2, j : j + 2].max(axis=(0, 1))


def _forward_jac(resid, step=1e-4):
    """Forward-difference Jacobian with an absolute step in the log-parameters (scipy's relative step
    is 0 at a parameter that is exactly 0, e.g. ``log c`` of a perfectly calibrated profile)."""

    def jac(x, *args):
        r0 = resid(x)
        cols = []
        for i in range(len(x)):
            xi = np.array(x, float)
            xi[i] += step
            cols.append((resid(xi) - r0) / step)
        return np.stack(cols, axis=1)

    return jac


def describe_reasons(bits: int) -> list[str]:
    """The reasons (:data:`REASONS`) set in a mask value."""
    return [text for bit, text in REASONS.items() if int(bits) & bit]


#: Mask bits that leave ``mu_s'`` / ``mu_a`` without an estimate (a ``mu_a`` beside a ``mu_s'`` stuck at the edge is none).
_MU_S_BAD = 1 | 2 | 8 | 32 | 64
_MU_A_BAD = 1 | 2 | 4 | 16 | 64


def _log_bounds(table: ForwardTable):
    """``(lo, hi)``: the fit's bounds in per-row ``(log mu_s', log mu_a)``, the dipole beyond the table's ``mu_s'``."""
    (s0, s1), (a0, a1) = table.bounds_per_row
    s1 = max(s1, DIPOLE_MU_S_PRIME_MAX_PER_ROW)
    return np.array([math.log(s0), math.log(a0)]), np.array([math.log(s1), math.log(a1)])


def _grid_starts(table: ForwardTable, offsets, foot):
    """The table's grid points ``(G, 2)`` in per-row log-coefficients and their kernels ``(G, U)``: the coarse start."""
    GS, GA = np.meshgrid(np.log(table.mu_s_prime_per_row), np.log(table.mu_a_per_row), indexing="ij")
    starts = np.stack([GS.ravel(), GA.ravel()], axis=1)
    return starts, _kernel_per_row(table, starts[:, 0], starts[:, 1], offsets, foot)


def _bottom_row(depth_mm, region, mm_per_row):
    """A region's bottom as a ``walls`` row (``depth_mm``: one value or ``{region: depth}``), None: semi-infinite."""
    v = depth_mm.get(region) if isinstance(depth_mm, dict) else depth_mm
    if v is None or not np.isfinite(float(v)):
        return None
    if not float(v) > 0:
        raise InputError(f"depth_mm must be positive, got {v!r}")
    return np.array([[float(v) / float(mm_per_row), BOTTOM_ANGLE_DEG, 0.0, 1.0]])


def _out_of_range(log_s_per_row, bottom, distances) -> bool:
    """Whether a fit's walls or bottom lie within :data:`DIFFUSION_RANGE_MFP` transport mean free paths.

    ``log_s_per_row``: the fitted ``log(mu_s' h)``; ``bottom``: :func:`_bottom_row` (rows) or None; ``distances``:
    the region's pixels' wall distances (:func:`container_wall_distances`, rows) or None -- the median pixel's
    nearest wall counts.
    """
    if not np.isfinite(log_s_per_row):
        return False
    reach = DIFFUSION_RANGE_MFP / math.exp(float(log_s_per_row))  # rows
    if bottom is not None and bottom[0, 0] < reach:
        return True
    if distances is not None and len(distances):
        d = np.asarray(distances, np.float64).reshape(-1, 4)
        nearest = np.min(np.where(np.isfinite(d), d, np.inf), axis=1)
        return bool(np.median(nearest) < reach)
    return False


def _regions_and_walls(labels, containers, shape, rows_per_camera_row, what):
    """The region labels (default one region) and each pixel's wall distances (None without ``containers``)."""
    lab = np.ones(shape, np.int64) if labels is None else np.asarray(labels, np.int64)
    if lab.shape != tuple(shape):
        raise InputError(f"labels have shape {lab.shape}, the {what} {tuple(shape)}")
    if containers is None:
        return lab, None
    if np.shape(containers) != tuple(shape):
        raise InputError(f"containers have shape {np.shape(containers)}, the {what} {tuple(shape)}")
    return lab, container_wall_distances(containers, rows_per_camera_row=rows_per_camera_row)


def fit_profiles(
    profiles,
    *,
    offsets_rows,
    mm_per_row,
    sigma=None,
    calibrated=False,
    rows_per_camera_row=1.0,
    table: ForwardTable | None = None,
    max_relative_se=MAX_RELATIVE_SE,
    model_relative_sd=MODEL_RELATIVE_SD,
    walls=None,
    wall_kind: str = "clear",
    p_misfit=DEFAULT_P_MISFIT,
) -> FitResult:
    """Fit ``mu_s'`` and ``mu_a`` to line-kernel profiles (weighted least squares in log-parameters).

    Parameters
    ----------
    profiles : array_like (P, U) or (U,)
        Transport profiles ``T(u)`` (demultiplexed, or a region's mean), in reflectance per
        offset bin when ``calibrated`` (divided by a white reference), else any unit.
    offsets_rows : array_like of int (U,)
        Their offsets, projector rows.
    mm_per_row : float
        Size of one projector row on the surface, mm.
    sigma : array_like, optional
        Standard deviation of every sample (broadcast to ``profiles``), same unit.  Without
        it the samples weigh equally and the errors come from the residual spread.
    calibrated : bool
        Use the magnitude (``c = 1``); otherwise fit a free scale and use the shape only.
    rows_per_camera_row : float
        Projector rows a camera row spans.
    table : ForwardTable, optional
        Default :func:`forward_table`.
    max_relative_se : float
        A parameter with a larger relative standard error is NaN (reason in ``mask``).
    model_relative_sd : float
        Relative uncertainty of the forward model's interpolation; with the table's own Monte
        Carlo relative error per offset (at the start grid point) it is added in quadrature to
        ``sigma`` (as a share of the data): without it, precise samples would fit the table's
        own errors.  Only with ``sigma``; 0 leaves the model's error out (data made by the
        table itself).
    walls : sequence of (ndarray (M, 4) or None), optional
        Per profile, the container walls its pixels see (:func:`container_wall_distances`): rows of
        ``[distance_rows, angle_deg, side, weight]`` -- a clear wall (air behind it) at
        ``distance_rows`` projector rows from a pixel, parallel (``angle_deg`` 0; ``side`` +1
        toward positive offsets, -1 negative) or perpendicular (90) to the lit lines, weighing
        ``weight`` (the share of the profile's pixels that see it).  The model is then the
        table's kernel times the walls' relative effect from diffusion theory (method of
        images; :func:`line_kernel` with ``walls``); a row of angle :data:`BOTTOM_ANGLE_DEG` is
        the bottom of a layer ``distance_rows`` deep (weight 1).  None: a semi-infinite medium
        without walls.
    wall_kind : {"clear", "black"}
        The walls' kind (:data:`WALL_KINDS`).
    p_misfit : float
        A fit whose chi-square is less probable than this is flagged "model does not fit"
        (:func:`planeray.goodness.fit_quality`).

    Returns
    -------
    FitResult
        Standard errors from the Jacobian, scaled by ``sqrt(chi2 / dof)`` where that exceeds 1 (the
        misfit inflates them; the model's own error is in ``sigma`` through ``model_relative_sd``).
    """
    table = table or forward_table()
    _check_wall_kind(wall_kind)
    Y = np.atleast_2d(np.asarray(profiles, np.float64))
    if walls is not None and len(walls) != Y.shape[0]:
        raise InputError(f"walls has {len(walls)} entries, one per profile expected ({Y.shape[0]})")
    offsets = np.asarray(offsets_rows)
    if offsets.ndim != 1 or offsets.size != Y.shape[1]:
        raise InputError(f"offsets_rows has {offsets.size} values, the profiles {Y.shape[1]} samples")
    if not float(mm_per_row) > 0:
        raise InputError(f"mm_per_row must be positive, got {mm_per_row!r}")
    S = np.ones_like(Y) if sigma is None else np.broadcast_to(np.asarray(sigma, np.float64), Y.shape)
    if np.any(~(S > 0)):
        raise InputError("sigma must be positive everywhere")
    # The table's own relative Monte Carlo error per offset (added to sigma at the start grid point).
    with np.errstate(divide="ignore", invalid="ignore"):
        table_rel = np.clip(np.nan_to_num(table.kernel_stderr / table.kernel, nan=1.0, posinf=1.0), 0.0, 1.0)
    u_tab = np.minimum(np.abs(offsets).astype(np.int64), table.offsets_rows[-1])
    h = float(mm_per_row)
    foot = _footprint(rows_per_camera_row)
    lo, hi = _log_bounds(table)
    P = Y.shape[0]
    out = {k: np.full(P, np.nan) for k in ("s", "a", "se_s", "se_a", "chi2")}
    scale = np.ones(P)
    mask = np.zeros(P, np.uint8)
    model = np.full(Y.shape, np.nan)
    raw, raw_se = np.full((P, 2), np.nan), np.full((P, 2), np.nan)
    dofs = np.zeros(P, np.int64)
    # A coarse start: the grid point of least misfit (shape only, scale solved in closed form).
    gs, ga = np.log(table.mu_s_prime_per_row), np.log(table.mu_a_per_row)
    starts, Kg = _grid_starts(table, offsets, foot)
    edge_tol = 0.02
    for p in range(P):
        y, sd = Y[p], S[p]
        wp = None if walls is None or walls[p] is None or not len(walls[p]) else np.asarray(walls[p], np.float64)
        ok = np.isfinite(y)
        if np.count_nonzero(ok & (y > 0)) < 4:
            mask[p] |= 1
            continue
        wy = np.where(ok, y / sd, 0.0)
        rho_g, tried = 1.0, set()
        for _ in range(4 if wp is not None else 1):
            # With walls: the grid kernels times the walls' effect at the best point so far, until it stays.
            wK = np.where(ok, Kg * rho_g / sd, 0.0)
            if calibrated:
                c_g = np.ones(len(Kg))
            else:
                c_g = np.maximum((wK @ wy) / np.maximum((wK * wK).sum(axis=1), 1e-300), 1e-300)
            cost_g = ((wy[None, :] - c_g[:, None] * wK) ** 2).sum(axis=1)
            g0 = int(np.argmin(cost_g))
            if wp is None or g0 in tried:
                break
            tried.add(g0)
            k_free = Kg[g0]
            k_wall = _model_kernel(table, starts[g0, 0], starts[g0, 1], offsets, foot, wp, wall_kind)
            rho_g = np.where(k_free > 0, k_wall / np.where(k_free > 0, k_free, 1.0), 0.0)
        sd0 = sd
        x0 = list(starts[g0])
        lo_p, hi_p = list(lo), list(hi)
        if not calibrated:
            x0.append(math.log(c_g[g0]))
            lo_p.append(-np.inf)
            hi_p.append(np.inf)
        x0 = np.clip(x0, np.array(lo_p) + 1e-9, np.array(hi_p) - 1e-9)
        # Two passes when sigma is given: the model's own error (the table's Monte Carlo error per
        # offset, largest of the grid cell around the estimate, plus the interpolation share) joins
        # the data's; first that of the start's cell, then of the first estimate's.
        # With walls, their relative effect (diffusion theory, costly) is evaluated at the current
        # estimate and held during a pass, until the estimate stops moving (a fixed point, exact for
        # data the model describes).
        model_error = sigma is not None and model_relative_sd > 0
        passes = _WALL_PASSES if wp is not None else 2 if model_error else 1
        try:
            for i_pass in range(passes):
                x_prev = np.array(x0, float)
                if model_error:
                    rel = float(model_relative_sd) + _cell_rel(table_rel, gs, ga, x0[0], x0[1])[u_tab]
                    sd = np.hypot(sd0, rel * np.nan_to_num(np.abs(y)))
                rho = 1.0
                if wp is not None:
                    k_free = _kernel_per_row(table, x0[0], x0[1], offsets, foot)
                    k_wall = _model_kernel(table, x0[0], x0[1], offsets, foot, wp, wall_kind)
                    rho = np.where(k_free > 0, k_wall / np.where(k_free > 0, k_free, 1.0), 0.0)

                def resid(x, y=y, sd=sd, ok=ok, rho=rho):
                    k = _kernel_per_row(table, x[0], x[1], offsets, foot) * rho
                    c = math.exp(x[2]) if len(x) > 2 else 1.0
                    return np.where(ok, (c * k - y) / sd, 0.0)

                res = least_squares(resid, x0, jac=_forward_jac(resid), bounds=(lo_p, hi_p), method="trf", x_scale=1.0)
                x0 = np.clip(res.x, np.array(lo_p) + 1e-9, np.array(hi_p) - 1e-9)
                if wp is not None and i_pass >= 1 and np.max(np.abs(x0[:2] - x_prev[:2])) < 1e-3:
                    break
            if wp is not None:  # polish with the walls' effect evaluated at every trial (the exact Jacobian)

                def resid(x, y=y, sd=sd, ok=ok, wp=wp):
                    k = _model_kernel(table, x[0], x[1], offsets, foot, wp, wall_kind)
                    c = math.exp(x[2]) if len(x) > 2 else 1.0
                    return np.where(ok, (c * k - y) / sd, 0.0)

                res = least_squares(resid, x0, jac=_forward_jac(resid), bounds=(lo_p, hi_p), method="trf", x_scale=1.0)
        except (ValueError, np.linalg.LinAlgError):
            mask[p] |= 64
            continue
        if not res.success:
            mask[p] |= 64
        n_dof = max(int(ok.sum()) - len(x0), 1)
        dofs[p] = n_dof
        chi2 = float(2.0 * res.cost / n_dof)
        J = res.jac
        try:
            cov = np.linalg.pinv(J.T @ J)
        except np.linalg.LinAlgError:
            cov = np.full((len(x0), len(x0)), np.inf)
        # without sigma the residual variance is the noise; with it, a misfit beyond the noise (and the model's
        # error in it) widens the errors by sqrt(chi2 / dof) (planeray.goodness, the Birge ratio)
        cov = cov * (chi2 if sigma is None else max(chi2, 1.0))
        se_log = np.sqrt(np.maximum(np.diag(cov), 0.0))
        x = res.x
        s_est, a_est = math.exp(x[0]) / h, math.exp(x[1]) / h
        out["s"][p], out["a"][p] = s_est, a_est
        out["se_s"][p], out["se_a"][p] = s_est * se_log[0], a_est * se_log[1]
        out["chi2"][p] = chi2
        raw[p], raw_se[p] = x[:2] - math.log(h), se_log[:2]
        scale[p] = math.exp(x[2]) if len(x) > 2 else 1.0
        model[p] = scale[p] * _model_kernel(table, x[0], x[1], offsets, foot, wp, wall_kind)
        if min(x[0] - lo[0], hi[0] - x[0]) < edge_tol:
            mask[p] |= 2
        if min(x[1] - lo[1], hi[1] - x[1]) < edge_tol:
            mask[p] |= 4
        if not se_log[0] <= max_relative_se:
            mask[p] |= 8
        if not se_log[1] <= max_relative_se:
            mask[p] |= 16
        k0 = _kernel_per_row(table, x[0], x[1], np.array([0, 1]), _footprint(1.0))
        if k0[1] < 0.05 * k0[0] and float(rows_per_camera_row) <= 1.0 + 1e-12:
            mask[p] |= 32
    bad_s = (mask & _MU_S_BAD) > 0
    bad_a = (mask & _MU_A_BAD) > 0
    for k in ("s", "se_s"):
        out[k][bad_s] = np.nan
    for k in ("a", "se_a"):
        out[k][bad_a] = np.nan
    flags = np.zeros(P, np.uint8)
    for p in range(P):
        if dofs[p] == 0:
            flags[p] = FLAG_NOT_FITTED
            continue
        if sigma is not None and not fit_quality(out["chi2"][p] * dofs[p], dofs[p], p_misfit=p_misfit).fits:
            flags[p] |= FLAG_MISFIT
        if mask[p] & (2 | 4):
            flags[p] |= FLAG_EDGE
    return FitResult(
        mu_s_prime_per_mm=out["s"],
        mu_a_per_mm=out["a"],
        mu_s_prime_se_per_mm=out["se_s"],
        mu_a_se_per_mm=out["se_a"],
        scale=scale,
        mask=mask,
        chi2_per_dof=out["chi2"],
        model=model,
        calibrated=bool(calibrated),
        log_estimate_per_mm=raw,
        log_se=raw_se,
        dof=dofs,
        flags=flags,
    )


@dataclass(frozen=True)
class TransportFit:
    """Maps and per-region results of :func:`fit_transport`.

    Attributes
    ----------
    maps : dict of str -> ndarray (H, W)
        ``mu_s_prime_per_mm``, ``mu_a_per_mm``, ``mu_s_prime_se_per_mm``, ``mu_a_se_per_mm``
        (float32, NaN where not fitted or not identifiable) and ``mask`` (uint8, the bits of
        :data:`REASONS`; 255: not fitted -- outside every region or no pixel block).
    regions : dict of int -> dict
        Per label: pixels, the fit of the region's mean profile (estimates, standard errors,
        reasons) and the median of the block estimates.
    profiles : dict of int -> (data, sigma, model)
        The regions' mean profiles, their standard errors and the fitted kernels (for figures).
    offsets_rows : ndarray
        The profiles' offsets (projector rows); for a stack fit the used images' indices.
    calibrated : bool
    source : str
        ``"transport"`` (:func:`fit_transport`: ``profiles`` are transport profiles over offsets) or
        ``"stack"`` (:func:`planeray.materials.stackfit.fit_stack`: the regions' mean stack images).
    """

    maps: dict
    regions: dict
    profiles: dict
    offsets_rows: np.ndarray
    calibrated: bool
    source: str = "transport"


def white_reference_scale(white_dense, *, albedo=1.0):
    """Per-pixel calibration from the transport of a white Lambertian reference of known ``albedo``.

    A Lambertian surface of albedo ``rho`` returns ``rho`` summed over the offsets (the
    scenes' unit); dividing a profile by ``sum_u T_white(u) / rho`` of the same pixel puts it
    in Lambertian-equivalent reflectance per offset, the unit of :func:`line_kernel`.

    Parameters
    ----------
    white_dense : ndarray (H, W, U)
        Transport of the reference, same sweep and camera settings.
    albedo : float
        Its albedo in (0, 1].

    Returns
    -------
    ndarray (H, W)
        The divisor (NaN where the reference is dark).
    """
    if not 0.0 < float(albedo) <= 1.0:
        raise InputError(f"the white reference's albedo must be in (0, 1], got {albedo!r}")
    total = np.asarray(white_dense, np.float64).sum(axis=-1) / float(albedo)
    return np.where(total > 0, total, np.nan)


def fit_transport(
    transport,
    *,
    mm_per_row,
    labels=None,
    white_scale=None,
    block_px=4,
    containers=None,
    table: ForwardTable | None = None,
    depth_mm=None,
    regions_only: bool = False,
    wall_kind: str = "clear",
    p_misfit=DEFAULT_P_MISFIT,
    progress=None,
) -> TransportFit:
    """Fit ``mu_s'`` and ``mu_a`` over a transport: maps (per pixel block) and per-region results.

    Parameters
    ----------
    transport : Transport
        Demultiplexed (or ground-truth) transport.
    mm_per_row : float
        Size of one projector row on the surface, mm.
    labels : ndarray (H, W) of int, optional
        Regions (0: left out).  Default: every pixel one region (1).
    white_scale : ndarray (H, W), optional
        :func:`white_reference_scale`: given, the fit is calibrated (absolute reflectance);
        otherwise shape only.
    block_px : int
        Pixels are averaged in ``block_px x block_px`` blocks (within a region) before
        fitting; the block's estimate fills its pixels.  1: every pixel.
    containers : ndarray (H, W) of int, optional
        The containers (labels; often ``labels`` itself): given, each container's boundary is
        a clear wall (air behind it; the image's border is none) and every block's and
        region's model is the mean kernel of its pixels with their walls
        (:func:`container_wall_distances`, :func:`fit_profiles`' ``walls``).  Without it the
        media are unbounded, and pixels near walls read the light lost through them as
        absorption.
    table : ForwardTable, optional
    depth_mm : float or dict, optional
        Depth (mm) of a layer whose bottom loses the light (``walls`` row of angle
        :data:`BOTTOM_ANGLE_DEG`): one value for every region, or ``{region: depth_mm}``;
        default every medium semi-infinite.
    regions_only : bool
        Fit the regions only (the maps stay NaN, mask 255): the blocks still give each
        region's noise, but are not fitted themselves (with walls, most of the time).
    wall_kind : {"clear", "black"}
        The containers' walls (:data:`WALL_KINDS`).
    p_misfit : float
        Chi-square probability below which a fit is flagged "model does not fit" (:mod:`planeray.goodness`).
    progress : callable, optional
        Called with the number of fits just done.

    Returns
    -------
    TransportFit
        ``maps["flags"]`` is the flag layer (bits of :data:`planeray.goodness.FLAGS`, 255 outside every
        region); each region's summary carries its ``fit_quality``, ``flags`` and ``model_fits``.

    Notes
    -----
    Samples whose transport is 0 (a line that misses the container, beyond the band) carry no
    information and are left out.  A block's noise is taken from the spread of its pixels
    (standard error of the mean, floored at 1 % of the block's peak); a region's from the
    spread of its blocks.
    """
    table = table or forward_table()
    dense = np.asarray(transport.dense, np.float64)
    H, W, U = dense.shape
    offsets = np.asarray(transport.offsets_rows)
    rpc = transport.geometry.rows_per_camera_row
    calibrated = white_scale is not None
    if calibrated:
        dense = dense / np.asarray(white_scale, np.float64)[..., None]
    lab, dist = _regions_and_walls(labels, containers, (H, W), rpc, "transport")
    b = int(block_px)
    if b < 1:
        raise InputError(f"block_px must be >= 1, got {block_px!r}")

    def depth_of(region):
        return _bottom_row(depth_mm, region, mm_per_row)

    def with_bottom(walls, bottom):
        if bottom is None:
            return walls
        return bottom if walls is None else np.concatenate([np.asarray(walls, np.float64).reshape(-1, 4), bottom])

    maps = {k: np.full((H, W), np.nan, np.float32) for k in _MAP_NAMES}
    maps["mask"] = np.full((H, W), 255, np.uint8)
    maps["flags"] = np.full((H, W), 255, np.uint8)
    _check_wall_kind(wall_kind)
    fit_kw = dict(wall_kind=wall_kind, p_misfit=p_misfit)
    regions, profiles = {}, {}
    for region in sorted(int(v) for v in np.unique(lab) if v != 0):
        inside = lab == region
        bottom = depth_of(region)
        blocks, means, sds, walls = [], [], [], []
        for r0 in range(0, H, b):
            for c0 in range(0, W, b):
                m = inside[r0 : r0 + b, c0 : c0 + b]
                if not m.any():
                    continue
                px = dense[r0 : r0 + b, c0 : c0 + b][m]  # (n, U)
                mean = px.mean(axis=0)
                sd = px.std(axis=0, ddof=1) / math.sqrt(px.shape[0]) if px.shape[0] > 1 else np.zeros(U)
                means.append(mean)
                sds.append(np.maximum(sd, 0.01 * max(float(np.abs(mean).max()), 1e-30)))
                blocks.append((r0, c0, m))
                if dist is not None or bottom is not None:
                    wb = None if dist is None else _group_walls(dist[r0 : r0 + b, c0 : c0 + b][m])
                    walls.append(with_bottom(wb, bottom))
        if not blocks:
            continue
        Y = np.stack(means)
        Y[Y == 0] = np.nan
        S = np.stack(sds)
        res = None
        if not regions_only:
            res = fit_profiles(
                Y, offsets_rows=offsets, mm_per_row=mm_per_row, sigma=S, calibrated=calibrated,
                rows_per_camera_row=rpc, table=table, walls=walls or None, **fit_kw,
            )  # fmt: skip
            if progress is not None:
                progress(len(blocks))
        for i, (r0, c0, m) in enumerate(blocks if res is not None else ()):
            sl = (slice(r0, r0 + b), slice(c0, c0 + b))
            for name, val in zip(
                _MAP_NAMES,
                (res.mu_s_prime_per_mm, res.mu_a_per_mm, res.mu_s_prime_se_per_mm, res.mu_a_se_per_mm),
            ):
                maps[name][sl][m] = val[i]
            maps["mask"][sl][m] = res.mask[i]
            maps["flags"][sl][m] = res.flags[i]
        # The region: its mean profile, noise from the spread of its blocks.
        fin = np.isfinite(Y)
        cnt = fin.sum(axis=0)
        Y0 = np.where(fin, Y, 0.0)
        y = np.where(cnt > 0, Y0.sum(axis=0) / np.maximum(cnt, 1), np.nan)  # nanmean without the warning
        var = np.where(fin, (Y0 - y) ** 2, 0.0).sum(axis=0) / np.maximum(cnt - 1, 1)
        s = np.sqrt(var) / np.sqrt(np.maximum(cnt, 1)) if len(blocks) > 2 else S[0]
        s = np.where(np.isfinite(s) & (s > 0) & (cnt > 2), s, np.nanmax(S))
        s = np.maximum(s, 1e-3 * np.nanmax(np.abs(y)))
        rw = None
        if dist is not None:
            # With the walls modelled, the region's profile is the mean of its pixels, zeros (lines
            # beyond a wall) included: its model is the mean of the pixels' kernels with their walls.
            y = dense[inside].mean(axis=0)
            y[y == 0] = np.nan
            rw = [_group_walls(dist[inside])]
        if bottom is not None:
            rw = [with_bottom(None if rw is None else rw[0], bottom)]
        rr = fit_profiles(
            y, offsets_rows=offsets, mm_per_row=mm_per_row, sigma=s, calibrated=calibrated,
            rows_per_camera_row=rpc, table=table, walls=rw, **fit_kw,
        )  # fmt: skip
        flag0 = int(rr.flags[0])
        log_s_row = rr.log_estimate_per_mm[0, 0] + math.log(float(mm_per_row))
        if _out_of_range(log_s_row, bottom, None if dist is None else dist[inside]):
            flag0 |= FLAG_RANGE
        if res is None:
            maps["flags"][inside] = flag0
        q = rr.quality(0)
        regions[region] = {
            "pixels": int(inside.sum()),
            "blocks": len(blocks),
            "mu_s_prime_per_mm": _num(rr.mu_s_prime_per_mm[0]),
            "mu_s_prime_se_per_mm": _num(rr.mu_s_prime_se_per_mm[0]),
            "mu_a_per_mm": _num(rr.mu_a_per_mm[0]),
            "mu_a_se_per_mm": _num(rr.mu_a_se_per_mm[0]),
            "not_identifiable": describe_reasons(int(rr.mask[0])),
            "chi2_per_dof": _num(rr.chi2_per_dof[0]),
            "fit_quality": None if q is None else q.to_json(),
            "model_fits": None if q is None else q.fits,
            "flags": describe_flags(flag0),
            "flag_bits": flag0,
            "blocks_flagged": None if res is None else float(((res.flags & (FLAG_MISFIT | FLAG_EDGE)) > 0).mean()),
            "blocks_median_mu_s_prime_per_mm": None if res is None else _nanmedian(res.mu_s_prime_per_mm),
            "blocks_median_mu_a_per_mm": None if res is None else _nanmedian(res.mu_a_per_mm),
            "blocks_identified": None
            if res is None
            else {
                "mu_s_prime": float(np.isfinite(res.mu_s_prime_per_mm).mean()),
                "mu_a": float(np.isfinite(res.mu_a_per_mm).mean()),
            },
        }
        profiles[region] = (y, s, rr.model[0])
    return TransportFit(maps, regions, profiles, offsets, calibrated)


_MAP_NAMES = ("mu_s_prime_per_mm", "mu_a_per_mm", "mu_s_prime_se_per_mm", "mu_a_se_per_mm")


def _num(v):
    return float(v) if np.isfinite(v) else None


def _nanmedian(v):
    v = np.asarray(v, float)
    return float(np.nanmedian(v)) if np.isfinite(v).any() else None

"""Vein tables: how a vein changes the plane-to-ray kernel of a layered skin, ``K = K0(u) R(rho, u)``.

:func:`mc_vein_table` tabulates the perturbation run of :func:`planeray.mc.layered.trace_virtual_veins`
(a pencil beam at the pixel through the vein-free layers, every virtual vein of a grid weighted by
its pathlength in blood; the method and its check against brute force are in
:mod:`planeray.mc.layered`) and stores it with the one table store
(:func:`planeray.kernels.store.stored`: shipped, else cached, else traced and saved).  The skin
scene (:mod:`planeray.scenes.skin`) and the vein fit (:mod:`planeray.skin.depth`) read it.
"""

from __future__ import annotations

import functools
import json
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..mc.cache import cache_key, save_table, stored, where
from ..mc.events import batch_stats, check_offsets
from ..mc.layered import LAYERED_VERSION, check_vein, layer_arrays, layer_params, trace_virtual_veins
from ..medium import Medium, as_medium

__all__ = [
    "VeinTable",
    "mc_vein_table",
    "vein_table_stored",
    "vein_table_seconds",
    "vein_table_slice",
    "vein_ratio",
    "TABLE_ANGLES_DEG",
    "TABLE_DEPTHS_MM",
    "TABLE_DIAMETERS_MM",
]


@dataclass(frozen=True)
class VeinTable:
    """How a vein changes the plane-to-ray kernel of a layered skin: ``K = K0(u) R(rho, u)``.

    ``ratio[a, d, D, r, k]``: kernel ratio for angle ``angles_deg[a]`` (0: the vein parallel
    to the projector rows, 90: across them), depth of the vein's top ``depths_mm[d]``,
    diameter ``diameters_mm[D]``, the pixel's signed distance ``rho_rows[r]`` from the vein
    axis (rows, ``rho = (x, y) . (cos a, -sin a)``) and offset ``offsets_rows[k]``.
    ``kernel`` is the background line kernel ``K0`` (power per offset bin per unit
    power), ``kernel_stderr`` its batch standard error, ``total_reflectance`` the total
    diffuse reflectance of the skin.
    """

    angles_deg: np.ndarray
    depths_mm: np.ndarray
    diameters_mm: np.ndarray
    rho_rows: np.ndarray
    offsets_rows: np.ndarray
    mm_per_row: float
    ratio: np.ndarray
    kernel: np.ndarray
    kernel_stderr: np.ndarray
    total_reflectance: float
    params: dict

    _ARRAYS = ("angles_deg", "depths_mm", "diameters_mm", "rho_rows", "offsets_rows", "kernel", "kernel_stderr")

    def save(self, path) -> Path:
        """Write the table as an ``.npz`` (no pickle); atomic (a temporary, then a rename)."""
        return save_table(
            path,
            **{k: getattr(self, k) for k in self._ARRAYS},
            ratio=self.ratio.astype(np.float32),
            mm_per_row=np.float64(self.mm_per_row),
            total_reflectance=np.float64(self.total_reflectance),
            params=np.array(json.dumps(self.params, sort_keys=True)),
        )

    @classmethod
    def load(cls, path) -> VeinTable:
        """Read a table written by :meth:`save`."""
        with np.load(path, allow_pickle=False) as z:
            return cls(
                **{k: z[k] for k in cls._ARRAYS},
                ratio=z["ratio"].astype(np.float64),
                mm_per_row=float(z["mm_per_row"]),
                total_reflectance=float(z["total_reflectance"]),
                params=json.loads(str(z["params"])),
            )


@functools.lru_cache(maxsize=8)
def _read_vein_table(path: str, mtime_ns: int, size: int) -> VeinTable:
    table = VeinTable.load(path)
    for name in (*VeinTable._ARRAYS, "ratio"):
        getattr(table, name).flags.writeable = False  # shared by every later hit: never changed in place
    return table


def _load_vein_table(path: str, mtime_ns: int, size: int) -> VeinTable:
    """:meth:`VeinTable.load`, read once per file version (path, modification time, size) in a process.

    A skin scene reads its tables at every build (a pulse video builds several); the arrays
    of a cached table are read-only and its ``params`` a fresh copy at every hit.
    """
    table = _read_vein_table(path, mtime_ns, size)
    return replace(table, params=json.loads(json.dumps(table.params)))


#: Default grid of the vein tables: angles (deg), depth of the vein's top (mm), diameter (mm).
TABLE_ANGLES_DEG = (0.0, 45.0, 90.0)
TABLE_DEPTHS_MM = (1.0, 2.0, 3.0, 4.0, 5.0)
TABLE_DIAMETERS_MM = (1.0, 2.0, 3.0, 4.0)


def _rho_grid(rho_rows):
    rho = np.asarray(rho_rows, dtype=np.float64).ravel()
    if rho.size < 2 or not np.allclose(np.diff(rho), rho[1] - rho[0]) or rho[1] <= rho[0]:
        raise InputError("rho_rows must be an increasing, evenly spaced grid")
    return rho


def _vein_table_key(layers, blood, depths_mm, diameters_mm, angles_deg, rho_rows, offsets_rows, mm, n_photons, seed):
    """``(params, rho grid, offsets, file name)`` of a vein table: its cache entry is named by every input."""
    rho = _rho_grid(np.arange(-48, 49, 2) if rho_rows is None else rho_rows)
    off = check_offsets(np.arange(-64, 65) if offsets_rows is None else offsets_rows, consecutive=True)
    params = {
        "kind": "skin-vein-table",
        "version": LAYERED_VERSION,
        "layers": [layer_params(as_medium(m)) for m in layers],
        "blood": layer_params(as_medium(blood)),
        "depths_mm": np.asarray(depths_mm, dtype=np.float64).tolist(),
        "diameters_mm": np.asarray(diameters_mm, dtype=np.float64).tolist(),
        "angles_deg": np.asarray(angles_deg, dtype=np.float64).tolist(),
        "rho_rows": rho.tolist(),
        "mm_per_row": float(mm),
        "n_photons": int(n_photons),
        "seed": int(seed),
    }
    return params, rho, off, f"skin-{cache_key(params, off)}.npz"


def vein_table_stored(layers, blood, *, mm_per_row=0.3, n_photons=400_000, seed=0) -> bool:
    """Whether :func:`mc_vein_table` of these layers (default grids) is shipped or cached: no tracing needed."""
    name = _vein_table_key(
        layers, blood, TABLE_DEPTHS_MM, TABLE_DIAMETERS_MM, TABLE_ANGLES_DEG, None, None, mm_per_row, n_photons, seed
    )[3]
    return where(name) is not None


def vein_table_seconds(layers, blood, *, mm_per_row=0.3, n_photons=400_000, fraction=0.02) -> float:
    """Estimated seconds to trace :func:`mc_vein_table` of these layers on this machine, from a pilot run.

    A run of a few photons (after one that compiles the kernels) measures the fixed cost; a run of
    ``fraction`` of the photons (not cached) the cost per photon, scaled to ``n_photons``.
    """
    import time

    kw = dict(mm_per_row=mm_per_row, seed=12345, cache=False)
    mc_vein_table(layers, blood, n_photons=64, **kw)
    t0 = time.perf_counter()
    mc_vein_table(layers, blood, n_photons=64, **kw)
    fixed = time.perf_counter() - t0
    photons = max(int(n_photons * fraction), 2_000)
    t0 = time.perf_counter()
    mc_vein_table(layers, blood, n_photons=photons, **kw)
    return fixed + max(time.perf_counter() - t0 - fixed, 0.0) * n_photons / photons


def mc_vein_table(
    layers,
    blood: Medium,
    *,
    depths_mm=TABLE_DEPTHS_MM,
    diameters_mm=TABLE_DIAMETERS_MM,
    angles_deg=TABLE_ANGLES_DEG,
    rho_rows=None,
    offsets_rows=None,
    mm_per_row=0.3,
    n_photons=400_000,
    seed=0,
    cache=True,
    progress=None,
) -> VeinTable:
    """The vein perturbation table of a layered skin (pencil beam at the pixel + pathlength weighting).

    One run traces ``n_photons`` photons from a pencil beam at the pixel through the
    vein-free layers.  Each photon carries the optical depth ``(mu_a,blood - mu_a,layer) L``
    of its path inside every virtual vein of the grid -- per angle, per distance ``rho``
    of the pixel from the vein (``rho_rows``, default every 2 rows over +-48 rows) and per
    (depth, diameter) -- and every exit adds ``w`` to the background and ``w exp(-tau)`` to
    each vein's bin ``(rho, u)``; their ratio is the vein's effect on the pixel's kernel
    (exact for absorption; blood is taken to scatter like the tissue around it, which
    :func:`mc_layered_vein_brute` checks).

    Cached like the other Monte Carlo results (shipped tables first, :data:`TABLES_DIR`,
    then :func:`planeray.mc.cache.cache_dir`), keyed by every input.
    """
    layer_arrays(layers)
    blood = as_medium(blood)
    mm = float(mm_per_row)
    params, rho, off, name = _vein_table_key(
        layers, blood, depths_mm, diameters_mm, angles_deg, rho_rows, offsets_rows, mm, n_photons, seed
    )
    depths = np.asarray(depths_mm, dtype=np.float64)
    diams = np.asarray(diameters_mm, dtype=np.float64)
    angles = np.asarray(angles_deg, dtype=np.float64)
    for d in depths:
        for D in diams:
            check_vein(layers, d, D)

    def load(path):
        stat = Path(path).stat()
        return _load_vein_table(str(path), stat.st_mtime_ns, stat.st_size)

    def build():
        run = trace_virtual_veins(
            layers, blood, depths_mm=depths, diameters_mm=diams, angles_deg=angles, rho_rows=rho, offsets_rows=off,
            mm_per_row=mm, n_photons=n_photons, seed=seed, progress=progress,
        )  # fmt: skip
        counts, refl_bins, pert, refl = run["counts"], run["refl_bins"], run["pert"], run["refl"]
        kernel, kernel_err = batch_stats(refl_bins, counts)
        base = refl_bins.sum(axis=0)  # (u,)
        pert = pert.sum(axis=0)  # (angle, combo, rho, u)
        if np.allclose(rho, -rho[::-1]) and off[0] == -off[-1]:
            # Mirroring x -> -x maps (rho, u) to (-rho, -u) at the same angle: average both.
            base = base + base[::-1]
            pert = pert + pert[:, :, ::-1, ::-1]
        with np.errstate(invalid="ignore", divide="ignore"):
            ratio = np.where(base > 0, pert / base, 1.0)
        ratio = ratio.reshape(angles.size, depths.size, diams.size, rho.size, off.size)
        return VeinTable(
            angles_deg=angles,
            depths_mm=depths,
            diameters_mm=diams,
            rho_rows=rho,
            offsets_rows=off,
            mm_per_row=mm,
            ratio=ratio,
            kernel=kernel,
            kernel_stderr=kernel_err,
            total_reflectance=float(refl.sum() / counts.sum()),
            params=params,
        )

    return stored(
        name,
        load=load,
        build=build,
        save=lambda path, table: table.save(path),
        cache=cache,
        on_hit=None if progress is None else (lambda: progress(int(n_photons))),
    )


# ---------------------------------------------------------------- reading a vein off the table
# ---------------------------------------------------------------- the vein ratio
def vein_table_slice(table: VeinTable, depth_mm, diameter_mm):
    """``ratio[angle, rho, u]`` of one vein (``depth_mm`` to its top, ``diameter_mm`` wide): bilinear in
    (depth, diameter) over the table's grid (clamped at its edges)."""

    def weights(grid, v):
        i = int(np.clip(np.searchsorted(grid, v) - 1, 0, len(grid) - 2))
        w = float(np.clip((v - grid[i]) / (grid[i + 1] - grid[i]), 0.0, 1.0))
        return i, w

    i, wi = weights(table.depths_mm, depth_mm)
    j, wj = weights(table.diameters_mm, diameter_mm)
    r = table.ratio
    return (
        (1 - wi) * (1 - wj) * r[:, i, j]
        + wi * (1 - wj) * r[:, i + 1, j]
        + (1 - wi) * wj * r[:, i, j + 1]
        + wi * wj * r[:, i + 1, j + 1]
    )


def vein_ratio(sl, table: VeinTable, rho_rows, angle_deg, u_table):
    """Kernel ratio ``(n, U)`` of pixels at ``rho_rows`` from a vein at ``angle_deg``; ``u_table`` (n, U) offsets,
    or (U,): the same offsets for every pixel (one gather of the table's columns instead of one per pixel).

    ``sl`` is the vein's :func:`vein_table_slice`; bilinear in (angle, rho), linear along the offsets; 1 (no
    change) beyond the table's offsets or distances.  Angles in (90, 180) mirror onto ``180 - angle``.
    """
    # Angles in (90, 180) mirror (y -> -y) onto 180 - a with rho -> -rho.
    flip = angle_deg > 90.0
    a = np.where(flip, 180.0 - angle_deg, angle_deg)
    rho = np.where(flip, -rho_rows, rho_rows)
    ga = table.angles_deg
    ia = np.clip(np.searchsorted(ga, a) - 1, 0, ga.size - 2)
    wa = np.clip((a - ga[ia]) / (ga[ia + 1] - ga[ia]), 0.0, 1.0)
    gr = table.rho_rows
    fr = (rho - gr[0]) / (gr[1] - gr[0])
    ir = np.clip(np.floor(fr).astype(np.int64), 0, gr.size - 2)
    wr = np.clip(fr - ir, 0.0, 1.0)
    fk = u_table - table.offsets_rows[0]
    ik = np.clip(np.floor(fk).astype(np.int64), 0, table.offsets_rows.size - 2)
    wk = np.clip(fk - ik, 0.0, 1.0)
    # bilinear in (angle, rho): each pixel's own table row (n, K), then linear along the offsets
    rows = np.zeros((rho.size, sl.shape[-1]))
    for da, wa_ in ((0, 1 - wa), (1, wa)):
        for dr, wr_ in ((0, 1 - wr), (1, wr)):
            rows += (wa_ * wr_)[:, None] * sl[ia + da, ir + dr]
    if ik.ndim == 1:
        lo, hi = rows[:, ik], rows[:, ik + 1]
    else:
        lo, hi = np.take_along_axis(rows, ik, axis=1), np.take_along_axis(rows, ik + 1, axis=1)
    out = (1 - wk) * lo + wk * hi
    far = (np.abs(u_table) > table.offsets_rows[-1]) | (np.abs(rho) > gr[-1])[:, None]
    return np.where(far, 1.0, out)

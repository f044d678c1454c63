"""Wall-kernel tables: line kernels of a medium for pixels near a container wall (Sec. 8).

A scene (:mod:`planeray.scenes.materials`) cannot trace a Monte Carlo run per pixel: it
interpolates :class:`WallKernelTable`, traced once per medium and wall model by
:func:`mc_wall_table` from :func:`planeray.mc.wall.mc_wall_profile` runs (the geometry and
the reciprocity argument are in :mod:`planeray.mc.wall`) and stored by the one table store
(:func:`planeray.kernels.store.stored`: shipped, else cached, else traced and saved).
"""

from __future__ import annotations

import functools
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..mc.cache import ENGINE_VERSION, cache_key, save_table, stored, where
from ..mc.diffusion import DIFFUSION_DEPTH_MFP
from ..mc.engine import mc_line_profile
from ..mc.wall import WALL_VERSION, check_wall_model, trace_wall_run, wall_run_params
from ..medium import Medium, as_medium

__all__ = [
    "WallKernelTable",
    "mc_wall_table",
    "wall_table_key",
    "wall_table_stored",
    "TABLE_DISTANCES_ROWS",
    "TABLE_ANGLES_DEG",
    "TABLE_PHOTONS",
    "TABLE_SLAB_PHOTONS",
    "TABLE_RUNS",
]

#: Default wall distances of a table, in projector rows: dense near the wall, out to the
#: canonical kernel reach (:data:`planeray.kernels.MC_KERNEL_REACH_ROWS`).
TABLE_DISTANCES_ROWS = (0.0, 1.5, 3.0, 5.0, 8.0, 12.0, 17.0, 24.0, 33.0, 45.0, 60.0, 80.0, 105.0, 140.0, 192.0)
#: Default wall angles of a table: parallel, oblique and perpendicular to the lit lines (trays use 0 and 90).
TABLE_ANGLES_DEG = (0.0, 45.0, 90.0)
#: Photons per wall distance and angle of a table; the slab kernel gets :data:`TABLE_SLAB_PHOTONS`.
TABLE_PHOTONS = 100_000
TABLE_SLAB_PHOTONS = 1_000_000

#: Monte Carlo runs of a default table (the slab, the reference without a wall, one per angle and distance):
#: what :func:`mc_wall_table` counts with ``progress``.
TABLE_RUNS = 2 + len(TABLE_ANGLES_DEG) * len(TABLE_DISTANCES_ROWS)

_TABLE_ARRAYS = (
    "offsets_rows",
    "angles_deg",
    "distances_rows",
    "kernel",
    "kernel_stderr",
    "wall_loss",
    "slab",
    "slab_stderr",
)


def _physical(kernel, angles_deg, distances_rows, offsets_rows):
    """Kernels with what cannot be: no negative light (the control variate's noise), and nothing from
    behind a wall parallel to the lines (angle 0: bins wholly beyond the wall, where the run with the
    wall has no exits and the difference is the reference's noise alone)."""
    k = np.clip(kernel, 0.0, None)
    for i, ang in enumerate(angles_deg):
        if ang == 0.0:
            beyond = np.asarray(offsets_rows)[None, :] - 0.5 >= np.asarray(distances_rows)[:, None]
            k[i][beyond] = 0.0
    return k


@dataclass(frozen=True)
class WallKernelTable:
    """Line kernels of a medium for pixels at several distances and angles from a wall.

    ``kernel[i, j]`` is what a pixel ``distances_rows[j]`` projector rows from a wall at
    ``angles_deg[i]`` (:func:`mc_wall_profile`) receives from the lit line at each offset,
    in **Lambertian-equivalent reflectance per offset bin**: ``pi`` times the normal-view
    radiance times the bin width, so that a white Lambertian surface would sum to 1 (the
    unit of the scenes' transport).  ``slab`` is the same without a wall.

    Attributes
    ----------
    medium : Medium
    wall : str
        ``"fresnel"`` or ``"absorbing"``.
    mm_per_row : float
    offsets_rows : ndarray (U,) of int
    angles_deg : ndarray (A,)
    distances_rows : ndarray (D,)
    kernel, kernel_stderr : ndarray (A, D, U)
        Kernels and their Monte Carlo standard errors.
    wall_loss : ndarray (A, D)
        Power lost through the wall per unit power entering at the pixel.
    slab, slab_stderr : ndarray (U,)
        The kernel far from any wall and its error.
    params : dict
        How the table was computed (photons, seed, versions).
    """

    medium: Medium
    wall: str
    mm_per_row: float
    offsets_rows: np.ndarray
    angles_deg: np.ndarray
    distances_rows: np.ndarray
    kernel: np.ndarray
    kernel_stderr: np.ndarray
    wall_loss: np.ndarray
    slab: np.ndarray
    slab_stderr: np.ndarray
    params: dict = field(default_factory=dict)

    @functools.cached_property
    def _wall_effect(self) -> np.ndarray:
        """``kernel - slab``, what :meth:`kernels` interpolates (computed once: a scene asks per pixel row)."""
        return self.kernel - self.slab[None, None, :]

    def kernels(self, distance_rows, angle_deg) -> np.ndarray:
        """Kernels of pixels at ``distance_rows`` from a wall at ``angle_deg`` (broadcast), ``(..., U)``.

        Bilinear interpolation of the wall's effect (``kernel - slab``) in angle and
        distance; beyond the largest tabulated distance the slab kernel.  Angles outside
        the tabulated range take the nearest tabulated angle.
        """
        d, a = np.broadcast_arrays(np.asarray(distance_rows, np.float64), np.asarray(angle_deg, np.float64))
        pert = self._wall_effect
        A, D = self.angles_deg, self.distances_rows
        fa = np.interp(a, A, np.arange(A.size)) if A.size > 1 else np.zeros_like(a)
        ia = np.minimum(np.floor(fa).astype(np.int64), A.size - 1)
        ia1 = np.minimum(ia + 1, A.size - 1)
        wa = (fa - ia)[..., None]
        dd = np.clip(d, D[0], None)
        fd = np.interp(dd, D, np.arange(D.size))
        idd = np.minimum(np.floor(fd).astype(np.int64), D.size - 1)
        id1 = np.minimum(idd + 1, D.size - 1)
        wd = (fd - idd)[..., None]
        p = (1 - wa) * ((1 - wd) * pert[ia, idd] + wd * pert[ia, id1]) + wa * (
            (1 - wd) * pert[ia1, idd] + wd * pert[ia1, id1]
        )
        p = np.where((d > D[-1])[..., None], 0.0, p)
        return self.slab + p

    # ------------------------------------------------------------ storage
    def save(self, path) -> Path:
        """Write the table as one compressed ``.npz`` (no pickle), atomically."""
        meta = {
            "medium": self.medium.to_dict(),
            "wall": self.wall,
            "mm_per_row": self.mm_per_row,
            "params": self.params,
        }
        arrays = {k: getattr(self, k) for k in _TABLE_ARRAYS}
        arrays = {k: (v.astype(np.float32) if v.dtype.kind == "f" else v) for k, v in arrays.items()}
        return save_table(path, meta=np.array(json.dumps(meta, sort_keys=True)), **arrays)

    @classmethod
    def load(cls, path) -> WallKernelTable:
        """Read a table written by :meth:`save`."""
        with np.load(path, allow_pickle=False) as z:
            meta = json.loads(str(z["meta"]))
            arrays = {k: z[k] for k in _TABLE_ARRAYS}
        arrays = {k: (v.astype(np.float64) if v.dtype.kind == "f" else v) for k, v in arrays.items()}
        arrays["kernel"] = _physical(
            arrays["kernel"], arrays["angles_deg"], arrays["distances_rows"], arrays["offsets_rows"]
        )
        return cls(
            medium=Medium.from_dict(meta["medium"]),
            wall=meta["wall"],
            mm_per_row=float(meta["mm_per_row"]),
            params=meta["params"],
            **arrays,
        )


def wall_table_key(
    medium: Medium,
    *,
    wall,
    angles_deg,
    distances_rows,
    offsets_rows,
    mm_per_row,
    n_photons,
    slab_photons,
    seed,
    diffusion_depth_mfp=DIFFUSION_DEPTH_MFP,
) -> str:
    """File name of a wall table in the caches: ``wall-`` and a hash of everything it depends on."""
    params = dict(
        kind="wall-table",
        wall_version=WALL_VERSION,
        medium=as_medium(medium).to_dict(),
        wall=wall,
        angles_deg=[float(v) for v in angles_deg],
        distances_rows=[float(v) for v in distances_rows],
        mm_per_row=float(mm_per_row),
        n_photons=int(n_photons),
        slab_photons=int(slab_photons),
        seed=int(seed),
        diffusion_depth_mfp=None if diffusion_depth_mfp is None else float(diffusion_depth_mfp),
    )
    return f"wall-{cache_key(params, np.asarray(offsets_rows, dtype=np.int64))}.npz"


def wall_table_stored(medium: Medium, *, wall="fresnel", offsets_rows=None, mm_per_row=0.3) -> bool:
    """Whether the default :func:`mc_wall_table` of ``medium`` is shipped or cached (no Monte Carlo to run).

    Lets a front end say, before it starts, that tables will be traced (minutes each).
    """
    offsets = np.arange(-192, 193) if offsets_rows is None else np.asarray(offsets_rows, dtype=np.int64)
    name = wall_table_key(
        medium,
        wall=wall,
        angles_deg=np.asarray(TABLE_ANGLES_DEG, dtype=np.float64),
        distances_rows=np.asarray(TABLE_DISTANCES_ROWS, dtype=np.float64),
        offsets_rows=offsets,
        mm_per_row=mm_per_row,
        n_photons=TABLE_PHOTONS,
        slab_photons=TABLE_SLAB_PHOTONS,
        seed=0,
    )
    return where(name) is not None


def mc_wall_table(
    medium: Medium,
    *,
    wall="fresnel",
    angles_deg=TABLE_ANGLES_DEG,
    distances_rows=TABLE_DISTANCES_ROWS,
    offsets_rows=None,
    mm_per_row=0.3,
    n_photons=TABLE_PHOTONS,
    slab_photons=TABLE_SLAB_PHOTONS,
    seed=0,
    cache=True,
    progress=None,
) -> WallKernelTable:
    """Line kernels of ``medium`` beside a wall, at every tabulated distance and angle.

    The slab kernel is :func:`planeray.mc.mc_line_profile` (``slab_photons``); each wall
    kernel is that plus the wall's effect, estimated as the difference between a run
    with the wall (:func:`mc_wall_profile`, ``n_photons``) and one without it that traces
    the very same photons (the same per-photon random streams): photons that never meet
    the wall cancel exactly, so the difference carries only the noise of those that do
    (a control variate).  Far from the wall the kernel is the slab's, without added noise.

    Parameters
    ----------
    medium : Medium
    wall : {"fresnel", "absorbing"}
    angles_deg : sequence of float
        Wall angles in ``[0, 90]`` (see :func:`mc_wall_profile`).
    distances_rows : sequence of float
        Distances from the pixel to the wall, projector rows, increasing.
    offsets_rows : array_like of int, optional
        Offset bins; default ``-192 .. 192`` (:data:`planeray.kernels.MC_KERNEL_REACH_ROWS`).
    mm_per_row : float
        Size of a projector row on the surface (mm).
    n_photons, slab_photons : int
        Photons per wall run and of the slab kernel.
    seed : int
    cache : bool
        Look the table up in the shipped tables (:data:`planeray.mc.cache.TABLES_DIR`) and
        the disk cache, and store it there when computed.
    progress : callable, optional
        Called with 1 after each Monte Carlo run (``1 + 1 + A * D`` runs).

    Returns
    -------
    WallKernelTable
    """
    medium = as_medium(medium)
    check_wall_model(wall)
    if offsets_rows is None:
        offsets_rows = np.arange(-192, 193)
    offsets = np.asarray(offsets_rows, dtype=np.int64)
    angles = np.asarray(angles_deg, dtype=np.float64)
    dists = np.asarray(distances_rows, dtype=np.float64)
    if angles.size == 0 or np.any(np.diff(angles) <= 0) or angles.min() < 0 or angles.max() > 90:
        raise InputError(f"angles_deg must increase within [0, 90], got {list(angles)}")
    if dists.size == 0 or np.any(np.diff(dists) <= 0) or dists.min() < 0:
        raise InputError(f"distances_rows must increase from >= 0, got {list(dists)}")
    name = wall_table_key(
        medium,
        wall=wall,
        angles_deg=angles,
        distances_rows=dists,
        offsets_rows=offsets,
        mm_per_row=mm_per_row,
        n_photons=n_photons,
        slab_photons=slab_photons,
        seed=seed,
    )
    return stored(
        name,
        load=WallKernelTable.load,
        build=lambda: _trace_table(
            medium, wall, angles, dists, offsets, mm_per_row, n_photons, slab_photons, seed, cache, progress
        ),
        save=lambda path, table: table.save(path),
        cache=cache,
    )


def _trace_table(medium, wall, angles, dists, offsets, mm_per_row, n_photons, slab_photons, seed, cache, progress):
    """Trace :func:`mc_wall_table`: the slab, the reference without a wall, then one run per angle and distance."""

    def tick():
        if progress is not None:
            progress(1)

    mm = float(mm_per_row)
    slab = mc_line_profile(medium, n_photons=slab_photons, offsets_rows=offsets, mm_per_row=mm, seed=seed, cache=cache)
    tick()
    base = dict(n_photons=int(n_photons), offsets_rows=offsets, mm_per_row=mm, seed=seed, wall=wall)
    ref_params = wall_run_params(medium, offsets, wall_distance_mm=math.inf, wall_angle_deg=0.0, **base)
    _, ref = trace_wall_run(medium, offsets, ref_params)
    tick()
    to_lambert = np.pi * mm
    kernel = np.empty((angles.size, dists.size, offsets.size))
    kernel_err = np.empty_like(kernel)
    wall_loss = np.empty((angles.size, dists.size))
    n_b = ref.shape[0]
    for i, ang in enumerate(angles):
        for j, dist in enumerate(dists):
            params = wall_run_params(medium, offsets, wall_distance_mm=dist * mm, wall_angle_deg=ang, **base)
            prof, batches = trace_wall_run(medium, offsets, params)
            diff = batches - ref
            kernel[i, j] = to_lambert * (slab.radiance + diff.mean(axis=0))
            kernel_err[i, j] = to_lambert * np.hypot(slab.radiance_stderr, diff.std(axis=0, ddof=1) / math.sqrt(n_b))
            wall_loss[i, j] = prof.wall_loss
            tick()
    table = WallKernelTable(
        medium=medium,
        wall=wall,
        mm_per_row=mm,
        offsets_rows=offsets.copy(),
        angles_deg=angles,
        distances_rows=dists,
        kernel=_physical(kernel, angles, dists, offsets),
        kernel_stderr=kernel_err,
        wall_loss=wall_loss,
        slab=to_lambert * slab.radiance,
        slab_stderr=to_lambert * slab.radiance_stderr,
        params=dict(
            n_photons=int(n_photons),
            slab_photons=int(slab_photons),
            seed=int(seed),
            wall_version=WALL_VERSION,
            engine_version=ENGINE_VERSION,
            slab_total_reflectance=slab.total_reflectance,
            diffusion_depth_mfp=DIFFUSION_DEPTH_MFP,
        ),
    )
    return table

"""Plain-file output of a Monte Carlo profile: CSV of the bins, JSON of the scalars.

The CSV has one row per offset bin with the columns ``offset_rows``, ``x_mm``
(bin centre), ``exitance`` and ``exitance_stderr`` (power leaving the top face
per bin, fraction of the incident line power), ``radiance`` and
``radiance_stderr`` (normal-view radiance, mm^-1 sr^-1 per unit line power).
A point-source profile has ``radius_bin`` and ``r_mm`` (annulus centre) first;
its exitance is per annulus and its radiance per mm^2.
The JSON sidecar (same name, ``.json``) holds the totals, the energy balance
and every parameter of the run, so the file alone reproduces it: ``medium``
is the :class:`~planeray.medium.Medium` as :meth:`~planeray.medium.Medium.to_dict`
(read it back with :meth:`~planeray.medium.Medium.from_dict`), ``params`` the
run's cache-key parameters.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np

from ..io import atomic_file
from .result import MCProfile

__all__ = ["profile_columns", "write_profile", "profile_summary"]

COLUMNS = ("offset_rows", "x_mm", "exitance", "exitance_stderr", "radiance", "radiance_stderr")


POINT_COLUMNS = ("radius_bin", "r_mm") + COLUMNS[2:]


def _columns(prof: MCProfile):
    return POINT_COLUMNS if prof.params.get("source") == "point" else COLUMNS


def profile_columns(prof: MCProfile) -> dict:
    """The CSV columns of ``prof`` as float64/int64 arrays keyed by :data:`COLUMNS`
    (:data:`POINT_COLUMNS` for a point source: radial bin and annulus centre ``r_mm``)."""
    first, second = _columns(prof)[:2]
    return {
        first: np.asarray(prof.offsets_rows, np.int64),
        second: np.asarray(prof.offsets_rows, np.float64) * prof.mm_per_row,
        "exitance": np.asarray(prof.values, np.float64),
        "exitance_stderr": np.asarray(prof.stderr, np.float64),
        "radiance": np.asarray(prof.radiance, np.float64),
        "radiance_stderr": np.asarray(prof.radiance_stderr, np.float64),
    }


def profile_summary(prof: MCProfile) -> dict:
    """Scalars of a run (JSON-ready): totals with errors, energy balance, cost, medium, parameters."""
    return {
        "total_reflectance": prof.total_reflectance,
        "total_reflectance_stderr": prof.total_reflectance_stderr,
        "specular_reflectance": prof.specular_reflectance,
        "transmittance": prof.transmittance,
        "transmittance_stderr": prof.transmittance_stderr,
        "absorbed": prof.absorbed,
        "truncated": prof.truncated,
        "energy_balance": prof.energy_balance,
        "binned_exitance": float(np.sum(prof.values)),
        "n_photons": prof.n_photons,
        "n_interactions": prof.n_interactions,
        "medium": prof.medium.to_dict(),
        "params": prof.params,
    }


def write_profile(prof: MCProfile, path) -> tuple[Path, Path]:
    """Write ``path`` (CSV, see the module docstring) and its ``.json`` sidecar atomically.

    Both carry planeray's mark: the CSV's first line is the comment
    ``# planeray_mark: planeray:table:VERSION`` (pandas: ``read_csv(path, comment="#")``),
    the JSON the key ``planeray_mark``.
    """
    from ..io.marks import MARK_KEY, mark_text

    path = Path(path)
    side = path.with_suffix(".json")
    existed = path.exists()
    try:
        _write_csv(prof, path)
        with atomic_file(side) as tmp:
            tmp.write_text(
                json.dumps({MARK_KEY: mark_text("record"), **profile_summary(prof)}, indent=2, sort_keys=True)
            )
    except BaseException:
        if not existed:  # the CSV without its sidecar is no result: a failed run leaves neither
            path.unlink(missing_ok=True)
        raise
    return path, side


def _write_csv(prof: MCProfile, path: Path) -> None:
    from ..io.marks import MARK_KEY, mark_text

    cols = profile_columns(prof)
    names = _columns(prof)
    with atomic_file(path) as tmp:
        with open(tmp, "w", newline="") as f:
            f.write(f"# {MARK_KEY}: {mark_text('table')}\n")
            w = csv.writer(f)
            w.writerow(names)
            for i in range(cols[names[0]].size):
                w.writerow([int(cols[names[0]][i])] + [repr(float(cols[c][i])) for c in names[1:]])

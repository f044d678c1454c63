"""The disk cache of Monte Carlo results, and the read-only tables shipped with the package.

An entry is one ``.npz`` (no pickle) named by :func:`cache_key`: a hash of
:data:`ENGINE_VERSION`, every parameter of the run and its bins, so a result is
reused only for an identical run.

:func:`stored` is the one look-up of every cached result (profiles, wall, vein and
forward tables): the table shipped with the package, else the user's cache, else
build it and save it there.  :func:`where` says which of the two holds an entry.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np

from .result import MCProfile

__all__ = [
    "ENGINE_VERSION",
    "TABLES_DIR",
    "cache_dir",
    "cache_key",
    "where",
    "stored",
    "save_table",
    "save_profile",
    "load_profile",
    "write_or_warn",
]

#: Bumped whenever the engine's results change, so stale cache entries are never used.
ENGINE_VERSION = 4

#: Read-only results shipped with the package (the built-in scenes' media), looked up
#: before :func:`cache_dir`; regenerate with ``python tools/build_mc_tables.py``.
TABLES_DIR = Path(__file__).with_name("tables")


def cache_dir() -> Path:
    """Cache folder: ``$PLANERAY_CACHE/mc`` if set, else ``~/.cache/planeray/mc``.

    Returns
    -------
    pathlib.Path
        The folder (not created).

    See Also
    --------
    planeray.mc_line_profile : ``cache=True`` stores there.

    Examples
    --------
    >>> import os
    >>> os.environ.get("PLANERAY_CACHE") is None or cache_dir().name == "mc"
    True
    """
    root = os.environ.get("PLANERAY_CACHE")
    base = Path(root) if root else Path.home() / ".cache" / "planeray"
    return base / "mc"


def cache_key(params: dict, offsets: np.ndarray) -> str:
    """File stem of a run's cache entry: a hash of the engine version, parameters and bins."""
    blob = json.dumps({"v": ENGINE_VERSION, **params}, sort_keys=True)
    h = hashlib.sha256(blob.encode())
    h.update(np.ascontiguousarray(offsets, dtype=np.int64).tobytes())
    return h.hexdigest()[:32]


_ARRAYS = ("offsets_rows", "values", "stderr", "radiance", "radiance_stderr")
_SCALARS = (
    "mm_per_row",
    "total_reflectance",
    "total_reflectance_stderr",
    "specular_reflectance",
    "transmittance",
    "transmittance_stderr",
    "absorbed",
    "truncated",
)
#: Fields the layered entries written before their results were profiles lack (read as NaN).
_LAYERED_ABSENT = ("radiance", "radiance_stderr", "transmittance_stderr")
#: Scalars written since the wall runs (absent from older entries: read as 0).
_OPTIONAL_SCALARS = ("wall_loss", "wall_loss_stderr")


def write_or_warn(write: Callable[[Path], None], path: Path, *, stacklevel: int = 3) -> None:
    """Write a cache entry with ``write(path)``; if the disk refuses, warn and go on.

    A read-only home must not cost the result just computed: the warning (a
    ``RuntimeWarning`` attributed to the caller of the Monte Carlo function) names the
    file and says how to point the cache elsewhere.  An entry another planeray run is
    writing at this moment is left to it (the same inputs, the same bytes).
    """
    from ..io.lock import OutputBusyError  # here: planeray.io imports Zarr, which a Monte Carlo run does not need

    try:
        write(path)
    except OutputBusyError:
        return
    except OSError as exc:
        warnings.warn(
            f"{path}: could not write the Monte Carlo cache ({exc}); set PLANERAY_CACHE to a writable folder",
            RuntimeWarning,
            stacklevel=stacklevel,
        )


def where(name: str) -> str | None:
    """Which store holds the entry ``name``: ``"shipped"`` (:data:`TABLES_DIR`), ``"cached"`` (:func:`cache_dir`)
    or None (it would be built)."""
    if (TABLES_DIR / name).exists():
        return "shipped"
    if (cache_dir() / name).exists():
        return "cached"
    return None


def stored(name: str, *, load, build, save, cache: bool = True, on_hit=None):
    """The one look-up of a cached result: the shipped table, else the user cache, else build it and save it.

    Parameters
    ----------
    name : str
        File name of the entry (a hash of everything it depends on: :func:`cache_key`).
    load : callable
        ``load(path)`` reads an entry; one that raises ``OSError``, ``ValueError`` or ``KeyError``
        (unreadable, truncated, of an older format) is passed over, and rebuilt.
    build : callable
        ``build()`` computes the result.
    save : callable
        ``save(path, result)`` writes it (atomically); a refusing disk only warns (:func:`write_or_warn`).
    cache : bool
        False: build, and neither read nor write the stores.
    on_hit : callable, optional
        Called with no argument when an entry was read (progress reports count it as done).
    """
    path = cache_dir() / name
    if cache:
        for hit in (TABLES_DIR / name, path):
            if hit.exists():
                try:
                    value = load(hit)
                except (OSError, ValueError, KeyError):
                    continue  # unreadable entry: rebuild (and overwrite the user cache)
                if on_hit is not None:
                    on_hit()
                return value
    value = build()
    if cache:
        write_or_warn(lambda p: save(p, value), path, stacklevel=4)
    return value


def save_npz(path, *, compressed: bool = False, **arrays) -> Path:
    """Write ``arrays`` as one ``.npz`` (no pickle), atomically (:func:`planeray.io.atomic_file`)."""
    from ..errors import StorageError
    from ..io.atomic import atomic_file  # here: planeray.io imports Zarr, which a Monte Carlo run does not need

    path = Path(path)
    with atomic_file(path, error=StorageError) as tmp:
        (np.savez_compressed if compressed else np.savez)(tmp, **arrays)
    return path


def save_table(path, **arrays) -> Path:
    """Write ``arrays`` as one compressed ``.npz`` (no pickle), atomically.

    The precomputed tables (wall kernels, vein tables, the fit's forward table) are written this way.
    """
    return save_npz(path, compressed=True, **arrays)


def save_profile(path: Path, prof: MCProfile) -> None:
    """Write a Monte Carlo profile as one ``.npz`` (no pickle), atomically."""
    save_npz(
        path,
        **{k: getattr(prof, k) for k in _ARRAYS},
        n_photons=np.int64(prof.n_photons),
        n_interactions=np.int64(prof.n_interactions),
        params=np.array(json.dumps(prof.params, sort_keys=True)),
        **{k: np.float64(getattr(prof, k)) for k in _SCALARS + _OPTIONAL_SCALARS},
    )


def load_profile(path: Path) -> MCProfile:
    """Read a profile written by :func:`save_profile`.

    The layered runs' entries written before their results were profiles (the shipped
    ``layered-*.npz``) lack the radiance, the transmittance's error, the collision count and
    the parameters: read as NaN, NaN, 0 and ``{}``.
    """
    with np.load(path, allow_pickle=False) as z:
        files = set(z.files)
        values = z["values"]
        arrays = {
            k: (z[k] if k in files or k not in _LAYERED_ABSENT else np.full(values.shape, np.nan)) for k in _ARRAYS
        }
        scalars = {k: (float(z[k]) if k in files or k not in _LAYERED_ABSENT else math.nan) for k in _SCALARS}
        return MCProfile(
            **arrays,
            n_photons=int(z["n_photons"]),
            n_interactions=int(z["n_interactions"]) if "n_interactions" in files else 0,
            params=json.loads(str(z["params"])) if "params" in files else {},
            **scalars,
            **{k: float(z[k]) for k in _OPTIONAL_SCALARS if k in files},
        )

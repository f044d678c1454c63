"""The disk cache of Monte Carlo profiles, and the read-only tables shipped with the package.

An entry is one ``.npz`` (no pickle) named by :func:`cache_key`: a hash of
:data:`ENGINE_VERSION`, every parameter of the run and its bins, so a result is
reused only for an identical run.
"""

from __future__ import annotations

import hashlib
import json
import os
import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np

from .result import MCProfile

__all__ = ["ENGINE_VERSION", "TABLES_DIR", "cache_dir", "cache_key", "save_profile", "load_profile", "write_or_warn"]

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
#: Scalars written since the wall runs (absent from older entries: read as 0).
_OPTIONAL_SCALARS = ("wall_loss", "wall_loss_stderr")


def write_or_warn(write: Callable[[Path], None], path: Path) -> None:
    """Write a cache entry with ``write(path)``; if the disk refuses, warn and go on.

    A read-only home must not cost the result just computed: the warning (a
    ``RuntimeWarning`` attributed to the caller of the Monte Carlo function) names the
    file and says how to point the cache elsewhere.
    """
    try:
        write(path)
    except OSError as exc:
        warnings.warn(
            f"{path}: could not write the Monte Carlo cache ({exc}); set PLANERAY_CACHE to a writable folder",
            RuntimeWarning,
            stacklevel=3,
        )


def save_table(path, **arrays) -> Path:
    """Write ``arrays`` as one compressed ``.npz`` (no pickle), atomically: a temporary beside it, then a rename.

    The precomputed tables (wall kernels, vein tables, the fit's forward table) are written this way.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.stem}.{os.getpid()}.tmp.npz")
    try:
        np.savez_compressed(tmp, **arrays)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path


def save_profile(path: Path, prof: MCProfile) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.stem + f".{os.getpid()}.tmp.npz")
    try:
        np.savez(
            tmp,
            **{k: getattr(prof, k) for k in _ARRAYS},
            n_photons=np.int64(prof.n_photons),
            n_interactions=np.int64(prof.n_interactions),
            params=np.array(json.dumps(prof.params, sort_keys=True)),
            **{k: np.float64(getattr(prof, k)) for k in _SCALARS + _OPTIONAL_SCALARS},
        )
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def load_profile(path: Path) -> MCProfile:
    with np.load(path, allow_pickle=False) as z:
        return MCProfile(
            **{k: z[k] for k in _ARRAYS},
            n_photons=int(z["n_photons"]),
            n_interactions=int(z["n_interactions"]),
            params=json.loads(str(z["params"])),
            **{k: float(z[k]) for k in _SCALARS},
            **{k: float(z[k]) for k in _OPTIONAL_SCALARS if k in z.files},
        )

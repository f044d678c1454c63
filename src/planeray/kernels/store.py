"""The one table store of the forward models: the table shipped with the package, else the user's cache, else
build it and save it there.

Every precomputed table -- Monte Carlo profiles (:func:`planeray.mc.mc_line_profile`), wall-kernel
tables (:mod:`planeray.kernels.wall`), vein tables (:mod:`planeray.kernels.vein`), the fit's forward
table (:mod:`planeray.kernels.forward`) -- is looked up by :func:`stored`, under a file name that hashes
everything the table depends on (:func:`cache_key`).  The implementation lives with the Monte Carlo
cache (:mod:`planeray.mc.cache`, which the photon runs use too); this module is its public face.

* :data:`TABLES_DIR`: the read-only tables shipped with the package (``tools/build_mc_tables.py``,
  ``tools/build_fit_table.py`` write them);
* :func:`cache_dir`: the user cache, ``$PLANERAY_CACHE/mc`` or ``~/.cache/planeray/mc``;
* :func:`where`: ``"shipped"``, ``"cached"`` or None for an entry's file name.
"""

from __future__ import annotations

from ..mc.cache import TABLES_DIR, cache_dir, cache_key, save_table, stored, where

__all__ = ["TABLES_DIR", "cache_dir", "cache_key", "save_table", "stored", "where"]

"""Regenerate the Monte Carlo kernels shipped in src/planeray/mc/tables/.

Every built-in scene is built once with its defaults in an empty cache; whatever
Monte Carlo profiles that traces (10^6 photons each, today only the wax medium)
are copied into the package, so building a scene never waits for Monte Carlo.
Run after any change to the MC engine or to a scene's medium defaults (the
engine version and all parameters are part of every cache key, so stale tables
are simply not found; tests/test_mc.py checks they are):

    python tools/build_mc_tables.py
"""

from __future__ import annotations

import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

from planeray.mc.cache import TABLES_DIR
from planeray.scenes import list_scenes, make_scene


def main() -> int:
    TABLES_DIR.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        os.environ["PLANERAY_CACHE"] = tmp
        for name in list_scenes():
            t0 = time.perf_counter()
            make_scene(name, (64, 64), projector_rows=720, seed=0)
            for f in sorted((Path(tmp) / "mc").glob("*.npz")):
                if not (TABLES_DIR / f.name).exists():
                    shutil.copy(f, TABLES_DIR / f.name)
                    print(f"{name}: {f.name} ({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())

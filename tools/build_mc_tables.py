"""Regenerate the Monte Carlo kernels shipped in src/planeray/mc/tables/.

Every built-in scene is built once with its defaults in an empty cache; whatever
Monte Carlo profiles that traces are copied into the package, so building a scene
never waits for Monte Carlo:

* the wax medium's line kernel (10^6 photons);
* the ``materials`` scene's wall-kernel tables (``wall-*.npz``: per medium, the slab
  kernel with 10^6 photons and the kernels beside a wall at 15 distances and 3 angles
  with 10^5 photons each; :func:`planeray.kernels.wall.mc_wall_table`), for the default
  (Narasimhan et al.) media at the red, green and blue laser lines and for the Jensen et
  al. milks of the report's robustness check (red).  The slab profiles they trace on the way are not shipped (the tables hold them);
* the ``skin`` scene's vein perturbation tables (``skin-*.npz``: fair and dark skin at 638
  and 850 nm, 400,000 photons each; :func:`planeray.kernels.vein.mc_vein_table`) and the
  background kernels of the tones in between (``layered-*.npz``, 100,000 photons each;
  tests/test_skin.py checks they are all shipped).

Run after any change to the MC engine, the wall runs or a scene's medium defaults (the
engine and wall versions and all parameters are part of every cache key, so stale tables
are simply not found; tests/test_mc.py and tests/test_mc_wall.py check they are):

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
from planeray.optical_data_skin import SKIN_TONES
from planeray.scenes import list_scenes, make_scene

#: Scene builds beyond the defaults whose kernels ship too: (scene, parameters).
EXTRA = [
    ("materials", {"source": "jensen"}),
    ("materials", {"channel": "green"}),
    ("materials", {"channel": "blue"}),
] + [("skin", {"wavelength_nm": w, "tone": t}) for w in (638, 850) for t in SKIN_TONES if (w, t) != (638, "fair")]
#: Which of a scene's cache entries ship (default: all it traced).
SHIPPED = {"materials": "wall-*.npz"}


def main() -> int:
    TABLES_DIR.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        os.environ["PLANERAY_CACHE"] = tmp
        builds = [(name, {}) for name in list_scenes()] + EXTRA
        cache = Path(tmp) / "mc"
        for name, params in builds:
            t0 = time.perf_counter()
            before = set(cache.glob("*.npz"))
            make_scene(name, (64, 64), projector_rows=720, seed=0, **params)
            pattern = SHIPPED.get(name, "*.npz")
            for f in sorted(set(cache.glob(pattern)) - before):
                if not (TABLES_DIR / f.name).exists():
                    shutil.copy(f, TABLES_DIR / f.name)
                    print(
                        f"{name} {params or ''}: {f.name} ({f.stat().st_size / 1e3:.0f} kB, {time.perf_counter() - t0:.0f} s)"
                    )
    return 0


if __name__ == "__main__":
    sys.exit(main())

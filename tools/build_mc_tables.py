"""Regenerate the Monte Carlo kernels shipped in src/planeray/mc/tables/.

The built-in scenes' default media are traced once here (10^6 photons each) so
that building a scene never waits for Monte Carlo.  Run after any change to the
MC engine (its version is part of every cache key, so stale tables are simply
not found; tests/test_mc.py checks they are):

    python tools/build_mc_tables.py
"""

from __future__ import annotations

import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from planeray.kernels import mc_line_kernel
from planeray.mc.engine import TABLES_DIR

# (sigma_a, sigma_s', eta, g, mm_per_row) of the built-in scenes' defaults.
MEDIA = {
    "wax": (0.003, 0.3, 1.4, 0.8, 0.3),
}


def main() -> int:
    TABLES_DIR.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        os.environ["PLANERAY_CACHE"] = tmp
        for name, (sigma_a, sigma_sp, eta, g, mm) in MEDIA.items():
            t0 = time.perf_counter()
            mc_line_kernel(np.arange(-1, 2), mm, sigma_a, sigma_sp / (1.0 - g), g, eta)
            for f in (Path(tmp) / "mc").glob("*.npz"):
                if not (TABLES_DIR / f.name).exists():
                    shutil.copy(f, TABLES_DIR / f.name)
                    print(f"{name}: {f.name} ({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())

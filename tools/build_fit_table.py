"""Regenerate the forward table of ``planeray materials fit`` shipped in src/planeray/mc/tables/ (``fit-*.npz``).

90 Monte Carlo line kernels (:func:`planeray.materials.fit.build_forward_table`: 10 x 9 log grid of
``mu_s'`` 0.126-8 /mm and ``mu_a`` 0.0005-0.2 /mm at 0.3 mm per row, g 0.8, n 1.33, 10^5 photons
each; about 6 minutes on 2 cores).  Run after any change to the Monte Carlo engine:

    python tools/build_fit_table.py
"""

from __future__ import annotations

import time

from planeray.kernels.forward import forward_table_name
from planeray.materials import fit
from planeray.mc.cache import TABLES_DIR


def main() -> None:
    t0 = time.time()
    done = [0]

    def tick(k):
        done[0] += k
        print(f"\r{done[0]} / 90 grid points, {time.time() - t0:.0f} s", end="", flush=True)

    table = fit.build_forward_table(progress=tick)
    name = forward_table_name(fit.DEFAULT_G, fit.DEFAULT_N, fit.TABLE_PHOTONS, 0)
    path = table.save(TABLES_DIR / name)
    print(f"\nwrote {path} in {time.time() - t0:.0f} s")


if __name__ == "__main__":
    main()

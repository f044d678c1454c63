"""Build the shipped media library (src/planeray/mc/tables/media-library.json): physical parameters (version 2).

    nice -n 19 python tools/build_media_library.py [--size 64] [--ship-tables]

The library: the five Fig. 10 media **measured** on a reference capture of the ``materials`` scene (``--size`` x
``--size`` pixels, placement 0, seed 0, the default camera, red line, Narasimhan milks), each tray fitted as a whole
from the stack's images with its walls modelled (:func:`planeray.materials.recognize.entries_from_stack`), with the
medium's refractive index and, for the soap, its 30 mm layer (the user states them; ``planeray.optical_data``).
An entry holds the fitted ``mu_s'`` and ``mu_a`` with their uncertainties: values of the medium, which recognize it
in captures of any resolution and row size.  ``--ship-tables`` also copies the forward tables of the indices other
than 1.33 (traced once, cached) into the shipped tables, so a fresh clone recognizes without tracing.
"""

from __future__ import annotations

import argparse
import math
import shutil

from planeray.camera import CameraModel
from planeray.experiments.materials import simulate_capture
from planeray.kernels.forward import forward_table_name
from planeray.materials import fit
from planeray.materials.library import DEFAULT_LIBRARY_PATH, MediaLibrary, save_library
from planeray.materials.recognize import entries_from_stack
from planeray.mc.cache import TABLES_DIR, cache_dir
from planeray.optical_data import MATERIAL_CLASSES, material_medium, optical_table


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=64)
    ap.add_argument("--ship-tables", action="store_true")
    args = ap.parse_args()
    cap = simulate_capture(size=(args.size, args.size), seed=0, placement=0)
    camera = CameraModel.from_metadata(cap.stack.metadata)
    published = {
        r["class_id"]: {
            "mu_s_prime_per_mm": r["sigma_s_prime"],
            "mu_a_per_mm": r["sigma_a"],
            "reference": "planeray.optical_data (Narasimhan et al. 2006 milks; toothpaste, soap argued there)",
        }
        for r in optical_table()
    }
    source = f"materials scene, {args.size}x{args.size}, seed 0, placement 0, red, Narasimhan 2006 milks"
    entries = []
    for cid, name in MATERIAL_CLASSES.items():
        med = material_medium(cid)
        n = round(float(med.n), 4)
        depth = None if math.isinf(med.thickness_mm) else float(med.thickness_mm)
        (e,) = entries_from_stack(
            cap.stack, cap.labels, {cid: name}, mm_per_row=0.3, n=n, depth_mm=depth, camera=camera,
            source=source, published=published, table=fit.forward_table(n=n),
        )  # fmt: skip
        entries.append(e)
        print(f"{name}: mu_s' {e.mu_s_prime_per_mm:.4g} /mm (+- {100 * e.mu_s_prime_log_sd:.1f} %), mu_a "
              f"{e.mu_a_per_mm} (+- {e.mu_a_log_sd}), published {published[cid]}")  # fmt: skip
        if args.ship_tables and n != fit.DEFAULT_N:
            name_ = forward_table_name(fit.DEFAULT_G, n, fit.TABLE_PHOTONS, 0)
            if not (TABLES_DIR / name_).exists():
                shutil.copy(cache_dir() / name_, TABLES_DIR / name_)
                print(f"  shipped the forward table of n = {n:g}: {TABLES_DIR / name_}")
    lib = MediaLibrary(
        tuple(entries),
        {"reference_capture": source, "mm_per_row": 0.3, "rows_per_camera_row": 720 / args.size,
         "fit": "each tray as a whole from the stack's images, walls modelled, shape only"},
        2,
    )  # fmt: skip
    save_library(lib, DEFAULT_LIBRARY_PATH)
    print(f"wrote {DEFAULT_LIBRARY_PATH}")


if __name__ == "__main__":
    main()

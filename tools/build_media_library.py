"""Build the shipped media library (src/planeray/mc/tables/media-library.json) and run the recognition study.

    nice -n 19 python tools/build_media_library.py [--out-study DIR]

The library: the five Fig. 10 media as planeray's fit returns them on the reference capture
(the materials report's training capture, 128 x 128, red line, Narasimhan milks), 2 x 2
pixel blocks within each labelled tray, every pixel including those next to the walls
(:func:`planeray.experiments.materials_recognition.reference_library`).  About 15-25
minutes on 2 shared cores (the block fits); ``--out-study`` also writes the study's folder
(:func:`~planeray.experiments.materials_recognition.run_recognition_study`), which repeats
the library's fit.
"""

from __future__ import annotations

import argparse

from planeray.experiments.materials import TRAIN_SETTINGS, simulate_capture
from planeray.experiments.materials_recognition import reference_library, run_recognition_study
from planeray.materials.library import DEFAULT_LIBRARY_PATH, save_library
from planeray.materials.model import capture_transport


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out-study", default=None, help="also run the recognition study into this folder")
    args = ap.parse_args()
    cap = simulate_capture(size=(128, 128), **TRAIN_SETTINGS)
    lib, _ = reference_library(capture_transport(cap.stack), cap.labels, source=_SOURCE)
    save_library(lib, DEFAULT_LIBRARY_PATH)
    print(f"wrote {DEFAULT_LIBRARY_PATH}")
    if args.out_study:
        run_recognition_study(args.out_study, progress=print)


_SOURCE = "materials scene, report training capture (seed 0, placement 0, 128x128, red, Narasimhan 2006 milks)"

if __name__ == "__main__":
    main()

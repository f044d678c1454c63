"""Screenshots of the projector's patterns for the docs page "Build and run the rig".

Starts its own two-screen Xvfb, shows each pattern with ``planeray.projector.ProjectorWindow`` on screen 1,
reads the screen back from the X server and writes it (and a 4x crop of its top-left corner, where single
rows can be seen) to docs/_static/rig/::

    python tools/rig_screenshots.py
"""

import os
import sys
from pathlib import Path

import numpy as np
from PIL import Image

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from xvfb import start_xvfb, stop_xvfb

OUT = Path(__file__).resolve().parents[1] / "docs" / "_static" / "rig"
PATTERNS = {"comb_8_3": "comb:8:3", "rows_300_340": "rows:300:340", "card": "card"}


def main() -> None:
    proc, name = start_xvfb()
    os.environ["DISPLAY"] = name
    from planeray.projector import ProjectorWindow, grab_screen, parse_pattern

    OUT.mkdir(parents=True, exist_ok=True)
    try:
        with ProjectorWindow(1) as window:
            for stem, spec in PATTERNS.items():
                pattern = parse_pattern(spec, window.shape)
                window.show(pattern)
                shot = grab_screen(window.screen)
                assert np.array_equal(shot[:, :, 0], pattern), spec
                Image.fromarray(shot).save(OUT / f"{stem}.png", optimize=True)
                crop = shot[:90, :160].repeat(4, axis=0).repeat(4, axis=1)
                Image.fromarray(crop).save(OUT / f"{stem}_corner.png", optimize=True)
                print(OUT / f"{stem}.png")
    finally:
        stop_xvfb(proc)


if __name__ == "__main__":
    main()

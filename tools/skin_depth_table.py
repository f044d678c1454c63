"""Vein depth on the simulated skin scene: the validation table of ``planeray.experiments.skin_depth``.

Every vein of the straight layout or the seeded forearm, over tones, wavelengths and seeds:
the true depth of its top and diameter, the estimate +- standard error, resolved or the reason,
and the counts against the issue's target (resolved veins 1-3 mm deep within 0.5 mm).

Run (nice: ~3-20 s per vein on 2 busy cores):
``nice -n 19 .venv/bin/python tools/skin_depth_table.py --layout forearm --seeds 0 1 [--conditions fair:638 dark:850]
[--json out.json --figure out.png]``
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from planeray.experiments.skin_depth import CONDITIONS, depth_summary, depth_validation, format_table


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--layout", choices=("forearm", "straight"), default="forearm")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1])
    ap.add_argument("--conditions", nargs="+", default=[f"{t}:{w}" for t, w in CONDITIONS], help="TONE:NM ...")
    ap.add_argument("--size", type=int, default=128)
    ap.add_argument("--joint-rounds", type=int, default=1)
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--figure", type=Path, default=None, help="PNG of estimated against true depth")
    a = ap.parse_args(argv)
    conds = [(c.split(":")[0], int(c.split(":")[1])) for c in a.conditions]
    rows = depth_validation(
        a.layout,
        conditions=conds,
        seeds=a.seeds,
        size=(a.size, a.size),
        joint_rounds=a.joint_rounds,
        progress=lambda m: print(m, flush=True),
    )
    print(format_table(rows))
    print(json.dumps(depth_summary(rows)))
    if a.json is not None:
        a.json.write_text(json.dumps(rows, indent=1))
    if a.figure is not None:
        from planeray.figures.skin import depth_validation_figure

        depth_validation_figure(rows, title=f"Vein depth, {a.layout}: estimated vs true", out=a.figure)


if __name__ == "__main__":
    main()

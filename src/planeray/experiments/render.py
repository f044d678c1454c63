"""The example Mitsuba scenes end to end: transport stores, figures and numbers in one folder.

For each shipped example (:func:`planeray.render.example_scenes`: the paper's
Fig. 8/9 setups -- a mirror ball on a book page, a disco ball, a wax candle, a
room corner) :func:`run_render_examples` renders the transport
(:func:`planeray.render.render_to_store`; the disco ball with its caustic pass),
draws :func:`planeray.figures.render.rendered_scene_figure` and records the
numbers (time, variant, light per path class, labels, long-range entries) in
``render_examples.json``.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .._validate import check_integer
from ..figures.render import rendered_scene_figure
from ..io import atomic_file
from ..render import example_scenes, render_to_store, render_work
from ..scenes import EFFECTS

__all__ = ["run_render_examples", "render_examples_work"]


def _kwargs(size, projector_rows, spp, seed):
    return {"shape": (size, size), "projector_rows": projector_rows, "spp": spp, "seed": seed}


def render_examples_work(*, size=128, projector_rows=720, spp=64, seed=0, names=None) -> int:
    """Progress units of :func:`run_render_examples` (render batches + one per figure)."""
    names = list(names or example_scenes())
    kw = _kwargs(size, projector_rows, spp, seed)
    return sum(render_work(example_scenes()[n], **kw) + 1 for n in names)


def run_render_examples(
    out_dir, *, size=128, projector_rows=720, spp=64, seed=0, names=None, overwrite=False, progress=None
) -> dict:
    """Render the example scenes into ``out_dir``: ``NAME.zarr`` (transport store), ``NAME.png``, a JSON summary.

    Parameters
    ----------
    out_dir : str or os.PathLike
    size : int
        Camera pixels per side.
    projector_rows, spp, seed : int
        As :func:`planeray.render.render_transport`.
    names : list of str, optional
        A subset of the examples (default: all).
    overwrite : bool
        Replace stores and figures a previous run wrote.
    progress : callable, optional
        ``progress(n)``; :func:`render_examples_work` gives the total.

    Returns
    -------
    dict
        Per scene: seconds, variant, light per path class (fractions), label counts,
        sparse entries, dropped fraction; also written as ``render_examples.json``.
    """
    check_integer(size, "size", minimum=8)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    examples = example_scenes()
    names = list(names or examples)
    unknown = [n for n in names if n not in examples]
    if unknown:
        raise ValueError(f"unknown example scenes {unknown}; choose from {sorted(examples)}")
    summary = {}
    for name in names:
        store = out / f"{name}.zarr"
        _, result = render_to_store(
            examples[name], store, overwrite=overwrite, progress=progress, **_kwargs(size, projector_rows, spp, seed)
        )
        png = out / f"{name}.png"
        if png.exists() and not overwrite:
            raise FileExistsError(f"{png}: already exists (pass --overwrite, or overwrite=True, to replace it)")
        rendered_scene_figure(result.transport, result.labels, title=f"{name} (Mitsuba 3, {spp} spp)", out=png)
        if progress is not None:
            progress(1)
        light = result.classes.sum(axis=(1, 2))
        total = float(light.sum()) or 1.0
        counts = np.bincount(result.labels.ravel(), minlength=len(EFFECTS))
        summary[name] = {
            "seconds": round(result.attrs["seconds"], 2),
            "variant": result.attrs["variant"],
            "caustics": result.attrs["caustics"],
            "light_fraction": {EFFECTS[i + 1]: round(float(v) / total, 4) for i, v in enumerate(light)},
            "labels": {EFFECTS[i]: int(c) for i, c in enumerate(counts) if c},
            "sparse_entries": len(result.transport.sparse),
            "dropped_fraction": result.dropped_fraction,
            "files": [store.name, png.name],
        }
    with atomic_file(out / "render_examples.json", overwrite=True) as tmp:
        tmp.write_text(json.dumps({"size": size, "projector_rows": projector_rows, "spp": spp, **summary}, indent=2))
    return summary

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
from ..io.marks import MARK_KEY, mark_text
from ..render import example_scenes, render_to_store, render_work
from ..scenes import EFFECTS

__all__ = ["run_render_examples", "render_examples_work", "render_examples_outputs"]

#: The summary of a run, beside the stores and figures.
SUMMARY = "render_examples.json"


def _kwargs(size, projector_rows, spp, seed):
    return {"shape": (size, size), "projector_rows": projector_rows, "spp": spp, "seed": seed}


def render_examples_work(*, size=128, projector_rows=720, spp=64, seed=0, names=None) -> int:
    """Progress units of :func:`run_render_examples` (render batches + one per figure)."""
    names = list(names or example_scenes())
    kw = _kwargs(size, projector_rows, spp, seed)
    return sum(render_work(example_scenes()[n], **kw) + 1 for n in names)


def _names(names) -> list[str]:
    examples = example_scenes()
    names = list(names or examples)
    unknown = [n for n in names if n not in examples]
    if unknown:
        raise ValueError(f"unknown example scenes {unknown}; choose from {sorted(examples)}")
    return names


def render_examples_outputs(out_dir, *, names=None) -> list[tuple[Path, str]]:
    """``(path, kind)`` of every file :func:`run_render_examples` writes (to check them before any work)."""
    out = Path(out_dir)
    files = []
    for name in _names(names):
        files += [(out / f"{name}.zarr", "transport"), (out / f"{name}.png", "figure")]
    return files + [(out / SUMMARY, "record")]


def run_render_examples(
    out_dir,
    *,
    size=128,
    projector_rows=720,
    spp=64,
    seed=0,
    names=None,
    overwrite=False,
    progress=None,
    on_resume=None,
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
    on_resume : callable, optional
        ``on_resume(name, done, total)`` when the render of scene ``name`` resumes
        an unfinished one (batches).

    Every output (:func:`render_examples_outputs`) is checked before any work: an
    existing one is replaced only with ``overwrite`` and only if planeray wrote it
    (a result of the same kind); ``out_dir`` itself may hold other files.

    Returns
    -------
    dict
        Per scene: seconds, variant, light per path class (fractions), label counts,
        sparse entries, dropped fraction; also written as ``render_examples.json``.
    """
    from ..io.atomic import check_replaceable

    check_integer(size, "size", minimum=8)
    out = Path(out_dir)
    names = _names(names)
    for path, kind in render_examples_outputs(out, names=names):
        check_replaceable(path, overwrite=overwrite, kind=kind)
    out.mkdir(parents=True, exist_ok=True)
    examples = example_scenes()
    summary = {}
    for name in names:
        store = out / f"{name}.zarr"
        _, result = render_to_store(
            examples[name],
            store,
            overwrite=overwrite,
            progress=progress,
            on_resume=None if on_resume is None else (lambda done, total, name=name: on_resume(name, done, total)),
            **_kwargs(size, projector_rows, spp, seed),
        )
        png = out / f"{name}.png"
        check_replaceable(png, overwrite=overwrite, kind="figure")  # it may have appeared meanwhile
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
    record = {MARK_KEY: mark_text("record"), "size": size, "projector_rows": projector_rows, "spp": spp, **summary}
    check_replaceable(out / SUMMARY, overwrite=overwrite, kind="record")
    with atomic_file(out / SUMMARY) as tmp:
        tmp.write_text(json.dumps(record, indent=2))
    return summary

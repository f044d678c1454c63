"""A simulated capture of the skin scene: a native stack plus its ground truth beside it.

:func:`simulate_skin` builds the ``skin`` scene (:mod:`planeray.scenes.skin`), sweeps it on
the simulated Episcan (:func:`planeray.acquire.simulate_stack`) and writes ``STACK`` (a
native Zarr stack) with, beside it (``STEM`` is ``STACK``'s name without ``.zarr``):

``STEM_vein_mask.png``
    8-bit PNG, 255 over a vein (the scene's ``vein_mask``);
``STEM_veins.json``
    ``{"format": "planeray-skin-truth", "stack": ..., "scene": scene.params, "veins": [...]}``:
    every vein (id, parent, depth of its top and of its axis, diameter, centreline in
    surface mm, pixel count);
``STEM_maps.npz``
    every ground-truth map of the scene (``vein_id``, ``vein_depth_mm``, ...), no pickle.

:func:`read_skin_truth` reads them back.  Each file carries planeray's mark of kind ``skin truth``
(:mod:`planeray.io.marks`: the PNG's ``Software`` text, the JSON's ``planeray_mark``, the npz's
``planeray_mark`` member), and each is replaced (``overwrite``) only if its own mark says planeray
wrote it as ground truth -- never a user's file of the same name, nor another planeray file
(a video's vein mask, a figure).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..acquire import simulate_stack
from ..camera import CameraModel
from ..errors import InputError
from ..io import atomic_file, write_stack
from ..io.atomic import check_replaceable
from ..io.marks import MARK_KEY, mark_text, png_mark_info
from ..scenes import make_scene
from ..scenes.skin import skin_veins
from ..timing import PAPER_PROJECTOR_ROWS, make_sweep

__all__ = [
    "TRUTH_FORMAT",
    "TRUTH_KIND",
    "SkinCapture",
    "truth_paths",
    "simulate_skin",
    "write_skin_truth",
    "read_skin_truth",
]

TRUTH_FORMAT = "planeray-skin-truth"
#: Kind of the mark every ground-truth file carries (:func:`planeray.io.marks.mark_text`).
TRUTH_KIND = "skin truth"


def truth_paths(stack_path) -> dict:
    """The ground-truth files beside a stack: ``mask``, ``veins`` and ``maps`` paths."""
    p = Path(stack_path)
    stem = p.name[: -len(".zarr")] if p.name.endswith(".zarr") else p.name
    return {
        "mask": p.with_name(f"{stem}_vein_mask.png"),
        "veins": p.with_name(f"{stem}_veins.json"),
        "maps": p.with_name(f"{stem}_maps.npz"),
    }


def _ours(veins_json: Path) -> bool:
    try:
        meta = json.loads(veins_json.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    return isinstance(meta, dict) and meta.get("format") == TRUTH_FORMAT


def _check_truth(stack_path, overwrite: bool) -> None:
    """Refuse ground-truth files beside the stack that exist (without ``overwrite``) or are not planeray's truth."""
    for path in truth_paths(stack_path).values():
        check_replaceable(path, overwrite=overwrite, kind=TRUTH_KIND)


def write_skin_truth(scene, stack_path, *, overwrite: bool = False, then=None) -> dict:
    """Write the ground truth of a skin ``scene`` beside ``stack_path`` (see the module docstring).

    The three files are written into temporaries and renamed into place together, after
    ``then()`` (if given: :func:`simulate_skin` writes the stack there) has succeeded: a failure
    anywhere leaves none of them behind.
    """
    import contextlib

    from PIL import Image

    _check_truth(stack_path, overwrite)
    paths = truth_paths(stack_path)
    veins = [
        {
            "id": v.id,
            "parent": v.parent,
            "depth_mm": v.depth_mm,
            "axis_depth_mm": v.axis_depth_mm,
            "diameter_mm": v.diameter_mm,
            "pixels": int(v.mask.sum()),
            "points_mm": np.round(v.points_mm, 4).tolist(),
        }
        for v in skin_veins(scene)
    ]
    mark = mark_text(TRUTH_KIND)
    meta = {
        "format": TRUTH_FORMAT,
        MARK_KEY: mark,
        "stack": Path(stack_path).name,
        "scene": scene.params,
        "veins": veins,
    }
    with contextlib.ExitStack() as files:
        tmp = {k: files.enter_context(atomic_file(p, overwrite=overwrite)) for k, p in paths.items()}
        with open(tmp["maps"], "wb") as f:
            maps = {k: np.asarray(v) for k, v in scene.maps.items() if k != MARK_KEY}
            np.savez_compressed(f, **maps, **{MARK_KEY: np.asarray(mark)})
        Image.fromarray(np.where(scene.maps["vein_mask"], 255, 0).astype(np.uint8), mode="L").save(
            tmp["mask"], format="PNG", pnginfo=png_mark_info(TRUTH_KIND)
        )
        Path(tmp["veins"]).write_text(json.dumps(meta, indent=1), encoding="utf-8")
        if then is not None:
            then()
    return paths


def read_skin_truth(stack_path) -> tuple[dict, dict]:
    """``(meta, maps)`` written by :func:`write_skin_truth` beside ``stack_path``."""
    paths = truth_paths(stack_path)
    if not _ours(paths["veins"]):
        raise InputError(f"no {TRUTH_FORMAT} ground truth beside the stack", paths["veins"])
    meta = json.loads(paths["veins"].read_text(encoding="utf-8"))
    try:
        with np.load(paths["maps"], allow_pickle=False) as z:
            maps = {k: z[k] for k in z.files if k != MARK_KEY}
    except (OSError, ValueError) as exc:
        raise InputError(f"unreadable ground-truth maps ({exc})", paths["maps"]) from None
    return meta, maps


@dataclass
class SkinCapture:
    """A simulated skin capture: the scene (ground truth) and the stack."""

    scene: object
    stack: object
    paths: dict


def simulate_skin(
    out=None,
    *,
    size=(128, 128),
    projector_rows: int = PAPER_PROJECTOR_ROWS,
    seed: int = 0,
    sweep: str = "paper",
    camera: CameraModel | None = None,
    noise: bool = True,
    overwrite: bool = False,
    progress=None,
    **scene_params,
) -> SkinCapture:
    """Simulate a sweep of the ``skin`` scene; with ``out`` write the stack and its ground truth.

    ``scene_params`` go to ``make_scene("skin", ...)`` (``tone``, ``wavelength_nm``,
    ``hair``, ``curved``, ``veins``, ...); ``camera`` defaults to :class:`CameraModel`.
    Outputs are checked before any work.
    """
    if out is not None:
        check_replaceable(out, overwrite=overwrite, kind="stack")
        _check_truth(out, overwrite)
    scene = make_scene("skin", tuple(int(v) for v in size), projector_rows=projector_rows, seed=seed, **scene_params)
    stack = simulate_stack(scene, make_sweep(sweep), camera=camera, seed=seed, noise=noise, progress=progress)
    paths = {}
    if out is not None:
        # the truth files go into place only once the stack is written (a failure leaves neither)
        paths = write_skin_truth(
            scene, out, overwrite=overwrite, then=lambda: write_stack(stack, out, overwrite=overwrite)
        )
        paths["stack"] = Path(out)
    return SkinCapture(scene, stack, paths)

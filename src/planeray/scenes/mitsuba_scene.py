"""``mitsuba:FILE.xml``: any Mitsuba 3 scene, its transport rendered physically (:mod:`planeray.render`).

``make_scene("mitsuba:room.xml", (128, 128), projector_rows=720)`` renders the
scene file's plane-to-ray transport with :func:`planeray.render.render_transport`
(one camera-side pass, plus the caustic pass when asked or when the file says
``<default name="planeray_caustics" value="true"/>``), so the simulated device,
the viewer and every analysis run on it.  ``FILE`` may also name a shipped
example (``mitsuba:mirror_ball``, ``disco_ball``, ``wax_candle``, ``room_corner``:
:func:`planeray.render.example_scenes`).  The ground truth is the render: an
estimate with Monte Carlo noise (``spp`` camera paths per pixel), not an exact
transport; the labels come from the path classes of the render
(:func:`planeray.render.labels_from_classes`), the direct image from its
single-bounce paths and the ambient albedo from the diffuse reflectance each
pixel sees first.
"""

from __future__ import annotations

from pathlib import Path

from ..errors import InputError
from .base import DEFAULT_BAND_ROWS, Scene, register_scene


def resolve_scene_file(argument: str) -> Path:
    """A scene file path, or a shipped example's by name."""
    from ..render import example_scenes

    path = Path(argument)
    if path.is_file():
        return path
    examples = example_scenes()
    if argument in examples:
        return examples[argument]
    raise InputError(f"no such scene file, and not an example scene (examples: {', '.join(examples)})", argument)


@register_scene(
    "mitsuba", "any Mitsuba 3 scene file rendered to its transport (or a shipped example)", argument="FILE.xml"
)
def build(shape, projector_rows, seed, *, argument, spp=64, band_rows=DEFAULT_BAND_ROWS, **render_options) -> Scene:
    """Render ``argument`` (a scene file or a shipped example's name) into a :class:`Scene`.

    ``render_options`` are those of :func:`planeray.render.render_transport`
    (``batch_spp``, ``max_depth``, ``caustics``, ``caustic_paths``, ``baseline``,
    ``projector_aspect``, ``projector_columns``, ``projector_vfov_deg``, ``rgb``,
    ``variant``, ``max_sparse``, ``camera``, ``vfov_deg``...).
    """
    from ..render import render_transport

    path = resolve_scene_file(argument)
    P = int(shape[0]) if projector_rows is None else int(projector_rows)
    result = render_transport(
        path, shape=shape, projector_rows=P, spp=spp, seed=seed, band_rows=band_rows, **render_options
    )
    a = result.attrs
    params = {
        "scene_file": str(path),
        "scene_digest": a["scene_digest"],
        "spp": int(spp),
        "max_depth": int(a["max_depth"]),
        "caustics": bool(a["caustics"]),
        "band_rows": int(band_rows),
        "baseline": a["rig"]["baseline"],
        "rig": a["rig"],
        "variant": a["variant"],
    }
    maps = {f"light_{k}": result.classes[i] for i, k in enumerate(("direct", "subsurface", "diffuse", "specular"))}
    return Scene("mitsuba", result.transport, result.direct, result.albedo, result.labels, params, maps)

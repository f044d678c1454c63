"""Any Mitsuba 3 scene -> plane-to-ray transport, rendered physically in one pass.

Modules (one topic each):

* :mod:`~planeray.render._mitsuba`: importing Mitsuba, choosing the variant (llvm where its runtime loads);
* :mod:`~planeray.render.rig`: the rectified projector-camera pair and its convention;
* :mod:`~planeray.render.scene_file`: loading and fingerprinting a scene file;
* :mod:`~planeray.render.integrator`: the one-pass tally (camera paths binned by projector row);
* :mod:`~planeray.render.caustics`: the projector-side pass for specular-first paths;
* :mod:`~planeray.render.reference`: per-row renders with Mitsuba's own integrators (check, scalar fallback);
* :mod:`~planeray.render.render`: the driver (batches, resuming, normalization, band + sparse, labels);
* ``scenes/``: example scene files (the paper's Fig. 8/9 setups), :func:`example_scene` finds them.
"""

from __future__ import annotations

from pathlib import Path

from .render import RenderResult, RenderWarning, labels_from_classes, render_to_store, render_transport, render_work

__all__ = [
    "RenderResult",
    "RenderWarning",
    "example_scene",
    "example_scenes",
    "labels_from_classes",
    "render_to_store",
    "render_transport",
    "render_work",
]

_SCENES = Path(__file__).resolve().parent / "scenes"


def example_scenes() -> dict[str, Path]:
    """The shipped example scene files by name (``mirror_ball``, ``disco_ball``, ``wax_candle``, ``room_corner``).

    Returns
    -------
    dict of str to pathlib.Path

    See Also
    --------
    render_transport : renders one.

    Examples
    --------
    >>> sorted(example_scenes())
    ['disco_ball', 'mirror_ball', 'room_corner', 'wax_candle']
    """
    return {p.stem: p for p in sorted(_SCENES.glob("*.xml"))}


def example_scene(name: str) -> Path:
    """Path of a shipped example scene file (a name of :func:`example_scenes`, or a path as it is).

    Parameters
    ----------
    name : str
        A name of :func:`example_scenes`, or a path.

    Returns
    -------
    pathlib.Path

    See Also
    --------
    example_scenes : the names.

    Examples
    --------
    >>> example_scene("room_corner").name
    'room_corner.xml'
    """
    scenes = example_scenes()
    if name in scenes:
        return scenes[name]
    return Path(name)

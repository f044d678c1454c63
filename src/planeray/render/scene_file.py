"""Loading a user's Mitsuba scene file: geometry, materials and media, checked for what planeray renders.

planeray keeps the file's shapes (with their BSDFs and media) and its first
``perspective`` sensor (the camera pose, :mod:`planeray.render.rig`), and
builds the rectified projector itself.  Media must be ``homogeneous`` (the
one-pass tally handles them exactly; heterogeneous media are refused with
one line) behind boundaries that do not refract (``null``, ``thindielectric``):
a point projector's light cannot refract into a medium, so a dielectric
boundary is refused with one line naming the shape.  The file's identity for resuming a render is the SHA-256 of its
bytes and of every file it references (``filename`` properties: meshes,
textures), so a render resumes only on provably identical inputs.
"""

from __future__ import annotations

import hashlib
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

from ..errors import InputError

__all__ = ["LoadedScene", "load_scene_file", "scene_file_digest"]


@dataclass
class LoadedScene:
    """A Mitsuba scene file, loaded in the active variant.

    Attributes
    ----------
    path : Path
    shapes : list of mitsuba.Shape
    sensor : mitsuba.Sensor or None
        The file's first sensor (the camera pose), if any.
    has_media : bool
        Some shape bounds a (homogeneous) medium.
    scene : mitsuba.Scene
        The geometry alone (no emitters), for ray queries.
    defaults : dict
        The file's ``<default>`` parameters (planeray reads ``planeray_*``).
    """

    path: Path
    shapes: list
    sensor: object
    has_media: bool
    scene: object
    defaults: dict


def _referenced_files(path: Path) -> list[Path]:
    root = ET.parse(path).getroot()
    files = []
    for node in root.iter():
        if node.get("name") == "filename" and node.get("value"):
            files.append((path.parent / node.get("value")).resolve())
    return sorted(set(files))


def scene_file_digest(path) -> str:
    """SHA-256 over the scene file's bytes and those of the files it references."""
    path = Path(path)
    h = hashlib.sha256()
    try:
        h.update(path.read_bytes())
        for ref in _referenced_files(path):
            h.update(str(ref.name).encode())
            h.update(ref.read_bytes() if ref.is_file() else b"<missing>")
    except OSError as exc:
        raise InputError(f"cannot read ({exc.strerror})", exc.filename or path) from None
    except ET.ParseError as exc:
        raise InputError(f"not a readable Mitsuba XML scene ({exc})", path) from None
    return h.hexdigest()


def _check_medium_boundary(mi, shape, path) -> None:
    """Refuse a medium whose boundary refracts (a dielectric): no light of a point projector can enter it.

    The projector is a pinhole (a delta light): a path inside the medium reaches it
    only along a straight shadow ray, which a refracting interface never lets
    through, and the caustic pass stops at medium boundaries.  Such light would be
    silently missing from ``T`` (Mitsuba's own ``volpath`` misses it too), so the
    scene is refused.  Boundaries that let light through unbent -- ``null``,
    ``thindielectric`` (a null-transmission component) -- and opaque ones are fine.
    """
    bsdf = shape.bsdf()
    if bsdf is None:
        return
    flags = int(bsdf.flags())
    if flags & int(mi.BSDFFlags.Transmission) and not flags & int(mi.BSDFFlags.Null):
        kind = str(bsdf).split("[", 1)[0].strip() or "refracting"
        raise InputError(
            f"shape {shape.id()!r} bounds a medium through a {kind} boundary, which refracts: no light of the "
            "point projector can enter the medium that way, so it would be missing from T; give the shape an "
            'index-matched boundary (<bsdf type="null"/>, or "thindielectric" for a thin glass wall)',
            path,
        )


def load_scene_file(path) -> LoadedScene:
    """Load ``path`` in the active Mitsuba variant (:func:`planeray.render._mitsuba.choose_variant`)."""
    import mitsuba as mi

    from .rig import xml_defaults

    path = Path(path)
    if not path.is_file():
        raise InputError("no such scene file", path)
    defaults = xml_defaults(path)
    try:
        loaded = mi.load_file(str(path))
    except Exception as exc:  # Mitsuba's parser errors are long; keep their first line
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise InputError(f"Mitsuba cannot load it: {first}", path) from None
    shapes = list(loaded.shapes())
    if not shapes:
        raise InputError("the scene has no shapes", path)
    has_media = False
    for shape in shapes:
        for medium in (shape.interior_medium(), shape.exterior_medium()):
            if medium is not None:
                if not medium.is_homogeneous():
                    raise InputError(
                        f"shape {shape.id()!r} has a heterogeneous medium; planeray renders homogeneous media only",
                        path,
                    )
                _check_medium_boundary(mi, shape, path)
                has_media = True
    sensors = list(loaded.sensors())
    sensor = sensors[0] if sensors else None
    geometry = mi.load_dict({"type": "scene", **{f"shape_{i}": s for i, s in enumerate(shapes)}})
    return LoadedScene(path, shapes, sensor, has_media, geometry, defaults)

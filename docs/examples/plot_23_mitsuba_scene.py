"""
Your own scene: a Mitsuba 3 render as a transport
=================================================

Any Mitsuba 3 scene file becomes a plane-to-ray transport: planeray reads Eq. 4 backwards, tallying
each camera path by the projector row it reaches, in one pass (``planeray render``). The result is
a transport like the built-in scenes', with exact effect labels per pixel; every tool of planeray
applies to it. Here the room corner shipped with planeray, at 64x64 and 32 samples per pixel.

Command line: ``planeray render SCENE.xml --out T.zarr --size 64 64 --spp 32``.
"""

from importlib.resources import files

from planeray.figures.render import rendered_scene_figure
from planeray.render import render_transport

scene_file = files("planeray.render") / "scenes" / "room_corner.xml"
result = render_transport(str(scene_file), shape=(64, 64), projector_rows=720, spp=32, seed=0)
T = result.transport
print(
    f"transport of {T.geometry.camera_rows} camera rows x {T.geometry.projector_rows} projector rows, "
    f"{T.sparse.value.size if T.sparse is not None else 0} sparse entries beyond the band"
)
fig = rendered_scene_figure(T, result.labels, title="room_corner.xml, rendered by Mitsuba 3")

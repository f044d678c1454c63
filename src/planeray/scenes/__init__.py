"""Built-in scenes with exact ground-truth light transport (one module per scene)."""

from .base import (
    EFFECTS,
    Scene,
    footprint_kernel,
    is_scene_name,
    list_scenes,
    make_scene,
    register_scene,
    representative_pixels,
    scene_offsets,
    split_scene_name,
)

__all__ = [
    "EFFECTS",
    "Scene",
    "footprint_kernel",
    "is_scene_name",
    "list_scenes",
    "make_scene",
    "register_scene",
    "representative_pixels",
    "scene_offsets",
    "split_scene_name",
]

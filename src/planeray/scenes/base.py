"""Scene interface and registry (Mitsuba-style: plugins chosen by name).

A scene is a deterministic (seeded) function of image size and geometry that
returns the exact ground-truth :class:`~planeray.transport.Transport` plus the
maps a test or a figure needs to judge an estimate against it.  Each built-in
scene lives in its own module of this package and registers itself with
:func:`register_scene`; modules are discovered automatically, so adding a scene
is adding one module.
"""

from __future__ import annotations

import importlib
import pkgutil
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ..kernels.footprint import footprint_kernel
from ..timing import RowGeometry
from ..transport import Transport

__all__ = [
    "EFFECTS",
    "Scene",
    "register_scene",
    "make_scene",
    "list_scenes",
    "is_scene_name",
    "split_scene_name",
    "scene_offsets",
    "footprint_kernel",
    "DEFAULT_BAND_ROWS",
    "DEFAULT_MM_PER_ROW",
    "representative_pixels",
]

#: Light-transport effect labels of ground-truth pixels (``Scene.labels``).
EFFECTS = {
    0: "none",  # background / no light of interest
    1: "diffuse",  # direct diffuse reflection: narrow, unimodal delay profile
    2: "subsurface",  # subsurface scattering: broadened profile
    3: "diffuse_interreflection",  # steep, one-sided profile
    4: "specular_interreflection",  # a second, displaced peak
}
#: Half-width of the dense offset band stored by built-in scenes (projector rows);
#: light from farther rows becomes sparse long-range entries.
DEFAULT_BAND_ROWS = 128
#: Size of one projector row on the scene: 720 rows over ~216 mm.
DEFAULT_MM_PER_ROW = 0.3


@dataclass
class Scene:
    """A scene with known light transport.

    Attributes
    ----------
    name : str
    transport : Transport
        Exact ground-truth ``T`` (dense band + sparse long-range entries).
    direct : ndarray (H, W) float32
        Ground-truth physical direct light (single bounce).  The epipolar image of
        the transport (Eq. 5) can hold more: indirect light that lands on the
        epipolar plane (e.g. the offset-0 bin of a subsurface kernel).
    ambient_albedo : ndarray (H, W) float32
        Reflectance under ambient (room) light, used by the camera's ambient term.
    labels : ndarray (H, W) uint8
        Dominant effect of each pixel, keys of :data:`EFFECTS`.
    params : dict
        JSON-serializable parameters that rebuild the scene.
    maps : dict of str to ndarray (H, W)
        Further per-pixel ground truth a scene provides (the ``materials`` scene: class
        ids, distance to the nearest container wall, pixels whose kernel the wall changes).

    See Also
    --------
    make_scene : builds one by name.

    Examples
    --------
    >>> scene = make_scene("wax", (8, 8), seed=0)
    >>> scene.name, scene.transport.dense.shape[:2], scene.labels.shape
    ('wax', (8, 8), (8, 8))
    """

    name: str
    transport: Transport
    direct: np.ndarray
    ambient_albedo: np.ndarray
    labels: np.ndarray
    params: dict = field(default_factory=dict)
    maps: dict = field(default_factory=dict)

    @property
    def shape(self) -> tuple[int, int]:
        return self.transport.shape

    @property
    def geometry(self) -> RowGeometry:
        return self.transport.geometry

    def effect_masks(self) -> dict[str, np.ndarray]:
        """``{"all": every pixel, effect name: its pixels}`` for each effect label present (:data:`EFFECTS`).

        The regions that analysis reports errors over (e.g.
        :func:`planeray.baselines.compare_direct_global`), without importing the scenes.
        """
        masks = {"all": np.ones(self.shape, bool)}
        for label in np.unique(self.labels):
            if label != 0:
                masks[EFFECTS[int(label)]] = self.labels == label
        return masks


@dataclass(frozen=True)
class _Entry:
    build: Callable[..., Scene]
    description: str
    argument: str | None = None


_REGISTRY: dict[str, _Entry] = {}
_DISCOVERED = False


def register_scene(name: str, description: str, *, argument: str | None = None):
    """Decorator registering ``build(shape, projector_rows, seed, **params) -> Scene``.

    A *parametric* scene takes an argument in its name, ``NAME:ARGUMENT`` (the
    ``mitsuba`` scene: ``mitsuba:path/to/scene.xml``); ``argument`` names it for
    help texts, and ``build`` receives it as the keyword ``argument``.
    Parametric scenes are listed by ``list_scenes(parametric=True)`` only.

    Parameters
    ----------
    name : str
        The scene's name (no ``:``).
    description : str
        One line for ``planeray scenes``.
    argument : str, optional
        For a parametric scene, the name of its argument (``FILE.xml``).

    Returns
    -------
    callable
        The decorator; it returns ``build`` unchanged.

    See Also
    --------
    make_scene : builds a registered scene.

    Examples
    --------
    A scene of your own, then built by name like the built-in ones:

    >>> import numpy as np
    >>> from planeray.transport import Transport
    >>> @register_scene("doc_flat", "a flat grey plane (an example)")
    ... def _flat(shape, projector_rows, seed, **params):
    ...     H, W = shape
    ...     dense = np.zeros((H, W, 3), np.float32)
    ...     dense[..., 1] = 0.5
    ...     T = Transport(dense, np.array([-1, 0, 1]))
    ...     return Scene(
    ...         "doc_flat", T, direct=dense[..., 1], ambient_albedo=np.full(shape, 0.5), labels=np.ones(shape, int)
    ...     )
    >>> make_scene("doc_flat", (8, 8)).transport.dense.shape
    (8, 8, 3)
    >>> del _REGISTRY["doc_flat"]  # this example leaves the registry as it found it
    """

    def deco(build):
        if name in _REGISTRY and _REGISTRY[name].build is not build:
            raise ValueError(f"scene {name!r} registered twice")
        if ":" in name:
            raise ValueError(f"scene names may not contain ':', got {name!r}")
        _REGISTRY[name] = _Entry(build, description, argument)
        return build

    return deco


def _discover() -> None:
    global _DISCOVERED
    if _DISCOVERED:
        return
    package = __name__.rsplit(".", 1)[0]
    for mod in pkgutil.iter_modules(importlib.import_module(package).__path__):
        if mod.name not in ("base",) and not mod.name.startswith("_"):
            importlib.import_module(f"{package}.{mod.name}")
    _DISCOVERED = True


def list_scenes(*, parametric: bool = False) -> dict[str, str]:
    """Names and one-line descriptions of the registered scenes.

    Parameters
    ----------
    parametric : bool
        Also the scenes that take an argument, as ``NAME:ARGUMENT`` (e.g. ``mitsuba:FILE.xml``).

    Returns
    -------
    dict of str to str
        Name -> one-line description.

    See Also
    --------
    make_scene : build one by name.

    Examples
    --------
    >>> scenes = list_scenes()
    >>> "wax" in scenes, "skin" in scenes
    (True, True)
    """
    _discover()
    out = {k: v.description for k, v in sorted(_REGISTRY.items()) if v.argument is None}
    if parametric:
        out.update({f"{k}:{v.argument}": v.description for k, v in sorted(_REGISTRY.items()) if v.argument})
    return out


def split_scene_name(text: str) -> tuple[str, str | None]:
    """``"mitsuba:room.xml"`` -> ``("mitsuba", "room.xml")``; ``"wax"`` -> ``("wax", None)``.

    Parameters
    ----------
    text : str
        A scene name as typed.

    Returns
    -------
    name : str
    argument : str or None

    See Also
    --------
    is_scene_name : whether it is registered.

    Examples
    --------
    >>> split_scene_name("mitsuba:room.xml"), split_scene_name("wax")
    (('mitsuba', 'room.xml'), ('wax', None))
    """
    name, sep, argument = str(text).partition(":")
    return name, (argument if sep else None)


def is_scene_name(text: str) -> bool:
    """True if ``text`` names a registered scene (``NAME`` or, for a parametric one, ``NAME:ARGUMENT``).

    Parameters
    ----------
    text : str
        A name as typed (``wax``, ``mitsuba:room.xml``).

    Returns
    -------
    bool

    See Also
    --------
    split_scene_name : its parts.

    Examples
    --------
    >>> is_scene_name("wax"), is_scene_name("mitsuba:room.xml"), is_scene_name("wax:x"), is_scene_name("nope")
    (True, True, False, False)
    """
    _discover()
    name, argument = split_scene_name(text)
    entry = _REGISTRY.get(name)
    return entry is not None and (argument is None) == (entry.argument is None) and argument != ""


def make_scene(name: str, shape=(128, 128), *, projector_rows: int | None = None, seed: int = 0, **params) -> Scene:
    """Build a registered scene by name.

    Parameters
    ----------
    name : str
        One of :func:`list_scenes`, or ``NAME:ARGUMENT`` for a parametric scene
        (``mitsuba:scene.xml``: :mod:`planeray.scenes.mitsuba_scene`).
    shape : (int, int)
        Camera image ``(H, W)``.
    projector_rows : int, optional
        Projector rows spanned by the image height (default ``H``).
    seed : int
        Seed of every random element (textures); same seed, same bytes.
    **params
        Scene-specific physical parameters (see each scene's docstring).

    Returns
    -------
    Scene
        Its exact ground-truth ``transport`` (normalized image value per projector row),
        the ``direct`` light, the ``ambient_albedo`` and the effect ``labels`` of each pixel.

    See Also
    --------
    list_scenes : the names.
    planeray.simulate_stack : capture a sweep of it.

    Examples
    --------
    >>> scene = make_scene("wax", (32, 32), projector_rows=180, seed=0)
    >>> scene.shape, scene.geometry.projector_rows
    ((32, 32), 180)
    >>> sorted(list_scenes())
    ['corner', 'diffuse_plane', 'disco_ball', 'materials', 'mirror_ball', 'skin', 'wax']
    """
    _discover()
    full_name = name
    name, argument = split_scene_name(name)
    if name not in _REGISTRY:
        raise ValueError(f"unknown scene {full_name!r}; choose one of {sorted(list_scenes(parametric=True))}")
    entry = _REGISTRY[name]
    if entry.argument is not None and not argument:
        raise ValueError(f"scene {name!r} needs an argument: {name}:{entry.argument}")
    if entry.argument is None and argument is not None:
        raise ValueError(f"scene {name!r} takes no argument, got {full_name!r}")
    if argument is not None:
        params["argument"] = argument
    H, W = (int(shape[0]), int(shape[1]))
    if H < 8 or W < 8:
        raise ValueError(f"scene size must be at least 8x8, got {H}x{W}")
    scene = entry.build((H, W), projector_rows, int(seed), **params)
    scene.params = {
        "name": full_name,
        "shape": [H, W],
        "projector_rows": scene.geometry.projector_rows,
        "seed": int(seed),
        **scene.params,
    }
    return scene


def scene_offsets(band_rows: int = DEFAULT_BAND_ROWS) -> np.ndarray:
    """Offsets ``-band_rows`` to ``band_rows`` of a scene's dense band.

    Parameters
    ----------
    band_rows : int
        Half-width of the dense band, projector rows.

    Returns
    -------
    ndarray of int

    See Also
    --------
    planeray.Transport : its ``offsets_rows``.

    Examples
    --------
    >>> offsets = scene_offsets(4)
    >>> offsets.tolist()
    [-4, -3, -2, -1, 0, 1, 2, 3, 4]
    """
    return np.arange(-int(band_rows), int(band_rows) + 1)


def representative_pixels(
    scene: Scene, support_rows: int, *, per_label: int = 1, exposure_us: float = 600.0
) -> tuple[np.ndarray, list[str]]:
    """Pick pixels that show each ground-truth effect of a scene most clearly.

    Direct/diffuse pixels: the brightest whose in-sweep indirect light is below 1 %
    of their direct light, at least 6 pixels from any other effect or the border.
    Other effects: the pixels whose noise-free delay profile (the paper's delays at
    ``exposure_us``, rendered from the ground truth) has the most prominent second
    peak beside the one on the epipolar plane -- the clearest two-peak profiles.

    Parameters
    ----------
    scene : Scene
        A scene with ground-truth labels.
    support_rows : int
        Half-width of the sweep's offset support, projector rows.
    per_label : int
        Pixels per effect.
    exposure_us : float
        Exposure of the delay profiles compared, microseconds.

    Returns
    -------
    pixels : ndarray (P, 2) of int
        ``(row, col)`` of each pixel.
    labels : list of str
        The effect of each (a name of :data:`EFFECTS`).

    See Also
    --------
    planeray.measured_delay_profiles : their profiles.

    Examples
    --------
    >>> scene = make_scene("mirror_ball", (32, 32), seed=0)
    >>> pixels, labels = representative_pixels(scene, 114)
    >>> len(pixels) == len(labels) > 0
    True
    """
    from scipy.ndimage import distance_transform_edt

    from ..timing import PAPER_LINES_PER_SECOND, Band, paper_sweep

    T = scene.transport
    u = T.offsets_rows
    footprint = np.abs(u) <= T.geometry.rows_per_camera_row
    near = T.dense[:, :, footprint].sum(axis=2)
    in_sweep = (np.abs(u) <= support_rows) & ~footprint
    indirect = T.dense[:, :, in_sweep].max(axis=2)
    delays = np.unique(paper_sweep().delay_us)
    profile = np.stack([T.render(Band(d, exposure_us, PAPER_LINES_PER_SECOND)) for d in delays])
    centre = np.abs(delays) <= exposure_us / 2
    on_plane = profile[centre].max(axis=0)
    # The clearest second peak on either side: its prominence over the valley
    # towards the epipolar plane and over the fall-off beyond it (a peak cut by
    # the end of the sweep does not count).
    bimodality = np.full(on_plane.shape, -np.inf)
    for side in (delays < 0, delays > 0):
        order = np.argsort(np.abs(delays[side]))
        prof = profile[side][order]  # from the plane outward
        inner = np.minimum.accumulate(prof, axis=0)
        outer = np.minimum.accumulate(prof[::-1], axis=0)[::-1]
        beyond_band = np.abs(delays[side][order]) > exposure_us / 2
        for k in np.flatnonzero(beyond_band)[:-1]:
            peak = prof[k]
            drop = np.minimum(peak - inner[k], peak - outer[k + 1])
            score = np.minimum(drop, on_plane - inner[k]) / (np.maximum(on_plane, peak) + 1e-9)
            bimodality = np.maximum(bimodality, score)
    pixels, names = [], []
    for label in sorted(set(np.unique(scene.labels)) - {0}):
        mask = scene.labels == label
        if label == 1:
            interior = distance_transform_edt(np.pad(mask, 1))[1:-1, 1:-1] > 6
            score = np.where(interior & (indirect < 0.01 * near), near, -np.inf)
        else:
            score = np.where(mask, bimodality, -np.inf)
        order = np.argsort(score, axis=None)[::-1]
        chosen = []
        for flat in order:
            if len(chosen) == per_label or not np.isfinite(score.flat[flat]):
                break
            p = np.array(np.unravel_index(flat, score.shape))
            if all(np.abs(p - q).max() > 6 for q in chosen):  # spread the picks out
                chosen.append(p)
        pixels += chosen
        names += [EFFECTS[int(label)].replace("_", " ")] * len(chosen)
    return np.array(pixels, dtype=np.int64).reshape(-1, 2), names

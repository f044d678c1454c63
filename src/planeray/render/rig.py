"""Where the rectified projector and camera are: planeray's convention for a user's Mitsuba scene.

An Episcan is a *rectified* projector-camera pair (Kubo et al. [1]_, Sec. 3):
the projector's rows and the camera's rows lie on the same epipolar planes, so
projector row ``v`` lights exactly the scene points seen by camera rows near
``t = v H / P``.  planeray builds the pair from the scene's camera:

* **Camera**: the first ``perspective`` sensor of the scene file (its
  ``to_world`` and its field of view).  planeray replaces its film (``H x W``
  pixels, ``box`` filter so a pixel is the plain average of its samples) and
  keeps its **vertical** field of view.  A file without a sensor needs
  ``Rig.look_at``.
* **Projector**: a pinhole with the camera's orientation and vertical field of
  view, ``baseline`` scene units to the camera's right (image right, the
  camera's ``-x`` axis in Mitsuba's ``look_at`` frame), so the baseline is
  parallel to the rows of both: rectified by construction.  It has ``P`` rows
  (``projector_rows``) and ``round(P * projector_aspect)`` columns (16:9 like
  the paper's PicoPro by default, so its light covers the camera's view
  beside the baseline; ``--projector-aspect`` / ``--projector-columns`` set
  yours); its row 0 is at the top, like the camera's.  A projector whose
  vertical field of view differs from the camera's (``--projector-vfov``)
  makes the camera take it: a rectified Episcan image spans the projector's
  rows.
* Camera row ``t`` then sees projector coordinate ``p_t = (t + 1/2) P / H -
  1/2`` on its own epipolar plane (:class:`planeray.timing.RowGeometry`), and
  the offset ``u = v - p_t`` is the row distance between where the light
  entered the scene and where the camera sees it.

A scene file can carry planeray's rig parameters as Mitsuba defaults
(``<default name="planeray_baseline" value="0.2"/>``, ``planeray_projector_aspect``,
``planeray_projector_vfov``); command-line values win, and the store records
where each value came from (``rig_sources``).  Light sources in the file are ignored: the
projector is the only light of the transport (ambient light is the camera
model's business).

References
----------
.. [1] H. Kubo, S. Jayasuriya, T. Iwaguchi, T. Funatomi, Y. Mukaigawa,
   S. G. Narasimhan, "Programmable Non-Epipolar Indirect Light Transport:
   Capture and Analysis", IEEE TVCG 27(4), 2021, Sec. 3.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError

__all__ = ["Rig", "xml_defaults"]

#: The paper's projector (Celluon PicoPro): 1280 x 720.
DEFAULT_PROJECTOR_ASPECT = 16 / 9
#: The narrowest and widest projectors a rig takes (width / height): a tenth to 32 times as wide as tall (a thin
#: render of a wide medium needs lines much longer than the view: tools/honest_cases.py renders at 16).
MIN_PROJECTOR_ASPECT, MAX_PROJECTOR_ASPECT = 0.1, 32.0


def xml_defaults(path) -> dict[str, str]:
    """``<default name="..." value="...">`` entries of a Mitsuba scene file (planeray reads ``planeray_*``)."""
    path = Path(path)
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise InputError(f"not a readable Mitsuba XML scene ({exc})", path) from None
    except OSError as exc:
        raise InputError(f"cannot read ({exc.strerror})", path) from None
    return {d.get("name"): d.get("value") for d in root.iter("default") if d.get("name")}


@dataclass(frozen=True)
class Rig:
    """A rectified projector-camera pair.

    Parameters
    ----------
    camera_to_world : ndarray (4, 4)
        Mitsuba ``to_world`` of the camera (local ``+z`` forward, ``+y`` up,
        ``+x`` to the image's left).
    vfov_deg : float
        Vertical field of view of camera and projector (degrees).
    baseline : float
        Projector centre minus camera centre along the image's right
        direction, in scene units (may be negative: projector on the left).
    projector_rows : int
        ``P``.
    projector_aspect : float
        Projector width / height (columns = ``round(P * aspect)``).
    """

    camera_to_world: np.ndarray
    vfov_deg: float
    baseline: float
    projector_rows: int = 720
    projector_aspect: float = DEFAULT_PROJECTOR_ASPECT

    def __post_init__(self):
        m = np.asarray(self.camera_to_world, dtype=np.float64)
        if m.shape != (4, 4) or not np.all(np.isfinite(m)):
            raise InputError(f"camera_to_world must be a finite 4x4 matrix, got shape {m.shape}")
        object.__setattr__(self, "camera_to_world", m)
        if not 0 < self.vfov_deg < 180:
            raise InputError(f"vertical field of view must be in (0, 180) degrees, got {self.vfov_deg}")
        if not math.isfinite(self.baseline):
            raise InputError(f"baseline must be finite, got {self.baseline}")
        if int(self.projector_rows) < 1:
            raise InputError(f"projector_rows must be at least 1, got {self.projector_rows}")
        if not MIN_PROJECTOR_ASPECT <= self.projector_aspect <= MAX_PROJECTOR_ASPECT:
            raise InputError(
                f"projector_aspect (width / height) must be in {MIN_PROJECTOR_ASPECT:g}-{MAX_PROJECTOR_ASPECT:g}, "
                f"got {self.projector_aspect:g}"
            )
        if round(self.projector_rows * self.projector_aspect) < 1:
            raise InputError(
                f"projector_aspect {self.projector_aspect:g} with {self.projector_rows} rows leaves the projector "
                "no column"
            )

    # ------------------------------------------------------------ builders
    @classmethod
    def look_at(cls, origin, target, up, *, vfov_deg, baseline, projector_rows=720, projector_aspect=None):
        """A rig whose camera looks from ``origin`` at ``target`` (Mitsuba's ``look_at`` frame)."""
        o, t, u = (np.asarray(x, dtype=np.float64) for x in (origin, target, up))
        d = t - o
        if np.linalg.norm(d) == 0:
            raise InputError("camera origin and target coincide")
        d /= np.linalg.norm(d)
        left = np.cross(u, d)
        if np.linalg.norm(left) == 0:
            raise InputError("camera up vector is parallel to the viewing direction")
        left /= np.linalg.norm(left)
        new_up = np.cross(d, left)
        m = np.eye(4)
        m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = left, new_up, d, o
        aspect = DEFAULT_PROJECTOR_ASPECT if projector_aspect is None else float(projector_aspect)
        return cls(m, float(vfov_deg), float(baseline), int(projector_rows), aspect)

    @classmethod
    def from_sensor(cls, sensor, *, baseline, projector_rows=720, projector_aspect=None, path=None):
        """The rig of a loaded Mitsuba ``perspective`` sensor (its pose and vertical field of view).

        ``path`` (the scene file) is named in the error a sensor of another kind gives.
        """
        import mitsuba as mi

        params = mi.traverse(sensor)
        if "x_fov" not in params:
            kind = str(sensor).split("[", 1)[0].strip() or type(sensor).__name__
            raise InputError(
                f"the scene's first sensor is a {kind}, but planeray's camera is a pinhole: give the file a "
                "'perspective' sensor, or place the camera with --look-from X Y Z --look-at X Y Z (camera= in Python)",
                path,
            )
        x_fov = float(np.asarray(params["x_fov"]).ravel()[0])
        to_world = np.asarray(params["to_world"].matrix, dtype=np.float64).reshape(4, 4)
        width, height = (int(s) for s in sensor.film().size())
        vfov = 2 * math.degrees(math.atan(math.tan(math.radians(x_fov) / 2) * height / width))
        aspect = DEFAULT_PROJECTOR_ASPECT if projector_aspect is None else float(projector_aspect)
        return cls(to_world, vfov, float(baseline), int(projector_rows), aspect)

    # ------------------------------------------------------------ geometry
    @property
    def projector_columns(self) -> int:
        return max(1, int(round(self.projector_rows * self.projector_aspect)))

    @property
    def projector_to_world(self) -> np.ndarray:
        """The camera's pose moved by ``baseline`` along the image's right (``-x`` local)."""
        m = self.camera_to_world.copy()
        m[:3, 3] -= self.baseline * m[:3, 0] / np.linalg.norm(m[:3, 0])
        return m

    @property
    def projector_hfov_deg(self) -> float:
        half = math.tan(math.radians(self.vfov_deg) / 2) * self.projector_columns / self.projector_rows
        return 2 * math.degrees(math.atan(half))

    @property
    def camera_origin(self) -> np.ndarray:
        return self.camera_to_world[:3, 3].copy()

    @property
    def camera_forward(self) -> np.ndarray:
        f = self.camera_to_world[:3, 2]
        return f / np.linalg.norm(f)

    # ------------------------------------------------------- Mitsuba dicts
    def sensor_dict(self, shape, *, rgb: bool = False, spp: int = 1) -> dict:
        """``perspective`` sensor: ``shape = (H, W)`` pixels, box filter, the rig's vertical fov."""
        import mitsuba as mi

        H, W = (int(shape[0]), int(shape[1]))
        return {
            "type": "perspective",
            "fov": self.vfov_deg,
            "fov_axis": "y",
            "to_world": mi.ScalarTransform4f(self.camera_to_world.tolist()),
            "film": {
                "type": "hdrfilm",
                "width": W,
                "height": H,
                "rfilter": {"type": "box"},
                "pixel_format": "rgb" if rgb else "luminance",
            },
            "sampler": {"type": "independent", "sample_count": int(spp)},
        }

    def projector_dict(self, pattern=None) -> dict:
        """``projector`` emitter with a ``(P, columns)`` pattern (default all ones), nearest filtering.

        ``pattern`` may be a length-``P`` vector (one value per row).
        """
        import mitsuba as mi

        P, C = self.projector_rows, self.projector_columns
        if pattern is None:
            image = np.ones((P, C, 1), np.float32)
        else:
            rows = np.asarray(pattern, dtype=np.float32).reshape(P, 1, 1)
            image = np.ascontiguousarray(np.broadcast_to(rows, (P, C, 1)))
        return {
            "type": "projector",
            "fov": self.projector_hfov_deg,
            "to_world": mi.ScalarTransform4f(self.projector_to_world.tolist()),
            "irradiance": {"type": "bitmap", "bitmap": mi.Bitmap(image), "filter_type": "nearest", "raw": True},
        }

    def describe(self) -> dict:
        """JSON-serializable record of the rig (stored in the transport's attributes)."""
        return {
            "camera_to_world": self.camera_to_world.tolist(),
            "projector_to_world": self.projector_to_world.tolist(),
            "vfov_deg": self.vfov_deg,
            "baseline": self.baseline,
            "projector_rows": int(self.projector_rows),
            "projector_columns": self.projector_columns,
            "projector_aspect": self.projector_aspect,
        }

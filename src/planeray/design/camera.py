"""The camera a sweep is designed for: its noise model, its scanline velocity and what it can realize.

A design needs the noise of every candidate image (:meth:`planeray.camera.CameraModel.image_variance`),
the band of every (delay, exposure) (Eqs. 2-3, blurred by the synchronization jitter) and the
settings the camera can realize: its exposure range and the steps of its exposure and trigger
delay (the ``ranges`` and ``steps`` capabilities of :mod:`planeray.devices.capabilities`).
:class:`DesignCamera` holds them; it is built from the defaults (the simulated Episcan), from a
device, or from a file (``acquisition.json``, a stack's metadata, or a camera record).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field, fields, replace
from pathlib import Path

from ..camera import CameraModel
from ..errors import InputError
from ..timing import PAPER_LINES_PER_SECOND

__all__ = ["DesignCamera", "camera_from_device", "camera_from_file"]


@dataclass(frozen=True)
class DesignCamera:
    """What a sweep design knows of the camera.

    Parameters
    ----------
    model : CameraModel
        Sensor noise (shot, read, quantization), frames averaged per image, ambient light and the
        synchronization jitter that blurs the band edges.
    lines_per_second : float
        Projector scanline velocity ``v_p`` (Eq. 2).
    exposure_range_us : (float, float)
        Shortest and longest exposure the camera realizes (us).
    exposure_step_us, delay_step_us : float
        The steps of the camera's exposure and trigger delay (us); 0: any value.
    source : str
        Where these came from (``"default"``, ``"device:NAME"``, ``"file:PATH"``).

    See Also
    --------
    camera_from_device, camera_from_file : from a device or a file.

    Examples
    --------
    >>> cam = DesignCamera()  # the default camera of the simulated Episcan
    >>> cam.lines_per_second, cam.model.read_noise_e, cam.source
    (54000.0, 7.0, 'default')
    """

    model: CameraModel = field(default_factory=CameraModel)
    lines_per_second: float = PAPER_LINES_PER_SECOND
    exposure_range_us: tuple[float, float] = (1.0, 1_000_000.0)
    exposure_step_us: float = 0.0
    delay_step_us: float = 0.0
    source: str = "default"

    def __post_init__(self):
        lo, hi = (float(x) for x in self.exposure_range_us)
        if not (math.isfinite(lo) and math.isfinite(hi) and 0 <= lo < hi):
            raise InputError(f"exposure range must be 0 <= min < max, got {self.exposure_range_us!r}")
        object.__setattr__(self, "exposure_range_us", (lo, hi))
        for name in ("exposure_step_us", "delay_step_us"):
            v = float(getattr(self, name) or 0.0)
            if not (math.isfinite(v) and v >= 0):
                raise InputError(f"{name} must be a non-negative number, got {getattr(self, name)!r}")
            object.__setattr__(self, name, v)
        if not (math.isfinite(self.lines_per_second) and self.lines_per_second > 0):
            raise InputError(f"lines_per_second must be positive, got {self.lines_per_second!r}")

    def with_frames(self, frames: int) -> DesignCamera:
        """The same camera averaging ``frames`` frames per image."""
        return replace(self, model=replace(self.model, frames_averaged=int(frames)))

    def to_dict(self) -> dict:
        """JSON record (a sweep file's ``record.camera``)."""
        return {
            "source": self.source,
            "model": self.model.to_dict(),
            "lines_per_second": self.lines_per_second,
            "exposure_range_us": list(self.exposure_range_us),
            "exposure_step_us": self.exposure_step_us,
            "delay_step_us": self.delay_step_us,
        }


_MODEL_FIELDS = {f.name for f in fields(CameraModel)}


def _model_from(record: dict, where) -> CameraModel:
    """A CameraModel from a record's known fields (the others at their defaults)."""
    known = {k: v for k, v in record.items() if k in _MODEL_FIELDS}
    try:
        return CameraModel(**known)
    except (TypeError, ValueError) as exc:
        raise InputError(f"camera record: {exc}", where) from None


def camera_from_device(device, name: str) -> DesignCamera:
    """The camera of an open device: its description's camera model (if it has one), scanline velocity,
    exposure range (``ranges`` capability) and steps (``steps`` capability).

    A camera that does not describe its noise gets the default model, with its averaging where
    known.

    Parameters
    ----------
    device : Device
        An open device.
    name : str
        Its registered name (for the record).

    Returns
    -------
    DesignCamera

    See Also
    --------
    camera_from_file : from a file.

    Examples
    --------
    >>> import planeray as pr
    >>> device = pr.SimulatedEpiscan(pr.make_scene("corner", (8, 8), seed=0), seed=0)
    >>> camera_from_device(device, "sim").lines_per_second
    54000.0
    """
    from ..devices.capabilities import has

    desc = device.describe()
    cam = desc.get("camera") if isinstance(desc.get("camera"), dict) else {}
    model = _model_from({k: v for k, v in cam.items() if k in _MODEL_FIELDS}, f"device {name}")
    sync = desc.get("sync") or {}
    if "jitter_us" in sync and "jitter_us" not in cam:
        model = replace(model, jitter_us=float(sync["jitter_us"]))
    rng = (1.0, 1_000_000.0)
    if has(device, "ranges"):
        rng = tuple(float(x) for x in device.get_exposure_range_us())
    e_step = d_step = 0.0
    if has(device, "steps"):
        e_step = float(device.get_exposure_step_us() or 0.0)
        d_step = float(device.get_trigger_delay_step_us() or 0.0)
    return DesignCamera(
        model=model,
        lines_per_second=float(device.lines_per_second),
        exposure_range_us=rng,
        exposure_step_us=e_step,
        delay_step_us=d_step,
        source=f"device:{name}",
    )


def camera_from_file(path) -> DesignCamera:
    """The camera recorded in a file: a native stack (its metadata), an ``acquisition.json`` (its
    ``camera`` object or top-level sensor fields, ``lines_per_second``, ``sync``), or a sweep file's
    camera record (``record.camera``).

    Parameters
    ----------
    path : str or path
        A native stack, an ``acquisition.json`` or a sweep file.

    Returns
    -------
    DesignCamera

    Raises
    ------
    InputError
        One line naming the file: unreadable, or no camera in it.

    See Also
    --------
    camera_from_device : from an open device.

    Examples
    --------
    >>> import json, pathlib, tempfile
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     path = pathlib.Path(tmp) / "acquisition.json"
    ...     _ = path.write_text(json.dumps({"lines_per_second": 52000.0, "camera": {"read_noise_e": 3.0}}))
    ...     cam = camera_from_file(path)
    >>> cam.lines_per_second, cam.model.read_noise_e
    (52000.0, 3.0)
    """
    path = Path(path)
    if path.is_dir() and (path / "zarr.json").is_file():
        from ..io import read_stack

        st = read_stack(path)
        meta = dict(st.metadata)
        meta.setdefault("lines_per_second", st.lines_per_second)
        return _camera_from_record(meta, path)
    if path.is_dir():
        path = path / "acquisition.json"
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError("no such camera file", path) from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"cannot read a camera from it ({type(exc).__name__}: {exc})", path) from None
    if not isinstance(doc, dict):
        raise InputError("a camera file is a JSON object", path)
    if isinstance(doc.get("record"), dict) and isinstance(doc["record"].get("camera"), dict):  # a sweep file
        doc = doc["record"]["camera"]
    return _camera_from_record(doc, path)


def _camera_from_record(doc: dict, path) -> DesignCamera:
    cam = doc.get("camera") if isinstance(doc.get("camera"), dict) else None
    if cam is None and isinstance(doc.get("model"), dict):
        cam = doc["model"]
    if cam is None:
        cam = {k: v for k, v in doc.items() if k in _MODEL_FIELDS}
        if not cam and "lines_per_second" not in doc:
            raise InputError("no camera in it (expected a 'camera' object or sensor fields such as full_well_e)", path)
    model = _model_from(cam, path)
    sync = doc.get("sync") or {}
    if isinstance(sync, dict) and "jitter_us" in sync and "jitter_us" not in cam:
        model = replace(model, jitter_us=float(sync["jitter_us"]))
    lps = doc.get("lines_per_second", PAPER_LINES_PER_SECOND)
    extra = {}
    for key in ("exposure_range_us", "exposure_step_us", "delay_step_us"):
        if key in doc:
            extra[key] = tuple(doc[key]) if key == "exposure_range_us" else doc[key]
    try:
        return DesignCamera(model=model, lines_per_second=float(lps), source=f"file:{path}", **extra)
    except (TypeError, ValueError) as exc:
        raise InputError(f"camera record: {exc}", path) from None

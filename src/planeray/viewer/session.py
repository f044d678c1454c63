"""What ``planeray view PATH`` shows: a scene, a transport store or a stack, rendered on demand (no web here).

:func:`open_source` turns the ``PATH`` of the command line into a :class:`ViewSource`:

* a **scene name** (``wax``, ``disco_ball``, ...): a virtual Episcan.  The scene's
  ground-truth transport is rendered live through the simulated device's camera:
  images are in the camera's normalized units (``signal_scale`` times Eq. 4), with
  the camera noise model and ambient light as toggles of the band image (noise is
  seeded by the settings, as the first grab of :class:`~planeray.devices.simulated.SimulatedEpiscan`:
  the same settings give the same bytes as ``planeray simulate``);
* a **transport store** (ground truth or demultiplexed): every mode of
  :mod:`planeray.synthesis`, in the store's units;
* a **stack** (native store or import folder): its captured images, on the
  captured delay-exposure grid.

Every image comes from the O(pixels) band renderer :meth:`planeray.transport.Transport.render`
(Eq. 4) or the synthesis functions built on it; :meth:`ViewSource.pixel` gives the
data of the plots of one pixel (its delay profiles for a stack, its ``T(u)`` for a
transport, with the ground truth overlaid when known).
"""

from __future__ import annotations

import math
import threading
from contextlib import contextmanager
from dataclasses import asdict, dataclass, fields, replace
from pathlib import Path

import numpy as np

from .. import synthesis as syn
from ..camera import CameraModel, row_shifts_rows
from ..errors import InputError
from ..profiles import area_normalize
from ..timing import PAPER_LINES_PER_SECOND, PAPER_PROJECTOR_ROWS, Band, band_bin_weights
from ..transport import Transport

__all__ = [
    "MODES",
    "PATTERNS",
    "ViewSettings",
    "ViewSource",
    "TransportSource",
    "StackSource",
    "open_source",
    "pattern_rows",
    "FrameBuffers",
]

#: Display modes: name -> label.  A stack shows only ``band`` (its captured images).
MODES = {
    "band": "band image (delay, exposure)",
    "epipolar": "epipolar (Eq. 5)",
    "non_epipolar": "non-epipolar (Eq. 6)",
    "sharpened": "sharpened epipolar",
    "short_range": "short-range indirect",
    "long_range": "long-range indirect",
    "relight_row": "relight: one projector row",
    "relight_pattern": "relight: pattern",
}

#: Built-in relighting patterns over projector rows ``v`` (``period_rows``, ``phase_deg`` where they apply).
PATTERNS = {
    "sine": "0.5 + 0.5 cos(2 pi v / period + phase)",
    "stripes": "1 where cos(2 pi v / period + phase) >= 0, else 0",
    "ramp": "v / (P - 1), dark at the top",
    "full": "every row lit (direct + global)",
}

_BOOL_FIELDS = {"noise", "ambient"}
_INT_FIELDS = {"row"}
_STR_FIELDS = {"mode", "pattern"}


@dataclass(frozen=True)
class ViewSettings:
    """What one panel shows; every field has a default, so a panel may send only what changed.

    Parameters
    ----------
    mode : str
        One of :data:`MODES`.
    delay_us, exposure_us : float
        Band of ``band`` mode (any values for scenes and transports; a stack shows
        its captured image nearest to them).
    width_rows : float
        Width of the ``sharpened`` epipolar band, projector rows.
    max_rows : float
        Offset threshold between short- and long-range indirect light, projector rows.
    row : int or None
        Projector row of ``relight_row`` (None: the middle row).
    pattern : str
        ``relight_pattern``: one of :data:`PATTERNS` or a pattern file named on the command line.
    period_rows, phase_deg : float
        Period and phase of the ``sine`` and ``stripes`` patterns.
    noise, ambient : bool
        Scenes only: camera noise (shot, read, quantization, row jitter) and ambient
        light in the band image.

    See Also
    --------
    ViewSource.render : renders them.

    Examples
    --------
    >>> settings = ViewSettings(mode="band", delay_us=375.0, exposure_us=600.0)
    >>> settings.mode, settings.width_rows
    ('band', 1.0)
    """

    mode: str = "band"
    delay_us: float = 0.0
    exposure_us: float = 600.0
    width_rows: float = 1.0
    max_rows: float = 20.0
    row: int | None = None
    pattern: str = "sine"
    period_rows: float = 48.0
    phase_deg: float = 0.0
    noise: bool = False
    ambient: bool = False

    @classmethod
    def from_dict(cls, data) -> ViewSettings:
        """Settings from JSON; unknown keys, wrong types and non-finite numbers are refused by name.

        Examples
        --------
        >>> ViewSettings.from_dict({"mode": "band", "delay_us": 375}).delay_us
        375.0
        >>> ViewSettings.from_dict({"delay": 1})
        Traceback (most recent call last):
        ...
        planeray.errors.InputError: unknown setting 'delay' (known: mode, delay_us, exposure_us, width_rows, ...)
        """
        if data is None:
            return cls()
        if not isinstance(data, dict):
            raise InputError(f"settings must be a JSON object, got {type(data).__name__}")
        names = [f.name for f in fields(cls)]
        values = {}
        for key, value in data.items():
            if key not in names:
                raise InputError(f"unknown setting {key!r} (known: {', '.join(names[:4])}, ...)")
            if key in _STR_FIELDS:
                if not isinstance(value, str):
                    raise InputError(f"setting {key!r} must be a string, got {value!r}")
            elif key in _BOOL_FIELDS:
                if not isinstance(value, bool):
                    raise InputError(f"setting {key!r} must be true or false, got {value!r}")
            elif key in _INT_FIELDS:
                if value is not None and (isinstance(value, bool) or not _is_integral(value)):
                    raise InputError(f"setting {key!r} must be an integer, got {value!r}")
                value = None if value is None else int(value)
            else:
                if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
                    raise InputError(f"setting {key!r} must be a finite number, got {value!r}")
                value = float(value)
            values[key] = value
        return cls(**values)

    def to_dict(self) -> dict:
        return asdict(self)


def _is_integral(value) -> bool:
    return isinstance(value, int) or (isinstance(value, float) and math.isfinite(value) and value.is_integer())


def pattern_rows(name: str, projector_rows: int, *, period_rows: float = 48.0, phase_deg: float = 0.0) -> np.ndarray:
    """A built-in relighting pattern (:data:`PATTERNS`) over ``projector_rows`` rows.

    Examples
    --------
    >>> pattern_rows("stripes", 8, period_rows=4).tolist()
    [1.0, 1.0, 0.0, 1.0, 1.0, 1.0, 0.0, 1.0]
    """
    v = np.arange(int(projector_rows), dtype=np.float64)
    if name in ("sine", "stripes"):
        if not period_rows >= 2:
            raise InputError(f"pattern period must be at least 2 projector rows, got {period_rows!r}")
        c = np.cos(2 * np.pi * v / period_rows + np.deg2rad(phase_deg))
        return 0.5 + 0.5 * c if name == "sine" else (c >= -1e-12).astype(np.float64)
    if name == "ramp":
        return v / max(projector_rows - 1, 1)
    if name == "full":
        return np.ones_like(v)
    raise InputError(f"unknown pattern {name!r}; choose one of {sorted(PATTERNS)}")


class ViewSource:
    """Something the viewer shows.  Subclasses: :class:`TransportSource`, :class:`StackSource`.

    Attributes
    ----------
    kind : str
        ``"scene"``, ``"transport"`` or ``"stack"``.
    name : str
        What the command line named (a scene name or the path).
    shape : (int, int)
        Image ``(H, W)``.

    See Also
    --------
    open_source : the source of a path or scene name.

    Examples
    --------
    >>> import planeray as pr
    >>> source = TransportSource(pr.make_scene("corner", (8, 8), seed=0).transport, name="corner")
    >>> isinstance(source, ViewSource), source.shape
    (True, (8, 8))
    """

    kind = "source"
    modes: tuple[str, ...] = ("band",)
    #: The labels of the modes a source of this kind may show.
    mode_labels: dict[str, str] = MODES

    def __init__(self, name: str, shape):
        self.name = str(name)
        self.shape = (int(shape[0]), int(shape[1]))
        self._lock = threading.Lock()  # renders share caches and frame buffers; one at a time
        self._buffers = FrameBuffers(self.shape)

    def describe(self) -> dict:
        """What the page needs to build its controls (JSON)."""
        raise NotImplementedError

    def check(self, settings: ViewSettings) -> ViewSettings:
        """Refuse settings this source cannot show (one line naming the setting)."""
        if settings.mode not in self.mode_labels:
            raise InputError(f"unknown mode {settings.mode!r}; choose one of {sorted(self.mode_labels)}")
        if settings.mode not in self.modes:
            raise InputError(f"a {self.kind} shows only {', '.join(self.modes)}, not {settings.mode!r}")
        if not settings.exposure_us > 0:
            raise InputError(f"exposure_us must be positive, got {settings.exposure_us!r}")
        return settings

    def render(self, settings: ViewSettings) -> tuple[np.ndarray, dict]:
        """The image of ``settings`` (float32, ``shape``) and what it shows (JSON)."""
        settings = self.check(settings)
        with self._lock:
            return self._render(settings, None)

    @contextmanager
    def frame(self, settings: ViewSettings):
        """``with source.frame(settings) as (image, info):`` the image of ``settings`` in the source's
        reused frame buffers (the server's path: no frame-sized allocation once warm).

        The image is valid, and the source locked, inside the ``with`` block only: the next frame
        overwrites it.  Read it there (encode, copy), never keep it.
        """
        settings = self.check(settings)
        with self._lock:
            yield self._render(settings, self._buffers)

    def warm(self) -> None:
        """Render the page's first frame once (buffers allocated, compiled kernels loaded): call it
        in the thread that will render, before the first request, so the first drag is as fast as the
        hundredth."""
        with self.frame(ViewSettings.from_dict(self.describe()["defaults"])) as (image, _):
            np.count_nonzero(image)

    def pixel(self, row: int, col: int, settings: ViewSettings) -> dict:
        """The plot data of one pixel (JSON)."""
        if isinstance(row, bool) or isinstance(col, bool) or not (_is_integral(row) and _is_integral(col)):
            raise InputError(f"pixel must be two integers (row, col), got {row!r}, {col!r}")
        row, col = int(row), int(col)
        H, W = self.shape
        if not (0 <= row < H and 0 <= col < W):
            raise InputError(f"pixel ({row}, {col}) outside the {H}x{W} image")
        settings = self.check(settings)
        with self._lock:
            return self._pixel(row, col, settings)

    def _render(self, settings, buffers):  # pragma: no cover - abstract
        """``(image, info)``; ``buffers`` (a :class:`FrameBuffers`, or None: new arrays) may hold the image."""
        raise NotImplementedError

    def _pixel(self, row, col, settings):  # pragma: no cover - abstract
        raise NotImplementedError


class FrameBuffers:
    """Frame-sized arrays a source renders into, allocated on first use and reused for every frame.

    A fresh process would otherwise allocate (and the C allocator map, fault in and return to the
    system) several megabytes of temporaries per 512x512 frame; reusing them makes a fresh server's
    first frames as fast as its hundredth.

    Parameters
    ----------
    shape : (int, int)
        Image ``(H, W)``.
    """

    def __init__(self, shape):
        self.shape = (int(shape[0]), int(shape[1]))
        self._arrays: dict[str, np.ndarray] = {}

    def get(self, name: str, dtype=np.float32) -> np.ndarray:
        """The buffer ``name`` (``shape``, ``dtype``), the same array every call; its contents are stale."""
        a = self._arrays.get(name)
        if a is None:
            a = self._arrays[name] = np.empty(self.shape, dtype)
        return a

    def __len__(self) -> int:
        return len(self._arrays)


def _out(buffers: FrameBuffers | None, name: str, dtype=np.float32) -> np.ndarray | None:
    return None if buffers is None else buffers.get(name, dtype)


def _round_up(x: float, step: float) -> float:
    return float(math.ceil(x / step - 1e-9) * step)


class TransportSource(ViewSource):
    """A transport (ground truth of a scene, or a transport store), rendered for any settings.

    Parameters
    ----------
    transport : Transport
    name : str
    lines_per_second : float
        Projector scanline velocity (delay <-> rows, Eq. 2).
    kind : {"transport", "scene"}
    camera : CameraModel, optional
        Scenes: the virtual Episcan's camera; images are then in its normalized
        units (``signal_scale`` times the transport's) and the band image has the
        noise and ambient toggles.
    ambient_albedo : ndarray, optional
        Scenes: reflectance under ambient light.
    seed : int
        Scenes: noise seed.
    truth : Transport, optional
        Ground truth to overlay in the ``T(u)`` plot (a scene is its own ground truth).
    truth_scale : float, optional
        Multiplies the ground truth in the plot (a transport demultiplexed from a
        simulated stack is ``signal_scale`` times the scene's); None: the plot
        normalizes both curves by their area.
    patterns : dict, optional
        Extra relighting patterns by name (rows of the projector).
    attrs : dict, optional
        The store's attributes (``epipolar_resolution_rows`` is shown).

    See Also
    --------
    StackSource : a stack.

    Examples
    --------
    >>> import planeray as pr
    >>> source = TransportSource(pr.make_scene("corner", (8, 8), seed=0).transport, name="corner")
    >>> image, info = source.render(ViewSettings(mode="band", delay_us=375.0, exposure_us=600.0))
    >>> image.shape
    (8, 8)
    """

    modes = tuple(MODES)

    def __init__(
        self,
        transport: Transport,
        *,
        name: str,
        lines_per_second: float = PAPER_LINES_PER_SECOND,
        kind: str = "transport",
        camera: CameraModel | None = None,
        ambient_albedo=None,
        seed: int = 0,
        truth: Transport | None = None,
        truth_scale: float | None = 1.0,
        patterns: dict | None = None,
        attrs: dict | None = None,
    ):
        super().__init__(name, transport.shape)
        self.kind = kind
        self.transport = transport
        self.lines_per_second = float(lines_per_second)
        self.camera = camera
        self.ambient_albedo = None if ambient_albedo is None else np.asarray(ambient_albedo, np.float32)
        self.seed = int(seed)
        self.truth = truth if truth is not None else (transport if kind == "scene" else None)
        if truth is not None and truth.shape != transport.shape:
            raise InputError(
                f"ground truth is {truth.shape[0]}x{truth.shape[1]}, the transport "
                f"{transport.shape[0]}x{transport.shape[1]}"
            )
        self.truth_scale = None if truth_scale is None else float(truth_scale)
        self.scale = camera.signal_scale if camera is not None else 1.0
        self.attrs = dict(attrs or {})
        P = transport.geometry.projector_rows
        self.patterns = {}
        for key, values in (patterns or {}).items():
            values = np.asarray(values, np.float64).ravel()
            if values.size != P:
                raise InputError(f"pattern {key!r} has {values.size} rows, the projector has {P}")
            self.patterns[str(key)] = values
        # Warm the caches once (prefix sums, Eqs. 5-6): renders then only read them.
        transport.render(Band(0.0, 600.0, self.lines_per_second))
        self._epipolar = transport.epipolar_image()
        self._full = transport.full_image()
        u = transport.offsets_rows
        self._epi_bins = band_bin_weights(u, 0.0, transport.geometry.rows_per_camera_row) > 0

    # ------------------------------------------------------------ description
    @property
    def noise_toggles(self) -> bool:
        return self.camera is not None

    def delay_range_us(self) -> tuple[float, float]:
        reach_rows = float(np.abs(self.transport.offsets_rows).max(initial=1))
        top = _round_up(reach_rows * 1e6 / self.lines_per_second, 100.0)
        return -top, top

    def describe(self) -> dict:
        T = self.transport
        lo, hi = self.delay_range_us()
        res = self.attrs.get("epipolar_resolution_rows")
        return {
            "kind": self.kind,
            "name": self.name,
            "shape": list(self.shape),
            "projector_rows": int(T.geometry.projector_rows),
            "lines_per_second": self.lines_per_second,
            "modes": [{"name": m, "label": MODES[m]} for m in self.modes],
            "delay_us": {"min": lo, "max": hi, "step": 1.0, "grid": None},
            "exposure_us": {"min": 10.0, "max": 3000.0, "step": 1.0, "grid": None},
            "width_rows": {"min": 0.25, "max": 64.0, "step": 0.25},
            "max_rows": {"min": 1.0, "max": float(np.abs(T.offsets_rows).max(initial=1)), "step": 1.0},
            "row": {"min": 0, "max": int(T.geometry.projector_rows) - 1, "step": 1},
            "patterns": sorted(PATTERNS) + sorted(self.patterns),
            "toggles": ["noise", "ambient"] if self.noise_toggles else [],
            "has_truth": self.truth is not None,
            "truth_scale": self.truth_scale,
            "units": "camera (normalized: 1 = full well)" if self.camera is not None else "transport",
            "epipolar_resolution_rows": res,
            "defaults": ViewSettings(row=int(T.geometry.projector_rows) // 2).to_dict(),
        }

    def check(self, settings: ViewSettings) -> ViewSettings:
        settings = super().check(settings)
        P = self.transport.geometry.projector_rows
        if settings.mode == "sharpened" and not settings.width_rows > 0:
            raise InputError(f"width_rows must be positive, got {settings.width_rows!r}")
        if settings.mode in ("short_range", "long_range") and not settings.max_rows > 0:
            raise InputError(f"max_rows must be positive, got {settings.max_rows!r}")
        if settings.mode == "relight_row":
            row = P // 2 if settings.row is None else settings.row
            if not 0 <= row < P:
                raise InputError(f"projector row {row} outside 0..{P - 1}")
            settings = replace(settings, row=row)
        if settings.mode == "relight_pattern":
            if settings.pattern not in PATTERNS and settings.pattern not in self.patterns:
                raise InputError(
                    f"unknown pattern {settings.pattern!r}; choose one of {sorted(PATTERNS) + sorted(self.patterns)}"
                )
            if settings.pattern in ("sine", "stripes") and not settings.period_rows >= 2:
                raise InputError(f"period_rows must be at least 2, got {settings.period_rows!r}")
        if (settings.noise or settings.ambient) and not self.noise_toggles:
            raise InputError("noise and ambient light are toggles of a scene (a virtual Episcan) only")
        return settings

    # ------------------------------------------------------------- rendering
    def band(self, delay_us: float, exposure_us: float, rng=None) -> Band:
        """The illumination of a band image: the camera's jitter for a scene, none for a store."""
        if self.camera is None:
            return Band(float(delay_us), float(exposure_us), self.lines_per_second)
        cam = self.camera
        shifts = None
        if rng is not None:
            shifts = row_shifts_rows(rng, cam.frames_averaged, self.shape[0], cam.row_jitter_us, self.lines_per_second)
        return Band(float(delay_us), float(exposure_us), self.lines_per_second, cam.jitter_us, 0.0, shifts)

    def _band_image(self, s: ViewSettings, buffers: FrameBuffers | None) -> tuple[np.ndarray, dict]:
        T = self.transport
        info = {"label": f"band  t_d {s.delay_us:g} us  t_e {s.exposure_us:g} us"}
        if self.camera is None:
            return T.render(self.band(s.delay_us, s.exposure_us), out=_out(buffers, "image")), info
        cam = self.camera
        albedo = self.ambient_albedo if s.ambient else None
        if not s.noise:
            signal = T.render(self.band(s.delay_us, s.exposure_us), out=_out(buffers, "signal"))
            image, n_saturated = cam.expected_image(
                signal,
                s.exposure_us,
                ambient_albedo=albedo,
                out=_out(buffers, "image"),
                work=_out(buffers, "work", np.float64),
            )
        else:
            # The first grab of the simulated device at these settings (same seed, same bytes).
            key = (int(round(s.delay_us * 1000)), int(round(s.exposure_us * 1000)))
            rng = np.random.default_rng([self.seed, key[0] + 2**40, key[1], 0])
            signal = T.render(self.band(s.delay_us, s.exposure_us, rng), out=_out(buffers, "signal"))
            image, saturated = cam.expose(signal, s.exposure_us, rng, ambient_albedo=albedo, noise=True)
            n_saturated = int(saturated.sum())
        info["saturated"] = n_saturated
        return image, info

    def _short_range(self, max_rows: float, buffers: FrameBuffers | None) -> np.ndarray:
        """Short-range indirect light (as :func:`planeray.synthesis.short_long_range`) with two
        O(pixels) plateau renders (the offsets below and above the epipolar bins)."""
        T = self.transport
        u = T.offsets_rows
        short = (np.abs(u) <= max_rows) & ~self._epi_bins
        image = _out(buffers, "short")
        image = np.zeros(self.shape, np.float32) if image is None else image
        image[...] = 0.0
        for side in (u < 0, u > 0):
            w = (short & side).astype(np.float64)
            if w.any():
                image += T.render_weights(np.broadcast_to(w, (self.shape[0], u.size)), out=_out(buffers, "part"))
        return image

    def _render(self, s: ViewSettings, buffers: FrameBuffers | None) -> tuple[np.ndarray, dict]:
        T = self.transport
        info: dict = {}
        if s.mode == "band":
            return self._band_image(s, buffers)
        out = _out(buffers, "image")
        if s.mode == "epipolar":
            image, info["label"] = self._epipolar, "epipolar (Eq. 5)"
        elif s.mode == "non_epipolar":
            image, info["label"] = np.subtract(self._full, self._epipolar, out=out), "non-epipolar (Eq. 6)"
        elif s.mode == "sharpened":
            image = syn.sharpened_epipolar(T, width_rows=s.width_rows)
            info["label"] = f"sharpened epipolar  {s.width_rows:g} rows"
        elif s.mode in ("short_range", "long_range"):
            short = self._short_range(s.max_rows, buffers)
            if s.mode == "short_range":
                image, info["label"] = short, f"short-range indirect  |u| <= {s.max_rows:g} rows"
            else:
                image = np.subtract(self._full, self._epipolar, out=out)
                image -= short
                info["label"] = f"long-range indirect  |u| > {s.max_rows:g} rows"
        elif s.mode == "relight_row":
            image = syn.relight(T, syn.single_line_pattern(T.geometry.projector_rows, s.row))
            info["label"] = f"relit by projector row {s.row}"
        else:
            image = syn.relight(T, self.pattern(s))
            info["label"] = f"relit by pattern {s.pattern}"
        if self.scale != 1.0:
            image = np.multiply(image, np.float32(self.scale), out=out)
        return np.asarray(image, np.float32), info

    def pattern(self, s: ViewSettings) -> np.ndarray:
        """The projector-row pattern of ``relight_pattern`` settings."""
        if s.pattern in self.patterns:
            return self.patterns[s.pattern]
        P = self.transport.geometry.projector_rows
        return pattern_rows(s.pattern, P, period_rows=s.period_rows, phase_deg=s.phase_deg)

    # ----------------------------------------------------------------- pixel
    def window_rows(self, s: ViewSettings):
        """The offsets ``[lo, hi]`` (projector rows) a mode lets through, for the plot; None if not a window."""
        v = self.lines_per_second * 1e-6
        if s.mode == "band":
            return [s.delay_us * v - s.exposure_us * v / 2, s.delay_us * v + s.exposure_us * v / 2]
        if s.mode == "sharpened":
            return [-s.width_rows / 2, s.width_rows / 2]
        if s.mode == "short_range":
            return [-s.max_rows, s.max_rows]
        if s.mode == "epipolar":
            r = self.transport.geometry.rows_per_camera_row / 2
            return [-r, r]
        return None

    @staticmethod
    def _pixel_curve(T: Transport, row: int, col: int) -> dict:
        sp = T.sparse
        hit = (sp.row == row) & (sp.col == col)
        return {
            "offsets_rows": T.offsets_rows.tolist(),
            "T": np.asarray(T.dense[row, col], np.float64).tolist(),
            "sparse_offsets_rows": sp.offset[hit].tolist(),
            "sparse_T": np.asarray(sp.value[hit], np.float64).tolist(),
        }

    def _pixel(self, row, col, s) -> dict:
        image, _ = self._render(s, self._buffers)
        data = {
            "kind": self.kind,
            "row": row,
            "col": col,
            "value": float(image[row, col]),
            "rows_per_us": self.lines_per_second * 1e-6,
            "window_rows": self.window_rows(s),
            "estimate": None if self.kind == "scene" else self._pixel_curve(self.transport, row, col),
            "truth": None if self.truth is None else self._pixel_curve(self.truth, row, col),
            "truth_scale": 1.0 if self.kind == "scene" else self.truth_scale,
            "epipolar_resolution_rows": self.attrs.get("epipolar_resolution_rows"),
        }
        return data


class StackSource(ViewSource):
    """A captured (or simulated) stack: its images on the captured delay-exposure grid.

    Parameters
    ----------
    stack : Stack
        Read into memory (the page shows any image at once).
    name : str
    truth : Transport, optional
        Ground truth: its continuous delay profiles (noise-free bands of every delay
        at each captured exposure) are overlaid on the measured ones.

    See Also
    --------
    TransportSource : a transport.

    Examples
    --------
    >>> import planeray as pr
    >>> stack = pr.simulate_stack(pr.make_scene("corner", (8, 8), seed=0), pr.quick_sweep(), seed=0)
    >>> image, info = StackSource(stack, name="corner").render(ViewSettings(delay_us=375.0, exposure_us=600.0))
    >>> image.shape
    (8, 8)
    """

    kind = "stack"
    modes = ("band",)

    def __init__(self, stack, *, name: str, truth: Transport | None = None):
        super().__init__(name, stack.shape)
        self.stack = stack
        self.images = np.asarray(stack.images, dtype=np.float32)
        self.saturated = None if stack.saturated is None else np.asarray(stack.saturated, dtype=bool)
        self.delays = stack.delays()
        self.exposures = stack.exposures()
        if truth is not None and truth.shape != stack.shape:
            raise InputError(
                f"ground truth is {truth.shape[0]}x{truth.shape[1]}, the stack {stack.shape[0]}x{stack.shape[1]}"
            )
        self.truth = truth
        self._di = np.searchsorted(self.delays, stack.delay_us)
        self._ei = np.searchsorted(self.exposures, stack.exposure_us)
        self._index = np.full((self.exposures.size, self.delays.size), -1, np.int64)
        self._index[self._ei, self._di] = np.arange(len(stack))

    def describe(self) -> dict:
        st = self.stack
        return {
            "kind": "stack",
            "name": self.name,
            "shape": list(self.shape),
            "projector_rows": int(st.projector_rows),
            "lines_per_second": st.lines_per_second,
            "modes": [{"name": "band", "label": "captured image (delay, exposure)"}],
            "delay_us": {"min": float(self.delays[0]), "max": float(self.delays[-1]), "grid": self.delays.tolist()},
            "exposure_us": {
                "min": float(self.exposures[0]),
                "max": float(self.exposures[-1]),
                "grid": self.exposures.tolist(),
            },
            "n_images": len(st),
            "patterns": [],
            "toggles": [],
            "has_truth": self.truth is not None,
            "units": "camera (normalized: 0 = black level, 1 = top code)",
            "defaults": ViewSettings(
                delay_us=float(self.delays[np.argmin(np.abs(self.delays))]), exposure_us=float(self.exposures[0])
            ).to_dict(),
        }

    def nearest_index(self, delay_us: float, exposure_us: float) -> int:
        """The captured image nearest to a (delay, exposure): the nearest exposure, then the nearest delay
        captured at it."""
        e = int(np.argmin(np.abs(self.exposures - exposure_us)))
        have = np.flatnonzero(self._index[e] >= 0)
        d = have[np.argmin(np.abs(self.delays[have] - delay_us))]
        return int(self._index[e, d])

    def _render(self, s: ViewSettings, buffers: FrameBuffers | None) -> tuple[np.ndarray, dict]:
        n = self.nearest_index(s.delay_us, s.exposure_us)
        d, e = float(self.stack.delay_us[n]), float(self.stack.exposure_us[n])
        info = {
            "label": f"image {n}  t_d {d:g} us  t_e {e:g} us"
            + ("  (boundary image)" if self.stack.excluded[n] else ""),
            "index": n,
            "delay_us": d,
            "exposure_us": e,
            "excluded": bool(self.stack.excluded[n]),
        }
        if self.saturated is not None:
            info["saturated"] = int(self.saturated[n].sum())
        return self.images[n], info

    def _pixel(self, row, col, s) -> dict:
        n = self.nearest_index(s.delay_us, s.exposure_us)
        raw = np.full((self.exposures.size, self.delays.size), np.nan)
        raw[self._ei, self._di] = self.images[:, row, col]
        sat = np.zeros(raw.shape, bool)
        if self.saturated is not None:
            sat[self._ei, self._di] = self.saturated[:, row, col]
        data = {
            "kind": "stack",
            "row": row,
            "col": col,
            "value": float(self.images[n, row, col]),
            "delays_us": self.delays.tolist(),
            "exposures_us": self.exposures.tolist(),
            "raw": _nan_to_none(raw),
            "normalized": _nan_to_none(area_normalize(raw, self.delays)),
            "saturated": sat.tolist(),
            "current": {"delay_us": float(self.stack.delay_us[n]), "exposure_us": float(self.stack.exposure_us[n])},
            "truth": None,
        }
        if self.truth is not None:
            fine = _fine_delays(self.delays, self.stack.lines_per_second)
            curves = np.stack(
                [
                    pixel_band_profile(
                        self.truth,
                        row,
                        col,
                        fine,
                        e,
                        lines_per_second=self.stack.lines_per_second,
                        jitter_us=self.stack.jitter_us,
                    )
                    for e in self.exposures
                ]
            )
            data["truth"] = {
                "delays_us": fine.tolist(),
                "raw": curves.tolist(),
                "normalized": area_normalize(curves, fine).astype(np.float64).tolist(),
            }
        return data


def _nan_to_none(a) -> list:
    a = np.asarray(a, np.float64)
    return [[None if not np.isfinite(x) else float(x) for x in r] for r in a]


def _fine_delays(delays, lines_per_second) -> np.ndarray:
    step = 1e6 / float(lines_per_second)
    lo, hi = float(delays.min()), float(delays.max())
    n = max(int(np.ceil((hi - lo) / step)), 1)
    return np.linspace(lo, hi, n + 1)


def pixel_band_profile(
    transport: Transport, row: int, col: int, delays_us, exposure_us: float, *, lines_per_second, jitter_us=0.0
) -> np.ndarray:
    """One pixel's noise-free band images over ``delays_us`` (Eq. 4 at one pixel, sparse entries included).

    The same numbers as ``transport.render(Band(d, exposure_us, lines_per_second, jitter_us))[row, col]``
    for each delay, without rendering whole images.
    """
    T = transport
    sp = T.sparse
    hit = (sp.row == row) & (sp.col == col)
    out = np.empty(len(delays_us), np.float64)
    dense = T.dense[row, col].astype(np.float64)
    for i, d in enumerate(delays_us):
        band = Band(float(d), float(exposure_us), float(lines_per_second), float(jitter_us))
        w = band.weights(T.geometry, np.array([row]), T.offsets_rows[None, :])[0]
        value = float(w @ dense)
        if hit.any():
            ws = band.weights(T.geometry, sp.row[hit], sp.offset[hit])
            value += float(np.sum(ws * sp.value[hit]))
        out[i] = value
    return out


# ============================================================================ opening a PATH
def open_source(
    path,
    *,
    size: int | tuple[int, int] = 128,
    projector_rows: int | None = PAPER_PROJECTOR_ROWS,
    seed: int = 0,
    lines_per_second: float = PAPER_LINES_PER_SECOND,
    truth=None,
    truth_scale: float | None = None,
    patterns=(),
    camera: CameraModel | None = None,
) -> ViewSource:
    """Open what ``planeray view PATH`` names: an existing stack or transport store, or a scene name.

    Parameters
    ----------
    path : str or os.PathLike
        A native stack, an import folder or a transport store; else the name of a
        built-in scene (:func:`planeray.scenes.list_scenes`).
    size : int or (int, int)
        Scenes: image size ``(H, W)`` in camera pixels (one integer: a square).
    projector_rows : int, optional
        Scenes: projector rows spanned by the image (the paper's 720).
    seed : int
        Scenes: texture and noise seed.
    lines_per_second : float
        Scenes: projector scanline velocity; transport stores without one.
    truth : path, optional
        A ground-truth transport store to overlay in the pixel plots.
    truth_scale : float, optional
        Multiplies the ground truth in the ``T(u)`` plot (None: both curves normalized by their area;
        a stack's own ``signal_scale`` is not needed: its profiles are always compared by area).
    patterns : sequence of paths
        Relighting pattern files (:func:`planeray.synthesis.load_pattern`), named by their stem.
    camera : CameraModel, optional
        Scenes: the virtual camera (default :class:`~planeray.camera.CameraModel`).

    Returns
    -------
    ViewSource

    See Also
    --------
    TransportSource, StackSource

    Examples
    --------
    >>> src = open_source("diffuse_plane", size=16, projector_rows=90)
    >>> src.kind, src.shape
    ('scene', (16, 16))
    >>> image, info = src.render(ViewSettings(delay_us=0.0, exposure_us=600.0))
    >>> image.dtype, info["label"]
    (dtype('float32'), 'band  t_d 0 us  t_e 600 us')
    """
    from ..io import read_stack, read_transport, store_format
    from ..scenes import is_scene_name, list_scenes, make_scene

    text = str(path)
    p = Path(path)
    scenes = list_scenes(parametric=True)
    if not p.exists() and is_scene_name(text) and truth is not None:
        raise InputError("a scene is its own ground truth; --truth is for stacks and transport stores")
    truth_T = None
    if truth is not None:
        truth_T, _ = read_transport(truth)
    if p.exists():
        fmt = store_format(p)
        if fmt is None:
            raise InputError("not a planeray stack, import folder or transport store", p)
        loaded = {}
        for name in patterns:
            if fmt == "stack":
                raise InputError("relighting patterns need a transport or a scene, not a stack", name)
            loaded[Path(name).stem] = name
        if fmt == "stack":
            return StackSource(read_stack(p, lazy=False), name=text, truth=truth_T)
        T, attrs = read_transport(p)
        lps = attrs.get("lines_per_second") or lines_per_second
        pats = {k: syn.load_pattern(v, T.geometry.projector_rows) for k, v in loaded.items()}
        if attrs.get("method") == "ground_truth" and truth_T is None:
            truth_T, truth_scale = T, 1.0  # a ground-truth store is its own truth
        return TransportSource(
            T, name=text, lines_per_second=lps, truth=truth_T, truth_scale=truth_scale, patterns=pats, attrs=attrs
        )
    if not is_scene_name(text):
        raise InputError(f"no such file or folder, and not a scene name (scenes: {', '.join(scenes)})", text)
    h, w = (size, size) if np.ndim(size) == 0 else size
    scene = make_scene(text, (int(h), int(w)), projector_rows=projector_rows, seed=int(seed))
    pats = {Path(v).stem: syn.load_pattern(v, scene.geometry.projector_rows) for v in patterns}
    return TransportSource(
        scene.transport,
        name=text,
        kind="scene",
        lines_per_second=lines_per_second,
        camera=camera or CameraModel(),
        ambient_albedo=scene.ambient_albedo,
        seed=seed,
        patterns=pats,
        attrs={"scene": scene.params},
    )

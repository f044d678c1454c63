"""The simulated Episcan: a built-in scene seen through the camera model.

Rendering uses the same illumination model (:mod:`planeray.timing`) as the
demultiplexer, with the camera's sync jitter and realized per-row trigger
offsets, then the sensor model (:mod:`planeray.camera`) adds ambient light and
noise.  Noise is seeded by ``(seed, delay, exposure, n-th grab at that
setting)``, so a sweep gives the same bytes whatever order it is captured in --
which lets an interrupted capture resume exactly.

The simulated rig
-----------------
With ``screen=N`` the device's projector is plugged into screen ``N`` of the X
display: every grab reads that screen back from the X server
(:func:`planeray.projector.grab_screen`) and its rows light the scene, so its
images follow whatever the projector window shows (``planeray project``, the
calibration captures, ``planeray rig check``).  Without it the projector shows
white, as before.  The rig's timing is modelled from the projector's VSYNC:
the raster lights row ``v`` at ``raster_start_us + v / v_p`` after the VSYNC's
rising edge, every ``1 / frame_rate_hz``; a global-shutter exposure opens
``trigger_delay_us`` after the trigger.  Faults can be injected as options
(``trigger_wired=False``, ``trigger_edge="falling"``, ``gamma=2.2``,
``shutter="global"``, ``row_time_error=0.1``, ``exposure_range_us=[20, 1000]``,
``screen`` another than the window's) for ``rig check`` to find.

The pulsing skin
----------------
With ``pulse_bpm`` (the ``skin`` scene only) the veins' blood volume pulses: each grab renders the
transport at the blood scale ``s = 1 + pulse_amplitude * (1 - cos(2 pi f t)) / 2`` averaged over the
grab's frame times ``t`` on the rig's clock (``frame_rate_hz``), ``f = pulse_bpm / 60``, linearized
as the live pulse simulation is (:mod:`planeray.pulse.simulate`): ``T(s) = T(1) + (s - 1) dT/ds``, the
derivative a central difference of two scene builds at ``1 +- 0.02``.  A sinusoid, so that the rate
is exactly ``pulse_bpm`` (the heart's waveform and its variability are the pulse simulation's).
"""

from __future__ import annotations

import numpy as np

from ..camera import CameraModel, binned_camera, row_shifts_rows
from ..errors import DeviceError, InputError
from ..scenes import Scene
from ..timing import PAPER_LINES_PER_SECOND, PAPER_PROJECTOR_ROWS, Band, RowPattern
from ..transport import Transport
from .base import DeviceBase, register_device
from .capabilities import SHUTTER_MODES, TRIGGER_EDGES

#: The simulated rig's settings and their defaults (a device at these defaults is the plain simulated Episcan).
RIG_DEFAULTS = dict(
    screen=None,
    display=None,
    trigger_wired=True,
    trigger_edge="rising",
    shutter="rolling",
    gamma=1.0,
    row_time_error=0.0,
    delay_error_us=0.0,
    exposure_range_us=(1.0, 1_000_000.0),
    trigger_delay_range_us=(0.0, 2_000_000.0),
    frame_rate_hz=60.0,
    raster_start_us=1000.0,
    vsync_pulse_us=100.0,
    trigger_timeout_s=1.0,
)

__all__ = ["SimulatedEpiscan", "open_simulated", "simulated_device"]


class SimulatedEpiscan(DeviceBase):
    """A simulated synchronized laser-projector / rolling-shutter camera.

    Parameters
    ----------
    scene : Scene
        Ground-truth scene (see :func:`planeray.scenes.make_scene`).
    camera : CameraModel, optional
    lines_per_second : float
        Projector scanline velocity (paper: 54,000).
    seed : int
        Noise seed.
    noise : bool
        False renders expected images (no noise, no quantization) for ground-truth checks.
    rig : dict, optional
        The simulated rig (:data:`RIG_DEFAULTS`): ``screen`` (the X screen the
        projector shows, None: white), ``display``, and the rig's timing and faults
        (see the module's docstring).

    See Also
    --------
    planeray.simulate_stack : a whole sweep in one call.
    planeray.ReplayDevice : a recorded stack as a device.
    planeray.devices.open_device : every device by name.

    References
    ----------
    .. [1] H. Kubo, S. Jayasuriya, T. Iwaguchi, T. Funatomi, Y. Mukaigawa, S. G. Narasimhan,
       "Programmable Non-Epipolar Indirect Light Transport: Capture and Analysis",
       IEEE TVCG 27(4), 2019, doi:10.1109/TVCG.2019.2946812, Sec. 6 (the Episcan prototype).

    Examples
    --------
    >>> import planeray as pr
    >>> device = pr.SimulatedEpiscan(pr.make_scene("wax", (8, 8), seed=0), seed=0)
    >>> device.set_delay(0.0)
    >>> device.set_exposure(600.0)
    >>> image, saturated = device.grab()
    >>> image.shape, image.dtype.name, bool(saturated.any())
    ((8, 8), 'float32', False)
    """

    kind = "simulated"
    shutter_modes = SHUTTER_MODES

    def __init__(
        self,
        scene: Scene,
        camera: CameraModel | None = None,
        *,
        lines_per_second=PAPER_LINES_PER_SECOND,
        seed=0,
        noise=True,
        rig: dict | None = None,
        pulse: dict | None = None,
    ):
        self.scene = scene
        self._pulse = None if pulse is None else dict(pulse)
        self.camera = camera or CameraModel()
        self.lines_per_second = float(lines_per_second)
        self.seed = int(seed)
        self.noise = bool(noise)
        self.delay_us = 0.0
        self.exposure_us = 600.0
        self._grabs: dict[tuple[int, int], int] = {}
        unknown = sorted(set(rig or {}) - set(RIG_DEFAULTS))
        if unknown:
            raise InputError(f"unknown rig setting {', '.join(unknown)}; known: {', '.join(RIG_DEFAULTS)}")
        self.rig = {**RIG_DEFAULTS, **(rig or {})}
        r = self.rig
        if r["trigger_edge"] not in TRIGGER_EDGES:
            raise InputError(f"trigger_edge must be 'rising' or 'falling', got {r['trigger_edge']!r}")
        if r["shutter"] not in SHUTTER_MODES:
            raise InputError(f"shutter must be 'rolling' or 'global', got {r['shutter']!r}")
        if not (isinstance(r["gamma"], (int, float)) and r["gamma"] > 0):
            raise InputError(f"gamma must be a positive number, got {r['gamma']!r}")
        for key in ("exposure_range_us", "trigger_delay_range_us"):
            lo_hi = r[key]
            if not (isinstance(lo_hi, (list, tuple)) and len(lo_hi) == 2 and 0 <= lo_hi[0] < lo_hi[1]):
                raise InputError(f"{key} must be [min, max] with 0 <= min < max, got {lo_hi!r}")
            r[key] = (float(lo_hi[0]), float(lo_hi[1]))
        self._shutter = r["shutter"]
        self._edge = r["trigger_edge"]
        self._global = (600.0, 0.5e6 / r["frame_rate_hz"])  # (exposure, trigger delay) of a global exposure
        self._clock_s = 0.0
        self._frame_times = np.zeros(0)
        self._screen = None
        if r["screen"] is not None:
            from ..projector import get_screen

            self._screen = get_screen(r["screen"], r["display"])
            if self._screen.height != self.scene.geometry.projector_rows:
                raise InputError(
                    f"the simulated projector shows screen {self._screen.index} ({self._screen.height} rows) but the "
                    f"scene has {self.scene.geometry.projector_rows} projector rows: give -O projector_rows="
                    f"{self._screen.height}"
                )

    # ------------------------------------------------------------------ capabilities
    def get_shutter(self) -> str:
        return self._shutter

    def set_shutter(self, mode: str) -> None:
        if mode not in SHUTTER_MODES:
            raise InputError(f"shutter mode must be 'rolling' or 'global', got {mode!r}")
        self._shutter = mode

    def set_global_timing(self, exposure_us: float, trigger_delay_us: float) -> None:
        self._check_exposure(exposure_us)
        lo, hi = self.rig["trigger_delay_range_us"]
        if not lo <= trigger_delay_us <= hi:
            raise DeviceError(f"trigger delay {trigger_delay_us:g} us is outside the camera's {lo:g}..{hi:g} us")
        self._global = (float(exposure_us), float(trigger_delay_us))

    def get_trigger_edge(self) -> str:
        return self._edge

    def set_trigger_edge(self, edge: str) -> None:
        if edge not in TRIGGER_EDGES:
            raise InputError(f"trigger edge must be 'rising' or 'falling', got {edge!r}")
        self._edge = edge

    def frame_times_s(self) -> np.ndarray:
        return self._frame_times.copy()

    def get_gamma(self) -> float:
        return float(self.rig["gamma"])

    def get_row_time_us(self) -> float:
        """Camera row time: a projector row's scanline time, times the rows per camera row, times the fault."""
        g = self.scene.geometry
        return 1e6 / self.lines_per_second * g.rows_per_camera_row * (1.0 + self.rig["row_time_error"])

    def get_exposure_range_us(self) -> tuple[float, float]:
        return self.rig["exposure_range_us"]

    def get_exposure_step_us(self) -> float:
        """0: the simulated camera realizes any exposure in its range."""
        return 0.0

    def get_trigger_delay_step_us(self) -> float:
        """0: the simulated camera realizes any delay."""
        return 0.0

    def get_timing_us(self) -> tuple[float, float]:
        """The delay and exposure the next grab renders (us)."""
        return self.delay_us, self.exposure_us

    def get_trigger_delay_range_us(self) -> tuple[float, float]:
        return self.rig["trigger_delay_range_us"]

    @property
    def frame_period_us(self) -> float:
        """The projector's frame period (us)."""
        return 1e6 / self.rig["frame_rate_hz"]

    def _check_exposure(self, exposure_us) -> None:
        if not exposure_us > 0:
            raise ValueError(f"exposure must be positive, got {exposure_us}")
        lo, hi = self.rig["exposure_range_us"]
        if not lo <= exposure_us <= hi:
            raise DeviceError(f"exposure {exposure_us:g} us is outside the camera's range {lo:g}..{hi:g} us")

    # ------------------------------------------------------------------ the pulsing skin
    def blood_scale(self) -> float:
        """The veins' blood scale of the last grab (1 without a pulse): the mean over its frames' times."""
        if self._pulse is None or self._frame_times.size == 0:
            return 1.0
        phase = 2.0 * np.pi * self._pulse["bpm"] / 60.0 * self._frame_times
        return float(np.mean(1.0 + self._pulse["amplitude"] * 0.5 * (1.0 - np.cos(phase))))

    def _render(self, illumination) -> np.ndarray:
        """The scene's transport rendered under ``illumination`` (at the grab's blood scale, with a pulse)."""
        signal = self.scene.transport.render(illumination)
        if self._pulse is not None:
            s = self.blood_scale()
            if s != 1.0:
                signal = signal + np.float32(s - 1.0) * self._pulse["derivative"].render(illumination)
        return signal

    # ------------------------------------------------------------------ the projector and the trigger
    def projected_rows(self) -> np.ndarray | None:
        """What the projector shows now, one value per projector row in [0, 1] (None: white, no screen)."""
        if self._screen is None:
            return None
        from ..projector import grab_screen

        shot = grab_screen(self._screen).astype(np.float64)
        return shot.mean(axis=(1, 2)) / 255.0

    def _frames(self, n: int) -> None:
        """Wait for ``n`` triggers (simulated clock): refuse as a camera does when none comes."""
        r = self.rig
        if not r["trigger_wired"]:
            raise DeviceError(
                f"no trigger on VSYNC within {r['trigger_timeout_s']:g} s: is the projector on, and its VSYNC "
                "wired to the camera's trigger input?"
            )
        period = 1.0 / r["frame_rate_hz"]
        start = np.ceil(self._clock_s / period + 1e-9) * period
        self._frame_times = start + period * np.arange(n)
        self._clock_s = float(self._frame_times[-1])

    def _edge_shift_us(self) -> float:
        """How much later a frame starts than on the rising edge (the VSYNC pulse on the falling one)."""
        return self.rig["vsync_pulse_us"] if self._edge == "falling" else 0.0

    def _output(self, image, saturated):
        """The camera's output stage: gamma (1: linear)."""
        g = self.rig["gamma"]
        if g != 1.0:
            image = (np.clip(image, 0.0, None) ** (1.0 / g)).astype(np.float32)
        return image, saturated

    def set_delay(self, delay_us: float) -> None:
        self.delay_us = float(delay_us)

    def set_exposure(self, exposure_us: float) -> None:
        self._check_exposure(exposure_us)
        self.exposure_us = float(exposure_us)

    def _rng(self) -> np.random.Generator:
        key = (int(round(self.delay_us * 1000)), int(round(self.exposure_us * 1000)))
        n = self._grabs.get(key, 0)
        self._grabs[key] = n + 1
        # Entropy must be non-negative: fold the signed delay into two words.
        return np.random.default_rng([self.seed, key[0] + 2**40, key[1], n])

    def band(self, rng: np.random.Generator | None = None) -> Band:
        """Illumination of the current settings, with realized row jitter if ``rng`` is given.

        The rig's delay error and trigger edge move the band's true delay; a row time
        off by ``row_time_error`` moves each camera row's band by that fraction of its
        projector row (the rolling shutter drifts against the raster).
        """
        cam = self.camera
        shifts = None
        if rng is not None and self.noise:
            shifts = row_shifts_rows(
                rng, cam.frames_averaged, self.scene.shape[0], cam.row_jitter_us, self.lines_per_second
            )
        e = self.rig["row_time_error"]
        if e:
            geometry = self.scene.geometry
            drift = -e * geometry.projector_row_of(np.arange(geometry.camera_rows))
            shifts = drift[None, :] if shifts is None else shifts + drift[None, :]
        delay = self.delay_us + self.rig["delay_error_us"] - self._edge_shift_us()
        return Band(delay, self.exposure_us, self.lines_per_second, cam.jitter_us, 0.0, shifts)

    def grab(self):
        """One averaged image: the rolling-shutter band of Eq. 3 or, in global mode, one global exposure.

        A rolling exposure of a whole projector frame or more collects the frame's
        raster once per frame period (every row lit once a frame), whatever its delay.
        """
        self._frames(self.camera.frames_averaged)
        if self._shutter == "global":
            exposure_us, trigger_delay_us = self._global
            return self._output(*self.global_exposure(exposure_us, trigger_delay_us))
        rng = self._rng()
        rows = self.projected_rows()
        if self.exposure_us >= self.frame_period_us:
            pattern = np.ones(self.scene.geometry.projector_rows) if rows is None else rows
            signal = (self.exposure_us / self.frame_period_us) * self._render(RowPattern(pattern))
        else:
            band = self.band(rng)
            signal = self._render(band if rows is None else _Lit(band, RowPattern(rows)))
        return self._output(
            *self.camera.expose(
                signal, self.exposure_us, rng, ambient_albedo=self.scene.ambient_albedo, noise=self.noise
            )
        )

    def global_exposure(self, exposure_us: float, trigger_delay_us: float):
        """One global-shutter exposure of what the projector shows, opened ``trigger_delay_us`` after the trigger.

        Projector row ``v`` is lit during its scanline, ``raster_start_us + v / v_p``
        after the VSYNC; the exposure collects the fraction of each row's scanline it
        overlaps (as :meth:`capture_line_sweep`), times the row's value on the screen.
        """
        P = self.scene.geometry.projector_rows
        v_p = self.lines_per_second
        opens_us = float(trigger_delay_us) + self._edge_shift_us() - self.rig["raster_start_us"]
        start_row = opens_us * 1e-6 * v_p - 0.5
        n_v = v_p * float(exposure_us) * 1e-6
        rng = np.random.default_rng(
            [
                self.seed,
                2**44,
                int(round(exposure_us * 1000)),
                int(round(trigger_delay_us * 1000)),
                self._next_pattern(),
            ]
        )
        rows = self.projected_rows()
        pattern = self._exposed(rng, start_row, n_v) * (np.ones(P) if rows is None else rows)
        signal = self._render(RowPattern(pattern))
        return self.camera.expose(signal, exposure_us, rng, ambient_albedo=self.scene.ambient_albedo, noise=self.noise)

    def _exposed(self, rng, start, length):
        """Exposed fraction of each projector row's scanline in ``[start, start + length)`` rows, over the frames."""
        from ..timing import band_bin_weights

        rows = np.arange(self.scene.geometry.projector_rows, dtype=float)
        cam = self.camera
        jitter_rows = cam.jitter_us * 1e-6 * self.lines_per_second
        if not self.noise:  # expected value over the jitter
            return band_bin_weights(rows, start + 0.5 * length, length, blur_sigma_rows=jitter_rows)
        shifts = rng.normal(0.0, jitter_rows, cam.frames_averaged) if jitter_rows > 0 else np.zeros(1)
        return np.mean([band_bin_weights(rows, start + s + 0.5 * length, length) for s in shifts], axis=0)

    def capture_pattern(self, pattern, exposure_us: float, *, frame_period_us: float = 1e6 / 60.0):
        """Conventional (unsynchronized) capture: project a row pattern, one full-frame exposure.

        The raster projector repeats the pattern every ``frame_period_us``; each
        pass lights every projector row for one scanline, so an exposure collects
        ``exposure_us / frame_period_us`` passes of ``sum_v pattern(v) T(v)``,
        while ambient light is integrated over the whole exposure.  This is the
        paper's single-line baseline of Fig. 12 (16 ms and 800 ms exposures).

        Returns the normalized image and its saturation mask (``frames_averaged``
        such exposures averaged, as for sweep images).
        """
        from ..timing import RowPattern

        passes = float(exposure_us) / float(frame_period_us)
        rng = np.random.default_rng([self.seed, 2**41, int(round(exposure_us * 1000)), self._next_pattern()])
        signal = passes * self.scene.transport.render(RowPattern(np.asarray(pattern, float)))
        return self.camera.expose(signal, exposure_us, rng, ambient_albedo=self.scene.ambient_albedo, noise=self.noise)

    def capture_line_sweep(
        self,
        exposure_us: float = 500.0,
        *,
        line_step_rows: int | None = None,
        start_row: float | None = None,
        phases=None,
        references: bool = True,
        falloff: float = 0.0,
        blur_rows: float = 0.0,
    ):
        """Global-shutter images of a swept line comb: the line-velocity calibration (Sec. 6).

        The paper projects a single-pixel horizontal line, sweeps it down the
        projector and images the sweep with one global-shutter exposure of 500 us;
        the ``n_v = v_p t_e`` rows the laser raster scans during the exposure are the
        visible lines (27 at 54,000 lines/s).  Adjacent lit rows would merge into
        one band, so the pattern here is a *comb*: every ``k``-th projector row
        (``line_step_rows``), one image per comb phase, all phases with the same
        VSYNC-triggered exposure window.  Each image then shows about ``n_v / k``
        lines separated by ``k`` projector rows, and the phases together light
        every row once, so their fractional line counts add up to exactly ``n_v``
        whatever the fractional phase of the window relative to the raster (a
        single image of a comb can only bound a window end that fell in a dark
        gap; see :func:`planeray.calibration.calibrate_lines_per_second`).

        Physics: projector row ``v`` is lit during its scanline period
        ``[v - 1/2, v + 1/2)`` (raster time in rows); the exposure spans raster
        rows ``[start_row, start_row + n_v)``, so row ``v`` contributes the overlap
        fraction of its scanline, each frame shifted by the laser-to-shutter jitter
        (``camera.jitter_us``, drawn per averaged frame).  The images are rendered
        with the scene's transport (:class:`~planeray.timing.RowPattern`), so the
        camera-row footprint blurs the lines as it blurs everything else; an
        optional smooth projector falloff and optical blur make brightness and
        line shape less ideal; ambient light integrates over the whole global
        exposure and the camera adds its noise (:meth:`CameraModel.expose`).

        The scene should resolve the projector's rows (a calibration target imaged
        at full resolution, e.g. ``make_scene("diffuse_plane", (3 * P, W),
        projector_rows=P)``): 27 rows of a 720-row projector span under 5 rows of
        a 128-row image.

        Parameters
        ----------
        exposure_us : float
            Global-shutter exposure ``t_e`` (paper: 500 us).
        line_step_rows : int, optional
            Comb step ``k``; default: the smallest ``k >= 2`` that puts lines at
            least 6 camera rows apart.
        start_row : float, optional
            Raster position (projector rows, fractional) at which the exposure
            opens; default: random (seeded), with the window and its margins on
            the projector.
        phases : sequence of int, optional
            Comb phases to capture (default: all ``k``).
        references : bool
            Also capture a dark frame (laser off, ``t_e``) and a flat frame (every
            row lit, exposure ``2 t_e`` opened ``t_e / 2`` earlier, so that every
            row of the window is fully exposed).
        falloff : float
            Projector illumination falloff: 1 at the image centre, ``1 - falloff``
            at the corners (quadratic).
        blur_rows : float
            Gaussian optical blur (camera pixels, sigma).

        Returns
        -------
        planeray.calibration.LineSweep
            Images ``(n_phases, H, W)``, references, and in ``metadata`` the truth
            (``lines_per_second``, ``start_row``, ``window_rows``) and the device.
        """
        from scipy.ndimage import gaussian_filter

        from ..linesweep import LineSweep
        from ..timing import RowPattern, band_bin_weights

        if not exposure_us > 0:
            raise ValueError(f"exposure must be positive, got {exposure_us}")
        geometry = self.scene.geometry
        P, H = geometry.projector_rows, geometry.camera_rows
        cam = self.camera
        v_p = self.lines_per_second
        n_v = v_p * float(exposure_us) * 1e-6  # rows scanned during the exposure
        k = int(line_step_rows) if line_step_rows is not None else max(2, int(np.ceil(6.0 * P / H - 1e-9)))
        if k < 1:
            raise ValueError(f"line_step_rows must be at least 1, got {line_step_rows}")
        phases = tuple(range(k)) if phases is None else tuple(int(p) % k for p in phases)
        self._line_sweeps = getattr(self, "_line_sweeps", 0) + 1
        rng = np.random.default_rng([self.seed, 2**43, int(round(exposure_us * 1000)), k, self._line_sweeps])
        margin = max(0.5 * n_v if references else 0.0, k + 1.0) + 1.0
        if start_row is None:
            lo, hi = -0.5 + margin, P - 0.5 - margin - n_v
            if hi < lo:
                raise ValueError(
                    f"the {n_v:.1f} rows scanned in {exposure_us} us and their margins do not fit on the "
                    f"projector's {P} rows; use a shorter exposure or a taller projector"
                )
            start_row = float(rng.uniform(lo, hi))
        start_row = float(start_row)
        rows = np.arange(P, dtype=float)
        jitter_rows = cam.jitter_us * 1e-6 * v_p

        def exposed(start, length):
            """Exposed fraction of each projector row's scanline, averaged over the frames."""
            if not self.noise:  # expected value over the jitter
                return band_bin_weights(rows, start + 0.5 * length, length, blur_sigma_rows=jitter_rows)
            shifts = rng.normal(0.0, jitter_rows, cam.frames_averaged) if jitter_rows > 0 else np.zeros(1)
            return np.mean([band_bin_weights(rows, start + s + 0.5 * length, length) for s in shifts], axis=0)

        gain = 1.0
        if falloff:
            yy = (np.arange(H) + 0.5) / H - 0.5
            xx = (np.arange(self.scene.shape[1]) + 0.5) / self.scene.shape[1] - 0.5
            gain = 1.0 - float(falloff) * 2.0 * (yy[:, None] ** 2 + xx[None, :] ** 2)
        ambient = self.scene.ambient_albedo
        if blur_rows > 0:
            ambient = gaussian_filter(np.asarray(ambient, np.float64), blur_rows, mode="nearest")

        def shoot(pattern, t_us):
            signal = self.scene.transport.render(RowPattern(pattern)) * gain
            if blur_rows > 0:
                signal = gaussian_filter(np.asarray(signal, np.float64), blur_rows, mode="nearest")
            return cam.expose(signal, t_us, rng, ambient_albedo=ambient, noise=self.noise)

        images, saturated = [], []
        for j in phases:
            img, sat = shoot(exposed(start_row, n_v) * (np.arange(P) % k == j), exposure_us)
            images.append(img)
            saturated.append(sat)
        dark = flat = flat_exposure = None
        if references:
            dark = shoot(np.zeros(P), exposure_us)[0]
            flat_exposure = 2.0 * float(exposure_us)
            flat = shoot(exposed(start_row - 0.5 * n_v, 2.0 * n_v), flat_exposure)[0]
        return LineSweep(
            np.stack(images),
            float(exposure_us),
            k,
            phases,
            dark,
            flat,
            flat_exposure,
            np.stack(saturated),
            timing_jitter_us=cam.jitter_us / np.sqrt(cam.frames_averaged) if self.noise else 0.0,
            metadata={
                "truth": {"lines_per_second": v_p, "start_row": start_row, "window_rows": n_v},
                "falloff": float(falloff),
                "blur_rows": float(blur_rows),
                "device": self.describe(),
            },
        )

    def _next_pattern(self) -> int:
        self._patterns = getattr(self, "_patterns", 0) + 1
        return self._patterns

    def describe(self) -> dict:
        rig = {k: (list(v) if isinstance(v, tuple) else v) for k, v in self.rig.items() if v != RIG_DEFAULTS[k]}
        return {
            **({"rig": rig} if rig else {}),
            "device": self.kind,
            "image_shape": list(self.scene.shape),
            "projector_rows": self.scene.geometry.projector_rows,
            "lines_per_second": self.lines_per_second,
            "camera": self.camera.to_dict(),
            "signal_scale": self.camera.signal_scale,
            "sync": {
                "jitter_us": self.camera.jitter_us,
                "row_jitter_us": self.camera.row_jitter_us,
                "line_width_us": 0.0,
            },
            "scene": self.scene.params,
            "seed": self.seed,
            "noise": self.noise,
            **(
                {"pulse": {"bpm": self._pulse["bpm"], "amplitude": self._pulse["amplitude"]}}
                if self._pulse is not None
                else {}
            ),
        }


class _Lit:
    """A band of the rolling shutter times what the projector shows (row by row)."""

    def __init__(self, band, pattern):
        self.band, self.pattern = band, pattern

    def weights(self, geometry, rows, offsets_rows):
        return self.band.weights(geometry, rows, offsets_rows) * self.pattern.weights(geometry, rows, offsets_rows)


@register_device("sim", "simulated Episcan: a built-in scene seen through the camera model")
def open_simulated(
    *,
    scene: str = "wax",
    size=(128, 128),
    projector_rows: int | None = None,
    seed: int = 0,
    lines_per_second: float = PAPER_LINES_PER_SECOND,
    noise: bool = True,
    screen: int | None = None,
    display: str | None = None,
    trigger_wired: bool = True,
    trigger_edge: str = "rising",
    shutter: str = "rolling",
    gamma: float = 1.0,
    row_time_error: float = 0.0,
    delay_error_us: float = 0.0,
    exposure_range_us=(1.0, 1_000_000.0),
    trigger_delay_range_us=(0.0, 2_000_000.0),
    frame_rate_hz: float = 60.0,
    frames_averaged: int = 8,
    sensor_rows: int | None = None,
    pulse_bpm: float | None = None,
    pulse_amplitude: float = 0.02,
) -> SimulatedEpiscan:
    """A :class:`SimulatedEpiscan` of a built-in scene (``planeray acquire --device sim``).

    Parameters
    ----------
    scene : str
        Built-in scene (:func:`planeray.scenes.list_scenes`).
    size : (int, int)
        Image ``(H, W)`` in camera pixels.
    projector_rows : int, optional
        Projector rows spanned by the image (default ``H``).
    seed : int
        Seed of the scene and of the noise.
    lines_per_second : float
        Projector scanline velocity ``v_p``.
    noise : bool
        False renders expected images.
    screen : int, optional
        The X screen the simulated projector shows (``--screen`` of the window); its
        rows light the scene.  ``projector_rows`` defaults to the screen's height.
    display : str, optional
        Its X display (default ``$DISPLAY``).
    trigger_wired, trigger_edge, shutter, gamma, row_time_error, delay_error_us : optional
        The rig as built (faults to inject): VSYNC wired to the trigger, the edge the
        camera triggers on (the rig is wired for ``rising``), the shutter mode the
        camera is in, its output gamma, its row time's relative error against the
        projector's line time, and a hidden sync error (us).
    exposure_range_us, trigger_delay_range_us : [float, float]
        What the camera can realize (us).
    frame_rate_hz : float
        The projector's frame rate.
    frames_averaged : int
        Frames averaged per image (the paper: 8; a live view: 1).
    sensor_rows : int, optional
        The real sensor's rows over the projector's whole field (the paper's camera: 1200): a simulated
        pixel then sums the sensor pixels that see its patch (:func:`planeray.camera.binned_camera`), so
        that its noise is the real camera's; default: one sensor pixel per simulated pixel.
    pulse_bpm : float, optional
        The ``skin`` scene only: the veins' blood volume pulses at this rate (30-240 per minute; see
        the module's docstring), on the rig's clock.
    pulse_amplitude : float
        Relative blood-volume change of the veins from diastole to systole (0-0.1).
    """
    from dataclasses import replace

    from ..scenes import make_scene

    if isinstance(frames_averaged, bool) or int(frames_averaged) != frames_averaged or frames_averaged < 1:
        raise InputError(f"frames_averaged must be a positive integer, got {frames_averaged!r}")
    if sensor_rows is not None and (
        isinstance(sensor_rows, bool) or int(sensor_rows) != sensor_rows or sensor_rows < 1
    ):
        raise InputError(f"sensor_rows must be a positive integer, got {sensor_rows!r}")
    if pulse_bpm is not None:
        if scene != "skin":
            raise InputError(f"pulse_bpm needs scene='skin' (the pulsing veins), got scene={scene!r}")
        if isinstance(pulse_bpm, bool) or not 30.0 <= float(pulse_bpm) <= 240.0:
            raise InputError(f"pulse_bpm must be between 30 and 240 beats per minute, got {pulse_bpm!r}")
        if isinstance(pulse_amplitude, bool) or not 0.0 <= float(pulse_amplitude) <= 0.1:
            raise InputError(f"pulse_amplitude must be between 0 and 0.1, got {pulse_amplitude!r}")

    if screen is not None and projector_rows is None:
        from ..projector import get_screen

        projector_rows = get_screen(screen, display).height
    shape = tuple(int(n) for n in size)
    built = make_scene(scene, shape, projector_rows=projector_rows, seed=seed)
    pulse = None
    if pulse_bpm is not None:
        step = 0.02  # the central difference of the live pulse simulation (planeray.pulse.simulate.linearize)
        up, down = (
            make_scene(scene, shape, projector_rows=projector_rows, seed=seed, blood_scale=1.0 + k * step).transport
            for k in (1, -1)
        )
        if len(up.sparse) or len(down.sparse):
            raise InputError("the pulsing skin needs a scene without sparse entries")
        derivative = Transport((up.dense - down.dense) / np.float32(2 * step), up.offsets_rows, up.geometry)
        pulse = {"bpm": float(pulse_bpm), "amplitude": float(pulse_amplitude), "derivative": derivative}
    rig = dict(
        screen=screen,
        display=display,
        trigger_wired=trigger_wired,
        trigger_edge=trigger_edge,
        shutter=shutter,
        gamma=gamma,
        row_time_error=row_time_error,
        delay_error_us=delay_error_us,
        exposure_range_us=tuple(exposure_range_us),
        trigger_delay_range_us=tuple(trigger_delay_range_us),
        frame_rate_hz=frame_rate_hz,
    )
    camera = replace(CameraModel(), frames_averaged=int(frames_averaged))
    if sensor_rows is not None:  # the sensor spans the projector's whole field; the scene may show a part of it
        rows = float(sensor_rows) * built.geometry.projector_rows / PAPER_PROJECTOR_ROWS
        camera = binned_camera(camera, (rows / shape[0]) ** 2)
    return SimulatedEpiscan(
        built, camera, lines_per_second=lines_per_second, seed=seed, noise=noise, rig=rig, pulse=pulse
    )


def simulated_device(
    scene: str,
    size,
    *,
    projector_rows=None,
    seed: int = 0,
    ambient_e_per_us: float = 0.01,
    noise: bool = True,
    lines_per_second: float | None = None,
):
    """The simulated Episcan on built-in ``scene`` in a dim room, as ``planeray emulate`` and ``separate`` use it.

    Parameters
    ----------
    scene : str
        Built-in scene name.
    size : tuple of int
        Image size ``(H, W)`` (camera pixels).
    projector_rows : int, optional
        Projector rows spanned by the image height (default: ``H``, as :func:`planeray.scenes.make_scene`).
    seed : int
        Scene and noise seed.
    ambient_e_per_us : float
        Room light, electrons per microsecond (a dim room by default: conventional
        frames integrate 16.7 ms).
    noise : bool
        Simulate noise.
    lines_per_second : float, optional
        Projector line rate (default: the paper's 54,000 lines/s).

    Returns
    -------
    SimulatedEpiscan

    See Also
    --------
    planeray.baselines.compare_direct_global, planeray.baselines.compare_emulation : the comparisons it serves.

    Examples
    --------
    >>> device = simulated_device("corner", (16, 16), seed=0)
    >>> device.lines_per_second, device.scene.name
    (54000.0, 'corner')
    """
    from ..scenes import make_scene

    return SimulatedEpiscan(
        make_scene(scene, tuple(size), projector_rows=projector_rows, seed=seed),
        camera=CameraModel(ambient_e_per_us=ambient_e_per_us),
        lines_per_second=lines_per_second or PAPER_LINES_PER_SECOND,
        seed=seed,
        noise=noise,
    )

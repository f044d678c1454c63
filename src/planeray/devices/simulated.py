"""The simulated Episcan: a built-in scene seen through the camera model.

Rendering uses the same illumination model (:mod:`planeray.timing`) as the
demultiplexer, with the camera's sync jitter and realized per-row trigger
offsets, then the sensor model (:mod:`planeray.camera`) adds ambient light and
noise.  Noise is seeded by ``(seed, delay, exposure, n-th grab at that
setting)``, so a sweep gives the same bytes whatever order it is captured in --
which lets an interrupted capture resume exactly.
"""

from __future__ import annotations

import numpy as np

from ..camera import CameraModel, row_shifts_rows
from ..scenes import Scene
from ..timing import PAPER_LINES_PER_SECOND, Band
from .base import DeviceBase, register_device

__all__ = ["SimulatedEpiscan", "open_simulated"]


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
    """

    kind = "simulated"

    def __init__(
        self,
        scene: Scene,
        camera: CameraModel | None = None,
        *,
        lines_per_second=PAPER_LINES_PER_SECOND,
        seed=0,
        noise=True,
    ):
        self.scene = scene
        self.camera = camera or CameraModel()
        self.lines_per_second = float(lines_per_second)
        self.seed = int(seed)
        self.noise = bool(noise)
        self.delay_us = 0.0
        self.exposure_us = 600.0
        self._grabs: dict[tuple[int, int], int] = {}

    def set_delay(self, delay_us: float) -> None:
        self.delay_us = float(delay_us)

    def set_exposure(self, exposure_us: float) -> None:
        if exposure_us <= 0:
            raise ValueError(f"exposure must be positive, got {exposure_us}")
        self.exposure_us = float(exposure_us)

    def _rng(self) -> np.random.Generator:
        key = (int(round(self.delay_us * 1000)), int(round(self.exposure_us * 1000)))
        n = self._grabs.get(key, 0)
        self._grabs[key] = n + 1
        # Entropy must be non-negative: fold the signed delay into two words.
        return np.random.default_rng([self.seed, key[0] + 2**40, key[1], n])

    def band(self, rng: np.random.Generator | None = None) -> Band:
        """Illumination of the current settings, with realized row jitter if ``rng`` is given."""
        cam = self.camera
        shifts = None
        if rng is not None and self.noise:
            shifts = row_shifts_rows(
                rng, cam.frames_averaged, self.scene.shape[0], cam.row_jitter_us, self.lines_per_second
            )
        return Band(self.delay_us, self.exposure_us, self.lines_per_second, cam.jitter_us, 0.0, shifts)

    def grab(self):
        rng = self._rng()
        signal = self.scene.transport.render(self.band(rng))
        return self.camera.expose(
            signal, self.exposure_us, rng, ambient_albedo=self.scene.ambient_albedo, noise=self.noise
        )

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
        return {
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
        }


@register_device("sim", "simulated Episcan: a built-in scene seen through the camera model")
def open_simulated(
    *,
    scene: str = "wax",
    size=(128, 128),
    projector_rows: int | None = None,
    seed: int = 0,
    lines_per_second: float = PAPER_LINES_PER_SECOND,
    noise: bool = True,
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
    """
    from ..scenes import make_scene

    built = make_scene(scene, tuple(int(n) for n in size), projector_rows=projector_rows, seed=seed)
    return SimulatedEpiscan(built, lines_per_second=lines_per_second, seed=seed, noise=noise)

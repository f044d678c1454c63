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

__all__ = ["SimulatedEpiscan"]


class SimulatedEpiscan:
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

    def __init__(self, scene: Scene, camera: CameraModel | None = None, lines_per_second=PAPER_LINES_PER_SECOND, seed=0, noise=True):
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
            shifts = row_shifts_rows(rng, cam.frames_averaged, self.scene.shape[0], cam.row_jitter_us, self.lines_per_second)
        return Band(self.delay_us, self.exposure_us, self.lines_per_second, cam.jitter_us, 0.0, shifts)

    def grab(self):
        rng = self._rng()
        signal = self.scene.transport.render(self.band(rng))
        return self.camera.expose(signal, self.exposure_us, rng, self.scene.ambient_albedo, noise=self.noise)

    def capture_pattern(self, pattern, exposure_us: float, frame_period_us: float = 1e6 / 60.0):
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
        return self.camera.expose(signal, exposure_us, rng, self.scene.ambient_albedo, noise=self.noise)

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
            "sync": {"jitter_us": self.camera.jitter_us, "row_jitter_us": self.camera.row_jitter_us, "line_width_us": 0.0},
            "scene": self.scene.params,
            "seed": self.seed,
            "noise": self.noise,
        }

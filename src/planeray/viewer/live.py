"""What ``planeray view --device NAME`` shows: a device live (no web here; the capture is :mod:`planeray.live`).

:class:`DeviceSource` is the :class:`~planeray.viewer.session.ViewSource` of an open device.  Its
:class:`~planeray.live.LiveCapture` captures continuously; a page's render request sets what is
captured (its delay and exposure: the camera's trigger delay and exposure; a cycle of delays for
Eq. 7's composite) and is answered by the first frame newer than the one the page has, captured at
those settings, in the page's view (:data:`planeray.live.VIEWS`): the band image, the vein view,
Eq. 7's composite, or the frame with the pulse of the rolling window (rate and spectrum).  A
snapshot writes what was shown -- the frame, or the cycle of frames -- as a native stack into the
folder the command line named.
"""

from __future__ import annotations

import math
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from ..devices.capabilities import has
from ..errors import InputError
from ..live import (
    DEFAULT_CYCLE_DELAYS_US,
    PULSE_WINDOW_S,
    VIEWS,
    LiveCapture,
    PulseMonitor,
    composite_view,
    cycle_delays,
    snapshot_path,
    vein_view,
    write_snapshot,
)
from .session import FrameBuffers, ViewSettings, ViewSource

__all__ = ["DeviceSource", "MODE_DEFAULTS", "DELAY_REACH_US"]

#: The delay slider's reach (us): a projector frame's worth around the epipolar plane is +-8,333 us;
#: the paper's sweep spans +-1,500.
DELAY_REACH_US = 3000.0
#: Settings a view starts from when the page switches to it (the skin's delay, Sec. 10; the pulse's longer
#: exposure halves the relative weight of the rows' sync jitter).
MODE_DEFAULTS = {
    "band": {},
    "vein": {"delay_us": 450.0, "exposure_us": 600.0},
    "composite": {"exposure_us": 600.0},
    "pulse": {"delay_us": 450.0, "exposure_us": 1200.0},
}


class DeviceSource(ViewSource):
    """A device shown live (the views of :data:`planeray.live.VIEWS`).

    Parameters
    ----------
    device : Device
        An open device; closed by :meth:`close`.
    name : str
        Its registered name (shown).
    max_fps : float, optional
        Capture at most this many frames a second (a simulated device).
    snapshot_dir : path, optional
        Where snapshots are written (default: the current folder).
    frame_timeout_s : float
        How long a render waits for its frame.
    """

    kind = "device"
    modes = tuple(VIEWS)
    mode_labels = VIEWS

    def __init__(self, device, *, name: str, max_fps=None, snapshot_dir=None, frame_timeout_s: float = 5.0):
        description = device.describe()
        super().__init__(name, description["image_shape"])
        self.description = description
        self.lines_per_second = float(device.lines_per_second)
        self.projector_rows = int(description.get("projector_rows") or self.shape[0])
        history = int(PULSE_WINDOW_S * min(max_fps or 100.0, 100.0)) + 64
        self.capture = LiveCapture(device, history=history, max_fps=max_fps)
        self.pulse = PulseMonitor()
        self._analysis = ThreadPoolExecutor(max_workers=1, thread_name_prefix="planeray-pulse")
        self.snapshot_dir = Path(snapshot_dir) if snapshot_dir is not None else Path.cwd()
        self.frame_timeout_s = float(frame_timeout_s)
        self._last = -1  # the newest frame shown
        self._hinted: dict = {}  # settings -> the capture's generation when it was pointed at them
        self._generation = None
        self._shown: list = []
        lo, hi = 10.0, 3000.0
        if has(device, "ranges"):
            e_lo, e_hi = device.get_exposure_range_us()
            lo, hi = max(lo, float(e_lo)), min(hi, float(e_hi))
        self.exposure_range_us = (lo, max(hi, lo))

    # ------------------------------------------------------------------ description
    def describe(self) -> dict:
        lo, hi = self.exposure_range_us
        defaults = ViewSettings(delay_us=0.0, exposure_us=float(min(max(600.0, lo), hi)))
        return {
            "kind": "device",
            "live": True,
            "name": self.name,
            "shape": list(self.shape),
            "projector_rows": self.projector_rows,
            "lines_per_second": self.lines_per_second,
            "modes": [{"name": m, "label": VIEWS[m]} for m in self.modes],
            "mode_defaults": MODE_DEFAULTS,
            "delay_us": {"min": -DELAY_REACH_US, "max": DELAY_REACH_US, "step": 1.0, "grid": None},
            "exposure_us": {"min": lo, "max": hi, "step": 1.0, "grid": None},
            "patterns": [],
            "toggles": [],
            "has_truth": False,
            "units": "camera (normalized: 0 = black level, 1 = top code)",
            "cycle_delays_us": list(DEFAULT_CYCLE_DELAYS_US),
            "pulse_window_s": PULSE_WINDOW_S,
            "device": self.description,
            "defaults": defaults.to_dict(),
        }

    def check(self, settings: ViewSettings) -> ViewSettings:
        settings = super().check(settings)
        if not math.isfinite(settings.delay_us) or abs(settings.delay_us) > DELAY_REACH_US:
            raise InputError(f"delay_us must be within +-{DELAY_REACH_US:g} us, got {settings.delay_us!r}")
        if settings.mode == "composite":
            cycle_delays(settings.exposure_us)  # at least two delays off the epipolar band, or one line
        return settings

    # ------------------------------------------------------------------ capture
    def hint(self, settings: ViewSettings) -> None:
        """Point the capture at ``settings`` now (the server calls it as a request arrives, before its render)."""
        if settings.mode == "composite":
            self.capture.set_cycle(cycle_delays(settings.exposure_us), settings.exposure_us)
        else:
            self.capture.set_timing(settings.delay_us, settings.exposure_us)
        self._hinted[self._key(settings)] = self.capture.generation
        if len(self._hinted) > 256:
            self._hinted.pop(next(iter(self._hinted)))

    @staticmethod
    def _key(settings: ViewSettings):
        return (settings.mode == "composite", float(settings.delay_us), float(settings.exposure_us))

    def warm(self) -> None:
        """Start the capture and wait for its first frame."""
        self.capture.start()
        self.capture.wait_frame(timeout_s=max(self.frame_timeout_s, 30.0))

    def _render(self, s: ViewSettings, buffers: FrameBuffers | None) -> tuple[np.ndarray, dict]:
        # the capture was pointed at these settings when the request came (hint), in some generation; a frame of
        # that generation or a later one is at them or at newer settings.  Never point it back to older ones.
        self._generation = self._hinted.get(self._key(s))
        if self._generation is None:
            self.hint(s)
            self._generation = self._hinted[self._key(s)]
        if s.mode == "composite":
            delays = cycle_delays(s.exposure_us)
            if self.capture.target != (tuple(float(d) for d in delays), float(s.exposure_us)):
                self.hint(s)  # a cycle is captured only while asked for: ask again
            frames = self.capture.wait_cycle(  # a whole cycle newer than anything shown
                delays, s.exposure_us, after=self._last, timeout_s=self.frame_timeout_s * len(delays)
            )
            image, used = composite_view(frames)
            info = {
                "label": f"Eq. 7 composite of {len(used['delays_us'])} delays "
                f"{used['delays_us'][0]:g}-{used['delays_us'][-1]:g} us  t_e {s.exposure_us:g} us",
                "composite": used,
            }
        else:
            # the first new frame at these settings -- or at newer ones a later request already asked for
            # (a slider being dragged: never wait for a timing the capture has left)
            frame = self.capture.wait_frame(
                self._last,
                timing=(float(s.delay_us), float(s.exposure_us)),
                generation=self._generation,
                timeout_s=self.frame_timeout_s,
            )
            frames = [frame]
            timing = (frame.delay_us, frame.exposure_us)
            image = vein_view(frame.image) if s.mode == "vein" else frame.image
            info = {
                "label": f"{'vein view' if s.mode == 'vein' else 'live'}  t_d {timing[0]:g} us  t_e {timing[1]:g} us"
            }
            if s.mode == "pulse":
                result = self.pulse.update(self.capture.window(PULSE_WINDOW_S, timing=timing), self._analysis)
                info["pulse"] = result
                if result is None or result["rate_bpm"] is None:
                    info["label"] += "  pulse: collecting" if result is None else "  no pulse found"
                else:
                    info["label"] += f"  pulse {result['rate_bpm']:.1f} bpm (window {result['window_s']:.1f} s)"
        last = frames[-1]
        self._last = max(self._last, last.index)
        self._shown = frames
        info.update(
            frame_index=last.index,
            delay_us=last.delay_us,
            exposure_us=last.exposure_us,
            camera_fps=round(self.capture.fps, 2),
            saturated=int(sum(int(f.saturated.sum()) for f in frames)),
        )
        return np.asarray(image, np.float32), info

    def _pixel(self, row, col, s) -> dict:
        timing = (float(s.delay_us), float(s.exposure_us))
        frames = self.capture.window(PULSE_WINDOW_S, timing=timing)
        t = [f.time_s - frames[-1].time_s for f in frames] if frames else []
        return {
            "kind": "device",
            "row": row,
            "col": col,
            "value": float(frames[-1].image[row, col]) if frames else None,
            "t_s": t,
            "values": [float(f.image[row, col]) for f in frames],
            "timing": list(timing),
        }

    # ------------------------------------------------------------------ snapshot and close
    def snapshot(self, settings: ViewSettings) -> dict:
        """Write what was shown last (a frame, or Eq. 7's cycle) as a native stack; its path and size."""
        with self._lock:
            frames = list(self._shown)
        if not frames:
            raise InputError("nothing shown yet to write")
        out = snapshot_path(self.snapshot_dir, settings.mode)
        path = write_snapshot(
            frames,
            out,
            device=self.description,
            lines_per_second=self.lines_per_second,
            projector_rows=self.projector_rows,
            view=settings.mode,
        )
        return {"path": str(path), "images": len(frames), "delays_us": [f.delay_us for f in frames]}

    def close(self) -> None:
        """Stop the capture and release the device (idempotent)."""
        self._analysis.shutdown(wait=False, cancel_futures=True)
        self.capture.stop()

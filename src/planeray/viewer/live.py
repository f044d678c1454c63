"""What ``planeray view --device NAME`` shows: a device live (no web here; the capture is :mod:`planeray.live`).

:class:`DeviceSource` is the :class:`~planeray.viewer.session.ViewSource` of an open device.  Its
:class:`~planeray.live.LiveCapture` captures continuously; a page's render request sets what is
captured (its delay and exposure: the camera's trigger delay and exposure; a cycle of delays for
Eq. 7's composite) and is answered by the first frame newer than the one the page has, captured at
those settings, in the page's view (:data:`planeray.live.VIEWS`): the band image, the vein view,
Eq. 7's composite, or the frame with the pulse of the rolling window (rate and spectrum).  A
snapshot writes what was shown -- the frame, or the cycle of frames -- as a native stack into the
folder the command line named.

:class:`LiveTransportSource` (``--sweep``) cycles a sweep instead and shows the live transport of its
rolling window (:class:`planeray.live.LiveTransport`): sharpened epipolar, relit, short/long range,
as they update, with the update rate and age.
"""

from __future__ import annotations

import math
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace
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
from .session import MODES, PATTERNS, FrameBuffers, ViewSettings, ViewSource

__all__ = ["DeviceSource", "LiveTransportSource", "MODE_DEFAULTS", "DELAY_REACH_US", "TRANSPORT_MODES"]

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
        return _snapshot(self, settings)

    def close(self) -> None:
        """Stop the capture and release the device (idempotent)."""
        self._analysis.shutdown(wait=False, cancel_futures=True)
        self.capture.stop()


#: The views of a live transport: the captured image nearest the sliders, and the transport's syntheses.
TRANSPORT_MODES = ("band", "epipolar", "non_epipolar", "sharpened", "short_range", "long_range", "relight_row",
                   "relight_pattern")  # fmt: skip


class LiveTransportSource(ViewSource):
    """A device cycling a sweep, its rolling window demultiplexed as images arrive (``view --device NAME --sweep``).

    The capture cycles the sweep's settings (:class:`planeray.live.LiveTransport`); every view but ``band``
    shows the newest transport -- epipolar, non-epipolar, sharpened, short/long range, relit -- rendered as
    :class:`~planeray.viewer.session.TransportSource` renders a transport store, with the update's
    number, the update rate and its age in the label; ``band`` shows the newest captured image of the
    setting nearest the sliders.  A render waits for the next update (or image), so the page shows them as
    they come; a snapshot writes the window of the transport shown as a stack.

    Parameters
    ----------
    device : Device
        An open device; closed by :meth:`close`.
    sweep : Sweep
        The sweep cycled (a design: ``planeray sweep design``).
    name : str
    max_fps : float, optional
        Capture at most this many images a second (a simulated device).
    snapshot_dir : path, optional
    frame_timeout_s : float
        How long a render waits for its update (the first, cold one, may take several seconds).
    alpha, beta : float
        The demultiplexing's weights.
    """

    kind = "device"
    modes = TRANSPORT_MODES
    mode_labels = {**MODES, "band": "captured image (delay, exposure of the sweep)"}

    def __init__(
        self,
        device,
        sweep,
        *,
        name: str,
        max_fps=None,
        snapshot_dir=None,
        frame_timeout_s: float = 30.0,
        alpha: float = 0.01,
        beta: float = 0.01,
    ):
        from ..live import LiveTransport

        description = device.describe()
        super().__init__(name, description["image_shape"])
        self.description = description
        self.lines_per_second = float(device.lines_per_second)
        self.projector_rows = int(description.get("projector_rows") or self.shape[0])
        jitter = float((description.get("sync") or {}).get("jitter_us", 0.0))
        self.capture = LiveCapture(device, history=max(256, 8 * len(sweep)), max_fps=max_fps)
        try:
            self.live = LiveTransport(self.capture, sweep, lines_per_second=self.lines_per_second,
                                      projector_rows=self.projector_rows, jitter_us=jitter, alpha=alpha, beta=beta,
                                      frame_timeout_s=frame_timeout_s)  # fmt: skip
        except BaseException:
            self.capture.stop()
            raise
        self.sweep = self.live.sweep
        self.snapshot_dir = Path(snapshot_dir) if snapshot_dir is not None else Path.cwd()
        self.frame_timeout_s = float(frame_timeout_s)
        self._view = None  # TransportSource of the update shown
        self._view_number = 0
        self._last_frame = -1
        self._shown: list = []
        self._delays = np.unique(self.sweep.delay_us)
        self._exposures = np.unique(self.sweep.exposure_us)

    # ------------------------------------------------------------------ description
    def describe(self) -> dict:
        K = int(np.abs(self.live.solver.offsets_rows).max())
        defaults = ViewSettings(mode="sharpened", delay_us=float(self.sweep.delay_us[0]),
                                exposure_us=float(self.sweep.exposure_us[0]), row=self.projector_rows // 2)  # fmt: skip
        return {
            "kind": "device",
            "live": True,
            "transport": self.live.describe(),
            "name": self.name,
            "shape": list(self.shape),
            "projector_rows": self.projector_rows,
            "lines_per_second": self.lines_per_second,
            "modes": [{"name": m, "label": self.mode_labels[m]} for m in self.modes],
            "mode_defaults": {},
            "delay_us": {"min": float(self._delays[0]), "max": float(self._delays[-1]), "grid": self._delays.tolist()},
            "exposure_us": {
                "min": float(self._exposures[0]),
                "max": float(self._exposures[-1]),
                "grid": self._exposures.tolist(),
            },
            "width_rows": {"min": 0.25, "max": 64.0, "step": 0.25},
            "max_rows": {"min": 1.0, "max": float(K), "step": 1.0},
            "row": {"min": 0, "max": self.projector_rows - 1, "step": 1},
            "patterns": sorted(PATTERNS),
            "toggles": [],
            "has_truth": False,
            "truth_scale": None,
            "units": "camera (normalized: 0 = black level, 1 = top code)",
            "epipolar_resolution_rows": self.live.solver.problem.epipolar_resolution_rows,
            "device": self.description,
            "defaults": defaults.to_dict(),
        }

    def check(self, settings: ViewSettings) -> ViewSettings:
        settings = super().check(settings)
        if settings.mode != "band":
            if self._view is not None:
                settings = self._view.check(settings)
            elif settings.mode == "relight_row" and settings.row is None:
                settings = replace(settings, row=self.projector_rows // 2)
        return settings

    # ------------------------------------------------------------------ capture and transport
    def warm(self) -> None:
        """Start the capture and the demultiplexing, and wait for the first transport (a cold solve)."""
        self.live.start()
        update = self.live.wait_update(timeout_s=max(self.frame_timeout_s, 120.0))
        self._adopt(update)

    def _adopt(self, update) -> None:
        """Show ``update``'s transport from now on (a new TransportSource: prefix sums of Eqs. 5-6)."""
        from .session import TransportSource

        if update.number != self._view_number:
            self._view = TransportSource(update.transport, name=self.name, lines_per_second=self.lines_per_second,
                                         attrs={"epipolar_resolution_rows": self.live.solver.problem.epipolar_resolution_rows})  # fmt: skip
            self._view_number = update.number
            self._update = update

    def _nearest(self, delay_us: float, exposure_us: float) -> tuple[float, float]:
        """The sweep's setting nearest to (delay, exposure): the nearest exposure, then the nearest delay at it."""
        e = float(self._exposures[np.argmin(np.abs(self._exposures - exposure_us))])
        at = self.sweep.delay_us[self.sweep.exposure_us == e]
        return float(at[np.argmin(np.abs(at - delay_us))]), e

    def _render(self, s: ViewSettings, buffers):
        if s.mode == "band":
            timing = self._nearest(s.delay_us, s.exposure_us)
            frame = self.capture.wait_frame(self._last_frame, timing=timing,
                                            timeout_s=self.frame_timeout_s)  # fmt: skip
            self._last_frame = max(self._last_frame, frame.index)
            self._shown = [frame]
            info = {
                "label": f"captured  t_d {timing[0]:g} us  t_e {timing[1]:g} us  (the sweep's setting nearest the sliders)",
                "frame_index": frame.index,
                "delay_us": frame.delay_us,
                "exposure_us": frame.exposure_us,
                "saturated": int(frame.saturated.sum()),
                "camera_fps": round(self.capture.fps, 2),
            }
            return np.asarray(frame.image, np.float32), info
        update = self.live.wait_update(self._view_number, timeout_s=self.frame_timeout_s)
        self._adopt(update)
        image, info = self._view._render(s, buffers)
        self._shown = list(update.frames)
        rate = self.live.rate_hz
        info["label"] = (
            f"{info['label']}  |  live transport #{update.number}: {rate:.1f} updates/s, age {update.age_s():.2f} s, "
            f"{float(update.maps['iterations'].mean()):.0f} iterations{' (warm)' if update.warm else ''}"
        )
        info.update(
            transport_number=update.number,
            update_rate_hz=round(rate, 3),
            age_s=round(update.age_s(), 3),
            solve_s=round(update.seconds, 3),
            window_span_s=round(update.window_span_s, 3),
            converged=float(update.maps["converged"].mean()),
            camera_fps=round(self.capture.fps, 2),
        )
        return image, info

    def _pixel(self, row, col, s) -> dict:
        if self._view is None:
            raise InputError("no transport yet")
        data = self._view._pixel(row, col, replace(s, mode="sharpened") if s.mode == "band" else s)
        data["live_transport"] = self._view_number
        return data

    # ------------------------------------------------------------------ snapshot and close
    def snapshot(self, settings: ViewSettings) -> dict:
        """Write the window of the transport shown (or the image shown) as a native stack; its path and size.

        Every image of the window is used (the sweep's excluded images are not captured)."""
        return _snapshot(self, settings, all_used=True)

    def close(self) -> None:
        """Stop the demultiplexing and the capture, and release the device (idempotent)."""
        try:
            self.live.stop()
        finally:
            self.capture.stop()


def _snapshot(source, settings: ViewSettings, *, all_used: bool = False) -> dict:
    """Write the frames a live source showed last as a native stack in its snapshot folder; its path and size."""
    with source._lock:
        frames = list(source._shown)
    if not frames:
        raise InputError("nothing shown yet to write")
    path = write_snapshot(
        frames,
        snapshot_path(source.snapshot_dir, settings.mode),
        device=source.description,
        lines_per_second=source.lines_per_second,
        projector_rows=source.projector_rows,
        view=settings.mode,
        excluded=np.zeros(len(frames), bool) if all_used else None,
    )
    return {"path": str(path), "images": len(frames), "delays_us": [f.delay_us for f in frames]}

"""A device captured continuously in a thread of its own: the frames, their timing, and what to capture next.

:class:`LiveCapture` owns an open device (:mod:`planeray.devices`).  Its thread grabs one image after
another at the timing it was last given -- one delay and exposure (:meth:`LiveCapture.set_timing`), a
cycle of delays at one exposure (:meth:`LiveCapture.set_cycle`, Eq. 7's set) or a sweep's settings
(:meth:`LiveCapture.set_sweep`, a live transport's window) -- and keeps the recent
frames (:class:`Frame`), each with the timing it was captured at, its index and its time on the
device's clock (the camera's own time stamps where it has them, :mod:`planeray.devices.capabilities`).
Readers wait for a frame newer than the one they have (:meth:`LiveCapture.wait_frame`), take the
frames of a rolling window (:meth:`LiveCapture.window`), the latest complete cycle
(:meth:`LiveCapture.latest_cycle`) or the newest frame of each of a sweep's settings
(:meth:`LiveCapture.latest_sweep`).  A device error ends the thread, is kept, and is raised to every
reader as the one line it is; the device is closed when the thread ends, however it ends.

Nothing here knows about a browser: the explorer (:mod:`planeray.viewer`) and any other front end
(a live transport, a recorder) read frames the same way.
"""

from __future__ import annotations

import collections
import math
import threading
import time
from dataclasses import dataclass

import numpy as np

from ..devices.base import apply_timing
from ..devices.capabilities import has
from ..errors import DeviceError, InputError, PlanerayError

__all__ = ["Frame", "LiveCapture"]


def wait_on(cond: threading.Condition, found, check, timeout_s: float, what: str):
    """Wait on ``cond`` (held by the caller) until ``found()`` returns something, and return it.

    ``check()`` raises when waiting is pointless (the capture stopped on an error); after ``timeout_s``
    a DeviceError says what was waited for: ``"{what} within {timeout_s} s"``.
    """
    deadline = time.monotonic() + timeout_s
    while True:
        value = found()
        if value is not None:
            return value
        check()
        left = deadline - time.monotonic()
        if left <= 0:
            raise DeviceError(f"{what} within {timeout_s:g} s")
        cond.wait(left)


@dataclass(frozen=True)
class Frame:
    """One captured image and how it was captured.

    Attributes
    ----------
    index : int
        Running number of the frame in this capture (0, 1, 2, ...).
    image : ndarray (H, W) float32
        The device's normalized image.
    saturated : ndarray (H, W) bool
    delay_us, exposure_us : float
        The timing it was captured at.
    time_s : float
        Its time on the device's clock (the mean of its frames' time stamps), or the host's
        monotonic clock for a device without time stamps.
    captured_at : float
        The host's monotonic time when it was ready.
    generation : int
        The timing request it answers (a new :meth:`LiveCapture.set_timing` or ``set_cycle`` starts
        a new generation).

    See Also
    --------
    LiveCapture : produces them.

    Examples
    --------
    >>> import numpy as np
    >>> import planeray as pr
    >>> from planeray.live import Frame
    >>> stack = pr.simulate_stack(pr.make_scene("wax", (8, 8), seed=0), pr.quick_sweep(), seed=0)
    >>> frames = [
    ...     Frame(
    ...         i,
    ...         stack.images[i],
    ...         stack.saturated[i],
    ...         float(stack.delay_us[i]),
    ...         float(stack.exposure_us[i]),
    ...         time_s=i / 30,
    ...         captured_at=i / 30,
    ...         generation=0,
    ...     )
    ...     for i in range(len(stack))
    ... ]
    >>> frames[4].delay_us, frames[4].exposure_us, frames[4].image.shape
    (0.0, 600.0, (8, 8))
    """

    index: int
    image: np.ndarray
    saturated: np.ndarray
    delay_us: float
    exposure_us: float
    time_s: float
    captured_at: float
    generation: int


class LiveCapture:
    """Capture a device continuously in a background thread.

    Parameters
    ----------
    device : Device
        An open device; closed when the capture stops (``close_device``).
    delay_us, exposure_us : float
        The first timing.
    history : int
        Frames kept (the pulse window needs ``seconds x frame rate`` of them).
    max_fps : float, optional
        Capture at most this many frames a second (a simulated device would otherwise take every
        core it gets; a camera is paced by its trigger).
    close_device : bool
        Close the device when the capture stops.

    See Also
    --------
    LiveTransport : demultiplexes its frames.

    Examples
    --------
    >>> from planeray.devices import open_device
    >>> with LiveCapture(open_device("sim", scene="diffuse_plane", size=(8, 8), frames_averaged=1)) as live:
    ...     frame = live.wait_frame(timeout_s=30)
    >>> frame.image.shape, frame.delay_us
    ((8, 8), 0.0)
    """

    def __init__(
        self,
        device,
        *,
        delay_us: float = 0.0,
        exposure_us: float = 600.0,
        history: int = 1024,
        max_fps: float | None = None,
        close_device: bool = True,
    ):
        if int(history) < 2:
            raise InputError(f"history must be at least 2 frames, got {history!r}")
        if max_fps is not None and not (math.isfinite(max_fps) and max_fps > 0):
            raise InputError(f"max_fps must be positive, got {max_fps!r}")
        self.device = device
        self.max_fps = None if max_fps is None else float(max_fps)
        self.close_device = bool(close_device)
        self._frames: collections.deque[Frame] = collections.deque(maxlen=int(history))
        self._cond = threading.Condition()
        self._target = ((float(delay_us),), float(exposure_us))
        self._generation = 0
        self._cycle_pos = 0
        self._count = 0
        self._stop = False
        self._error: BaseException | None = None
        self._thread: threading.Thread | None = None
        self._ready_times: collections.deque[float] = collections.deque(maxlen=256)
        self.shape = tuple(int(n) for n in device.describe().get("image_shape", ()))

    # ------------------------------------------------------------------ what to capture
    def set_timing(self, delay_us: float, exposure_us: float) -> None:
        """Capture at one delay and exposure from the next frame on (nothing changes if they are the same)."""
        self._set(((float(delay_us),), float(exposure_us)))

    def set_cycle(self, delays_us, exposure_us: float) -> None:
        """Capture a cycle of delays at one exposure, one frame each, round and round (Eq. 7's set)."""
        delays = tuple(float(d) for d in delays_us)
        if not delays:
            raise InputError("a cycle needs at least one delay")
        self._set((delays, float(exposure_us)))

    def set_sweep(self, delays_us, exposures_us) -> None:
        """Capture a sweep's settings, one frame each, round and round (a live transport's window).

        ``delays_us`` and ``exposures_us`` pair up; the target is then ``(delays, exposures)``, both tuples.
        """
        delays = tuple(float(d) for d in delays_us)
        exposures = tuple(float(e) for e in exposures_us)
        if not delays or len(delays) != len(exposures):
            raise InputError(
                f"a sweep needs one exposure per delay, got {len(delays)} delays, {len(exposures)} exposures"
            )
        self._set((delays, exposures))

    def _set(self, target) -> None:
        with self._cond:
            if target != self._target:
                self._target = target
                self._generation += 1
                self._cycle_pos = 0
                self._cond.notify_all()

    @property
    def target(self) -> tuple[tuple[float, ...], float | tuple[float, ...]]:
        """``(delays_us, exposure_us)`` being captured (a sweep: ``(delays_us, exposures_us)``)."""
        return self._target

    @property
    def generation(self) -> int:
        """The number of the current target (each new :meth:`set_timing` or :meth:`set_cycle` adds one)."""
        return self._generation

    # ------------------------------------------------------------------ the thread
    def start(self) -> LiveCapture:
        """Start capturing (idempotent)."""
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name="planeray-live-capture", daemon=True)
            self._thread.start()
        return self

    def _run(self) -> None:
        try:
            while True:
                with self._cond:
                    if self._stop:
                        return
                    delays, exposure = self._target
                    generation = self._generation
                    delay = delays[self._cycle_pos % len(delays)]
                    if isinstance(exposure, tuple):  # a sweep: one exposure per delay
                        exposure = exposure[self._cycle_pos % len(delays)]
                    self._cycle_pos += 1
                t0 = time.monotonic()
                apply_timing(self.device, delay, exposure)
                image, saturated = self.device.grab()
                now = time.monotonic()
                stamps = np.asarray(self.device.frame_times_s(), float) if has(self.device, "frame_times") else ()
                clock = float(np.mean(stamps)) if len(stamps) else now
                with self._cond:
                    frame = Frame(
                        self._count,
                        np.asarray(image, np.float32),
                        np.asarray(saturated, bool),
                        float(delay),
                        float(exposure),
                        clock,
                        now,
                        generation,
                    )
                    self._count += 1
                    self._frames.append(frame)
                    self._ready_times.append(now)
                    self._cond.notify_all()
                if self.max_fps is not None:
                    rest = 1.0 / self.max_fps - (time.monotonic() - t0)
                    if rest > 0:
                        with self._cond:
                            self._cond.wait_for(lambda: self._stop, timeout=rest)
        except BaseException as exc:  # kept for the readers: a camera error is their error
            with self._cond:
                self._error = exc
                self._cond.notify_all()
        finally:
            if self.close_device:
                close = getattr(self.device, "close", None)
                if close is not None:
                    close()

    def stop(self, timeout_s: float = 10.0) -> None:
        """Stop capturing and close the device (idempotent); waits up to ``timeout_s`` for the frame in flight."""
        with self._cond:
            self._stop = True
            self._cond.notify_all()
        if self._thread is not None:
            self._thread.join(timeout_s)
            if self._thread.is_alive():
                raise DeviceError(f"the capture did not stop within {timeout_s:g} s (a grab still waits for its frame)")
        elif self.close_device:
            close = getattr(self.device, "close", None)
            if close is not None:
                close()

    def __enter__(self) -> LiveCapture:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    # ------------------------------------------------------------------ reading frames
    @property
    def error(self) -> BaseException | None:
        """What ended the capture, if something did."""
        return self._error

    def _raise(self) -> None:
        if self._error is not None:
            if isinstance(self._error, PlanerayError):
                raise DeviceError(f"the capture stopped: {self._error}")
            raise DeviceError(f"the capture stopped: {type(self._error).__name__}: {self._error}")
        if self._stop:
            raise DeviceError("the capture was stopped")

    def wait_frame(
        self,
        after: int = -1,
        *,
        timing: tuple[float, float] | None = None,
        generation: int | None = None,
        timeout_s: float = 5.0,
    ) -> Frame:
        """The newest frame with an index above ``after``: captured at ``timing``, or in ``generation`` or a later
        one (what a live view wants: its own timing, or a newer one it was already asked for), when given.

        Raises DeviceError saying what it waited for when none comes within ``timeout_s``, or the
        device's own error when the capture stopped on one.
        """
        self.start()

        def found():
            for frame in reversed(self._frames):
                if frame.index <= after:
                    return None
                if generation is not None and frame.generation >= generation:
                    return frame
                if (timing is None and generation is None) or (frame.delay_us, frame.exposure_us) == timing:
                    return frame
            return None

        what = "" if timing is None else f" at delay {timing[0]:g} us, exposure {timing[1]:g} us"
        with self._cond:
            return wait_on(self._cond, found, self._raise, timeout_s, f"no frame{what} from the device")

    def window(self, seconds: float, *, timing: tuple[float, float] | None = None) -> list[Frame]:
        """The latest run of consecutive frames (one timing, nothing else between) spanning up to ``seconds``."""
        with self._cond:
            frames = list(self._frames)
        run: list[Frame] = []
        for frame in reversed(frames):
            key = (frame.delay_us, frame.exposure_us)
            if timing is not None and key != timing:
                break
            if run and (key != (run[-1].delay_us, run[-1].exposure_us) or frame.index != run[-1].index - 1):
                break
            if run and run[0].time_s - frame.time_s > seconds:
                break
            run.append(frame)
        return run[::-1]

    def latest_cycle(self, delays_us, exposure_us: float, *, after: int = -1) -> list[Frame] | None:
        """The newest frame of each delay of a cycle (in the cycle's order), if every one is newer than ``after``."""
        want = [float(d) for d in delays_us]
        with self._cond:
            frames = list(self._frames)
        got: dict[float, Frame] = {}
        for frame in reversed(frames):
            if frame.exposure_us == float(exposure_us) and frame.delay_us in want and frame.delay_us not in got:
                got[frame.delay_us] = frame
            if len(got) == len(want):
                break
        if len(got) < len(want) or min(f.index for f in got.values()) <= after:
            return None
        return [got[d] for d in want]

    def latest_sweep(self, delays_us, exposures_us) -> list[Frame] | None:
        """The newest frame of every setting of a sweep, in the sweep's order; None while one is missing."""
        want = list(zip((float(d) for d in delays_us), (float(e) for e in exposures_us)))
        with self._cond:
            frames = list(self._frames)
        got: dict[tuple[float, float], Frame] = {}
        wanted = set(want)
        for frame in reversed(frames):
            key = (frame.delay_us, frame.exposure_us)
            if key in wanted and key not in got:
                got[key] = frame
                if len(got) == len(wanted):
                    break
        if len(got) < len(wanted):
            return None
        return [got[k] for k in want]

    def wait_sweep(self, delays_us, exposures_us, *, after: int = -1, timeout_s: float = 10.0) -> list[Frame]:
        """Wait for a complete window of a sweep (:meth:`latest_sweep`) holding a frame newer than ``after``."""
        self.start()

        def found():
            window = self.latest_sweep(delays_us, exposures_us)
            return window if window is not None and max(f.index for f in window) > after else None

        what = f"no new frame of the {len(list(delays_us))} settings of the sweep from the device"
        with self._cond:
            return wait_on(self._cond, found, self._raise, timeout_s, what)

    def wait_cycle(self, delays_us, exposure_us: float, *, after: int = -1, timeout_s: float = 10.0) -> list[Frame]:
        """Wait for a complete cycle whose every frame is newer than ``after`` (see :meth:`latest_cycle`)."""
        self.start()
        what = f"no complete cycle of {len(list(delays_us))} delays from the device"
        with self._cond:
            return wait_on(
                self._cond, lambda: self.latest_cycle(delays_us, exposure_us, after=after), self._raise, timeout_s, what
            )

    @property
    def fps(self) -> float:
        """Frames captured per second over the last second (host clock)."""
        with self._cond:
            times = list(self._ready_times)
        if len(times) < 2:
            return 0.0
        now = time.monotonic()
        recent = [t for t in times if t >= now - 1.0]
        if len(recent) >= 2:
            return (len(recent) - 1) / max(recent[-1] - recent[0], 1e-9)
        return 0.0

    @property
    def frames_captured(self) -> int:
        return self._count

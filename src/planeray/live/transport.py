"""A live transport: a device cycles a sweep, and the latest image of each setting is demultiplexed as it comes.

The paper's transport is a still (Sec. 11: 80-100 images, minutes to demultiplex).  With a short
designed sweep (:mod:`planeray.design`: 24 images that determine the transport about as well as the
paper's 85) a device can capture it round and round (:meth:`LiveCapture.set_sweep`), and the
**rolling window** -- the newest image of every setting -- is a complete stack at every new frame.
:class:`WindowSolver` demultiplexes a window with the default solver (:mod:`planeray.demux.fast`) on
the problem of the sweep, built once, **warm-started** from the previous window's end state of
every pixel (:class:`~planeray.demux.fast.WarmStart`): after one new image most pixels are certified
after a few iterations instead of ~50.  The certificate is the same as a cold solve's, so a live
transport equals an offline ``planeray demux`` of the same images to the solver's certified accuracy
(a relative objective gap ``<= tol`` for both, hence ``||x_live - x_offline||_Q <= sqrt(2 gap_live)
+ sqrt(2 gap_offline)``; ``tests/test_live_transport.py``).

:class:`LiveTransport` runs it in a thread of its own over a :class:`~planeray.live.capture.LiveCapture`
and keeps the latest :class:`LiveUpdate` (the transport, its window, when it was solved, how long it
took), its update rate and age; the explorer (``planeray view --device NAME --sweep sweep.json``)
shows its sharpened epipolar, relit and short/long-range images as they update.
"""

from __future__ import annotations

import collections
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from ..demux.fast import DEFAULT_TOL, WarmStart, blas_one_thread, row_solver, solver_threads
from ..demux.problem import DemuxProblem
from ..errors import DeviceError, InputError, PlanerayError
from ..stack import Stack
from ..timing import RowGeometry, Sweep
from ..transport import Transport
from .capture import wait_on

__all__ = ["WindowSolver", "LiveTransport", "LiveUpdate", "window_stack"]

#: Pixels per solver task (a batch of the fast solver).
_TASK_PIXELS = 512


def _used(sweep: Sweep) -> Sweep:
    """The sweep without its excluded images (a live capture cycles only what is demultiplexed)."""
    keep = ~np.asarray(sweep.excluded, bool)
    if keep.sum() < 4:
        raise InputError(f"sweep {sweep.name!r} has {int(keep.sum())} usable images; a live transport needs at least 4")
    return Sweep(sweep.delay_us[keep], sweep.exposure_us[keep], np.zeros(int(keep.sum()), bool), name=sweep.name,
                 record=sweep.record)  # fmt: skip


def window_stack(frames, *, lines_per_second: float, projector_rows: int, jitter_us: float = 0.0, metadata=None):
    """The frames of a window as a :class:`~planeray.stack.Stack` (one image per frame, in order, all used):
    what an offline ``planeray demux`` of the same images reads.

    Parameters
    ----------
    frames : sequence of Frame
        A window of frames.
    lines_per_second : float
        Projector scan rate, rows per second.
    projector_rows : int
        Projector rows spanned by the image height.
    jitter_us : float
        Synchronization jitter, microseconds (recorded).
    metadata : dict, optional
        More of the record.

    Returns
    -------
    Stack

    See Also
    --------
    WindowSolver : solves a window.

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
    >>> window = window_stack(frames, lines_per_second=54000.0, projector_rows=8)
    >>> window.images.shape, int(window.excluded.sum())  # every frame of a window is used
    ((27, 8, 8), 0)
    """
    frames = list(frames)
    meta = {"sync": {"jitter_us": float(jitter_us), "line_width_us": 0.0}} | dict(metadata or {})
    return Stack(
        np.stack([f.image for f in frames]).astype(np.float32),
        np.array([f.delay_us for f in frames]),
        np.array([f.exposure_us for f in frames]),
        float(lines_per_second),
        excluded=np.zeros(len(frames), bool),
        saturated=np.stack([f.saturated for f in frames]),
        projector_rows=int(projector_rows),
        metadata=meta,
    )


class WindowSolver:
    """Demultiplexes windows of one sweep (images in the sweep's order), each pixel warm-started from the last.

    Parameters
    ----------
    sweep : Sweep
        The sweep (its excluded images are left out).
    shape : (int, int)
        Image size ``(H, W)``.
    lines_per_second : float
    projector_rows : int
    jitter_us : float
        The synchronization jitter of the illumination model (the device's).
    alpha, beta : float
        The weights of Eq. 6 (the paper's problem).
    tol : float, optional
        Certified relative objective gap (the fast solver's default, 1e-4).
    threads : int, optional
        Solver threads (default: Numba's count, at most two).

    See Also
    --------
    planeray.demultiplex : the offline solve.

    References
    ----------
    .. [1] H. Kubo, S. Jayasuriya, T. Iwaguchi, T. Funatomi, Y. Mukaigawa, S. G. Narasimhan,
       "Programmable Non-Epipolar Indirect Light Transport: Capture and Analysis",
       IEEE TVCG 27(4), 2019, doi:10.1109/TVCG.2019.2946812, Sec. 4.

    Examples
    --------
    >>> import numpy as np
    >>> import planeray as pr
    >>> stack = pr.simulate_stack(pr.make_scene("wax", (8, 8), seed=0), pr.quick_sweep(), seed=0)
    >>> sweep = pr.quick_sweep()
    >>> solver = WindowSolver(sweep, (8, 8), lines_per_second=54000.0, projector_rows=8)
    >>> used = ~sweep.excluded
    >>> T, maps = solver.solve(stack.images[used])
    >>> T.dense.shape, bool(maps["converged"].all())
    ((8, 8, 229), True)
    >>> T, maps = solver.solve(stack.images[used])  # the next window starts warm
    >>> int(maps["iterations"].max()) <= 10
    True
    """

    def __init__(
        self,
        sweep: Sweep,
        shape,
        *,
        lines_per_second: float,
        projector_rows: int,
        jitter_us: float = 0.0,
        alpha: float = 0.01,
        beta: float = 0.01,
        tol: float | None = None,
        threads: int | None = None,
    ):
        self.sweep = _used(sweep)
        self.shape = (int(shape[0]), int(shape[1]))
        self.lines_per_second = float(lines_per_second)
        self.projector_rows = int(projector_rows)
        self.jitter_us = float(jitter_us)
        self.tol = DEFAULT_TOL if tol is None else float(tol)
        self.threads = solver_threads() if threads is None else max(1, int(threads))
        H, W = self.shape
        n = len(self.sweep)
        template = Stack(np.zeros((n, H, W), np.float32), self.sweep.delay_us, self.sweep.exposure_us,
                         self.lines_per_second, excluded=self.sweep.excluded, projector_rows=self.projector_rows,
                         metadata={"sync": {"jitter_us": self.jitter_us, "line_width_us": 0.0}})  # fmt: skip
        self.problem = DemuxProblem.from_stack(template, alpha=alpha, beta=beta)
        self._tasks = []
        for group in self.problem.groups:
            pixels = group.rows.size * W
            for s in range(0, pixels, _TASK_PIXELS):
                self._tasks.append((group, slice(s, min(s + _TASK_PIXELS, pixels))))
        self._state = {id(g): WarmStart.empty(g.rows.size * W, g.A.shape[1]) for g in self.problem.groups}
        self.solves = 0

    @property
    def offsets_rows(self) -> np.ndarray:
        return self.problem.offsets_rows

    def reset(self) -> None:
        """Forget the warm starts (the next window is solved cold)."""
        for state in self._state.values():
            state.V[...] = 0.0
            state.level[...] = 0
        self.solves = 0

    def solve(self, images, saturated=None, *, warm: bool = True) -> tuple[Transport, dict]:
        """The transport of one window.

        Parameters
        ----------
        images : ndarray (K, H, W)
            The window's images, in the sweep's order (its used images).
        saturated : ndarray (K, H, W) bool, optional
            Saturated observations (dropped from their pixel's fit).
        warm : bool
            Start each pixel from its state after the previous window (the first window is cold).

        Returns
        -------
        transport : Transport
        maps : dict of (H, W) arrays
            ``converged``, ``iterations``, ``objective`` and ``gap`` (the certified bound on each
            pixel's absolute objective gap).
        """
        images = np.asarray(images, np.float64)
        K, H, W = images.shape
        if K != len(self.sweep) or (H, W) != self.shape:
            raise InputError(f"a window of {K} images of {H}x{W}; the sweep has {len(self.sweep)}, images {self.shape}")
        use_warm = warm and self.solves > 0
        alpha, beta = self.problem.alpha, self.problem.beta
        # (pixels of each group's rows, row-major) x images
        obs = {}
        masks = {}
        for group in self.problem.groups:
            obs[id(group)] = images[:, group.rows, :].reshape(K, -1).T
            if saturated is not None:
                m = ~np.asarray(saturated, bool)[:, group.rows, :].reshape(K, -1).T
                masks[id(group)] = None if m.all() else m
            else:
                masks[id(group)] = None

        def run(task):
            group, sl = task
            solver = row_solver(group, alpha, beta)
            state = self._state[id(group)][sl]
            mask = masks[id(group)]
            return solver.solve(
                obs[id(group)][sl],
                self.tol,
                mask=None if mask is None else mask[sl],
                start=state if use_warm else None,
                state=state,
            )

        with blas_one_thread():
            if self.threads > 1 and len(self._tasks) > 1:
                with ThreadPoolExecutor(self.threads, thread_name_prefix="planeray-live-demux") as pool:
                    results = list(pool.map(run, self._tasks))
            else:
                results = [run(t) for t in self._tasks]
        U = self.problem.n_offsets
        T = np.zeros((H, W, U), np.float32)
        maps = {
            "converged": np.zeros((H, W), bool),
            "iterations": np.zeros((H, W), np.int32),
            "objective": np.zeros((H, W)),
            "gap": np.zeros((H, W)),
        }
        flatT = T.reshape(H * W, U)
        flat = {k: v.reshape(H * W) for k, v in maps.items()}
        for (group, sl), (X, iters, conv, rel_gap, f, _kkt, _rss) in zip(self._tasks, results):
            where = (group.rows[:, None] * W + np.arange(W)[None, :]).reshape(-1)[sl]
            flatT[where, group.valid] = group.transport(X)
            flat["converged"][where] = conv
            flat["iterations"][where] = iters
            flat["objective"][where] = f
            flat["gap"][where] = rel_gap * np.maximum(f, 0.0) / (1.0 + rel_gap)
        self.solves += 1
        return Transport(T, self.problem.offsets_rows, RowGeometry(H, self.projector_rows)), maps


@dataclass(frozen=True)
class LiveUpdate:
    """One update of a live transport.

    Attributes
    ----------
    number : int
        Its running number (1, 2, ...).
    transport : Transport
    maps : dict
        ``converged``, ``iterations``, ``objective``, ``gap`` (see :meth:`WindowSolver.solve`).
    frames : list of Frame
        The window it was demultiplexed from (in the sweep's order).
    solved_at : float
        Host monotonic time when it was ready.
    seconds : float
        Wall time of its solve.
    warm : bool
        Whether it was warm-started.

    See Also
    --------
    LiveTransport : its updates.

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
    >>> solver = WindowSolver(pr.quick_sweep(), (8, 8), lines_per_second=54000.0, projector_rows=8)
    >>> used = [f for f, x in zip(frames, pr.quick_sweep().excluded) if not x]
    >>> T, maps = solver.solve(np.stack([f.image for f in used]))
    >>> update = LiveUpdate(1, T, maps, used, solved_at=0.0, seconds=0.1, warm=False)
    >>> update.number, update.transport.dense.shape
    (1, (8, 8, 229))
    """

    number: int
    transport: Transport
    maps: dict
    frames: list
    solved_at: float
    seconds: float
    warm: bool

    @property
    def newest_captured_at(self) -> float:
        return max(f.captured_at for f in self.frames)

    @property
    def window_span_s(self) -> float:
        """Host seconds between the window's oldest and newest frame."""
        return self.newest_captured_at - min(f.captured_at for f in self.frames)

    def age_s(self, now: float | None = None) -> float:
        """How old the newest image it holds is, now (host seconds)."""
        return (time.monotonic() if now is None else now) - self.newest_captured_at


class LiveTransport:
    """Demultiplex a device's rolling window of a sweep in a thread of its own, as images arrive.

    Parameters
    ----------
    capture : LiveCapture
        The device's capture; pointed at the sweep (:meth:`LiveCapture.set_sweep`) when started.
    sweep : Sweep
    lines_per_second, projector_rows : float, int
        The rig (Eq. 2; the image height's projector rows).
    jitter_us : float
        The synchronization jitter of the illumination model.
    alpha, beta, tol, threads :
        As :class:`WindowSolver`.
    warm : bool
        Warm-start each window from the last (False: every window cold, for comparison).
    frame_timeout_s : float
        How long to wait for a new frame before the loop reports the device stalled.

    See Also
    --------
    WindowSolver : the solver it runs.

    Examples
    --------
    >>> from planeray.devices import open_device
    >>> from planeray.live import LiveCapture
    >>> from planeray.timing import quick_sweep
    >>> dev = open_device("sim", scene="wax", size=(16, 16), projector_rows=90, frames_averaged=1)
    >>> with LiveTransport(
    ...     LiveCapture(dev),
    ...     quick_sweep(),
    ...     lines_per_second=dev.lines_per_second,
    ...     projector_rows=90,
    ...     jitter_us=dev.camera.jitter_us,
    ... ) as live:
    ...     update = live.wait_update(timeout_s=60)
    >>> update.transport.shape, bool(update.maps["converged"].all())
    ((16, 16), True)
    """

    def __init__(
        self,
        capture,
        sweep: Sweep,
        *,
        lines_per_second: float,
        projector_rows: int,
        jitter_us: float = 0.0,
        alpha: float = 0.01,
        beta: float = 0.01,
        tol: float | None = None,
        threads: int | None = None,
        warm: bool = True,
        frame_timeout_s: float = 30.0,
    ):
        self.capture = capture
        shape = capture.shape
        if len(shape) != 2:
            raise InputError("the device does not describe its image shape")
        self.solver = WindowSolver(sweep, shape, lines_per_second=lines_per_second, projector_rows=projector_rows,
                                   jitter_us=jitter_us, alpha=alpha, beta=beta, tol=tol, threads=threads)  # fmt: skip
        self.sweep = self.solver.sweep
        self.warm = bool(warm)
        self.frame_timeout_s = float(frame_timeout_s)
        self._cond = threading.Condition()
        self._latest: LiveUpdate | None = None
        self._times: collections.deque[float] = collections.deque(maxlen=32)
        self._stop = False
        self._error: BaseException | None = None
        self._thread: threading.Thread | None = None

    # ------------------------------------------------------------------ running
    def start(self) -> LiveTransport:
        """Point the capture at the sweep and start demultiplexing (idempotent)."""
        if self._thread is None:
            self.capture.set_sweep(self.sweep.delay_us, self.sweep.exposure_us)
            self.capture.start()
            self._thread = threading.Thread(target=self._run, name="planeray-live-transport", daemon=True)
            self._thread.start()
        return self

    def _run(self) -> None:
        last = -1
        number = 0
        try:
            while True:
                with self._cond:
                    if self._stop:
                        return
                frames = self.capture.wait_sweep(self.sweep.delay_us, self.sweep.exposure_us, after=last,
                                                 timeout_s=self.frame_timeout_s)  # fmt: skip
                with self._cond:
                    if self._stop:
                        return
                images = np.stack([f.image for f in frames])
                saturated = np.stack([f.saturated for f in frames])
                t0 = time.monotonic()
                warm = self.warm and self.solver.solves > 0
                transport, maps = self.solver.solve(images, saturated if saturated.any() else None, warm=self.warm)
                now = time.monotonic()
                number += 1
                update = LiveUpdate(number, transport, maps, frames, now, now - t0, warm)
                last = max(f.index for f in frames)
                with self._cond:
                    self._latest = update
                    self._times.append(now)
                    self._cond.notify_all()
        except BaseException as exc:  # kept for the readers
            with self._cond:
                self._error = exc
                self._cond.notify_all()

    def stop(self, timeout_s: float = 30.0) -> None:
        """Stop demultiplexing (the capture is the caller's to stop); waits for the solve in flight."""
        with self._cond:
            self._stop = True
            self._cond.notify_all()
        if self._thread is not None:
            self._thread.join(timeout_s)
            if self._thread.is_alive():
                raise DeviceError(f"the live transport did not stop within {timeout_s:g} s (a solve still runs)")

    def __enter__(self) -> LiveTransport:
        return self.start()

    def __exit__(self, *exc) -> None:
        try:
            self.stop()
        finally:
            self.capture.stop()

    # ------------------------------------------------------------------ reading
    def _raise(self) -> None:
        if self._error is not None:
            if isinstance(self._error, PlanerayError):
                raise DeviceError(f"the live transport stopped: {self._error}")
            raise DeviceError(f"the live transport stopped: {type(self._error).__name__}: {self._error}")

    @property
    def latest(self) -> LiveUpdate | None:
        """The newest update (None before the first)."""
        with self._cond:
            self._raise()
            return self._latest

    def wait_update(self, after: int = 0, *, timeout_s: float = 10.0) -> LiveUpdate:
        """The newest update numbered above ``after``; DeviceError saying what it waited for after ``timeout_s``."""
        self.start()

        def found():
            self._raise()
            return self._latest if self._latest is not None and self._latest.number > after else None

        what = f"no update of the live transport (a window of {len(self.sweep)} images)"
        with self._cond:
            return wait_on(self._cond, found, self._raise, timeout_s, what)

    @property
    def rate_hz(self) -> float:
        """Updates per second over the last (up to 32) updates within the last 5 seconds (host clock)."""
        with self._cond:
            times = list(self._times)
        now = time.monotonic()
        recent = [t for t in times if t >= now - 5.0]
        if len(recent) < 2:
            return 0.0
        return (len(recent) - 1) / max(recent[-1] - recent[0], 1e-9)

    def describe(self) -> dict:
        """What is demultiplexed (JSON)."""
        p = self.solver.problem
        return {
            "sweep": self.sweep.name,
            "images": len(self.sweep),
            "offsets_rows": [int(p.offsets_rows[0]), int(p.offsets_rows[-1])],
            "alpha": p.alpha,
            "beta": p.beta,
            "tol": self.solver.tol,
            "warm": self.warm,
            "epipolar_resolution_rows": p.epipolar_resolution_rows,
        }

"""The delay-exposure stack: the interface between capture and analysis.

A :class:`Stack` is what every device, simulator and import produces and what
every later stage (demultiplexing, profiles, figures) consumes.  Images are
float32 and normalized so that 0 is the black level and 1 the largest code of the
ADC; read noise can take dark pixels slightly below 0, which is kept on purpose
(clipping would bias dark pixels).
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field

import numpy as np

from .errors import StackError
from .timing import RowGeometry, Sweep, boundary_images

__all__ = ["Stack", "recorded_mm_per_row"]


@dataclass
class Stack:
    """Images of a delay-exposure sweep with everything needed to interpret them.

    Parameters
    ----------
    images : array_like, shape (N, H, W)
        Normalized images (float32); may be a lazily read Zarr array.
    delay_us, exposure_us : ndarray, shape (N,)
        Delay ``t_d`` and exposure ``t_e`` of each image, in microseconds.
    lines_per_second : float
        Projector scanline velocity ``v_p`` (Eq. 2).
    excluded : ndarray of bool, shape (N,), optional
        Images left out of demultiplexing (boundary images, Sec. 4).  Defaults to
        the paper's rule ``||t_d| - t_e/2| <= 75 us``.
    saturated : array_like of bool, shape (N, H, W), optional
        Pixels that hit the top of the ADC in any averaged frame.
    projector_rows : int, optional
        Projector rows spanned by the image height (default: one per camera row).
    metadata : dict
        JSON-serializable acquisition record: ``camera``, ``sync``, ``scene``,
        ``seed``, ``source``, ``sweep`` ... (free-form, kept verbatim).

    See Also
    --------
    planeray.simulate_stack, planeray.acquire_sweep : stacks from a device.
    planeray.read_stack, planeray.import_folder : stacks from disk.
    planeray.demultiplex : the transport of a stack.

    References
    ----------
    .. [1] H. Kubo, S. Jayasuriya, T. Iwaguchi, T. Funatomi, Y. Mukaigawa, S. G. Narasimhan,
       "Programmable Non-Epipolar Indirect Light Transport: Capture and Analysis",
       IEEE TVCG 27(4), 2019, doi:10.1109/TVCG.2019.2946812, Sec. 4.

    Examples
    --------
    Three images of a 2 x 2 camera:

    >>> import numpy as np
    >>> stack = Stack(np.zeros((3, 2, 2), np.float32), [-750.0, 0.0, 750.0], [600.0] * 3, 54000.0)
    >>> stack.shape, stack.excluded.tolist()
    ((2, 2), [False, False, False])
    """

    images: object
    delay_us: np.ndarray
    exposure_us: np.ndarray
    lines_per_second: float
    excluded: np.ndarray | None = None
    saturated: object | None = None
    projector_rows: int | None = None
    metadata: dict = field(default_factory=dict)

    def __post_init__(self):
        self.delay_us = np.asarray(self.delay_us, dtype=np.float64).ravel()
        self.exposure_us = np.asarray(self.exposure_us, dtype=np.float64).ravel()
        n = len(self.images)
        if self.delay_us.size != n or self.exposure_us.size != n:
            raise StackError(f"{n} images but {self.delay_us.size} delays and {self.exposure_us.size} exposures")
        if len(self.images.shape) != 3:
            raise StackError(f"images must be (N, H, W), got shape {tuple(self.images.shape)}")
        if not np.isfinite(self.lines_per_second) or self.lines_per_second <= 0:
            raise StackError(f"lines_per_second must be a positive number, got {self.lines_per_second!r}")
        if np.any(~np.isfinite(self.delay_us)) or np.any(~np.isfinite(self.exposure_us)):
            raise StackError("delay_us and exposure_us must be finite")
        if np.any(self.exposure_us <= 0):
            raise StackError("exposure_us must be positive")
        if self.excluded is None:
            self.excluded = boundary_images(self.delay_us, self.exposure_us)
        self.excluded = np.asarray(self.excluded, dtype=bool).ravel()
        if self.excluded.size != n:
            raise StackError(f"excluded has {self.excluded.size} entries for {n} images")
        if self.saturated is not None and tuple(self.saturated.shape) != tuple(self.images.shape):
            raise StackError(
                f"saturation mask {tuple(self.saturated.shape)} does not match images {tuple(self.images.shape)}"
            )
        if self.projector_rows is None:
            self.projector_rows = int(self.images.shape[1])
        self.lines_per_second = float(self.lines_per_second)

    def __len__(self) -> int:
        return len(self.images)

    def __repr__(self) -> str:
        """A summary, never the arrays: shape, dtype, sweep, geometry.

        Examples
        --------
        >>> import numpy as np
        >>> Stack(np.zeros((3, 8, 6), np.float32), [0.0, 300.0, 600.0], [200.0, 200.0, 400.0], 54000.0)
        Stack(images=(3, 8, 6) float32, delay_us=[0 .. 600] (3 images), exposure_us=[200 .. 400], excluded=0, lines_per_second=54000, projector_rows=8, sweep='custom')
        """
        kind = "" if isinstance(self.images, np.ndarray) else " lazy"  # read from its store on demand
        return (
            f"Stack(images={tuple(self.images.shape)} {np.dtype(self.images.dtype)}{kind}, "
            f"delay_us={_span(self.delay_us)} ({len(self)} images), exposure_us={_span(self.exposure_us)}, "
            f"excluded={int(np.count_nonzero(self.excluded))}, lines_per_second={self.lines_per_second:g}, "
            f"projector_rows={self.projector_rows}, sweep={self.metadata.get('sweep', 'custom')!r})"
        )

    @property
    def shape(self) -> tuple[int, int]:
        """Image shape ``(H, W)``."""
        return tuple(self.images.shape[1:])

    @property
    def geometry(self) -> RowGeometry:
        return RowGeometry(self.shape[0], self.projector_rows)

    @property
    def sweep(self) -> Sweep:
        return Sweep(self.delay_us, self.exposure_us, self.excluded, name=self.metadata.get("sweep", "custom"))

    @property
    def jitter_us(self) -> float:
        """Synchronization jitter (Gaussian sigma) recorded for the illumination model."""
        return float(self.metadata.get("sync", {}).get("jitter_us", 0.0))

    @property
    def line_width_us(self) -> float:
        return float(self.metadata.get("sync", {}).get("line_width_us", 0.0))

    def bands(self):
        """The illumination model of every image (same discretization as the simulator)."""
        return self.sweep.bands(self.lines_per_second, jitter_us=self.jitter_us, line_width_us=self.line_width_us)

    def image(self, index: int) -> np.ndarray:
        return np.asarray(self.images[index], dtype=np.float32)

    def delays(self) -> np.ndarray:
        """Sorted unique delays."""
        return np.unique(self.delay_us)

    def exposures(self) -> np.ndarray:
        """Sorted unique exposures."""
        return np.unique(self.exposure_us)

    def restricted_to(self, sweep: Sweep) -> Stack:
        """The same stack with only ``sweep``'s images used for demultiplexing (the others excluded).

        Every setting of ``sweep`` must be in the stack (within 1e-6 us); an image the sweep
        excludes stays excluded, as does one the stack excludes.  The images are not copied (a
        lazily read stack stays lazy); :class:`planeray.demux.DemuxProblem` then uses exactly the
        sweep's images, e.g. a designed sweep's 24 out of a captured 85 (``planeray demux --sweep``).

        Raises
        ------
        StackError
            A setting of the sweep that the stack does not have (the first few named).

        Examples
        --------
        >>> import numpy as np
        >>> from planeray.timing import paper_sweep, quick_sweep
        >>> q = quick_sweep()
        >>> st = Stack(np.zeros((len(q), 4, 4), np.float32), q.delay_us, q.exposure_us, 54_000.0)
        >>> sub = Sweep(q.delay_us[:6], q.exposure_us[:6], q.excluded[:6])
        >>> int((~st.restricted_to(sub).excluded).sum())
        4
        """
        index = np.full(len(sweep), -1)
        for i, (d, e) in enumerate(zip(sweep.delay_us, sweep.exposure_us)):
            hit = np.flatnonzero((np.abs(self.delay_us - d) <= 1e-6) & (np.abs(self.exposure_us - e) <= 1e-6))
            if hit.size:
                index[i] = hit[0]
        missing = np.flatnonzero(index < 0)
        if missing.size:
            shown = ", ".join(f"({sweep.delay_us[i]:g}, {sweep.exposure_us[i]:g})" for i in missing[:3])
            more = f" and {missing.size - 3} more" if missing.size > 3 else ""
            raise StackError(
                f"the stack has no image at {missing.size} of the sweep {sweep.name!r}'s {len(sweep)} settings "
                f"(delay us, exposure us): {shown}{more}"
            )
        excluded = np.ones(len(self), bool)
        excluded[index] = np.asarray(sweep.excluded, bool)
        excluded |= self.excluded
        meta = dict(self.metadata)
        meta["demux_sweep"] = sweep.name
        return Stack(
            self.images,
            self.delay_us,
            self.exposure_us,
            self.lines_per_second,
            excluded=excluded,
            saturated=self.saturated,
            projector_rows=self.projector_rows,
            metadata=meta,
        )

    def index_of(self, delay_us: float, exposure_us: float) -> int | None:
        """Index of the image with this (delay, exposure), or None."""
        hit = np.flatnonzero(np.isclose(self.delay_us, delay_us) & np.isclose(self.exposure_us, exposure_us))
        return int(hit[0]) if hit.size else None

    def content_digest(self, *, progress=None) -> str:
        """A hash of everything the stack holds: every image, the saturation mask, the sweep and geometry.

        Two stacks with the same digest give the same demultiplexing, so a resumed run
        is allowed only when its stack's digest matches (:func:`planeray.demux.demultiplex_to_store`).
        A stack read lazily from a store hashes the stored (compressed) chunk bytes and
        array metadata -- identical bytes, identical values -- without decoding them
        (0.2 s for a 512x512 paper-sweep stack); an in-memory stack hashes its values
        image by image (0.23 s for the same 89 MB).  The two kinds give different
        digests for the same data, which only ever refuses a resume, never allows a
        wrong one.

        Parameters
        ----------
        progress : callable, optional
            Called with 1 after each image.

        Returns
        -------
        str
            Hexadecimal digest.
        """
        h = hashlib.blake2b(digest_size=32)
        meta = {
            "shape": [len(self), *self.shape],
            "lines_per_second": float(self.lines_per_second),
            "projector_rows": int(self.geometry.projector_rows),
        }
        h.update(json.dumps(meta, sort_keys=True).encode())
        for arr in (self.delay_us, self.exposure_us, np.asarray(self.excluded, np.uint8)):
            h.update(np.ascontiguousarray(arr).tobytes())
        stored = [getattr(a, "update_digest", None) for a in (self.images, self.saturated)]
        if all(hook is not None for hook in stored):
            # lazy arrays in a store: hash what is stored instead of decoding it
            h.update(b"stored")
            if all(hook(h) for hook in stored):
                if progress is not None:
                    progress(len(self))
                return h.hexdigest()
        unsaturated = np.packbits(np.zeros(self.shape, bool)).tobytes()  # no mask = nothing saturated
        for i in range(len(self)):
            h.update(np.ascontiguousarray(np.asarray(self.images[i], np.float32)).tobytes())
            if self.saturated is None:
                h.update(unsaturated)
            else:
                h.update(np.packbits(np.asarray(self.saturated[i], bool)).tobytes())
            if progress is not None:
                progress(1)
        return h.hexdigest()


def _positive_number(value):
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    value = float(value)
    return value if np.isfinite(value) and value > 0 else None


def recorded_mm_per_row(metadata) -> tuple[float | None, str | None]:
    """The size of a projector row on the surface (mm) a capture records, and where it came from.

    Looked up, in this order: the import folder's ``acquisition.json`` (its optional ``mm_per_row``,
    kept in the stack's metadata under ``acquisition``: the user's statement of the capture), the
    metadata's own ``mm_per_row``, and the scene a simulated stack (or a transport store's attributes)
    records (``scene.mm_per_row``).

    Parameters
    ----------
    metadata : dict or None
        :attr:`Stack.metadata`, or a transport store's attributes.

    Returns
    -------
    (float or None, str or None)
        The row size and ``"acquisition.json"``, ``"the capture's record"`` or ``"the scene's record"``;
        ``(None, None)`` when nothing records it.

    See Also
    --------
    Stack : its ``metadata``.

    Examples
    --------
    >>> recorded_mm_per_row({"acquisition": {"mm_per_row": 0.25}, "scene": {"mm_per_row": 0.3}})
    (0.25, 'acquisition.json')
    >>> recorded_mm_per_row({})
    (None, None)
    """
    if not isinstance(metadata, dict):
        return None, None
    acq = metadata.get("acquisition")
    for where, source in ((acq, "acquisition.json"), (metadata, "the capture's record"),
                          (metadata.get("scene"), "the scene's record")):  # fmt: skip
        if isinstance(where, dict):
            value = _positive_number(where.get("mm_per_row"))
            if value is not None:
                return value, source
    return None, None


def _span(values: np.ndarray) -> str:
    """``[min .. max]`` of a sweep's values (``[]`` for none)."""
    return f"[{np.min(values):g} .. {np.max(values):g}]" if np.size(values) else "[]"

"""Per-pixel features for material recognition: area-normalized delay profiles (Sec. 8, Fig. 10b).

Kubo et al. recognize materials from each pixel's **delay profile**, its intensity against
delay, normalized by the area under the curve "to cancel out the effects of albedo".  Two
kinds of profile, each defined by a :class:`FeatureDefinition` that travels with a
trained model:

``"stack"``
    The measured profiles of a delay-exposure stack: at each exposure, the pixel's
    values over the sweep's delays, each exposure's curve divided by its area over delay
    (ms), the exposures' curves concatenated.  Ambient light adds the same
    ``ambient x t_e x albedo`` to every delay of an exposure
    (:class:`planeray.camera.CameraModel`), a floor that the paper's plain normalization
    (``floor="none"``) keeps; ``floor="edge"`` (default) subtracts from each curve the
    mean of its :data:`EDGE_SAMPLES` outermost samples on each side (the largest ``|delay|``;
    four samples, so the floor's noise is half that of one), ``floor="min"`` its minimum
    (noisier: the minimum of 17 noisy samples).  A broad profile keeps some light at the
    edges, which the edge floor removes too -- the same in every capture, so the
    features stay comparable.
``"transport"``
    The profile of a demultiplexed transport (Sec. 4, :func:`planeray.demux.demultiplex`):
    ``T(u)`` over the transport's offsets, area-normalized over the delays ``u / v_p``
    (:func:`planeray.profiles.transport_delay_profiles`).  The floor is removed from the
    *stack* before demultiplexing (:func:`remove_floor`): the regularized demultiplexing
    turns an ambient offset into a broad pedestal of ``T`` that no floor of ``T`` removes.

A definition records what makes two profiles comparable -- the (delay, exposure) pairs
or the offsets, ``lines_per_second``, the normalization and floor, and the
demultiplexing weights -- and :meth:`FeatureDefinition.check` refuses anything else.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from ..errors import InputError
from ..stack import Stack

__all__ = [
    "FEATURE_KINDS",
    "FLOORS",
    "FeatureDefinition",
    "stack_definition",
    "stack_features",
    "transport_definition",
    "transport_features",
    "normalize_profiles",
    "remove_floor",
]

#: Kinds of profile a model can be trained on.
FEATURE_KINDS = ("stack", "transport")
#: Floor removal before the area normalization.
FLOORS = ("edge", "min", "none")
#: Samples averaged at each end of a curve by the ``"edge"`` floor.
EDGE_SAMPLES = 2
_TOL_US = 1e-6


@dataclass(frozen=True)
class FeatureDefinition:
    """What a feature vector is: which samples, in which order, normalized how.

    Attributes
    ----------
    kind : {"stack", "transport"}
    delay_us : tuple of float
        Delay of every sample, in feature order (for a transport: ``u / v_p`` per offset).
    exposure_us : tuple of float
        Exposure of every sample (a transport: empty).
    lines_per_second : float
        Projector line velocity of the sweep (it ties delays to offsets).
    floor : {"edge", "min", "none"}
        Per-curve floor subtracted before normalizing (mean of the outermost samples,
        minimum), or none.
    normalization : str
        ``"area"``: each curve divided by its area over delay in ms (the paper's).
    offsets_rows : tuple of int
        A transport's offsets (empty for a stack).
    demux : dict
        A transport's demultiplexing options (``alpha``, ``beta``, ``method``), empty for a stack.

    See Also
    --------
    capture_features : features so defined.
    MaterialModel : keeps the definition it was trained on.

    Examples
    --------
    >>> import numpy as np
    >>> import planeray as pr
    >>> scene = pr.make_scene("wax", (8, 8), seed=0)  # a wax object (label 2) on a plane (label 1)
    >>> stack = pr.simulate_stack(scene, pr.quick_sweep(), seed=0)
    >>> from planeray.materials import capture_features
    >>> features, signal, definition = capture_features(stack)
    >>> type(definition).__name__, definition.kind, len(definition.delay_us) == features.shape[1]
    ('FeatureDefinition', 'stack', True)
    """

    kind: str
    delay_us: tuple
    exposure_us: tuple
    lines_per_second: float
    floor: str = "edge"
    normalization: str = "area"
    offsets_rows: tuple = ()
    demux: dict | None = None

    def __post_init__(self):
        if self.kind not in FEATURE_KINDS:
            raise InputError(f"unknown feature kind {self.kind!r}; choose one of {', '.join(FEATURE_KINDS)}")
        if self.floor not in FLOORS:
            raise InputError(f"unknown floor {self.floor!r}; choose one of {', '.join(FLOORS)}")
        if self.normalization != "area":
            raise InputError(f"unknown normalization {self.normalization!r}; planeray normalizes by area")
        object.__setattr__(self, "delay_us", tuple(float(v) for v in self.delay_us))
        object.__setattr__(self, "exposure_us", tuple(float(v) for v in self.exposure_us))
        object.__setattr__(self, "offsets_rows", tuple(int(v) for v in self.offsets_rows))
        object.__setattr__(self, "lines_per_second", float(self.lines_per_second))
        object.__setattr__(self, "demux", dict(self.demux or {}))
        values = self.delay_us + self.exposure_us + (self.lines_per_second,)
        if not all(math.isfinite(v) for v in values) or self.lines_per_second <= 0:
            raise InputError("feature definition: delays, exposures and lines per second must be finite (> 0)")
        if self.kind == "stack" and (len(self.exposure_us) != len(self.delay_us) or self.offsets_rows or self.demux):
            raise InputError(
                f"feature definition: stack profiles need one exposure per delay ({len(self.delay_us)} delays, "
                f"{len(self.exposure_us)} exposures) and no offsets or demultiplexing"
            )
        if self.kind == "transport":
            if self.exposure_us or len(self.offsets_rows) != len(self.delay_us):
                raise InputError(
                    f"feature definition: transport profiles need one offset per delay ({len(self.delay_us)} "
                    f"delays, {len(self.offsets_rows)} offsets) and no exposures"
                )
            if set(self.demux) != {"alpha", "beta", "method"}:
                raise InputError(
                    f"feature definition: transport profiles need demux alpha, beta and method, got {sorted(self.demux)}"
                )

    @property
    def n_features(self) -> int:
        return len(self.delay_us)

    def to_dict(self) -> dict:
        """JSON-ready fields."""
        d = asdict(self)
        d["delay_us"], d["exposure_us"], d["offsets_rows"] = (
            list(self.delay_us),
            list(self.exposure_us),
            list(self.offsets_rows),
        )
        return d

    @classmethod
    def from_dict(cls, data) -> FeatureDefinition:
        if not isinstance(data, dict):
            raise InputError(f"malformed feature definition: expected an object, got {type(data).__name__}")
        try:
            return cls(**data)
        except (TypeError, ValueError, OverflowError) as exc:
            if isinstance(exc, InputError):
                raise
            raise InputError(f"malformed feature definition: {exc}") from None

    def describe(self) -> str:
        """One line: what the features are."""
        if self.kind == "stack":
            delays, exposures = sorted(set(self.delay_us)), sorted(set(self.exposure_us))
            what = (
                f"stack profiles, {len(delays)} delays {delays[0]:g}..{delays[-1]:g} us x {len(exposures)} exposures "
                f"{', '.join(f'{e:g}' for e in exposures)} us"
            )
        else:
            what = (
                f"transport profiles over offsets {self.offsets_rows[0]}..{self.offsets_rows[-1]} (demux {self.demux})"
            )
        return f"{what}, {self.lines_per_second:g} lines/s, area-normalized, floor {self.floor}"

    def check(self, other: FeatureDefinition, *, source=None) -> None:
        """Raise :class:`InputError` unless ``other`` (the data's definition) matches this (the model's).

        The samples must be the same ones, in the same order (delays and exposures within
        1e-6 us, offsets equal), at the same line velocity (relative 1e-6), with the same
        normalization, floor and demultiplexing -- otherwise the model would be applied
        to numbers that do not mean what it learnt, silently wrong.
        """
        where = source

        def refuse(problem):
            raise InputError(f"the model was trained on {self.describe()}; {problem}", where)

        if other.kind != self.kind:
            refuse(f"these are {other.kind} profiles")
        if not math.isclose(other.lines_per_second, self.lines_per_second, rel_tol=1e-6):
            refuse(f"this sweep runs at {other.lines_per_second:g} lines/s")
        if self.kind == "stack":
            mine = set(zip(self.delay_us, self.exposure_us))
            theirs = list(zip(other.delay_us, other.exposure_us))
            if len(theirs) != len(mine) or not np.allclose(
                np.array(theirs), np.array(list(zip(self.delay_us, self.exposure_us))), rtol=0, atol=_TOL_US
            ):
                missing = sorted(p for p in mine if not any(np.allclose(p, q, atol=_TOL_US, rtol=0) for q in theirs))
                extra = sorted(q for q in theirs if not any(np.allclose(p, q, atol=_TOL_US, rtol=0) for p in mine))
                detail = []
                if missing:
                    detail.append(
                        f"missing (delay, exposure) {missing[0]}"
                        + (f" and {len(missing) - 1} more" if len(missing) > 1 else "")
                    )
                if extra:
                    detail.append(
                        f"unknown (delay, exposure) {extra[0]}"
                        + (f" and {len(extra) - 1} more" if len(extra) > 1 else "")
                    )
                refuse(
                    f"this stack is a different sweep ({len(theirs)} images: {'; '.join(detail) or 'another order'})"
                )
        else:
            if other.offsets_rows != self.offsets_rows:
                refuse(
                    f"this transport has offsets {other.offsets_rows[0]}..{other.offsets_rows[-1]} ({len(other.offsets_rows)})"
                )
            if other.demux != self.demux:
                refuse(f"this transport was demultiplexed with {other.demux}")
        if other.floor != self.floor:
            refuse(f"these features use floor {other.floor}")


def normalize_profiles(values, delay_us, *, floor="edge"):
    """Area-normalize profiles over delay (last axis, sorted delays), after removing a floor.

    Vectorized :func:`planeray.profiles.area_normalize` (same result for ``floor="none"``
    and NaN-free profiles): each profile divided by the trapezoidal area of its positive
    part over delay in ms; a profile with no positive area becomes 0.  ``floor``:
    ``"edge"`` subtracts the mean of the :data:`EDGE_SAMPLES` outermost samples at each
    end, ``"min"`` the minimum, ``"none"`` nothing.

    Parameters
    ----------
    values : array_like (..., D)
        Profiles over delay (last axis, delays sorted).
    delay_us : array_like (D,)
        The delays, microseconds.
    floor : {"edge", "min", "none"}
        The floor removed first.

    Returns
    -------
    profiles : ndarray (..., D) float32
        The profiles over their areas (1/ms).
    area : ndarray (...)
        The areas (input units times ms).

    See Also
    --------
    planeray.profiles.area_normalize : the plain normalization.

    Examples
    --------
    Returns the normalized profiles (float32) and the area each was divided by (1/ms units of the input).
    The floor here is the mean of the two outermost samples at each end (0.35):

    >>> import numpy as np
    >>> p, area = normalize_profiles(
    ...     np.array([[0.1, 0.6, 1.1, 0.6, 0.1]]), np.array([-1000.0, -500.0, 0.0, 500.0, 1000.0])
    ... )
    >>> p.round(2).tolist(), area.tolist()
    ([[-0.4, 0.4, 1.2, 0.4, -0.4]], [0.625])
    """
    if floor not in FLOORS:
        raise InputError(f"unknown floor {floor!r}; choose one of {', '.join(FLOORS)}")
    v = np.asarray(values, dtype=np.float64)
    if floor == "min":
        v = v - v.min(axis=-1, keepdims=True)
    elif floor == "edge":
        k = min(EDGE_SAMPLES, v.shape[-1] // 2)
        if k > 0:
            v = v - 0.5 * (v[..., :k].mean(axis=-1, keepdims=True) + v[..., -k:].mean(axis=-1, keepdims=True))
    x = np.asarray(delay_us, dtype=np.float64) * 1e-3
    area = np.trapezoid(np.clip(v, 0.0, None), x, axis=-1) if x.size > 1 else np.zeros(v.shape[:-1])
    safe = np.where(area > 0, area, 1.0)[..., None]
    return np.where(area[..., None] > 0, v / safe, 0.0).astype(np.float32), area


def _stack_layout(stack: Stack):
    """Image order of the features: by exposure, then delay; and the curves' slices."""
    order = np.lexsort((stack.delay_us, stack.exposure_us))
    exposures = np.unique(stack.exposure_us)
    groups = [order[np.isclose(stack.exposure_us[order], e, rtol=0, atol=_TOL_US)] for e in exposures]
    return order, groups


def stack_definition(stack: Stack, *, floor="edge") -> FeatureDefinition:
    """The feature definition of a stack's measured delay profiles (every image, by exposure then delay)."""
    order, _ = _stack_layout(stack)
    return FeatureDefinition(
        kind="stack",
        delay_us=tuple(stack.delay_us[order]),
        exposure_us=tuple(stack.exposure_us[order]),
        lines_per_second=stack.lines_per_second,
        floor=floor,
    )


def stack_features(stack: Stack, *, floor="edge", definition: FeatureDefinition | None = None, source=None):
    """Area-normalized measured delay profiles of every pixel of a stack.

    Parameters
    ----------
    stack : Stack
    floor : {"edge", "min", "none"}
        Floor removal (module docstring); ignored when ``definition`` is given.
    definition : FeatureDefinition, optional
        A model's definition: the stack must match it (:meth:`FeatureDefinition.check`).
    source : str, optional
        Name of the stack in error messages.

    Returns
    -------
    features : ndarray (H * W, F) float32
        One row per pixel (row-major), the exposures' normalized curves concatenated.
    signal : ndarray (H, W) float64
        Sum over exposures of the curves' areas (0: a pixel with no usable profile).
    definition : FeatureDefinition

    See Also
    --------
    transport_features : from a transport.

    Examples
    --------
    >>> from planeray.acquire import simulate_stack
    >>> from planeray.scenes import make_scene
    >>> from planeray.timing import paper_sweep
    >>> stack = simulate_stack(make_scene("wax", (8, 8), projector_rows=45, seed=0), paper_sweep(), seed=0)
    >>> X, signal, d = stack_features(stack)
    >>> X.shape, d.n_features, d.kind
    ((64, 85), 85, 'stack')
    """
    mine = stack_definition(stack, floor=definition.floor if definition is not None else floor)
    if definition is not None:
        definition.check(mine, source=source)
    _, groups = _stack_layout(stack)
    H, W = stack.shape
    feats, areas = [], np.zeros(H * W)
    for idx in groups:
        curve = np.stack([stack.image(int(i)).ravel() for i in idx], axis=-1)  # (H*W, D_e)
        f, area = normalize_profiles(curve, stack.delay_us[idx], floor=mine.floor)
        feats.append(f)
        areas += area
    return np.concatenate(feats, axis=1), areas.reshape(H, W), mine


def transport_definition(transport, *, lines_per_second, floor="edge", demux=None) -> FeatureDefinition:
    """The feature definition of a transport's profiles ``T(u)`` (``demux``: how it was demultiplexed)."""
    offsets = np.asarray(transport.offsets_rows)
    return FeatureDefinition(
        kind="transport",
        delay_us=tuple(offsets * 1e6 / float(lines_per_second)),
        exposure_us=(),
        lines_per_second=float(lines_per_second),
        floor=floor,
        offsets_rows=tuple(int(u) for u in offsets),
        demux=demux or {},
    )


def transport_features(
    transport, *, lines_per_second, floor="edge", demux=None, definition: FeatureDefinition | None = None, source=None
):
    """Area-normalized profiles ``T(u)`` of every pixel of a (demultiplexed) transport.

    Returns ``(features (H * W, U) float32, signal (H, W), definition)`` like
    :func:`stack_features`; ``demux`` records the demultiplexing options and ``floor``
    the floor removed from the stack before demultiplexing (:func:`remove_floor`), both
    compared by a model.

    Parameters
    ----------
    transport : Transport
        A (demultiplexed) transport.
    lines_per_second : float
        Projector scan rate, rows per second.
    floor : {"edge", "min", "none"}
        The floor removed from the stack before demultiplexing (recorded).
    demux : dict
        The demultiplexing options (recorded, compared by a model).
    definition : FeatureDefinition, optional
        A model's definition.
    source : str, optional
        Name of the capture, for messages.

    Returns
    -------
    features : ndarray (H * W, U) float32
    signal : ndarray (H, W)
    definition : FeatureDefinition

    See Also
    --------
    capture_transport : the transport of a capture.

    Examples
    --------
    >>> import numpy as np
    >>> import planeray as pr
    >>> scene = pr.make_scene("wax", (8, 8), seed=0)  # a wax object (label 2) on a plane (label 1)
    >>> stack = pr.simulate_stack(scene, pr.quick_sweep(), seed=0)
    >>> from planeray.materials import capture_transport
    >>> features, signal, definition = transport_features(
    ...     capture_transport(stack), lines_per_second=54000.0, demux={"alpha": 0.01, "beta": 0.01, "method": "fast"}
    ... )
    >>> features.shape[0], definition.kind
    (64, 'transport')
    """
    mine = transport_definition(
        transport,
        lines_per_second=lines_per_second,
        floor=definition.floor if definition is not None else floor,
        demux=definition.demux if definition is not None and demux is None else demux,
    )
    if definition is not None:
        definition.check(mine, source=source)
    H, W = transport.shape
    dense = np.asarray(transport.dense, dtype=np.float32).reshape(H * W, -1)
    f, area = normalize_profiles(dense, np.asarray(mine.delay_us), floor="none")  # the floor left with the stack
    return f, area.reshape(H, W), mine


def remove_floor(stack: Stack, *, floor="edge") -> Stack:
    """The stack with each pixel's floor subtracted, per exposure (before demultiplexing).

    The same floor as :func:`stack_features` (``"edge"``: the mean of the outermost
    delays at each end; ``"min"``: the minimum; ``"none"``: the stack itself), taken
    per pixel over the delays of each exposure and subtracted from all its images: what
    the ambient light adds (``ambient x t_e x albedo``) goes, exactly.

    Parameters
    ----------
    stack : Stack
        The capture.
    floor : {"edge", "min", "none"}
        The floor to subtract.

    Returns
    -------
    Stack
        A new stack; the input is left as it is.

    See Also
    --------
    stack_features : the same floor.

    Examples
    --------
    >>> import numpy as np
    >>> import planeray as pr
    >>> scene = pr.make_scene("wax", (8, 8), seed=0)  # a wax object (label 2) on a plane (label 1)
    >>> stack = pr.simulate_stack(scene, pr.quick_sweep(), seed=0)
    >>> floored = remove_floor(stack)
    >>> floored.images.shape == stack.images.shape, bool(floored.images.min() < stack.images.min())
    (True, True)
    """
    if floor not in FLOORS:
        raise InputError(f"unknown floor {floor!r}; choose one of {', '.join(FLOORS)}")
    if floor == "none":
        return stack
    images = np.stack([stack.image(i) for i in range(len(stack))]).astype(np.float64)
    out = images.copy()
    _, groups = _stack_layout(stack)
    for idx in groups:  # by exposure, delays increasing
        curves = images[idx]
        if floor == "min":
            level = curves.min(axis=0)
        else:
            k = min(EDGE_SAMPLES, len(idx) // 2)
            level = 0.5 * (curves[:k].mean(axis=0) + curves[-k:].mean(axis=0)) if k else np.zeros(stack.shape)
        out[idx] -= level
    return Stack(
        out.astype(np.float32),
        stack.delay_us,
        stack.exposure_us,
        stack.lines_per_second,
        excluded=stack.excluded,
        saturated=None if stack.saturated is None else np.asarray(stack.saturated),
        projector_rows=stack.projector_rows,
        metadata={**stack.metadata, "floor_removed": floor},
    )

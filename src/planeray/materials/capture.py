"""A capture's features for the classifier: its delay images, or the transport demultiplexed from it.

:func:`capture_transport` demultiplexes a stack with :data:`DEFAULT_DEMUX` (the paper's weights,
the fast solver); :func:`capture_features` returns the per-pixel features of either kind
(:data:`planeray.materials.features.FEATURE_KINDS`).
"""

from __future__ import annotations

from ..errors import InputError
from ..stack import Stack
from .features import FEATURE_KINDS, FeatureDefinition, stack_features, transport_features


# ---------------------------------------------------------------- features of a capture
def capture_features(
    stack: Stack,
    *,
    kind: str = "stack",
    floor: str = "edge",
    definition: FeatureDefinition | None = None,
    transport=None,
    demux: dict | None = None,
    source=None,
    progress=None,
):
    """Features of every pixel of a capture: measured profiles, or those of its demultiplexed transport.

    ``definition`` (a model's) fixes the kind, floor and demultiplexing; otherwise
    ``kind``, ``floor`` and ``demux`` (``alpha``, ``beta``, ``method``; default the
    paper's 0.01, 0.01, ``"fast"``) do.  A transport, if not given, is
    :func:`capture_transport` of the stack.  Returns ``(features, signal, definition)``.

    Parameters
    ----------
    stack : Stack
        The capture.
    kind : {"stack", "transport"}
        Measured profiles, or the profiles of the demultiplexed transport.
    floor : {"edge", "min", "none"}
        The floor removed before the area normalization.
    definition : FeatureDefinition, optional
        A model's definition: fixes kind, floor and demultiplexing.
    transport : Transport, optional
        The capture's transport, when already demultiplexed.
    demux : dict, optional
        Demultiplexing options (``alpha``, ``beta``, ``method``).
    source : str, optional
        Name of the capture, for messages.
    progress : callable, optional
        Called as the demultiplexing advances.

    Returns
    -------
    features : ndarray (H * W, F) float32
        One area-normalized profile per pixel (1/ms).
    signal : ndarray (H, W)
        Each pixel's profile area before normalization.
    definition : FeatureDefinition

    See Also
    --------
    train_model : learns from them.

    Examples
    --------
    >>> import numpy as np
    >>> import planeray as pr
    >>> scene = pr.make_scene("wax", (8, 8), seed=0)  # a wax object (label 2) on a plane (label 1)
    >>> stack = pr.simulate_stack(scene, pr.quick_sweep(), seed=0)
    >>> features, signal, definition = capture_features(stack)
    >>> features.shape, signal.shape  # one area-normalized profile per pixel
    ((64, 27), (8, 8))
    """
    if definition is not None:
        kind = definition.kind
    if kind not in FEATURE_KINDS:
        raise InputError(f"unknown feature kind {kind!r}; choose one of {', '.join(FEATURE_KINDS)}")
    if kind == "stack":
        return stack_features(stack, floor=floor, definition=definition, source=source)
    opts = (
        dict(definition.demux)
        if definition is not None
        else {"alpha": 0.01, "beta": 0.01, "method": "fast", **(demux or {})}
    )
    if transport is None:
        from ..demux import demultiplex

        transport = demultiplex(
            stack, alpha=opts["alpha"], beta=opts["beta"], method=opts["method"], progress=progress
        ).transport
    return transport_features(
        transport,
        lines_per_second=stack.lines_per_second,
        floor=floor if definition is None else definition.floor,
        demux=opts,
        definition=definition,
        source=source,
    )


#: Demultiplexing options of transport features (the paper's weights, the fast solver).
DEFAULT_DEMUX = {"alpha": 0.01, "beta": 0.01, "method": "fast"}


def capture_transport(stack: Stack, *, floor: str = "edge", demux: dict | None = None, progress=None):
    """The transport of a capture as transport features see it: floor removed, then demultiplexed.

    :func:`~planeray.materials.features.remove_floor` then :func:`planeray.demux.demultiplex`
    with ``demux`` (default :data:`DEFAULT_DEMUX`).

    Parameters
    ----------
    stack : Stack
        The capture.
    floor : {"edge", "min", "none"}
        The floor removed before demultiplexing.
    demux : dict, optional
        Demultiplexing options (default :data:`DEFAULT_DEMUX`).
    progress : callable, optional
        Called as the demultiplexing advances.

    Returns
    -------
    Transport

    See Also
    --------
    transport_features : its features.

    Examples
    --------
    >>> import numpy as np
    >>> import planeray as pr
    >>> scene = pr.make_scene("wax", (8, 8), seed=0)  # a wax object (label 2) on a plane (label 1)
    >>> stack = pr.simulate_stack(scene, pr.quick_sweep(), seed=0)
    >>> capture_transport(stack).dense.shape
    (8, 8, 229)
    """
    from ..demux import demultiplex
    from .features import remove_floor

    opts = {**DEFAULT_DEMUX, **(demux or {})}
    return demultiplex(
        remove_floor(stack, floor=floor),
        alpha=opts["alpha"],
        beta=opts["beta"],
        method=opts["method"],
        progress=progress,
    ).transport

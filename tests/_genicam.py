"""Aravis's fake GenICam camera for the tests: availability, the options that open it, and its frames written out.

The fake camera (Aravis 0.8, ``arvfakecamera.c``) is driven through its real node map and stream
(planeray's GenICam file, ``aravis_fake_episcan.xml``).  Its image generator draws, in Mono16, the
diagonal ramp ``(256 (x + y + frame_id)) mod 65535``, times ``1 + GainRaw + log10(exposure_us / 10^4)``,
clamped and truncated to 16 bits: :func:`fake_frame` computes it here from the frame's id, so that a
capture can be checked pixel for pixel against what the camera made -- never against planeray's output.
"""

from __future__ import annotations

import contextlib
import fcntl
import gc
import os
import tempfile
from pathlib import Path

import numpy as np
import pytest

from planeray.devices.genicam import aravis_available

#: Options of a small fake camera: Mono16 (what its generator draws), gain 1 (a ramp scaled by 0.78-1.08 at
#: 600-1200 us: positive, and no frame wholly saturated),
#: 24x16 pixels, one frame per image, software triggers (the tests' trigger source).
FAKE = dict(
    camera_id="Fake_1",
    pixel_format="Mono16",
    gain=1,
    region=[0, 0, 24, 16],
    frames_averaged=1,
    base_trigger_delay_us=3000.0,
    trigger_source="Software",
    fake_trigger_hz=200.0,
)


def fake_options(**changes) -> dict:
    return {**FAKE, **changes}


def as_cli(options: dict) -> list[str]:
    """``-O KEY=VALUE`` arguments for ``options``."""
    import json

    args = []
    for k, v in options.items():
        args += ["-O", f"{k}={v if isinstance(v, str) else json.dumps(v)}"]
    return args


def require_aravis() -> None:
    """Skip (fail in CI) without Aravis and PyGObject: ``make test`` installs them as root."""
    if aravis_available():
        return
    reason = (
        "no Aravis 0.8 with PyGObject: apt-get install gir1.2-aravis-0.8 libgirepository1.0-dev libcairo2-dev "
        "pkg-config and pip install -e '.[genicam]' (make test does it as root)"
    )
    if os.environ.get("CI"):
        pytest.fail(reason)
    pytest.skip(reason)


def fake_frame(frame_id: int, shape, exposure_us: float, gain: int) -> np.ndarray:
    """The fake camera's Mono16 frame ``frame_id`` (``arv_fake_camera_diagonal_ramp``, Aravis 0.8)."""
    h, w = shape
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    scale = 1.0 + gain + np.log10(float(int(exposure_us)) / 10000.0)  # the exposure register holds whole us
    value = ((256.0 * (x + frame_id + y)) % 65535.0) * scale
    return np.trunc(np.clip(value, 0.0, 65535.0)).astype(np.uint16)


def expected_image(frame_ids, shape, exposure_us: float, gain: int, *, black_level: int = 0) -> np.ndarray:
    """The normalized image of frames ``frame_ids`` averaged: ``(mean code - black) / (65535 - black)``."""
    total = np.zeros(shape, np.float64)
    for i in frame_ids:
        total += fake_frame(i, shape, exposure_us, gain)
    return ((total / len(frame_ids) - black_level) / (65535 - black_level)).astype(np.float32)


@contextlib.contextmanager
def gv_fake_camera(serial: str):
    """Aravis's GigE Vision fake camera on 127.0.0.1 with planeray's GenICam file (one at a time: it owns GVCP's port)."""
    from gi.repository import Aravis

    from planeray.devices.genicam import FAKE_GENICAM_XML

    with open(Path(tempfile.gettempdir()) / "planeray-aravis-gv-fake.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        camera = Aravis.GvFakeCamera.new_full("127.0.0.1", serial, str(FAKE_GENICAM_XML))
        try:
            yield f"Aravis-Fake-{serial}"
        finally:
            del camera
            gc.collect()

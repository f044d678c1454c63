"""The device conformance suite: one set of tests that every registered device passes.

Each device is opened by its registered name (:func:`planeray.devices.open_device`) on the real stack
that emulates it -- the simulated Episcan, a replay of a recorded stack, the uEye driver on its
stand-in SDK (``fake_pyueye``), the GenICam driver on Aravis's fake camera -- and must:

* give the exposure and trigger-delay ranges it can realize, and refuse a point outside them;
* realize a sweep point and say, read back from the camera, which delay and exposure it realized;
* deliver images of its described shape, float32, with a saturation mask, quantized to its bit depth;
* say what it waited for when a trigger never comes (a device that waits for none is exempt);
* be released when an error ends its use (it opens again);
* resume an interrupted capture (``acquire``) without losing or retaking an image.

A new device is added by registering it (:func:`planeray.devices.register_device`) and adding its
harness to :data:`HARNESSES` -- how to open it, and how to make its trigger never come -- and passing.
"""

from __future__ import annotations

import contextlib
import gc
import json

import numpy as np
import pytest

from planeray.acquire import acquire_to_store
from planeray.devices import is_hardware, list_devices, open_device
from planeray.devices.capabilities import has
from planeray.errors import DeviceError, InputError
from planeray.io import read_stack
from planeray.timing import Sweep

#: The sweep every device captures: 3 delays x 2 exposures.
SWEEP = Sweep.grid([-375.0, 0.0, 375.0], [600.0, 900.0], name="conformance")


class Harness:
    """How the suite opens one device and makes its trigger fail; ``released()`` says whether it let go."""

    name = ""
    waits_for_a_trigger = True

    def setup(self, monkeypatch, tmp_path_factory) -> None:
        """Prepare what the device talks to (an SDK stand-in, a recording)."""

    def options(self) -> dict:
        raise NotImplementedError

    def open(self, **changes):
        return open_device(self.name, **{**self.options(), **changes})

    @contextlib.contextmanager
    def no_trigger(self):
        """An open device whose trigger never comes."""
        raise NotImplementedError
        yield

    def released(self, device) -> bool:
        return True


class SimHarness(Harness):
    name = "sim"

    def options(self):
        return dict(scene="diffuse_plane", size=(12, 16), projector_rows=90, seed=1, frames_averaged=1)

    @contextlib.contextmanager
    def no_trigger(self):
        with self.open(trigger_wired=False) as dev:
            yield dev


class ReplayHarness(Harness):
    name = "replay"
    waits_for_a_trigger = False
    recording = None

    def setup(self, monkeypatch, tmp_path_factory):
        if ReplayHarness.recording is None:
            path = tmp_path_factory.mktemp("replay") / "recorded.zarr"
            with open_device("sim", **SimHarness().options()) as sim:
                acquire_to_store(sim, SWEEP, path)
            ReplayHarness.recording = path

    def options(self):
        return dict(replay=str(self.recording))


class UEyeHarness(Harness):
    name = "ueye"

    def setup(self, monkeypatch, tmp_path_factory):
        from fake_pyueye import FakeCamera, install

        self.camera = FakeCamera()
        install(monkeypatch, self.camera)

    def options(self):
        return dict(frames_averaged=1, base_trigger_delay_us=3000.0)

    @contextlib.contextmanager
    def no_trigger(self):
        self.camera.vsync = False
        try:
            with self.open() as dev:
                yield dev
        finally:
            self.camera.vsync = True

    def released(self, device):
        return self.camera.opened == self.camera.exited


class GenICamHarness(Harness):
    name = "genicam"

    def setup(self, monkeypatch, tmp_path_factory):
        from _genicam import require_aravis

        require_aravis()
        self.freed: list = []

    def options(self):
        from _genicam import fake_options

        return fake_options()

    def open(self, **changes):
        dev = super().open(**changes)
        dev._camera.weak_ref(lambda *a: self.freed.append(1))
        return dev

    @contextlib.contextmanager
    def no_trigger(self):
        import os

        from _genicam import gv_fake_camera

        # Aravis's GigE Vision fake: the real protocol, a hardware trigger line nothing drives
        with gv_fake_camera(f"PRC{os.getpid()}") as device_id:
            with self.open(camera_id=device_id, trigger_source="Line0", trigger_timeout_s=0.3) as dev:
                yield dev

    def released(self, device):
        gc.collect()
        return device.aravis_device is None and len(self.freed) > 0


HARNESSES = {h.name: h for h in (SimHarness, ReplayHarness, UEyeHarness, GenICamHarness)}


@pytest.fixture(params=sorted(HARNESSES))
def harness(request, monkeypatch, tmp_path_factory):
    h = HARNESSES[request.param]()
    h.setup(monkeypatch, tmp_path_factory)
    return h


def test_every_registered_device_has_a_harness():
    assert set(list_devices()) <= set(HARNESSES), "register a harness for the new device and pass this suite"


def test_description_is_json_and_does_not_change_while_open(harness):
    with harness.open() as dev:
        before = json.dumps(dev.describe(), sort_keys=True, default=str)
        dev.set_timing(0.0, 600.0)
        dev.grab()
        assert json.dumps(dev.describe(), sort_keys=True, default=str) == before
        assert dev.describe()["device"] in (harness.name, "simulated") and len(dev.describe()["image_shape"]) == 2
        assert dev.lines_per_second > 0


def test_ranges_cover_the_sweep_and_a_point_outside_is_refused(harness):
    with harness.open() as dev:
        if not has(dev, "ranges"):
            assert harness.name == "replay"  # a recording realizes what it recorded, nothing else
            dev.set_timing(0.0, 750.0)
            with pytest.raises(InputError, match="has no image at delay 0 us, exposure 750 us"):
                dev.grab()
            return
        lo, hi = dev.get_exposure_range_us()
        d_lo, d_hi = dev.get_trigger_delay_range_us()
        assert 0 <= lo < hi and 0 <= d_lo < d_hi
        assert lo <= SWEEP.exposure_us.min() and SWEEP.exposure_us.max() <= hi
        with pytest.raises((DeviceError, InputError), match="exposure"):
            dev.set_timing(0.0, lo / 2 if lo > 0 else -1.0)
            dev.grab()


def test_sweep_points_are_realized_and_read_back(harness):
    with harness.open() as dev:
        assert has(dev, "timing")
        for d, e in zip(SWEEP.delay_us, SWEEP.exposure_us):
            dev.set_timing(float(d), float(e))
            got_d, got_e = dev.get_timing_us()
            assert got_e == pytest.approx(e, abs=0.5)
            assert got_d == pytest.approx(d, abs=1.0)  # a camera's trigger delay register: 1 us steps


def _bits(description: dict) -> dict:
    camera = description.get("camera") or description.get("recording", {}).get("camera", {})
    return {k: camera[k] for k in ("bit_depth", "black_level", "frames_averaged")}


def test_images_have_the_described_shape_dtype_and_bit_depth(harness):
    with harness.open() as dev:
        shape = tuple(dev.describe()["image_shape"])
        bits = _bits(dev.describe())
        dev.set_timing(0.0, 600.0)
        image, saturated = dev.grab()
    assert image.dtype == np.float32 and image.shape == shape and np.all(np.isfinite(image))
    assert saturated.dtype == bool and saturated.shape == shape
    full, black, n = 2 ** bits["bit_depth"] - 1, bits["black_level"], bits["frames_averaged"]
    codes = (image.astype(np.float64) * (full - black) + black) * n  # the sum of the frames' codes
    assert codes.min() >= -0.05 and codes.max() <= full * n + 0.05  # within the bit depth's codes
    if is_hardware(harness.name):  # a camera's frames are whole codes (the simulation dithers its rounding)
        assert np.abs(codes - np.round(codes)).max() < 0.05


def test_a_trigger_that_never_comes_says_what_it_waited_for_and_the_device_is_released(harness):
    if not harness.waits_for_a_trigger:
        pytest.skip(f"{harness.name} waits for no trigger")
    with harness.no_trigger() as dev:
        dev.set_timing(0.0, 600.0)
        with pytest.raises(DeviceError) as err:
            dev.grab()
    message = str(err.value)
    assert "trigger" in message and "within" in message and "\n" not in message
    assert harness.released(dev)


def test_an_error_releases_the_device_and_it_opens_again(harness):
    with pytest.raises(RuntimeError, match="the user's code failed"):
        with harness.open() as dev:
            dev.set_timing(0.0, 600.0)
            dev.grab()
            raise RuntimeError("the user's code failed")
    assert harness.released(dev)
    with harness.open() as again:
        again.set_timing(0.0, 600.0)
        assert again.grab()[0].shape == tuple(again.describe()["image_shape"])


def test_an_interrupted_acquire_resumes_without_losing_or_retaking_an_image(harness, tmp_path):
    out = tmp_path / "s.zarr"
    with harness.open() as dev:
        partial = acquire_to_store(dev, SWEEP, out, _stop_after=2)  # "killed" after two images
    import zarr

    first = np.asarray(zarr.open_group(str(partial), mode="r")["images"][:2])
    resumed, taken = [], []
    with harness.open() as dev:
        grab = dev.grab

        def counted():
            taken.append(1)
            return grab()

        dev.grab = counted
        acquire_to_store(dev, SWEEP, out, on_resume=lambda done, total: resumed.append((done, total)))
    st = read_stack(out, lazy=False)
    assert resumed == [(2, len(SWEEP))] and len(taken) == len(SWEEP) - 2
    assert len(st) == len(SWEEP) and np.all(np.isfinite(st.images))
    np.testing.assert_array_equal(st.images[:2], first)
    np.testing.assert_array_equal(st.delay_us, SWEEP.delay_us)

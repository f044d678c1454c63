"""``planeray view --device``: a device live in the page, in Debian's chromium through Playwright.

The simulated pulsing skin: frames arrive and are painted without any input, each the frame the
capture took (float32, exactly); the delay typed into the page is the timing the next frames are
captured at; the vein view is the contrast stretch of the frame; 'save stack' writes the frame shown
as a stack that reads back.  Aravis's fake camera: each painted frame is one of the camera's frames
(its generator written out in ``_genicam``).
"""

from __future__ import annotations

import os

import numpy as np
import pytest

from _browser import system_chromium
from planeray.devices import open_device
from planeray.io import read_stack
from planeray.live import vein_view
from planeray.viewer.live import DeviceSource
from planeray.viewer.server import ViewerServer
from test_viewer_browser import _unavailable, done, frame, open_page, wait_for


@pytest.fixture(scope="module")
def browser():
    yield from system_chromium(_unavailable)


def _captured(source, index):
    for f in list(source.capture._frames):
        if f.index == index:
            return f
    raise AssertionError(f"frame {index} is no longer kept")


def test_the_simulated_skin_live_in_the_page(browser, tmp_path):
    dev = open_device("sim", scene="skin", size=(24, 32), pulse_bpm=72.0, frames_averaged=1, sensor_rows=1200)
    source = DeviceSource(dev, name="sim", max_fps=60.0, snapshot_dir=tmp_path)
    with ViewerServer(source) as server:
        page = open_page(browser, server)
        assert page.is_hidden("#side-by-side") and page.is_visible("#save-stack")
        # frames arrive and are painted with no input at all, each the frame the capture took
        first = page.evaluate("window.planeray.panels[0].painted")
        wait_for(page, f"window.planeray.panels[0].painted >= {first + 5}")
        data, header, _, _ = frame(page)
        np.testing.assert_array_equal(data, _captured(source, header["frame_index"]).image)
        # a delay typed into the page is the timing the frames are captured at
        page.fill(".panel[data-panel='0'] input.num-delay_us", "450")
        page.press(".panel[data-panel='0'] input.num-delay_us", "Enter")
        wait_for(page, "window.planeray.panels[0].image.header.delay_us === 450")
        data, header, _, _ = frame(page)
        shown = _captured(source, header["frame_index"])
        assert (shown.delay_us, shown.exposure_us) == (450.0, 600.0)
        np.testing.assert_array_equal(data, shown.image)
        assert "camera" in page.text_content("#camera-fps")
        # the vein view: the frame, contrast-stretched
        page.select_option(".panel[data-panel='0'] select.mode", "vein")
        wait_for(page, "window.planeray.panels[0].image.header.settings.mode === 'vein'")
        data, header, _, _ = frame(page)
        np.testing.assert_array_equal(data, vein_view(_captured(source, header["frame_index"]).image))
        # the pulse view: the frame, and once 3 s of frames are in, the rate and spectrum of skin pulse's analysis
        page.select_option(".panel[data-panel='0'] select.mode", "pulse")
        pulse = wait_for(page, "window.planeray.panels[0].image.header.pulse", timeout_s=60)
        assert pulse["timing"] == [450.0, 1200.0] and pulse["window_s"] >= 3.0 and len(pulse["spectrum"]["bpm"]) > 10
        assert page.text_content("#plot-title").startswith("Pulse: ")
        # save stack: the frame shown, written where the command line said
        page.select_option(".panel[data-panel='0'] select.mode", "band")
        wait_for(page, "window.planeray.panels[0].image.header.settings.mode === 'band'")
        page.click("#save-stack")
        saved = wait_for(page, "window.planeray.lastStack")
        st = read_stack(saved["path"], lazy=False)
        assert os.path.dirname(saved["path"]) == str(tmp_path) and len(st) == 1 and st.delay_us[0] == 450.0
        assert st.exposure_us[0] == 1200.0  # the pulse view's exposure, kept when the band view came back
        assert st.metadata["live"]["view"] == "band" and st.metadata["device"] == "simulated"
        done(page)
    assert not source.capture._thread.is_alive()  # the server stopped, the device released


def test_the_fake_genicam_camera_live_in_the_page(browser):
    from _genicam import expected_image, fake_options, require_aravis

    require_aravis()
    dev = open_device("genicam", **fake_options(fake_trigger_hz=60.0))
    source = DeviceSource(dev, name="genicam")
    with ViewerServer(source) as server:
        page = open_page(browser, server)
        wait_for(page, "window.planeray.panels[0].painted >= 3")
        data, header, _, _ = frame(page)
        shown = _captured(source, header["frame_index"])
        np.testing.assert_array_equal(data, shown.image)
        # the camera's frame: some id of the fake's generator, at the exposure asked
        ids = [*range(65401, 65536), *range(1, 2000)]
        assert any(np.array_equal(data, expected_image([i], data.shape, 600.0, gain=1)) for i in ids)
        done(page)
    assert dev.aravis_device is None  # released when the server stopped


def test_the_live_transport_of_a_sweep_in_the_page(browser, tmp_path):
    """``view --device sim --sweep``: the transport's views painted as updates arrive, with rate and age."""
    from planeray import synthesis as syn
    from planeray.timing import quick_sweep
    from planeray.viewer.live import LiveTransportSource

    dev = open_device("sim", scene="wax", size=(16, 20), projector_rows=90, frames_averaged=1)
    source = LiveTransportSource(dev, quick_sweep(), name="sim", max_fps=120.0, snapshot_dir=tmp_path)
    with ViewerServer(source) as server:
        page = open_page(browser, server)
        assert page.is_visible("#save-stack")
        wait_for(page, "window.planeray.panels[0].image.header.transport_number >= 3", timeout_s=60)
        # a painted frame is the sharpened epipolar image of the transport it names
        for _ in range(50):
            data, header, _, _ = frame(page)
            update = source._update
            if header["transport_number"] == update.number:
                break
        else:  # pragma: no cover - the page always catches up within 50 tries
            raise AssertionError("no frame of the newest transport")
        np.testing.assert_array_equal(data, syn.sharpened_epipolar(update.transport, width_rows=1.0))
        label = page.text_content(".panel[data-panel='0'] .label")
        assert "live transport #" in label and "updates/s" in label and "age" in label
        assert header["update_rate_hz"] > 0 and header["age_s"] >= 0
        # relit by a projector row: the transport's relighting
        page.select_option(".panel[data-panel='0'] select.mode", "relight_row")
        wait_for(page, "window.planeray.panels[0].image.header.settings.mode === 'relight_row'")
        # save stack: the window of the transport shown, a stack planeray demux reads
        page.click("#save-stack")
        saved = wait_for(page, "window.planeray.lastStack")
        st = read_stack(saved["path"], lazy=False)
        assert len(st) == int((~quick_sweep().excluded).sum()) and not st.excluded.any()
        page.screenshot(path=str(tmp_path / "live_transport.png"))
        done(page)
    assert not source.capture._thread.is_alive()

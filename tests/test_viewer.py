"""The viewer without a browser: what a PATH renders, its pixel plots, the display mapping, the server's
protocol and safety, the video, the command line.  The page itself is tested in test_viewer_browser.py."""

from __future__ import annotations

import asyncio
import json
import os
import signal
import subprocess
import sys
import urllib.error
import urllib.request
from pathlib import Path

import numpy as np
import pytest

from planeray import synthesis as syn
from planeray.acquire import simulate_stack
from planeray.camera import CameraModel
from planeray.errors import InputError
from planeray.io import write_stack, write_transport
from planeray.profiles import measured_delay_profiles
from planeray.scenes import make_scene
from planeray.timing import PAPER_LINES_PER_SECOND, Band, Sweep, quick_sweep
from planeray.transport import Transport
from planeray.viewer import display
from planeray.viewer.server import ViewerServer, decode_frame, encode_frame
from planeray.viewer.session import (
    MODES,
    StackSource,
    TransportSource,
    ViewSettings,
    open_source,
    pattern_rows,
    pixel_band_profile,
)

LPS = PAPER_LINES_PER_SECOND


@pytest.fixture(scope="module")
def scene():
    return make_scene("mirror_ball", (24, 24), projector_rows=96, seed=0)


@pytest.fixture(scope="module")
def truth_store(tmp_path_factory, scene):
    path = tmp_path_factory.mktemp("viewer") / "truth.zarr"
    write_transport(scene.transport, path, attrs={"lines_per_second": LPS, "method": "ground_truth"})
    return path


@pytest.fixture(scope="module")
def stack_store(tmp_path_factory, scene):
    path = tmp_path_factory.mktemp("viewer") / "stack.zarr"
    write_stack(simulate_stack(scene, quick_sweep(), seed=0), path)
    return path


# ----------------------------------------------------------------------------- settings
def test_settings_parse_and_refuse_by_name():
    s = ViewSettings.from_dict({"mode": "sharpened", "width_rows": 2, "noise": True, "row": 5.0})
    assert (s.mode, s.width_rows, s.noise, s.row) == ("sharpened", 2.0, True, 5)
    for bad, words in [
        ({"delay": 1}, "unknown setting 'delay'"),
        ({"delay_us": float("nan")}, "'delay_us' must be a finite number"),
        ({"delay_us": "3"}, "'delay_us' must be a finite number"),
        ({"exposure_us": True}, "'exposure_us' must be a finite number"),
        ({"noise": 1}, "'noise' must be true or false"),
        ({"row": 2.5}, "'row' must be an integer"),
        ({"mode": 3}, "'mode' must be a string"),
        ([1, 2], "settings must be a JSON object"),
    ]:
        with pytest.raises(InputError, match=words):
            ViewSettings.from_dict(bad)


def test_patterns():
    assert pattern_rows("full", 5).tolist() == [1.0] * 5
    assert pattern_rows("ramp", 3).tolist() == [0.0, 0.5, 1.0]
    sine = pattern_rows("sine", 96, period_rows=48, phase_deg=90)
    assert sine.min() >= 0 and sine.max() <= 1 and abs(sine[0] - 0.5) < 1e-12
    with pytest.raises(InputError, match="unknown pattern"):
        pattern_rows("checker", 10)
    with pytest.raises(InputError, match="period"):
        pattern_rows("sine", 10, period_rows=1)


# ----------------------------------------------------------------------------- transport sources
def test_transport_modes_are_the_synthesis_functions(truth_store, scene):
    src = open_source(truth_store)
    T = scene.transport
    assert src.kind == "transport" and src.shape == (24, 24)
    assert set(src.modes) == set(MODES)

    def show(**kw):
        image, info = src.render(ViewSettings(**kw))
        assert image.dtype == np.float32 and image.shape == (24, 24) and info["label"]
        return image

    assert np.array_equal(show(delay_us=375.0, exposure_us=600.0), syn.band_image(T, 375.0, 600.0))
    assert np.array_equal(show(delay_us=-213.7, exposure_us=91.0), T.render(Band(-213.7, 91.0, LPS)))
    assert np.array_equal(show(mode="epipolar"), syn.epipolar_image(T))
    assert np.allclose(show(mode="non_epipolar"), syn.non_epipolar_image(T), atol=1e-6)
    assert np.array_equal(show(mode="sharpened", width_rows=1.5), syn.sharpened_epipolar(T, width_rows=1.5))
    short, long = syn.short_long_range(T, 12.0)
    assert np.allclose(show(mode="short_range", max_rows=12.0), short, atol=1e-5)
    assert np.allclose(show(mode="long_range", max_rows=12.0), long, atol=1e-5)
    assert np.array_equal(show(mode="relight_row", row=40), syn.relight(T, syn.single_line_pattern(96, 40)))
    pattern = pattern_rows("stripes", 96, period_rows=16, phase_deg=30)
    assert np.array_equal(
        show(mode="relight_pattern", pattern="stripes", period_rows=16, phase_deg=30), syn.relight(T, pattern)
    )


def test_transport_refuses_what_it_cannot_show(truth_store):
    src = open_source(truth_store)
    for settings, words in [
        (ViewSettings(mode="xray"), "unknown mode 'xray'"),
        (ViewSettings(exposure_us=0.0), "exposure_us must be positive"),
        (ViewSettings(mode="relight_row", row=96), "projector row 96 outside 0..95"),
        (ViewSettings(mode="relight_pattern", pattern="nope"), "unknown pattern 'nope'"),
        (ViewSettings(noise=True), "toggles of a scene"),
        (ViewSettings(mode="sharpened", width_rows=-1.0), "width_rows must be positive"),
    ]:
        with pytest.raises(InputError, match=words):
            src.render(settings)
    with pytest.raises(InputError, match=r"pixel \(24, 0\) outside the 24x24 image"):
        src.pixel(24, 0, ViewSettings())
    with pytest.raises(InputError, match="two integers"):
        src.pixel("a", 0, ViewSettings())


def test_transport_pixel_plot_data(truth_store, scene):
    src = open_source(truth_store)
    r, c = 10, 13
    data = src.pixel(r, c, ViewSettings(delay_us=375.0, exposure_us=600.0))
    T = scene.transport
    assert data["estimate"]["offsets_rows"] == T.offsets_rows.tolist()
    assert np.array_equal(np.array(data["estimate"]["T"], np.float32), T.dense[r, c])
    assert data["truth"]["T"] == data["estimate"]["T"] and data["truth_scale"] == 1.0  # a ground-truth store
    lo, hi = data["window_rows"]
    assert lo == pytest.approx(375 * LPS * 1e-6 - 300 * LPS * 1e-6) and hi == pytest.approx(675 * LPS * 1e-6)
    hit = (T.sparse.row == r) & (T.sparse.col == c)
    assert data["estimate"]["sparse_offsets_rows"] == T.sparse.offset[hit].tolist()
    assert json.dumps(data)  # JSON as it is


def test_demultiplexed_store_with_truth_and_patterns(tmp_path, scene, truth_store):
    est = scene.transport
    est_path = tmp_path / "est.zarr"
    write_transport(est, est_path, attrs={"lines_per_second": LPS, "method": "fast", "epipolar_resolution_rows": 6.0})
    pattern = tmp_path / "my_pattern.npy"
    np.save(pattern, np.linspace(0, 1, 50))
    src = open_source(est_path, truth=truth_store, truth_scale=0.6, patterns=[pattern])
    assert src.describe()["patterns"][-1] == "my_pattern" and src.describe()["epipolar_resolution_rows"] == 6.0
    image, _ = src.render(ViewSettings(mode="relight_pattern", pattern="my_pattern"))
    assert np.array_equal(image, syn.relight(est, syn.load_pattern(pattern, 96)))
    data = src.pixel(3, 4, ViewSettings())
    assert data["truth_scale"] == 0.6 and data["truth"] is not None
    with pytest.raises(InputError, match="ground truth is 24x24"):
        TransportSource(make_scene("wax", (16, 16), projector_rows=96).transport, name="x", truth=est)


# ----------------------------------------------------------------------------- the virtual Episcan
def test_scene_is_the_simulated_device():
    src = open_source("wax", size=16, projector_rows=90, seed=3)
    scene = make_scene("wax", (16, 16), projector_rows=90, seed=3)
    cam = CameraModel()
    assert src.kind == "scene" and src.describe()["toggles"] == ["noise", "ambient"]
    # Noise-free: the camera's expected image of Eq. 4 with the camera's sync jitter.
    image, _ = src.render(ViewSettings(delay_us=187.5, exposure_us=750.0))
    expected = np.minimum(scene.transport.render(Band(187.5, 750.0, LPS, cam.jitter_us)) * cam.signal_scale, 1.0)
    assert np.allclose(image, expected, rtol=1e-6, atol=1e-7)
    # Synthesized modes are in the same units.
    epi, _ = src.render(ViewSettings(mode="epipolar"))
    assert np.allclose(epi, scene.transport.epipolar_image() * cam.signal_scale)
    # Noise and ambient: the same bytes as `planeray simulate` at these settings.
    sweep = Sweep(np.array([187.5, -375.0]), np.array([750.0, 600.0]), np.zeros(2, bool))
    stack = simulate_stack(scene, sweep, seed=3)
    for n in range(2):
        s = ViewSettings(delay_us=sweep.delay_us[n], exposure_us=sweep.exposure_us[n], noise=True, ambient=True)
        noisy, info = src.render(s)
        assert np.array_equal(noisy, stack.image(n))
        assert info["saturated"] == int(np.asarray(stack.saturated[n]).sum())
    ambient, _ = src.render(ViewSettings(ambient=True))
    plain, _ = src.render(ViewSettings())
    assert np.all(ambient >= plain) and ambient.mean() > plain.mean()


def test_open_source_errors(tmp_path):
    with pytest.raises(InputError, match="not a scene name.*wax"):
        open_source(tmp_path / "nothing_here")
    (tmp_path / "folder").mkdir()
    with pytest.raises(InputError, match="not a planeray stack, import folder or transport store"):
        open_source(tmp_path / "folder")
    with pytest.raises(InputError, match="its own ground truth"):
        open_source("wax", size=16, truth=tmp_path / "t.zarr")


# ----------------------------------------------------------------------------- stacks
def test_stack_source(stack_store, truth_store, scene):
    src = open_source(stack_store, truth=truth_store)
    assert isinstance(src, StackSource) and src.modes == ("band",)
    info = src.describe()
    assert info["delay_us"]["grid"] == [-1500.0, -1125.0, -750.0, -375.0, 0.0, 375.0, 750.0, 1125.0, 1500.0]
    assert info["exposure_us"]["grid"] == [600.0, 900.0, 1200.0]
    image, shown = src.render(ViewSettings(delay_us=400.0, exposure_us=1000.0))  # nearest captured
    assert (shown["delay_us"], shown["exposure_us"]) == (375.0, 900.0)
    assert np.array_equal(image, src.stack.image(shown["index"]))
    with pytest.raises(InputError, match="shows only band"):
        src.render(ViewSettings(mode="epipolar"))
    data = src.pixel(12, 12, ViewSettings(delay_us=0.0, exposure_us=600.0))
    prof = measured_delay_profiles(src.stack, [(12, 12)])
    assert np.allclose(np.array(data["raw"], float), prof.raw[0], equal_nan=True)
    assert np.allclose(np.array(data["normalized"], float), prof.values[0], equal_nan=True)
    # The ground truth's noise-free profile, one pixel at a time, is the band renderer's.
    fine = np.array(data["truth"]["delays_us"])
    k = len(fine) // 3
    full = scene.transport.render(Band(float(fine[k]), 900.0, LPS, src.stack.jitter_us))[12, 12]
    assert data["truth"]["raw"][1][k] == pytest.approx(float(full), rel=1e-5, abs=1e-9)
    assert json.dumps(data)


def test_import_folder_is_a_stack(tmp_path, stack_store):
    from planeray.io import export_folder, read_stack

    folder = export_folder(read_stack(stack_store), tmp_path / "captured")
    src = open_source(folder)
    assert src.kind == "stack" and src.describe()["n_images"] == 27
    image, shown = src.render(ViewSettings(delay_us=-375.0, exposure_us=1200.0))
    assert shown["label"].startswith("image ") and image.shape == (24, 24)
    with pytest.raises(InputError, match="relighting patterns need a transport"):
        open_source(folder, patterns=[tmp_path / "p.npy"])


def test_pixel_band_profile_matches_render(scene):
    T = scene.transport
    d = np.array([-700.0, 0.0, 310.0])
    prof = pixel_band_profile(T, 5, 7, d, 600.0, lines_per_second=LPS, jitter_us=5.0)
    expect = [T.render(Band(x, 600.0, LPS, 5.0))[5, 7] for x in d]
    assert np.allclose(prof, expect, rtol=1e-5, atol=1e-9)


# ----------------------------------------------------------------------------- display mapping
def test_display_mapping():
    image = np.array([[-1.0, 0.0, 0.25, 0.5, 1.0, 3.0, np.nan]], np.float32)
    codes = display.display_codes(image, white=1.0, gamma=1.0)
    assert codes[0].tolist() == [0, 0, 64, 128, 255, 255, 0]
    assert display.display_codes(np.array([0.25]), white=1.0, gamma=0.5).tolist() == [128]
    rgb = display.to_rgb(image, white=2.0, colormap="magma")
    assert rgb.shape == (1, 7, 3) and rgb.dtype == np.uint8
    tables = display.colormap_tables()
    assert set(tables) == set(display.COLORMAPS) and all(len(t) == 256 for t in tables.values())
    assert tables["gray"][255] == 0xFFFFFF
    with pytest.raises(InputError, match="colormap must be one of"):
        display.to_rgb(image, white=1.0, colormap="jet")
    with pytest.raises(InputError, match="white must be a positive number"):
        display.to_rgb(image, white=0.0)
    assert display.auto_white(np.zeros((4, 4))) == 1.0


def test_the_page_needs_no_internet():
    """Every asset ships in the package and names no other host (no CDN, no font service)."""
    from importlib import resources

    from planeray.viewer.server import STATIC_FILES

    root = resources.files("planeray.viewer") / "static"
    shipped = sorted(p.name for p in root.iterdir())
    assert shipped == sorted(STATIC_FILES)
    for name in shipped:
        text = (root / name).read_text(encoding="utf-8")
        assert "http://" not in text and "https://" not in text and "//cdn" not in text, name


def test_frame_encoding_round_trip():
    image = np.arange(12, dtype=np.float32).reshape(3, 4) / 7
    data = encode_frame(image, {"type": "frame", "label": "é"})
    (n,) = np.frombuffer(data[:4], "<u4")
    assert (4 + n) % 4 == 0
    header, back = decode_frame(data)
    assert header["width"] == 4 and header["height"] == 3 and header["label"] == "é"
    assert np.array_equal(back, image)


# ----------------------------------------------------------------------------- the server
@pytest.fixture(scope="module")
def server(truth_store):
    srv = ViewerServer(open_source(truth_store)).start()
    yield srv
    srv.stop()


def _get(url, headers=None):
    req = urllib.request.Request(url, headers=headers or {})
    try:
        with urllib.request.urlopen(req, timeout=10) as r:
            return r.status, r.read(), dict(r.headers)
    except urllib.error.HTTPError as e:
        with e:
            return e.code, e.read(), dict(e.headers)


def test_server_needs_the_token_and_serves_only_its_assets(server):
    base = f"http://127.0.0.1:{server.port}"
    status, body, headers = _get(server.url)
    assert status == 200 and b"<canvas" in body and "default-src 'self'" in headers["content-security-policy"]
    assert _get(f"{base}/")[0] == 403 and b"access token" in _get(f"{base}/")[1]
    assert _get(f"{base}/?token=wrong")[0] == 403
    status, body, _ = _get(f"{base}/api/info?token={server.token}")
    info = json.loads(body)
    assert status == 200 and info["source"]["kind"] == "transport" and "gray" in info["colormaps"]
    assert _get(f"{base}/api/info")[0] == 403
    assert _get(f"{base}/api/reports")[0] == 403

    async def report():  # what a page opened with ?bench= sends (no answer); the ping's answer follows it
        import websockets

        async with websockets.connect(_ws_url(server), compression=None) as ws:
            await ws.recv()
            await ws.send(json.dumps({"type": "report", "stats": {"fps": 12.5, "frames": 25}}))
            await ws.send(json.dumps({"type": "ping", "id": 1}))
            await asyncio.wait_for(ws.recv(), 20)

    asyncio.run(report())
    status, body, _ = _get(f"{base}/api/reports?token={server.token}")
    assert status == 200 and json.loads(body)[-1] == {"fps": 12.5, "frames": 25}
    assert _get(f"{base}/static/app.js")[0] == 200
    for path in [
        "/static/../session.py",
        "/static/..%2fsession.py",
        "/static/%2e%2e%2f%2e%2e%2fpyproject.toml",
        "/static/session.py",
        "/etc/passwd",
        "/static/",
    ]:
        status, body, _ = _get(base + path)
        assert status == 404, path
    req = urllib.request.Request(server.url, data=b"x", method="POST")
    with pytest.raises(urllib.error.HTTPError) as err:
        urllib.request.urlopen(req, timeout=10)
    with err.value as e:
        assert e.code == 405 and b"Method Not Allowed" in e.read()
    # DNS rebinding: a page of another name that resolves to 127.0.0.1 gets nothing.
    assert _get(server.url, {"Host": f"evil.example:{server.port}"})[0] == 403
    status, body, _ = _get(f"{base}/api/info?token={server.token}", {"Host": f"localhost:{server.port}"})
    assert status == 200


def _ws_url(server, token=None):
    return f"ws://127.0.0.1:{server.port}/ws?token={token or server.token}"


async def _session(server, messages, *, token=None, origin=None):
    """Connect, send each message, collect one answer per message."""
    import websockets

    headers = {"Origin": origin} if origin else None
    answers = []
    async with websockets.connect(
        _ws_url(server, token), max_size=None, compression=None, additional_headers=headers
    ) as ws:
        hello = json.loads(await ws.recv())
        for msg in messages:
            await ws.send(msg if isinstance(msg, str | bytes) else json.dumps(msg))
            answers.append(await asyncio.wait_for(ws.recv(), 20))
    return hello, answers


def test_websocket_protocol(server, scene):
    settings = {"delay_us": 375.0, "exposure_us": 700.0}
    hello, answers = asyncio.run(
        _session(
            server,
            [
                "not json",
                {"type": "launch"},
                {"type": "render", "panel": 9},
                b"\x00\x01",
                {"type": "render", "panel": 0, "id": 7, "settings": {"delay_us": "x"}},
                {"type": "render", "panel": 1, "id": 8, "settings": {"mode": "xray"}},
                {"type": "pixel", "panel": 0, "id": 9, "row": 99, "col": 0},
                {"type": "render", "panel": 0, "id": 10, "settings": settings},
                {"type": "pixel", "panel": 0, "id": 11, "row": 3, "col": 4, "settings": settings},
                {"type": "ping", "id": 12},
            ],
        )
    )
    assert hello["type"] == "hello" and hello["source"]["shape"] == [24, 24]
    errors = [json.loads(a) for a in answers[:7]]
    assert all(e["type"] == "error" for e in errors)
    assert "bad request" in errors[0]["message"]
    assert "unknown message type 'launch'" in errors[1]["message"]
    assert "panel must be an integer 0..3" in errors[2]["message"]
    assert "binary messages" in errors[3]["message"]
    assert errors[4]["id"] == 7 and "'delay_us' must be a finite number" in errors[4]["message"]
    assert errors[5]["panel"] == 1 and "unknown mode 'xray'" in errors[5]["message"]
    assert "outside the 24x24 image" in errors[6]["message"]
    header, image = decode_frame(answers[7])  # the connection survived every bad request
    assert header["id"] == 10 and header["settings"]["delay_us"] == 375.0
    assert np.array_equal(image, scene.transport.render(Band(375.0, 700.0, LPS)))
    for key in ("render_ms", "encode_ms", "queue_ms", "sent_at_ms", "auto_white"):
        assert header[key] >= 0
    pixel = json.loads(answers[8])
    assert pixel["type"] == "pixel" and pixel["data"]["row"] == 3
    assert json.loads(answers[9])["type"] == "pong"


def test_websocket_refuses_without_token_or_from_another_origin(server):
    import websockets

    with pytest.raises(websockets.exceptions.WebSocketException):
        asyncio.run(_session(server, [], token="wrong"))
    with pytest.raises(websockets.exceptions.WebSocketException):
        asyncio.run(_session(server, [], origin="http://evil.example"))
    hello, _ = asyncio.run(_session(server, [], origin=f"http://127.0.0.1:{server.port}"))
    assert hello["type"] == "hello"


def test_render_requests_of_a_panel_are_coalesced(server):
    """A burst of requests (a fast drag) is answered by the newest, never by a queue of stale frames."""
    import websockets

    async def burst():
        async with websockets.connect(_ws_url(server), max_size=None, compression=None) as ws:
            await ws.recv()
            for i in range(40):
                await ws.send(json.dumps({"type": "render", "panel": 0, "id": i, "settings": {"delay_us": 10.0 * i}}))
            ids = []
            while not ids or ids[-1] != 39:
                header, _ = decode_frame(await asyncio.wait_for(ws.recv(), 20))
                ids.append(header["id"])
            return ids

    ids = asyncio.run(burst())
    assert ids == sorted(ids) and ids[-1] == 39 and len(ids) < 40


def test_a_flood_of_requests_is_bounded(server):
    import websockets

    async def flood():
        async with websockets.connect(_ws_url(server), max_size=None, compression=None) as ws:
            await ws.recv()
            for i in range(300):
                await ws.send(json.dumps({"type": "pixel", "id": i, "row": 1, "col": 1}))
            answers = [json.loads(await asyncio.wait_for(ws.recv(), 30)) for _ in range(300)]
            return answers

    answers = asyncio.run(flood())
    kinds = {a["type"] for a in answers}
    assert kinds <= {"pixel", "error"} and "pixel" in kinds
    refused = [a for a in answers if a["type"] == "error"]
    assert all("too many requests waiting" in a["message"] for a in refused)


def test_server_binds_loopback_and_falls_back_from_a_busy_port(truth_store):
    src = open_source(truth_store)
    first = ViewerServer(src, port=0)
    second = ViewerServer(src, port=first.port)
    try:
        assert first.host == "127.0.0.1" and first.loopback
        assert second.port != first.port and second.port_fallback
        assert len(first.token) >= 32 and first.token != second.token
    finally:
        first.sock.close()
        second.sock.close()


# ----------------------------------------------------------------------------- video
def _probe(path):
    """(frames, width, height, comment metadata, first frame as RGB) of a video, through the ffmpeg of imageio-ffmpeg."""
    import re
    import subprocess

    import imageio_ffmpeg

    exe = imageio_ffmpeg.get_ffmpeg_exe()
    n, _ = imageio_ffmpeg.count_frames_and_secs(str(path))
    info = subprocess.run([exe, "-hide_banner", "-i", str(path)], capture_output=True, text=True).stderr
    w, h = (int(x) for x in re.search(r"Video: .*?, (\d+)x(\d+)", info).groups())
    meta = subprocess.run(
        [exe, "-v", "error", "-i", str(path), "-f", "ffmetadata", "-"], capture_output=True, text=True
    )
    comment = json.loads(
        re.search(r"^comment=(.*)$", meta.stdout, re.MULTILINE | re.IGNORECASE).group(1).replace("\\", "")
    )
    raw = subprocess.run(
        [exe, "-v", "error", "-i", str(path), "-frames:v", "1", "-f", "rawvideo", "-pix_fmt", "rgb24", "-"],
        capture_output=True,
        check=True,
    ).stdout
    return n, w, h, comment, np.frombuffer(raw, np.uint8).reshape(h, w, 3)


def test_sweep_video(tmp_path, stack_store):
    from planeray.viewer.video import write_sweep_video

    src = open_source("diffuse_plane", size=32, projector_rows=96)
    out = write_sweep_video(src, tmp_path / "sweep.mp4", sweep="delay", frames=6, start_us=-600, stop_us=600)
    n, w, h, comment, first = _probe(out)
    assert n == 6 and w == 512 and h > 512  # 32 pixels upscaled 16 times, a caption strip below
    assert comment["sweep"] == "delay" and comment["values_us"] == [-600.0, -360.0, -120.0, 120.0, 360.0, 600.0]
    # The first frame is the page's colouring of the first band image (up to the codec's loss).
    image, _ = src.render(ViewSettings(delay_us=-600.0))
    expect = np.repeat(np.repeat(display.to_rgb(image, white=comment["display"]["white"]), 16, 0), 16, 1)
    assert np.abs(first[:512].astype(int) - expect).mean() < 4
    assert [p.name for p in tmp_path.iterdir()] == ["sweep.mp4"]  # written atomically
    with pytest.raises(InputError, match="already exists"):
        write_sweep_video(src, out, frames=3)
    with pytest.raises(InputError, match="must end in"):
        write_sweep_video(src, tmp_path / "sweep.avi", frames=3)
    with pytest.raises(InputError, match="mode band"):
        write_sweep_video(src, tmp_path / "b.mp4", settings=ViewSettings(mode="epipolar"))
    # A stack: one frame per captured exposure.
    stack = open_source(stack_store)
    out = write_sweep_video(stack, tmp_path / "exposures.webm", sweep="exposure", scale=4)
    n, w, h, comment, _ = _probe(out)
    assert n == 3 and w == 96 and comment["values_us"] == [600.0, 900.0, 1200.0]


# ----------------------------------------------------------------------------- command line
def test_cli_video_and_errors(tmp_path):
    from typer.testing import CliRunner

    from planeray.cli import app

    runner = CliRunner()
    out = tmp_path / "v.mp4"
    res = runner.invoke(app, ["video", "diffuse_plane", "--size", "16", "24", "--projector-rows", "64", "--frames", "4",
                              "--out", str(out)])  # fmt: skip
    assert res.exit_code == 0, res.output
    assert out.is_file()
    for args, words in [
        (["video", "diffuse_plane", "--out", str(out)], "already exists"),
        (["video", "no_such_scene", "--out", str(tmp_path / "x.mp4")], "not a scene name"),
        (
            ["video", "diffuse_plane", "--size", "16", "16", "--sweep", "gain", "--out", str(tmp_path / "y.mp4")],
            "delay or exposure",
        ),
        (["view", str(tmp_path / "missing.zarr"), "--no-browser"], "not a scene name"),
    ]:
        res = runner.invoke(app, args)
        assert res.exit_code == 1 and words in res.output and "Traceback" not in res.output, res.output


def test_cli_view_serves_until_interrupted():
    """`planeray view wax` as a user runs it: prints the URL, serves the page, stops on Ctrl-C."""
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1] / "src")}
    env.pop("DISPLAY", None)
    proc = subprocess.Popen(
        [sys.executable, "-m", "planeray.cli", "view", "wax", "--size", "32", "--port", "0", "--no-browser"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    try:
        url = proc.stdout.readline().strip()
        assert url.startswith("http://127.0.0.1:") and "?token=" in url
        status, body, _ = _get(url)
        assert status == 200 and b"planeray" in body
        status, body, _ = _get(url.replace("/?token=", "/api/info?token="))
        assert json.loads(body)["source"]["name"] == "wax"
    finally:
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=20)
    assert proc.returncode == 0, err
    assert "Traceback" not in err


def test_a_failing_render_or_a_vanishing_page_never_stops_the_server(truth_store, scene):
    import websockets

    source = open_source(truth_store)
    original = source._render

    def flaky(settings, buffers):
        if settings.delay_us == 13.0:
            raise RuntimeError("the renderer broke")
        return original(settings, buffers)

    source._render = flaky
    with ViewerServer(source) as srv:

        async def vanish():  # ask for frames and leave before they come
            async with websockets.connect(_ws_url(srv), max_size=None, compression=None) as ws:
                await ws.recv()
                for i in range(5):
                    await ws.send(json.dumps({"type": "render", "panel": i % 2, "id": i}))

        asyncio.run(vanish())
        hello, answers = asyncio.run(
            _session(
                srv,
                [
                    {"type": "render", "panel": 0, "id": 1, "settings": {"delay_us": 13.0}},
                    {"type": "render", "panel": 0, "id": 2, "settings": {"delay_us": 14.0}},
                ],
            )
        )
    error = json.loads(answers[0])
    assert error["type"] == "error" and error["id"] == 1
    assert error["message"] == "internal error (RuntimeError: the renderer broke)"
    header, image = decode_frame(answers[1])
    assert header["id"] == 2 and np.array_equal(image, scene.transport.render(Band(14.0, 600.0, LPS)))


# ----------------------------------------------------------------------------- a fresh server is a warm one
def test_frames_are_rendered_into_the_sources_reused_buffers(truth_store):
    """The server's path (``ViewSource.frame``) renders every frame into the same buffers, with the bytes of
    ``render`` (whose arrays stay the caller's: a later frame never overwrites them)."""
    for src in (open_source("wax", size=16, projector_rows=90), open_source(truth_store)):
        src.warm()
        pointers = set()
        band = [ViewSettings(delay_us=d, exposure_us=e) for d, e in ((0.0, 600.0), (375.0, 900.0), (-750.0, 600.0))]
        others = [ViewSettings(mode="non_epipolar"), ViewSettings(mode="long_range", max_rows=5.0)]
        for s in band + others:
            want, want_info = src.render(s)
            with src.frame(s) as (image, info):
                assert np.array_equal(image, want) and info == want_info, s
                assert not np.shares_memory(image, want)
                if s.mode == "band":
                    pointers.add(image.__array_interface__["data"][0])
        assert len(pointers) == 1, "every band frame in one buffer"
        kept, _ = src.render(ViewSettings(delay_us=0.0))
        copy = kept.copy()
        with src.frame(ViewSettings(delay_us=900.0)) as (image, _):
            assert not np.array_equal(image, copy)
        assert np.array_equal(kept, copy)


def test_a_warm_frame_allocates_nothing_the_size_of_a_frame():
    """After warm-up a frame of the virtual Episcan (band render, camera response) allocates no
    frame-sized array: tracemalloc's peak while rendering it stays below half the frame's bytes,
    where ``render`` (new arrays: the image, the float64 electrons) peaks at several frames."""
    import tracemalloc

    H, W = 32, 2048  # wide rows, few offsets: the (H, U) illumination weights are tiny next to a frame
    rng = np.random.default_rng(0)
    T = Transport(rng.random((H, W, 9), dtype=np.float32) * 0.2, np.arange(-4, 5))
    src = TransportSource(T, name="wide", kind="scene", camera=CameraModel())
    src.warm()
    frame_bytes = H * W * 4
    tracemalloc.start()
    try:
        for d in (-80.0, 0.0, 45.0, 90.0):
            tracemalloc.reset_peak()
            base = tracemalloc.get_traced_memory()[0]
            with src.frame(ViewSettings(delay_us=d, exposure_us=150.0)) as (image, info):
                assert image.shape == (H, W) and info["saturated"] >= 0
            peak = tracemalloc.get_traced_memory()[1] - base
            assert peak < frame_bytes / 2, f"a warm frame allocated {peak} bytes (a frame is {frame_bytes})"
        tracemalloc.reset_peak()
        base = tracemalloc.get_traced_memory()[0]
        src.render(ViewSettings(delay_us=0.0, exposure_us=150.0))
        assert tracemalloc.get_traced_memory()[1] - base >= 3 * frame_bytes  # the measurement sees new frames
    finally:
        tracemalloc.stop()


def test_server_renders_in_one_thread_and_is_warm_before_serving(truth_store):
    src = open_source(truth_store)
    with ViewerServer(src) as srv:
        assert len(src._buffers) > 0  # warmed: the first frame's buffers exist before any page asked
        threads = set()
        original = src._render

        def spy(settings, buffers):
            import threading

            threads.add(threading.current_thread().name)
            return original(settings, buffers)

        src._render = spy
        messages = [{"type": "render", "panel": i % 2, "id": i, "settings": {"delay_us": 40.0 * i}} for i in range(6)]
        _, answers = asyncio.run(_session(srv, messages))
        assert [decode_frame(a)[0]["id"] for a in answers] == list(range(6))
        assert len(threads) == 1 and threads.pop().startswith("planeray-render")


@pytest.mark.skipif(
    not Path("/proc/self/stat").exists() or __import__("platform").libc_ver()[0] != "glibc",
    reason="page faults read from /proc; the allocator setting is glibc's",
)
def test_the_test_workers_allocator_settings_are_the_servers():
    """conftest.py cannot import the server (1 s) to read them: its GLIBC_TUNABLES copy them, checked here."""
    import inspect
    import sys

    from planeray.viewer.server import keep_freed_memory

    defaults = {k: p.default for k, p in inspect.signature(keep_freed_memory).parameters.items()}
    expected = (
        f"glibc.malloc.mmap_threshold={defaults['mmap_threshold_bytes']}"
        f":glibc.malloc.trim_threshold={defaults['trim_threshold_bytes']}"
    )
    assert sys.modules["conftest"]._MALLOC_TUNABLES == expected


def test_a_freshly_started_server_reuses_its_memory_frame_after_frame(tmp_path):
    """`planeray view` as a user starts it, asked for a drag of frames: after the first few, the server
    process faults in (almost) no new memory per frame.  Each frame computes megabytes of temporaries
    (here, as in a 512-row scene, the (H, U) = (512, 257) float64 illumination weights and what is made
    of them); by default glibc returned them to the system and faulted them in again page by page,
    every frame (740 page faults per frame here, 1000 for the 512x512 wax scene)."""
    from websockets.sync.client import connect

    H, W, U = 512, 8, 257
    rng = np.random.default_rng(1)
    T = Transport(rng.random((H, W, U), dtype=np.float32), np.arange(U) - U // 2)
    store = write_transport(T, tmp_path / "tall.zarr", attrs={"lines_per_second": LPS})
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1] / "src")}
    env.pop("DISPLAY", None)
    env.pop("GLIBC_TUNABLES", None)  # glibc's defaults: the server's own setting is what this checks (conftest.py)
    proc = subprocess.Popen(
        [sys.executable, "-m", "planeray.cli", "view", str(store), "--port", "0", "--no-browser"],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
        env=env,
    )

    def faults() -> int:
        with open(f"/proc/{proc.pid}/stat") as f:
            return int(f.read().rsplit(")", 1)[1].split()[7])

    try:
        url = proc.stdout.readline().strip()
        host, token = url.split("//")[1].split("/")[0], url.split("token=")[1]
        per_frame = []
        with connect(f"ws://{host}/ws?token={token}", max_size=None, compression=None) as ws:
            ws.recv()
            for i in range(40):
                f0 = faults()
                ws.send(json.dumps({"type": "render", "panel": 0, "id": i, "settings": {"delay_us": 7.0 * i}}))
                header, image = decode_frame(ws.recv())
                per_frame.append(faults() - f0)
                assert header["id"] == i and image.shape == (H, W)
    finally:
        proc.send_signal(signal.SIGINT)
        proc.communicate(timeout=20)
    weight_pages = H * U * 8 // 4096  # one (H, U) float64 array
    assert np.mean(per_frame[10:]) < weight_pages / 8, per_frame

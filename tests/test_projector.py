"""The projector window against a real X server: Xvfb with two 1280x720 screens, read back from the screen itself.

Every pattern is compared pixel for pixel with an independent construction in the
test, on a screenshot of the chosen screen taken by the X server (not of the
window's buffer); the other screen must stay untouched.
"""

import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from typer.testing import CliRunner

from planeray.cli import app
from planeray.errors import InputError
from xvfb import display_for_tests, send_key


@pytest.fixture(scope="module")
def xdisplay():
    yield from display_for_tests()


@pytest.fixture(scope="module")
def window(xdisplay):
    from planeray.projector import ProjectorWindow

    with ProjectorWindow(1) as win:
        yield win


def screenshot(index):
    from planeray.projector import grab_screen, list_screens

    return grab_screen(list_screens()[index])


def test_the_screens_are_listed(xdisplay):
    from planeray.projector import list_screens

    screens = list_screens()
    assert [(s.index, s.x_screen, s.shape) for s in screens] == [(0, 0, (720, 1280)), (1, 1, (720, 1280))]
    assert screens[1].x_display == f"{xdisplay}.1"


def test_every_pattern_is_on_the_chosen_screen_pixel_for_pixel(window, tmp_path):
    from PIL import Image

    from planeray.projector import black, comb, parse_pattern, rectification_card, rows, white

    H, W = 720, 1280
    rng = np.random.default_rng(5)
    noise = rng.integers(0, 256, (H, W, 3), dtype=np.uint8)
    Image.fromarray(noise).save(tmp_path / "noise.png")
    cases = {
        "white": (white((H, W)), np.full((H, W, 3), 255)),
        "black": (black((H, W)), np.zeros((H, W, 3))),
        "row 360": (rows((H, W), 360), np.where((np.arange(H) == 360)[:, None, None], 255, 0) + np.zeros((1, W, 3))),
        "rows 100-140": (
            rows((H, W), 100, 140),
            np.where(((np.arange(H) >= 100) & (np.arange(H) <= 140))[:, None, None], 255, 0) + np.zeros((1, W, 3)),
        ),
        "image file": (parse_pattern(str(tmp_path / "noise.png"), (H, W)), noise),
        "float array": (noise[:, :, 1] / 255.0, np.repeat(noise[:, :, 1:2], 3, axis=2)),
    }
    for name, (pattern, expected) in cases.items():
        window.show(pattern)
        shot = screenshot(1)
        assert shot.shape == (H, W, 3), name
        np.testing.assert_array_equal(shot, expected.astype(np.uint8), err_msg=name)
        assert screenshot(0).max() == 0, name  # the other screen is untouched
    # the comb of Sec. 6: 720 rows, phase j, lit rows j, j + k, ... and nothing else
    k, j = 7, 3
    window.show(comb((H, W), k, j))
    shot = screenshot(1)
    lit = np.flatnonzero(shot.max(axis=(1, 2)))
    np.testing.assert_array_equal(lit, np.arange(j, H, k))
    assert (shot[lit] == 255).all() and shot[np.setdiff1d(np.arange(H), lit)].max() == 0
    # the rectification card: one-pixel full-width lines every 40 rows
    window.show(rectification_card((H, W)))
    shot = screenshot(1)
    full = np.flatnonzero((shot[:, :, 0] == 255).all(axis=1))
    np.testing.assert_array_equal(full, np.arange(0, H, 40))


def test_a_pattern_of_another_size_is_refused_unless_placed(window):
    small = np.full((10, 20), 200, np.uint8)
    with pytest.raises(InputError, match=r"20x10 pixels, screen 1 is 1280x720.*place"):
        window.show(small)
    window.show(small, at=(700, 1000))
    expected = np.zeros((720, 1280), np.uint8)
    expected[700:710, 1000:1020] = 200
    np.testing.assert_array_equal(screenshot(1)[:, :, 2], expected)
    with pytest.raises(InputError, match="does not fit"):
        window.show(small, at=(715, 0))


def test_cli_lists_screens_and_refuses_bad_input_in_one_line(xdisplay, tmp_path):
    from PIL import Image

    runner = CliRunner()
    res = runner.invoke(app, ["project", "--list-screens"])
    assert res.exit_code == 0 and "screen 1: 1280x720" in res.output
    Image.fromarray(np.zeros((100, 100), np.uint8)).save(tmp_path / "small.png")
    for args, text in (
        (["project", "white", "--screen", "2"], "no screen 2"),
        (["project", str(tmp_path / "small.png"), "--screen", "1"], "100x100 pixels, screen 1 is 1280x720"),
        (["project", "comb:0:1", "--screen", "1"], "step_rows"),
        (["project", str(tmp_path / "missing.png")], "pattern file not found"),
    ):
        res = runner.invoke(app, args)
        assert res.exit_code == 1, (args, res.output)
        assert text in res.output and len(res.output.strip().splitlines()) == 1, res.output


def _wait_for(predicate, what, timeout_s=20.0):
    deadline = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError(f"waited {timeout_s} s for {what}")
        time.sleep(0.05)


@pytest.mark.parametrize("close_with", ["Escape", "SIGINT"])
def test_project_closes_on_esc_or_ctrl_c_and_leaves_the_screen_as_it_was(xdisplay, close_with):
    before = screenshot(1)
    cmd = [sys.executable, "-m", "planeray.cli", "project", "white", "--screen", "1"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, env=dict(os.environ))
    try:
        _wait_for(lambda: screenshot(1).min() == 255, "the white window on screen 1")
        if close_with == "Escape":
            send_key(xdisplay, 1, "Escape")
        else:
            proc.send_signal(signal.SIGINT)
        output = proc.communicate(timeout=20)[0].decode()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == (0 if close_with == "Escape" else 130), output
    assert ("closed (escape)" in output) if close_with == "Escape" else ("interrupted" in output)
    _wait_for(lambda: np.array_equal(screenshot(1), before), "the screen as it was")

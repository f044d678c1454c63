"""Messages that explain, and degenerate inputs refused (issue 40): what a careless user met, in one line each."""

from __future__ import annotations

import errno
import os

import numpy as np
import pytest

from _new_user import run_bad, user_files
from test_faults import failing_folder  # noqa: F401  (the fixture: writes under a folder fail)


@pytest.fixture
def folder(tmp_path):
    user_files(tmp_path / "user")
    return tmp_path / "user"


def test_the_current_folder_as_an_output_is_named_as_such(folder, monkeypatch):
    monkeypatch.chdir(folder)
    for args in (
        ("skin", "simulate", "--size", 16, 16, "--out", "."),  # was: "PosixPath('.') has an empty name"
        ("simulate", "wax", "--size", 8, 8, "--out", "..", "--overwrite"),
    ):
        run_bad(args, folder=folder, option="--out", needles=("is the current folder",))


def test_a_transport_with_negative_light_is_no_scene(folder, tmp_path):
    """A pinv demux (or a sign error) stored as a transport: simulating it is refused, naming the store."""
    import planeray as pr
    from planeray.io import write_transport

    scene = pr.make_scene("diffuse_plane", (8, 8), projector_rows=16, seed=0)
    T = scene.transport
    T.dense[2, 3, T.dense.shape[2] // 2] = -0.25
    store = write_transport(T, tmp_path / "neg.zarr")
    line = run_bad(["simulate", store, "--out", "{d}/s.zarr"], folder=folder, needles=("1 negative entries", "-0.25"))
    assert "neg.zarr" in line


def test_a_projector_with_no_column_is_refused(folder):
    run_bad(
        ["render", "mirror_ball", "--size", 8, 8, "--rows", 16, "--projector-aspect", "1e-9", "--out", "{d}/r.zarr"],
        folder=folder,
        option="--projector-aspect",
        needles=(">= 0.1",),
    )


def _noise_images(n):
    rng = np.random.default_rng(0)
    return [rng.normal(100, 10, (288, 64)) for _ in range(n)]


def test_noise_is_no_comb_of_lines(folder):
    """Pure noise, once "lines reaching the image border" (the 4th of these): now what it is, for every one."""
    import tifffile

    from planeray.calibration.lines import count_lines
    from planeray.errors import InputError

    images = _noise_images(12)
    tifffile.imwrite(folder / "noise.tif", images[3].astype(np.uint16))
    run_bad(
        ["calibrate", "lines", "{d}/noise.tif", "--exposure-us", 500, "--rows-per-line", 4],
        folder=folder,
        needles=("no comb of lit lines found",),
    )
    for image in images:
        with pytest.raises(InputError, match="no (comb of )?lit lines|need at least 3"):
            count_lines(image)


def test_a_video_onto_a_read_only_folder_gives_one_line_without_ffmpegs_command(folder, failing_folder):  # noqa: F811
    (folder / "ro").mkdir()
    failing_folder(folder / "ro", errno.EROFS)
    line = run_bad(["video", "wax", "--size", 16, "--out", "{d}/ro/v.mp4"], folder=folder, needles=("v.mp4",))
    assert os.strerror(errno.EROFS) in line and "FFMPEG" not in line.upper()


def test_an_encoders_failure_is_its_first_line():
    from planeray.io.atomic import storage_error

    exc = OSError(
        "[Errno 32] Broken pipe\n\nFFMPEG COMMAND:\n/usr/bin/ffmpeg -y -f rawvideo ... out.mp4\n\nFFMPEG STDERR:"
    )
    text = str(storage_error(exc, "out.mp4"))
    assert text == "out.mp4: cannot write: OSError: [Errno 32] Broken pipe"


def test_a_folder_that_is_no_store_is_named_without_zarrs_exception_names(folder):
    (folder / "empty").mkdir()
    for command in (
        ["demux", "{d}/empty", "--out", "{d}/T.zarr"],
        ["synth", "{d}/empty", "--epipolar", "--out", "{d}/e.png"],
    ):
        line = run_bad(command, folder=folder, needles=("no zarr.json",))
        assert "GroupNotFound" not in line and "Error" not in line.split(":", 2)[-1]

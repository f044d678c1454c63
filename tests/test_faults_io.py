"""Fault injection in the io layer: absent or corrupt chunks, odd pixel types, duplicated manifest lines.

Whatever is wrong, the user gets one line naming the file and the problem (or an
explicit, documented option to accept it), never zeros or a traceback.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import tifffile
import zarr
from PIL import Image
from typer.testing import CliRunner

from planeray import io
from planeray.acquire import acquire_to_store, simulate_stack
from planeray.cli import app
from planeray.demux import demultiplex_to_store
from planeray.devices import SimulatedEpiscan
from planeray.errors import StackError, TransportError
from planeray.io._common import ALL_CHUNKS_ATTR, absent_chunks
from planeray.scenes import make_scene
from planeray.stack import Stack
from planeray.timing import RowGeometry, paper_sweep, quick_sweep
from planeray.transport import Transport

#: what these tests check is what happens to files, not what the figures show (conftest.py)
pytestmark = pytest.mark.usefixtures("figures_not_drawn")

runner = CliRunner()


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


def error_lines(output: str) -> list[str]:
    return [line for line in output.splitlines() if line.strip()]


def small_stack(n=4, h=64, w=20, seed=0, **kwargs):
    rng = np.random.default_rng(seed)
    images = rng.random((n, h, w), dtype=np.float32)
    return Stack(
        images=images,
        delay_us=np.linspace(-750.0, 750.0, n),
        exposure_us=np.full(n, 600.0),
        lines_per_second=54000.0,
        **kwargs,
    )


def chunk_file(store: Path, array: str, *coords: int) -> Path:
    """The file of one chunk in a Zarr v3 directory store (default ``c/i/j/k`` keys)."""
    return store / array / "c" / Path(*(str(c) for c in coords))


def all_chunks_present(store: Path) -> dict:
    group = zarr.open_group(str(store), mode="r")
    return {name: absent_chunks(member)[0] for name, member in group.members() if isinstance(member, zarr.Array)}


def corrupt(file: Path) -> None:
    """Overwrite 16 bytes in the middle of a chunk file (the zstd checksum catches it)."""
    data = bytearray(file.read_bytes())
    middle = len(data) // 2
    data[middle : middle + 16] = bytes(16)
    file.write_bytes(bytes(data))


@pytest.fixture(scope="module")
def wax_store(tmp_path_factory):
    """A simulated 16x16 stack store: one chunk (1, 16, 16) per image."""
    stack = simulate_stack(make_scene("wax", (16, 16), projector_rows=90, seed=0), quick_sweep(), seed=0)
    return io.write_stack(stack, tmp_path_factory.mktemp("wax") / "wax.zarr")


@pytest.fixture
def wax_copy(wax_store, tmp_path):
    import shutil

    return Path(shutil.copytree(wax_store, tmp_path / "wax.zarr"))


# ----------------------------------------------------------------------------
# complete stores: planeray writes every chunk, so an absent one is lost data
# ----------------------------------------------------------------------------
def test_written_stack_stores_every_chunk_also_empty_ones(tmp_path):
    stack = small_stack()
    stack.images[1] = 0.0  # all fill value
    out = io.write_stack(stack, tmp_path / "s.zarr")  # no mask: all False
    assert zarr.open_group(str(out), mode="r").attrs[ALL_CHUNKS_ATTR] is True
    assert all(not missing for missing in all_chunks_present(out).values())
    back = io.read_stack(out, lazy=False)
    assert not back.images[1].any() and not back.saturated.any()


def test_missing_image_chunk_is_refused(tmp_path):
    out = io.write_stack(small_stack(), tmp_path / "s.zarr")
    chunk_file(out, "images", 2, 1, 0).unlink()
    for lazy in (True, False):
        with pytest.raises(StackError) as info:
            io.read_stack(out, lazy=lazy)
        message = str(info.value)
        assert message == (
            f"{out}: images: chunk (2, 1, 0) is missing (image 2, rows 32-63) -- the store is incomplete"
        )
    chunk_file(out, "images", 3, 0, 0).unlink()
    with pytest.raises(StackError, match=r"chunk \(2, 1, 0\) is missing .*\(2 of 8 chunks missing\)"):
        io.read_stack(out)


@pytest.mark.parametrize(
    ("array", "coords", "where"), [("saturated", (1, 0, 0), "image 1, rows 0-31"), ("excluded", (0,), "entries 0-3")]
)
def test_missing_mask_and_vector_chunks_are_refused(tmp_path, array, coords, where):
    out = io.write_stack(small_stack(), tmp_path / "s.zarr")
    chunk_file(out, array, *coords).unlink()
    with pytest.raises(StackError, match=rf"{array}: chunk \({coords[0]},.*is missing \({where}\)"):
        io.read_stack(out)


def test_stores_without_the_marker_keep_reading_absent_chunks_as_fill_value(tmp_path):
    """Older planeray skipped chunks equal to the fill value: nothing to check them against."""
    out = io.write_stack(small_stack(), tmp_path / "s.zarr")
    group = zarr.open_group(str(out), mode="r+")
    del group.attrs[ALL_CHUNKS_ATTR]
    chunk_file(out, "saturated", 0, 0, 0).unlink()
    back = io.read_stack(out, lazy=False)
    assert not back.saturated[0].any()


def test_missing_chunk_cli_demux_fails_in_one_line_without_partial(wax_copy, tmp_path):
    chunk_file(wax_copy, "images", 12, 0, 0).unlink()
    out = tmp_path / "T.zarr"
    res = invoke("demux", wax_copy, "--out", out)
    assert res.exit_code == 1
    lines = error_lines(res.output)
    assert len(lines) == 1, res.output
    assert str(wax_copy) in lines[0] and "images: chunk (12, 0, 0) is missing (image 12)" in lines[0]
    assert "Traceback" not in res.output
    assert sorted(p.name for p in tmp_path.iterdir()) == ["wax.zarr"]  # no output, no .partial


# ----------------------------------------------------------------------------
# corrupt chunks: one error naming the store, the chunk and the cause
# ----------------------------------------------------------------------------
def test_corrupt_image_chunk_is_named_lazily_and_eagerly(tmp_path):
    out = io.write_stack(small_stack(), tmp_path / "s.zarr")
    corrupt(chunk_file(out, "images", 2, 1, 0))
    lazy = io.read_stack(out)  # opening reads no image
    np.testing.assert_array_equal(lazy.images[1], small_stack().images[1])
    expected = rf"^{out}: images: cannot read chunk \(2, 1, 0\) \(image 2, rows 32-63\): RuntimeError: .*damaged$"
    for read in (
        lambda: lazy.images[2],
        lambda: lazy.images[:, 40:50, :],  # a row block of every image, as demultiplexing reads
        lambda: np.asarray(lazy.images),
        lambda: io.validate_images(lazy, out),
        lambda: io.read_stack(out, lazy=False),
    ):
        with pytest.raises(StackError, match=expected) as info:
            read()
        assert "\n" not in str(info.value)


def test_a_bad_selection_is_not_reported_as_a_damaged_store(tmp_path):
    lazy = io.read_stack(io.write_stack(small_stack(), tmp_path / "s.zarr"))
    with pytest.raises(IndexError):
        lazy.images[10]
    with pytest.raises(IndexError):
        lazy.images[0, 0, 0, 0]


@pytest.mark.parametrize("damage", ["truncate", "garbage", "empty"])
def test_damaged_chunk_files_of_any_kind(tmp_path, damage):
    out = io.write_stack(small_stack(), tmp_path / "s.zarr")
    file = chunk_file(out, "saturated", 3, 0, 0)
    data = file.read_bytes()
    file.write_bytes({"truncate": data[: len(data) // 2], "garbage": b"not zstd at all", "empty": b""}[damage])
    with pytest.raises(StackError, match=r"saturated: cannot read chunk \(3, 0, 0\) \(image 3, rows 0-31\): \w+: "):
        io.read_stack(out).saturated[3]


def test_corrupt_chunk_cli_demux_fails_in_one_line(wax_copy, tmp_path):
    corrupt(chunk_file(wax_copy, "images", 7, 0, 0))
    res = invoke("demux", wax_copy, "--out", tmp_path / "T.zarr")
    assert res.exit_code == 1
    # found while demultiplexing: the progress bar has started, the error is one line after it
    lines = [line for line in error_lines(res.output) if "demultiplexing (" not in line]
    assert len(lines) == 1, res.output
    assert str(wax_copy) in lines[0] and "cannot read chunk (7, 0, 0) (image 7)" in lines[0]
    assert "Traceback" not in res.output and not (tmp_path / "T.zarr").exists()


# ----------------------------------------------------------------------------
# transport stores
# ----------------------------------------------------------------------------
def make_transport():
    dense = np.random.default_rng(3).random((80, 12, 5), dtype=np.float32)
    dense[64:] = 0.0  # one block of rows all fill value: stored anyway
    return Transport(dense, np.arange(-2, 3), RowGeometry(80, 90))


def test_transport_missing_chunk_is_refused(tmp_path):
    out = io.write_transport(make_transport(), tmp_path / "T.zarr")
    assert all(not missing for missing in all_chunks_present(out).values())
    np.testing.assert_array_equal(io.read_transport(out)[0].dense, make_transport().dense)
    chunk_file(out, "T", 1, 0, 0).unlink()
    with pytest.raises(TransportError) as info:
        io.read_transport(out)
    assert str(info.value) == f"{out}: T: chunk (1, 0, 0) is missing (rows 64-79) -- the store is incomplete"


def test_transport_corrupt_chunk_is_named(tmp_path):
    out = io.write_transport(make_transport(), tmp_path / "T.zarr")
    corrupt(chunk_file(out, "T", 0, 0, 0))
    with pytest.raises(TransportError, match=rf"^{out}: T: cannot read chunk \(0, 0, 0\) \(rows 0-63\): RuntimeError"):
        io.read_transport(out)
    res = invoke("synth", out, "--epipolar", "--out", tmp_path / "e.png")
    assert res.exit_code == 1 and "Traceback" not in res.output
    lines = error_lines(res.output)
    assert len(lines) == 1 and str(out) in lines[0] and "T: cannot read chunk (0, 0, 0)" in lines[0], res.output


@pytest.fixture(scope="module")
def demux_store(tmp_path_factory):
    """A demultiplexed store whose bottom rows (a whole store chunk) are black, written by a resumed run."""
    stack = simulate_stack(make_scene("wax", (32, 8), projector_rows=90, seed=0), paper_sweep(), seed=0)
    stack.images[:, 16:] = 0.0
    stack.saturated = None
    out = tmp_path_factory.mktemp("demux") / "T.zarr"
    demultiplex_to_store(stack, out, chunk_rows=16, _stop_after=1)  # "killed" after the top rows
    demultiplex_to_store(stack, out, chunk_rows=16)  # the resumed run writes the black rows
    return out


def test_demux_store_written_by_a_resumed_run_has_every_chunk(demux_store):
    assert all(not missing for missing in all_chunks_present(demux_store).values())
    transport, attrs = io.read_transport(demux_store)
    assert attrs[ALL_CHUNKS_ATTR] is True
    assert not transport.dense[16:].any()
    maps = io.read_transport_maps(demux_store)
    assert set(maps) >= {"residual_rms", "converged", "iterations"}


def test_demux_store_missing_or_corrupt_map_chunk(demux_store, tmp_path):
    import shutil

    out = Path(shutil.copytree(demux_store, tmp_path / "T.zarr"))
    chunk_file(out, "iterations", 1, 0).unlink()
    with pytest.raises(TransportError, match=r"iterations: chunk \(1, 0\) is missing \(rows 16-31\)"):
        io.read_transport_maps(out)
    io.read_transport(out)  # T itself is complete
    out2 = Path(shutil.copytree(demux_store, tmp_path / "T2.zarr"))
    corrupt(chunk_file(out2, "residual_rms", 0, 0))
    with pytest.raises(TransportError, match=r"residual_rms: cannot read chunk \(0, 0\) \(rows 0-15\)"):
        io.read_transport_maps(out2)


def test_resumed_capture_stores_every_chunk(tmp_path):
    scene = make_scene("corner", (40, 12), projector_rows=90, seed=1)
    out = tmp_path / "cap.zarr"
    acquire_to_store(SimulatedEpiscan(scene, seed=3), quick_sweep(), out, _stop_after=5)
    acquire_to_store(SimulatedEpiscan(scene, seed=3), quick_sweep(), out)
    assert all(not missing for missing in all_chunks_present(out).values())
    stack = io.read_stack(out, lazy=False)
    assert not stack.saturated.all()


# ----------------------------------------------------------------------------
# import folder: pixel types, bit depth, float images, duplicated lines
# ----------------------------------------------------------------------------
ACQ = {"lines_per_second": 54000.0, "bit_depth": 12, "black_level": 64}


def capture(folder: Path, images, *, acq=ACQ, names=None, delays=None, exposures=None, rows=None):
    """An import folder: ``images`` (arrays) saved under ``names`` (.tif via tifffile, .png via Pillow)."""
    folder.mkdir(parents=True, exist_ok=True)
    n = len(images)
    names = names or [f"frame{i}.tif" for i in range(n)]
    delays = np.linspace(-600.0, 600.0, n) if delays is None else delays
    exposures = np.full(n, 900.0) if exposures is None else exposures
    for name, image in zip(names, images):
        if name.endswith(".png"):
            Image.fromarray(image).save(folder / name)
        else:
            tifffile.imwrite(folder / name, image)
    lines = ["file,delay_us,exposure_us"]
    lines += (
        rows if rows is not None else [f"{a},{float(d)!r},{float(e)!r}" for a, d, e in zip(names, delays, exposures)]
    )
    (folder / "manifest.csv").write_text("\n".join(lines) + "\n")
    if acq is not None:
        (folder / "acquisition.json").write_text(json.dumps(acq))
    return folder


def codes(n=3, dtype=np.uint16, top=4095, seed=1):
    rng = np.random.default_rng(seed)
    return [rng.integers(0, top + 1, size=(8, 10)).astype(dtype) for _ in range(n)]


def refusal(folder) -> str:
    with pytest.raises(StackError) as info:
        io.import_folder(folder)
    message = str(info.value)
    assert "\n" not in message
    return message


def test_8bit_png_among_16bit_tiffs(tmp_path):
    images = codes(4)
    images[2] = codes(1, np.uint8, 255)[0]
    names = ["frame0.tif", "frame1.tif", "frame2.png", "frame3.tif"]
    message = refusal(capture(tmp_path / "c", images, names=names))
    assert message == (
        f"{tmp_path / 'c' / 'frame2.png'}: pixel type uint8 PNG (mode 'L') differs from uint16 TIFF of the first "
        "image 'frame0.tif' (manifest.csv line 2); all images must have the same pixel type"
    )


def test_odd_first_image_is_reported_as_a_mismatch_not_a_bit_depth_problem(tmp_path):
    images = codes(3)
    images[0] = codes(1, np.uint8, 255)[0]
    message = refusal(capture(tmp_path / "c", images, names=["a.png", "b.tif", "c.tif"]))
    assert "b.tif: pixel type uint16 TIFF differs from uint8 PNG (mode 'L') of the first image 'a.png'" in message


def test_8bit_images_need_bit_depth_8(tmp_path):
    images = codes(2, np.uint8, 255)
    names = ["a.png", "b.png"]
    no_depth = {"lines_per_second": 54000.0}
    message = refusal(capture(tmp_path / "c", images, names=names, acq=no_depth))
    assert message.startswith(f"{tmp_path / 'c' / 'a.png'}: uint8 PNG (mode 'L') image holds at most 8-bit codes")
    assert "acquisition.json gives no bit_depth (default 12)" in message and '"bit_depth": 8' in message
    message = refusal(capture(tmp_path / "d", images, names=names, acq=ACQ))
    assert "holds at most 8-bit codes but bit_depth is 12" in message and '"bit_depth": 8' in message
    # the documented fix
    stack = io.import_folder(capture(tmp_path / "e", images, names=names, acq={**no_depth, "bit_depth": 8}))
    np.testing.assert_allclose(stack.images[0], images[0] / 255.0, atol=1e-7)
    assert stack.images.max() > 0.9


def test_float_tiff_needs_float_images(tmp_path):
    raw = [np.array([[64.0, 4095.0], [1000.5, 70.0]], np.float32)] * 1
    message = refusal(capture(tmp_path / "c", raw))
    assert message.startswith(f"{tmp_path / 'c' / 'frame0.tif'}: float32 TIFF image holds floating-point values")
    assert '"float_images": "raw"' in message and '"normalized"' in message
    stack = io.import_folder(capture(tmp_path / "raw", raw, acq={**ACQ, "float_images": "raw"}))
    np.testing.assert_allclose(stack.images[0], (raw[0] - 64) / (4095 - 64), atol=1e-7)
    assert stack.saturated[0].tolist() == [[False, True], [False, False]]


def test_normalized_float_tiffs_are_taken_as_they_are(tmp_path):
    images = [np.array([[-0.01, 0.5], [1.0, 0.25]], np.float32), np.array([[0.0, 0.9], [0.99, 1.2]], np.float32)]
    stack = io.import_folder(capture(tmp_path / "c", images, acq={**ACQ, "float_images": "normalized"}))
    np.testing.assert_array_equal(stack.images, np.stack(images))
    np.testing.assert_array_equal(stack.saturated, np.stack(images) >= 1.0)
    acq = {"lines_per_second": 54000.0, "float_images": "normalized", "saturation_level": 0.95}
    stack = io.import_folder(capture(tmp_path / "d", images, acq=acq))
    np.testing.assert_array_equal(stack.saturated, np.stack(images) >= 0.95)


@pytest.mark.parametrize(
    ("acq", "images", "problem"),
    [
        ({**ACQ, "float_images": "codes"}, "float", r"acquisition.json: field 'float_images' must be \"raw\" or"),
        ({**ACQ, "float_images": "raw"}, "uint16", r"acquisition.json: field 'float_images' is set but the images"),
        (
            {**ACQ, "float_images": "normalized", "saturation_level": 4095},
            "float",
            r"acquisition.json: field 'saturation_level' must be in \(0, 1\] with",
        ),
    ],
)
def test_float_images_field_is_checked(tmp_path, acq, images, problem):
    data = codes(2) if images == "uint16" else [np.zeros((2, 2), np.float32)] * 2
    assert re_search(problem, refusal(capture(tmp_path / "c", data, acq=acq)))


def re_search(pattern, text):
    import re

    assert re.search(pattern, text), text
    return True


def test_float_among_integer_images_is_a_mismatch(tmp_path):
    images = codes(3)
    images[1] = images[1].astype(np.float32)
    message = refusal(capture(tmp_path / "c", images, acq={**ACQ, "float_images": "raw"}))
    assert "frame1.tif: pixel type float32 TIFF differs from uint16 TIFF of the first image 'frame0.tif'" in message


def test_duplicated_file_lines(tmp_path):
    rows = ["frame0.tif,-600.0,900.0", "frame1.tif,0.0,900.0", "frame2.tif,600.0,900.0", "./frame1.tif,300.0,900.0"]
    message = refusal(capture(tmp_path / "c", codes(3), rows=rows))
    assert message == f"{tmp_path / 'c' / 'manifest.csv'}: lines 3 and 5 both list the image './frame1.tif'"


def test_duplicated_delay_exposure_settings(tmp_path):
    message = refusal(capture(tmp_path / "c", codes(4), delays=[-600.0, 0.0, 300.0, 0.0]))
    assert message.startswith(
        f"{tmp_path / 'c' / 'manifest.csv'}: lines 3 and 5 have the same delay_us 0.0 and exposure_us 900.0"
    )
    assert "does not average" in message
    # -0 and 0 are the same setting; another exposure is another setting
    refusal(capture(tmp_path / "d", codes(2), delays=[-0.0, 0.0]))
    io.import_folder(capture(tmp_path / "e", codes(2), delays=[0.0, 0.0], exposures=[600.0, 900.0]))


MARKUP = "img_[bold]0009.tif"


def test_file_names_with_markup_characters_appear_verbatim(tmp_path):
    folder = capture(tmp_path / "c", codes(2), names=[MARKUP, "img_[red]1.tif"], delays=[0.0, 0.0])
    message = refusal(folder)
    assert "lines 2 and 3 have the same delay_us" in message
    images = codes(2)
    images[1] = images[1].astype(np.uint8)
    message = refusal(capture(tmp_path / "d", images, names=["a.tif", MARKUP]))
    assert message.startswith(f"{tmp_path / 'd' / MARKUP}: pixel type uint8 TIFF differs")
    rows = [f"{MARKUP},0.0,900.0", f"{MARKUP},1.0,900.0"]
    message = refusal(capture(tmp_path / "e", codes(1), names=[MARKUP], rows=rows))
    assert f"both list the image {MARKUP!r}" in message


def test_cli_import_refusal_is_one_line(tmp_path):
    rows = ["a.tif,0.0,900.0", "b.tif,0.0,900.0"]
    folder = capture(tmp_path / "c", codes(2), names=["a.tif", "b.tif"], rows=rows)
    res = invoke("import", folder, "--out", tmp_path / "s.zarr")
    assert res.exit_code == 1 and "Traceback" not in res.output
    lines = error_lines(res.output)
    assert len(lines) == 1 and "lines 2 and 3 have the same delay_us 0.0" in lines[0], res.output
    assert not (tmp_path / "s.zarr").exists()


def test_export_import_round_trip_still_works(tmp_path):
    stack = small_stack(n=3, h=8, w=6)
    for fmt in ("tiff", "png"):
        back = io.import_folder(io.export_folder(stack, tmp_path / fmt, fmt=fmt))
        np.testing.assert_allclose(back.images, stack.images, atol=0.5 / (65535 - 256) + 1e-7)


# ------------------------------------------------------------------ single files: planeray's mark
def test_single_files_planeray_writes_carry_a_mark_and_only_those_are_replaced(tmp_path):
    """--overwrite replaces a single file only when its own metadata says planeray wrote it."""
    import json

    import tifffile
    from PIL import Image

    from planeray.errors import InputError
    from planeray.figures._common import new_figure, save_png
    from planeray.io import write_image
    from planeray.io.atomic import check_replaceable
    from planeray.io.marks import file_mark

    img = np.linspace(0, 1, 16).reshape(4, 4)
    ours = {
        "a.tif": lambda p: write_image(p, img),
        "a.png": lambda p: write_image(p, img),
        "fig.png": lambda p: save_png(new_figure((2, 2)), p),
    }
    for name, write in ours.items():
        path = tmp_path / name
        write(path)
        check_replaceable(path, overwrite=True)  # planeray's: may be replaced
        with pytest.raises(InputError, match="already exists"):
            check_replaceable(path, overwrite=False)
    assert file_mark(tmp_path / "fig.png") == "figure" and file_mark(tmp_path / "a.tif") == "image"
    # the mark is plain metadata, readable by any tool
    with Image.open(tmp_path / "a.png") as im:
        assert im.info["Software"].startswith("planeray:image:")
    with tifffile.TiffFile(tmp_path / "a.tif") as t:
        assert t.pages[0].tags[305].value.startswith("planeray:image:")
    # the same kinds of files written by someone else are never replaced
    theirs = {
        "b.tif": lambda p: tifffile.imwrite(p, np.zeros((4, 4), np.uint16)),
        "b.png": lambda p: Image.fromarray(np.zeros((4, 4), np.uint8)).save(p),
        "b.json": lambda p: p.write_text(json.dumps({"format": "mine"})),
        "b.npz": lambda p: np.savez(p, x=np.zeros(3)),
        "b.csv": lambda p: p.write_text("a,b\n1,2\n"),
        "b.mp4": lambda p: p.write_bytes(b"\x00\x00\x00\x18ftypmp42" + bytes(64)),
        "b.txt": lambda p: p.write_text("notes"),
    }
    for name, write in theirs.items():
        path = tmp_path / name
        write(path)
        before = path.read_bytes()
        with pytest.raises(InputError, match="planeray did not write"):
            check_replaceable(path, overwrite=True)
        assert path.read_bytes() == before
    # a forged-looking but wrong mark is not enough
    (tmp_path / "c.json").write_text(json.dumps({"planeray_mark": "planeray"}))
    assert file_mark(tmp_path / "c.json") is None

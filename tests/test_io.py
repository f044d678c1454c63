"""Tests of planeray.io: native stack store, import/export folders, transport store."""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

import numpy as np
import pytest
import tifffile
import zarr
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from PIL import Image

from planeray import io
from planeray.errors import InputError, StackError, TransportError
from planeray.stack import Stack
from planeray.timing import RowGeometry, boundary_images
from planeray.transport import SparseEntries, Transport

F32_EPS = float(np.finfo(np.float32).eps)


# ----------------------------------------------------------------------------
# helpers
# ----------------------------------------------------------------------------
def make_stack(n=6, h=16, w=20, saturated=True, seed=0):
    rng = np.random.default_rng(seed)
    images = rng.random((n, h, w), dtype=np.float32)
    sat = (images > 0.95) if saturated else None
    return Stack(
        images=images,
        delay_us=np.linspace(-750.0, 750.0, n),
        exposure_us=np.full(n, 600.0),
        lines_per_second=54000.0,
        saturated=sat,
        projector_rows=2 * h,
        metadata={
            "seed": np.int64(7),
            "sync": {"jitter_us": np.float32(2.5), "line_width_us": 0.0},
            "scene": "plane",
            "sweep": "custom",
            "levels": np.arange(3),
            "nested": [{"a": (1, 2)}],
        },
    )


EXPECTED_META = {
    "seed": 7,
    "sync": {"jitter_us": 2.5, "line_width_us": 0.0},
    "scene": "plane",
    "sweep": "custom",
    "levels": [0, 1, 2],
    "nested": [{"a": [1, 2]}],
}


def leftovers(parent: Path):
    """Temporary or backup siblings left in a folder."""
    return [p.name for p in parent.iterdir() if re.match(r"^\..*\.(tmp|bak)-", p.name)]


def write_capture(
    folder: Path,
    raws,
    fmt="tif",
    acq=None,
    delays=None,
    exposures=None,
    excluded=None,
    extra_columns=False,
):
    """Hand-make an import folder from raw code images."""
    folder.mkdir(parents=True, exist_ok=True)
    n = len(raws)
    delays = np.linspace(-600.0, 600.0, n) if delays is None else delays
    exposures = np.full(n, 900.0) if exposures is None else exposures
    header = ["file", "delay_us", "exposure_us"]
    if excluded is not None:
        header.append("excluded")
    if extra_columns:
        header.append("note")
    lines = [",".join(header)]
    for i, raw in enumerate(raws):
        name = f"frame{i}.{fmt}"
        if fmt in ("tif", "tiff"):
            tifffile.imwrite(folder / name, raw)
        else:
            Image.fromarray(raw).save(folder / name)
        row = [name, repr(float(delays[i])), repr(float(exposures[i]))]
        if excluded is not None:
            row.append(str(excluded[i]))
        if extra_columns:
            row.append("hello")
        lines.append(",".join(row))
    (folder / "manifest.csv").write_text("\n".join(lines) + "\n")
    acq = {"lines_per_second": 54000.0, "bit_depth": 12, "black_level": 64} if acq is None else acq
    (folder / "acquisition.json").write_text(json.dumps(acq))
    return folder


def raw_images(n=3, h=8, w=10, max_code=4095, seed=1):
    rng = np.random.default_rng(seed)
    raws = rng.integers(0, max_code + 1, size=(n, h, w)).astype(np.uint16)
    raws[0, 0, 0] = max_code  # one saturated pixel
    return list(raws)


# ----------------------------------------------------------------------------
# native store
# ----------------------------------------------------------------------------
@pytest.mark.parametrize("lazy", [True, False])
def test_native_round_trip(tmp_path, lazy):
    stack = make_stack()
    calls = []
    out = io.write_stack(stack, tmp_path / "s.zarr", progress=calls.append)
    assert out == tmp_path / "s.zarr"
    assert calls == list(range(len(stack)))
    back = io.read_stack(tmp_path / "s.zarr", lazy=lazy)
    if lazy:
        assert isinstance(back.images, io.LazyArray)
        assert isinstance(back.saturated, io.LazyArray)
        assert len(back.images) == 6 and back.images.shape == (6, 16, 20)
        assert back.images.dtype == np.float32
        assert back.image(2).shape == (16, 20)
    else:
        assert isinstance(back.images, np.ndarray) and back.images.dtype == np.float32
    np.testing.assert_array_equal(np.asarray(back.images), stack.images)
    np.testing.assert_array_equal(np.asarray(back.saturated), stack.saturated)
    np.testing.assert_array_equal(back.delay_us, stack.delay_us)
    np.testing.assert_array_equal(back.exposure_us, stack.exposure_us)
    np.testing.assert_array_equal(back.excluded, stack.excluded)
    assert back.lines_per_second == 54000.0
    assert back.projector_rows == 32
    assert back.metadata == EXPECTED_META
    assert back.jitter_us == 2.5
    assert leftovers(tmp_path) == []


def test_native_layout_and_attributes(tmp_path):
    stack = make_stack(saturated=False)
    io.write_stack(stack, tmp_path / "s.zarr")
    group = zarr.open_group(str(tmp_path / "s.zarr"), mode="r")
    attrs = dict(group.attrs)
    assert attrs["format"] == "planeray-stack"
    assert attrs["format_version"] == 1
    assert attrs["lines_per_second"] == 54000.0
    assert attrs["projector_rows"] == 32
    assert attrs["metadata"] == EXPECTED_META
    assert "planeray_version" in attrs
    assert group["images"].dtype == np.float32 and tuple(group["images"].chunks) == (1, 16, 20)
    assert group["saturated"].dtype == np.bool_ and not group["saturated"][...].any()
    assert group["delay_us"].dtype == np.float64 and group["exposure_us"].dtype == np.float64
    assert group["excluded"].dtype == np.bool_
    back = io.read_stack(tmp_path / "s.zarr", lazy=False)
    assert back.saturated.shape == (6, 16, 20) and not back.saturated.any()


def test_write_from_lazy_stack(tmp_path):
    stack = make_stack()
    io.write_stack(stack, tmp_path / "a.zarr")
    lazy = io.read_stack(tmp_path / "a.zarr")
    io.write_stack(lazy, tmp_path / "b.zarr")
    back = io.read_stack(tmp_path / "b.zarr", lazy=False)
    np.testing.assert_array_equal(back.images, stack.images)
    np.testing.assert_array_equal(back.saturated, stack.saturated)
    assert back.metadata == EXPECTED_META
    # a lazy stack can replace its own store: every image is copied before the swap
    lazy = io.read_stack(tmp_path / "b.zarr")
    lazy.metadata["note"] = "rewritten"
    io.write_stack(lazy, tmp_path / "b.zarr", overwrite=True)
    again = io.read_stack(tmp_path / "b.zarr", lazy=False)
    np.testing.assert_array_equal(again.images, stack.images)
    assert again.metadata["note"] == "rewritten"
    assert leftovers(tmp_path) == []


def test_overwrite_refused_and_allowed(tmp_path):
    path = tmp_path / "s.zarr"
    io.write_stack(make_stack(seed=0), path)
    with pytest.raises(StackError, match=r"s\.zarr.*already exists"):
        io.write_stack(make_stack(seed=1), path)
    np.testing.assert_array_equal(io.read_stack(path, lazy=False).images, make_stack(seed=0).images)
    io.write_stack(make_stack(seed=1), path, overwrite=True)
    np.testing.assert_array_equal(io.read_stack(path, lazy=False).images, make_stack(seed=1).images)
    assert leftovers(tmp_path) == []


class Boom(RuntimeError):
    pass


def _explode_at(k):
    def progress(i):
        if i == k:
            raise Boom("midway")

    return progress


def test_write_stack_atomic_new_path(tmp_path):
    path = tmp_path / "s.zarr"
    with pytest.raises(Boom):
        io.write_stack(make_stack(), path, progress=_explode_at(3))
    assert not path.exists()
    assert list(tmp_path.iterdir()) == []


def test_write_stack_atomic_overwrite_keeps_old(tmp_path):
    path = tmp_path / "s.zarr"
    io.write_stack(make_stack(seed=0), path)
    with pytest.raises(Boom):
        io.write_stack(make_stack(seed=1), path, overwrite=True, progress=_explode_at(2))
    np.testing.assert_array_equal(io.read_stack(path, lazy=False).images, make_stack(seed=0).images)
    assert leftovers(tmp_path) == []


def test_write_stack_atomic_when_zarr_fails(tmp_path, monkeypatch):
    calls = {"n": 0}
    original = zarr.Array.__setitem__

    def flaky(self, key, value):
        calls["n"] += 1
        if calls["n"] == 4:
            raise OSError("disk full")
        return original(self, key, value)

    monkeypatch.setattr(zarr.Array, "__setitem__", flaky)
    with pytest.raises(OSError, match="disk full"):
        io.write_stack(make_stack(), tmp_path / "s.zarr")
    assert list(tmp_path.iterdir()) == []


def test_write_stack_rejects_nan(tmp_path):
    stack = make_stack()
    stack.images[4, 1, 1] = np.nan
    with pytest.raises(StackError, match="image 4"):
        io.write_stack(stack, tmp_path / "s.zarr")
    assert list(tmp_path.iterdir()) == []


def test_write_stack_rejects_unserializable_metadata(tmp_path):
    stack = make_stack()
    stack.metadata["camera"] = {"obj": object()}
    with pytest.raises(StackError, match=r"metadata\['camera'\]\['obj'\]"):
        io.write_stack(stack, tmp_path / "s.zarr")
    assert list(tmp_path.iterdir()) == []


def _raw_store(path, n=3, images=None, drop=(), attrs=None, **shapes):
    """A hand-made stack store, to exercise read_stack's validation."""
    group = zarr.open_group(str(path), mode="w", zarr_format=3)
    data = {
        "images": np.zeros((n, 4, 5), np.float32) if images is None else images,
        "saturated": np.zeros((n, 4, 5), bool),
        "delay_us": np.zeros(n),
        "exposure_us": np.full(n, 600.0),
        "excluded": np.zeros(n, bool),
    }
    for name, shape in shapes.items():
        data[name] = np.ones(shape, data[name].dtype)
    for name, value in data.items():
        if name not in drop:
            group.create_array(name, data=value)
    default = {"format": "planeray-stack", "format_version": 1, "lines_per_second": 54000.0, "projector_rows": 4}
    group.attrs.update(default if attrs is None else attrs)
    return path


def test_read_stack_errors(tmp_path):
    with pytest.raises(StackError, match="nope.zarr: path does not exist"):
        io.read_stack(tmp_path / "nope.zarr")
    (tmp_path / "empty").mkdir()
    with pytest.raises(StackError, match="empty: not a planeray store: no zarr.json"):
        io.read_stack(tmp_path / "empty")
    (tmp_path / "file.txt").write_text("x")
    with pytest.raises(StackError, match="file.txt"):
        io.read_stack(tmp_path / "file.txt")
    with pytest.raises(StackError, match=r"a.zarr: not a planeray stack \(no 'format' attribute\)"):
        io.read_stack(_raw_store(tmp_path / "a.zarr", attrs={"lines_per_second": 1.0}))
    with pytest.raises(StackError, match="format is 'planeray-transport'"):
        io.read_stack(_raw_store(tmp_path / "b.zarr", attrs={"format": "planeray-transport"}))
    with pytest.raises(StackError, match=r"c.zarr: missing array 'delay_us'"):
        io.read_stack(_raw_store(tmp_path / "c.zarr", drop=("delay_us",)))
    with pytest.raises(StackError, match=r"d.zarr: array 'exposure_us' has shape \(4,\), expected \(3,\)"):
        io.read_stack(_raw_store(tmp_path / "d.zarr", exposure_us=(4,)))
    with pytest.raises(StackError, match=r"array 'saturated' has shape"):
        io.read_stack(_raw_store(tmp_path / "e.zarr", saturated=(3, 4, 6)))
    with pytest.raises(StackError, match=r"array 'images' must be \(N, H, W\)"):
        io.read_stack(_raw_store(tmp_path / "f.zarr", images=np.zeros((3, 20), np.float32)))
    with pytest.raises(StackError, match=r"g.zarr: missing attribute 'lines_per_second'"):
        io.read_stack(_raw_store(tmp_path / "g.zarr", attrs={"format": "planeray-stack", "format_version": 1}))
    with pytest.raises(StackError, match="unsupported format_version 2"):
        io.read_stack(
            _raw_store(
                tmp_path / "h.zarr", attrs={"format": "planeray-stack", "format_version": 2, "lines_per_second": 1.0}
            )
        )
    # a problem Stack itself finds is re-raised with the path
    group = zarr.open_group(str(_raw_store(tmp_path / "i.zarr")), mode="r+")
    group["exposure_us"][...] = np.array([600.0, -1.0, 600.0])
    with pytest.raises(StackError, match=r"i.zarr: exposure_us must be positive"):
        io.read_stack(tmp_path / "i.zarr")


def test_read_stack_nan_eager_and_validate_images(tmp_path):
    images = np.zeros((3, 4, 5), np.float32)
    images[2, 3, 4] = np.nan
    path = _raw_store(tmp_path / "s.zarr", images=images)
    with pytest.raises(StackError, match=r"s.zarr: image 2 contains NaN"):
        io.read_stack(path, lazy=False)
    lazy = io.read_stack(path)  # lazy: not scanned
    with pytest.raises(StackError, match=r"s.zarr: image 2 contains NaN"):
        io.validate_images(lazy, path)
    io.validate_images(io.read_stack(_raw_store(tmp_path / "ok.zarr")))


def test_read_stack_without_saturated_array(tmp_path):
    stack = io.read_stack(_raw_store(tmp_path / "s.zarr", drop=("saturated",)))
    assert stack.saturated is None and len(stack) == 3


# ----------------------------------------------------------------------------
# import folder
# ----------------------------------------------------------------------------
@pytest.mark.parametrize("fmt", ["tif", "tiff", "png"])
def test_import_normalization_and_saturation(tmp_path, fmt):
    raws = raw_images()
    folder = write_capture(tmp_path / "cap", raws, fmt=fmt, extra_columns=True)
    stack = io.import_folder(folder)
    assert stack.images.dtype == np.float32 and stack.images.shape == (3, 8, 10)
    expected = (np.stack(raws).astype(np.float64) - 64) / (4095 - 64)
    np.testing.assert_allclose(stack.images, expected, rtol=0, atol=1e-7)
    # spot checks of the formula
    assert stack.images[0, 0, 0] == pytest.approx(1.0)
    np.testing.assert_array_equal(stack.saturated, np.stack(raws) >= 4095)
    assert stack.saturated[0, 0, 0]
    np.testing.assert_array_equal(stack.delay_us, [-600.0, 0.0, 600.0])
    np.testing.assert_array_equal(stack.exposure_us, [900.0] * 3)
    np.testing.assert_array_equal(stack.excluded, boundary_images(stack.delay_us, stack.exposure_us))
    assert stack.lines_per_second == 54000.0
    assert stack.projector_rows == 8
    assert stack.metadata["source"] == f"import:{folder}"
    assert stack.metadata["acquisition"] == {"lines_per_second": 54000.0, "bit_depth": 12, "black_level": 64}


def test_import_black_below_zero_kept(tmp_path):
    raw = np.full((4, 4), 10, np.uint16)
    stack = io.import_folder(write_capture(tmp_path / "c", [raw]))
    np.testing.assert_allclose(stack.images, (10 - 64) / (4095 - 64), rtol=1e-6)


def test_import_options(tmp_path):
    raws = [np.array([[0, 100, 200], [250, 254, 255]], np.uint8)] * 2
    acq = {
        "lines_per_second": 27000,
        "bit_depth": 8,
        "saturation_level": 250,
        "projector_rows": 9,
        "camera": {"model": "IMX"},
    }
    folder = write_capture(tmp_path / "c", raws, fmt="png", acq=acq, excluded=["true", "0"])
    stack = io.import_folder(folder)
    np.testing.assert_allclose(stack.images[0], raws[0] / 255.0, atol=1e-7)
    np.testing.assert_array_equal(stack.saturated[0], raws[0] >= 250)
    np.testing.assert_array_equal(stack.excluded, [True, False])
    assert stack.projector_rows == 9 and stack.lines_per_second == 27000.0
    assert stack.metadata["acquisition"]["camera"] == {"model": "IMX"}


def test_import_float_tiff(tmp_path):
    raw = np.array([[64.0, 4095.0], [1000.5, 70.0]], np.float32)
    acq = {"lines_per_second": 54000.0, "bit_depth": 12, "black_level": 64, "float_images": "raw"}
    stack = io.import_folder(write_capture(tmp_path / "c", [raw], acq=acq))
    np.testing.assert_allclose(stack.images[0], (raw - 64) / (4095 - 64), atol=1e-7)
    assert stack.saturated[0].tolist() == [[False, True], [False, False]]


def test_read_stack_on_import_folder(tmp_path):
    folder = write_capture(tmp_path / "cap", raw_images())
    stack = io.read_stack(folder)
    assert isinstance(stack.images, np.ndarray) and len(stack) == 3
    np.testing.assert_array_equal(stack.images, io.import_folder(folder).images)


def _bad(tmp_path, **kwargs):
    return write_capture(tmp_path / "cap", raw_images(), **kwargs)


def _edit(path: Path, old: str, new: str):
    path.write_text(path.read_text().replace(old, new, 1))


def _set_acq(folder, **fields):
    acq = {"lines_per_second": 54000.0, "bit_depth": 12, "black_level": 64}
    acq.update(fields)
    acq = {k: v for k, v in acq.items() if v is not DROP}
    (folder / "acquisition.json").write_text(json.dumps(acq))


DROP = object()


def _break_manifest(text):
    def apply(folder):
        (folder / "manifest.csv").write_text(text)

    return apply


def _replace_image(index, data, fmt="tif"):
    def apply(folder):
        target = folder / f"frame{index}.tif"
        if fmt == "tif":
            tifffile.imwrite(target, data)
        else:  # write a PNG under a .png name and point the manifest at it
            Image.fromarray(data).save(folder / f"frame{index}.png")
            _edit(folder / "manifest.csv", f"frame{index}.tif", f"frame{index}.png")

    return apply


def _truncate(index, suffix="tif"):
    def apply(folder):
        if suffix == "png":
            _replace_image(index, np.zeros((8, 10), np.uint16), fmt="png")(folder)
        target = folder / f"frame{index}.{suffix}"
        data = target.read_bytes()
        target.write_bytes(data[: len(data) // 3])

    return apply


BAD_INPUTS = [
    # (id, mutation, file named in the message, problem regex)
    ("manifest missing", lambda f: (f / "manifest.csv").unlink(), "manifest.csv", "file not found"),
    (
        "missing column",
        _break_manifest("file,delay_us\nframe0.tif,0\n"),
        "manifest.csv",
        "missing column 'exposure_us'",
    ),
    ("empty manifest", _break_manifest(""), "manifest.csv", "empty manifest"),
    ("header only", _break_manifest("file,delay_us,exposure_us\n"), "manifest.csv", "empty manifest"),
    (
        "non-numeric delay",
        lambda f: _edit(f / "manifest.csv", ",0.0,", ",abc,"),
        "manifest.csv",
        "line 3: delay_us 'abc' is not a finite number",
    ),
    (
        "nan exposure",
        lambda f: _edit(f / "manifest.csv", "900.0\n", "nan\n"),
        "manifest.csv",
        "line 2: exposure_us 'nan' is not a finite number",
    ),
    (
        "zero exposure",
        lambda f: _edit(f / "manifest.csv", "900.0\n", "0\n"),
        "manifest.csv",
        "line 2: exposure_us must be positive",
    ),
    (
        "bad excluded",
        _break_manifest("file,delay_us,exposure_us,excluded\nframe0.tif,0,600,maybe\n"),
        "manifest.csv",
        "line 2: excluded 'maybe'",
    ),
    ("image missing", lambda f: (f / "frame1.tif").unlink(), "frame1.tif", r"image not found \(manifest.csv line 3\)"),
    ("truncated tiff", _truncate(2), "frame2.tif", "cannot read image"),
    ("truncated png", _truncate(1, "png"), "frame1.png", "cannot read image"),
    ("not an image", lambda f: (f / "frame0.tif").write_text("hello"), "frame0.tif", "cannot read image"),
    (
        "unsupported suffix",
        lambda f: _edit(f / "manifest.csv", "frame0.tif", "frame0.jpg") or (f / "frame0.jpg").write_text("x"),
        "frame0.jpg",
        "unsupported image format",
    ),
    (
        "rgb tiff",
        _replace_image(1, np.zeros((8, 10, 3), np.uint8)),
        "frame1.tif",
        r"expected a grayscale image, got shape \(8, 10, 3\)",
    ),
    (
        "rgb png",
        _replace_image(1, np.zeros((8, 10, 3), np.uint8), fmt="png"),
        "frame1.png",
        r"expected a grayscale image, got shape \(8, 10, 3\)",
    ),
    (
        "size mismatch",
        _replace_image(2, np.zeros((8, 11), np.uint16)),
        "frame2.tif",
        r"image size \(8, 11\) differs from the first image 'frame0.tif' \(8, 10\)",
    ),
    (
        "above bit depth",
        _replace_image(1, np.full((8, 10), 5000, np.uint16)),
        "frame1.tif",
        "raw value 5000 above the largest code 4095 of bit_depth 12",
    ),
    ("nan float image", _replace_image(1, np.full((8, 10), np.nan, np.float32)), "frame1.tif", "NaN"),
    ("acquisition missing", lambda f: (f / "acquisition.json").unlink(), "acquisition.json", "file not found"),
    (
        "invalid json",
        lambda f: (f / "acquisition.json").write_text("{lines_per_second: 1"),
        "acquisition.json",
        "invalid JSON",
    ),
    (
        "json not object",
        lambda f: (f / "acquisition.json").write_text("[1, 2]"),
        "acquisition.json",
        "expected a JSON object",
    ),
    (
        "no lines_per_second",
        lambda f: _set_acq(f, lines_per_second=DROP),
        "acquisition.json",
        "missing field 'lines_per_second'",
    ),
    (
        "string lines_per_second",
        lambda f: _set_acq(f, lines_per_second="fast"),
        "acquisition.json",
        "'lines_per_second' must be a positive number",
    ),
    (
        "negative lines_per_second",
        lambda f: _set_acq(f, lines_per_second=-1),
        "acquisition.json",
        "'lines_per_second' must be a positive number",
    ),
    (
        "bit depth 17",
        lambda f: _set_acq(f, bit_depth=17),
        "acquisition.json",
        r"'bit_depth' must be an integer in 1\.\.16",
    ),
    ("bit depth 0", lambda f: _set_acq(f, bit_depth=0), "acquisition.json", "'bit_depth' must be an integer"),
    ("bit depth str", lambda f: _set_acq(f, bit_depth="12"), "acquisition.json", "'bit_depth' must be an integer"),
    (
        "black level too high",
        lambda f: _set_acq(f, black_level=4095),
        "acquisition.json",
        "'black_level' .* must be below",
    ),
    ("black level type", lambda f: _set_acq(f, black_level=[1]), "acquisition.json", "'black_level' must be a number"),
    (
        "projector rows",
        lambda f: _set_acq(f, projector_rows=2.5),
        "acquisition.json",
        "'projector_rows' must be a positive integer",
    ),
]


@pytest.mark.parametrize(("mutate", "filename", "problem"), [b[1:] for b in BAD_INPUTS], ids=[b[0] for b in BAD_INPUTS])
def test_import_bad_inputs(tmp_path, mutate, filename, problem):
    folder = _bad(tmp_path)
    mutate(folder)
    before = sorted(p.name for p in tmp_path.rglob("*"))
    with pytest.raises(StackError) as info:
        io.import_folder(folder)
    message = str(info.value)
    assert filename in message
    assert re.search(problem, message), message
    assert sorted(p.name for p in tmp_path.rglob("*")) == before  # nothing created


def test_import_folder_missing(tmp_path):
    with pytest.raises(StackError, match="nowhere: folder does not exist"):
        io.import_folder(tmp_path / "nowhere")
    (tmp_path / "f.txt").write_text("x")
    with pytest.raises(StackError, match="f.txt: not a folder"):
        io.import_folder(tmp_path / "f.txt")


def test_stack_error_is_input_error():
    assert issubclass(StackError, InputError) and issubclass(StackError, ValueError)


# ----------------------------------------------------------------------------
# export
# ----------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("fmt", "bit_depth", "black_level"), [("tiff", 16, 256), ("png", 16, 256), ("tiff", 12, 64), ("png", 10, 0)]
)
def test_export_import_round_trip(tmp_path, fmt, bit_depth, black_level):
    stack = make_stack()
    stack.images[0, 0, :3] = [1.0, 1.5, -1e6]  # saturated, above range, below range (clipped)
    folder = io.export_folder(stack, tmp_path / "out", fmt=fmt, bit_depth=bit_depth, black_level=black_level)
    suffix = ".tif" if fmt == "tiff" else ".png"
    assert sorted(p.name for p in folder.iterdir()) == sorted(
        [f"img_{i:04d}{suffix}" for i in range(6)] + ["manifest.csv", "acquisition.json"]
    )
    back = io.import_folder(folder)
    span = 2**bit_depth - 1 - black_level
    expected = np.clip(stack.images, -black_level / span, 1.0)
    np.testing.assert_allclose(back.images, expected, rtol=0, atol=0.5 / span + F32_EPS)
    assert back.images[0, 0, 1] == pytest.approx(1.0)
    assert back.images[0, 0, 2] == pytest.approx(-black_level / span)
    assert back.saturated[stack.images >= 1].all()
    np.testing.assert_array_equal(back.delay_us, stack.delay_us)
    np.testing.assert_array_equal(back.exposure_us, stack.exposure_us)
    np.testing.assert_array_equal(back.excluded, stack.excluded)
    assert back.lines_per_second == stack.lines_per_second
    assert back.projector_rows == stack.projector_rows
    for key, value in EXPECTED_META.items():
        assert back.metadata[key] == value
    assert back.metadata["acquisition"]["bit_depth"] == bit_depth
    with Image.open(folder / f"img_0001{suffix}") as im:
        assert np.asarray(im).dtype == np.uint16
    assert leftovers(tmp_path) == []


def test_export_excluded_is_kept_even_when_not_boundary(tmp_path):
    stack = make_stack()
    stack.excluded = np.array([False, True, False, True, False, False])
    back = io.import_folder(io.export_folder(stack, tmp_path / "out"))
    np.testing.assert_array_equal(back.excluded, stack.excluded)


def test_export_refuses_overwrite_and_is_atomic(tmp_path, monkeypatch):
    io.export_folder(make_stack(seed=0), tmp_path / "out")
    with pytest.raises(StackError, match="out: already exists"):
        io.export_folder(make_stack(seed=1), tmp_path / "out")
    calls = {"n": 0}
    original = io.folder.write_raw

    def flaky(*args):
        calls["n"] += 1
        if calls["n"] == 3:
            raise OSError("disk full")
        original(*args)

    monkeypatch.setattr(io.folder, "write_raw", flaky)
    with pytest.raises(OSError):
        io.export_folder(make_stack(seed=1), tmp_path / "out", overwrite=True)
    back = io.import_folder(tmp_path / "out")
    np.testing.assert_allclose(back.images, make_stack(seed=0).images, atol=1e-4)
    assert leftovers(tmp_path) == []
    monkeypatch.setattr(io.folder, "write_raw", original)
    io.export_folder(make_stack(seed=1), tmp_path / "out", overwrite=True)
    np.testing.assert_allclose(io.import_folder(tmp_path / "out").images, make_stack(seed=1).images, atol=1e-4)


def test_export_bad_arguments(tmp_path):
    with pytest.raises(StackError, match="unknown image format 'jpeg'"):
        io.export_folder(make_stack(), tmp_path / "a", fmt="jpeg")
    with pytest.raises(StackError, match="black_level"):
        io.export_folder(make_stack(), tmp_path / "b", bit_depth=8, black_level=255)
    with pytest.raises(StackError, match="bit_depth"):
        io.export_folder(make_stack(), tmp_path / "c", bit_depth=20)
    assert list(tmp_path.iterdir()) == []


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    bit_depth=st.integers(2, 16),
    black_frac=st.floats(0.0, 0.9),
    fmt=st.sampled_from(["tiff", "png"]),
    values=st.lists(st.floats(-0.0625, 1.25, allow_nan=False, width=32), min_size=6, max_size=6),
)
def test_export_quantization_property(tmp_path_factory, bit_depth, black_frac, fmt, values):
    max_code = 2**bit_depth - 1
    black = int(black_frac * (max_code - 1))
    images = np.array(values, np.float32).reshape(1, 2, 3)
    stack = Stack(images=images, delay_us=[0.0], exposure_us=[600.0], lines_per_second=1000.0)
    folder = io.export_folder(
        stack, tmp_path_factory.mktemp("q") / "out", fmt=fmt, bit_depth=bit_depth, black_level=black
    )
    back = io.import_folder(folder)
    span = max_code - black
    expected = np.clip(images, -black / span, 1.0)
    np.testing.assert_allclose(back.images, expected, rtol=0, atol=0.5 / span + F32_EPS)
    assert back.saturated[images >= 1].all()


@pytest.mark.parametrize("suffix", [".tif", ".tiff", ".png"])
def test_write_image(tmp_path, suffix):
    image = np.array([[0.0, 0.5], [1.0, 2.0]], np.float32)
    path = io.write_image(tmp_path / "sub" / f"img{suffix}", image)
    raw = tifffile.imread(path) if suffix != ".png" else np.asarray(Image.open(path))
    assert raw.dtype == np.uint16
    np.testing.assert_array_equal(raw, [[0, 32768], [65535, 65535]])
    io.write_image(path, np.zeros((2, 2)), bit_depth=8)  # replaces
    raw = tifffile.imread(path) if suffix != ".png" else np.asarray(Image.open(path))
    assert raw.max() == 0
    assert leftovers(path.parent) == []


def test_write_image_errors(tmp_path):
    with pytest.raises(InputError, match=r"img.jpg: unsupported image extension"):
        io.write_image(tmp_path / "img.jpg", np.zeros((2, 2)))
    with pytest.raises(InputError, match="expected a 2-D image"):
        io.write_image(tmp_path / "img.tif", np.zeros((2, 2, 3)))
    with pytest.raises(InputError, match="NaN"):
        io.write_image(tmp_path / "img.png", np.full((2, 2), np.nan))
    assert list(tmp_path.iterdir()) == []


# ----------------------------------------------------------------------------
# atomic helpers
# ----------------------------------------------------------------------------
def test_atomic_file_cleans_up(tmp_path):
    target = tmp_path / "a.txt"
    target.write_text("old")
    with pytest.raises(Boom):
        with io.atomic_file(target) as tmp:
            assert tmp.parent == tmp_path and tmp.suffix == ".txt" and tmp.name.startswith(".a.txt.tmp-")
            tmp.write_text("new")
            raise Boom
    assert target.read_text() == "old" and leftovers(tmp_path) == []
    with io.atomic_file(target) as tmp:
        tmp.write_text("new")
    assert target.read_text() == "new" and leftovers(tmp_path) == []
    with pytest.raises(InputError, match="already exists"):
        with io.atomic_file(target, overwrite=False):
            pass


def test_atomic_directory_names_and_cleanup(tmp_path):
    target = tmp_path / "d"
    with io.atomic_directory(target, overwrite=False) as tmp:
        assert tmp.parent == tmp_path and tmp.name.startswith(".d.tmp-") and tmp.is_dir()
        (tmp / "x").write_text("1")
        # a planeray result (format attributes): only such a folder may be replaced
        (tmp / "zarr.json").write_text(json.dumps({"attributes": {"format": "planeray-stack"}}))
        assert not target.exists()
    assert (target / "x").read_text() == "1"
    with pytest.raises(Boom):
        with io.atomic_directory(target, overwrite=True) as tmp:
            (tmp / "x").write_text("2")
            raise Boom
    assert (target / "x").read_text() == "1" and leftovers(tmp_path) == []
    with io.atomic_directory(target, overwrite=True) as tmp:
        (tmp / "y").write_text("2")
    assert sorted(os.listdir(target)) == ["y"] and leftovers(tmp_path) == []


# ----------------------------------------------------------------------------
# transport store
# ----------------------------------------------------------------------------
def make_transport(sparse=True):
    rng = np.random.default_rng(3)
    dense = rng.random((10, 12, 7), dtype=np.float32)
    entries = SparseEntries([1, 9, 4], [0, 11, 5], [-40, 55, 30], [0.25, 0.5, 1.5]) if sparse else SparseEntries.empty()
    return Transport(dense, np.arange(-3, 4), RowGeometry(10, 40), entries)


@pytest.mark.parametrize("sparse", [True, False])
def test_transport_round_trip(tmp_path, sparse):
    transport = make_transport(sparse)
    attrs = {"lines_per_second": 54000.0, "alpha": np.float64(0.1), "beta": 2, "method": "demux"}
    io.write_transport(transport, tmp_path / "t.zarr", attrs=attrs)
    back, read_attrs = io.read_transport(tmp_path / "t.zarr")
    np.testing.assert_array_equal(back.dense, transport.dense)
    np.testing.assert_array_equal(back.offsets_rows, transport.offsets_rows)
    assert back.geometry == transport.geometry
    for name in ("row", "col", "offset", "value"):
        np.testing.assert_array_equal(getattr(back.sparse, name), getattr(transport.sparse, name))
    assert len(back.sparse) == (3 if sparse else 0)
    assert read_attrs["format"] == "planeray-transport" and read_attrs["format_version"] == 1
    assert read_attrs["offsets_rows"] == list(range(-3, 4))
    assert read_attrs["projector_rows"] == 40 and read_attrs["lines_per_second"] == 54000.0
    assert read_attrs["alpha"] == 0.1 and read_attrs["beta"] == 2 and read_attrs["method"] == "demux"
    np.testing.assert_allclose(back.full_image(), transport.full_image(), rtol=1e-6)
    group = zarr.open_group(str(tmp_path / "t.zarr"), mode="r")
    assert group["T"].dtype == np.float32 and tuple(group["T"].chunks) == (10, 12, 7)
    if sparse:
        assert group["sparse_row"].dtype == np.int32 and group["sparse_value"].dtype == np.float32
    # the attributes read back can be passed to write_transport again
    io.write_transport(back, tmp_path / "t.zarr", attrs=read_attrs, overwrite=True)
    assert io.read_transport(tmp_path / "t.zarr")[1]["alpha"] == 0.1
    assert leftovers(tmp_path) == []


def test_transport_without_lines_per_second(tmp_path):
    io.write_transport(make_transport(), tmp_path / "t.zarr")
    _, attrs = io.read_transport(tmp_path / "t.zarr")
    assert attrs["lines_per_second"] is None


def test_transport_overwrite_refused(tmp_path):
    io.write_transport(make_transport(), tmp_path / "t.zarr")
    with pytest.raises(TransportError, match="t.zarr: already exists"):
        io.write_transport(make_transport(), tmp_path / "t.zarr")


def _raw_transport(path, T=None, attrs=None, sparse=None):
    group = zarr.open_group(str(path), mode="w", zarr_format=3)
    if T is not False:
        group.create_array("T", data=np.zeros((4, 5, 3), np.float32) if T is None else T)
    base = {"format": "planeray-transport", "format_version": 1, "offsets_rows": [-1, 0, 1], "lines_per_second": None}
    base.update(attrs or {})
    group.attrs.update(base)
    for name, value in (sparse or {}).items():
        group.create_array(name, data=value)
    return path


def test_read_transport_errors(tmp_path):
    with pytest.raises(TransportError, match="none.zarr: path does not exist"):
        io.read_transport(tmp_path / "none.zarr")
    with pytest.raises(TransportError, match=r"a.zarr: missing array 'T'"):
        io.read_transport(_raw_transport(tmp_path / "a.zarr", T=False))
    with pytest.raises(TransportError, match=r"b.zarr: array 'T' must be \(H, W, U\)"):
        io.read_transport(_raw_transport(tmp_path / "b.zarr", T=np.zeros((4, 5), np.float32)))
    with pytest.raises(TransportError, match=r"c.zarr: 2 offsets_rows for array 'T' with U = 3"):
        io.read_transport(_raw_transport(tmp_path / "c.zarr", attrs={"offsets_rows": [0, 1]}))
    bad = np.zeros((4, 5, 3), np.float32)
    bad[1, 1, 1] = np.inf
    with pytest.raises(TransportError, match=r"d.zarr: array 'T' contains NaN or infinite"):
        io.read_transport(_raw_transport(tmp_path / "d.zarr", T=bad))
    with pytest.raises(TransportError, match="e.zarr: missing attribute 'offsets_rows'"):
        io.read_transport(_raw_transport(tmp_path / "e.zarr", attrs={"offsets_rows": None}))
    with pytest.raises(TransportError, match="f.zarr: offsets_rows must be consecutive"):
        io.read_transport(_raw_transport(tmp_path / "f.zarr", attrs={"offsets_rows": [0, 2, 3]}))
    with pytest.raises(TransportError, match="g.zarr: missing array 'sparse_value'"):
        io.read_transport(
            _raw_transport(
                tmp_path / "g.zarr",
                sparse={
                    "sparse_row": np.zeros(2, np.int32),
                    "sparse_col": np.zeros(2, np.int32),
                    "sparse_offset": np.zeros(2, np.int32),
                },
            )
        )
    io.write_stack(make_stack(), tmp_path / "s.zarr")
    with pytest.raises(TransportError, match="s.zarr: not a planeray transport"):
        io.read_transport(tmp_path / "s.zarr")

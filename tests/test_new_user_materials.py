"""A new user's bad inputs to ``planeray materials ...`` (issue 24): one line naming the option, nothing lost.

Every case runs in a folder of the user's own files (``tests/_new_user.py``) and checks exit 1,
one ``error:`` line without a traceback or "unexpected", the option as typed, and that no file
of the user's changed and nothing was left behind.  The captures and models the cases read are
made once, outside the user's folder: a 40x40 capture (paper sweep), one of the quick sweep, a
model, and damaged or malicious model files (record edited, digest over the record, deep JSON,
a 300 MB member, wrong kind or version).  Every case is refused before any work: the whole file
runs in seconds.
"""

from __future__ import annotations

import hashlib
import json
import re
import zipfile

import pytest

from _new_user import run_bad, user_files

SIZE = (40, 40)
GRID = {"C": (10.0,), "gamma_scale": (1.0,)}


@pytest.fixture(scope="module")
def env(tmp_path_factory):
    """Paths the cases name: ``{c}`` a capture, ``{q}`` a quick-sweep capture, ``{m}`` a model, bad models."""
    from planeray.experiments.materials import simulate_capture
    from planeray.materials import train_model

    root = tmp_path_factory.mktemp("materials_env")
    cap = simulate_capture(root / "cap", size=SIZE, seed=0)
    simulate_capture(root / "quick", size=SIZE, seed=1, sweep="quick")
    model = train_model([cap.stack], [cap.labels], param_grid=GRID, ignore_classes=(6,), max_per_class=60)
    good = model.save(root / "model.zip")
    paths = {"c": root / "cap", "q": root / "quick", "m": good, "v1": _version_1_library(root / "v1.json")}
    paths.update(bad_models(good, root))
    return paths


def _version_1_library(path):
    """A version-1 media library (fits bound to their capture's resolution: 5.625 rows per camera row)."""
    entry = {
        "name": "fat-free milk", "class_id": 1, "mu_s_prime_per_mm": 0.8, "mu_s_prime_log_sd": 0.2,
        "mu_a_per_mm": 0.009, "mu_a_log_sd": 0.86, "correlation": -0.6, "beyond_table": {"above": 0.0, "below": 0.0},
        "blocks": 1764, "source": "written by the test",
    }  # fmt: skip
    conditions = {"mm_per_row": 0.3, "n": 1.33, "calibrated": False, "block_px": 2, "rows_per_camera_row": 5.625}
    record = {
        "planeray_mark": "planeray:media library:0.1.0", "format": "planeray-media-library", "version": 1,
        "conditions": conditions, "media": [entry],
    }  # fmt: skip
    path.write_text(json.dumps(record))
    return path


def _members(path):
    with zipfile.ZipFile(path) as z:
        return json.loads(z.read("planeray-model.json")), z.read("model.skops")


def _write(path, meta, blob, *, redigest=True):
    from planeray.materials.model import record_digest

    if redigest:
        meta = dict(meta, estimator_sha256=hashlib.sha256(blob).hexdigest())
        meta["record_sha256"] = record_digest(meta)
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as z:
        z.writestr("planeray-model.json", meta if isinstance(meta, (bytes, str)) else json.dumps(meta))
        z.writestr("model.skops", blob)
    return path


def bad_models(good, root) -> dict:
    """Damaged and malicious model files, each refused in one line by ``load_model``."""
    meta, blob = _members(good)
    out = {}
    # The record edited by hand, its digest left as it was: the floor, the class names.
    out["floor"] = _write(
        root / "floor.zip", {**meta, "definition": {**meta["definition"], "floor": "none"}}, blob, redigest=False
    )
    names = dict(meta["classes"])
    names["1"], names["2"] = names["2"], names["1"]
    out["names"] = _write(root / "names.zip", {**meta, "classes": names}, blob, redigest=False)
    # Consistent digests, but a record that cannot describe the estimator.
    out["kind"] = _write(root / "kind.zip", {**meta, "definition": {**meta["definition"], "kind": "transport"}}, blob)
    out["kind2"] = _write(root / "kind2.zip", {**meta, "definition": {**meta["definition"], "kind": ["stack"]}}, blob)
    out["classes"] = _write(root / "classes.zip", {**meta, "classes": {**meta["classes"], "9": "mayonnaise"}}, blob)
    out["version"] = _write(root / "version.zip", {**meta, "format_version": 2.5}, blob)
    out["version_text"] = _write(root / "version_text.zip", {**meta, "format_version": "2"}, blob)
    out["version_old"] = _write(root / "version_old.zip", {**meta, "format_version": 1}, blob)
    out["version_new"] = _write(root / "version_new.zip", {**meta, "format_version": 99}, blob)
    # Deep JSON: the record itself, and the estimator's schema (200,000 levels: a parser's recursion limit).
    out["deep_record"] = _write(root / "deep_record.zip", b"[" * 200_000 + b"]" * 200_000, blob, redigest=False)
    deep = root / "deep.skops"
    with zipfile.ZipFile(deep, "w") as z:
        z.writestr("schema.json", '{"__class__": "Pipeline", "content": ' + "[" * 200_000 + "]" * 200_000 + "}")
    out["deep_schema"] = _write(root / "deep_schema.zip", meta, deep.read_bytes())
    # A 300 MB member (zeros, compressed fast to 1.4 MB): refused from the zip's directory, never read.
    huge = root / "huge.zip"
    with zipfile.ZipFile(huge, "w", compression=zipfile.ZIP_DEFLATED, compresslevel=1) as z:
        z.writestr("planeray-model.json", json.dumps(meta))
        with z.open("model.skops", "w", force_zip64=True) as f:
            chunk = bytes(2**20)
            for _ in range(300):
                f.write(chunk)
    out["huge"] = huge
    # A zip that is a planeray model plus something else; a pickle named like a model.
    extra = root / "extra.zip"
    with zipfile.ZipFile(good) as z, zipfile.ZipFile(extra, "w") as w:
        for name in z.namelist():
            w.writestr(name, z.read(name))
        w.writestr("payload.pkl", b"\x80\x04cos\nsystem\n.")
    out["extra"] = extra
    pkl = root / "pickle.zip"
    pkl.write_bytes(b"\x80\x04cos\nsystem\n(S'echo hi'\ntR.")
    out["pickle"] = pkl
    return out


@pytest.fixture
def folder(tmp_path):
    user_files(tmp_path / "user")
    return tmp_path / "user"


SIM = ("materials", "simulate", "--out", "{d}/cap")
TRAIN = ("materials", "train", "{c}/stack.zarr", "--labels", "{c}/labels.png", "--out", "{d}/m.zip")
# Refused at parse: the stack named does not even exist, so any reading would fail first with another message.
TRAIN_PARSE = ("materials", "train", "{d}/nothing.zarr", "--labels", "{d}/nothing.png", "--out", "{d}/m.zip")
PREDICT = ("materials", "predict", "{m}", "{c}/stack.zarr", "--out", "{d}/seg.png")
REPORT = ("materials", "report", "--out", "{d}/rep")

CASES = [
    # classes
    (("materials", "classes", "--source", "milkman"), "--source", ("narasimhan",)),
    (("materials", "classes", "--channel", "purple"), "--channel", ("red, green, blue",)),
    # simulate: every number and choice
    ((*SIM, "--size", 0, 16), "--size", (">= 8",)),
    ((*SIM, "--size", 16, -5), "--size", ()),
    ((*SIM, "--size", 4, 4), "--size", ()),
    ((*SIM, "--size", 100000, 100000), "--size", ("<= 4096",)),
    ((*SIM, "--size", 4096, 4096), "--size", ("GiB",)),
    ((*SIM, "--size", 16, 16, "--projector-rows", 0), "--projector-rows", ()),
    ((*SIM, "--size", 16, 16, "--projector-rows", -720), "--projector-rows", ()),
    ((*SIM, "--size", 16, 16, "--projector-rows", 20000), "--projector-rows", ("kernel tables",)),
    ((*SIM, "--size", 16, 16, "--seed", -1), "--seed", (">= 0",)),
    ((*SIM, "--size", 16, 16, "--seed", 2**40), "--seed", ()),
    ((*SIM, "--size", 16, 16, "--placement", -1), "--placement", ()),
    ((*SIM, "--size", 16, 16, "--container", "box"), "--container", ("tray, cup",)),
    ((*SIM, "--size", 16, 16, "--wall", "glass"), "--wall", ("fresnel",)),
    ((*SIM, "--size", 16, 16, "--source", "milkman"), "--source", ()),
    ((*SIM, "--size", 16, 16, "--channel", "purple"), "--channel", ()),
    ((*SIM, "--size", 16, 16, "--noise", 0), "--noise", ()),
    ((*SIM, "--size", 16, 16, "--noise", -1), "--noise", ()),
    ((*SIM, "--size", 16, 16, "--noise", "nan"), "--noise", ()),
    ((*SIM, "--size", 16, 16, "--noise", "inf"), "--noise", ()),
    ((*SIM, "--size", 16, 16, "--noise", 1e6), "--noise", ("no signal",)),
    ((*SIM, "--size", 16, 16, "--ambient-e-per-us", -1), "--ambient-e-per-us", ()),
    ((*SIM, "--size", 16, 16, "--ambient", "nan"), "--ambient-e-per-us", ()),
    ((*SIM, "--size", 16, 16, "--ambient", "inf"), "--ambient-e-per-us", ()),
    ((*SIM, "--size", 16, 16, "--ambient", 1e9), "--ambient-e-per-us", ("full well",)),
    ((*SIM, "--size", 16, 16, "--sweep", "fast"), "--sweep", ("paper",)),
    (("materials", "simulate", "--out", "{d}/notes.txt"), None, ("already exists",)),
    (("materials", "simulate", "--out", "{d}/notes.txt", "--overwrite"), None, ("planeray did not write",)),
    (("materials", "simulate", "--out", "{d}", "--overwrite"), None, ("planeray did not write",)),
    (("materials", "simulate", "--out", "{d}/notes.txt/cap"), None, ()),
    (("materials", "simulate", "--out", "{c}", "--size", 16, 16), None, ("already exists",)),
    # train: refused at parse, before any capture is read
    ((*TRAIN_PARSE, "--floor", "purple"), "--floor", ("edge, min, none",)),
    ((*TRAIN_PARSE, "--features", "foo"), "--features", ("stack, transport",)),
    ((*TRAIN_PARSE, "--max-per-class", 0), "--max-per-class", ()),
    ((*TRAIN_PARSE, "--max-per-class", -5), "--max-per-class", ()),
    ((*TRAIN_PARSE, "--max-per-class", 10**9), "--max-per-class", ("<= 5000",)),
    ((*TRAIN_PARSE, "--cv-folds", 1), "--cv-folds", ()),
    ((*TRAIN_PARSE, "--cv-folds", 0), "--cv-folds", ()),
    ((*TRAIN_PARSE, "--cv-folds", 1000), "--cv-folds", ()),
    ((*TRAIN_PARSE, "--seed", -1), "--seed", ()),
    ((*TRAIN_PARSE, "--ignore-class", -1), "--ignore-class", ()),
    ((*TRAIN_PARSE, "--ignore-class", 300), "--ignore-class", ()),
    ((*TRAIN_PARSE, "--class-name", "mayonnaise"), "--class-name", ("ID=NAME",)),
    ((*TRAIN_PARSE, "--class-name", "7="), "--class-name", ()),
    ((*TRAIN_PARSE, "--class-name", "300=x"), "--class-name", ()),
    ((*TRAIN_PARSE, "--class-name", "0=x"), "--class-name", ()),
    (
        ("materials", "train", "{d}/a.zarr", "{d}/b.zarr", "--labels", "{d}/x.png", "--out", "{d}/m.zip"),
        "--labels",
        ("2 stacks but 1",),
    ),
    ((*TRAIN_PARSE[:-1], "{d}/model.txt"), "--out", (".zip",)),
    (("materials", "train", "{c}/stack.zarr", "--labels", "{d}/labels.png", "--out", "{d}/labels.png"), "--out", ()),
    (
        ("materials", "train", "{c}/stack.zarr", "--labels", "{d}/labels.png", "--out", "{d}/labels.zip"),
        "--labels",
        ("32x32", "40x40"),
    ),
    ((*TRAIN[:4], "{d}/notes.txt", *TRAIN[5:]), "--labels", ()),
    ((*TRAIN[:4], "{d}/missing.png", *TRAIN[5:]), "--labels", ("no such",)),
    ((*TRAIN[:4], "{d}/scan.tif", *TRAIN[5:]), "--labels", ("16x16",)),
    ((*TRAIN[:4], "{d}/clip.tif", *TRAIN[5:]), "--labels", ("one channel",)),
    (
        ("materials", "train", "{d}/notes.json", "--labels", "{c}/labels.png", "--out", "{d}/m.zip"),
        None,
        ("notes.json",),
    ),
    (
        ("materials", "train", "{d}/missing.zarr", "--labels", "{c}/labels.png", "--out", "{d}/m.zip"),
        None,
        ("missing.zarr",),
    ),
    ((*TRAIN[:-1], "{d}/notes.zip"), None, ()),  # placeholder replaced below: an existing user .zip
    ((*TRAIN[:-1], "{d}/lines.zip", "--overwrite"), None, ("not a planeray materials model",)),
    ((*TRAIN[:-1], "{d}/notes.txt/m.zip"), None, ()),
    (
        (
            *TRAIN,
            "--ignore-class",
            1,
            "--ignore-class",
            2,
            "--ignore-class",
            3,
            "--ignore-class",
            4,
            "--ignore-class",
            5,
            "--ignore-class",
            6,
        ),
        None,
        ("training needs at least two",),
    ),
    # predict: outputs and every input checked before anything is classified or written
    (("materials", "predict", "{m}", "{c}/stack.zarr", "--out", "{d}/photo.png"), None, ("already exists",)),
    (
        ("materials", "predict", "{m}", "{c}/stack.zarr", "--out", "{d}/photo.png", "--overwrite"),
        None,
        ("planeray did not write",),
    ),
    (
        ("materials", "predict", "{m}", "{c}/stack.zarr", "--out", "{d}/scan.tif", "--overwrite"),
        None,
        ("planeray did not write",),
    ),
    (
        ("materials", "predict", "{m}", "{c}/stack.zarr", "--labels", "{d}/labels.png", "--out", "{d}/labels.png"),
        "--out",
        ("also an input (--labels)",),
    ),
    (
        (
            "materials",
            "predict",
            "{m}",
            "{c}/stack.zarr",
            "--labels",
            "{d}/labels.png",
            "--out",
            "{d}/./labels.png",
            "--overwrite",
        ),
        "--out",
        ("also an input (--labels)",),
    ),
    ((*PREDICT[:-1], "{m}", "--overwrite"), "--out", ()),
    ((*PREDICT[:-1], "{d}/seg.jpg"), "--out", (".png, .tif or .tiff",)),
    ((*PREDICT, "--near-wall", "{c}/near_wall.png"), "--near-wall", ("needs --labels",)),
    ((*PREDICT, "--labels", "{d}/labels.png"), "--labels", ("32x32",)),
    ((*PREDICT, "--labels", "{c}/labels.png", "--near-wall", "{d}/labels.png"), "--near-wall", ("32x32",)),
    ((*PREDICT, "--labels", "{c}/labels.png", "--near-wall", "{d}/notes.txt"), "--near-wall", ()),
    ((*PREDICT, "--labels", "{d}/notes.txt"), "--labels", ()),
    ((*PREDICT, "--labels", "{d}/clip.tif"), "--labels", ()),
    ((*PREDICT, "--labels", "{d}/fake.png"), "--labels", ("cannot read as PNG",)),
    ((*PREDICT, "--unclassified-below", -0.1), "--unclassified-below", ()),
    ((*PREDICT, "--unclassified-below", 1.5), "--unclassified-below", ()),
    ((*PREDICT, "--unclassified-below", "nan"), "--unclassified-below", ()),
    ((*PREDICT, "--majority-px", -1), "--majority-px", ()),
    ((*PREDICT, "--majority-px", 51), "--majority-px", ()),
    (
        ("materials", "predict", "{d}/notes.json", "{c}/stack.zarr", "--out", "{d}/seg.png"),
        None,
        ("not a planeray materials model",),
    ),
    (
        ("materials", "predict", "{d}/photo.png", "{c}/stack.zarr", "--out", "{d}/seg.png"),
        None,
        ("not a planeray materials model",),
    ),
    (("materials", "predict", "{d}/missing.zip", "{c}/stack.zarr", "--out", "{d}/seg.png"), None, ("no such",)),
    (("materials", "predict", "{m}", "{d}/notes.txt", "--out", "{d}/seg.png"), None, ("notes.txt",)),
    (("materials", "predict", "{m}", "{q}/stack.zarr", "--out", "{d}/seg.png"), None, ("different sweep",)),
    ((*PREDICT[:-1], "{d}/notes.txt/seg.png"), None, ()),
    # damaged and malicious model files
    (("materials", "predict", "{floor}", "{c}/stack.zarr", "--out", "{d}/seg.png"), None, ("record_sha256",)),
    (("materials", "predict", "{names}", "{c}/stack.zarr", "--out", "{d}/seg.png"), None, ("record_sha256",)),
    (("materials", "predict", "{kind}", "{c}/stack.zarr", "--out", "{d}/seg.png"), None, ("malformed model record",)),
    (("materials", "predict", "{kind2}", "{c}/stack.zarr", "--out", "{d}/seg.png"), None, ("malformed model record",)),
    (
        ("materials", "predict", "{classes}", "{c}/stack.zarr", "--out", "{d}/seg.png"),
        None,
        ("malformed model record",),
    ),
    (
        ("materials", "predict", "{version}", "{c}/stack.zarr", "--out", "{d}/seg.png"),
        None,
        ("format_version must be an integer",),
    ),
    (
        ("materials", "predict", "{version_text}", "{c}/stack.zarr", "--out", "{d}/seg.png"),
        None,
        ("format_version must be an integer",),
    ),
    (("materials", "predict", "{version_old}", "{c}/stack.zarr", "--out", "{d}/seg.png"), None, ("train the model",)),
    (("materials", "predict", "{version_new}", "{c}/stack.zarr", "--out", "{d}/seg.png"), None, ("newer",)),
    (("materials", "predict", "{deep_record}", "{c}/stack.zarr", "--out", "{d}/seg.png"), None, ("nested",)),
    (("materials", "predict", "{deep_schema}", "{c}/stack.zarr", "--out", "{d}/seg.png"), None, ("nested",)),
    (("materials", "predict", "{huge}", "{c}/stack.zarr", "--out", "{d}/seg.png"), None, ("300 MiB",)),
    (("materials", "predict", "{extra}", "{c}/stack.zarr", "--out", "{d}/seg.png"), None, ("payload.pkl",)),
    (("materials", "predict", "{pickle}", "{c}/stack.zarr", "--out", "{d}/seg.png"), None, ("not a zip archive",)),
    # report: checked before the work
    ((*REPORT, "--size", 8), "--size", (">= 16",)),
    ((*REPORT, "--size", 0), "--size", ()),
    ((*REPORT, "--size", -1), "--size", ()),
    ((*REPORT, "--size", 100000), "--size", ()),
    ((*REPORT, "--size", 4000), "--size", ("GiB",)),
    (("materials", "report", "--out", "{d}/notes.txt"), None, ("already exists",)),
    (("materials", "report", "--out", "{d}/notes.txt", "--overwrite"), None, ("planeray did not write",)),
    (("materials", "report", "--out", "{d}", "--overwrite"), None, ("planeray did not write",)),
    (("materials", "report", "--out", "{c}", "--overwrite"), None, ("not a materials report",)),
]


def _words(args, env):
    words = []
    for a in args:
        a = str(a)
        for key, path in env.items():
            a = a.replace("{" + key + "}", str(path))
        words.append(a)
    return words


@pytest.mark.parametrize(
    ("args", "option", "needles"), CASES, ids=[f"{i:02d} " + " ".join(map(str, c[0][1:])) for i, c in enumerate(CASES)]
)
def test_bad_input_gives_one_line_naming_the_option_and_loses_nothing(
    args, option, needles, folder, monkeypatch, request
):
    # The capture and model only for the cases that name them: under pytest-xdist the worker that runs
    # only the other cases then never builds them.
    named = {key for a in args for key in re.findall(r"\{(\w+)\}", str(a))} - {"d"}
    env = request.getfixturevalue("env") if named else {}
    # A machine with 16 GiB available: a 4096x4096 capture (80 GiB) is refused whatever runs the tests.
    monkeypatch.setattr("planeray.experiments.materials.available_memory_bytes", lambda: 16 * 2**30)
    (folder / "notes.zip").write_bytes(b"PK\x05\x06" + bytes(18))  # an (empty) zip of the user's
    (folder / "lines.zip").write_bytes((folder / "notes.zip").read_bytes())
    (folder / "fake.png").write_text("not an image")
    run_bad(_words(args, env), folder=folder, option=option, needles=needles)


def test_the_cases_cover_every_option_of_every_materials_command():
    """Every option of the materials commands that takes a value appears in at least one bad case."""
    import typing

    from planeray.cli import materials as cli
    from planeray.cli._common import option_spellings

    used = {str(w) for case in CASES for w in case[0]}
    for command in (cli.classes, cli.simulate, cli.train, cli.predict, cli.report):
        hints = typing.get_type_hints(command, include_extras=True)
        for param, option in option_spellings(command).items():
            if typing.get_args(hints[param])[0] is bool:
                continue
            assert option in used or (option == "--ambient-e-per-us" and "--ambient" in used), (command, option)


def test_refused_before_reading(env, folder, monkeypatch):
    """train and predict check options and outputs before a stack is opened or a model loaded."""
    import planeray.cli.materials as cli

    def never(*a, **k):
        raise AssertionError("read before the options were checked")

    monkeypatch.setattr(cli, "_load_stack", never)
    run_bad(_words((*TRAIN, "--floor", "purple"), env), folder=folder, option="--floor")
    run_bad(_words((*TRAIN, "--features", "foo"), env), folder=folder, option="--features")
    run_bad(_words((*PREDICT[:-1], "{d}/photo.png"), env), folder=folder, needles=("already exists",))
    monkeypatch.setattr("planeray.materials.load_model", never)
    run_bad(_words((*PREDICT, "--unclassified-below", 2), env), folder=folder, option="--unclassified-below")


# ---------------------------------------------------------------------------- degenerate inputs (issue 40)
def _label_image(path, shape, fill=0, pixels=(), dtype="uint8"):
    """A label image: ``fill`` everywhere, class ids at ``pixels`` (``(row, col, id)``)."""
    import numpy as np
    import tifffile
    from PIL import Image

    lab = np.full(shape, fill, dtype)
    for r, c, cid in pixels:
        lab[r, c] = cid
    if str(path).endswith(".tif"):
        tifffile.imwrite(path, lab)
    else:
        Image.fromarray(lab).save(path)
    return path


DEGENERATE = [
    # an all-zero label image: nothing to fit, recognize, train or score
    (("materials", "fit", "{c}/stack.zarr", "--labels", "{d}/zero.png", "--out", "{d}/fit"), "--labels", ("no labelled pixel", "zero.png")),
    (("materials", "recognize", "{c}/stack.zarr", "--regions", "{d}/zero.png", "--out", "{d}/rec"), "--regions", ("no labelled pixel", "zero.png")),
    (("materials", "train", "{c}/stack.zarr", "--labels", "{d}/zero.png", "--out", "{d}/m.zip"), "--labels", ("no labelled pixel", "zero.png")),
    # a class id beyond the 8-bit segmentations
    (("materials", "train", "{c}/stack.zarr", "--labels", "{d}/big.tif", "--out", "{d}/m.zip"), "--labels", ("0-255", "300", "big.tif")),
    # a capture as its own white reference: by path, and as a copy
    (("materials", "fit", "{c}/stack.zarr", "--white-reference", "{c}/./stack.zarr", "--out", "{d}/fit"), "--white-reference", ("the capture itself",)),
    (("materials", "fit", "{c}/stack.zarr", "--white-reference", "{d}/copy.zarr", "--out", "{d}/fit"), "--white-reference", ("the capture itself", "the same images", "copy.zarr")),
    # one id named twice, one name given twice
    (("materials", "train", "{c}/stack.zarr", "--labels", "{c}/labels.png", "--class-name", "7=a", "--class-name", "7=b", "--out", "{d}/m.zip"), "--class-name", ("named twice",)),
    (("materials", "library-add", "{c}/stack.zarr", "--labels", "{c}/labels.png", "--class-name", "1=a", "--class-name", "2=a", "--out", "{d}/l.json"), "--class-name", ("two ids",)),
    # a number that is no number
    (("materials", "library-add", "{c}/stack.zarr", "--labels", "{c}/labels.png", "--class-name", "1=a", "--mm-per-row", "nan", "--out", "{d}/l.json"), "--mm-per-row", ("finite",)),
    (("materials", "recognize", "{c}/stack.zarr", "--mm-per-row", "-1", "--out", "{d}/rec"), "--mm-per-row", ("> 0",)),
    # an entry from a capture of another resolution than a version-1 library's (fits bound to 128-row captures)
    (("materials", "library-add", "{c}/stack.zarr", "--labels", "{c}/labels.png", "--class-name", "3=mine", "--library", "{v1}", "--out", "{d}/l.json"), "--library", ("5.625 projector rows per camera row", "has 18")),
]  # fmt: skip


@pytest.mark.parametrize(("args", "option", "needles"), DEGENERATE, ids=[f"{i:02d}" for i in range(len(DEGENERATE))])
def test_a_degenerate_input_is_refused_in_one_line_naming_the_option_and_the_file(
    args, option, needles, env, folder, monkeypatch
):
    import shutil

    import planeray.cli.materials as cli

    def never(*a, **k):
        raise AssertionError("the capture was demultiplexed or fitted before the input was checked")

    monkeypatch.setattr("planeray.materials.model.capture_transport", never)  # refused before any demultiplexing
    monkeypatch.setattr("planeray.materials.capture.capture_transport", never)
    monkeypatch.setattr(cli, "progress_bar", never)
    _label_image(folder / "zero.png", (40, 40))
    _label_image(folder / "big.tif", (40, 40), fill=1, pixels=[(3, 3, 300)], dtype="uint16")
    if any("copy.zarr" in str(a) for a in args):
        shutil.copytree(env["c"] / "stack.zarr", folder / "copy.zarr")
    run_bad(_words(args, env), folder=folder, option=option, needles=needles, may_create=_made(args))


def _made(args):
    """The inputs a case writes into the user's folder before it runs (they are not left by the command)."""
    return [n for n in ("zero.png", "big.tif") if any(n in str(a) for a in args)]

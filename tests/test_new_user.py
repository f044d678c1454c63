"""A new user's bad inputs, command by command (issue 24): one line naming the option, nothing lost.

Each case runs in a folder of the user's own files (``tests/_new_user.py``) and checks exit 1, one
``error:`` line without a traceback or "unexpected", the option as typed, and that no file of the user's
changed and nothing was left behind.  Cases of other commands are in ``tests/test_new_user_*.py``.
"""

from __future__ import annotations

import pytest

from _new_user import run_bad, user_files


@pytest.fixture
def folder(tmp_path):
    user_files(tmp_path / "user")
    return tmp_path / "user"


CASES = [
    # simulate
    (("simulate", "wax", "--out", "{d}/w.zarr", "--size", 0, 16), "--size", ("must be",)),
    (("simulate", "wax", "--out", "{d}/w.zarr", "--size", 16, 16, "--projector-rows", 0), "--projector-rows", ()),
    (("simulate", "wax", "--out", "{d}/w.zarr", "--frames", 0), "--frames", ()),
    (("simulate", "wax", "--out", "{d}/w.zarr", "--ambient", "nan"), "--ambient-e-per-us", ()),
    (("simulate", "wax", "--out", "{d}/w.zarr", "--spp", 8), "--spp", ("mitsuba:",)),
    (("simulate", "wax", "--out", "{d}/notes.txt"), None, ("already exists",)),
    (("simulate", "wax", "--out", "{d}/notes.json", "--overwrite"), None, ("planeray did not write",)),
    (("simulate", "{d}/notes.json", "--out", "{d}/w.zarr"), None, ("notes.json: not a transport store",)),
    # render
    (("render", "mirror_ball", "--out", "{d}/T.zarr", "--rows", 0), "--rows", ()),
    (("render", "mirror_ball", "--out", "{d}/T.zarr", "--size", 0, 8), "--size", ()),
    (("render", "mirror_ball", "--out", "{d}/T.zarr", "--spp", 0), "--spp", ()),
    (("render", "mirror_ball", "--out", "{d}/T.zarr", "--batch-spp", -1), "--batch-spp", ()),
    (("render", "mirror_ball", "--out", "{d}/T.zarr", "--band-rows", -3), "--band-rows", ()),
    (("render", "mirror_ball", "--out", "{d}/T.zarr", "--max-sparse", -1), "--max-sparse", ()),
    (("render", "mirror_ball", "--out", "{d}/T.zarr", "--projector-aspect", 0), "--projector-aspect", ()),
    (("render", "mirror_ball", "--out", "{d}/T.zarr", "--projector-columns", 0), "--projector-columns", ()),
    (("render", "mirror_ball", "--out", "{d}/T.zarr", "--projector-vfov", "nan"), "--projector-vfov", ()),
    (("render", "mirror_ball", "--out", "{d}/T.zarr", "--variant", "gpu"), "--variant", ()),
    (("render", "mirror_ball", "--out", "{d}/notes.txt", "--overwrite"), None, ("planeray did not write",)),
    (("render", "{d}/notes.txt", "--out", "{d}/T.zarr"), None, ("notes.txt: not a readable Mitsuba XML scene",)),
]


@pytest.mark.parametrize(("args", "option", "needles"), CASES, ids=[" ".join(map(str, c[0][:4])) for c in CASES])
def test_bad_input_gives_one_line_naming_the_option_and_loses_nothing(args, option, needles, folder):
    if args[0] == "render":
        pytest.importorskip("mitsuba")
    run_bad(args, folder=folder, option=option, needles=needles)

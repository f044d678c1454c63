"""A new user's bad inputs to ``planeray skin ...``, ``view`` and ``video`` (issue 24): refused before any work.

Every option of every command of the area that takes a number, a path or a choice: out of its
physical range, NaN, infinite, absurdly large (memory: one line instead of being killed), of the
wrong type or extension, an existing user file as output with and without ``--overwrite``, a user
file where a planeray file is expected.  Each case runs in a folder of the user's own files
(``tests/_new_user.py``) and checks exit 1, one ``error:`` line without a traceback or
"unexpected", the option as typed (never the library's name), and that no file of the user's
changed and nothing was left behind.  A bad input is refused before any work, so every case is fast.

Placeholders: ``{d}`` the user's folder, ``{s}`` a small planeray stack (48x48, quick sweep),
``{v}`` a planeray pulse video (4 s at 30 fps, 16x16), ``{T}`` a planeray transport store.
"""

from __future__ import annotations

import numpy as np
import pytest

from _new_user import run_bad, user_files


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    """Planeray inputs, outside the user's folder: a stack, a video, a transport."""
    import planeray as pr
    from _skin_toy import toy_vein_scene
    from planeray.pulse.video_io import Video, write_video

    d = tmp_path_factory.mktemp("inputs")
    scene = toy_vein_scene((48, 48), projector_rows=270, columns=(8, 24, 40))
    pr.write_stack(pr.simulate_stack(scene, pr.timing.quick_sweep(), seed=0), d / "s.zarr")
    pr.write_transport(scene.transport, d / "T.zarr")
    rng = np.random.default_rng(0)
    frames = (0.5 + 0.01 * rng.standard_normal((120, 16, 16))).astype(np.float32)
    write_video(d / "v.tif", Video(frames, 30.0, "test"))
    return {"s": d / "s.zarr", "v": d / "v.tif", "T": d / "T.zarr"}


@pytest.fixture
def folder(tmp_path):
    """The user's folder: their files, plus files named as planeray's companions would be, and a video."""
    from PIL import Image

    d = tmp_path / "user"
    user_files(d)
    Image.fromarray(np.full((8, 8), 7, np.uint8)).save(d / "arm_vein_mask.png")  # the user's own mask
    Image.fromarray(np.full((8, 8), 9, np.uint8)).save(d / "arm_video_vein_mask.png")
    (d / "movie.mp4").write_bytes(b"\x00\x00\x00\x18ftypmp42" + bytes(64))  # the user's own video
    return d


S, V = "{s}", "{v}"
EXISTS, THEIRS = "already exists", "planeray did not write"

CASES = [
    # ---------------------------------------------------------------- skin simulate
    (("skin", "simulate", "--out", "{d}/a.zarr", "--size", 0, 16), "--size", ("at least 8x8",)),
    (("skin", "simulate", "--out", "{d}/a.zarr", "--size", 100000, 100000), "--size", ("of memory",)),
    (("skin", "simulate", "--out", "{d}/a.zarr", "--projector-rows", 0), "--projector-rows", ()),
    (("skin", "simulate", "--out", "{d}/a.zarr", "--projector-rows", 721), "--projector-rows", ("<= 720",)),
    (("skin", "simulate", "--out", "{d}/a.zarr", "--mm-per-row", "nan"), "--mm-per-row", ()),
    (("skin", "simulate", "--out", "{d}/a.zarr", "--mm-per-row", 0), "--mm-per-row", ()),
    (("skin", "simulate", "--out", "{d}/a.zarr", "--mm-per-row", 1e6), "--mm-per-row", ("<= 10",)),
    (("skin", "simulate", "--out", "{d}/a.zarr", "--tone", "purple"), "--tone", ("very_fair",)),
    (("skin", "simulate", "--out", "{d}/a.zarr", "--tone", 2), "--tone", ("[0, 0.5]",)),
    (("skin", "simulate", "--out", "{d}/a.zarr", "--tone", "nan"), "--tone", ()),
    (("skin", "simulate", "--out", "{d}/a.zarr", "--wavelength", 500), "--wavelength", ("638", "850")),
    (("skin", "simulate", "--out", "{d}/a.zarr", "--ambient", "nan"), "--ambient-e-per-us", ()),
    (("skin", "simulate", "--out", "{d}/a.zarr", "--ambient", -1), "--ambient-e-per-us", ()),
    (("skin", "simulate", "--out", "{d}/a.zarr", "--ambient", 1e30), "--ambient-e-per-us", ("<= 1000",)),
    (("skin", "simulate", "--out", "{d}/a.zarr", "--sweep", "slow"), "--sweep", ("paper", "quick")),
    (("skin", "simulate", "--out", "{d}/a.zarr", "--seed", -1), "--seed", ()),
    (("skin", "simulate", "--out", "{d}/notes.txt"), None, (EXISTS,)),
    (("skin", "simulate", "--out", "{d}/notes.json", "--overwrite"), None, (THEIRS,)),
    (("skin", "simulate", "--out", "{d}/arm.zarr"), None, ("arm_vein_mask.png: " + EXISTS,)),
    (("skin", "simulate", "--out", "{d}/arm.zarr", "--overwrite"), None, ("arm_vein_mask.png", THEIRS)),
    # ---------------------------------------------------------------- skin validate
    (("skin", "validate", "--out", "{d}/v", "--n-photons", 0), "--n-photons", (">= 32",)),
    (("skin", "validate", "--out", "{d}/v", "--n-photons", -5), "--n-photons", ()),
    (("skin", "validate", "--out", "{d}/v", "--n-photons", 10**14), "--n-photons", ("<= 10000000",)),
    (("skin", "validate", "--out", "{d}/v", "--wavelength", 500), "--wavelength", ()),
    (("skin", "validate", "--out", "{d}/notes.txt"), None, (EXISTS,)),
    (("skin", "validate", "--out", "{d}"), None, (EXISTS,)),
    (("skin", "validate", "--out", "{d}", "--overwrite"), None, (THEIRS,)),
    # ---------------------------------------------------------------- skin veins
    (("skin", "veins", S, "--out", "{d}/v", "--delay-us", "nan"), "--delay-us", ()),
    (("skin", "veins", S, "--out", "{d}/v", "--delay-us", 1e9), "--delay-us", ("13333",)),
    (("skin", "veins", S, "--out", "{d}/v", "--delay-us", 9000), "--delay-us", ("no image near",)),
    (("skin", "veins", S, "--out", "{d}/v", "--exposure-us", 0), "--exposure-us", ()),
    (("skin", "veins", S, "--out", "{d}/v", "--exposure-us", "inf"), "--exposure-us", ()),
    (("skin", "veins", S, "--out", "{d}/v", "--exposure-us", 700), "--exposure-us", ("no image at that",)),
    (("skin", "veins", S, "--out", "{d}/v", "--mm-per-row", "nan"), "--mm-per-row", ()),
    (("skin", "veins", S, "--out", "{d}/v", "--mm-per-row", 1e6), "--mm-per-row", ()),
    (("skin", "veins", S, "--out", "{d}/v", "--mask", "{d}/photo.png"), "--mask", ("64x64",)),
    (("skin", "veins", S, "--out", "{d}/v", "--mask", "{d}/notes.txt"), "--mask", ("notes.txt",)),
    (("skin", "veins", S, "--out", "{d}/v", "--transport", "{d}/notes.json"), "--transport", ()),
    (("skin", "veins", "{d}/notes.json", "--out", "{d}/v"), None, ("not a planeray stack",)),
    (("skin", "veins", "{d}", "--out", "{d}/v"), None, ("not a planeray stack",)),
    (("skin", "veins", "{d}/missing.zarr", "--out", "{d}/v"), None, ("no such file",)),
    (("skin", "veins", S, "--out", "{d}/notes.txt"), None, (EXISTS,)),
    (("skin", "veins", S, "--out", "{d}/notes.txt", "--overwrite"), None, (THEIRS,)),
    (("skin", "veins", S, "--out", "{d}", "--overwrite"), None, (THEIRS,)),
    # ---------------------------------------------------------------- skin enhance
    (("skin", "enhance", S, "--out", "{d}/e", "--patch-px", 0), "--patch-px", ()),
    (("skin", "enhance", S, "--out", "{d}/e", "--patch-px", 1), "--patch-px", ()),
    (("skin", "enhance", S, "--out", "{d}/e", "--patch-px", 100000), "--patch-px", ("<= 48",)),
    (("skin", "enhance", S, "--out", "{d}/e", "--min-delay-us", "nan"), "--min-delay-us", ()),
    (("skin", "enhance", S, "--out", "{d}/e", "--min-delay-us", 1e9), "--min-delay-us", ()),
    (("skin", "enhance", S, "--out", "{d}/e", "--min-delay-us", 5000), "--min-delay-us", ("at least 2",)),
    (("skin", "enhance", S, "--out", "{d}/e", "--exposure-us", "nan"), "--exposure-us", ()),
    (("skin", "enhance", S, "--out", "{d}/e", "--exposure-us", 700), "--exposure-us", ("no image at that",)),
    (("skin", "enhance", S, "--out", "{d}/e", "--mm-per-row", -1), "--mm-per-row", ()),
    (("skin", "enhance", S, "--out", "{d}/e", "--mask", "{d}/labels.png"), "--mask", ("32x32",)),
    (("skin", "enhance", "{d}/notes.txt", "--out", "{d}/e"), None, ("not a planeray stack",)),
    (("skin", "enhance", S, "--out", "{d}/notes.json", "--overwrite"), None, (THEIRS,)),
    # ---------------------------------------------------------------- skin compare
    (("skin", "compare", "--out", "{d}/c", "--size", 0), "--size", (">= 16",)),
    (("skin", "compare", "--out", "{d}/c", "--size", 8), "--size", ()),
    (("skin", "compare", "--out", "{d}/c", "--size", 100000), "--size", ("of memory",)),
    (("skin", "compare", "--out", "{d}/c", "--delay-us", 1e9), "--delay-us", ("885.2",)),
    (("skin", "compare", "--out", "{d}/c", "--delay-us", "nan"), "--delay-us", ()),
    (("skin", "compare", "--out", "{d}/c", "--delay-us", -500), "--delay-us", ()),
    (("skin", "compare", "--out", "{d}/c", "--delay-us", 100), "--delay-us", ("epipolar plane",)),
    (("skin", "compare", "--out", "{d}/c", "--seed", -1), "--seed", ()),
    (("skin", "compare", "--out", "{d}/notes.txt"), None, (EXISTS,)),
    (("skin", "compare", "--out", "{d}", "--overwrite"), None, (THEIRS,)),
    # ---------------------------------------------------------------- skin pulse
    (("skin", "pulse", V, "--out", "{d}/p", "--fps", "nan"), "--fps", ()),
    (("skin", "pulse", V, "--out", "{d}/p", "--fps", 0), "--fps", ()),
    (("skin", "pulse", V, "--out", "{d}/p", "--fps", 1e9), "--fps", ("two of its periods",)),
    (("skin", "pulse", V, "--out", "{d}/p", "--band", "0.5,100"), "--band", ("Nyquist",)),
    (("skin", "pulse", V, "--out", "{d}/p", "--band", "2,0.5"), "--band", ()),
    (("skin", "pulse", V, "--out", "{d}/p", "--band", "nan,2"), "--band", ()),
    (("skin", "pulse", V, "--out", "{d}/p", "--band", "-1,2"), "--band", ()),
    (("skin", "pulse", V, "--out", "{d}/p", "--band", "1"), "--band", ("LOW,HIGH",)),
    (("skin", "pulse", V, "--out", "{d}/p", "--rate-band", "0.5,100"), "--rate-band", ("Nyquist",)),
    (("skin", "pulse", V, "--out", "{d}/p", "--rate-band", "0,2"), "--rate-band", ()),
    (("skin", "pulse", V, "--out", "{d}/p", "--alpha", -1), "--alpha", ()),
    (("skin", "pulse", V, "--out", "{d}/p", "--alpha", "nan"), "--alpha", ()),
    (("skin", "pulse", V, "--out", "{d}/p", "--alpha", 1e30), "--alpha", ("<= 1000",)),
    (("skin", "pulse", V, "--out", "{d}/p", "--levels", -1), "--levels", ()),
    (("skin", "pulse", V, "--out", "{d}/p", "--levels", 100), "--levels", ("too many",)),
    (("skin", "pulse", V, "--out", "{d}/p", "--pyramid", "steerable"), "--pyramid", ()),
    (("skin", "pulse", V, "--out", "{d}/p", "--method", "music"), "--method", ()),
    (("skin", "pulse", V, "--out", "{d}/p", "--channel", "infrared"), "--channel", ()),
    (("skin", "pulse", V, "--out", "{d}/p", "--region", "1000,1000"), "--region", ()),
    (("skin", "pulse", V, "--out", "{d}/p", "--region", "a,b"), "--region", ()),
    (("skin", "pulse", V, "--out", "{d}/p", "--mask", "{d}/photo.png"), "--mask", ("64x64",)),
    (("skin", "pulse", V, "--out", "{d}/p", "--mask", "{d}/notes.txt"), "--mask", ()),
    (("skin", "pulse", V, "--out", "{d}/p", "--magnified", "{d}/m.jpg"), "--magnified", (".tif",)),
    (("skin", "pulse", V, "--out", "{d}/p", "--magnified", "{d}/clip.tif"), None, ("clip.tif: " + EXISTS,)),
    (("skin", "pulse", V, "--out", "{d}/p", "--magnified", "{d}/clip.tif", "--overwrite"), None, (THEIRS,)),
    (("skin", "pulse", V, "--out", "{d}/p", "--magnified", "{d}/movie.mp4", "--overwrite"), None, (THEIRS,)),
    (("skin", "pulse", V, "--out", "{d}/p.tif", "--magnified", "{d}/p.tif"), None, ("named twice",)),
    (("skin", "pulse", "{d}/notes.txt", "--out", "{d}/p"), None, ("unknown video format",)),
    (("skin", "pulse", "{d}/clip.tif", "--out", "{d}/p"), None, ("no frame rate",)),
    (("skin", "pulse", V, "--out", "{d}/notes.txt"), None, (EXISTS,)),
    (("skin", "pulse", V, "--out", "{d}", "--overwrite"), None, (THEIRS,)),
    # ---------------------------------------------------------------- skin video
    (("skin", "video", "--out", "{d}/o.tif", "--bpm", 0), "--bpm", ("30",)),
    (("skin", "video", "--out", "{d}/o.tif", "--bpm", "nan"), "--bpm", ()),
    (("skin", "video", "--out", "{d}/o.tif", "--bpm", 1000), "--bpm", ("240",)),
    (("skin", "video", "--out", "{d}/o.tif", "--seconds", 0), "--seconds", ()),
    (("skin", "video", "--out", "{d}/o.tif", "--seconds", "nan"), "--seconds", ()),
    (("skin", "video", "--out", "{d}/o.tif", "--seconds", 1e6), "--seconds", ("of memory",)),
    (("skin", "video", "--out", "{d}/o.tif", "--seconds", 0.05), "--seconds", ("at least 8",)),
    (("skin", "video", "--out", "{d}/o.tif", "--fps", 0), "--fps", ()),
    (("skin", "video", "--out", "{d}/o.tif", "--fps", 1e6, "--seconds", 1), "--fps", ("75",)),
    (("skin", "video", "--out", "{d}/o.tif", "--fps", 2), "--fps", ("Nyquist",)),
    (("skin", "video", "--out", "{d}/o.tif", "--method", "sideways"), "--method", ()),
    (("skin", "video", "--out", "{d}/o.tif", "--size", 0, 0), "--size", ()),
    (("skin", "video", "--out", "{d}/o.tif", "--size", 100000, 100000), "--size", ("of memory",)),
    (("skin", "video", "--out", "{d}/o.tif", "--projector-rows", 0), "--projector-rows", ()),
    (("skin", "video", "--out", "{d}/o.tif", "--projector-rows", 100000), "--projector-rows", ()),
    (("skin", "video", "--out", "{d}/o.tif", "--seed", -1), "--seed", ()),
    (("skin", "video", "--out", "{d}/o.tif", "--hrv", -1), "--hrv", ()),
    (("skin", "video", "--out", "{d}/o.tif", "--hrv", 5), "--hrv", ("0.2",)),
    (("skin", "video", "--out", "{d}/o.tif", "--rsa", 5), "--rsa", ()),
    (("skin", "video", "--out", "{d}/o.tif", "--breaths-per-min", 0), "--breaths-per-min", ()),
    (("skin", "video", "--out", "{d}/o.tif", "--breaths-per-min", 1e9), "--breaths-per-min", ("60",)),
    (("skin", "video", "--out", "{d}/o.tif", "--pulse-amplitude", 5), "--pulse-amplitude", ("0.1",)),
    (("skin", "video", "--out", "{d}/o.tif", "--pulse-amplitude", -0.1), "--pulse-amplitude", ()),
    (("skin", "video", "--out", "{d}/o.tif", "--delay-us", "nan"), "--delay-us", ()),
    (("skin", "video", "--out", "{d}/o.tif", "--delay-us", 1e9), "--delay-us", ()),
    (("skin", "video", "--out", "{d}/o.tif", "--delay-us", 2000), "--delay-us", ("kernel",)),
    (("skin", "video", "--out", "{d}/o.tif", "--exposure-us", 0), "--exposure-us", ()),
    (("skin", "video", "--out", "{d}/o.tif", "--exposure-us", 1e9), "--exposure-us", ()),
    (("skin", "video", "--out", "{d}/o.jpg"), "--out", (".tif",)),
    (("skin", "video", "--out", "{d}/clip.tif"), None, (EXISTS,)),
    (("skin", "video", "--out", "{d}/clip.tif", "--overwrite"), None, (THEIRS,)),
    (("skin", "video", "--out", "{d}/movie.mp4", "--overwrite"), None, (THEIRS,)),
    (("skin", "video", "--out", "{d}/arm.tif"), None, ("arm_video_vein_mask.png: " + EXISTS,)),
    (("skin", "video", "--out", "{d}/arm.tif", "--overwrite"), None, ("arm_video_vein_mask.png", THEIRS)),
    # ---------------------------------------------------------------- skin pulse-report
    (("skin", "pulse-report", "--out", "{d}/r", "--size", 0, 0), "--size", ()),
    (("skin", "pulse-report", "--out", "{d}/r", "--size", 8, 8), "--size", ("pyramid levels",)),
    (("skin", "pulse-report", "--out", "{d}/r", "--size", 100000, 100000), "--size", ("of memory",)),
    (("skin", "pulse-report", "--out", "{d}/r", "--projector-rows", 0), "--projector-rows", ()),
    (("skin", "pulse-report", "--out", "{d}/r", "--seconds", 0), "--seconds", ()),
    (("skin", "pulse-report", "--out", "{d}/r", "--seconds", 1), "--seconds", ("2.86",)),
    (("skin", "pulse-report", "--out", "{d}/r", "--seconds", 1e9), "--seconds", ("of memory",)),
    (("skin", "pulse-report", "--out", "{d}/r", "--fps", 0), "--fps", ()),
    (("skin", "pulse-report", "--out", "{d}/r", "--fps", "nan"), "--fps", ()),
    (("skin", "pulse-report", "--out", "{d}/r", "--fps", 1e9), "--fps", ("75",)),
    (("skin", "pulse-report", "--out", "{d}/r", "--fps", 3), "--fps", ("Nyquist",)),
    (("skin", "pulse-report", "--out", "{d}/notes.txt"), None, (EXISTS,)),
    (("skin", "pulse-report", "--out", "{d}", "--overwrite"), None, (THEIRS,)),
    # ---------------------------------------------------------------- view
    (("view", "wax", "--no-browser", "--port", 99999), "--port", ("65535",)),
    (("view", "wax", "--no-browser", "--port", -1), "--port", ()),
    (("view", "wax", "--no-browser", "--truth-scale", "nan"), "--truth-scale", ()),
    (("view", "wax", "--no-browser", "--truth-scale", 0), "--truth-scale", ()),
    (("view", "wax", "--no-browser", "--size", 0), "--size", ()),
    (("view", "wax", "--no-browser", "--size", 100000), "--size", ("of memory",)),
    (("view", "wax", "--no-browser", "--projector-rows", 0), "--projector-rows", ()),
    (("view", "wax", "--no-browser", "--seed", -1), "--seed", ()),
    (("view", "{d}/notes.json", "--no-browser"), None, ("not a planeray stack",)),
    (("view", S, "--no-browser", "--truth", "{d}/notes.json"), None, ("notes.json",)),
    (("view", "wax", "--no-browser", "--pattern", "{d}/notes.json"), None, ("notes.json",)),
    # ---------------------------------------------------------------- video
    (("video", "wax", "--out", "{d}/o.mp4", "--fps", 1e9), "--fps", ("240",)),
    (("video", "wax", "--out", "{d}/o.mp4", "--fps", 0), "--fps", ()),
    (("video", "wax", "--out", "{d}/o.mp4", "--fps", "nan"), "--fps", ()),
    (("video", "wax", "--out", "{d}/o.mp4", "--frames", 0), "--frames", ()),
    (("video", "wax", "--out", "{d}/o.mp4", "--frames", 10**9), "--frames", ("100000",)),
    (("video", "wax", "--out", "{d}/o.mp4", "--from", "nan"), "--from", ()),
    (("video", "wax", "--out", "{d}/o.mp4", "--from", -1e9), "--from", ()),
    (("video", "wax", "--out", "{d}/o.mp4", "--to", 1e9), "--to", ()),
    (("video", "wax", "--out", "{d}/o.mp4", "--sweep", "exposure", "--from", -5), "--from", ()),
    (("video", "wax", "--out", "{d}/o.mp4", "--sweep", "gain"), "--sweep", ()),
    (("video", "wax", "--out", "{d}/o.mp4", "--delay-us", "nan"), "--delay-us", ()),
    (("video", "wax", "--out", "{d}/o.mp4", "--exposure-us", 0), "--exposure-us", ()),
    (("video", "wax", "--out", "{d}/o.mp4", "--exposure-us", 1e9), "--exposure-us", ()),
    (("video", "wax", "--out", "{d}/o.mp4", "--white", -1), "--white", ()),
    (("video", "wax", "--out", "{d}/o.mp4", "--white", "nan"), "--white", ()),
    (("video", "wax", "--out", "{d}/o.mp4", "--gamma", 0), "--gamma", ()),
    (("video", "wax", "--out", "{d}/o.mp4", "--colormap", "jet"), "--colormap", ()),
    (("video", "wax", "--out", "{d}/o.mp4", "--scale", 0), "--scale", ()),
    (("video", "wax", "--out", "{d}/o.mp4", "--scale", 1000), "--scale", ()),
    (("video", "wax", "--out", "{d}/o.mp4", "--size", 0), "--size", ()),
    (("video", "wax", "--out", "{d}/o.mp4", "--size", 100000), "--size", ("of memory",)),
    (("video", "wax", "--out", "{d}/o.mp4", "--seed", -1), "--seed", ()),
    (("video", "wax", "--out", "{d}/o.jpg"), "--out", (".mp4",)),
    (("video", "wax", "--out", "{d}/movie.mp4"), None, (EXISTS,)),
    (("video", "wax", "--out", "{d}/movie.mp4", "--overwrite"), None, (THEIRS,)),
    (("video", "{d}/notes.json", "--out", "{d}/o.mp4"), None, ("not a planeray stack",)),
]


def _words(args, inputs):
    return [str(a).replace("{s}", str(inputs["s"])).replace("{v}", str(inputs["v"])) for a in args]


@pytest.mark.parametrize(
    ("args", "option", "needles"), CASES, ids=[" ".join(map(str, c[0][:2] + c[0][-2:])) for c in CASES]
)
def test_bad_input_is_refused_before_any_work_naming_the_option(args, option, needles, folder, inputs):
    run_bad(_words(args, inputs), folder=folder, option=option, needles=needles)


def test_there_are_about_a_hundred_cases_over_every_command_of_the_area():
    commands = {" ".join(map(str, c[0][:2])) if c[0][0] == "skin" else c[0][0] for c in CASES}
    assert commands == {
        "skin simulate",
        "skin validate",
        "skin veins",
        "skin enhance",
        "skin compare",
        "skin pulse",
        "skin video",
        "skin pulse-report",
        "view",
        "video",
    }
    assert len(CASES) >= 100

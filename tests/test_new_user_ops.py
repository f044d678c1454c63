"""A new user's bad inputs to the capture, calibration, rendering and analysis commands (issue 24).

``calibrate lines | simulate-lines | delay-zero``, ``acquire``, ``devices``, ``render``,
``render-examples``, ``simulate``, ``info``, ``contact-sheet``, ``profiles``, ``synth``,
``figure``, ``export``, ``import``, ``demux``, ``emulate``, ``separate direct-global``,
``mc profile`` and ``study demux``: every number, path and choice they take, out of range,
NaN, infinite, absurdly large, of the wrong type or extension, and the user's own files as
outputs (with and without ``--overwrite``) or where a planeray file is expected.

Each case runs in a folder of the user's own files (``tests/_new_user.py``) and checks exit 1,
one ``error:`` line without a traceback or "unexpected", the option as typed (never the
library's name), and that no file of the user's changed and nothing was left behind.  Every
case is refused before any work (the whole file runs in well under a minute).
"""

from __future__ import annotations

import importlib.util
import json

import numpy as np
import pytest
from typer.testing import CliRunner

from _new_user import run_bad, user_files
from planeray.cli import app

runner = CliRunner()
HAS_MITSUBA = importlib.util.find_spec("mitsuba") is not None


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    """planeray's own files to give the commands: a stack, its transport, an export folder, a line sweep."""
    d = tmp_path_factory.mktemp("ops_inputs")
    for args in (
        ("simulate", "wax", "--size", 24, 20, "--projector-rows", 90, "--out", d / "s.zarr"),
        ("demux", d / "s.zarr", "--out", d / "T.zarr"),
        ("export", d / "s.zarr", "--out", d / "exp"),
        ("calibrate", "simulate-lines", "--out", d / "lines.npz"),
    ):
        res = runner.invoke(app, [str(a) for a in args])
        assert res.exit_code == 0, res.output
    return {"S": d / "s.zarr", "T": d / "T.zarr", "X": d / "exp", "L": d / "lines.npz"}


@pytest.fixture
def folder(tmp_path):
    """The user's folder: their own files, and some that carry the names planeray's outputs would have."""
    d = tmp_path / "user"
    files = user_files(d)
    (d / "dup.json").write_text('{"lines_per_second": 1, "lines_per_second": 2}')
    (d / "list.json").write_text("[1, 2]")
    (d / "calstr.json").write_text(json.dumps({"calibration": "my notes on the rig"}))
    for sub, name in (("figs", "fig8.json"), ("emu", "emulation.json"), ("st", "study.json"), ("rex", "x.txt")):
        (d / sub).mkdir()
        (d / sub / name).write_text(json.dumps({"mine": True}))
    files["image"].replace(d / "rex" / "mirror_ball.png")
    user_files(d)  # photo.png again
    return d


S, T, X, L = "{S}", "{T}", "{X}", "{L}"
SIM_LINES = ("calibrate", "simulate-lines", "--out", "{d}/new.npz")
DZ = ("calibrate", "delay-zero", "--simulate")
ACQ = ("acquire", "--out", "{d}/a.zarr", "--sweep", "quick")
SIM = ("simulate", "wax", "--out", "{d}/w.zarr", "--size", 16, 16)
RENDER = ("render", "mirror_ball", "--out", "{d}/R.zarr", "--size", 8, 8, "--rows", 16, "--spp", 1)
REX = ("render-examples", "--out", "{d}/ex", "--size", 8, "--rows", 16, "--spp", 1)
EMU = ("emulate", "wax", "--out", "{d}/e", "--size", 16, 16)
SEP = ("separate", "direct-global", "wax", "--out", "{d}/g", "--size", 16, 16)
MC = ("mc", "profile", "--out", "{d}/m.csv", "--photons", 100, "--rows", 2)

# (args, option as typed that the message must name (None: a file or a choice), text the message must hold)
CASES = [
    # ------------------------------------------------------------------ calibrate simulate-lines
    (("calibrate", "simulate-lines", "--out", "{d}/lines.npz"), None, ("lines.npz", "already exists")),
    (("calibrate", "simulate-lines", "--out", "{d}/lines.npz", "--overwrite"), None, ("planeray did not write",)),
    (("calibrate", "simulate-lines", "--out", "{d}/lines.txt"), "--out", (".npz",)),
    ((*SIM_LINES, "--lines-per-second", 0), "--lines-per-second", ()),
    ((*SIM_LINES, "--lines-per-second", "nan"), "--lines-per-second", ()),
    ((*SIM_LINES, "--lines-per-second", "1e12"), "--lines-per-second", ()),
    ((*SIM_LINES, "--size", 0, 8), "--size", ()),
    ((*SIM_LINES, "--size", 99999, 64), "--size", ()),
    ((*SIM_LINES, "--size", 8, 8), "--size", ("do not fit",)),
    ((*SIM_LINES, "--projector-rows", 0), "--projector-rows", ()),
    ((*SIM_LINES, "--projector-rows", 100000), "--projector-rows", ()),
    ((*SIM_LINES, "--exposure-us", 0), "--exposure-us", ()),
    ((*SIM_LINES, "--exposure-us", "nan"), "--exposure-us", ()),
    ((*SIM_LINES, "--exposure-us", "inf"), "--exposure-us", ()),
    ((*SIM_LINES, "--exposure-us", "1e9"), "--exposure-us", ()),
    ((*SIM_LINES, "--seed", -1), "--seed", ()),
    # ------------------------------------------------------------------ calibrate lines
    (("calibrate", "lines", L, "--exposure-us", 0), "--exposure-us", ()),
    (("calibrate", "lines", L, "--exposure-us", "inf"), "--exposure-us", ()),
    (("calibrate", "lines", L, "--exposure-us", "1e12"), "--exposure-us", ()),
    (("calibrate", "lines", L, "--exposure-us", 19999), "--exposure-us", ("lines/s",)),
    (("calibrate", "lines", L, "--rows-per-line", 0), "--rows-per-line", ()),
    (("calibrate", "lines", L, "--rows-per-line", 100000), "--rows-per-line", ()),
    (("calibrate", "lines", "{d}/lines.npz"), None, ("not a planeray line sweep",)),
    (("calibrate", "lines", "{d}/missing.npz"), None, ("not found",)),
    (("calibrate", "lines", L, "--write", "{d}/notes.txt"), "--write", (".json",)),
    (("calibrate", "lines", L, "--write", "{d}/photo.png"), "--write", ()),
    (("calibrate", "lines", L, "--write", "{d}/dup.json"), "--write", ("appears twice",)),
    (("calibrate", "lines", L, "--write", "{d}/list.json"), "--write", ("JSON object",)),
    (("calibrate", "lines", L, "--write", "{d}/calstr.json"), "--write", ("'calibration'",)),
    # ------------------------------------------------------------------ calibrate delay-zero
    ((*DZ, "--exposure-us", 0), "--exposure-us", ()),
    ((*DZ, "--exposure-us", "1e12"), "--exposure-us", ()),
    ((*DZ, "--exposure-us", "nan"), "--exposure-us", ()),
    ((*DZ, "--delay-error-us", "nan"), "--delay-error-us", ()),
    ((*DZ, "--delay-error-us", "inf"), "--delay-error-us", ()),
    ((*DZ, "--delay-error-us", "1e12"), "--delay-error-us", ("within",)),
    ((*DZ, "--seed", -1), "--seed", ()),
    ((*DZ, "--frame-period-us", 1000), "--frame-period-us", ("--device only",)),
    ((*DZ, "--base-trigger-delay-us", 5), "--base-trigger-delay-us", ("--device only",)),
    ((*DZ, "--calibration", "{d}/notes.json"), "--calibration", ("--device only",)),
    ((*DZ, "--write", "{d}/notes.txt"), "--write", ()),
    ((*DZ, "--write", "{d}/list.json"), "--write", ()),
    (("calibrate", "delay-zero", S, "--simulate"), None, ("one of STACK",)),
    (("calibrate", "delay-zero", S, "--delay-error-us", 3), "--delay-error-us", ("--simulate only",)),
    (("calibrate", "delay-zero", S, "--exposure-us", 601), "--exposure-us", ("600, 750",)),
    (("calibrate", "delay-zero", "{d}/notes.txt"), None, ("notes.txt",)),
    (("calibrate", "delay-zero"), None, ("STACK",)),
    (("calibrate", "delay-zero", "--device", "sim", "--frame-period-us", 0), "--frame-period-us", ()),
    (("calibrate", "delay-zero", "--device", "sim", "--frame-period-us", "nan"), "--frame-period-us", ()),
    (("calibrate", "delay-zero", "--device", "ueye", "--base-trigger-delay-us", -5), "--base-trigger-delay-us", ()),
    (("calibrate", "delay-zero", "--device", "sim", "-O", "noise=3"), "-O noise", ()),
    (("calibrate", "delay-zero", "--device", "sim", "-O", "size=[0, 8]"), "-O size", ()),
    (("calibrate", "delay-zero", "--device", "nope"), "--device", ()),
    (("calibrate", "delay-zero", "--device", "sim", "--sweep", "nope"), "--sweep", ()),
    # ------------------------------------------------------------------ acquire
    (("acquire", "--out", "{d}/notes.txt"), None, ("already exists",)),
    (("acquire", "--out", "{d}/notes.json", "--overwrite"), None, ("planeray did not write",)),
    ((*ACQ, "--size", 0, 16), "--size", ()),
    ((*ACQ, "--size", 5000, 5000), "--size", ()),
    ((*ACQ, "--projector-rows", 0), "--projector-rows", ()),
    ((*ACQ, "--projector-rows", 99999), "--projector-rows", ()),
    ((*ACQ, "--seed", -1), "--seed", ()),
    ((*ACQ, "--lines-per-second", 0), "--lines-per-second", ()),
    ((*ACQ, "--lines-per-second", -1), "--lines-per-second", ()),
    ((*ACQ, "--lines-per-second", "inf"), "--lines-per-second", ()),
    ((*ACQ, "--lines-per-second", "1e12"), "--lines-per-second", ()),
    ((*ACQ, "-O", "size=[1]"), "-O size", ()),
    ((*ACQ, "-O", "size=abc"), "-O size", ()),
    ((*ACQ, "-O", "seed=1.5"), "-O seed", ()),
    ((*ACQ, "-O", "noise=3"), "-O noise", ("true or false",)),
    ((*ACQ, "-O", 'lines_per_second="x"'), "-O lines_per_second", ("a number",)),
    ((*ACQ, "-O", "scene=nope"), "-O scene", ()),
    ((*ACQ, "-O", "bogus=1"), "-O bogus", ("no option",)),
    ((*ACQ, "-O", "size"), "--device-option", ("KEY=VALUE",)),
    ((*ACQ, "--size", 16, 16, "-O", "size=[32, 32]"), "--device-option", ("twice",)),
    ((*ACQ, "--camera-id", 3), "--camera-id", ("no option",)),
    ((*ACQ, "--device", "nope"), "--device", ()),
    ((*ACQ, "--sweep", "nope"), "--sweep", ()),
    ((*ACQ, "--scene", "nope"), "--scene", ()),
    ((*ACQ, "--calibration", "{d}/notes.json"), "--calibration", ("no calibration field",)),
    ((*ACQ, "--calibration", "{d}/photo.png"), "--calibration", ()),
    ((*ACQ, "--calibration", "{d}/missing.json"), "--calibration", ("not found",)),
    ((*ACQ, "--device", "replay", "--replay", "{d}/notes.txt"), "--replay", ()),
    ((*ACQ, "--device", "replay"), None, ("replay",)),
    ((*ACQ, "--device", "ueye"), "--base-trigger-delay-us", ()),
    # ------------------------------------------------------------------ simulate
    ((*SIM, "--lines-per-second", "1e12"), "--lines-per-second", ()),
    ((*SIM, "--lines-per-second", -1), "--lines-per-second", ()),
    ((*SIM, "--read-noise-e", "1e5"), "--read-noise-e", ()),
    ((*SIM, "--jitter-us", "1e12"), "--jitter-us", ()),
    ((*SIM, "--row-jitter-us", "nan"), "--row-jitter-us", ()),
    ((*SIM, "--frames", 100000000), "--frames", ()),
    ((*SIM, "--projector-rows", 100000), "--projector-rows", ()),
    (("simulate", "wax", "--out", "{d}/w.zarr", "--size", 5000, 5000), "--size", ()),
    (("simulate", "wax", "--out", "{d}/w.zarr", "--size", 4, 4), "--size", ()),
    ((*SIM, "--seed", -1), "--seed", ()),
    ((*SIM, "--full-well-e", 0), "--full-well-e", ()),
    ((*SIM, "--laser-electrons", "inf"), "--laser-electrons", ()),
    ((*SIM, "--ambient-e-per-us", "1e12"), "--ambient-e-per-us", ()),
    ((*SIM, "--bit-depth", 17), "--bit-depth", ()),
    ((*SIM, "--black-level", 5000), "--black-level", ()),
    ((*SIM, "--sweep", "nope"), "--sweep", ()),
    ((*SIM, "--truth", "{d}/w.zarr"), None, ("named twice",)),
    ((*SIM, "--truth", "{d}/notes.json"), None, ("already exists",)),
    # ------------------------------------------------------------------ info, contact-sheet
    (("info", "{d}/notes.txt"), None, ("notes.txt",)),
    (("info", "{d}/photo.png"), None, ("photo.png",)),
    (("contact-sheet", S, "--out", "{d}/c.png", "--gamma", 0), "--gamma", ()),
    (("contact-sheet", S, "--out", "{d}/c.png", "--gamma", "nan"), "--gamma", ()),
    (("contact-sheet", S, "--out", "{d}/c.png", "--gamma", "1e12"), "--gamma", ()),
    (("contact-sheet", S, "--out", "{d}/c.png", "--max-delays", 0), "--max-delays", ()),
    (("contact-sheet", S, "--out", "{d}/photo.png"), None, ("already exists",)),
    (("contact-sheet", S, "--out", "{d}/photo.png", "--overwrite"), None, ("planeray did not write",)),
    (("contact-sheet", S, "--out", "{d}/c.jpg"), "--out", (".png",)),
    (("contact-sheet", "{d}/notes.txt", "--out", "{d}/c.png"), None, ("notes.txt",)),
    # ------------------------------------------------------------------ profiles
    (("profiles", S, "--pixel", "999,3", "--out", "{d}/p.png"), "--pixel", ("outside",)),
    (("profiles", S, "--pixel", "-1,3", "--out", "{d}/p.png"), "--pixel", ()),
    (("profiles", S, "--pixel", "a,b", "--out", "{d}/p.png"), "--pixel", ()),
    (("profiles", S, "--pixel", "3,3", "--exposure-us", 601, "--out", "{d}/p.png"), "--exposure-us", ()),
    (("profiles", S, "--pixel", "3,3", "--exposure-us", "nan", "--out", "{d}/p.png"), "--exposure-us", ()),
    (("profiles", S, "--pixel", "3,3", "--out", "{d}/p.png", "--csv", "{d}/table.csv"), None, ("already exists",)),
    (
        ("profiles", S, "--pixel", "3,3", "--out", "{d}/p.png", "--csv", "{d}/table.csv", "--overwrite"),
        None,
        ("table.csv", "planeray did not write"),
    ),
    (("profiles", S, "--pixel", "3,3", "--out", "{d}/p.png", "--csv", "{d}/p.txt"), "--csv", (".csv",)),
    (("profiles", S, "--pixel", "3,3", "--out", "{d}/photo.png", "--overwrite"), None, ("planeray did not write",)),
    (
        ("profiles", S, "--pixel", "3,3", "--transport", T, "--classify", "{d}/p.png", "--out", "{d}/p.png"),
        None,
        ("named twice",),
    ),
    (("profiles", S, "--classify", "{d}/l.png", "--out", "{d}/p.png"), "--transport", ()),
    (("profiles", S, "--out", "{d}/p.png"), "--pixel", ()),
    (("profiles", S, "--pixel", "3,3", "--transport", "{d}/notes.json", "--out", "{d}/p.png"), None, ("notes.json",)),
    # ------------------------------------------------------------------ synth
    (("synth", T, "--sharpen", "1e12", "--out", "{d}/e.png"), "--sharpen", ()),
    (("synth", T, "--sharpen", 0, "--out", "{d}/e.png"), "--sharpen", ()),
    (("synth", T, "--short-range", "nan", "--out", "{d}/e.png"), "--short-range", ()),
    (("synth", T, "--long-range", "1e12", "--out", "{d}/e.png"), "--long-range", ()),
    (("synth", T, "--band", 0, 0, "--out", "{d}/e.png"), "--band", ()),
    (("synth", T, "--band", "1e12", 600, "--out", "{d}/e.png"), "--band", ()),
    (("synth", T, "--relight", 9999, "--out", "{d}/e.png"), "--relight", ()),
    (("synth", T, "--relight", "nan", "--out", "{d}/e.png"), "--relight", ()),
    (("synth", T, "--epipolar", "--out", "{d}/scan.tif", "--overwrite"), None, ("planeray did not write",)),
    (("synth", T, "--epipolar", "--out", "{d}/e.jpg"), "--out", ()),
    (("synth", T, "--out", "{d}/e.png"), None, ("choose exactly one",)),
    (("synth", T, "--epipolar", "--non-epipolar", "--out", "{d}/e.png"), None, ("choose exactly one",)),
    (("synth", S, "--epipolar", "--out", "{d}/e.png"), None, ("s.zarr",)),
    # ------------------------------------------------------------------ figure
    (("figure", "fig8", "--out", "{d}/f", "--size", 0), "--size", ()),
    (("figure", "fig8", "--out", "{d}/f", "--size", 5000), "--size", ()),
    (("figure", "fig8", "--out", "{d}/f", "--seed", -1), "--seed", ()),
    (("figure", "effects", "--out", "{d}/f", "--size", 32), "--size", ()),
    (("figure", "fig99", "--out", "{d}/f"), None, ("unknown figure",)),
    (("figure", "fig8", "--out", "{d}/notes.txt"), "--out", ("is a file",)),
    (("figure", "fig8", "--out", "{d}/figs"), None, ("fig8.json", "already exists")),
    (("figure", "fig8", "--out", "{d}/figs", "--overwrite"), None, ("fig8.json", "planeray did not write")),
    # ------------------------------------------------------------------ export, import
    (("export", S, "--out", "{d}/x", "--bit-depth", 0), "--bit-depth", ()),
    (("export", S, "--out", "{d}/x", "--bit-depth", 17), "--bit-depth", ()),
    (("export", S, "--out", "{d}/x", "--black-level", -1), "--black-level", ()),
    (("export", S, "--out", "{d}/x", "--black-level", 70000), "--black-level", ()),
    (("export", S, "--out", "{d}/x", "--format", "jpg"), "--format", ()),
    (("export", S, "--out", "{d}/figs", "--overwrite"), None, ("planeray did not write",)),
    (("export", S, "--out", "{d}/notes.txt"), None, ("already exists",)),
    (("import", "{d}/notes.txt", "--out", "{d}/i.zarr"), None, ("notes.txt",)),
    (("import", "{d}/figs", "--out", "{d}/i.zarr"), None, ("acquisition.json",)),
    (("import", X, "--out", "{d}/notes.txt"), None, ("already exists",)),
    (("import", X, "--out", "{d}/figs", "--overwrite"), None, ("planeray did not write",)),
    # ------------------------------------------------------------------ demux
    (("demux", S, "--out", "{d}/D.zarr", "--alpha", -1), "--alpha", ()),
    (("demux", S, "--out", "{d}/D.zarr", "--alpha", "1e12"), "--alpha", ()),
    (("demux", S, "--out", "{d}/D.zarr", "--beta", "nan"), "--beta", ()),
    (("demux", S, "--out", "{d}/D.zarr", "--method", "bogus"), "--method", ()),
    (("demux", S, "--out", "{d}/D.zarr", "--workers", 0), "--workers", ()),
    (("demux", S, "--out", "{d}/D.zarr", "--workers", 100000), "--workers", ()),
    (("demux", S, "--out", "{d}/D.zarr", "--chunk-rows", 0), "--chunk-rows", ()),
    (("demux", S, "--out", "{d}/D.zarr", "--chunk-rows", 100000), "--chunk-rows", ()),
    (("demux", S, "--out", "{d}/D.zarr", "--tol", 2), "--tol", ()),
    (("demux", S, "--out", "{d}/D.zarr", "--ambient", "yes"), "--ambient", ("none, estimate",)),
    (("demux", S, "--out", "{d}/D.zarr", "--ambient", "estimate", "--method", "pinv"), "--ambient", ("--method pinv",)),
    (("demux", S, "--out", "{d}/D.zarr", "--ambient", "estimate", "--beta", 0), "--beta", ("not identifiable",)),
    (("demux", S, "--out", "{d}/notes.txt"), None, ("already exists",)),
    (("demux", S, "--out", S, "--overwrite"), None, ("is also an input (STACK)",)),
    (("demux", "{d}/photo.png", "--out", "{d}/D.zarr"), None, ("photo.png",)),
    # ------------------------------------------------------------------ emulate, separate direct-global
    ((*EMU, "--delay-us", "1e12"), "--delay-us", ()),
    ((*EMU, "--exposure-us", 0), "--exposure-us", ()),
    ((*EMU, "--exposure-us", "1e12"), "--exposure-us", ()),
    ((*EMU, "--spacing-rows", 0), "--spacing-rows", ()),
    ((*EMU, "--spacing-rows", 1000), "--spacing-rows", ()),
    ((*EMU, "--seed", -1), "--seed", ()),
    ((*EMU, "--ambient", "nan"), "--ambient-e-per-us", ()),
    ((*EMU, "--projector-rows", 0), "--projector-rows", ()),
    (("emulate", "wax", "--out", "{d}/e", "--size", 0, 0), "--size", ()),
    (("emulate", "wax", "--out", "{d}/notes.txt"), "--out", ("is a file",)),
    (("emulate", "wax", "--out", "{d}/emu", "--size", 16, 16), None, ("emulation.json", "already exists")),
    (("emulate", "wax", "--out", "{d}/emu", "--overwrite"), None, ("emulation.json", "planeray did not write")),
    (("emulate", "nope", "--out", "{d}/e"), None, ("nope",)),
    ((*SEP, "--shifts", 0), "--shifts", ()),
    ((*SEP, "--contrast-b", 1.5), "--contrast-b", ()),
    ((*SEP, "--period-rows", 3), "--period-rows", ()),
    ((*SEP, "--period-rows", 4, "--shifts", 6), "--shifts", ()),
    ((*SEP, "--epipolar-exposure-us", "1e12"), "--epipolar-exposure-us", ()),
    ((*SEP, "--ambient", -1), "--ambient-e-per-us", ()),
    (("separate", "direct-global", "wax", "--out", "{d}/g", "--size", 9999, 16), "--size", ()),
    (("separate", "direct-global", "wax", "--out", "{d}/notes.txt"), "--out", ()),
    # ------------------------------------------------------------------ mc profile
    ((*MC, "--sigma-s", "nan"), "--sigma-s", ()),
    ((*MC, "--sigma-s", "1e12"), "--sigma-s", ()),
    ((*MC, "--sigma-a", -1), "--sigma-a", ()),
    ((*MC, "--g", 1.5), "--g", ()),
    ((*MC, "--n", 0), "--n", ()),
    ((*MC, "--n", "1e12"), "--n", ()),
    ((*MC, "--thickness-mm", 0), "--thickness-mm", ()),
    ((*MC, "--photons", 0), "--photons", ()),
    (("mc", "profile", "--out", "{d}/m.csv", "--photons", 10**14), "--photons", ()),
    ((*MC, "--rows", -1), "--rows", ()),
    ((*MC, "--mm-per-row", "inf"), "--mm-per-row", ()),
    ((*MC, "--source-width-mm", "inf"), "--source-width-mm", ()),
    ((*MC, "--cutoff-mm", 0), "--cutoff-mm", ()),
    ((*MC, "--diffusion-depth-mfp", -1), "--diffusion-depth-mfp", ()),
    ((*MC, "--seed", -1), "--seed", ()),
    (("mc", "profile", "--out", "{d}/table.csv"), None, ("already exists",)),
    (("mc", "profile", "--out", "{d}/table.csv", "--overwrite"), None, ("planeray did not write",)),
    (("mc", "profile", "--out", "{d}/notes.csv"), None, ("notes.json", "already exists")),
    (("mc", "profile", "--out", "{d}/m.txt"), "--out", (".csv",)),
    ((*MC, "--plot", "{d}/photo.png", "--overwrite"), None, ("photo.png", "planeray did not write")),
    ((*MC, "--plot", "{d}/p.jpg"), "--plot", ()),
    # ------------------------------------------------------------------ study demux
    (("study", "demux", "--out", "{d}/s", "--seeds", 0), "--seeds", ()),
    (("study", "demux", "--out", "{d}/s", "--seeds", 100000), "--seeds", ()),
    (("study", "demux", "--out", "{d}/s", "--provider", "bogus"), "--provider", ()),
    (("study", "demux", "--out", "{d}/notes.txt"), "--out", ()),
    (("study", "demux", "--out", "{d}/st"), None, ("study.json", "already exists")),
    (("study", "demux", "--out", "{d}/st", "--overwrite"), None, ("study.json", "planeray did not write")),
]

MITSUBA_CASES = [
    ((*RENDER, "--rows", 100000), "--rows", ()),
    (("render", "mirror_ball", "--out", "{d}/R.zarr", "--size", 5000, 5000), "--size", ()),
    ((*RENDER, "--spp", 10000000), "--spp", ()),
    ((*RENDER, "--batch-spp", 10000000), "--batch-spp", ()),
    ((*RENDER, "--caustic-paths", 0), "--caustic-paths", ()),
    ((*RENDER, "--no-caustics", "--caustic-paths", 10), "--caustic-paths", ()),
    ((*RENDER, "--seed", -1), "--seed", ()),
    ((*RENDER, "--band-rows", 100000), "--band-rows", ()),
    ((*RENDER, "--max-sparse", 10**10), "--max-sparse", ()),
    ((*RENDER, "--projector-aspect", "1e12"), "--projector-aspect", ()),
    ((*RENDER, "--projector-columns", 100000), "--projector-columns", ()),
    ((*RENDER, "--max-depth", 0), "--max-depth", ()),
    ((*RENDER, "--max-depth", 100000), "--max-depth", ()),
    ((*RENDER, "--baseline", "nan"), "--baseline", ()),
    ((*RENDER, "--baseline", "1e12"), "--baseline", ()),
    ((*RENDER, "--look-from", "1e12", 0, 0, "--look-at", 0, 0, 0), "--look-from", ("float32",)),
    ((*RENDER, "--vfov", 10), "--vfov", ()),
    ((*RENDER, "--up", 0, 0, 1), "--up", ()),
    ((*RENDER, "--look-from", 1, 1, 1), "--look-at", ()),
    ((*RENDER, "--look-from", 0, 0, 0, "--look-at", 0, 0, 0), "--look-from", ()),
    ((*RENDER, "--look-from", "nan", 0, 0, "--look-at", 0, 0, 0), "--look-from", ()),
    ((*RENDER, "--look-from", 1, 1, 1, "--look-at", 0, 0, 0, "--up", 1, 1, 1), "--up", ()),
    ((*RENDER, "--look-from", 1, 1, 1, "--look-at", 0, 0, 0, "--vfov", 180), "--vfov", ()),
    (("render", "mirror_ball", "--out", "{d}/notes.txt"), None, ("already exists",)),
    (("render", "{d}/photo.png", "--out", "{d}/R.zarr"), None, ("photo.png",)),
    ((*REX, "--size", 0), "--size", ()),
    (("render-examples", "--out", "{d}/ex", "--size", 5000), "--size", ()),
    ((*REX, "--rows", 0), "--rows", ()),
    ((*REX, "--spp", 0), "--spp", ()),
    ((*REX, "--seed", -1), "--seed", ()),
    ((*REX, "--scene", "nope"), "--scene", ()),
    (("render-examples", "--out", "{d}/notes.txt"), "--out", ()),
    (("render-examples", "--out", "{d}/rex", "--scene", "mirror_ball"), None, ("mirror_ball.png", "already exists")),
    (
        ("render-examples", "--out", "{d}/rex", "--scene", "mirror_ball", "--overwrite"),
        None,
        ("mirror_ball.png", "planeray did not write"),
    ),
    (("simulate", "mitsuba:mirror_ball", "--out", "{d}/w.zarr", "--spp", 0), "--spp", ()),
    (("simulate", "mitsuba:mirror_ball", "--out", "{d}/w.zarr", "--projector-rows", 100000), "--projector-rows", ()),
]


def _id(case) -> str:
    args = [str(a) for a in case[0]]
    return " ".join(args[:2] + [a for a in args[2:] if a.startswith("-")][-2:] + args[-1:])


def _run(case, folder, inputs):
    args, option, needles = case
    words = [str(a).format(d="{d}", **{k: str(v) for k, v in inputs.items()}) for a in args]
    return run_bad(words, folder=folder, option=option, needles=needles)


@pytest.mark.parametrize("case", CASES, ids=[_id(c) for c in CASES])
def test_bad_input_is_refused_in_one_line_naming_the_option_and_loses_nothing(case, folder, inputs):
    _run(case, folder, inputs)


@pytest.mark.skipif(not HAS_MITSUBA, reason="render needs mitsuba")
@pytest.mark.parametrize("case", MITSUBA_CASES, ids=[_id(c) for c in MITSUBA_CASES])
def test_bad_render_input_is_refused_in_one_line_naming_the_option_and_loses_nothing(case, folder, inputs):
    _run(case, folder, inputs)


# ---------------------------------------------------------------------------- help and listings
def test_devices_prints_no_markup_and_options_as_dash_o_takes_them():
    res = runner.invoke(app, ["devices"])
    assert res.exit_code == 0, res.output
    assert "[bold]" not in res.output and "[/]" not in res.output
    assert "size=[128, 128]" in res.output and "noise=true" in res.output and "scene=wax" in res.output


@pytest.mark.parametrize(
    "command", [["acquire"], ["calibrate", "delay-zero"], ["calibrate", "simulate-lines"], ["render"], ["simulate"]]
)
def test_help_has_no_stray_dots_and_round_defaults(command):
    res = runner.invoke(app, [*command, "--help"], env={"COLUMNS": "250"})
    assert res.exit_code == 0, res.output
    import re

    assert not re.search(r" \.(?=\s|$)", res.output), res.output  # a default in brackets eaten as markup left " ."
    assert "16666.666" not in res.output
    text = " ".join(res.output.split())  # the help wraps at the terminal's width
    if command == ["acquire"]:
        assert "[default: (wax)]" in text and "[default: (128 128)]" in text
    if command == ["calibrate", "delay-zero"]:
        assert "16666.7 (60 Hz)" in text


def test_the_memory_a_run_needs_is_checked_before_it_allocates(monkeypatch, tmp_path):
    """A size that fits the limits but not the machine's memory is refused in one line, before any work."""
    import planeray.cli._limits as lim

    monkeypatch.setattr(lim, "available_memory", lambda: 64 * 2**20)  # a 64 MiB machine
    user_files(tmp_path)
    line = run_bad(
        ["simulate", "wax", "--out", str(tmp_path / "w.zarr"), "--size", 1024, 1024],
        folder=tmp_path,
        option="--size",
        needles=("memory",),
    )
    assert "GiB" in line
    run_bad(
        ["acquire", "--out", str(tmp_path / "a.zarr"), "--size", 1024, 1024],
        folder=tmp_path,
        option="--size",
        needles=("memory",),
    )


def test_usage_errors_of_click_name_the_option_and_write_nothing(tmp_path):
    """Integers that are not integers are refused by the parser itself (exit 2), naming the option."""
    user_files(tmp_path)
    for args, option in (
        (["acquire", "--out", str(tmp_path / "a.zarr"), "--seed", "nan"], "--seed"),
        (
            ["calibrate", "simulate-lines", "--out", str(tmp_path / "l.npz"), "--projector-rows", "1.5"],
            "--projector-rows",
        ),
        (["render", "mirror_ball", "--out", str(tmp_path / "R.zarr"), "--rows", "1e12"], "--rows"),
    ):
        res = runner.invoke(app, args)
        assert res.exit_code == 2 and option in res.output and "Traceback" not in res.output, res.output
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        ["photo.png", "labels.png", "scan.tif", "clip.tif", "notes.json", "lines.npz", "table.csv", "notes.txt"]
    )


def test_the_cases_cover_every_command_of_the_area():
    covered = {" ".join(str(a) for a in c[0][:2]) for c in CASES + MITSUBA_CASES}
    first = {c.split()[0] for c in covered}
    for command in (
        "calibrate simulate-lines",
        "calibrate lines",
        "calibrate delay-zero",
        "separate direct-global",
        "mc profile",
        "study demux",
    ):
        assert command in covered, command
    for command in ("acquire", "render", "render-examples", "simulate", "info", "contact-sheet", "profiles", "synth"):
        assert command in first, command
    for command in ("figure", "export", "import", "demux", "emulate"):
        assert command in first, command
    assert len(CASES) + len(MITSUBA_CASES) >= 120
    assert np.unique([_id(c) for c in CASES]).size > 0


def test_messages_rename_library_names_but_not_device_options_or_python_flags():
    from planeray.cli._common import _as_typed

    names = {"size": "--size", "overwrite": "--overwrite", "projector_rows": "--projector-rows"}
    assert _as_typed("projector_rows must be an integer", names) == "--projector-rows must be an integer"
    assert (
        _as_typed("-O size must be two integers H W, got (1,)", names) == "-O size must be two integers H W, got (1,)"
    )
    text = "x.png: already exists (pass --overwrite, or overwrite=True, to replace it)"
    assert _as_typed(text, names) == text

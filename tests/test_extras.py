"""The optional dependencies: the core runs without them; a command that needs one says which extra to install.

Each case runs in a subprocess where the optional module cannot be imported (``sys.modules[name] = None``
makes ``import name`` raise ``ImportError``, as on an environment without the package).
"""

from __future__ import annotations

import os
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from planeray._extras import EXTRAS

ROOT = Path(__file__).resolve().parents[1]


def _run_blocked(blocked, code: str, cwd: Path) -> subprocess.CompletedProcess:
    prelude = "import sys\n" + "".join(f"sys.modules[{m!r}] = None\n" for m in blocked)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in sys.path if p), "COLUMNS": "200"}
    return subprocess.run(
        [sys.executable, "-c", prelude + code], capture_output=True, text=True, cwd=cwd, env=env, timeout=300
    )


def _cli(*args) -> str:
    return f"from planeray.cli import main\nmain({list(args)!r})\n"


def test_extras_in_pyproject_match_the_modules_that_need_them():
    meta = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    core = " ".join(meta["dependencies"])
    for _module, (extra, dist) in EXTRAS.items():
        assert dist not in core  # not a core dependency
        assert any(req.startswith(dist) for req in meta["optional-dependencies"][extra])
        (everything,) = meta["optional-dependencies"]["all"]
        assert extra in everything.removeprefix("planeray[").removesuffix("]").split(",")


def test_video_without_imageio_ffmpeg_names_the_video_extra(tmp_path):
    out = tmp_path / "sweep.mp4"
    run = _run_blocked(
        ["imageio_ffmpeg"],
        _cli("video", "diffuse_plane", "--size", "8", "--projector-rows", "16", "--frames", "2", "--out", str(out)),
        tmp_path,
    )
    text = run.stdout + run.stderr
    assert run.returncode == 1, text
    assert "Traceback" not in text
    lines = [line for line in text.splitlines() if line.strip()]
    assert len(lines) == 1 and "pip install 'planeray[video]'" in lines[0], text
    assert not out.exists()


def test_paper_without_opencv_names_the_cv_extra_before_any_work(tmp_path):
    out = tmp_path / "paper"
    run = _run_blocked(["cv2"], _cli("paper", "--quick", "--out", str(out)), tmp_path)
    text = run.stdout + run.stderr
    assert run.returncode == 1, text
    assert "Traceback" not in text
    assert "pip install 'planeray[cv]'" in text and "planeray paper" in text, text
    assert not out.exists()


@pytest.mark.parametrize(
    ("module", "call", "extra"),
    [
        ("cv2", "from planeray.skin.enhance import bilateral; bilateral(np.ones((8, 8)))", "cv"),
        ("cv2", "from planeray.pulse.evm import pyramid_down; pyramid_down(np.ones((2, 8, 8)), 1)", "cv"),
        ("imageio_ffmpeg", "from planeray.pulse.video_io import encode_frames; "
         "encode_frames('v.mp4', iter([np.zeros((8, 8))]), n_frames=1, shape=(8, 8), fps=10.0, suffix='.mp4')", "video"),
    ],
)  # fmt: skip
def test_library_calls_without_the_extra_raise_one_line(tmp_path, module, call, extra):
    code = (
        "import numpy as np\nfrom planeray._extras import MissingExtraError\n"
        f"try:\n    {call}\nexcept MissingExtraError as e:\n    print('MISSING', e)\n"
    )
    run = _run_blocked([module], code, tmp_path)
    assert run.returncode == 0, run.stderr
    assert run.stdout.startswith("MISSING ") and f"pip install 'planeray[{extra}]'" in run.stdout, run.stdout


def test_the_demo_runs_without_either_extra(tmp_path):
    """`planeray demo` (simulate, demultiplex, figures, the skin's veins) with neither OpenCV nor imageio-ffmpeg."""
    run = _run_blocked(["cv2", "imageio_ffmpeg"], _cli("demo", "--out", str(tmp_path / "d"), "--size", "16"), tmp_path)
    assert run.returncode == 0, run.stdout + run.stderr
    assert (tmp_path / "d" / "fig8_contact_sheet.png").is_file() and (tmp_path / "d" / "skin_veins.png").is_file()

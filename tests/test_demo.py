"""``planeray demo`` (what ``make demo`` runs) writes every file the docs promise, and they read back.

The promise is the "What `make demo` writes" block of the getting-started page (docs/getting_started.md).
"""

import csv
import re
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from typer.testing import CliRunner

from planeray.cli import app
from planeray.io import read_stack, read_transport, read_transport_maps

GETTING_STARTED = Path(__file__).resolve().parents[1] / "docs" / "getting_started.md"
SIZE = 32


def _promised_files() -> list[str]:
    """The names under ``out/`` in the getting-started page's "What `make demo` writes" block."""
    text = GETTING_STARTED.read_text(encoding="utf-8")
    section = text.split("## What `make demo` writes", 1)[1].split("\n## ", 1)[0]
    block = section.split("```", 2)[1]
    return re.findall(r"^out/(\S+)", block, flags=re.MULTILINE)


@pytest.fixture(scope="module")
def demo_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo") / "out"
    res = CliRunner().invoke(app, ["demo", "--out", str(out), "--size", str(SIZE)])
    assert res.exit_code == 0, res.output
    return out


def test_the_docs_list_the_demo_outputs():
    names = _promised_files()
    assert "disco_ball.zarr" in names and "transport_vs_truth.png" in names and len(names) == 10


@pytest.mark.parametrize("name", _promised_files())
def test_every_promised_file_exists_and_reads(demo_dir, name):
    path = demo_dir / name
    assert path.exists(), f"demo did not write {name}"
    if name.endswith(".png"):
        with Image.open(path) as im:
            im.verify()
        with Image.open(path) as im:
            assert im.size[0] > 0 and im.size[1] > 0
    elif name.endswith(".csv"):
        with path.open() as fh:
            rows = [r for r in csv.reader(fh) if not r[0].startswith("#")]  # the first line: planeray's mark
        assert rows[0][:2] == ["row", "col"] and len(rows) > 1
    elif name.endswith(".zarr") and ("truth" in name or "transport" in name):
        T, attrs = read_transport(path)
        assert T.shape == (SIZE, SIZE) and T.geometry.projector_rows == 720
        assert "lines_per_second" in attrs
    elif name.endswith(".zarr"):
        st = read_stack(path)
        assert len(st) == 85 and st.shape == (SIZE, SIZE) and st.projector_rows == 720
        assert np.isfinite(np.asarray(st.images[:])).all()
    else:
        pytest.fail(f"no check for {name}")


def test_demultiplexed_transport_converged(demo_dir):
    maps = read_transport_maps(demo_dir / "mirror_ball_transport.zarr")
    assert maps["converged"].shape == (SIZE, SIZE)
    assert maps["converged"].mean() > 0.9

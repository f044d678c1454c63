"""The README is the front page (at most 250 lines); everything else it used to hold is in the docs.

Each page its table names ("| topic | page (source in `docs/`) |") exists in ``docs/``.  It is also the
package index's description (pyproject's ``readme``), where nothing relative to the repository resolves:
no picture or link into the repository.
"""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"


def test_the_readme_is_a_front_page():
    text = README.read_text(encoding="utf-8")
    assert len(text.splitlines()) <= 250
    for what in (
        "make demo",
        "make test",
        "make docs",
        "docs/_build/html/index.html",
        "import planeray as pr",
        "doi:10.1109/TVCG.2019.2946812",
    ):
        assert what in text, what


def test_the_readme_s_pages_and_picture_exist():
    text = README.read_text(encoding="utf-8")
    pages = re.findall(r"^\|[^|]+\|\s*`([\w/.-]+\.md|[\w/.-]+/)`", text, flags=re.MULTILINE)
    assert len(pages) >= 15, pages
    assert [p for p in pages if not (ROOT / "docs" / p).exists()] == []
    targets = re.findall(r"\]\(([^)]+)\)|<img[^>]+src=\"([^\"]+)", text)
    relative = [t for pair in targets for t in pair if t and not re.match(r"https?://", t)]
    assert relative == [], relative  # broken on a package index


def test_the_package_metadata_is_ready_for_an_index():
    import tomllib

    meta = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert meta["license"] == "BSD-3-Clause" and "License: BSD-3-Clause" in README.read_text(encoding="utf-8")
    licence = (ROOT / "LICENSE").read_text()
    assert "BSD 3-Clause License" in licence and "the planeray developers" in licence
    assert meta["license-files"] == ["LICENSE"]
    assert meta["authors"] == [{"name": "planeray developers"}]
    assert len(meta["keywords"]) >= 5
    assert "Programming Language :: Python :: 3.11" in meta["classifiers"]
    assert not any(c.startswith("License ::") for c in meta["classifiers"])  # PEP 639: the license expression

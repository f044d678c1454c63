"""The README is the front page (at most 250 lines); everything else it used to hold is in the docs.

Each page its table names ("| topic | page (source in `docs/`) |") exists in ``docs/``, and the
picture it shows is in the repository.
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
    pictures = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", text)
    assert pictures and all((ROOT / p).is_file() for p in pictures), pictures

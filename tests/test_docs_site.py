"""The built documentation site (``make docs``), read file by file and opened in a real browser.

Every HTML page of ``docs/_build/html`` is parsed: each internal link and image must resolve to a
file of the site (and a ``#fragment`` to an id of the page it names), nothing is loaded from the
internet (no script, stylesheet or image from another host: the site works offline), and no page
is empty.  Then Debian's chromium, driven by Playwright (never a downloaded browser), opens the
index, the API page of ``pr.demultiplex`` and a gallery page, and checks what a reader sees: the
pages render without script errors, every image is decoded, MathJax (served by the site) typesets
the equations, and no request leaves the machine.

``make docs`` builds the site and runs this file with ``PLANERAY_DOCS_SITE`` set, where a missing
site or browser fails.  Under plain ``make test`` the site is usually not built: then these tests
skip, saying so.
"""

from __future__ import annotations

import os
import re
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote, urlsplit

import pytest

from _browser import system_chromium

ROOT = Path(__file__).resolve().parents[1]
REQUIRED = bool(os.environ.get("PLANERAY_DOCS_SITE"))  # set by `make docs`
SITE = Path(os.environ.get("PLANERAY_DOCS_SITE") or ROOT / "docs" / "_build" / "html")
if not SITE.is_absolute():
    SITE = ROOT / SITE

# The pages the browser opens.
DEMULTIPLEX_PAGE = "reference/api/generated/planeray.demultiplex.html"
GALLERY_PAGE = "auto_examples/plot_08_fig8_contact_sheet.html"


def _unavailable(reason: str):
    if REQUIRED or os.environ.get("CI") and (SITE / "index.html").is_file():
        pytest.fail(reason)
    pytest.skip(reason)


@pytest.fixture(scope="module")
def site() -> Path:
    if not (SITE / "index.html").is_file():
        _unavailable(f"the documentation site is not built ({SITE / 'index.html'} is missing): run `make docs`")
    return SITE


class _Page(HTMLParser):
    """Links, resources, ids and the article's text of one HTML page."""

    def __init__(self):
        super().__init__(convert_charrefs=True)
        self.links: list[str] = []  # <a href>
        self.article_links: list[str] = []  # <a href> inside the page's article (not the navigation)
        self.resources: list[tuple[str, str]] = []  # (tag, url) the browser loads: img/script src, link href, ...
        self.ids: set[str] = set()
        self.text: list[str] = []
        self._article = 0  # depth inside <article class="bd-article">
        self._skip = 0  # inside <script>/<style>

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        for key in ("id", "name"):
            if a.get(key):
                self.ids.add(a[key])
        if tag == "a" and a.get("href"):
            self.links.append(a["href"])
            if self._article:
                self.article_links.append(a["href"])
        elif tag in ("img", "script", "source", "iframe", "video", "audio", "embed") and a.get("src"):
            self.resources.append((tag, a["src"]))
        elif tag == "link" and a.get("href") and {"stylesheet", "icon", "preload"} & set((a.get("rel") or "").split()):
            self.resources.append((tag, a["href"]))
        if tag in ("script", "style"):
            self._skip += 1
        if self._article or (tag == "article" and "bd-article" in (a.get("class") or "")):
            self._article += 1

    def handle_endtag(self, tag):
        if tag in ("script", "style"):
            self._skip = max(0, self._skip - 1)
        if self._article:
            self._article -= 1

    def handle_data(self, data):
        if self._article and not self._skip:
            self.text.append(data)


_PAGES: dict[Path, _Page] = {}


def parse(path: Path) -> _Page:
    if path not in _PAGES:
        page = _Page()
        page.feed(path.read_text(encoding="utf-8"))
        _PAGES[path] = page
    return _PAGES[path]


def html_pages(site: Path) -> list[Path]:
    # _static holds the theme's and MathJax's files; _sources the pages' sources (text)
    return sorted(
        p for p in site.rglob("*.html") if not {"_static", "_sources", "_images"} & set(p.relative_to(site).parts)
    )


def local_target(page: Path, url: str) -> tuple[Path, str] | None:
    """The file of the site a URL of ``page`` names, and its fragment; None for another host or scheme."""
    parts = urlsplit(url)
    if parts.scheme or parts.netloc or url.startswith("//"):
        return None
    path = unquote(parts.path)
    target = page if not path else (page.parent / path).resolve()
    if path.endswith("/") or target.is_dir():
        target = target / "index.html"
    return target, unquote(parts.fragment)


def test_the_site_has_every_part(site):
    """The pages the documentation promises exist: guide, reference, API, CLI, gallery."""
    expected = [
        "index.html",
        "getting_started.html",
        "concepts.html",
        "user_guide/index.html",
        "user_guide/paper.html",
        "reference/file_formats.html",
        "reference/data_promises.html",
        "reference/cli.html",
        "reference/cli_commands.html",
        "reference/api/index.html",
        DEMULTIPLEX_PAGE,
        "auto_examples/index.html",
        GALLERY_PAGE,
        "benchmarks.html",
        "changelog.html",
        "contributing.html",
    ]
    assert [p for p in expected if not (site / p).is_file()] == []
    examples = sorted((site / "auto_examples").glob("plot_*.html"))
    assert len(examples) >= 12, [p.name for p in examples]
    # the command-line page is generated from the program: every command is on it
    import typer

    from planeray.cli import app

    cli_text = " ".join(parse(site / "reference/cli_commands.html").text)
    commands = typer.main.get_command(app).commands
    assert len(commands) >= 20
    assert [name for name in commands if f"planeray {name}" not in cli_text] == []


def test_every_gallery_example_ran(site):
    """Each example of the gallery ran at build time (its running time and its pictures are on its page).

    How long they took is reported by ``make docs`` (tools/gallery_times.py), never asserted: a busy
    machine is no failure of the docs."""
    times = {}
    for page in sorted((site / "auto_examples").glob("plot_*.html")):
        text = " ".join(parse(page).text)
        m = re.search(r"Total running time of the script:\s*\(\s*(\d+) minutes\s+([\d.]+) seconds\)", text)
        assert m, f"{page.name}: no running time"
        times[page.stem] = 60 * int(m.group(1)) + float(m.group(2))
        pictures = [u for t, u in parse(page).resources if t == "img" and "sphx_glr_" + page.stem in u]
        assert pictures, f"{page.name}: no picture"
    assert len(times) >= 12


def test_the_docs_configuration_names_only_files_that_exist():
    """Every file docs/conf.py names beside itself (``HERE / "a" / "b"``) exists (a thumbnail once did not)."""
    conf = (ROOT / "docs" / "conf.py").read_text(encoding="utf-8")
    named = [re.findall(r'"([^"]+)"', m) for m in re.findall(r'HERE((?:\s*/\s*"[^"]+")+)', conf)]
    named = [parts for parts in named if parts[0] != "_build"]  # what the build itself writes
    assert named
    assert [parts for parts in named if not (ROOT / "docs").joinpath(*parts).exists()] == []


def test_no_two_files_differ_only_by_case(site):
    """On a case-insensitive file system (macOS, Windows) ``planeray.Stack.html`` and ``planeray.stack.html``
    would be one file: no two paths of the site may differ only by case."""
    by_case: dict[str, list[str]] = {}
    for path in site.rglob("*"):
        rel = path.relative_to(site).as_posix()
        if rel.startswith(".doctrees/"):  # Sphinx's cache, not served
            continue
        by_case.setdefault(rel.lower(), []).append(rel)
    assert len(by_case) > 200
    assert [v for v in by_case.values() if len(v) > 1] == []
    generated = site / "reference" / "api" / "generated"
    assert (generated / "planeray.Stack.html").is_file() and (generated / "planeray.stack-module.html").is_file()


def test_every_internal_link_and_image_resolves(site):
    """Every href and src of every page names a file of the site (and an id of it for a #fragment)."""
    pages = html_pages(site)
    assert len(pages) > 50
    broken = []
    for page in pages:
        parsed = parse(page)
        for kind, url in [("a", u) for u in parsed.links] + parsed.resources:
            target = local_target(page, url)
            if target is None:
                continue
            path, fragment = target
            where = f"{page.relative_to(site)}: <{kind}> {url}"
            if not path.is_file():
                broken.append(f"{where} (no file)")
            elif kind == "a" and fragment and path.suffix == ".html" and site in path.parents:
                if fragment not in parse(path).ids:
                    broken.append(f"{where} (no id {fragment!r})")
    assert broken == []


def test_every_guide_and_reference_page_is_two_clicks_from_the_index(site):
    """Following links in the pages' text alone (not the navigation bar), every page of the guide,
    the reference, the gallery's index and the other top-level pages is at most two clicks away."""
    depth = {site / "index.html": 0}
    frontier = [site / "index.html"]
    for d in (1, 2):
        following = []
        for page in frontier:
            for url in parse(page).article_links:
                target = local_target(page, url)
                if target and target[0].suffix == ".html" and target[0].is_file() and target[0] not in depth:
                    depth[target[0]] = d
                    following.append(target[0])
        frontier = following
    wanted = [p for p in html_pages(site) if p.parent in (site, site / "user_guide", site / "reference")]
    wanted += [site / "auto_examples/index.html", site / "reference/api/index.html"]
    skip = {"search.html", "genindex.html", "py-modindex.html"}
    assert sorted(str(p.relative_to(site)) for p in wanted if p not in depth and p.name not in skip) == []


def test_nothing_is_loaded_from_the_internet(site):
    """Scripts, stylesheets, images and fonts all come from the site itself (no CDN)."""
    remote = []
    for page in html_pages(site):
        remote += [
            f"{page.relative_to(site)}: <{tag}> {url}"
            for tag, url in parse(page).resources
            if local_target(page, url) is None
        ]
    assert remote == []
    # MathJax is configured to load from _static, and its files are there
    concepts = (site / "concepts.html").read_text(encoding="utf-8")
    assert re.search(r'src="_static/mathjax/tex-chtml\.js', concepts)
    assert (site / "_static/mathjax/output/chtml/fonts/woff-v2/MathJax_Main-Regular.woff").is_file()


def test_no_page_is_empty(site):
    """Every page's article has words (a page whose source failed to render would not)."""
    empty = []
    for page in html_pages(site):
        if page.name in ("search.html", "genindex.html", "py-modindex.html"):
            continue
        words = re.findall(r"\w+", " ".join(parse(page).text))
        if len(words) < 5:
            empty.append(f"{page.relative_to(site)} ({len(words)} words)")
    assert empty == []


@pytest.fixture(scope="module")
def browser(site):
    yield from system_chromium(_unavailable)


def open_page(browser, site: Path, name: str):
    """Open a page of the site from disk; return it with its script errors and the URLs it requested."""
    page = browser.new_page(viewport={"width": 1280, "height": 900})
    errors: list[str] = []
    requests: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.on("request", lambda r: requests.append(r.url))
    page.goto((site / name).as_uri(), wait_until="load")
    return page, errors, requests


def check_images(page) -> None:
    broken = page.evaluate(
        "Array.from(document.images).filter(i => !i.complete || i.naturalWidth === 0).map(i => i.src)"
    )
    assert broken == []


def offline(requests: list[str]) -> list[str]:
    return [u for u in requests if not u.startswith(("file://", "data:", "blob:"))]


def test_browser_index(browser, site):
    page, errors, requests = open_page(browser, site, "index.html")
    try:
        assert "planeray" in page.title()
        # the front page leads to every part in one click
        hrefs = page.eval_on_selector_all("article a", "els => els.map(e => e.getAttribute('href'))")
        for part in (
            "getting_started.html",
            "concepts.html",
            "user_guide/index.html",
            "auto_examples/index.html",
            "reference/index.html",
        ):
            assert any(h and h.split("#")[0] == part for h in hrefs), part
        # the navigation bar offers the sections
        nav = page.inner_text(".bd-header ul.navbar-nav")
        for section in ("Getting started", "Concepts", "User guide", "Gallery", "Reference"):
            assert section in nav
        check_images(page)
        assert errors == []
        assert offline(requests) == []
    finally:
        page.close()


def test_browser_demultiplex_api_page(browser, site):
    page, errors, requests = open_page(browser, site, DEMULTIPLEX_PAGE)
    try:
        title = page.inner_text("article h1")
        assert "demultiplex" in title
        sig = page.inner_text("dl.py.function > dt")
        assert "demultiplex" in sig and "alpha" in sig  # the signature, with its keyword-only options
        body = page.inner_text("article")
        assert "Parameters" in body and "Returns" in body  # the numpydoc sections
        # MathJax, served by the site, typesets any equation of the page (and loads nothing else)
        page.goto((site / "concepts.html").as_uri(), wait_until="load")
        page.wait_for_function("document.querySelectorAll('mjx-container').length > 0", timeout=20000)
        check_images(page)
        assert errors == []
        assert offline(requests) == []
    finally:
        page.close()


def test_browser_gallery_page(browser, site):
    page, errors, requests = open_page(browser, site, GALLERY_PAGE)
    try:
        # the picture, decoded, beside the code that made it, with the script to download
        assert (
            page.eval_on_selector_all(
                "article img.sphx-glr-single-img, article img.sphx-glr-multi-img", "els => els.length"
            )
            >= 1
        )
        check_images(page)
        code = page.inner_text("article div.highlight-Python")
        assert "import planeray" in code
        downloads = page.eval_on_selector_all("a.download", "els => els.map(e => e.getAttribute('href'))")
        assert any(h.endswith(".py") for h in downloads)
        # the gallery's index shows this example's thumbnail, linked to it
        page.goto((site / "auto_examples/index.html").as_uri(), wait_until="load")
        thumbs = page.eval_on_selector_all(".sphx-glr-thumbcontainer a", "els => els.map(e => e.getAttribute('href'))")
        assert any(Path(GALLERY_PAGE).name in (h or "") for h in thumbs)
        check_images(page)
        assert errors == []
        assert offline(requests) == []
    finally:
        page.close()


# ---------------------------------------------------------------------------------------------------
# A newcomer's pages: a task fits one screen before its first command, no "issue N", every name an Example

#: The user guide's task pages: each fits about one screen of prose before its first command or picture.
TASK_PAGES = (
    "simulate",
    "import",
    "demultiplex",
    "sweep_design",
    "synthesis",
    "profiles",
    "materials",
    "materials_fit",
    "subsurface",
    "skin",
    "skin_depth",
    "pulse",
    "mitsuba",
    "explorer",
    "camera",
    "rig",
    "paper",
)
#: The pages that explain how a task works or how well it works (linked from the task pages): no limit.
EXPLANATION_PAGES = (
    "index",
    "demultiplex_how",
    "demux_weights",
    "materials_how",
    "materials_library",
    "trust",
    "skin_scene",
    "skin_veins",
    "pulse_how",
    "camera_how",
)
#: About one screen of prose.
SCREEN_WORDS = 400

# The words of the article before its first code block or picture, as the browser lays the page out
# (the navigation, the sidebar and the page's title bar are not the article).
_WORDS_BEFORE_FIRST_COMMAND = """() => {
  const article = document.querySelector('article.bd-article');
  const walker = document.createTreeWalker(article, NodeFilter.SHOW_ELEMENT | NodeFilter.SHOW_TEXT);
  let words = 0;
  for (let node = walker.nextNode(); node; node = walker.nextNode()) {
    if (node.nodeType === Node.ELEMENT_NODE) {
      if (node.matches('pre, img, figure, svg')) return [words, node.tagName.toLowerCase()];
      if (node.matches('script, style, .headerlink')) { walker.currentNode = node.lastChild || node; }
      continue;
    }
    const inSkipped = node.parentElement && node.parentElement.closest('script, style, .headerlink');
    if (!inSkipped) words += (node.textContent.match(/\\S+/g) || []).length;
  }
  return [words, null];
}"""


def test_every_user_guide_page_is_a_task_or_explains_one(site):
    """A new page of the user guide is classified: a task page (one screen before its command) or an explanation."""
    pages = sorted(p.stem for p in (site / "user_guide").glob("*.html"))
    assert sorted(set(pages) - set(TASK_PAGES) - set(EXPLANATION_PAGES)) == []
    assert sorted((set(TASK_PAGES) | set(EXPLANATION_PAGES)) - set(pages)) == []


def test_browser_task_pages_fit_one_screen_before_their_first_command(browser, site):
    """In chromium: each task page shows its first command or picture after at most ~400 words of prose."""
    page = browser.new_page(viewport={"width": 1280, "height": 900})
    too_long, without = {}, []
    try:
        for name in TASK_PAGES:
            page.goto((site / "user_guide" / f"{name}.html").as_uri(), wait_until="load")
            words, first = page.evaluate(_WORDS_BEFORE_FIRST_COMMAND)
            if first is None:
                without.append(name)
            elif words > SCREEN_WORDS:
                too_long[name] = words
    finally:
        page.close()
    assert without == []
    assert too_long == {}


def test_task_pages_have_a_picture(site):
    """Each task page shows a picture of what the task makes (a figure from the gallery or the docs)."""
    bare = [
        name
        for name in TASK_PAGES
        if not [u for t, u in parse(site / "user_guide" / f"{name}.html").resources if t == "img"]
    ]
    assert bare == []


_ISSUE = re.compile(r"\bissues?[\s#-]*\d+", re.IGNORECASE)


def test_no_page_a_user_reads_names_an_issue_number(site):
    """No page says "issue 27": a reader has no issue tracker; the page says what the thing is.
    (The changelog may name what changed, and does without numbers too.)"""
    found = []
    for page in html_pages(site):
        if page.name in ("search.html", "genindex.html", "py-modindex.html", "changelog.html"):
            continue
        text = " ".join(parse(page).text)
        found += [
            f"{page.relative_to(site)}: ...{text[max(0, m.start() - 40) : m.end() + 20]}..."
            for m in _ISSUE.finditer(text)
        ]
    assert found == []


def _public_names():
    """The public functions and classes (of ``pr.`` and of each module's ``__all__``), from tools/missing_examples.py."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("missing_examples", ROOT / "tools" / "missing_examples.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_every_public_name_has_an_example():
    """Every public function and class has a numpydoc Examples section with a doctest (run by --doctest-modules)."""
    tool = _public_names()
    assert len(tool.public_names()) > 250
    assert tool.missing() == []


def test_browser_front_door_api_pages_show_their_example(browser, site):
    """In chromium: the API page of every name of ``import planeray as pr`` shows an Examples section with code."""
    import inspect

    import planeray

    names = [
        n for n in planeray.__all__ if inspect.isfunction(getattr(planeray, n)) or inspect.isclass(getattr(planeray, n))
    ]
    assert len(names) > 30
    page = browser.new_page(viewport={"width": 1280, "height": 900})
    lacking = []
    try:
        for name in names:
            page.goto((site / "reference/api/generated" / f"planeray.{name}.html").as_uri(), wait_until="load")
            shown = page.evaluate(
                """() => Array.from(document.querySelectorAll('article p.rubric'))
                       .some(r => r.textContent.trim() === 'Examples'
                                  && Array.from(document.querySelectorAll('article pre'))
                                       .some(p => p.textContent.includes('>>>')))"""
            )
            if not shown:
                lacking.append(name)
    finally:
        page.close()
    assert lacking == []


def test_browser_code_blocks_are_not_clipped(browser, site):
    """In chromium at a laptop's 1280 x 900: no code block of a task page, the getting-started page or the
    command overview runs off the article's right edge (long lines wrap; a reader saw every comment cut off)."""
    names = ["getting_started", "reference/cli"] + [f"user_guide/{n}" for n in TASK_PAGES]
    page = browser.new_page(viewport={"width": 1280, "height": 900})
    clipped = {}
    try:
        for name in names:
            page.goto((site / f"{name}.html").as_uri(), wait_until="load")
            n = page.evaluate(
                "() => Array.from(document.querySelectorAll('article pre'))"
                ".filter(p => p.scrollWidth > p.clientWidth + 1).length"
            )
            if n:
                clipped[name] = n
    finally:
        page.close()
    assert clipped == {}


def test_every_public_name_has_parameters_returns_and_see_also():
    """Every public function and class documents its Parameters (a class may give Attributes), a function its
    Returns, and each points to its neighbours (See Also): the API reference reads as numpydoc throughout."""
    assert _public_names().missing_sections() == {}

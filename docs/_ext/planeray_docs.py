"""Sphinx helpers of planeray's documentation (loaded by ``docs/conf.py``).

* :func:`figure_scraper`: sphinx-gallery collects the figures pyplot knows; planeray's figure
  functions build :class:`matplotlib.figure.Figure` objects without pyplot (so importing
  :mod:`planeray.figures` leaves the backend alone), so this scraper also collects every such
  Figure an example block leaves in a variable.
* :func:`copy_mathjax`: copies the MathJax that ``make docs`` installed from the npm registry
  into the built site (``_static/mathjax``), so no page loads a script from the internet.
* :func:`write_cli_page`: the page of every command and option, generated from the command line
  itself at every build.
* :func:`strip_summary_citations`: autosummary copies a docstring's first sentence into its
  tables, where a citation mark (``[1]_``) has no References section to point to.
"""

from __future__ import annotations

import re
import shutil
from pathlib import Path

_SEEN: dict[str, list] = {}

# What of MathJax's es5 build the site needs: the TeX-to-CommonHTML component, its fonts, and
# what it may load on demand (TeX extensions, the menu, the assistive MathML).
_MATHJAX_PARTS = ("tex-chtml.js", "input", "output/chtml", "ui", "a11y", "adaptors")


def reset_figures(gallery_conf, fname):
    """Forget the figures scraped from the previous example (a sphinx-gallery reset hook)."""
    _SEEN.clear()


def figure_scraper(block, block_vars, gallery_conf):
    """Save every new pyplot-free :class:`~matplotlib.figure.Figure` of an example's variables.

    Figures that pyplot manages are left to sphinx-gallery's own matplotlib scraper.
    """
    from matplotlib.figure import Figure
    from sphinx_gallery.scrapers import figure_rst

    seen = _SEEN.setdefault(str(block_vars.get("src_file", "")), [])
    paths = []
    for value in list(block_vars["example_globals"].values()):
        if not isinstance(value, Figure) or any(value is s for s in seen):
            continue
        seen.append(value)  # pyplot's too: once the matplotlib scraper closed it, it looks pyplot-free
        if getattr(value.canvas, "manager", None) is not None:
            continue
        path = next(block_vars["image_path_iterator"])
        value.savefig(path, dpi=100, bbox_inches="tight")
        paths.append(path)
    return figure_rst(paths, gallery_conf["src_dir"])


def copy_mathjax(app, exception):
    """Copy the locally installed MathJax into ``_static/mathjax`` of the built site."""
    if exception is not None or app.builder.format != "html":
        return
    source = Path(app.config.planeray_mathjax_source) / "es5"
    if not (source / "tex-chtml.js").is_file():
        raise RuntimeError(
            f"MathJax is not installed at {source}: run `make docs` (it installs it with "
            "`npm install --prefix docs/_build/mathjax mathjax@3`) or set PLANERAY_MATHJAX to a mathjax@3 package folder"
        )
    target = Path(app.outdir) / "_static" / "mathjax"
    for part in _MATHJAX_PARTS:
        src, dst = source / part, target / part
        if src.is_dir():
            shutil.copytree(src, dst, dirs_exist_ok=True)
        elif src.is_file():
            dst.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, dst)


# The groups of the front door, in the order of ``planeray/__init__.pyi`` (read into ``planeray._EXPORTS``).
_GROUPS = {
    "timing": "The imaging model (Eqs. 1-3)",
    "transport": "Light transport (Eqs. 4-6)",
    "stack": "Captures",
    "camera": "Captures",
    "scenes": "Captures",
    "scenes.skin": "Captures",
    "devices": "Captures",
    "acquire": "Captures",
    "calibration": "Calibration (Sec. 6)",
    "io": "Files",
    "demux": "Demultiplexing (Sec. 4)",
    "synthesis": "Analysis (Secs. 4, 7, 8, 9)",
    "profiles": "Analysis (Secs. 4, 7, 8, 9)",
    "classify": "Analysis (Secs. 4, 7, 8, 9)",
    "medium": "Subsurface scattering (Sec. 5.2)",
    "mc": "Subsurface scattering (Sec. 5.2)",
    "kernels": "Subsurface scattering (Sec. 5.2)",
    "render": "Any Mitsuba 3 scene",
}


def public_modules():
    """planeray's public top-level modules and packages (no leading underscore; the CLI has its own page)."""
    import pkgutil

    import planeray

    return sorted(
        m.name for m in pkgutil.iter_modules(planeray.__path__) if not m.name.startswith("_") and m.name != "cli"
    )


def case_distinct_pages() -> dict[str, str]:
    """``autosummary_filename_map``: a page name for each module whose name differs only by case from a name
    documented beside it (``planeray.stack`` the module, ``planeray.Stack`` the class of the front door).

    On a case-insensitive file system (macOS, Windows) ``planeray.stack.html`` and ``planeray.Stack.html``
    are one file; the module's page becomes ``planeray.stack-module.html`` (links follow, by name).
    """
    import importlib
    import pkgutil

    import planeray

    modules = ["planeray"] + [
        m.name
        for m in pkgutil.walk_packages(planeray.__path__, "planeray.", onerror=lambda name: None)
        if not any(part.startswith("_") for part in m.name.split(".")[1:]) and not m.name.startswith("planeray.cli")
    ]
    names = {f"planeray.{n}" for n in planeray._EXPORTS} | set(modules)
    for name in modules:
        try:
            module = importlib.import_module(name)
        except Exception:  # an optional dependency missing: autosummary reports it itself
            continue
        names |= {f"{name}.{member}" for member in getattr(module, "__all__", ())}
    by_case: dict[str, set[str]] = {}
    for name in names:
        by_case.setdefault(name.lower(), set()).add(name)
    return {m: f"{m}-module" for m in modules if len(by_case[m.lower()]) > 1}


def write_api_index(app, config=None):
    """Write ``reference/api/index.rst`` from ``planeray._EXPORTS`` and the package's modules.

    Generated at every build, so a name added to the front door or a module added to the
    package gets its page without anyone editing the docs.
    """
    import planeray

    app.config.autosummary_filename_map = {**app.config.autosummary_filename_map, **case_distinct_pages()}
    groups: dict[str, list[str]] = {}
    for name, module in planeray._EXPORTS.items():
        groups.setdefault(_GROUPS.get(module, "Other"), []).append(name)
    lines = [
        ".. This file is written by docs/_ext/planeray_docs.py at every build: do not edit.",
        "",
        "Python API",
        "==========",
        "",
        "Generated from the numpydoc docstrings. The front door, ``import planeray as pr``, holds the",
        "names a notebook needs (``planeray/__init__.pyi``: each name and the module that defines",
        "it); every module of the package follows, with a page per function and class.",
        "",
        ".. currentmodule:: planeray",
        "",
        "The front door: ``import planeray as pr``",
        "-----------------------------------------",
        "",
    ]
    for title, names in groups.items():
        lines += [title, "~" * len(title), "", ".. autosummary::", "   :toctree: generated/", "   :nosignatures:", ""]
        lines += [f"   {n}" for n in names] + [""]
    lines += [
        "Subpackages: ``pr.materials``, ``pr.skin``, ...",
        "~~~~~~~~~~~~~~~~~~~~~~~~~~~~~~~~~~~~~~~~~~~~~~~~",
        "",
        "Every public module and subpackage is an attribute of the front door too, loaded when first used",
        "(``planeray/__init__.pyi`` is the one list: lazy loading, ``__all__`` and type checkers):",
        "",
        ", ".join(f":mod:`pr.{m} <planeray.{m}>`" for m in planeray._SUBMODULES if m != "cli") + ".",
        "",
    ]
    lines += [
        "Modules",
        "-------",
        "",
        "One module (or subpackage) per pipeline stage; dependencies point down this list (see :doc:`/contributing`).",
        "",
        ".. autosummary::",
        "   :toctree: generated/",
        "   :recursive:",
        "",
    ]
    lines += [f"   {m}" for m in public_modules()]  # relative to the current module, planeray + [""]
    path = Path(app.srcdir) / "reference" / "api" / "index.rst"
    path.parent.mkdir(parents=True, exist_ok=True)
    text = "\n".join(lines)
    if not path.is_file() or path.read_text() != text:
        path.write_text(text)


def check_mathjax(app):
    """Fail at once, not after the whole build, when the local MathJax is missing."""
    if not (Path(app.config.planeray_mathjax_source) / "es5" / "tex-chtml.js").is_file():
        raise RuntimeError(
            f"MathJax is not installed at {app.config.planeray_mathjax_source}: run `make docs` (it installs it with "
            "`npm install --prefix docs/_build/mathjax mathjax@3`) or set PLANERAY_MATHJAX to a mathjax@3 package folder"
        )


_CITATION = re.compile(r"\s*\[([A-Za-z0-9_-]+)\]_")
_CITATION_TARGET = re.compile(r"^\s*\.\. \[([A-Za-z0-9_-]+)\]")


def strip_summary_citations(app, what, name, obj, options, lines):
    """Fix the citation marks (``[1]_``) docutils cannot resolve (an autodoc-process-docstring hook).

    Runs after numpydoc (which renames the marks of a docstring's own References section to
    ``[R...-1]_``).  The marks of the first paragraph are dropped: autosummary copies it into
    its tables, where no References section follows.  A mark whose reference is in another
    docstring (a function citing its module's References) is kept as plain text, ``[1]``.
    """
    targets = {m.group(1) for line in lines if (m := _CITATION_TARGET.match(line))}
    first = next((i for i, line in enumerate(lines) if line.strip()), len(lines))
    in_first = True
    for i in range(first, len(lines)):
        if not lines[i].strip():
            in_first = False
        if in_first:
            lines[i] = _CITATION.sub("", lines[i])
        else:
            lines[i] = _CITATION.sub(lambda m: m.group(0) if m.group(1) in targets else m.group(0)[:-1], lines[i])


def front_door_constant_docs(app, what, name, obj, options, lines):
    """The ``#:`` comment of a constant of the front door (an autodoc-process-docstring hook).

    ``planeray.PAPER_PROJECTOR_ROWS`` is loaded lazily from ``planeray.timing``, so autodoc,
    reading ``planeray/__init__.py``, finds no comment there and shows ``int``'s docstring instead.
    """
    if what not in ("data", "attribute") or not isinstance(obj, (int, float, str, tuple)):
        return
    from sphinx.pycode import ModuleAnalyzer

    import planeray

    module, _, short = name.rpartition(".")
    if module == "planeray" and short in planeray._EXPORTS:
        module = f"planeray.{planeray._EXPORTS[short]}"
    try:
        doc = ModuleAnalyzer.for_module(module).find_attr_docs().get(("", short))
    except Exception:  # a module without source: keep what autodoc found
        return
    if doc:
        lines[:] = [line.rstrip("\n") for line in doc]


def click_app():
    """The command line as a click-style command tree (typer builds it from ``planeray.cli.app``)."""
    import typer

    from planeray.cli import app

    return typer.main.get_command(app)


_RST_SPECIAL = re.compile(r"([\\`*|_\[\]<>])")


def _rst_text(text: str) -> str:
    """Help text as reStructuredText that shows it as it is (its markup characters escaped)."""
    return _RST_SPECIAL.sub(r"\\\1", " ".join((text or "").split()))


def _command_rst(command, ctx, path: list[str], level: int) -> list[str]:
    from typer import _click as click  # typer's own click, whose objects get_command returns

    title = " ".join(path)
    underline = "-~^"[min(level, 2)]
    lines = [f".. _cli-{'-'.join(path[1:]) or 'planeray'}:", "", f"``{title}``", underline * (len(title) + 4), ""]
    if command.help:
        lines += [_rst_text(command.help), ""]
    lines += [".. code-block:: text", "", "   " + command.get_usage(ctx).strip().replace("\n", "\n   "), ""]
    records = [p.get_help_record(ctx) for p in command.params if not getattr(p, "hidden", False)]
    for record in records:
        if record:
            lines += [f"``{record[0]}``", f"   {_rst_text(record[1]) or '(no description)'}", ""]
    for name, sub in (
        sorted(getattr(command, "commands", {}).items()) if level else getattr(command, "commands", {}).items()
    ):
        if getattr(sub, "hidden", False):
            continue
        lines += _command_rst(sub, click.Context(sub, info_name=name, parent=ctx), [*path, name], level + 1)
    return lines


def write_cli_page(app, config=None):
    """Write ``reference/cli_commands.rst``: every command and option, from the program itself.

    Read from the click-style tree typer builds (``--help`` shows the same records), at every
    build, so the page cannot drift from what the commands accept.  (sphinx-click cannot read
    it: typer >= 0.16 ships its own click, whose classes are not click's.)
    """
    from typer import _click as click

    root = click_app()
    ctx = click.Context(root, info_name="planeray")
    lines = [
        ".. This file is written by docs/_ext/planeray_docs.py at every build: do not edit.",
        "",
        "Every command and option",
        "========================",
        "",
        "Generated from the program itself (what ``planeray COMMAND --help`` prints), so it cannot drift",
        "from what the commands accept. See :doc:`cli` for the conventions all commands share.",
        "",
    ]
    lines += _command_rst(root, ctx, ["planeray"], 0)[5:]  # the page's own title stands for the root
    path = Path(app.srcdir) / "reference" / "cli_commands.rst"
    text = "\n".join(lines) + "\n"
    if not path.is_file() or path.read_text() != text:
        path.write_text(text)


def setup(app):
    # autosummary's tables show a docstring's first sentence, cut at ". " unless an abbreviation
    # ends it: the paper's references ("Sec. 4", "Eqs. 5, 6") are not sentence ends.
    from sphinx.ext import autosummary

    autosummary.WELL_KNOWN_ABBREVIATIONS = (
        *autosummary.WELL_KNOWN_ABBREVIATIONS,
        *(
            f"{sep}{a}."
            for a in ("Sec", "Secs", "Eq", "Eqs", "Fig", "Figs", "al", "cf", "approx", "vs")
            for sep in " ("
        ),
    )
    app.add_config_value("planeray_mathjax_source", "", "html")
    app.connect("config-inited", write_api_index)
    app.connect("config-inited", write_cli_page)
    app.connect("builder-inited", check_mathjax, priority=100)
    app.connect("build-finished", copy_mathjax)
    app.connect("autodoc-process-docstring", strip_summary_citations, priority=900)
    app.connect("autodoc-process-docstring", front_door_constant_docs, priority=400)
    return {"parallel_read_safe": True, "parallel_write_safe": True}

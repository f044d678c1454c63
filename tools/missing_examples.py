"""List the public names of planeray whose docstring lacks an Examples section.

The public names are those of ``planeray.__all__`` (the front door, ``import planeray as pr``) and of
the ``__all__`` of each public top-level module and subpackage (``planeray.demux``, ``planeray.skin``,
...: the modules of the API reference).  Only functions and classes are listed: a constant
(``PAPER_LINES_PER_SECOND``, ``__version__``) or a module has no docstring of its own to hold one.

Usage::

    python tools/missing_examples.py             # one line per name lacking an Example, then the count
    python tools/missing_examples.py --count     # the counts only
    python tools/missing_examples.py --sections  # also the names lacking Parameters, Returns or See Also

Exits 1 when a name lacks an Example (so CI or a test can use it), 0 otherwise.
"""

from __future__ import annotations

import argparse
import importlib
import inspect
import pkgutil
import re
import sys

_EXAMPLES = re.compile(r"^\s*Examples\s*\n\s*-{8,}\s*\n", re.MULTILINE)


def public_names() -> dict[str, object]:
    """Every public function and class, by the dotted name a user imports it under (first seen wins)."""
    import planeray

    found: dict[str, object] = {}
    seen: set[int] = set()
    modules = [("planeray", planeray)]
    for info in sorted(pkgutil.iter_modules(planeray.__path__), key=lambda m: m.name):
        if info.name.startswith("_"):
            continue
        modules.append((f"planeray.{info.name}", importlib.import_module(f"planeray.{info.name}")))
    for prefix, module in modules:
        for name in getattr(module, "__all__", ()):
            obj = getattr(module, name, None)
            if not (inspect.isfunction(obj) or inspect.isclass(obj)):
                continue  # constants, modules
            if id(obj) in seen:
                continue
            seen.add(id(obj))
            found[f"{prefix}.{name}"] = obj
    return found


def has_example(obj) -> bool:
    """Whether the object's own docstring has a numpydoc Examples section with a ``>>>`` line."""
    doc = inspect.getdoc(obj) or ""
    m = _EXAMPLES.search(doc)
    return bool(m) and ">>>" in doc[m.end() :]


def _headers(obj) -> set[str]:
    return set(re.findall(r"^(\w[\w ]*)\n-{3,}$", inspect.getdoc(obj) or "", re.MULTILINE))


def missing_sections() -> dict[str, list[str]]:
    """Per dotted name, the numpydoc sections it lacks of Parameters (a callable with parameters; a class
    may give Attributes instead), Returns (functions) and See Also."""
    out = {}
    for name, obj in public_names().items():
        heads = _headers(obj)
        try:
            params = [
                p.name
                for p in inspect.signature(obj).parameters.values()
                if not p.name.startswith("_") and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)
            ]
        except (TypeError, ValueError):
            params = []
        lacking = []
        if params and not heads & {"Parameters", "Attributes" if inspect.isclass(obj) else "Parameters"}:
            lacking.append("Parameters")
        if inspect.isfunction(obj) and not heads & {"Returns", "Yields"}:
            lacking.append("Returns")
        if "See Also" not in heads:
            lacking.append("See Also")
        if lacking:
            out[name] = lacking
    return out


def missing() -> list[str]:
    """The dotted names of the public functions and classes without an Example."""
    return [name for name, obj in public_names().items() if not has_example(obj)]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", action="store_true", help="print the counts only")
    parser.add_argument("--sections", action="store_true", help="also list the names lacking other sections")
    args = parser.parse_args(argv)
    names = public_names()
    lacking = missing()
    if not args.count:
        for name in lacking:
            print(name)
    print(f"{len(lacking)} of {len(names)} public functions and classes lack an Example", file=sys.stderr)
    if args.sections:
        sections = missing_sections()
        if not args.count:
            for name, which in sections.items():
                print(f"{name}: no {', '.join(which)}")
        for section in ("Parameters", "Returns", "See Also"):
            n = sum(section in which for which in sections.values())
            print(f"{n} lack {section}", file=sys.stderr)
    return 1 if lacking else 0


if __name__ == "__main__":
    sys.exit(main())

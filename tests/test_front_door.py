"""The front door, ``import planeray as pr``: one list (``planeray/__init__.pyi``) serves lazy loading,
``__all__``, ``dir()`` and type checkers, and every public module and subpackage is one attribute away."""

from __future__ import annotations

import importlib
import json
import pkgutil
import re
import subprocess
import sys
from pathlib import Path

import planeray

STUB = Path(planeray.__file__).with_name("__init__.pyi")
#: What ``import planeray`` alone must not load (it loads none of these today: the front door is lazy).
HEAVY = ("numpy", "scipy", "zarr", "dask", "numba", "sklearn", "matplotlib", "rich", "typer", "tifffile")


def _stub_names() -> tuple[list[str], list[str]]:
    """``(names, subpackages)`` of the stub, read line by line (not with the package's own reader)."""
    text = STUB.read_text()
    subs = re.findall(r"^from \. import (\w+) as \1$", text, flags=re.M)
    names = re.findall(r"^from \.[\w.]+ import (\w+) as \1$", text, flags=re.M)
    return ["__version__", *names], subs


def _run(code: str) -> str:
    src = str(Path(planeray.__file__).parents[1])
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120, env={"PYTHONPATH": src}
    )
    assert done.returncode == 0, done.stderr
    return done.stdout


def test_all_and_dir_are_the_stubs_list():
    names, subs = _stub_names()
    assert len(names) > 40 and len(subs) > 30
    assert planeray.__all__ == names + subs
    assert set(names + subs) <= set(dir(planeray))


def test_every_public_module_and_subpackage_is_in_the_stub():
    public = {m.name for m in pkgutil.iter_modules(planeray.__path__) if not m.name.startswith("_")}
    assert public == set(_stub_names()[1])


def test_import_planeray_alone_loads_nothing_heavy():
    code = f"import json, sys; import planeray; print(json.dumps([m for m in {HEAVY!r} if m in sys.modules]))"
    assert json.loads(_run(code)) == []


def test_every_name_and_subpackage_resolves_lazily_to_its_definition():
    names, subs = _stub_names()
    for name in subs:
        assert getattr(planeray, name) is importlib.import_module(f"planeray.{name}"), name
    for name in names[1:]:
        assert getattr(planeray, name) is getattr(importlib.import_module(f"planeray.{planeray._EXPORTS[name]}"), name)
    for name in ("materials", "skin", "pulse", "viewer", "experiments", "baselines", "render", "design"):
        assert name in subs


def test_an_unknown_name_is_an_attribute_error():
    import pytest

    with pytest.raises(AttributeError, match="no attribute 'not_a_name'"):
        planeray.not_a_name  # noqa: B018

"""The command line for a newcomer: ``--version``, ``python -m planeray`` and every help page at 80 columns."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from importlib import metadata

import pytest
import typer
from typer.testing import CliRunner

from planeray.cli import app
from planeray.cli._common import _square_size_args

runner = CliRunner()


def _commands(command, path=()):
    yield path, command
    if hasattr(command, "commands"):  # a group (typer's own click, or click's)
        for name, sub in command.commands.items():
            yield from _commands(sub, (*path, name))


ALL = list(_commands(typer.main.get_command(app)))


def test_every_help_page_at_80_columns_shows_whole_option_names_and_no_bool_metavar():
    assert len(ALL) > 50  # every command and group, from the program itself
    for path, command in ALL:
        res = runner.invoke(app, [*path, "--help"], env={"COLUMNS": "80", "TERMINAL_WIDTH": "80"})
        where = " ".join(("planeray", *path))
        assert res.exit_code == 0, (where, res.output)
        text = res.output
        assert "…" not in text, (where, text)
        assert "<bool>" not in text, (where, text)
        assert max(len(line) for line in text.splitlines()) <= 80, (where, text)
        words = set(re.findall(r"(?<![\w-])--?[\w][\w-]*", text))
        for param in command.params:
            if param.param_type_name == "option" and not param.hidden:
                for name in (*param.opts, *param.secondary_opts):
                    assert name in words, (where, name, text)
        if hasattr(command, "commands"):
            for name, sub in command.commands.items():
                if not sub.hidden:
                    assert re.search(rf"^  {re.escape(name)}\b", text, re.M), (where, name, text)


def test_command_list_gives_whole_first_sentences():
    res = runner.invoke(app, ["--help"], env={"COLUMNS": "80"})
    assert res.exit_code == 0
    # click's own short help stopped at the first word ending in a dot ("Reproduce Figs.", "Calibration (Sec.")
    assert not re.search(r"(Figs|Sec|al)\.\s*$", res.output, re.M), res.output
    assert "Calibration (Sec. 6)" in res.output


def test_version_long_and_short():
    version = metadata.version("planeray")
    for flag in ("--version", "-V"):
        res = runner.invoke(app, [flag])
        assert res.exit_code == 0, res.output
        assert res.output.strip() == f"planeray {version}"


def test_python_dash_m_planeray_is_the_command():
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in sys.path if p)}
    run = subprocess.run(
        [sys.executable, "-m", "planeray", "--version"], capture_output=True, text=True, env=env, timeout=120
    )
    assert run.returncode == 0, run.stderr
    assert run.stdout.startswith("planeray ")


@pytest.mark.parametrize(
    ("argv", "expected"),
    [
        (["view", "wax", "--size", "32"], ["view", "wax", "--size", "32", "32"]),
        (["view", "wax", "--size", "32", "48", "--seed", "1"], ["view", "wax", "--size", "32", "48", "--seed", "1"]),
        (["video", "wax", "--size", "16", "--out", "a.mp4"], ["video", "wax", "--size", "16", "16", "--out", "a.mp4"]),
        (["simulate", "wax", "--size", "32", "32"], ["simulate", "wax", "--size", "32", "32"]),
        (["--debug", "view", "wax", "--size", "8"], ["--debug", "view", "wax", "--size", "8", "8"]),
    ],
)
def test_view_size_takes_h_w_or_one_number(argv, expected):
    assert _square_size_args(argv) == expected


def test_view_size_is_h_w_in_its_help():
    res = runner.invoke(app, ["view", "--help"], env={"COLUMNS": "80"})
    assert "--size <int,int>..." in res.output or "--size INTEGER..." in res.output, res.output

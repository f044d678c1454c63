"""Long commands show progress, print what a script can read back, and give the same numbers every run."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

import planeray.cli.analysis
import planeray.cli.mc
import planeray.cli.study
from planeray.cli import app
from planeray.experiments.paper import FIGURES, fig12, figure_work
from planeray.experiments.study import study_work

SRC = Path(__file__).resolve().parents[1] / "src"
runner = CliRunner()


class RecordingBar:
    """Stands in for ``progress_bar()``: records every task's total and how far it got."""

    def __init__(self, log):
        self.tasks = []
        log.append(self)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def add_task(self, description, total):
        self.tasks.append({"description": description, "total": total, "completed": 0})
        return len(self.tasks) - 1

    def advance(self, task, n=1):
        self.tasks[task]["completed"] += n


@pytest.fixture
def bars(monkeypatch):
    log = []
    for module in (planeray.cli.analysis, planeray.cli.mc, planeray.cli.study):
        monkeypatch.setattr(module, "progress_bar", lambda: RecordingBar(log))
    return log


def _finished(bars):
    tasks = [t for bar in bars for t in bar.tasks]
    assert tasks and all(t["completed"] == t["total"] for t in tasks), tasks
    return tasks


def _numbers(result: dict) -> str:
    """A figure's numbers without the paths of its PNGs, as the bytes they are written with."""
    drop = {"png"}
    return json.dumps({k: v for k, v in result.items() if k not in drop}, sort_keys=True)


def test_figure_work_names_every_figure():
    assert set(FIGURES) == {"fig8", "fig9", "fig11", "fig12", "effects"}
    assert figure_work("fig12", size=32) == 5 * (85 + 32 + 4) + 1  # 5 camera-noise seeds, the figure
    with pytest.raises(ValueError, match="unknown figure"):
        figure_work("fig13")


@pytest.mark.usefixtures("figures_not_drawn")  # the runs in this process; the fresh process draws its figure
def test_fig12_prints_one_json_line_and_is_the_same_bytes_in_every_run_and_process(tmp_path, bars):
    # Twice in this process (no state carried from one run to the next) ...
    res = runner.invoke(app, ["figure", "fig12", "--out", str(tmp_path / "a"), "--size", "24", "--seed", "1"])
    assert res.exit_code == 0, res.output
    (task,) = _finished(bars)
    assert task["total"] == figure_work("fig12", size=24)
    (line,) = res.stdout.splitlines()
    printed = json.loads(line)
    assert printed["figure"] == "fig12" and printed["json"] == str(tmp_path / "a" / "fig12.json")
    saved = json.loads((tmp_path / "a" / "fig12.json").read_text())
    assert saved.pop("planeray_mark").startswith("planeray:record:") and printed["numbers"] == saved
    again = fig12(tmp_path / "b", size=24, seed=1)
    assert _numbers(again) == _numbers(printed["numbers"])
    # ... and in a fresh process (its own hash seed, thread pools, caches), at a narrow terminal.
    env = {**os.environ, "COLUMNS": "40", "PYTHONHASHSEED": "123"}
    env["PYTHONPATH"] = os.pathsep.join([str(SRC), *filter(None, [env.get("PYTHONPATH")])])
    out_dir = tmp_path / "a folder with a long name, [brackets] and spaces"
    cmd = [
        sys.executable,
        "-m",
        "planeray.cli",
        "figure",
        "fig12",
        "--out",
        str(out_dir),
        "--size",
        "24",
        "--seed",
        "1",
    ]
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    (line,) = proc.stdout.splitlines()
    other = json.loads(line)
    assert other["json"] == str(out_dir / "fig12.json")
    assert _numbers(other["numbers"]) == _numbers(printed["numbers"])
    assert "fig12" in proc.stderr  # the progress bar


def test_figure_rejects_an_unknown_name_before_running_anything(tmp_path, bars):
    res = runner.invoke(app, ["figure", "fig13", "--out", str(tmp_path)])
    assert res.exit_code == 1 and "unknown figure 'fig13'" in res.output
    assert not bars and not tmp_path.joinpath("fig13.json").exists()


def test_effects_figure_refuses_a_size_it_is_not_validated_at_before_running_anything(tmp_path, bars):
    for name in ("effects", "all"):
        res = runner.invoke(app, ["figure", name, "--out", str(tmp_path), "--size", "32"])
        assert res.exit_code == 1 and len(res.output.strip().splitlines()) == 1, res.output
        assert "--size 32" in res.output and "64 to 256" in res.output
    assert not bars and not any(tmp_path.iterdir())


@pytest.mark.slow
@pytest.mark.usefixtures("figures_not_drawn")  # its progress and numbers; each figure's picture has its own test
def test_figure_all_reports_all_its_work(tmp_path, bars, monkeypatch, figures_not_drawn):
    import planeray.experiments.paper as paper

    # What it reports, not what it draws (figures saved blank: each figure is tested by its own test).
    # 64: the smallest size the effects figure is validated at (README "Delay profiles"); its labels on two
    # scenes, the white target and skin (every scene's labels: tests/test_classify.py)
    monkeypatch.setattr(paper, "list_scenes", lambda: {"diffuse_plane": "", "skin": ""})
    res = runner.invoke(app, ["figure", "all", "--out", str(tmp_path), "--size", "64"])
    assert res.exit_code == 0, res.output
    tasks = _finished(bars)
    assert [t["description"] for t in tasks] == list(FIGURES)
    assert [t["total"] for t in tasks] == [figure_work(n, size=64) for n in FIGURES]
    lines = [json.loads(line) for line in res.stdout.splitlines()]
    assert [x["figure"] for x in lines] == list(FIGURES)
    for x in lines:
        saved = json.loads(Path(x["json"]).read_text())
        assert saved.pop("planeray_mark").startswith("planeray:record:") and x["numbers"] == saved


@pytest.mark.usefixtures("figures_not_drawn")  # what it prints; the study's figures: tests/test_study.py
def test_study_prints_its_findings_and_whole_paths(tmp_path, bars):
    out_dir = tmp_path / ("study_" + "x" * 80)
    res = runner.invoke(
        app, ["study", "demux", "--out", str(out_dir), "--quick", "--provider", "dipole", "--seeds", "1"]
    )
    assert res.exit_code == 0, res.output
    (task,) = _finished(bars)
    assert task["total"] == study_work(quick=True)
    lines = res.stdout.splitlines()
    assert lines[0].startswith("profiles: dipole") and "Fig. 5c: MSE vs noise eta" in lines
    assert any(line.startswith("regularization, eta 0.05: alpha 0.01, beta 0.01: MSE ") for line in lines)
    assert f"  {out_dir / 'study.json'}" in lines
    numbers = json.loads((out_dir / "study.json").read_text())
    assert numbers["files"] == [line.strip() for line in lines[lines.index("files:") + 1 :]]
    assert (out_dir / "fig6_mse_vs_params.png").exists() and (out_dir / "fig6c_mse_vs_g.csv").exists()
    bad = runner.invoke(app, ["study", "demux", "--out", str(out_dir), "--provider", "bogus"])
    assert bad.exit_code != 0


def test_mc_profile_shows_photons_traced(tmp_path, bars, monkeypatch):
    monkeypatch.setenv("PLANERAY_CACHE", str(tmp_path / "cache"))
    out = tmp_path / ("[x] " + "y" * 80) / "p.csv"
    args = ["mc", "profile", "--out", str(out), "--photons", "3000", "--rows", "5", "--sigma-a", "0.1"]
    res = runner.invoke(app, args)
    assert res.exit_code == 0, res.output
    (task,) = _finished(bars)
    assert task["total"] == 3000
    lines = res.stdout.splitlines()
    assert f"  {out}" in lines and f"  {out.with_suffix('.json')}" in lines
    res = runner.invoke(app, [*args, "--overwrite"])  # from the cache: the bar still completes
    assert res.exit_code == 0, res.output
    _finished(bars)


def test_paths_are_printed_as_they_are(tmp_path):
    # Rich markup would read "[a]" as a tag and drop it; a narrow table would cut a long value.
    path = tmp_path / "[a]" / ("stack_" + "z" * 120 + ".zarr")
    res = runner.invoke(app, ["simulate", "diffuse_plane", "--out", str(path), "--size", "8", "8", "--sweep", "quick"])
    assert res.exit_code == 0, res.output
    assert f"stack: {path}  (" in res.stdout
    res = runner.invoke(app, ["info", str(path)])
    assert res.exit_code == 0, res.output
    rows = [line.split("│")[1:3] for line in res.stdout.splitlines() if line.startswith("│")]
    start = next(i for i, (key, _) in enumerate(rows) if key.strip() == "path")
    end = next(i for i, (key, _) in enumerate(rows) if key.strip() == "images")
    assert "".join(value.strip() for _, value in rows[start:end]) == str(path)

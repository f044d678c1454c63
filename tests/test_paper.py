"""``planeray paper``: every figure, the report beside the paper's words, resuming, refusing.

One run at the smallest size (``--quick --size 16``; the effect labels clamp it to 64) is killed
after its third step (a step made to raise) and started again: the test checks that the rerun
continues without redoing a finished step, that every figure, ``numbers.json``, ``report.md`` and
``report.html`` are written, and that the numbers are those the figures' own commands compute
(rerun here, independently, with the exact commands the report prints).  The paper's quotations
are checked against the paper's text.
"""

from __future__ import annotations

import dataclasses
import json
import re
import shlex
from pathlib import Path

import pytest
from PIL import Image
from typer.testing import CliRunner

from planeray.cli import app
from planeray.experiments import paper, reproduce
from planeray.experiments.paper_report import FIGURE_ORDER, PAPER, WHERE, math_html
from planeray.io.marks import mark_text

runner = CliRunner()
ROOT = Path(__file__).resolve().parents[1]
#: The paper's text, beside the project (``../shared``, as ``fresh-clone-check`` links it too).
PAPER_TEXT = ROOT.parent / "shared" / "paper" / "non-epipolar-indirect-light-transport.txt"
OPTIONS = ["--quick", "--size", "16", "--seed", "0"]
KILLED_AT = "fig8"  # the third step


def _invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


@pytest.fixture(scope="module")
def run(tmp_path_factory, blank_figures):
    """A ``paper`` run killed at :data:`KILLED_AT`, then resumed; which steps each attempt ran.

    Its figures are saved blank (conftest ``blank_figures``): this test checks that every figure
    is written, linked and marked; what each figure shows is tested by its own command's test
    (``materials report``, ``skin pulse-report``, ``skin compare``, ``figure``, ``study``,
    ``emulate``) and by the gallery of the documentation site, which draws each at build time.
    """
    out = tmp_path_factory.mktemp("paper") / "run"
    calls = {"first": [], "second": []}
    attempt = ["first"]

    def counted(step):
        def run_step(folder, settings, advance):
            calls[attempt[0]].append(step.name)
            if attempt[0] == "first" and step.name == KILLED_AT:
                raise RuntimeError("killed for the test")
            return step.run(folder, settings, advance)

        return dataclasses.replace(step, run=run_step)

    with pytest.MonkeyPatch.context() as mp:
        blank_figures(mp)
        # The effect labels on two scenes, the white target and skin (every scene's labels: tests/test_classify.py).
        mp.setattr(paper, "list_scenes", lambda: {"diffuse_plane": "", "skin": ""})
        for name, step in list(reproduce.STEPS.items()):
            mp.setitem(reproduce.STEPS, name, counted(step))
        first = _invoke("paper", "--out", out, *OPTIONS)
        manifest_after_kill = json.loads((out / "planeray.json").read_text())
        left_after_kill = sorted(p.name for p in out.iterdir())
        attempt[0] = "second"
        second = _invoke("paper", "--out", out, *OPTIONS)
    return {
        "out": out,
        "first": first,
        "second": second,
        "calls": calls,
        "manifest_after_kill": manifest_after_kill,
        "left_after_kill": left_after_kill,
    }


@pytest.mark.slow
@pytest.mark.usefixtures("figures_not_drawn")  # the reruns of the figures' commands: their numbers
def test_a_quick_run_killed_and_resumed_writes_what_the_figures_own_commands_compute(run, tmp_path):
    """One test over the one run (under pytest-xdist a module fixture would run once per worker)."""
    _check_resumed(run)
    _check_files(run)
    _check_numbers(run, tmp_path)
    _check_report_quotes(run)


def _check_resumed(run):
    order = list(reproduce.STEPS)
    k = order.index(KILLED_AT)
    assert run["first"].exit_code == 1
    assert "killed for the test" in run["first"].output and "Traceback" not in run["first"].output
    assert run["calls"]["first"] == order[: k + 1]
    assert sorted(run["manifest_after_kill"]["steps"]) == sorted(order[:k])  # done: exactly those finished
    assert KILLED_AT not in run["left_after_kill"]  # nothing half-written at the step's folder
    assert not [n for n in run["left_after_kill"] if n.startswith(".")]  # no temporary left
    assert run["second"].exit_code == 0, run["second"].output
    assert f"resuming {run['out']}: {k} of {len(order)} steps already done" in run["second"].output
    assert run["calls"]["second"] == order[k:]  # the finished steps are not redone


def _check_files(run):
    out = run["out"]
    numbers = json.loads((out / "numbers.json").read_text())
    assert list(FIGURE_ORDER) == list(numbers["figures"])
    expected = {f"fig{i}" for i in (4, 5, 6, 8, 9, 10, 11, 12, 13, 14, 15, 16)} | {"labels"}
    assert set(FIGURE_ORDER) == expected and expected <= set(numbers)
    md = (out / "report.md").read_text()
    page = (out / "report.html").read_text()
    for key in FIGURE_ORDER:
        assert numbers[key], key
        assert numbers["figures"][key], key
        for png in numbers["figures"][key]:
            with Image.open(out / png) as im:  # a picture written by planeray, linked from both reports
                assert im.format == "PNG" and im.info["Software"] == mark_text("figure")
            assert f"]({png})" in md and f'src="{png}"' in page
        assert numbers["commands"][key] in md
    # offline: nothing fetched from elsewhere, every image relative and inside the folder
    assert not re.search(r"(src|href)=\"(https?:)?//", page)
    assert "<script" not in page
    # the summary first: every comparison of the page, in its order, each linked to its row; no raw TeX
    summary = page[page.index('<table class="summary">') : page.index("</table>")]
    assert page.index('<table class="summary">') < page.index("<p>") < page.index("<h2")
    linked = re.findall(r'<td><a href="#(\w+-\d+)">', summary)
    rows = re.findall(r'<tr id="(\w+-\d+)">', page)
    assert linked == rows and len(rows) >= 30
    assert [r.split("-")[0] for r in rows][:1] == ["fig4"]
    assert not re.search(r"\$[^$]*\\", page) and "\\mu" not in page and "\\alpha" not in page


def _rerun(command: str, out: Path):
    """Run a command the report prints (``planeray ...``) with its ``--out`` moved to ``out``."""
    words = shlex.split(command)
    assert words[0] == "planeray"
    words = words[1:]
    words[words.index("--out") + 1] = str(out)
    result = _invoke(*words)
    assert result.exit_code == 0, result.output
    return out


def _check_numbers(run, tmp_path):
    numbers = json.loads((run["out"] / "numbers.json").read_text())
    # Fig. 4 through `planeray emulate`
    got = json.loads((_rerun(numbers["commands"]["fig4"], tmp_path / "fig4") / "emulation.json").read_text())
    fig4 = numbers["fig4"]
    assert fig4["captures_emulated"] == got["n_captures"]["emulated"] == 17  # 16 camera rows + a dark frame
    for key, name in (("emulated_vs_truth", "emulated"), ("synchronized_vs_truth", "synchronized")):
        assert fig4[f"relative_rmse_{key}"] == got["errors"][key]["relative_rmse"], name
    # Figs. 11 and 12 through `planeray figure`
    for key in ("fig11", "fig12"):
        got = json.loads((_rerun(numbers["commands"][key], tmp_path / key) / f"{key}.json").read_text())
        assert numbers[key]["images"] == got["images"]
    assert numbers["fig12"]["relative_rmse_16ms"] == got["images"]["single line, 16 ms"]["relative_rmse"]
    # Figs. 13, 14, 16: the record `planeray skin compare` writes, in the step's folder
    assert numbers["commands"]["fig13"] == numbers["commands"]["fig16"]
    skin = json.loads((run["out"] / "skin" / "compare" / "skin.json").read_text())
    for row in skin["table"]:
        cell = numbers["fig16"]["by_condition"][row["condition"]][row["method"]]
        assert (cell["cnr"], cell["detected"]) == (row["cnr"], row["n_detected"])
    assert numbers["fig14"]["ladder"]["enhanced_cnr"] == skin["enhancement"]["enhanced_cnr"]
    # Figs. 5, 6: the study's own record in the step's folder, and Fig. 10's
    study = json.loads((run["out"] / "study" / "study.json").read_text())
    assert numbers["fig5"]["pinv_minimum"] == study["example_min"]["pinv"] < 0
    mat = json.loads((run["out"] / "fig10" / "materials" / "materials.json").read_text())
    assert numbers["fig10"]["accuracy"] == mat["stack_profiles"]["floor_edge"]["test"]["accuracy"]


def _sections(text: str) -> dict:
    """``{"5.1": (start, end)}``: each numbered section's span of the paper's text (to the next heading)."""
    heads = [(m.start(), m.group(1)) for m in re.finditer(r"^(\d+(?:\.\d+)?) (?:[A-Z]|3D )", text, flags=re.M)]
    spans = {}
    for i, (start, number) in enumerate(heads):
        later = [h for h, n in heads[i + 1 :] if n.count(".") <= number.count(".")]
        spans[number] = (start, later[0] if later else len(text))
    return spans


def test_the_paper_quotations_are_verbatim_and_where_the_report_says():
    if not PAPER_TEXT.is_file():
        pytest.skip(f"the paper's text is not beside the project ({PAPER_TEXT})")
    text = PAPER_TEXT.read_text(encoding="utf-8")
    spans = _sections(text)
    assert {"4", "5.1", "5.2", "6", "8", "9", "10"} <= set(spans)
    quotes = [(key, name, q) for key, entry in PAPER.items() for name, q in entry["quotes"].items()]
    assert len(quotes) >= 2 * len(FIGURE_ORDER)
    for key, name, q in quotes:
        assert text.count(q) >= 1, (key, name)
        place = WHERE[key][name]
        caption = re.fullmatch(r"Fig\. (\d+) caption", place)
        if caption:  # in the figure's caption line
            line = next(ln for ln in text.splitlines() if ln.startswith(f"Fig. {caption.group(1)}. "))
            assert q in line, (key, name, place)
        else:  # inside the section it names
            number = re.match(r"Sec\. (\d+(?:\.\d+)?)", place).group(1)
            start, end = spans[number]
            assert any(start <= m.start() < end for m in re.finditer(re.escape(q), text)), (key, name, place)
    for key, entry in PAPER.items():  # the figure the section names is the figure's own
        if key.startswith("fig"):
            assert f"Fig. {key[3:]}" in entry["section"]


def _check_report_quotes(run):
    md = (run["out"] / "report.md").read_text()
    for key, entry in PAPER.items():
        assert entry["section"] in md
        for name, q in entry["quotes"].items():
            cell = math_html(q).replace("|", "\\|")  # its TeX as text; a pipe in a Markdown table cell is escaped
            assert f'"{cell}" ({WHERE[key][name]})' in md, (key, q)


def test_other_options_refuse_to_resume_in_one_line(tmp_path):
    out = tmp_path / "run"
    plan = reproduce.plan_paper_run(out, quick=True, size=16)
    reproduce._start(plan)  # a run that wrote its manifest, then was killed
    before = sorted(p.name for p in out.iterdir())
    result = _invoke("paper", "--out", out, "--quick", "--size", "32")
    assert result.exit_code == 1
    line = result.output.strip()
    assert "\n" not in line and "--size 16" in line and "--size 32" in line and "--overwrite" in line
    assert sorted(p.name for p in out.iterdir()) == before
    # the same options resume it: planned, nothing done yet, nothing refused
    again = reproduce.plan_paper_run(out, quick=True, size=16)
    assert again.resuming and again.todo == list(reproduce.STEPS)
    # --overwrite starts again
    assert reproduce.plan_paper_run(out, quick=True, size=32, overwrite=True).restart
    # a file of yours where a step writes its folder: refused before any work, and kept
    (out / "fig8").write_text("mine")
    result = _invoke("paper", "--out", out, "--quick", "--size", "16")
    assert result.exit_code == 1 and "fig8" in result.output and "did not write" in result.output
    assert (out / "fig8").read_text() == "mine"


def test_a_folder_planeray_did_not_write_is_refused_even_with_overwrite(tmp_path):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    for extra in ([], ["--overwrite"]):
        result = _invoke("paper", "--out", out, "--quick", "--size", "16", *extra)
        assert result.exit_code == 1
        assert "did not write" in result.output or "already exists" in result.output
    assert (out / "notes.txt").read_text() == "mine"


def test_bad_options_name_the_option():
    result = _invoke("paper", "--out", "/tmp/x-never", "--size", "8")
    assert result.exit_code == 1 and "--size" in result.output
    result = _invoke("paper", "--out", "/tmp/x-never", "--seed", "-1")
    assert result.exit_code == 1 and "--seed" in result.output


def test_step_settings_follow_the_options():
    assert reproduce.step_settings("labels", quick=True, size=16)["size"] == 64  # validated range of effects
    assert reproduce.step_settings("fig15", quick=True, size=16) == {"size": 16, "projector_rows": 64, "quick": True}
    assert reproduce.step_settings("fig10", quick=False) == {"size": 128, "quick": False}
    assert "seed" not in reproduce.step_settings("study", quick=True, seed=3)
    assert reproduce.step_settings("fig8", quick=True, seed=3)["seed"] == 3


def test_the_extensions_report_what_was_measured():
    """Figs. 10 and 14 extended (the full run): the media's fitted coefficients and the veins' depths, in the
    comparison rows beside the paper's words; --quick says they were not measured."""
    from planeray.experiments.paper_report import comparisons
    from planeray.experiments.skin_depth import depth_summary

    veins = [  # (true depth of the top mm, resolved, error mm)
        (1.3, False, None),
        (2.1, True, -0.01),
        (1.6, True, 0.42),
        (4.1, True, 0.7),
        (3.6, False, None),
    ]
    rows = [
        {"true_depth_mm": d, "resolved": ok, "error_mm": e, "depth_se_mm": 0.1, "tone": "fair", "wavelength_nm": 850,
         "seed": 0, "id": i}
        for i, (d, ok, e) in enumerate(veins)
    ]  # fmt: skip
    depth = {"condition": {"tone": "fair", "wavelength_nm": 850}, "summary": depth_summary(rows), "veins": rows}
    base = {"ladder": {"gain": None, "enhanced_cnr": None, "best_single_cnr": None, "best_single_delay_us": 0.0}}
    base["forearm"] = base["ladder"]
    (_, row) = comparisons("fig14", {**base, "vein_depth": depth})
    assert "2 of 3 veins 1-3 mm deep resolved, 2 of them within 0.5 mm (worst 0.42 mm)" in row["planeray"]
    assert "deeper: 1 of 2 resolved" in row["planeray"] and row["verdict"] == "qualitative"
    assert comparisons("fig14", base)[1]["verdict"] == "not measured"
    media = {"fat-free milk": {"published": {}, "truth": {"mu_s_prime_rel_err": -0.016, "mu_a_rel_err": None}}}
    fig10 = {
        "accuracy": {"fat-free milk": 1.0},
        "min_material_accuracy": 1.0,
        "share_of_errors_near_wall": None,
        "near_wall_pixel_share": 0.4,
        "misclassified": 0,
    }
    row = comparisons("fig10", {**fig10, "media_fit": {"near_wall_mm": 3.0, "media": media}})[-1]
    assert "truth: fat-free milk -2% / not identified" in row["planeray"] and row["verdict"] == "qualitative"
    assert comparisons("fig10", fig10)[-1]["verdict"] == "not measured"

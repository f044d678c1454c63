"""The paper report's page: a summary of every comparison first, the paper's math as text, verdicts on intervals.

The report is rendered from records made here (two figures' measured numbers), so each rule is checked
without a ``planeray paper`` run (tests/test_paper.py runs one and checks the same on its page).
"""

from __future__ import annotations

import re
from html.parser import HTMLParser

import numpy as np
import pytest

from planeray.experiments.paper_report import PAPER, comparisons, math_html, render_html, render_markdown

FIG8 = {
    "delays_us": [-1500.0, 1500.0],
    "delay_step_us": 187.5,
    "n_delays": 17,
    "exposures_us": [600.0, 750.0, 900.0, 1050.0, 1200.0],
    "images": 85,
    "images_demultiplexed": 75,
    "boundary_images_left_out": 10,
    "epipolar_images": 45,
}


def _fig11(captured, one_row, truth=0.85):
    return {
        "michelson_captured_600us": captured[0],
        "michelson_sharpened_resolution": one_row[0],
        "michelson_sharpened_1_row": one_row[0],
        "michelson_truth_direct": truth,
        "michelson_seeds": {"captured_600us": captured, "sharpened_resolution": one_row, "sharpened_1_row": one_row},
    }


def _report(measured: dict):
    manifest = {
        "options": {"quick": True, "size": 16, "seed": 0},
        "planeray_version": "0",
        "inputs_digest": "x",
        "steps": {k: {"seconds": 1.0} for k in measured},
    }
    records = {
        k: {
            "results": {k: {"measured": m, "figures": [f"{k}/{k}.png"]}},
            "settings": {"size": 16},
            "seconds": 1.0,
            "command": f"planeray figure {k} --out x",
        }
        for k, m in measured.items()
    }
    return render_html(manifest, records), render_markdown(manifest, records)


class _Page(HTMLParser):
    def __init__(self):
        super().__init__()
        self.ids, self.hrefs, self.order = [], [], []

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if "id" in a:
            self.ids.append(a["id"])
        if tag == "a" and a.get("href", "").startswith("#"):
            self.hrefs.append(a["href"][1:])
        self.order.append((tag, a.get("class")))


def test_the_summary_comes_first_and_links_every_comparison_in_order():
    page, md = _report({"fig8": FIG8, "fig11": _fig11([0.30, 0.31, 0.29, 0.30, 0.32], [0.40, 0.41, 0.39, 0.42, 0.40])})
    n8, n11 = len(comparisons("fig8", FIG8)), len(comparisons("fig11", _fig11([0.3, 0.31], [0.4, 0.41])))
    parsed = _Page()
    parsed.feed(page)
    body = [t for t in parsed.order if t[0] not in ("html", "head", "meta", "title", "style", "body")]
    assert body[:2] == [("h1", None), ("table", "summary")]  # the summary: first thing after the title
    summary = page[page.index('<table class="summary">') : page.index("</table>")]
    anchors = re.findall(r'<td><a href="#(fig\d+)">', summary)
    claims = re.findall(r'<td><a href="#((?:fig8|fig11)-\d+)">', summary)
    assert claims == [f"fig8-{i}" for i in range(1, n8 + 1)] + [f"fig11-{i}" for i in range(1, n11 + 1)]
    assert anchors == ["fig8"] * n8 + ["fig11"] * n11
    assert set(claims + anchors) <= set(parsed.ids)  # every link lands on its section or comparison
    rows = [i for i in parsed.ids if re.fullmatch(r"fig(8|11)-\d+", i)]
    assert rows == claims  # the page's comparisons, in the summary's order
    verdicts = [v for v in re.findall(r'<span class="([\w-]+)">', summary) if v != "math"]
    assert len(verdicts) == len(claims)
    # Markdown: the same summary before the first section, with anchors the links reach
    head = md[: md.index("## ")]
    assert re.findall(r"\]\(#((?:fig8|fig11)-\d+)\)", head) == claims
    assert all(f'<a id="{c}"></a>' in md for c in claims + anchors)


def test_no_raw_latex_is_left_on_the_page():
    quotes = [q for v in PAPER.values() for q in v["quotes"].values()]
    assert any("\\mu" in q for q in quotes)  # the paper's own TeX, quoted verbatim
    for q in quotes:
        text = math_html(q)
        assert not re.search(r"\$[^$]*\\", text) and "\\" not in text, text
        assert "$" not in text, text
    page, md = _report({"fig8": FIG8, "fig11": _fig11([0.3, 0.31, 0.3], [0.4, 0.41, 0.42])})
    for text in (page, md):
        assert not re.search(r"\$[^$]*\\", text)
        assert "\\mu" not in text and "\\alpha" not in text
    assert "600 \u2009μs" in page and "t<sub>e</sub>" in page  # the wax candle's exposure, Fig. 8's rule


@pytest.mark.parametrize(
    ("one_row", "verdict"),
    [
        ([0.40, 0.41, 0.39, 0.42, 0.40], "agrees"),  # every seed's gain far above its spread
        ([0.33, 0.27, 0.31, 0.28, 0.33], "partly"),  # a mean gain, within the noise
        ([0.20, 0.21, 0.19, 0.22, 0.20], "differs"),
    ],
)
def test_fig11_contrast_verdict_rests_on_its_interval_over_noise_seeds(one_row, verdict):
    captured = [0.30, 0.31, 0.29, 0.30, 0.32]
    row = comparisons("fig11", _fig11(captured, one_row))[1]
    gain = np.subtract(one_row, captured)
    from scipy import stats

    half = stats.t.ppf(0.975, 4) * gain.std(ddof=1) / np.sqrt(5)  # the interval, computed here
    assert row["interval"] == pytest.approx([gain.mean() - half, gain.mean() + half])
    assert row["verdict"] == verdict
    assert "95 % interval" in row["planeray"] and "5 camera-noise seeds" in row["planeray"]


def _fig15(errors):
    return {
        "true_mean_rate_bpm": 72.0,
        "fig15a_rate_bpm": 72.5,
        "accuracy": {"total": len(errors), "detected": len(errors), "mean_abs_error_bpm": float(np.mean(errors))},
        "abs_errors_bpm": errors,
        "snr_db": {"indirect": 10.0, "global": 5.0},
        "rate_bpm": {"indirect": 72.0, "global": None},
    }


@pytest.mark.parametrize(
    ("errors", "verdict"),
    [([0.5, 1.0, 2.5, 3.0], "agrees"), ([0.1, 0.2, 0.4], "partly"), ([4.0, 6.0, 5.0], "differs")],
)
def test_fig15_agrees_only_when_the_paper_s_error_lies_within_planeray_s(errors, verdict):
    row = comparisons("fig15", _fig15(errors))[0]
    assert row["interval"] == [min(errors), max(errors)]
    assert row["verdict"] == verdict


def _fig12(syn, short, long):
    return {
        "relative_rmse_synthesized": syn[0],
        "relative_rmse_16ms": short[0],
        "relative_rmse_800ms": long[0],
        "relative_rmse_seeds": {"synthesized": syn, "16ms": short, "800ms": long},
    }


@pytest.mark.parametrize(
    ("short", "verdict"),
    [
        ([1.9, 1.95, 2.1, 1.97, 1.91], "agrees"),
        ([0.75, 0.5, 0.7, 0.65, 0.55], "partly"),  # the 16 ms capture within the synthesized image's spread
    ],
)
def test_fig12_verdicts_rest_on_intervals_over_noise_seeds(short, verdict):
    syn, long = [0.69, 0.55, 0.67, 0.69, 0.60], [0.24, 0.22, 0.25, 0.22, 0.23]
    first, second = comparisons("fig12", _fig12(syn, short, long))
    assert first["verdict"] == verdict and len(first["interval"]) == 2
    ratio = np.divide(syn, long)
    assert second["interval"][0] < ratio.mean() < second["interval"][1]
    assert second["verdict"] == "partly"  # ~2.8x the 800 ms capture's error: not "similar"
    assert comparisons("fig12", _fig12(syn, short, [0.6, 0.5, 0.6, 0.62, 0.58]))[1]["verdict"] == "agrees"


@pytest.mark.parametrize(
    ("accuracy", "pixels", "verdict"),
    [
        ({"a": 0.97, "b": 0.95}, {"a": 2000, "b": 2000}, "agrees"),  # every interval above 90 %
        ({"a": 0.97, "b": 0.92}, {"a": 100, "b": 100}, "partly"),  # 92 of 100: the interval spans 90 %
        ({"a": 0.97, "b": 0.80}, {"a": 100, "b": 99}, "differs"),  # the quick run's 2% milk: below 90 %
    ],
)
def test_fig10_accuracy_verdict_rests_on_binomial_intervals(accuracy, pixels, verdict):
    from scipy.stats import binomtest

    m = {"accuracy": accuracy, "pixels": pixels, "min_material_accuracy": min(accuracy.values())}
    m |= {"misclassified": 1, "share_of_errors_near_wall": 1.0, "near_wall_pixel_share": 0.4}
    row = comparisons("fig10", m)[0]
    b = min(accuracy, key=accuracy.get)
    ci = binomtest(round(accuracy[b] * pixels[b]), pixels[b]).proportion_ci(method="wilson")
    assert row["interval"][1] == pytest.approx(ci.high)
    assert row["verdict"] == verdict


@pytest.mark.parametrize(("wrong", "share", "verdict"), [(28, 1.0, "agrees"), (214, 0.55, "partly")])
def test_fig10_errors_near_walls_judged_on_their_interval(wrong, share, verdict):
    m = {"accuracy": {"a": 0.95}, "min_material_accuracy": 0.95, "misclassified": wrong}
    m |= {"share_of_errors_near_wall": share, "near_wall_pixel_share": 0.4}
    row = comparisons("fig10", m)[1]
    assert row["verdict"] == verdict
    lo, hi = row["interval"]
    assert lo < share <= hi  # the Wilson interval around the share measured

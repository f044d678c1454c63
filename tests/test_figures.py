"""The figure functions: usable from a notebook.

Importing :mod:`planeray.figures` leaves matplotlib's backend alone, every figure
function returns a :class:`matplotlib.figure.Figure` (and writes the PNG only when
given ``out=``), single-panel figures draw into a given Axes, options are
keyword-only, and no pyplot figure is left open.  pyplot is imported only inside
the tests that look at its state.
"""

from __future__ import annotations

import ast
import inspect
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from matplotlib.figure import Figure, SubFigure
from PIL import Image

import planeray as pr
from planeray.figures import (
    contact_sheet_figure,
    delay_profiles_figure,
    label_map_figure,
    transport_profiles_figure,
)
from planeray.figures import study as study_figs
from planeray.figures.mc import mc_profile_figure
from planeray.study import METHODS

SRC = Path(pr.__file__).resolve().parent


# --------------------------------------------------------------------- data
@pytest.fixture(scope="module")
def scene():
    return pr.make_scene("mirror_ball", (24, 24), projector_rows=180, seed=0)


@pytest.fixture(scope="module")
def stack(scene):
    return pr.simulate_stack(scene, pr.quick_sweep(), seed=0)


@pytest.fixture(scope="module")
def mc_profile():
    return pr.mc_line_profile(pr.Medium(sigma_s=1.0, sigma_a=0.1, g=0.5), n_photons=2000, offsets_rows=np.arange(-6, 7))


def _study_results():
    """Small made-up results shaped as :mod:`planeray.study` returns them."""
    rng = np.random.default_rng(0)
    u = np.arange(-20, 21)
    truth = np.exp(-np.abs(u) / 4.0)
    ex = {
        "offsets": u,
        "truth": truth,
        **{m: truth + 0.01 * rng.standard_normal(u.size) for m in METHODS},
        "mse": {m: 1e-4 * (k + 1) for k, m in enumerate(METHODS)},
    }
    ns = {"noise": np.array([0.01, 0.05, 0.2]), "mse": {m: rng.uniform(1e-5, 1e-3, (3, 2)) for m in METHODS}}
    sweeps = {
        name: {
            "name": name,
            "values": np.asarray(vals, float),
            "mse": {m: rng.uniform(1e-5, 1e-3, (len(vals), 2)) for m in METHODS},
            "mean_abs_offset": np.ones(len(vals)),
        }
        for name, vals in (("sigma_s", [0.5, 1.0, 2.0]), ("sigma_a", [0.0, 0.01, 0.1]), ("g", [-0.5, 0.0, 0.9]))
    }
    a, b = np.array([1e-3, 1e-2, 1e-1]), np.array([1e-3, 1e-2, 1e-1])
    mse = rng.uniform(1e-5, 1e-3, (3, 3))
    rs = {"alphas": a, "betas": b, "mse": mse, "bias2": mse / 2, "variance": mse / 2}
    return ex, ns, sweeps, rs


def _cases(scene, stack, mc_profile):
    """``(name, draw(**kw) -> Figure, expected number of Axes, dpi of the PNG)`` for every figure function."""
    pixels = [(5, 6), (12, 12), (20, 3)]
    prof = pr.measured_delay_profiles(stack, pixels)
    continuous = pr.transport_delay_profiles(
        scene.transport, prof.pixels, exposure_us=float(prof.exposure_us.min()), lines_per_second=stack.lines_per_second
    )
    ref = stack.image(0)
    ex, ns, sweeps, rs = _study_results()
    point = pr.mc.mc_point_profile(pr.Medium(sigma_s=1.0, sigma_a=0.1, g=0.5), n_photons=1000, radius_bins=np.arange(6))
    return [
        ("contact_sheet", lambda **kw: contact_sheet_figure(stack, **kw), 1, 110),  # one image of all tiles
        (
            "contact_sheet_max_delays",
            lambda **kw: contact_sheet_figure(stack, max_delays=4, gamma=1.0, **kw),
            1,
            110,
        ),
        ("delay_profiles", lambda **kw: delay_profiles_figure(stack, prof, names=["a", "b", "c"], **kw), 2, 110),
        (
            "delay_profiles_continuous",
            lambda **kw: delay_profiles_figure(
                stack, prof, exposure_us=float(prof.exposure_us.min()), continuous=continuous, **kw
            ),
            2,
            110,
        ),
        ("label_map", lambda **kw: label_map_figure(scene.labels, **kw), 1, 110),
        ("label_map_reference", lambda **kw: label_map_figure(scene.labels, reference=ref, title="t", **kw), 2, 110),
        (
            "transport_profiles",
            lambda **kw: transport_profiles_figure(
                scene.transport,
                pixels,
                truth=scene.transport,
                truth_scale=2.0,
                names=["a", "b", "c"],
                resolution_rows=3.0,
                **kw,
            ),
            3,
            110,
        ),
        ("mc_profile", lambda **kw: mc_profile_figure(mc_profile, **kw), 2, 100),
        ("mc_profile_point", lambda **kw: mc_profile_figure(point, compare_dipole=False, **kw), 2, 100),
        ("plot_reconstruction", lambda **kw: study_figs.plot_reconstruction(ex, noise=0.05, **kw), 2, 100),
        ("plot_noise_sweep", lambda **kw: study_figs.plot_noise_sweep(ns, **kw), 1, 100),
        ("plot_parameter_sweeps", lambda **kw: study_figs.plot_parameter_sweeps(sweeps, noise=0.05, **kw), 3, 100),
        (
            "plot_regularization",
            lambda **kw: study_figs.plot_regularization(rs, noise=0.05, **kw),
            4,
            100,
        ),  # 2 maps + 2 colorbars
    ]


@pytest.fixture(scope="module")
def cases(scene, stack, mc_profile):
    return {name: (draw, n_axes, dpi) for name, draw, n_axes, dpi in _cases(scene, stack, mc_profile)}


CASE_NAMES = [
    "contact_sheet",
    "contact_sheet_max_delays",
    "delay_profiles",
    "delay_profiles_continuous",
    "label_map",
    "label_map_reference",
    "transport_profiles",
    "mc_profile",
    "mc_profile_point",
    "plot_reconstruction",
    "plot_noise_sweep",
    "plot_parameter_sweeps",
    "plot_regularization",
]


# ------------------------------------------------------------------ backend
@pytest.mark.parametrize("backend", [None, "svg"])
def test_importing_figures_leaves_the_backend_alone(backend):
    """With ``MPLBACKEND`` unset (backend still undecided) or set to a non-Agg backend,
    importing the figure modules changes neither ``rcParams['backend']`` nor imports pyplot
    (an ``matplotlib.use("Agg")`` at import would fail both)."""
    code = """
import sys
import matplotlib
before = dict.__getitem__(matplotlib.rcParams, "backend")  # raw: the 'auto' sentinel when undecided
import planeray.figures, planeray.figures.mc, planeray.figures.study
import planeray.experiments.paper, planeray.experiments.study
after = dict.__getitem__(matplotlib.rcParams, "backend")
assert after is before or after == before, (before, after)
assert "matplotlib.pyplot" not in sys.modules, "pyplot was imported"
print("backend", after if isinstance(after, str) else "undecided")
"""
    env = {k: v for k, v in os.environ.items() if k != "MPLBACKEND"}
    env["PYTHONPATH"] = os.pathsep.join([str(SRC.parent), *filter(None, [env.get("PYTHONPATH")])])
    if backend is not None:
        env["MPLBACKEND"] = backend
    res = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == f"backend {backend or 'undecided'}"


def _calls(path: Path):
    """``(what, line)`` for every pyplot import and ``matplotlib.use`` / ``mpl.use`` call in a module."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    aliases = {"matplotlib"}
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                if a.name == "matplotlib" and a.asname:
                    aliases.add(a.asname)
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                if a.name == "matplotlib.pyplot":
                    yield "import matplotlib.pyplot", node.lineno
        elif isinstance(node, ast.ImportFrom):
            if node.module == "matplotlib.pyplot" or (
                node.module == "matplotlib" and any(a.name == "pyplot" for a in node.names)
            ):
                yield "from matplotlib import pyplot", node.lineno
            if node.module == "matplotlib" and any(a.name == "use" for a in node.names):
                yield "from matplotlib import use", node.lineno
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "use":
            if isinstance(node.func.value, ast.Name) and node.func.value.id in aliases:
                yield "matplotlib.use(...)", node.lineno


def test_no_module_chooses_a_backend_or_uses_pyplot():
    found = [
        f"{p.relative_to(SRC.parent)}:{line}: {what}" for p in sorted(SRC.rglob("*.py")) for what, line in _calls(p)
    ]
    assert not found, "\n".join(found)


# ------------------------------------------------------------------- figures
@pytest.mark.parametrize("name", CASE_NAMES)
def test_returns_a_figure_without_writing(cases, name, tmp_path, monkeypatch):
    import matplotlib.pyplot as plt

    monkeypatch.chdir(tmp_path)
    draw, n_axes, _ = cases[name]
    plt.close("all")
    fig = draw()
    assert plt.get_fignums() == []  # no pyplot figure left open
    assert isinstance(fig, Figure)
    assert len(fig.axes) == n_axes
    assert fig.canvas.manager is None  # not a pyplot figure
    assert list(tmp_path.iterdir()) == []
    # What a notebook's display does with it, render it to PNG without a backend chosen, is what
    # ``out=`` does with the same figure: test_out_writes_the_png renders every one.


@pytest.mark.parametrize("name", CASE_NAMES)
def test_out_writes_the_png(cases, name, tmp_path):
    import matplotlib.pyplot as plt

    draw, n_axes, dpi = cases[name]
    out = tmp_path / "sub" / f"{name}.png"
    plt.close("all")
    fig = draw(out=out)
    assert plt.get_fignums() == []
    assert isinstance(fig, Figure) and len(fig.axes) == n_axes
    with Image.open(out) as im:
        assert im.format == "PNG"
        expected = fig.get_size_inches() * dpi
        assert np.all(np.abs(np.array(im.size) - expected) <= 1), (im.size, expected)
    assert sorted(p.name for p in out.parent.iterdir()) == [out.name]  # atomic: no temporary left


def test_out_writes_the_same_png_as_savefig_and_takes_a_str(cases, tmp_path):
    draw, _, dpi = cases["label_map_reference"]
    (tmp_path / "a.png").write_bytes(b"old")
    fig = draw(out=str(tmp_path / "a.png"))  # a str path works too, and replaces the file
    from planeray.io.marks import file_mark, mark_text

    fig.savefig(tmp_path / "b.png", format="png", dpi=dpi, metadata={"Software": mark_text("figure")})
    assert (tmp_path / "a.png").read_bytes() == (tmp_path / "b.png").read_bytes()
    assert file_mark(tmp_path / "a.png") == "figure"  # planeray's mark: a later --overwrite may replace it


# --------------------------------------------------------------------- ax=
def _fresh_ax():
    return Figure(figsize=(4, 3)).subplots()


def test_single_panel_figures_draw_into_a_given_ax(scene, stack, tmp_path):
    ns = _study_results()[1]
    draws = {  # name: (draw, dpi of the PNG)
        "label_map": (lambda ax, **kw: label_map_figure(scene.labels, ax=ax, title="mine", **kw), 110),
        "transport_profiles": (
            lambda ax, **kw: transport_profiles_figure(
                scene.transport, [(12, 12)], truth=scene.transport, title="mine", ax=ax, **kw
            ),
            110,
        ),
        "transport_profiles_1d_pixel": (
            lambda ax, **kw: transport_profiles_figure(scene.transport, (12, 12), ax=ax, **kw),
            110,
        ),
        "plot_noise_sweep": (lambda ax, **kw: study_figs.plot_noise_sweep(ns, ax=ax, **kw), 100),
    }
    for name, (draw, dpi) in draws.items():
        ax = _fresh_ax()
        size = tuple(ax.figure.get_size_inches())
        fig = draw(ax)
        assert fig is ax.figure, name
        assert fig.axes == [ax], name  # nothing added (no colorbar, no second panel)
        assert ax.has_data(), name
        assert tuple(fig.get_size_inches()) == size, name  # the caller's figure keeps its size
        # and with out=: the caller's figure is written
        ax = _fresh_ax()
        fig = draw(ax, out=tmp_path / f"{name}.png")
        with Image.open(tmp_path / f"{name}.png") as im:
            assert im.size == (4 * dpi, 3 * dpi), name
    ax = _fresh_ax()
    label_map_figure(scene.labels, ax=ax, title="mine")
    assert ax.get_title() == "mine"
    ax = _fresh_ax()
    transport_profiles_figure(scene.transport, [(12, 12)], title="mine", ax=ax)
    assert ax.get_title() == "mine"


def test_ax_in_a_subfigure_and_next_to_other_panels(scene, tmp_path):
    fig = Figure(figsize=(8, 3))
    left, right = fig.subfigures(1, 2)
    other = left.subplots()
    other.plot([0, 1], [0, 1])
    ax = right.subplots()
    got = label_map_figure(scene.labels, ax=ax, out=tmp_path / "sub.png")
    assert got is ax.figure and isinstance(got, (Figure, SubFigure))
    assert len(fig.axes) == 2
    with Image.open(tmp_path / "sub.png") as im:  # the whole figure is written
        assert im.size == (880, 330)


def test_ax_refuses_what_does_not_fit_one_panel(scene, stack):
    with pytest.raises(ValueError, match="either ax"):
        label_map_figure(scene.labels, reference=stack.image(0), ax=_fresh_ax())
    with pytest.raises(ValueError, match="one pixel"):
        transport_profiles_figure(scene.transport, [(1, 1), (2, 2)], ax=_fresh_ax())


@pytest.mark.parametrize("max_delays", [None, 4])
def test_contact_sheet_shows_each_image_at_its_delay_and_exposure(stack, max_delays):
    """The sheet's one image: each tile is the stack's image at its delay (left to right) and exposure
    (longest on top), all scaled by one factor (gamma 1); frames red exactly where ``|t_d| >= t_e / 2``
    (images used), dashed grey on the excluded boundary images, black on the others."""
    from matplotlib.colors import to_rgba

    fig = contact_sheet_figure(stack, gamma=1.0, max_delays=max_delays)
    (ax,) = fig.axes
    mosaic = np.asarray(ax.images[0].get_array())
    H, W = stack.shape
    delays, exposures = stack.delays(), stack.exposures()[::-1]
    if max_delays:
        delays = delays[np.linspace(0, delays.size - 1, max_delays).round().astype(int)]
    assert [t.get_text() for t in ax.get_xticklabels()] == [f"{d:g}" for d in delays]
    assert [t.get_text() for t in ax.get_yticklabels()] == [f"{e:g}" for e in exposures]
    ratios, expected = [], {"red": 0, "dashed": 0, "black": 0}
    for y_mid, e in zip(ax.get_yticks(), exposures):
        for x_mid, d in zip(ax.get_xticks(), delays):
            y0, x0 = round(y_mid - (H - 1) / 2), round(x_mid - (W - 1) / 2)
            tile = mosaic[y0 : y0 + H, x0 : x0 + W]
            assert tile.shape[:2] == (H, W)
            i = stack.index_of(d, e)
            if i is None:
                assert np.all(tile == np.float32(0.85))
                continue
            np.testing.assert_array_equal(tile[..., 0], tile[..., 2])  # grey
            image = stack.image(i)
            shown = (tile[..., 0] < 1) & (image > 0)  # not clipped by the common scaling
            ratios.append(tile[..., 0][shown] / image[shown])
            expected["black"] += 1  # every image's frame, under its style's
            if stack.excluded[i]:
                expected["dashed"] += 1
            elif abs(d) >= e / 2:
                expected["red"] += 1
    ratios = np.concatenate(ratios)
    np.testing.assert_allclose(ratios, np.median(ratios), rtol=1e-5)  # one brightening factor for every tile
    (frames,) = ax.collections
    colors = [tuple(c) for c in frames.get_edgecolors()]
    styles = list(frames.get_linestyles())
    got = {
        "red": colors.count(to_rgba("red")),
        "dashed": sum(1 for c, ls in zip(colors, styles) if c == to_rgba("0.6") and ls[1] is not None),
        "black": colors.count(to_rgba("black")),
    }
    assert got == expected and min(expected.values()) > 0, (got, expected)


# ------------------------------------------------------------------- the API
FUNCTIONS = {
    contact_sheet_figure: ["stack"],
    delay_profiles_figure: ["stack", "profiles"],
    label_map_figure: ["labels"],
    transport_profiles_figure: ["estimate", "pixels"],
    mc_profile_figure: ["prof"],
    study_figs.plot_reconstruction: ["ex"],
    study_figs.plot_noise_sweep: ["ns"],
    study_figs.plot_parameter_sweeps: ["sweeps"],
    study_figs.plot_regularization: ["rs"],
}


@pytest.mark.parametrize("func", list(FUNCTIONS), ids=lambda f: f.__name__)
def test_options_are_keyword_only_and_out_is_optional(func):
    params = inspect.signature(func).parameters
    positional = [n for n, p in params.items() if p.kind is not inspect.Parameter.KEYWORD_ONLY]
    assert positional == FUNCTIONS[func]
    assert params["out"].kind is inspect.Parameter.KEYWORD_ONLY and params["out"].default is None
    doc = inspect.getdoc(func)
    for section in ("Parameters", "Returns", "Examples"):
        assert f"\n{section}\n---" in doc, (func.__name__, section)


def test_positional_out_is_refused(stack, tmp_path):
    with pytest.raises(TypeError):
        contact_sheet_figure(stack, tmp_path / "x.png")
    assert not (tmp_path / "x.png").exists()

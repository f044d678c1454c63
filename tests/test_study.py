"""The Sec. 5.2 demultiplexing study (quick grid, dipole provider)."""

import json

import numpy as np
import pytest

from planeray import study
from planeray.experiments.study import run_study, study_report, study_work


@pytest.fixture(scope="module")
def setup():
    return study.study_setup()


@pytest.fixture(scope="module")
def provider(setup):
    return study.dipole_provider(setup.offsets)


def test_setup_is_the_paper_sweep(setup):
    assert setup.A.shape == (75, 229)
    assert setup.offsets[0] == -114 and setup.offsets[-1] == 114


def test_truth_is_normalized(setup, provider):
    T = study.scaled_truth(setup.A, provider(1.0, 0.0, 0.9))
    assert np.max(setup.A @ T) == pytest.approx(1.0)
    assert T.min() >= 0


def test_pinv_goes_negative_and_full_wins_at_default_noise(setup, provider):
    ex = study.reconstruction_example(setup, provider)
    assert ex["pinv"].min() < -0.01  # measured about -0.09 (Fig. 5a)
    assert ex["nnls"].min() >= 0 and ex["full"].min() >= 0
    T = study.scaled_truth(setup.A, provider(1.0, 0.0, 0.9))
    mse = study.mse_trials(setup, T, 0.05, seeds=5)
    full, pinv, nnls = (mse[m].mean() for m in ("full", "pinv", "nnls"))
    # measured: full ~1.4e-4, pinv ~1e-3, nnls ~8e-4
    assert full < 0.5 * pinv and full < 0.5 * nnls


def test_mse_increases_with_noise(setup, provider):
    ns = study.noise_sweep(setup, provider, [0.005, 0.05, 0.3], seeds=3)
    for m in study.METHODS:
        assert np.all(np.diff(ns["mse"][m].mean(axis=1)) > 0), m
    # at low noise the unconstrained pinv is as good as the full method (paper: "can sometimes
    # yield lower MSE ... at low noise"), at high noise the regularized method is best
    assert ns["mse"]["pinv"][0].mean() < 2 * ns["mse"]["full"][0].mean()
    hi = {m: ns["mse"][m][-1].mean() for m in study.METHODS}
    assert hi["full"] < hi["nnls"] < hi["pinv"]


def test_run_study_quick_writes_files(tmp_path, provider):
    calls = []
    r = run_study(tmp_path, provider=provider, seeds=2, quick=True, progress=calls.append)
    assert sum(calls) == study_work(quick=True) == len(calls)
    names = {p.name for p in tmp_path.iterdir()}
    for stem in ("fig5_reconstruction", "fig5c_mse_vs_noise", "regularization_sweep"):
        assert f"{stem}.png" in names and f"{stem}.csv" in names
    assert {
        "fig6_mse_vs_params.png",
        "fig6a_mse_vs_sigma_s.csv",
        "fig6b_mse_vs_sigma_a.csv",
        "fig6c_mse_vs_g.csv",
        "study.json",
    } <= names
    saved = json.loads((tmp_path / "study.json").read_text())
    assert saved.pop("planeray_mark").startswith("planeray:record:") and saved == r
    assert r["files"][-1] == str(tmp_path / "study.json") and len(r["files"]) == 11
    report = study_report(r)
    first = {m: r["noise_sweep"][m]["mean"][0] for m in study.METHODS}  # eta 0.005
    assert report[4].split() == ["0.005", *(f"{v:.1e}" for v in first.values()), min(first, key=first.get)]
    assert not any(n.startswith(".") for n in names)  # no temporaries left
    mark, header, *rows = (tmp_path / "fig5c_mse_vs_noise.csv").read_text().splitlines()
    assert mark.startswith("# planeray_mark: planeray:table:") and header == "noise,seed,pinv,nnls,full"
    assert len(rows) == 3 * 2
    assert set(r["example_mse"]) == set(study.METHODS)
    assert np.array(r["regularization"]["mse"]).shape == (3, 3)


def test_custom_provider_and_errors(setup):
    flat = lambda s, a, g: np.exp(-np.abs(setup.offsets) / (5.0 * s))  # noqa: E731
    ps = study.parameter_sweep(setup, flat, "sigma_s", [1.0, 2.0], seeds=2)
    assert ps["mse"]["full"].shape == (2, 2)
    with pytest.raises(ValueError):
        study.parameter_sweep(setup, flat, "n", [1.0])
    with pytest.raises(ValueError):
        run_study("/nonexistent-never", provider="bogus")


def test_back_scattering_degrades_the_full_method_with_monte_carlo_profiles(setup):
    # Fig. 6c with real HG profiles (the dipole only sees sigma_s (1 - g)): the full
    # method's MSE grows as g turns negative and its lead over pinv shrinks.
    # Full-study measurement (`planeray study demux`, 2e5 photons, 5 seeds): full 1.2e-4 at
    # g = 0.9, 6.5e-4 at g = -0.45, 1.5e-3 at g = -0.9; pinv/full 8.6x -> 1.6x.
    mc = study.mc_provider(setup.offsets, n_photons=20_000, cache=False)
    ps = study.parameter_sweep(setup, mc, "g", [-0.6, 0.9], seeds=3)
    full = ps["mse"]["full"].mean(axis=1)
    pinv = ps["mse"]["pinv"].mean(axis=1)
    assert full[0] > 3 * full[1]
    assert pinv[1] / full[1] > 2 * (pinv[0] / full[0])


def test_regularization_heatmap_labels_are_readable_on_their_cells():
    """Each cell's number contrasts with the cell (WCAG ratio >= 4.5), and no marker sits on a number."""
    from matplotlib.colors import to_rgb

    from planeray.figures.study import plot_regularization

    a = b = np.array([1e-3, 1e-2, 1e-1])
    mse = np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0], [7.0, 8.0, 9.5]]) * 1e-4  # dark to bright (viridis)
    fig = plot_regularization({"alphas": a, "betas": b, "mse": mse, "bias2": mse / 2}, noise=0.05)

    def luminance(rgb):
        c = np.asarray(rgb, float)
        c = np.where(c <= 0.03928, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
        return 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]

    for ax in fig.axes[:2]:  # the two heatmaps (then their colour bars)
        im = ax.images[0]
        texts = [t for t in ax.texts if t.get_text()]
        assert len(texts) == 9
        for t in texts:
            q, p = (int(round(v)) for v in t.get_position())
            cell = im.cmap(im.norm(im.get_array()[p, q]))[:3]
            hi, lo = sorted((luminance(to_rgb(t.get_color())), luminance(cell)), reverse=True)
            assert (hi + 0.05) / (lo + 0.05) >= 4.5, (t.get_text(), t.get_color(), cell)
        for line in ax.lines:  # the lowest-MSE marker: in a corner of its cell, off the number at its centre
            x, y = line.get_xdata()[0], line.get_ydata()[0]
            assert abs(x - round(x)) > 0.2 and abs(y - round(y)) > 0.2

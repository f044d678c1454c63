"""Fig. 15: the pulse from a video -- (a) signal and spectrum with the detected rate, (b) the four kinds of light."""

from __future__ import annotations

import numpy as np

from ._common import figure_for, finish, new_figure

__all__ = ["pulse_signal_figure", "pulse_methods_figure", "rate_accuracy_figure"]

#: Colours of the four methods (and the unmagnified indirect signal).
METHOD_COLORS = {
    "regular": "tab:gray",
    "direct": "tab:blue",
    "global": "tab:green",
    "indirect": "tab:red",
    "indirect (no magnification)": "tab:orange",
}


def _relative(signal):
    """Zero-mean signal in percent of its mean (the pulsatile fraction)."""
    x = np.asarray(signal, np.float64)
    m = x.mean()
    return 100.0 * (x - m) / (abs(m) if m != 0 else 1.0)


def pulse_signal_figure(time_s, signal, estimate, *, raw=None, truth_bpm=None, title=None, out=None):
    """Fig. 15a: the (magnified) signal over time and its spectrum with the detected rate.

    Parameters
    ----------
    time_s : array_like (T,)
    signal : array_like (T,)
        The magnified signal of the chosen pixel or region.
    estimate : PulseEstimate
        From :func:`planeray.pulse.rate.estimate_heart_rate` on ``signal``.
    raw : array_like (T,), optional
        The same pixel before magnification, drawn underneath.
    truth_bpm : float, optional
        A reference rate (a smartwatch's, the simulation's), marked on the spectrum.

    Returns
    -------
    matplotlib.figure.Figure
        Two Axes: signal (percent of its mean) and power spectrum (bpm).

    See Also
    --------
    pulse_methods_figure : Fig. 15b.

    References
    ----------
    .. [1] H. Kubo, S. Jayasuriya, T. Iwaguchi, T. Funatomi, Y. Mukaigawa, S. G. Narasimhan,
       "Programmable Non-Epipolar Indirect Light Transport: Capture and Analysis",
       IEEE TVCG 27(4), 2019, doi:10.1109/TVCG.2019.2946812, Fig. 15a.

    Examples
    --------
    >>> import numpy as np
    >>> from planeray.pulse.rate import estimate_heart_rate
    >>> t = np.arange(600) / 30
    >>> signal = 1 + 0.01 * np.sin(2 * np.pi * 1.2 * t)  # 72 bpm
    >>> fig = pulse_signal_figure(t, signal, estimate_heart_rate(signal, 30.0), truth_bpm=72.0)
    >>> len(fig.axes)
    2
    """
    fig = new_figure((11, 4.2))
    ax_t, ax_f = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1.6, 1]})
    t = np.asarray(time_s)
    if raw is not None:
        ax_t.plot(t, _relative(raw), color="0.6", lw=1, label="before magnification")
    ax_t.plot(t, _relative(signal), color="tab:red", lw=1.3, label="magnified")
    ax_t.set_xlabel("time (s)")
    ax_t.set_ylabel("change (% of mean)")
    ax_t.legend(loc="upper right", fontsize=8)
    ax_t.set_xlim(t[0], t[-1])
    f_bpm = 60.0 * np.asarray(estimate.freqs_hz)
    keep = f_bpm <= 240
    p = np.asarray(estimate.power)[keep]
    ax_f.plot(f_bpm[keep], p / max(p.max(), 1e-30), color="k", lw=1.2)
    lo, hi = estimate.settings.get("band_hz", (0.7, 2.0))
    ax_f.axvspan(60 * lo, 60 * hi, color="tab:blue", alpha=0.08, label="rate band")
    if estimate.rate_bpm is not None:
        ax_f.axvline(estimate.rate_bpm, color="tab:red", ls="--", label=f"detected {estimate.rate_bpm:.2f} bpm")
    else:
        ax_f.axvline(estimate.peak_bpm, color="0.5", ls=":", label=f"no pulse (peak {estimate.peak_bpm:.1f} bpm)")
    if truth_bpm is not None:
        ax_f.axvline(truth_bpm, color="tab:green", ls=":", lw=2, label=f"reference {truth_bpm:.2f} bpm")
    ax_f.set_xlabel("frequency (bpm)")
    ax_f.set_ylabel("power (normalized)")
    ax_f.set_xlim(0, 240)
    ax_f.legend(loc="upper right", fontsize=8)
    ax_f.set_title(f"SNR {estimate.snr_db:.1f} dB, peak SNR {estimate.band_snr_db:.1f} dB", fontsize=9)
    fig.suptitle(title or "Pulse from the video (Fig. 15a)", fontsize=11)
    fig.tight_layout()
    return finish(fig, out, dpi=110)


def pulse_methods_figure(time_s, signals: dict, *, snr_db: dict | None = None, title=None, out=None):
    """Fig. 15b: one pixel's (or region's) signal in regular, direct, global and indirect light.

    Parameters
    ----------
    time_s : array_like (T,)
    signals : dict of str to array_like (T,)
        Label -> signal, drawn top to bottom in percent of its own mean on one common scale
        (e.g. the four magnified methods and ``"indirect (no magnification)"``).
    snr_db : dict, optional
        Label -> pulse SNR, printed beside each trace.

    Returns
    -------
    matplotlib.figure.Figure
        One Axes per signal, sharing both axes.

    See Also
    --------
    pulse_signal_figure : Fig. 15a.

    References
    ----------
    .. [1] H. Kubo, S. Jayasuriya, T. Iwaguchi, T. Funatomi, Y. Mukaigawa, S. G. Narasimhan,
       "Programmable Non-Epipolar Indirect Light Transport: Capture and Analysis",
       IEEE TVCG 27(4), 2019, doi:10.1109/TVCG.2019.2946812, Fig. 15b.

    Examples
    --------
    >>> import numpy as np
    >>> from planeray.pulse.rate import estimate_heart_rate
    >>> t = np.arange(600) / 30
    >>> signal = 1 + 0.01 * np.sin(2 * np.pi * 1.2 * t)  # 72 bpm
    >>> fig = pulse_methods_figure(t, {"regular": 1 + 0.2 * (signal - 1), "indirect": signal})
    >>> len(fig.axes)
    2
    """
    labels = list(signals)
    fig = new_figure((9, 1.5 * len(labels) + 0.8))
    axes = np.atleast_1d(fig.subplots(len(labels), 1, sharex=True, sharey=True))
    t = np.asarray(time_s)
    rel = {k: _relative(v) for k, v in signals.items()}
    lim = max(float(np.percentile(np.abs(v), 99.5)) for v in rel.values()) * 1.15 or 1.0
    for ax, k in zip(axes, labels):
        ax.plot(t, rel[k], color=METHOD_COLORS.get(k, "k"), lw=1)
        text = k if snr_db is None or k not in snr_db else f"{k}: SNR {snr_db[k]:.1f} dB"
        ax.text(0.01, 0.92, text, transform=ax.transAxes, va="top", fontsize=9, backgroundcolor="white")
        ax.set_ylim(-lim, lim)
        ax.set_xlim(t[0], t[-1])
    axes[len(labels) // 2].set_ylabel("change (% of mean)")
    axes[-1].set_xlabel("time (s)")
    fig.suptitle(title or "Amplitude of the pulse in each kind of light (Fig. 15b)", fontsize=11)
    fig.tight_layout()
    return finish(fig, out, dpi=110)


def rate_accuracy_figure(true_bpm, estimated_bpm, *, labels=None, ax=None, out=None):
    """Estimated against true heart rate (one series per estimator), with the +-2 bpm band.

    ``estimated_bpm``: dict label -> array (same length as ``true_bpm``; NaN for no pulse detected).

    Parameters
    ----------
    true_bpm : array_like
        The true mean heart rates, beats per minute.
    estimated_bpm : dict of str to array_like
        Estimator -> its rates (NaN: no pulse detected).
    labels : optional
        Unused (kept for callers).
    ax : matplotlib.axes.Axes, optional
        Draw into it.
    out : str or path, optional
        Also save as PNG.

    Returns
    -------
    matplotlib.figure.Figure

    See Also
    --------
    pulse_signal_figure : one video's pulse.

    Examples
    --------
    >>> fig = rate_accuracy_figure([60, 72, 90], {"indirect": [60.5, 71.8, 90.2]})
    >>> fig.axes[0].get_xlabel()
    'true mean heart rate (bpm)'
    """
    fig, ax, own = figure_for(ax, (5.2, 4.6))
    t = np.asarray(true_bpm, float)
    lo, hi = t.min() - 5, t.max() + 5
    ax.fill_between([lo, hi], [lo - 2, hi - 2], [lo + 2, hi + 2], color="0.85", label="$\\pm$2 bpm")
    ax.plot([lo, hi], [lo, hi], color="0.5", lw=1)
    for i, (k, v) in enumerate(estimated_bpm.items()):
        ax.plot(t, np.asarray(v, float), "o^sd"[i % 4], ms=4, mfc="none", label=k)
    ax.set_xlim(lo, hi)
    ax.set_ylim(lo, hi)
    ax.set_xlabel("true mean heart rate (bpm)")
    ax.set_ylabel("estimated (bpm)")
    ax.legend(fontsize=8, loc="upper left")
    if own:
        fig.tight_layout()
    return finish(fig, out, dpi=110)

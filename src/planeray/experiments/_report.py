"""Numbers behind a report's verdicts: the mean of repeated measurements with its interval."""

from __future__ import annotations

import numpy as np

__all__ = ["mean_interval"]


def mean_interval(values, level: float = 0.95) -> tuple[float, float | None, float | None]:
    """The mean of repeated measurements and its Student-t confidence interval at ``level``.

    Parameters
    ----------
    values : sequence of float
        One number per repetition (a noise seed, a video); None and non-finite values are left out.
    level : float
        Confidence level of the interval (0.95: 95 %).

    Returns
    -------
    (mean, low, high) : tuple
        ``low`` and ``high`` are None with fewer than two values.

    Examples
    --------
    >>> m, lo, hi = mean_interval([1.0, 2.0, 3.0])
    >>> m, round(lo, 3), round(hi, 3)  # 2 -/+ t(0.975, 2) * 1 / sqrt(3)
    (2.0, -0.484, 4.484)
    """
    from scipy import stats

    x = np.array([v for v in values if v is not None], dtype=float)
    x = x[np.isfinite(x)]
    if x.size == 0:
        return float("nan"), None, None
    mean = float(x.mean())
    if x.size < 2:
        return mean, None, None
    half = float(stats.t.ppf(0.5 + level / 2, x.size - 1) * x.std(ddof=1) / np.sqrt(x.size))
    return mean, mean - half, mean + half

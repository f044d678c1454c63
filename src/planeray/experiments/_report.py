"""What the experiments share when they write their numbers."""

from __future__ import annotations

import numpy as np

__all__ = ["jsonable"]


def jsonable(x):
    """``x`` with NumPy scalars and arrays as plain Python, non-finite floats as ``None`` (JSON null)."""
    if isinstance(x, dict):
        return {str(k): jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [jsonable(v) for v in x]
    if isinstance(x, (np.floating, float)):
        return None if not np.isfinite(x) else float(x)
    if isinstance(x, (np.integer, np.bool_)):
        return x.item()
    if isinstance(x, np.ndarray):
        return jsonable(x.tolist())
    return x

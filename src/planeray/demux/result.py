"""What a solver returns for a batch of pixels."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["SolveResult"]


@dataclass
class SolveResult:
    """Solution of a batch of pixels.

    Attributes
    ----------
    X : ndarray (P, V) float64
        Transport over the row group's valid offsets.
    iterations : ndarray (P,) int32
        Iterations each pixel took (solver-specific unit).
    converged : ndarray (P,) bool
        Whether the solver's own convergence test passed for the pixel.
    """

    X: np.ndarray
    iterations: np.ndarray
    converged: np.ndarray

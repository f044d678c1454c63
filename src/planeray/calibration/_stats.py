"""Robust statistics shared by the calibrations."""

#: Median absolute deviation -> standard deviation of a normal distribution (1 / Phi^-1(3/4)).
MAD_TO_SIGMA = 1.482602218505602

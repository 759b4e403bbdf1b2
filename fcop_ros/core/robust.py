"""Robust-statistics constants shared by the estimator's stages."""

# Median absolute deviation to standard deviation for Gaussian data (1 / Phi^-1(3/4)).
MAD_TO_SIGMA = 1.4826

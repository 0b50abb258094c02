"""Exact draws of a normal population's mean and spread, given its members.

The one-material model (:mod:`bayesgloss.sampling.material`) has two
populations of this kind: the facets' log albedos about the object's m
(spread tau), and, where the exposure is unknown and day-level
(``IlluminationPriors.day_exposure``), the frames' log exposures about the
day's mean mu_e (spread sd_e). Each has a normal prior on its mean and a
log-uniform prior on its spread over a bounded range, so both conditionals
are standard: the mean normal given the spread, the spread's inverse square
a gamma variable truncated to the range given the mean (Gelman et al.,
*Bayesian Data Analysis*, 3rd ed., sec. 3.3, with the prior's truncation).
"""

from __future__ import annotations

import numpy as np
from scipy import special

__all__ = ["draw_mean", "draw_log_spread"]


def draw_mean(members, axis: int, log_spread, prior_mean: float, prior_sd: float, rng):
    """The population's mean from its normal conditional given the members
    (along ``axis``) and the spread: precision n / sd^2 + 1 / prior_sd^2.

    Parameters
    ----------
    members : ndarray
        The members' values (log albedos, log exposures).
    axis : int
        The members' axis.
    log_spread : ndarray
        log sd, shaped as ``members`` without ``axis``.
    prior_mean, prior_sd : float
        The mean's normal prior.
    rng : numpy.random.Generator
    """
    n = members.shape[axis]
    var = np.exp(log_spread) ** 2
    prec = n / var + 1 / prior_sd**2
    mean = (members.sum(axis) / var + prior_mean / prior_sd**2) / prec
    return mean + rng.standard_normal(mean.shape) / np.sqrt(prec)


def draw_log_spread(ss, n: int, rng, bounds) -> np.ndarray:
    """log sd given the members' sum of squares ``ss`` about the mean: sd^-2 ~
    Gamma(n / 2, rate ss / 2) truncated to ``bounds`` (log sd uniform on them),
    drawn by its inverse CDF."""
    lo, hi = bounds
    k = 0.5 * n
    rate = np.maximum(0.5 * ss, 1e-300)
    x_lo, x_hi = np.exp(-2 * hi), np.exp(-2 * lo)  # sd^-2 between
    c_lo, c_hi = special.gammainc(k, rate * x_lo), special.gammainc(k, rate * x_hi)
    u = c_lo + (c_hi - c_lo) * rng.random(ss.shape)
    with np.errstate(invalid="ignore", divide="ignore"):
        x = special.gammaincinv(k, u) / rate
        log_sd = -0.5 * np.log(x)
    # the truncation's mass underflows when the members are far tighter (or
    # wider) than the prior's range allows: sd at the bound nearest its mode
    mode = 0.5 * np.log(np.maximum(ss, 1e-300) / max(n, 1))
    edge = np.where(mode < lo, lo, hi)
    bad = ~np.isfinite(log_sd) | (c_hi - c_lo <= 0)
    return np.clip(np.where(bad, edge, log_sd), lo, hi)

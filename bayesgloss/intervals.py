"""Posterior intervals: the 90 % highest-density interval bayesgloss reports.

The gloss factor gamma lives on [0, 1], and a matt or a mirror material puts
its true value on an edge. An equal-tailed interval (5 and 95 % quantiles)
can never hold an edge: for a matt object whose posterior piles up at 0 it
claims, with 95 % probability, a gamma above some small positive number.
The highest-density interval (the shortest interval holding the given
posterior mass; Hyndman 1996, "Computing and graphing highest density
regions", The American Statistician 50, and ArviZ's ``hdi``) is the interval
of highest posterior density, so it reaches the edge where the density is
highest there, and it equals the equal-tailed one for a symmetric posterior.
Either is a valid 90 % credible interval, so both are calibrated when the
posterior is; bayesgloss reports the highest-density one (``hdi90``) as *the*
90 % interval (summary, command line, report, flags, validation scores) and
keeps the quantiles ``q05``, ``q95`` beside it.

A leaf module: numpy only.
"""

from __future__ import annotations

import numpy as np

__all__ = ["INTERVAL_PROB", "highest_density_interval", "posterior_quantiles"]

#: Posterior mass of the reported interval.
INTERVAL_PROB = 0.9


def highest_density_interval(draws, prob: float = INTERVAL_PROB, axis: int = 0) -> np.ndarray:
    """The shortest interval holding ``prob`` of the draws, along ``axis``.

    Of the n sorted draws x_(1) <= ... <= x_(n), the interval
    [x_(i), x_(i + k)], k = floor(prob n), with the smallest width (the
    first such i where several tie): k + 1 >= prob n consecutive draws. This
    is the estimator of ArviZ's ``hdi`` for one mode.

    Parameters
    ----------
    draws : array_like
        Posterior draws; NaN draws are not allowed.
    prob : float
        Posterior mass, in (0, 1).
    axis : int
        The axis of the draws.

    Returns
    -------
    ndarray (2, ...)
        Lower and upper bounds, over the other axes.
    """
    if not 0.0 < prob < 1.0:
        raise ValueError(f"prob must be in (0, 1), got {prob}")
    x = np.sort(np.moveaxis(np.asarray(draws, dtype=float), axis, 0), axis=0)
    n = len(x)
    if n == 0:
        raise ValueError("no draws")
    k = min(n - 1, int(np.floor(prob * n)))
    width = x[k:] - x[: n - k]  # (n - k, ...)
    i = np.argmin(width, axis=0)
    lo = np.take_along_axis(x, i[None], axis=0)[0]
    hi = np.take_along_axis(x, (i + k)[None], axis=0)[0]
    return np.stack([lo, hi])


def posterior_quantiles(x) -> dict:
    """Median, 5 and 95 % quantiles, and the 90 % highest-density interval
    (``hdi90``, the interval bayesgloss reports) of draws ``x`` (flattened)."""
    x = np.asarray(x, float).ravel()
    q = np.quantile(x, [0.05, 0.5, 0.95])
    lo, hi = highest_density_interval(x)
    return {
        "median": float(q[1]),
        "q05": float(q[0]),
        "q95": float(q[2]),
        "hdi90": [float(lo), float(hi)],
    }

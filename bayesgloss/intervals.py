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

__all__ = [
    "GAMMA_BOUNDS",
    "INTERVAL_PROB",
    "highest_density_interval",
    "posterior_quantiles",
    "reported_interval",
    "reported_width",
]

#: The support of the gloss factor gamma.
GAMMA_BOUNDS = (0.0, 1.0)

#: Posterior mass of the reported interval.
INTERVAL_PROB = 0.9


def highest_density_interval(
    draws, prob: float = INTERVAL_PROB, axis: int = 0, bounds=None
) -> np.ndarray:
    """The shortest interval holding ``prob`` of the draws, along ``axis``.

    Of the n sorted draws x_(1) <= ... <= x_(n), the interval
    [x_(i), x_(i + k)], k = floor(prob n), with the smallest width (the
    first such i where several tie): k + 1 >= prob n consecutive draws. This
    is the estimator of ArviZ's ``hdi`` for one mode.

    With the support's ``bounds`` given, a window that starts at the
    smallest draw is taken down to the lower bound (and one that ends at the
    largest up to the upper bound): the shortest window starts there only
    where the density is highest toward that edge, and then the density's
    own highest-density region reaches the edge, which the draws, never
    exactly on it, only approach (for gamma of a matt material the smallest
    of 2000 draws is ~1e-6, and an interval ending there would say gamma = 0
    is excluded).

    Parameters
    ----------
    draws : array_like
        Posterior draws; NaN draws are not allowed.
    prob : float
        Posterior mass, in (0, 1).
    axis : int
        The axis of the draws.
    bounds : (float, float), optional
        The support of the quantity (e.g. (0, 1) for gamma).

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
    if bounds is not None:
        lo = np.where(i == 0, bounds[0], lo)
        hi = np.where(i + k == n - 1, bounds[1], hi)
    return np.stack([lo, hi])


def posterior_quantiles(x, bounds=None) -> dict:
    """Median, 5 and 95 % quantiles, and the 90 % highest-density interval
    (``hdi90``, the interval bayesgloss reports) of draws ``x`` (flattened)
    of a quantity with support ``bounds`` (see :func:`highest_density_interval`)."""
    x = np.asarray(x, float).ravel()
    q = np.quantile(x, [0.05, 0.5, 0.95])
    lo, hi = highest_density_interval(x, bounds=bounds)
    return {
        "median": float(q[1]),
        "q05": float(q[0]),
        "q95": float(q[2]),
        "hdi90": [float(lo), float(hi)],
    }


def reported_interval(q: dict) -> tuple[float, float]:
    """(lower, upper) of the 90 % interval a summary entry of
    :func:`posterior_quantiles` reports: its ``hdi90``, or the quantiles
    ``q05``, ``q95`` in a summary written before it had one."""
    lo, hi = q.get("hdi90") or (q["q05"], q["q95"])
    return float(lo), float(hi)


def reported_width(q: dict) -> float:
    """Width of the 90 % interval a summary entry reports (:func:`reported_interval`)."""
    lo, hi = reported_interval(q)
    return hi - lo

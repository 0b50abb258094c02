"""The log of an interval of the regularised incomplete gamma function, stable in its tails.

The likelihood with the noise scale integrated out
(:func:`bayesgloss.likelihood.log_likelihood_sigma_marginal`) needs
log(P(k, x_hi) - P(k, x_lo)) for intervals that may lie far in either tail,
where P and Q = 1 - P (scipy's ``gammainc``/``gammaincc``) underflow or
cancel. :func:`log_gamma_interval` evaluates only the tails that matter
(:func:`tail_cuts`) and switches to the asymptotic tails of Abramowitz &
Stegun (6.5.29, 6.5.32) where they underflow. A leaf module: numpy and
scipy only.
"""

from __future__ import annotations

import numpy as np
from scipy import special

__all__ = ["TAIL_DROP", "log_gamma_interval", "tail_cuts"]


#: Incomplete-gamma tails below this are dropped from log(P(k, x_hi) - P(k, x_lo)):
#: the log likelihood then errs by at most twice this, far below the ~1e-6 of
#: its float32 residuals.
TAIL_DROP = 1e-10


def _log_upper_gamma(k, x):
    """log Q(k, x), the regularised upper incomplete gamma function, stable
    where it underflows (x >> k: Abramowitz & Stegun 6.5.32, two terms)."""
    with np.errstate(divide="ignore"):
        out = np.log(special.gammaincc(k, x))
    tiny = ~(out > -575.0)  # Q < 1e-250
    if np.any(tiny):
        kk, xx = k[tiny], x[tiny]
        out[tiny] = (kk - 1.0) * np.log(xx) - xx - special.gammaln(kk) + np.log1p((kk - 1.0) / xx)
    return out


def _log_lower_gamma(k, x):
    """log P(k, x), the regularised lower incomplete gamma function, stable
    where it underflows (x << k: Abramowitz & Stegun 6.5.29, two terms)."""
    with np.errstate(divide="ignore"):
        out = np.log(special.gammainc(k, x))
    tiny = ~(out > -575.0)
    if np.any(tiny):
        kk, xx = k[tiny], x[tiny]
        out[tiny] = kk * np.log(xx) - xx - special.gammaln(kk + 1.0) + np.log1p(xx / (kk + 1.0))
    return out


def log_gamma_interval(k, x_lo, x_hi, cuts=None):
    """log of int_{x_lo}^{x_hi} t^(k-1) e^-t dt / Gamma(k), elementwise, stable.

    = log(P(k, x_hi) - P(k, x_lo)) with P, Q = 1 - P the regularised
    incomplete gamma functions (scipy's ``gammainc``/``gammaincc``), where
    tails that change it by less than ``TAIL_DROP`` (1e-10) relative are
    dropped:

    - P(k, x_lo) is kept where x_lo is above the x at which P(k, x) = 1e-10
      (:func:`tail_cuts`), Q(k, x_hi) where x_hi is below the x at which
      Q(k, x) = 1e-10; otherwise the interval holds the mode side's mass,
      P(k, k) > 1/2 or Q(k, k) > 0.3 (k >= 1/2), and the error is < 4e-10;
    - an interval wholly above k keeps Q(k, x_hi) unless Q(k, x_hi) /
      Q(k, x_lo) <= (x_hi / x_lo)^(k - 1) e^-(x_hi - x_lo) (k >= 1; without
      the power for k < 1) is below 1e-10; one wholly below k keeps P(k,
      x_lo) unless P(k, x_lo) / P(k, x_hi) <= (x_lo / x_hi)^k e^(x_hi - x_lo)
      is (bounds from substituting t + x_hi - x_lo, and t x_lo / x_hi, into
      the integrals).

    So only one side is evaluated where the interval cuts one tail (sigma
    near one bound of its prior), and nothing where it cuts neither (the
    common case).

    Parameters
    ----------
    k : array_like (B, 1)
    x_lo, x_hi : ndarray (B, K)
    cuts : tuple of ndarray (B, 1), optional
        The tail cuts above for this k, when precomputed.
    """
    k = np.asarray(k, dtype=float)  # cuts on k's own shape, before broadcasting
    lo_cut, hi_cut = tail_cuts(k) if cuts is None else cuts
    cut_lo = x_lo > lo_cut  # the interval cuts the lower tail off
    cut_hi = x_hi < hi_cut  # ... the upper tail
    out = np.zeros(x_lo.shape)
    # the few entries with a tail to evaluate (an interval wholly on one side of
    # k is among them: x_lo > k > lo_cut or x_hi < k < hi_cut)
    at = np.flatnonzero(cut_lo | cut_hi)
    if not at.size:
        return out
    kk = np.broadcast_to(k, x_lo.shape)[np.unravel_index(at, x_lo.shape)]
    lo, hi = x_lo.ravel()[at], x_hi.ravel()[at]
    c_lo, c_hi = cut_lo.ravel()[at], cut_hi.ravel()[at]
    log_drop = np.log(TAIL_DROP)
    with np.errstate(divide="ignore", invalid="ignore"):
        above, below = lo > kk, hi < kk
        c_hi |= above & (np.maximum(kk - 1.0, 0.0) * np.log(hi / lo) - (hi - lo) > log_drop)
        c_lo |= below & (kk * np.log(lo / hi) + (hi - lo) > log_drop)
    part = np.zeros(at.size)
    one = c_lo & ~c_hi
    if one.any():
        part[one] = _log_upper_gamma(kk[one], lo[one])  # log Q(k, x_lo)
    one = c_hi & ~c_lo
    if one.any():
        part[one] = _log_lower_gamma(kk[one], hi[one])  # log P(k, x_hi)
    both = c_lo & c_hi
    if both.any():  # difference the tails on the interval's side of the mode
        up, down = both & above, both & ~above
        with np.errstate(divide="ignore", invalid="ignore"):
            if up.any():
                lq_lo, lq_hi = _log_upper_gamma(kk[up], lo[up]), _log_upper_gamma(kk[up], hi[up])
                part[up] = lq_lo + np.log1p(-np.exp(lq_hi - lq_lo))
            if down.any():
                lp_lo = _log_lower_gamma(kk[down], lo[down])
                lp_hi = _log_lower_gamma(kk[down], hi[down])
                part[down] = lp_hi + np.log1p(-np.exp(lp_lo - lp_hi))
    out.ravel()[at] = part
    return out


def tail_cuts(k):
    """(x_lo, x_hi) beyond which the lower and upper tails of the regularised
    incomplete gamma function of order k are below ``TAIL_DROP``: P(k, x_lo)
    = Q(k, x_hi) = 1e-10 (scipy's inverses; NaN for k = 0, which cuts nothing)."""
    with np.errstate(invalid="ignore"):
        return special.gammaincinv(k, TAIL_DROP), special.gammainccinv(k, TAIL_DROP)

"""Convergence diagnostics and the one rule that says a chain has converged.

Every sampler of bayesgloss (the facet sampler of :mod:`bayesgloss.sampling`,
the model fits of :mod:`bayesgloss.compare`) and every summary
(:mod:`bayesgloss.estimate`) decides convergence here, by one rule:

1. the production run is at least ``min_tau_multiple`` (50) integrated
   autocorrelation times of every sampled parameter (:func:`integrated_time`,
   emcee's estimator; :func:`long_enough`), and
2. the parameters the rule is applied to have rank-normalised R-hat below
   :data:`RHAT_MAX` (1.01) and bulk and tail effective sample sizes of at
   least :data:`ESS_MIN` (400) over the independent chains (Vehtari et al.
   2021, "Rank-normalization, folding, and localization", Bayesian Analysis
   16; ArviZ's thresholds; :func:`converged`, and :func:`diagnose` with
   the statistics beside it).

:func:`rank_diagnostics` computes ArviZ's R-hat and ESS arithmetic
vectorised over many parameters (tests compare it with ``arviz.rhat`` and
``arviz.ess`` to 1e-9). This module imports nothing of bayesgloss.
"""

from __future__ import annotations

import numpy as np
from scipy import special

__all__ = [
    "RHAT_MAX",
    "ESS_MIN",
    "integrated_time",
    "fast_length",
    "long_enough",
    "converged",
    "diagnose",
    "meets_rule",
    "rank_diagnostics",
    "gamma_convergence",
]

#: R-hat below this counts as converged (Vehtari et al. 2021, sec. 4.3).
RHAT_MAX = 1.01
#: Bulk and tail effective sample sizes of at least this count as converged.
ESS_MIN = 400.0


def integrated_time(chain, c: float = 5.0) -> np.ndarray:
    """Integrated autocorrelation time of ensemble chains (emcee's estimator).

    The normalised autocorrelation function is averaged over walkers
    (Goodman & Weare 2010, sec. 3) and summed up to Sokal's automatic window,
    the smallest M with M >= c tau(M). The average is taken over the
    walkers' power spectra, each normalised by its series' sum of squares
    (the autocovariance at lag 0), so that one inverse transform per
    parameter gives the walker-mean of the normalised autocorrelation
    functions exactly as emcee's per-walker ones would.

    Parameters
    ----------
    chain : array_like (N, B, W, P)
    c : float

    Returns
    -------
    ndarray (B, P)
        [steps]; NaN where a parameter does not move at all.
    """
    x = np.asarray(chain)
    if x.dtype != np.float32:  # float32 chains stay float32 (tau to ~1e-5)
        x = x.astype(float)
    x = np.moveaxis(x, 0, -1)  # (B, W, P, N)
    n = x.shape[-1]
    # the mean in float64: a float32 sum of values far from 0 (log s ~ 12 with
    # sd 4e-5) errs by more than their spread and would make tau enormous
    x = x - x.mean(axis=-1, keepdims=True, dtype=np.float64).astype(x.dtype)
    var = np.einsum("...i,...i->...", x, x)  # lag-0 autocovariance x N, (B, W, P)
    moving = var > 0  # walkers whose series varies
    f = np.fft.rfft(x, n=fast_length(2 * n), axis=-1)
    power = f.real**2 + f.imag**2
    with np.errstate(invalid="ignore", divide="ignore"):
        power *= np.where(moving, 1.0 / np.where(moving, var, 1.0), 0.0)[..., None]
        mean_power = power.sum(axis=1) / moving.sum(axis=1)[..., None]  # (B, P, F)
        rho = np.fft.irfft(mean_power, axis=-1)[..., :n]  # mean normalised acf, (B, P, N)
    taus = 2.0 * np.cumsum(rho, axis=-1) - 1.0
    m = np.arange(n)
    reached = m >= c * taus
    window = np.where(np.any(reached, axis=-1), np.argmax(reached, axis=-1), n - 1)
    return np.take_along_axis(taus, window[..., None], axis=-1)[..., 0]


def fast_length(n: int) -> int:
    """The smallest 2^a 3^b 5^c >= n (fast FFT sizes)."""
    best = 1 << (n - 1).bit_length()
    p5 = 1
    while p5 < best:
        p35 = p5
        while p35 < best:
            p = p35
            while p < n:
                p *= 2
            best = min(best, p)
            p35 *= 3
        p5 *= 5
    return best


def long_enough(n_steps, tau, multiple: float = 50.0) -> np.ndarray:
    """Whether a run of ``n_steps`` is at least ``multiple`` integrated
    autocorrelation times of every parameter (emcee's rule of thumb).

    Parameters
    ----------
    n_steps : int or array_like
        Production steps run (broadcast against the leading axes of ``tau``).
    tau : array_like (..., P)
        Integrated autocorrelation times [steps]; NaN (a parameter that never
        moved) counts as infinitely long.
    multiple : float

    Returns
    -------
    ndarray (...) of bool
    """
    t_max = np.nan_to_num(np.max(np.asarray(tau, dtype=float), axis=-1), nan=np.inf)
    return np.asarray(n_steps) >= multiple * t_max


def diagnose(draws, rhat_max: float = RHAT_MAX, ess_min: float = ESS_MIN):
    """The convergence rule for many parameters at once, with its statistics:
    rank-normalised R-hat < 1.01 and bulk and tail ESS >= 400 (Vehtari et al.
    2021, sec. 4.3, ArviZ's defaults).

    Parameters
    ----------
    draws : array_like (F, C, S)
        F parameters (e.g. one facet's gamma each), C chains of S draws.

    Returns
    -------
    rhat, ess_bulk, ess_tail : ndarray (F,)
        :func:`rank_diagnostics`; NaN where a draw is not finite or all
        draws are equal.
    converged : ndarray (F,) of bool
        Whether the rule holds (False where the statistics are NaN).
    """
    x = np.asarray(draws, dtype=float)
    ok = np.isfinite(x).all(axis=(1, 2)) & (np.ptp(x, axis=(1, 2)) > 0)
    stats = np.full((3, len(x)), np.nan)
    if ok.any():
        stats[:, ok] = rank_diagnostics(x[ok])
    rhat, ess_bulk, ess_tail = stats
    return rhat, ess_bulk, ess_tail, meets_rule(rhat, ess_bulk, ess_tail, rhat_max, ess_min)


def meets_rule(rhat, ess_bulk, ess_tail, rhat_max: float = RHAT_MAX, ess_min: float = ESS_MIN):
    """The convergence rule of :func:`diagnose` on statistics already
    computed: R-hat < ``rhat_max`` and bulk and tail ESS >= ``ess_min``
    (False where a statistic is NaN)."""
    with np.errstate(invalid="ignore"):
        return (
            (np.asarray(rhat) < rhat_max)
            & (np.asarray(ess_bulk) >= ess_min)
            & (np.asarray(ess_tail) >= ess_min)
        )


def converged(draws, rhat_max: float = RHAT_MAX, ess_min: float = ESS_MIN) -> np.ndarray:
    """Whether the rule of :func:`diagnose` holds, (F,) of bool, for draws (F, C, S)."""
    return diagnose(draws, rhat_max, ess_min)[3]


def rank_diagnostics(draws):
    """ArviZ's rank-normalised R-hat and bulk and tail ESS, for many
    parameters at once (Vehtari et al. 2021, "Rank-normalization, folding,
    and localization", Bayesian Analysis 16, eqs. 3-4 and sec. 4.3).

    The same arithmetic as ``arviz.rhat``, ``arviz.ess(method="bulk")`` and
    ``arviz.ess(method="tail")`` (arviz 0.23) on each (chain, draw) slice,
    vectorised over the leading axis (tests/test_sampling.py compares them
    to 1e-9): chains split in halves; ranks over all draws (ties averaged)
    mapped to normal scores with Blom's offset 3/8; R-hat the larger of the
    bulk and the folded (|x - median|) split R-hat; ESS with Geyer's initial
    positive then monotone sequence on the chain-averaged autocovariance;
    tail ESS the smaller of those of the indicators x <= q_0.05 and
    x <= q_0.95 (type-7 quantiles).

    Parameters
    ----------
    draws : array_like (F, C, S)
        F parameters, C chains of S draws (C >= 2, S >= 4, finite).

    Returns
    -------
    rhat, ess_bulk, ess_tail : ndarray (F,)
    """
    x = np.asarray(draws, dtype=float)
    half = x.shape[2] // 2
    split = np.concatenate([x[:, :, :half], x[:, :, x.shape[2] - half :]], axis=1)
    z = _normal_scores(split)
    folded = np.abs(split - np.median(split.reshape(len(x), -1), axis=1)[:, None, None])
    rhat = np.maximum(_split_rhat(z), _split_rhat(_normal_scores(folded)))
    ess_bulk = _geyer_ess(z)
    q = np.quantile(x.reshape(len(x), -1), [0.05, 0.95], axis=1)  # (2, F)
    ess_tail = np.minimum(
        _geyer_ess((split <= q[0][:, None, None]).astype(float)),
        _geyer_ess((split <= q[1][:, None, None]).astype(float)),
    )
    return rhat, ess_bulk, ess_tail


def _normal_scores(x):
    """Rank-normal scores over each (C, S) slice of x (F, C, S): ranks with
    ties averaged, mapped by Blom's (r - 3/8) / (N + 1/4) to normal quantiles."""
    f = len(x)
    a = x.reshape(f, -1)
    n = a.shape[1]
    order = np.argsort(a, axis=1, kind="stable")
    sa = np.take_along_axis(a, order, axis=1)
    pos = np.arange(n)
    starts = np.ones(a.shape, dtype=bool)
    starts[:, 1:] = sa[:, 1:] != sa[:, :-1]  # first of a run of ties
    ends = np.ones(a.shape, dtype=bool)
    ends[:, :-1] = starts[:, 1:]  # last of a run of ties
    first = np.maximum.accumulate(np.where(starts, pos, 0), axis=1)
    last = np.minimum.accumulate(np.where(ends, pos, n)[:, ::-1], axis=1)[:, ::-1]
    rank = np.empty(a.shape)
    np.put_along_axis(rank, order, 0.5 * (first + last) + 1.0, axis=1)
    return special.ndtri((rank - 0.375) / (n + 0.25)).reshape(x.shape)


def _split_rhat(z):
    """Gelman-Rubin R-hat of each (C, S) slice of z (F, C, S)."""
    s = z.shape[2]
    between = s * np.var(z.mean(axis=2), axis=1, ddof=1)
    within = np.var(z, axis=2, ddof=1).mean(axis=1)
    return np.sqrt((between / within + s - 1) / s)


def _geyer_ess(x):
    """Effective sample size of each (C, S) slice of x (F, C, S): Geyer's
    initial positive sequence of autocorrelation pairs, made monotone."""
    f, c, s = x.shape
    const = (x.max(axis=(1, 2)) - x.min(axis=(1, 2))) < np.finfo(float).resolution
    d = x - x.mean(axis=2, keepdims=True)
    spec = np.fft.rfft(d, n=fast_length(2 * s), axis=2)
    acov = np.fft.irfft(spec.real**2 + spec.imag**2, n=fast_length(2 * s), axis=2)[..., :s] / s
    mean_var = acov[:, :, 0].mean(axis=1) * s / (s - 1.0)
    var_plus = mean_var * (s - 1.0) / s + np.var(x.mean(axis=2), axis=1, ddof=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        rho = 1.0 - (mean_var[:, None] - acov.mean(axis=1)) / var_plus[:, None]  # (F, S)
    rho[:, 0] = 1.0
    # pairs P_k = rho_2k + rho_2k+1; the positive sequence runs to the first
    # k >= 1 with P_k <= 0 (K), or to the last pair computed (2k - 1 < S - 3)
    k_lim = max(0, (s - 3) // 2)
    n_pairs = k_lim + 1
    pad = np.zeros((f, 2 * n_pairs + 1))
    m = min(s, pad.shape[1])
    pad[:, :m] = rho[:, :m]
    pairs = pad[:, 0 : 2 * n_pairs : 2] + pad[:, 1 : 2 * n_pairs : 2]  # (F, K+1)
    stop = np.concatenate([pairs[:, 1:] <= 0, np.ones((f, 1), dtype=bool)], axis=1)
    first = np.minimum(np.argmax(stop, axis=1) + 1, k_lim)
    big_k = np.where(pairs[:, 0] > 0, first, 0)  # (F,)
    idx = np.arange(n_pairs)
    used = idx[None, :] < big_k[:, None]
    mono = np.minimum.accumulate(np.where(used, pairs, np.inf), axis=1)
    total = np.where(used, mono, 0.0).sum(axis=1)
    last_even = np.take_along_axis(pad, (2 * big_k)[:, None], axis=1)[:, 0]
    last_pair = np.take_along_axis(pairs, big_k[:, None], axis=1)[:, 0]
    last = np.where((last_pair >= 0) | (last_even > 0), last_even, 0.0)
    last = np.where(big_k == 0, 1.0, last)
    tau = -1.0 + 2.0 * total + last
    n = c * s
    tau = np.maximum(tau, 1.0 / np.log10(n))
    ess = n / tau
    bad = ~np.isfinite(var_plus) | np.isnan(rho[:, : 2 * n_pairs]).any(axis=1)
    ess = np.where(bad, np.nan, ess)
    return np.where(const, float(n), ess)


def gamma_convergence(idata, facet_runs=None) -> dict:
    """R-hat and bulk/tail ESS of gamma per facet, and whether each converged
    (the rule of :func:`diagnose`).

    ``facet_runs``: the per-facet sampler's run given the object's
    illumination (:func:`bayesgloss.sampling.facets_given_frames`, copies of
    every facet at several illumination draws). Then each copy is diagnosed
    on its own chains and a facet converged if every copy did (R-hat the
    worst copy's, ESS the copies' sum): across the pooled chains, which hold
    different illumination draws by design, R-hat measures the light's
    spread, not the sampler's (the demo once printed 0 of 28 facets
    converged for that reason alone).
    """
    gamma = np.moveaxis(idata.posterior["gamma"].values, -1, 0)  # (F, E, S)
    if facet_runs is not None and facet_runs.draws.shape[0] % gamma.shape[0] == 0:
        f = gamma.shape[0]
        rhat, ess_bulk, ess_tail, ok = (
            np.asarray(x).reshape(-1, f) for x in diagnose(facet_runs.draws[..., 0])
        )
        return {
            "rhat": rhat.max(0),
            "ess_bulk": ess_bulk.sum(0),
            "ess_tail": ess_tail.sum(0),
            "converged": ok.all(0),
        }
    rhat, ess_bulk, ess_tail, ok = diagnose(gamma)
    return {"rhat": rhat, "ess_bulk": ess_bulk, "ess_tail": ess_tail, "converged": ok}

"""The object's gloss from its facets' posteriors: partial and complete pooling.

- :func:`population_gloss` (partial pooling): facet gammas drawn from a Beta
  population of mean mu and concentration kappa, fitted by reweighting the
  facet posteriors, which were sampled under a uniform prior on gamma (Hogg,
  Myers & Bovy 2010, eq. 11). The object's gloss is mu.
- :func:`shared_gloss` (complete pooling): one material, every facet with
  the same gamma and n, their own scale and noise.

Both take each facet's draws and, where known, their effective sample size,
which sets how much structure a facet's kernel density may have: the clumps
of autocorrelated draws must not be read as information. Checked against a
brute-force integral in ``tests/test_pooling.py``.
"""

from __future__ import annotations

import functools

import numpy as np
from scipy import special

from . import likelihood as lk
from ._cache import cached_array

__all__ = ["population_gloss", "shared_gloss"]


def population_gloss(
    gamma_draws,
    *,
    ess=None,
    seed=0,
    n_mu: int = 299,
    n_kappa: int = 80,
    n_bins: int = 400,
    max_draws: int = 1000,
    n_out: int = 4000,
):
    """Hierarchical Beta population of facet gammas (module docstring).

    Facet f's gammas are drawn from Beta(mu kappa, (1 - mu) kappa); its data
    enter through its posterior of gamma under the uniform prior it was
    sampled with, so that (Hogg, Myers & Bovy 2010, eq. 11)

        p(mu, kappa | data) ~ p(mu, kappa) prod_f int Beta(g; mu kappa, (1 - mu) kappa) p_f(g) dg.

    Each facet posterior p_f is a Gaussian kernel density of its draws,
    reflected at 0 and 1, whose bandwidth follows Scott's rule with the
    draws' *effective* sample size (h = 1.06 sd ESS^(-1/5)): a density of
    autocorrelated draws then has no more bumps than its information
    supports. (The earlier estimator, a mean of the Beta density over 200
    draws, read the clumps of autocorrelated draws from 24 flat posteriors
    as a population: intervals as narrow as 0.42 where the answer is the
    prior's.) The integral is a sum over ``n_bins`` bins of the kernel
    density's mass times the Beta distribution's mass in each bin, exact for
    a density constant on the bins; so flat facet posteriors give exactly
    the prior's likelihood, 1. The bins, and the cells of mu, are finer near
    0 and 1 (:func:`_cell_edges`: the 400 bins about 0.004 wide in the
    middle and 1.5e-5 at the ends, the 299 cells of mu 0.005 and 3e-5),
    where the posteriors of matt and mirror-like facets are sharpest. The two
    population parameters are integrated on a grid (mu in those cells,
    under a uniform prior; log kappa uniform over [log 0.5, log 1e4]); draws
    are taken from the grid posterior with jitter inside each cell.

    Parameters
    ----------
    gamma_draws : array_like (F, S)
        Posterior draws of each facet's gamma under a uniform prior (at most
        ``max_draws`` per facet are used, evenly spaced) [-].
    ess : array_like (F,), optional
        Effective sample size of each facet's draws (default S: independent
        draws) [-].
    seed : int or Generator
    n_mu, n_kappa : int
        Cells of mu (finer toward 0 and 1) and nodes of log kappa.
    n_bins : int
        Bins of gamma on which each facet's density is integrated.

    Returns
    -------
    dict
        ``mu`` and ``kappa`` draws.
    """
    rng = np.random.default_rng(seed)
    g = np.clip(np.asarray(gamma_draws, dtype=float), 0.0, 1.0)
    n_f, n_s = g.shape
    n_eff = np.full(n_f, float(n_s)) if ess is None else np.asarray(ess, dtype=float)
    n_eff = np.clip(np.nan_to_num(n_eff, nan=2.0), 2.0, n_s)
    h = np.maximum(1.06 * np.std(g, axis=1) * n_eff ** (-0.2), 1e-6)
    if n_s > max_draws:
        g = g[:, np.linspace(0, n_s - 1, max_draws).round().astype(int)]
    edges = _cell_edges(n_bins)
    mass = np.empty((n_f, n_bins))
    for f in range(n_f):  # one facet at a time bounds memory (draws x bins)
        x = g[f]
        cdf = sum(
            special.ndtr((edges[:, None] - r[None, :]) / h[f]) for r in (x, -x, 2.0 - x)
        ).mean(axis=1)  # reflected kernels: the mass below each edge
        mass[f] = np.maximum(np.diff(cdf), 0.0)  # rounding can make far tails negative
    mass /= mass.sum(axis=1, keepdims=True)
    lkap, beta_mass = _beta_bin_masses(n_mu, n_kappa, n_bins)  # (n_mu n_kappa, n_bins)
    density = mass.T / np.diff(edges)[:, None]  # (n_bins, F)
    with np.errstate(divide="ignore"):
        logp = np.log(beta_mass @ density).sum(axis=1).reshape(n_mu, n_kappa)
    mu_edges = _cell_edges(n_mu)
    logp += np.log(np.diff(mu_edges))[:, None]  # uniform prior: each mu cell's width
    w = np.exp(logp - logp.max()).ravel()
    w /= w.sum()
    pick = rng.choice(len(w), size=n_out, p=w)
    i, j = np.unravel_index(pick, (n_mu, n_kappa))
    dk = lkap[1] - lkap[0]
    mu_s = mu_edges[i] + np.diff(mu_edges)[i] * rng.random(n_out)
    k_s = np.exp(lkap[j] + dk * (rng.random(n_out) - 0.5))
    return {"mu": mu_s, "kappa": k_s}


def _cell_edges(n: int) -> np.ndarray:
    """Edges of n cells of [0, 1], equal in u for gamma = sin^2(pi u / 2): about
    pi / 2n wide in the middle and (pi / 2n)^2 at 0 and 1, where the posteriors
    of matt and mirror-like facets pile up (n + 1,)."""
    return np.sin(0.5 * np.pi * np.linspace(0.0, 1.0, n + 1)) ** 2


@functools.lru_cache(maxsize=4)
def _beta_bin_masses(n_mu: int, n_kappa: int, n_bins: int):
    """log kappa grid (n_kappa,) and the mass of Beta(mu kappa, (1 - mu) kappa)
    in each of the ``n_bins`` cells of :func:`_cell_edges`, (n_mu n_kappa,
    n_bins), mu at the centres (in u) of ``n_mu`` such cells (the same for
    every object: kept in memory and in the user's cache folder,
    :mod:`bayesgloss._cache`, since it takes seconds to compute)."""
    lkap = np.linspace(np.log(0.5), np.log(1e4), n_kappa)
    name = f"beta_bin_masses-v1-{n_mu}-{n_kappa}-{n_bins}"
    shape = (n_mu * n_kappa, n_bins)
    masses = cached_array(name, shape, np.float32, lambda: _beta_masses(n_mu, lkap, n_bins))
    masses.flags.writeable = False
    lkap.flags.writeable = False
    return lkap, masses


def _beta_masses(n_mu: int, lkap: np.ndarray, n_bins: int) -> np.ndarray:
    """The table of :func:`_beta_bin_masses`, computed.

    Each bin's mass is a difference of the distribution function below the
    mean and of the survival function, I_(1-x)(b, a), above it, so that no
    tail is a difference of two numbers close to 1. The cells of mu and of
    gamma are symmetric about 1/2 (to 3e-16) and Beta(b, a) is Beta(a, b)
    mirrored, so the rows of mu > 1/2 are those of 1 - mu reversed: half the
    9.6 million regularised incomplete beta functions.
    """
    half = (n_mu + 1) // 2  # mu below 1/2, and 1/2 itself when n_mu is odd
    mu = np.sin(0.5 * np.pi * (np.arange(half) + 0.5) / n_mu) ** 2
    kap = np.exp(lkap)
    a = (mu[:, None] * kap[None, :]).ravel()[:, None]
    b = ((1 - mu)[:, None] * kap[None, :]).ravel()[:, None]
    edges = _cell_edges(n_bins)[None, :]
    upper = edges > np.repeat(mu, len(kap))[:, None]  # (rows, n_bins + 1)
    # below the mean I_x(a, b); above it 1 - I_x(a, b) = I_(1-x)(b, a)
    tail = special.betainc(
        np.where(upper, b, a), np.where(upper, a, b), np.where(upper, 1 - edges, edges)
    )
    cdf_lo = np.where(upper, np.nan, tail)  # P(gamma <= x) where x is below the mean
    sf_hi = np.where(upper, tail, np.nan)  # P(gamma > x) where x is above it
    mass = np.where(
        upper[:, 1:],
        np.where(upper[:, :-1], sf_hi[:, :-1] - sf_hi[:, 1:], 1.0 - cdf_lo[:, :-1] - sf_hi[:, 1:]),
        cdf_lo[:, 1:] - cdf_lo[:, :-1],
    )
    # float32 halves the table (n_mu n_kappa x n_bins); the log likelihood it
    # gives errs by ~1e-7 relative, far below the grid's cell-to-cell range
    low = np.maximum(mass, 0.0).astype(np.float32).reshape(half, len(kap), n_bins)
    high = low[: n_mu - half][::-1, :, ::-1]  # mu -> 1 - mu, gamma -> 1 - gamma
    return np.concatenate([low, high]).reshape(n_mu * len(kap), n_bins)


def shared_gloss(
    draws, priors: lk.Priors, *, n_gamma: int = 201, n_logn: int = 93, max_draws: int = 500
):
    """One material for all facets: posterior of (gamma, log n) on a grid.

    Each facet's marginal posterior of (gamma, log n) is estimated by a
    Gaussian kernel density of its draws (Scott's bandwidth, reflected at
    the bounds); the shared posterior is their product divided by the prior
    F - 1 times (the prior is uniform, so it is the plain product).

    Parameters
    ----------
    draws : array_like (F, S, 2)
        Draws of (gamma, log n) per facet.

    Returns
    -------
    dict
        ``gamma`` grid and its marginal density, ``log_n`` grid and its
        marginal, and the median and 5/95 % quantiles of gamma.
    """
    d = np.asarray(draws, dtype=float)
    if d.shape[1] > max_draws:  # evenly spaced draws bound the kernel sums' cost
        d = d[:, np.linspace(0, d.shape[1] - 1, max_draws).round().astype(int)]
    gx = np.linspace(0, 1, n_gamma)
    nx = np.linspace(*priors.log_n, n_logn)
    log_post = np.zeros((n_gamma, n_logn))
    for f in range(len(d)):
        x, y = d[f, :, 0], d[f, :, 1]
        n = len(x)
        hx = max(1.06 * np.std(x) * n ** (-1 / 6), 0.5 * (gx[1] - gx[0]))
        hy = max(1.06 * np.std(y) * n ** (-1 / 6), 0.5 * (nx[1] - nx[0]))
        # product kernels reflected at the bounds of gamma and of log n: the
        # sum over the 3 x 3 reflections factorises, draw by draw
        kx = sum(np.exp(-0.5 * ((gx[:, None] - rx) / hx) ** 2) for rx in (x, -x, 2 - x))
        ky = sum(
            np.exp(-0.5 * ((nx[:, None] - ry) / hy) ** 2)
            for ry in (y, 2 * priors.log_n[0] - y, 2 * priors.log_n[1] - y)
        )
        dens = kx @ ky.T
        log_post += np.log(dens + 1e-300)
    post = np.exp(log_post - log_post.max())
    pg = post.sum(axis=1)
    pg /= pg.sum()
    cdf = np.cumsum(pg)
    q = [float(np.interp(v, cdf, gx)) for v in (0.05, 0.5, 0.95)]
    pn = post.sum(axis=0)
    pn /= pn.sum()
    return {
        "gamma": gx,
        "gamma_density": pg,
        "log_n": nx,
        "log_n_density": pn,
        "q05": q[0],
        "median": q[1],
        "q95": q[2],
        "n_median": float(np.exp(np.interp(0.5, np.cumsum(pn), nx))),
    }

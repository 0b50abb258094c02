"""Evidence: Bayes factors and marginal likelihoods, and averaging by them.

- :func:`savage_dickey`: the Bayes factor of a nested model at the prior's
  boundary (gamma = 0, Lambert) from the posterior density there (Dickey
  1971; Wagenmakers et al. 2010), estimated by a local-linear
  (boundary-corrected) kernel density (Jones 1993, :func:`boundary_density`).
- :func:`thermodynamic_integration`: ln Z = int_0^1 E_beta[ln L] d beta over
  power posteriors prior x L^beta (Lartillot & Philippe 2006; Friel &
  Pettitt 2008), all rungs of all problems run as one batch with swaps
  between neighbouring rungs (parallel tempering), the quadrature corrected
  by the rung variances (Friel, Hurn & Wyse 2014, eq. 8), on the ladder of
  :func:`power_ladder`; the uncertainty combines the Monte Carlo error and
  a quadrature error.
- :func:`sky_posterior` and :func:`marginal_gamma`: posterior probabilities
  of candidate models (skies) from their evidence, and gamma averaged over
  them.

The model-specific side (priors, likelihoods, starts) is
:class:`bayesgloss.compare.ComparisonModel`'s; this module takes plain
callables and draws.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import special

from . import diagnostics
from .sampling.ensemble import BatchedEnsemble, fold_copies, unfold_copies

__all__ = [
    "boundary_density",
    "savage_dickey",
    "power_ladder",
    "EvidenceResult",
    "thermodynamic_integration",
    "sky_posterior",
    "marginal_gamma",
]


# --------------------------------------------------------------------------
# Savage-Dickey at the prior's boundary


def boundary_density(x, *, bandwidth=None, ess=None) -> tuple[float, float, float]:
    """Density at 0 of draws supported on [0, inf): local-linear kernel estimate.

    A plain (or reflected) kernel estimate at a boundary is biased by
    O(h f'(0)); the local-linear estimator (Jones 1993, eq. 2.3, Gaussian
    kernel on the half line) removes that term:

        f(0) = 1/(n h) sum_i (a2 - a1 u_i) K(u_i) / (a0 a2 - a1^2),  u_i = x_i / h,

    a_j = int_0^inf u^j K(u) du (a0 = 1/2, a1 = 1/sqrt(2 pi), a2 = 1/2).

    Parameters
    ----------
    x : array_like (n,)
        Draws, >= 0 [-].
    bandwidth : float, optional
        Default: Silverman's rule for the draws reflected about 0,
        h = 0.9 sqrt(mean x^2) n^(-1/5).
    ess : float, optional
        Effective sample size for the standard error (default n).

    Returns
    -------
    density, se, bandwidth : float
        The estimate may be slightly negative when the true density at 0 is
        about zero; the standard error is that of the mean of the kernel
        terms with ``ess`` draws.
    """
    x = np.asarray(x, dtype=float).ravel()
    if x.size < 10 or np.any(x < 0) or not np.all(np.isfinite(x)):
        raise ValueError(f"need >= 10 finite draws >= 0, got {x.size} (min {np.min(x)})")
    n = x.size
    h = 0.9 * np.sqrt(np.mean(x**2)) * n ** (-0.2) if bandwidth is None else float(bandwidth)
    h = max(h, 1e-12)
    a0, a1, a2 = 0.5, 1.0 / np.sqrt(2 * np.pi), 0.5
    u = x / h
    terms = (a2 - a1 * u) * np.exp(-0.5 * u * u) / np.sqrt(2 * np.pi) / (a0 * a2 - a1**2) / h
    n_eff = n if ess is None else max(float(ess), 2.0)
    return float(terms.mean()), float(terms.std(ddof=1) / np.sqrt(n_eff)), float(h)


def savage_dickey(gamma_draws, *, prior_density: float = 1.0, ess=None) -> dict:
    """Bayes factor of gamma = 0 (Lambert) against the full model.

    BF01 = p(gamma = 0 | y) / p(gamma = 0) (Dickey 1971; Wagenmakers et al.
    2010, eq. 6), valid because the full model's likelihood at gamma = 0
    does not depend on the lobe width and the other priors are shared.

    Parameters
    ----------
    gamma_draws : array_like
        Posterior draws of gamma in [0, 1] under the full model.
    prior_density : float
        Prior density of gamma at 0 (uniform prior: 1) [-].
    ess : float, optional
        Effective sample size of the draws.

    Returns
    -------
    dict
        ``log_bf01`` (ln BF of Lambert over the full model), its ``se``
        (delta method), the ``density`` at 0, and ``bound``: True when the
        density estimate is indistinguishable from 0 (below 2 se); then
        ``log_bf01`` is an upper bound, ln(2 se / prior density), and
        ``se`` is None.
    """
    dens, se, h = boundary_density(gamma_draws, ess=ess)
    bound = dens < 2 * se
    value = 2 * se if bound else dens
    return {
        "log_bf01": float(np.log(value / prior_density)),
        "se": None if bound else float(se / dens),
        "density": dens,
        "bandwidth": h,
        "bound": bool(bound),
    }


# --------------------------------------------------------------------------
# thermodynamic integration


def power_ladder(n_rungs: int = 64, beta_min: float = 1e-24) -> np.ndarray:
    """Temperature ladder: 0, then ``n_rungs - 1`` rungs geometric from
    ``beta_min`` to 1.

    With the wide priors of the facet model, E_beta[ln L] at small beta is
    of order -1 / beta down to beta ~ 1e-20 (prior draws of a tiny noise
    scale give ln L ~ -1e20), so the ladder must be uniform in ln beta
    rather than the power ladder beta = (k / K)^5 of Friel & Pettitt (2008,
    sec. 2.2), which leaves most of that range in its first interval.
    """
    if n_rungs < 4 or n_rungs % 2:
        raise ValueError(f"need an even number of rungs >= 4, got {n_rungs}")
    if not 0 < beta_min < 1:
        raise ValueError(f"beta_min must lie in (0, 1), got {beta_min}")
    return np.concatenate([[0.0], np.geomspace(beta_min, 1.0, n_rungs - 1)])


@dataclass
class EvidenceResult:
    """ln Z per problem by thermodynamic integration.

    Attributes
    ----------
    log_z, se : ndarray (B,)
        Estimate and total standard uncertainty, sqrt(mc^2 + quadrature^2).
    mc_se, quadrature_error : ndarray (B,)
    betas : ndarray (K,)
    mean_log_lik, var_log_lik, ess : ndarray (K, B)
        E_beta[ln L], Var_beta[ln L] and effective sample size per rung.
    swap_rate : ndarray (K - 1,)
    """

    log_z: np.ndarray
    se: np.ndarray
    mc_se: np.ndarray
    quadrature_error: np.ndarray
    betas: np.ndarray
    mean_log_lik: np.ndarray
    var_log_lik: np.ndarray
    ess: np.ndarray
    swap_rate: np.ndarray


def _hermite_quadrature(betas, mean, var):
    """int_beta1^1 E_beta[ln L] d beta, (B,), and the weights of the rung means (K, 1).

    In u = ln beta the integral is int E(u) e^u du. On each interval E is
    the cubic Hermite interpolant of the rung means and their slopes
    dE/du = beta Var_beta[ln L] (as dE/d beta = Var_beta[ln L]; the
    derivative correction of Friel, Hurn & Wyse 2014, eq. 8, here in ln
    beta), integrated against e^u exactly (8-point Gauss-Legendre of a
    smooth integrand). Exact where E is a cubic in ln beta: constant near
    beta = 1, and close to it where E ~ -c / beta at small beta.
    """
    u = np.log(betas)
    h = np.diff(u)[:, None]  # (K-1, 1)
    x, wx = np.polynomial.legendre.leggauss(8)
    t, wt = 0.5 * (x + 1.0), 0.5 * wx
    basis = np.stack(
        [2 * t**3 - 3 * t**2 + 1, t**3 - 2 * t**2 + t, -2 * t**3 + 3 * t**2, t**3 - t**2]
    )  # h00, h10, h01, h11 at the nodes
    ints = (basis * wt * np.exp(h * t[None, :])[:, None, :]).sum(-1)  # (K-1, 4)
    scale = h[:, 0] * np.exp(u[:-1])  # d beta = e^u du, u = u0 + h t
    c00, c10, c01, c11 = (scale[:, None] * ints).T
    slope = betas[:, None] * var  # dE/du
    h1 = h[:, 0][:, None]
    total = (
        c00[:, None] * mean[:-1]
        + c10[:, None] * h1 * slope[:-1]
        + c01[:, None] * mean[1:]
        + c11[:, None] * h1 * slope[1:]
    ).sum(0)
    w = np.zeros((len(betas), 1))
    w[:-1, 0] += c00
    w[1:, 0] += c01
    return total, w


def thermodynamic_integration(
    log_prior,
    log_likelihood,
    start,
    *,
    betas=None,
    burn: int = 500,
    steps: int = 1500,
    thin: int = 5,
    swap_every: int = 1,
    n_blocks: int = 10,
    seed=0,
) -> EvidenceResult:
    """Marginal likelihood ln Z of B problems by thermodynamic integration.

    ln Z = int_0^1 E_beta[ln L] d beta, E_beta over the power posterior
    p_beta proportional to prior x L^beta (Friel & Pettitt 2008, eq. 6). All
    K rungs of all B problems are K x B problems of one
    :class:`bayesgloss.sampling.BatchedEnsemble`; every ``swap_every`` steps
    the walkers of neighbouring rungs (walker w of rung k with walker w of rung
    k+1, even and odd pairs in turn) swap with probability
    min(1, exp((beta_k+1 - beta_k)(ln L_k - ln L_k+1))) (parallel tempering;
    each rung keeps its distribution).

    Quadrature (:func:`power_ladder`): from beta_1 on, E_beta[ln L] as a
    cubic Hermite interpolant in ln beta of the rung means and their slopes
    (the variance correction of Friel, Hurn & Wyse 2014, eq. 8, in ln beta),
    integrated exactly; below beta_1, beta_1 E_beta1[ln L] (the rung at
    beta = 0, the prior, is sampled only to carry walkers between modes and
    its size counts as quadrature error). Uncertainty: the Monte Carlo
    standard error
    by batch means (the integral from each of ``n_blocks`` contiguous blocks
    of the production run; swaps correlate neighbouring rungs, so rung-wise
    errors cannot simply be added) combined with a quadrature error, the
    Richardson estimate |I_K - I_K/2| / 15 of the fourth-order rule from
    the ladder with every other rung.

    Parameters
    ----------
    log_prior, log_likelihood : callable
        theta (B, K', P) -> (B, K'); normalised prior; any K'.
    start : array_like (B, W, P)
        Starting walkers (copied to every rung).
    betas : array_like (K,), optional
        Increasing, from 0 to 1, even length (default :func:`power_ladder`).
    burn, steps, thin : int
        Steps discarded, steps kept, and the steps between stored ln L.
    swap_every : int
        Steps between swap attempts (1: the most mixing; each attempt costs
        one more likelihood evaluation of every walker).
    n_blocks : int
        Blocks of the batch-means error.
    seed : int or numpy.random.Generator
    """
    rng = np.random.default_rng(seed)
    betas = power_ladder() if betas is None else np.asarray(betas, dtype=float)
    if betas[0] != 0 or betas[-1] != 1 or np.any(np.diff(betas) <= 0) or len(betas) % 2:
        raise ValueError("betas must increase from 0 to 1 with an even number of rungs")
    start = np.asarray(start, dtype=float)
    b, w, p = start.shape
    k = len(betas)
    beta_col = np.repeat(betas, b)  # problem index = rung * B + b

    def prior_of(th):
        return unfold_copies(log_prior(fold_copies(th, k)), k)

    def loglik_of(th):
        return unfold_copies(log_likelihood(fold_copies(th, k)), k)

    def log_prob(th):
        lp = prior_of(th)
        ok = np.isfinite(lp)
        if not np.any(ok):
            return lp
        ll = loglik_of(th)
        with np.errstate(invalid="ignore"):
            out = np.where(ok, lp + np.where(ok, beta_col[:, None] * ll, 0.0), -np.inf)
        return np.where(np.isnan(out), -np.inf, out)

    ens = BatchedEnsemble(log_prob, rng=rng)
    coords = np.tile(start, (k, 1, 1))
    coords += 1e-3 * rng.standard_normal(coords.shape) * np.std(start, axis=1, keepdims=True).max()
    log_p = log_prob(coords)
    bad = ~np.isfinite(log_p)
    coords[bad] = np.tile(start, (k, 1, 1))[bad]
    log_p = log_prob(coords)
    n_keep = steps // thin
    lls = np.empty((n_keep, k * b, w))
    swaps = np.zeros(k - 1)
    tries = np.zeros(k - 1)
    for t in range(burn + steps):
        ens.step(coords, log_p)
        store = t >= burn and (t - burn) % thin == 0 and (t - burn) // thin < n_keep
        if not store and (t + 1) % swap_every:
            continue
        ll = loglik_of(coords)  # (K*B, W)
        if store:
            lls[(t - burn) // thin] = ll
        if (t + 1) % swap_every:
            continue
        # parallel-tempering swaps between neighbouring rungs
        lpr = prior_of(coords)
        lo = np.arange((t // swap_every) % 2, k - 1, 2)
        i = (lo[:, None] * b + np.arange(b)).ravel()
        j = i + b
        d_beta = (beta_col[j] - beta_col[i])[:, None]
        with np.errstate(invalid="ignore", over="ignore"):
            acc = np.log(rng.random((len(i), w))) < d_beta * (ll[i] - ll[j])
        acc &= np.isfinite(ll[i]) & np.isfinite(ll[j])
        for arr in (coords, ll, lpr):
            ai, aj = arr[i], arr[j]
            mask = acc[..., None] if arr.ndim == 3 else acc
            arr[i], arr[j] = np.where(mask, aj, ai), np.where(mask, ai, aj)
        with np.errstate(invalid="ignore"):
            log_p[:] = np.where(np.isfinite(lpr), lpr + beta_col[:, None] * ll, -np.inf)
        if t >= burn:
            swaps[lo] += acc.reshape(len(lo), b * w).mean(1)
            tries[lo] += 1
    lls = lls.reshape(n_keep, k, b, w)
    mean = lls.mean(axis=(0, 3))  # (K, B)
    var = lls.var(axis=(0, 3), ddof=1)
    tau = thin * diagnostics.integrated_time(lls.reshape(n_keep, k * b, w, 1))[..., 0]
    tau = np.nan_to_num(tau.reshape(k, b), nan=1.0)
    ess = np.clip(n_keep * thin * w / np.maximum(tau, 1.0), 2.0, n_keep * w)
    # rung 0 (the prior) carries the walkers between modes; the integral
    # starts at beta_1: int_0^beta1 E d beta lies in [beta_1 E_0, beta_1 E_1]
    # (E_beta increases with beta); beta_1 E_1 is taken and its size counted
    # as quadrature error
    lo, rest = betas[1], slice(1, None)
    full, weights = _hermite_quadrature(betas[rest], mean[rest], var[rest])
    half, _ = _hermite_quadrature(betas[rest][::2], mean[rest][::2], var[rest][::2])
    head = lo * mean[1]
    full = full + head
    # batch means in time: swaps correlate neighbouring rungs, so the
    # integral's Monte Carlo error is taken from its value over time blocks
    blocks = np.array_split(np.arange(n_keep), n_blocks)
    per_block = np.stack([(weights * lls[blk][:, rest].mean(axis=(0, 3))).sum(0) for blk in blocks])
    mc_se = per_block.std(axis=0, ddof=1) / np.sqrt(n_blocks)
    quad = np.abs(full - head - half) / 15.0 + np.abs(head)
    return EvidenceResult(
        full,
        np.sqrt(mc_se**2 + quad**2),
        mc_se,
        quad,
        betas,
        mean,
        var,
        ess,
        swaps / np.maximum(tries, 1),
    )


# --------------------------------------------------------------------------
# sky type as an unknown


def sky_posterior(log_z: dict, *, log_z_se: dict | None = None) -> dict:
    """Posterior probabilities of candidate skies from their evidence.

    p(sky | y) = Z_sky / sum Z (equal prior over the candidates).

    Parameters
    ----------
    log_z : dict
        ``sky -> ln Z`` (scalar, or summed over independent facets).
    log_z_se : dict, optional
        Standard uncertainties of ln Z; the probabilities' spread under them
        is reported as ``prob_sd`` (delta method).

    Returns
    -------
    dict
        ``prob`` (sky -> probability), ``best``, ``log_bf_best_vs_next``.
    """
    skies = list(log_z)
    z = np.array([float(log_z[s]) for s in skies])
    prob = np.exp(z - special.logsumexp(z))
    out = {"prob": dict(zip(skies, prob.tolist(), strict=True))}
    order = np.argsort(-z)
    out["best"] = skies[order[0]]
    out["log_bf_best_vs_next"] = float(z[order[0]] - z[order[1]]) if len(z) > 1 else None
    if log_z_se is not None:
        se = np.array([float(log_z_se[s]) for s in skies])
        # d p_i / d lnZ_j = p_i (delta_ij - p_j)
        jac = np.diag(prob) - np.outer(prob, prob)
        out["prob_sd"] = dict(zip(skies, np.sqrt((jac**2) @ se**2).tolist(), strict=True))
    return out


def marginal_gamma(gamma_draws: dict, prob: dict, *, n: int = 4000, seed=0) -> np.ndarray:
    """Draws of gamma with the sky marginalised: the mixture of the per-sky
    posteriors weighted by the skies' posterior probabilities.

    Parameters
    ----------
    gamma_draws : dict
        ``sky -> draws`` (..., S): draws of gamma under each sky (the last
        axis the draws, leading axes e.g. facets).
    prob : dict
        ``sky -> probability``.
    """
    rng = np.random.default_rng(seed)
    skies = list(gamma_draws)
    p = np.array([prob[s] for s in skies], dtype=float)
    p /= p.sum()
    pick = rng.choice(len(skies), size=n, p=p)
    out = None
    for i, s in enumerate(skies):
        g = np.asarray(gamma_draws[s], dtype=float)
        if out is None:
            out = np.empty(g.shape[:-1] + (n,))
        sel = np.nonzero(pick == i)[0]
        if len(sel):
            out[..., sel] = g[..., rng.integers(0, g.shape[-1], len(sel))]
    return out

"""The object's gloss from its facets: the Beta population against brute force."""

import numpy as np
import pytest
from scipy import stats

from bayesgloss import pooling

# -- the hierarchical object model -------------------------------------------------


def _beta_population_cdf(alpha, beta, n_cells=3000):
    """Brute-force posterior CDF of the population mean mu, for facet posteriors
    Beta(alpha_f, beta_f) under uniform priors: the integral over gamma in
    closed form, int Beta(g; a, b) Beta(g; al, be) dg = B(a + al - 1, b + be - 1)
    / (B(a, b) B(al, be)), 400 nodes in log kappa over the model's prior range,
    and mu in cells finer toward 0 and 1 (sin^2 spacing), each weighted by its
    width (the uniform prior). Returns the cell edges and the CDF at them."""
    from scipy import special

    edges = np.sin(0.5 * np.pi * np.linspace(0.0, 1.0, n_cells + 1)) ** 2
    mu = np.sin(0.5 * np.pi * (np.arange(n_cells) + 0.5) / n_cells) ** 2
    k = np.exp(np.linspace(np.log(0.5), np.log(1e4), 400))
    a, b = mu[:, None] * k, (1 - mu)[:, None] * k
    logp = sum(
        special.betaln(a + al - 1, b + be - 1) - special.betaln(a, b)
        for al, be in zip(alpha, beta, strict=True)
    )
    p = np.exp(logp - logp.max()).sum(axis=1) * np.diff(edges)
    return edges, np.concatenate([[0.0], np.cumsum(p) / p.sum()])


@pytest.mark.parametrize("case", ["sharp", "broad", "mixed", "flat", "matt", "mirror"])
def test_population_gloss_matches_brute_force(case):
    # exact draws from known facet posteriors; the object's posterior of mu
    # against the brute-force integral. Tolerances: sharp and broad facets
    # (sd 0.02 and 0.08) agree to 0.002 in every quantile (kernel widening and
    # the 199-cell mu grid); facets piled at 0 or 1 (Beta(1, 500)) leave mu a
    # long tail toward the middle (low-kappa populations fit them too: brute
    # force 5/50/95 % at 0.0001/0.0039/0.027), matched to 0.005; the estimator
    # before this test put it at 0.0003/0.0026/0.0049. Flat facets carry
    # kernel-density noise from 4000 draws into each of 24 factors (measured
    # KS 0.02-0.08), hence 0.1 in the CDF, and their 90 % interval must stay
    # the prior's, wider than 0.7
    rng = np.random.default_rng(5)
    sharp = np.clip(0.3 + 0.05 * rng.standard_normal(24), 0.05, 0.95)
    broad = np.clip(0.5 + 0.2 * rng.standard_normal(24), 0.05, 0.95)
    glossy = np.clip(0.7 + 0.1 * rng.standard_normal(12), 0.05, 0.95)
    al, be = {
        "sharp": (500 * sharp, 500 * (1 - sharp)),
        "broad": (30 * broad, 30 * (1 - broad)),
        "mixed": (np.r_[np.ones(12), 100 * glossy], np.r_[np.ones(12), 100 * (1 - glossy)]),
        "flat": (np.ones(24), np.ones(24)),
        "matt": (np.ones(16), np.full(16, 500.0)),  # piled at 0, as matt facets are
        "mirror": (np.full(16, 500.0), np.ones(16)),
    }[case]
    draws = rng.beta(al[:, None], be[:, None], (len(al), 4000))
    mu = pooling.population_gloss(draws, seed=1)["mu"]
    grid, ref = _beta_population_cdf(al, be)
    ks = np.abs(np.searchsorted(np.sort(mu), grid) / len(mu) - ref).max()
    q_ref = np.interp([0.05, 0.5, 0.95], ref, grid)
    q = np.quantile(mu, [0.05, 0.5, 0.95])
    if case in ("sharp", "broad"):
        np.testing.assert_allclose(q, q_ref, atol=0.004)
    elif case == "mixed":
        np.testing.assert_allclose(q, q_ref, atol=0.01)
    elif case in ("matt", "mirror"):
        np.testing.assert_allclose(q, q_ref, atol=0.005)
    else:
        assert q[2] - q[0] > 0.7, q
    assert ks < 0.1, ks


def test_population_of_flat_autocorrelated_facets_stays_flat():
    # 24 facets whose posteriors are flat, sampled as an MCMC run samples them
    # (autocorrelated draws, ESS 400 of 4000): the object's 90 % interval must
    # stay close to the prior's 0.9. The estimator before this test read the
    # clumps of such draws as a population (widths 0.60-0.77 over these seeds)
    rho, n = 0.818, 4000  # AR(1): ESS = n (1 - rho) / (1 + rho) = 400
    ess = np.full(24, n * (1 - rho) / (1 + rho))
    for seed in range(8):
        rng = np.random.default_rng(seed)
        x = np.empty((24, n))
        x[:, 0] = rng.standard_normal(24)
        e = rng.standard_normal((24, n)) * np.sqrt(1 - rho**2)
        for t in range(1, n):
            x[:, t] = rho * x[:, t - 1] + e[:, t]
        mu = pooling.population_gloss(stats.norm.cdf(x), ess=ess, seed=0)["mu"]
        q = np.quantile(mu, [0.05, 0.95])
        assert q[1] - q[0] > 0.7, (seed, q)


def test_population_of_facets_pinned_at_the_bounds():
    # facets pinned at gamma 0 and 1 (sd 1e-4) and at 0.5: the Beta masses of far
    # bins underflow, and rounding once made them negative (NaN probabilities);
    # the population must still be a proper posterior, wide where facets disagree
    rng = np.random.default_rng(0)
    low = np.abs(1e-4 * rng.standard_normal(4000))
    g = np.stack([low, 1 - low[::-1], 0.5 + 1e-4 * rng.standard_normal(4000), np.zeros(4000)])
    mu = pooling.population_gloss(g, seed=0)["mu"]
    assert np.all(np.isfinite(mu))
    q = np.quantile(mu, [0.05, 0.95])
    assert q[1] - q[0] > 0.3, q  # facets at 0, 0.5 and 1: a broad population


# -- the table of Beta masses ------------------------------------------------------


def test_beta_bin_masses_match_scipy_in_both_tails(monkeypatch):
    """Every bin's mass of Beta(mu kappa, (1 - mu) kappa) against scipy.stats'
    distribution and survival functions (the latter above the mean, so that
    the reference has no cancellation either), on a small grid with an odd
    number of cells of mu: the mirrored rows (mu > 1/2) and the middle one
    included. 1e-6 relative over masses above 1e-30: the table is float32
    (6e-8), and a difference of distribution functions near 1, the error
    the table avoids, is off by up to 10x in the far tail."""
    n_mu, n_kappa, n_bins = 15, 6, 40
    monkeypatch.setenv("BAYESGLOSS_CACHE_DIR", "")  # computed here, not read from a cache
    pooling._beta_bin_masses.cache_clear()
    lkap, masses = pooling._beta_bin_masses(n_mu, n_kappa, n_bins)
    pooling._beta_bin_masses.cache_clear()
    masses = masses.reshape(n_mu, n_kappa, n_bins).astype(float)
    edges = pooling._cell_edges(n_bins)
    mu = np.sin(0.5 * np.pi * (np.arange(n_mu) + 0.5) / n_mu) ** 2
    for i in range(n_mu):
        for j, kappa in enumerate(np.exp(lkap)):
            d = stats.beta(mu[i] * kappa, (1 - mu[i]) * kappa)
            lo = edges[1:] <= mu[i]
            ref = np.where(
                lo, d.cdf(edges[1:]) - d.cdf(edges[:-1]), d.sf(edges[:-1]) - d.sf(edges[1:])
            )
            ok = ref > 1e-30
            np.testing.assert_allclose(masses[i, j, ok], ref[ok], rtol=1e-6)
            assert masses[i, j].sum() == pytest.approx(1.0, abs=1e-6)


def test_beta_bin_masses_read_back_from_the_cache(tmp_path, monkeypatch):
    """A second process reads the table the first wrote (the same numbers),
    and a file of the wrong shape is computed again, not trusted."""
    monkeypatch.setenv("BAYESGLOSS_CACHE_DIR", str(tmp_path))
    pooling._beta_bin_masses.cache_clear()
    first = pooling._beta_bin_masses(7, 3, 10)[1].copy()
    (path,) = tmp_path.glob("beta_bin_masses-*-7-3-10.npy")
    pooling._beta_bin_masses.cache_clear()  # as in a new process
    np.testing.assert_array_equal(pooling._beta_bin_masses(7, 3, 10)[1], first)
    np.save(path, np.zeros((2, 2), dtype=np.float32))  # a file not of this table
    pooling._beta_bin_masses.cache_clear()
    np.testing.assert_array_equal(pooling._beta_bin_masses(7, 3, 10)[1], first)
    pooling._beta_bin_masses.cache_clear()

"""Likelihood: against scipy's densities, its own slow path, and closed forms."""

import numpy as np
import pytest
from scipy import integrate, special, stats

from bayesgloss import gamma_interval
from bayesgloss import likelihood as lk
from bayesgloss.render import FacetBases


def _bases(rng, f=6, t=12):
    exps = np.logspace(0, 4, 9)
    d = rng.uniform(1, 10, (f, t))
    g = rng.uniform(0, 20, (f, len(exps), t))
    return FacetBases(d, g, exps)


def _theta(rng, f, k, p=4):
    th = np.empty((f, k, p))
    th[..., 0] = rng.uniform(0.05, 0.95, (f, k))
    th[..., 1] = rng.uniform(0.1, 9.0, (f, k))
    th[..., 2] = rng.normal(0, 0.5, (f, k))
    th[..., 3] = np.log(rng.uniform(0.02, 0.3, (f, k)))
    if p == 5:
        th[..., 4] = rng.uniform(0.05, 1.0, (f, k))
    return th


def test_prediction_at_nodes_and_between():
    rng = np.random.default_rng(0)
    b = _bases(rng)
    data = lk.curve_data(np.ones((6, 12)), np.ones((6, 12), bool), b)
    th = np.zeros((6, 2, 4))
    th[:, 0, 1] = np.log(b.exponents[3])  # at a node, gamma 1, s 1
    th[:, 0, 0] = 1.0
    th[:, 1, 1] = 0.5 * (np.log(b.exponents[3]) + np.log(b.exponents[4]))  # halfway
    th[:, 1, 0] = 0.25
    th[:, 1, 2] = np.log(2.0)
    m = lk.predict(th, data)
    np.testing.assert_allclose(m[:, 0], b.glossy[:, 3], rtol=1e-12)
    half = 0.5 * (b.glossy[:, 3] + b.glossy[:, 4])
    np.testing.assert_allclose(m[:, 1], 2.0 * (0.75 * b.diffuse + 0.25 * half), rtol=1e-12)


@pytest.mark.parametrize("noise", ["gaussian", "relative", "student"])
def test_log_likelihood_matches_scipy(noise):
    rng = np.random.default_rng(1)
    b = _bases(rng)
    y = rng.uniform(5, 50, (6, 12))
    valid = rng.random((6, 12)) > 0.2
    data = lk.curve_data(y, valid, b, noise=noise)
    th = _theta(rng, 6, 5)
    m = lk.predict(th, data)
    sigma = np.exp(th[..., 3:4])
    if noise == "gaussian":
        sd = sigma * np.ones_like(m)
    else:
        floor = (
            0.01 * np.max(np.where(valid, b.diffuse, 0), 1)[:, None, None] * np.exp(th[..., 2:3])
        )
        sd = sigma * (m + floor)
    if noise == "student":
        ref = stats.t.logpdf(y[:, None, :], 4.0, loc=m, scale=sd)
    else:
        ref = stats.norm.logpdf(y[:, None, :], loc=m, scale=sd)
    ref = np.sum(np.where(valid[:, None, :], ref, 0.0), -1)
    got = lk.log_likelihood(th, data)
    # the default (relative) path runs in float32: 1e-5 relative is its rounding
    np.testing.assert_allclose(got, ref, rtol=1e-5 if noise == "relative" else 1e-10)
    pointwise = lk.log_likelihood(th, data, pointwise=True).sum(-1)
    np.testing.assert_allclose(pointwise, ref, rtol=1e-10)


def test_censored_entries_use_the_survival_function():
    rng = np.random.default_rng(2)
    b = _bases(rng)
    y = rng.uniform(5, 50, (6, 12))
    cens = np.zeros((6, 12), bool)
    cens[:, 5] = True
    data = lk.curve_data(y, np.ones((6, 12), bool), b, censored=cens, noise="gaussian")
    th = _theta(rng, 6, 3)
    m = lk.predict(th, data)
    sd = np.exp(th[..., 3:4])
    ref = np.where(
        cens[:, None, :],
        stats.norm.logsf(y[:, None, :], m, sd),
        stats.norm.logpdf(y[:, None, :], m, sd),
    ).sum(-1)
    np.testing.assert_allclose(lk.log_likelihood(th, data), ref, rtol=1e-10)


def test_power_camera_prediction():
    rng = np.random.default_rng(3)
    b = _bases(rng)
    data = lk.curve_data(np.ones((6, 12)) * 0.5, np.ones((6, 12), bool), b, camera="power")
    th = _theta(rng, 6, 4, p=5)
    lin = lk.curve_data(np.ones((6, 12)), np.ones((6, 12), bool), b)
    np.testing.assert_allclose(
        lk.predict(th, data), lk.predict(th[..., :4], lin) ** np.exp(-th[..., 4:5]), rtol=1e-12
    )
    assert lk.PARAMETERS("power")[-1] == "log_g"


def test_prior_support_and_bad_names():
    rng = np.random.default_rng(4)
    b = _bases(rng)
    data = lk.curve_data(np.ones((6, 12)), np.ones((6, 12), bool), b)
    th = _theta(rng, 6, 4)
    th[0, 0, 0] = 1.2  # gamma outside [0, 1]
    th[1, 1, 1] = 10.0  # n above 1e4
    lp = lk.log_probability(th, data)
    assert lp[0, 0] == -np.inf and lp[1, 1] == -np.inf
    assert np.all(np.isfinite(lp[2:]))
    with pytest.raises(ValueError, match="noise model 'cauchy'.*relative"):
        lk.curve_data(np.ones((6, 12)), np.ones((6, 12), bool), b, noise="cauchy")
    with pytest.raises(ValueError, match="uniform in log n"):
        lk.curve_data(
            np.ones((6, 12)),
            np.ones((6, 12), bool),
            FacetBases(b.diffuse, b.glossy[:, :3], np.array([1.0, 2.0, 10.0])),
        )


def test_simulated_noise_has_the_model_scale():
    # residuals of simulated data, divided by the model's sd, are standard normal
    rng = np.random.default_rng(5)
    b = _bases(rng, f=40, t=12)
    data = lk.curve_data(np.ones((40, 12)), np.ones((40, 12), bool), b)
    th = _theta(rng, 40, 50)
    y = lk.simulate(th, data, rng)
    m = lk.predict(th, data)
    floor = 0.01 * b.diffuse.max(1)[:, None, None] * np.exp(th[..., 2:3])
    z = (y - m) / (np.exp(th[..., 3:4]) * (m + floor))
    # 24000 draws: the sd of the sample sd is ~0.005; 0.02 is 4 of those
    assert abs(z.std() - 1) < 0.02 and abs(z.mean()) < 0.02


def _brute_sigma(th, data, n=40001):
    """log of int L(theta, sigma) p(sigma) d sigma by quadrature in log sigma, and
    the grid and normalised posterior of log sigma (the slow, scipy-checked path)."""

    lo, hi = data.priors.log_sigma
    grid = np.linspace(lo, hi, n)
    full = np.repeat(th[..., :3], n, axis=1)
    full = np.concatenate([full, np.broadcast_to(grid, full.shape[:2])[..., None]], axis=-1)
    ll = lk.log_likelihood(full, data)  # (B, n)
    # each step integrated with the log integrand linear across it (exact for
    # exponential segments: steep edges of a posterior piled at a bound)
    d = np.diff(ll, axis=1)
    a = np.maximum(np.abs(d), 1e-12)
    seg = np.maximum(d, 0.0) + np.log(-np.expm1(-a)) - np.log(a)  # log((e^d - 1) / d)
    step = grid[1] - grid[0]
    log_z = special.logsumexp(ll[:, :-1] + seg, axis=1) + np.log(step) - np.log(hi - lo)
    return log_z, grid, np.exp(ll - ll.max(axis=1, keepdims=True))


@pytest.mark.parametrize("noise", ["relative", "gaussian"])
def test_sigma_marginal_matches_quadrature(noise):
    # data at sigma well inside the prior, near its lower (1e-4) and upper (2)
    # bounds, and beyond them; the closed form (incomplete gamma) against a
    # 40001-point trapezoid over log sigma of the pointwise likelihood
    rng = np.random.default_rng(11)
    b = _bases(rng, f=5, t=14)
    valid = rng.random((5, 14)) > 0.15
    design = lk.curve_data(np.ones((5, 14)), valid, b, noise=noise)
    truth = _theta(rng, 5, 1)
    scale = 1.0 if noise == "relative" else 10.0  # gaussian sd in data units
    truth[:, 0, 3] = np.log(np.array([0.03, 1.3e-4, 1.7, 3e-5, 6.0]) * scale)
    y = lk.simulate(truth, design, rng)[:, 0]
    data = lk.curve_data(y, valid, b, noise=noise)
    th = np.concatenate([truth, truth + [0.05, 0.3, 0.1, 0.0]], axis=1)  # truth and off it
    th[..., 0] = np.clip(th[..., 0], 0, 1)
    got = lk.log_likelihood_sigma_marginal(th, data)
    for k in range(2):
        want, _, _ = _brute_sigma(th[:, k : k + 1], data)
        # quadrature error ~ 1e-7 of the peak; float32 residuals ~ 1e-6 relative
        np.testing.assert_allclose(got[:, k], want, rtol=2e-6, atol=2e-4)


def test_sigma_marginal_refuses_unsupported_models():
    rng = np.random.default_rng(12)
    b = _bases(rng)
    for kw in ({"noise": "student"}, {"camera": "power"}):
        data = lk.curve_data(rng.uniform(5, 50, (6, 12)), np.ones((6, 12), bool), b, **kw)
        assert not lk.sigma_marginal_supported(data)
        with pytest.raises(ValueError, match="sigma can be integrated out"):
            lk.log_likelihood_sigma_marginal(_theta(rng, 6, 2), data)


def test_draw_log_sigma_follows_its_conditional():
    # draws of log sigma at fixed (gamma, log n, log s) against the conditional
    # posterior by quadrature (KS at 1 %); one facet mid-prior, one pinned at the
    # upper bound, one at the lower bound (truncated draws through the inverse CDF)
    rng = np.random.default_rng(13)
    b = _bases(rng, f=3, t=14)
    valid = np.ones((3, 14), bool)
    design = lk.curve_data(np.ones((3, 14)), valid, b)
    truth = _theta(rng, 3, 1)
    truth[:, 0, 3] = np.log([0.05, 2.5, 1.2e-4])
    data = lk.curve_data(lk.simulate(truth, design, rng)[:, 0], valid, b)
    draws = lk.draw_log_sigma(np.repeat(truth, 4000, axis=1), data, np.random.default_rng(14))
    _, grid, dens = _brute_sigma(truth, data)
    lo, hi = data.priors.log_sigma
    assert np.all((draws >= lo) & (draws <= hi))
    for f in range(3):
        cdf = np.cumsum(dens[f])
        cdf /= cdf[-1]
        p = stats.kstest(draws[f], lambda x, c=cdf: np.interp(x, grid, c)).pvalue
        assert p > 0.01, (f, p)


def test_log_gamma_interval_in_every_tail_regime():
    # log of int_lo^hi t^(k-1) e^-t dt / Gamma(k) against adaptive quadrature of
    # the integrand scaled by its largest value on the interval (no underflow):
    # intervals cutting neither tail, the lower one (sigma at its upper bound),
    # the upper one (sigma at its lower bound) and both (narrow, far in either
    # tail, where P and Q both underflow or round to 1), mixed in one call as
    # the sampler's batches mix them; quad's relative accuracy is ~1e-10, and
    # the tails dropped (< 1e-10) are far below that relative to these intervals
    k = np.array([[2.0], [7.5], [9.5], [40.0]])
    pairs = [(1e-30, 1e6), (3.0, 1e6), (1e-30, 0.5), (0.2, 0.3), (60.0, 62.0), (8.0, 12.0)]
    pairs += [(1e-6, 2e-6), (30.0, 1e3)]  # wholly below, wholly above the mode
    x_lo = np.array([[lo for lo, _ in pairs]] * len(k))
    x_hi = np.array([[hi for _, hi in pairs]] * len(k))
    got = gamma_interval.log_gamma_interval(k, x_lo, x_hi)
    for i, kk in enumerate(k[:, 0]):
        for j, (lo, hi) in enumerate(pairs):

            def log_f(t, kk=kk):
                return (kk - 1.0) * np.log(t) - t - special.gammaln(kk)

            top = log_f(np.clip(kk - 1.0, lo, hi))  # the integrand's largest value
            val, _ = integrate.quad(
                lambda t, top=top, log_f=log_f: np.exp(log_f(t) - top),
                lo,
                min(hi, 1e4),
                epsabs=0,
                epsrel=1e-11,
                limit=200,
                points=[np.clip(kk - 1.0, lo, min(hi, 1e4))],
            )
            np.testing.assert_allclose(got[i, j], np.log(val) + top, rtol=1e-8, atol=1e-8)


@pytest.mark.parametrize("log_g", [0.0, np.log(2.2)])
def test_noise_floor_is_one_percent_of_the_peak_on_the_observed_scale(log_g):
    # a dark frame (D = G = 0, so m = 0) observed exactly: its pointwise log
    # likelihood is -log(sigma floor) - log(2 pi) / 2, so it reveals the floor,
    # which must be 1 % of the facet's peak diffuse value on the observed scale,
    # (s max D)^(1/g) for the power camera; a floor left in linear units
    # (0.01 s max D added to code values) is off by (s max D)^(1 - 1/g) = 8x here
    rng = np.random.default_rng(21)
    b = _bases(rng, f=2, t=6)
    b.diffuse[:, 0] = 0.0
    b.glossy[:, :, 0] = 0.0
    theta = _theta(rng, 2, 1, p=5)
    theta[..., 2] = np.log(100.0 / b.diffuse.max(axis=1))[:, None]  # s max D = 100
    theta[..., 4] = log_g
    design = lk.curve_data(np.ones((2, 6)), np.ones((2, 6), bool), b, camera="power")
    y = lk.predict(theta, design)[:, 0]
    data = lk.curve_data(y, np.ones((2, 6), bool), b, camera="power")
    ll = lk.log_likelihood(theta, data, pointwise=True)[:, 0, 0]
    floor = np.exp(-ll - 0.5 * np.log(2 * np.pi) - theta[:, 0, 3])
    np.testing.assert_allclose(floor, 0.01 * 100.0 ** np.exp(-log_g), rtol=1e-9)

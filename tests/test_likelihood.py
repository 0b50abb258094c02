"""Likelihood: against scipy's densities, its own slow path, and closed forms."""

import numpy as np
import pytest
from scipy import stats

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

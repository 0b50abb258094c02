"""The one-material model's density, gradient and hidden-sun step
(bayesgloss.sampling.material_density)."""

import dataclasses

import numpy as np
import pytest

from bayesgloss import illumination as il
from bayesgloss import likelihood as lk
from bayesgloss.sampling import material_density as hm


def _object(paper_three_skies, exposure_known=True, shapes=3, seed=1, sigma=0.02):
    """A simulated 6-facet, 6-frame object under the auto mixture (or one sky)
    drawn from the one-material prior, each facet's noise ``sigma``: (data,
    theta (1, F, 4), hyper (1, 4), lam (1, T, L))."""
    full, up = paper_three_skies
    frames = np.flatnonzero(up)[2:-2][::2][:6]
    bases = full.take(np.linspace(0, full.diffuse.shape[1] - 1, 6).round().astype(int), frames)
    if shapes == 1:
        bases = il.IlluminationBases(
            bases.diffuse[:3], bases.glossy[:3], bases.exponents, 1, bases.log_sun_ratio[:1]
        )
        bases = dataclasses.replace(
            bases,
            diffuse=np.concatenate([bases.diffuse[:2], bases.diffuse[1:2]]),
            glossy=np.concatenate([bases.glossy[:2], bases.glossy[1:2]]),
        )
    f, t = bases.diffuse.shape[1:]
    exposure = np.ones(t) if exposure_known else None
    ref = il.joint_data(
        np.ones((f, t)),
        np.ones((f, t), bool),
        bases,
        exposure=exposure,
        priors=lk.Priors(log_s_center=0.0),
    )
    ref = dataclasses.replace(ref, floor=0.01 * bases.total().diffuse.max(axis=1))
    rng = np.random.default_rng(seed)
    th, hyper, lam = il.sample_prior_material(ref, 1, rng, point_mass=True)
    th[..., 3] = np.log(sigma)
    y = il.simulate(th.transpose(1, 0, 2)[:, :, None, :], lam[:, None], ref, rng)[0, :, 0]
    return dataclasses.replace(ref, y=y), th.transpose(1, 0, 2), hyper, lam


def _states(data, th, hyper, lam, rng, n=3):
    """States about the truth (a hidden sun's log a at its pseudo-prior's mean)."""
    lay = hm.layout(data)
    lam = np.where(np.isneginf(lam), data.frame_priors.sun_cloud_mean, lam)
    x = hm.state_of(th, hyper, lam, lay)
    return lay, x + 0.03 * rng.standard_normal((n, lay.size))


@pytest.mark.parametrize("known,shapes", [(True, 3), (False, 3), (True, 1)])
def test_gradient_is_the_density_s(paper_three_skies, known, shapes):
    # central differences of the log density (step 1e-6) against the closed
    # form, every coordinate, with the sun hidden in some frames: a wrong
    # term (a chain-rule factor, a Jacobian, a softmax derivative) is off
    # by O(1) relative; the tolerance 1e-4 is the differences' own error
    data, th, hyper, lam = _object(paper_three_skies, known, shapes)
    rng = np.random.default_rng(2)
    lay, x = _states(data, th, hyper, lam, rng)
    hidden = rng.random((len(x), lay.t)) < 0.4
    lp, grad = hm.log_density_and_gradient(x, data, lay, hidden)
    assert np.all(np.isfinite(lp))
    num = np.empty_like(grad)
    for i in range(lay.size):
        e = np.zeros(lay.size)
        e[i] = 1e-6
        up = hm.log_density_and_gradient(x + e, data, lay, hidden)[0]
        down = hm.log_density_and_gradient(x - e, data, lay, hidden)[0]
        num[:, i] = (up - down) / 2e-6
    np.testing.assert_allclose(grad, num, rtol=1e-4, atol=1e-4 * np.abs(num).max())


def test_density_is_the_one_material_model(paper_three_skies):
    # differences of the sampler's log density between states equal those of
    # the model as bayesgloss.illumination writes it (likelihood with each
    # facet's sigma, log_prior_material, log_prior_frames with the day's sun
    # weights, a hidden sun log a = -inf) plus the logits' Jacobians and the
    # hidden frames' pseudo-prior: 1e-7 of densities of order 1e3
    data, th, hyper, lam = _object(paper_three_skies, exposure_known=False)
    rng = np.random.default_rng(3)
    lay, x = _states(data, th, hyper, lam, rng, n=4)
    hidden = rng.random((len(x), lay.t)) < 0.4
    ours = hm.log_density_and_gradient(x, data, lay, hidden)[0]
    th2, hy2, lam2 = hm.natural(x, lay, data)
    q = data.frame_priors
    pseudo = -0.5 * ((lam2[..., 1] - q.sun_cloud_mean) / q.sun_cloud_sd) ** 2
    pseudo = np.where(hidden, pseudo - np.log(q.sun_cloud_sd), 0.0).sum(-1)
    lam2[..., 1] = np.where(hidden, -np.inf, lam2[..., 1])
    t4 = th2[:, :, None, :]
    model = np.nansum(il.pointwise_log_likelihood(t4, lam2[:, None], data), axis=(1, 2, 3))
    model += il.log_prior_material(t4, hy2[:, None], data)[:, 0]
    model += il.log_prior_frames(lam2, data, il.log_sun_weights(hy2), point_mass=True).sum(-1)
    o = lay.hyper.start
    for i, name in ((0, "gamma"), (1, "log_n"), (lay.log_sigma, "log_sigma"), (o + 1, "log_tau")):
        jac = hm._bounded(x[:, i], lay.bounds[name])[2]
        model += jac.sum(-1) if jac.ndim > 1 else jac
    model += pseudo
    np.testing.assert_allclose(ours - ours[0], model - model[0], atol=1e-7 * np.abs(ours).max())


def test_hidden_sun_step_draws_its_conditional(paper_three_skies):
    # one state copied 4000 times: each frame's share of hidden draws must be
    # its conditional probability, computed here from bayesgloss.illumination
    # (the frame's likelihood with its sun and without, the day's weights,
    # the pseudo-prior); binomial sd <= 0.008, tolerance 0.035 (> 4 sd)
    data, th, hyper, lam = _object(paper_three_skies, seed=4, sigma=0.03)
    rng = np.random.default_rng(5)
    lay, x = _states(data, th, hyper, lam, rng, n=1)
    o = lay.hyper.start
    x[:, o + 2 : o + 4] = 0.0  # even day weights
    a_cols = lay.frames.start + np.arange(lay.t) * lay.k  # log a of each frame (exposure known)
    x[:, a_cols] = np.linspace(-7.0, -2.0, lay.t)  # suns from barely to clearly seen
    n = 4000
    draws = hm.hidden_step(np.repeat(x, n, 0), np.zeros((n, lay.t), bool), data, lay, rng)
    th2, hy2, lam2 = hm.natural(x, lay, data)
    t4 = th2[:, :, None, :]
    shown_ll = np.nansum(il.pointwise_log_likelihood(t4, lam2[:, None], data), axis=(1, 2))[0]
    gone = lam2.copy()
    gone[..., 1] = -np.inf
    hidden_ll = np.nansum(il.pointwise_log_likelihood(t4, gone[:, None], data), axis=(1, 2))[0]
    w = il.log_sun_weights(hy2)
    shown_p = il.log_prior_frames(lam2, data, w, point_mass=True)[0] + shown_ll
    q = data.frame_priors
    pseudo = -0.5 * ((lam2[0, :, 1] - q.sun_cloud_mean) / q.sun_cloud_sd) ** 2 - np.log(
        q.sun_cloud_sd
    )
    hidden_p = il.log_prior_frames(gone, data, w, point_mass=True)[0] + pseudo + hidden_ll
    expected = 1 / (1 + np.exp(shown_p - hidden_p))
    assert np.ptp(expected) > 0.3  # the frames differ
    np.testing.assert_allclose(draws.mean(0), expected, atol=0.035)

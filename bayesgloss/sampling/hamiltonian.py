"""Hamiltonian Monte Carlo of the one-material model, many chains in lockstep.

The one-material model (:mod:`bayesgloss.sampling.material`,
:func:`bayesgloss.illumination.log_prior_material`) has 2 shared
coordinates (gamma, log n), a scale and a noise level per facet, 4 of the
day, and 3 to 5 per frame: about 150 for 30 facets over 20 frames, strongly
coupled (a change of gamma changes every facet's level and every frame's
best brightness). Metropolis within Gibbs with ensemble moves crawled
there: on simulated 8-facet objects drawn from the prior, each walker's
gamma stayed where it started (R-hat over walkers 1.7-6.4 after 1200
sweeps), and simulation-based calibration found 90 % intervals holding the
truth for 79 % of objects (gamma) and 76 % (a frame's sun). Hamiltonian
Monte Carlo moves all coordinates at once along the gradient of the log
posterior, which the model's bilinear form gives in closed form
(:func:`log_density_and_gradient`).

The scheme (Neal 2011, "MCMC using Hamiltonian dynamics", Handbook of
MCMC, ch. 5; adaptation as Stan's, Hoffman & Gelman 2014, JMLR 15, sec.
3.2):

- bounded coordinates (gamma, log n, log sigma_f, log tau) are sampled as
  logits, x = lo + (hi - lo) / (1 + e^-eta), with the Jacobian
  log((hi - lo) sigma(eta) (1 - sigma(eta))) in the density;
- the noise level sigma_f of each facet is a coordinate (not integrated
  out as the Metropolis samplers do), so the density is a sum over
  entries and its gradient a few array products;
- a dense metric: the coordinates are whitened, x = c + L z, with L the
  Cholesky factor of the draws' within-chain covariance in the warm-up's
  windows (shrunk toward its diagonal), and identity mass in z;
- the step size by dual averaging to a mean acceptance of 0.8 during the
  warm-up, fixed afterwards; each iteration's number of leapfrog steps
  drawn uniformly about trajectory length pi / 2 (in whitened units: a
  quarter period of a standard normal), the step size jittered by +-10 %;
- C chains from dispersed starts (gamma spread over (0, 1), each chain's
  scales and frames fitted at its own gamma), so R-hat across chains can
  see a posterior the chains have not all found; the run stops when the
  rule of :mod:`bayesgloss.diagnostics` holds for gamma, every frame's log
  a and log b, and the log posterior, or at ``max_draws`` (flagged).

The hidden sun is a point mass at a = 0 here
(:func:`bayesgloss.illumination.log_prior_frames` with ``point_mass``):
each frame's hidden-sun indicator is drawn by Gibbs (:func:`hidden_step`)
between trajectories, a hidden frame's log a kept as a coordinate under a
pseudo-prior (Carlin & Chib 1995) adapted in the warm-up to that frame's
draws where its sun shows.

**Status (stop 24): not the default, and not yet fit to be.** The density
and gradient are checked against the model and finite differences, the
hidden-sun step against its conditional (tests/test_hamiltonian.py). But
on 8-facet, 6-frame objects drawn from the prior the adapted step size is
0.004-0.009 in whitened units, so an iteration takes the 128-step cap,
and 4000 iterations (300 s) leave gamma's R-hat at 1.05-1.19: the
posterior's curvature changes across it more than one dense metric can
follow (facets' noise levels drawn from 1e-4 to 2, the albedo funnel of
log s under log tau, the sky-shape weights). With no data at all the
chains stay in the funnel of log s under log tau (gamma's mean 0.35 for a
uniform prior). Next: a non-centred or Gibbs-updated albedo population,
(m, tau) drawn exactly between trajectories, and NUTS-style trajectory
lengths.

The gradient need not be exact for the chain to be: leapfrog with any
force that is a function of position is reversible and keeps volume, so
the Metropolis test on the exact density leaves the posterior invariant
(Neal 2011, sec. 5.2.3). The piecewise-linear exponent table (whose
gradient in log n is constant between nodes) costs acceptance, not
correctness.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from .. import diagnostics
from .. import illumination as il
from .joint import JointSamples, starting_frames

__all__ = ["Layout", "layout", "log_density_and_gradient", "sample_material_hmc"]

#: Target mean acceptance probability of the step-size adaptation.
TARGET_ACCEPTANCE = 0.8
#: Trajectory length in whitened units.
TRAJECTORY = 0.5 * np.pi
#: Most leapfrog steps an iteration takes.
MAX_LEAPFROG = 128
#: Warm-up: a first window with a diagonal metric, then windows whose draws
#: set the dense metric, then a last stretch adapting the step size alone.
WARMUP_WINDOWS = (100, 50, 100, 200)
WARMUP_TAIL = 50


@dataclass(frozen=True)
class Layout:
    """Where each quantity sits in the state vector of a chain.

    The state is (eta_gamma, eta_log_n, log s (F), eta_log_sigma (F), m,
    eta_log_tau, v_1, v_2, then each frame's free latents (T x K)); eta
    marks a logit of a bounded coordinate (module docstring).
    """

    f: int
    t: int
    free: np.ndarray  # (L,) of bool: which frame latents are coordinates
    bounds: dict  # name -> (lo, hi)

    @property
    def k(self) -> int:
        return int(self.free.sum())

    @property
    def size(self) -> int:
        return 2 + 2 * self.f + 4 + self.t * self.k

    @property
    def log_s(self) -> slice:
        return slice(2, 2 + self.f)

    @property
    def log_sigma(self) -> slice:
        return slice(2 + self.f, 2 + 2 * self.f)

    @property
    def hyper(self) -> slice:
        return slice(2 + 2 * self.f, 6 + 2 * self.f)

    @property
    def frames(self) -> slice:
        return slice(6 + 2 * self.f, self.size)


def layout(data: il.JointData) -> Layout:
    """The state layout of ``data``'s one-material model."""
    f, t = data.shape
    p = data.priors
    free = data.free.copy()
    return Layout(
        f,
        t,
        free,
        {
            "gamma": (0.0, 1.0),
            "log_n": tuple(p.log_n),
            "log_sigma": tuple(p.log_sigma),
            "log_tau": il.MATERIAL_LOG_TAU,
        },
    )


def _expit(eta):
    return 0.5 * (1.0 + np.tanh(0.5 * eta))


def _bounded(eta, bounds):
    """x, dx/deta and the log Jacobian log(dx/deta) of a logit coordinate."""
    lo, hi = bounds
    u = _expit(eta)
    dx = (hi - lo) * u * (1.0 - u)
    with np.errstate(divide="ignore"):
        log_j = np.log(hi - lo) + np.log(u) + np.log1p(-u)
    return lo + (hi - lo) * u, dx, log_j, 1.0 - 2.0 * u


def _logit(x, bounds):
    lo, hi = bounds
    u = np.clip((np.asarray(x, float) - lo) / (hi - lo), 1e-6, 1 - 1e-6)
    return np.log(u) - np.log1p(-u)


def natural(state, lay: Layout, data: il.JointData):
    """The model's coordinates of states (C, D): theta (C, F, 4) with gamma
    and log n shared, hyper (C, 4), lam (C, T, L) (fixed slots filled)."""
    c = state.shape[0]
    th = np.empty((c, lay.f, 4))
    th[..., 0] = _bounded(state[:, 0], lay.bounds["gamma"])[0][:, None]
    th[..., 1] = _bounded(state[:, 1], lay.bounds["log_n"])[0][:, None]
    th[..., 2] = state[:, lay.log_s]
    th[..., 3] = _bounded(state[:, lay.log_sigma], lay.bounds["log_sigma"])[0]
    hyper = state[:, lay.hyper].copy()
    hyper[:, 1] = _bounded(hyper[:, 1], lay.bounds["log_tau"])[0]
    lam = np.zeros((c, lay.t, len(lay.free)))
    lam[..., lay.free] = state[:, lay.frames].reshape(c, lay.t, lay.k)
    if data.exposure_known:
        lam[..., 0] = data.log_exposure
    return th, hyper, lam


def state_of(th, hyper, lam, lay: Layout):
    """The inverse of :func:`natural`: states (C, D)."""
    c = th.shape[0]
    x = np.empty((c, lay.size))
    x[:, 0] = _logit(th[:, 0, 0], lay.bounds["gamma"])
    x[:, 1] = _logit(th[:, 0, 1], lay.bounds["log_n"])
    x[:, lay.log_s] = th[..., 2]
    x[:, lay.log_sigma] = _logit(th[..., 3], lay.bounds["log_sigma"])
    x[:, lay.hyper] = hyper
    x[:, lay.hyper.start + 1] = _logit(hyper[:, 1], lay.bounds["log_tau"])
    x[:, lay.frames] = lam[..., lay.free].reshape(c, -1)
    return x


def _model(state, data: il.JointData, lay: Layout):
    """The forward model's pieces at states (C, D), for the density, its
    gradient and the hidden-sun step (a dict; ``parts`` (C, P, F, T) is each
    source's share of mu with the sun shown, whether hidden or not)."""
    c, t = state.shape[0], lay.t
    out = {}
    out["gamma"] = _bounded(state[:, 0], lay.bounds["gamma"])
    out["log_n"] = _bounded(state[:, 1], lay.bounds["log_n"])
    out["log_sigma"] = _bounded(state[:, lay.log_sigma], lay.bounds["log_sigma"])
    lam = np.zeros((c, t, len(lay.free)))
    lam[..., lay.free] = state[:, lay.frames].reshape(c, t, lay.k)
    log_e = np.broadcast_to(data.log_exposure, (c, t)) if data.exposure_known else lam[..., 0]
    shapes = data.shapes
    sources = 1 + shapes if shapes >= 2 else 2
    gamma = out["gamma"][0]
    grid = data.log_n_grid
    h = grid[1] - grid[0]
    pos = np.clip((out["log_n"][0] - grid[0]) / h, 0.0, len(grid) - 1.000001)
    j = pos.astype(np.intp)
    w = (pos - j)[:, None, None, None]
    g_lo = np.moveaxis(data.glossy[:sources][:, :, j, :], 2, 0)  # (C, P, F, T)
    g_hi = np.moveaxis(data.glossy[:sources][:, :, j + 1, :], 2, 0)
    d = data.diffuse[:sources][None]
    g_n = g_lo + w * (g_hi - g_lo)
    gam = gamma[:, None, None, None]
    out["du_dgamma"] = g_n - d
    out["du_dlogn"] = gam * (g_hi - g_lo) / h
    unit = d + gam * out["du_dgamma"]
    if shapes >= 2:
        u = np.concatenate([np.zeros((c, t, 1)), lam[..., 3 : 3 + shapes - 1]], -1)
        u = u - u.max(-1, keepdims=True)
        shape_w = np.exp(u)
        shape_w /= shape_w.sum(-1, keepdims=True)  # (C, T, K)
    else:
        shape_w = np.ones((c, t, 1))
    with np.errstate(over="ignore"):
        sun_w = np.exp(log_e + lam[..., 1])
        sky_w = np.exp(log_e + lam[..., 2])[..., None] * shape_w  # (C, T, K)
        weights = np.concatenate([sun_w[:, None], np.moveaxis(sky_w, -1, 1)], 1)  # (C, P, T)
        s = np.exp(state[:, lay.log_s])[:, :, None]  # (C, F, 1)
        out["sw"] = s[:, None] * weights[:, :, None, :]  # (C, P, F, T)
        out["parts"] = out["sw"] * unit
    out.update(lam=lam, log_e=log_e, shape_w=shape_w, shapes=shapes)
    return out


def _entry_log_likelihood(mu, log_sigma, data: il.JointData):
    """Each entry's log likelihood (C, F, T) (0 where invalid; the constant
    -log sqrt(2 pi) left out) and its derivative in mu."""
    valid = data.valid[None]
    y = data.y[None]
    floor = data.floor[None, :, None]
    vv = mu + floor
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        z = np.where(valid, (y - mu) / vv, 0.0)
        inv_var = np.exp(-2.0 * log_sigma)[..., None]
        ll = np.where(valid, -0.5 * z * z * inv_var - np.log(vv) - log_sigma[..., None], 0.0)
        g_mu = np.where(valid, z * inv_var * (y + floor) / vv**2 - 1.0 / vv, 0.0)
    return ll, g_mu, z * z * inv_var


def _sun_components(log_a, v, hidden, q, pseudo=None):
    """Each frame's sun prior by component, (C, T, 3), given the day's weights
    (softmax of (0, v)): clear and dimmed where the sun shows, and where it
    is hidden the hidden weight with the pseudo-prior of log a (``pseudo``,
    each frame's mean and sd, (T,) each; None: the dimmed component's
    normal): log a is then a coordinate the likelihood ignores (Carlin &
    Chib 1995, "Bayesian model choice via Markov chain Monte Carlo", JRSS B
    57); -inf for the components the frame is not in; and the means and
    sds of log a by component, (T, 3) each, and the day's log weights."""
    c = v.shape[0]
    vv3 = np.concatenate([np.zeros((c, 1)), v], -1)
    log_day = vv3 - np.logaddexp.reduce(vv3, axis=-1, keepdims=True)  # (C, 3)
    t = log_a.shape[-1]
    if pseudo is None:
        pseudo = (np.full(t, q.sun_cloud_mean), np.full(t, q.sun_cloud_sd))
    means = np.stack([np.zeros(t), np.full(t, q.sun_cloud_mean), pseudo[0]], -1)
    sds = np.stack([np.full(t, q.sun_clear_sd), np.full(t, q.sun_cloud_sd), pseudo[1]], -1)
    comp = -0.5 * ((log_a[..., None] - means) / sds) ** 2 - np.log(sds) + log_day[:, None, :]
    shown = np.stack([~hidden, ~hidden, hidden], -1)
    return np.where(shown, comp, -np.inf), means, sds, log_day


def log_density_and_gradient(state, data: il.JointData, lay: Layout, hidden=None, pseudo=None):
    """The one-material model's log posterior (up to a constant) and its
    gradient in the sampler's coordinates, for states (C, D) with the sun
    hidden in the frames ``hidden`` (C, T) (None: none): ((C,), (C, D)).

    mu_ft = s_f sum_p W_pt U_pft (:mod:`bayesgloss.illumination`), U_p =
    D_p + gamma (G_p(n) - D_p), W_0 = e a (0 where hidden), W_k = e b w_k;
    each valid entry adds -z^2 / (2 sigma_f^2) - log(mu + c_f) - log
    sigma_f, z = (y - mu) / (mu + c_f); the priors those of
    :func:`~bayesgloss.illumination.log_prior_material` and
    :func:`~bayesgloss.illumination.log_prior_frames` (with the day's sun
    weights; a hidden frame's log a under its pseudo-prior,
    :func:`_sun_components`), and the logits' Jacobians. -inf where not
    finite, the gradient then 0.
    """
    c = state.shape[0]
    f, t = lay.f, lay.t
    q = data.frame_priors
    if hidden is None:
        hidden = np.zeros((c, t), bool)
    mod = _model(state, data, lay)
    gamma, dgamma, jg, djg = mod["gamma"]
    _, dlogn, jn, djn = mod["log_n"]
    log_sigma, dls, jsig, djsig = mod["log_sigma"]
    lam, log_e, shape_w, shapes = mod["lam"], mod["log_e"], mod["shape_w"], mod["shapes"]
    log_a, log_b = lam[..., 1], lam[..., 2]
    shown = ~hidden[:, None, :]
    sw = mod["sw"].copy()
    sw[:, 0] *= shown
    parts = mod["parts"].copy()
    parts[:, 0] *= shown
    mu = parts.sum(1)
    mu_sky = mu - parts[:, 0]
    ll, g_mu, zz = _entry_log_likelihood(mu, log_sigma, data)
    ll = ll.sum((1, 2))
    gm = g_mu * mu

    # priors
    log_s = state[:, lay.log_s]
    o = lay.hyper.start
    m, v = state[:, o], state[:, o + 2 : o + 4]
    log_tau, dlt, jt, djt = _bounded(state[:, o + 1], lay.bounds["log_tau"])
    tau2 = np.exp(2 * log_tau)
    dev = log_s - m[:, None]
    c0 = il.material_m_center(data)
    lp = -0.5 * np.sum(dev**2, 1) / tau2 - f * log_tau
    lp -= 0.5 * ((m - c0) / il.MATERIAL_M_SD) ** 2
    comp, means, sds, log_day = _sun_components(log_a, v, hidden, q, pseudo)
    lp += log_day.sum(-1)  # Dirichlet(1, 1, 1) in the log-ratio coordinates
    top = comp.max(-1, keepdims=True)
    resp = np.exp(comp - top)
    norm = resp.sum(-1, keepdims=True)
    lp += np.sum(top[..., 0] + np.log(norm[..., 0]), -1)
    resp /= norm
    lp -= 0.5 * np.sum((log_b / q.sky_sd) ** 2, -1)
    if shapes >= 2:
        lp += np.sum(np.log(np.maximum(shape_w, 1e-300)), axis=(1, 2))
    if not data.exposure_known:
        lp -= 0.5 * np.sum((log_e / q.exposure_sd) ** 2, -1)
    lp += jg + jn + jsig.sum(1) + jt

    # the gradient
    grad = np.zeros_like(state)
    with np.errstate(invalid="ignore", over="ignore"):
        grad[:, 0] = np.sum(g_mu * np.sum(sw * mod["du_dgamma"], 1), (1, 2)) * dgamma + djg
        grad[:, 1] = np.sum(g_mu * np.sum(sw * mod["du_dlogn"], 1), (1, 2)) * dlogn + djn
        grad[:, lay.log_s] = gm.sum(-1) - dev / tau2[:, None]
        n_valid = data.valid.sum(1)[None]
        grad[:, lay.log_sigma] = (zz.sum(-1) - n_valid) * dls + djsig
        grad[:, o] = np.sum(dev, 1) / tau2 - (m - c0) / il.MATERIAL_M_SD**2
        grad[:, o + 1] = (np.sum(dev**2, 1) / tau2 - f) * dlt + djt
        day_w = np.exp(log_day)
        grad[:, o + 2 : o + 4] = (
            np.sum(resp[..., 1:] - day_w[:, None, 1:], 1) + 1.0 - 3.0 * day_w[:, 1:]
        )
        g_lam = np.zeros((c, t, len(lay.free)))
        g_lam[..., 0] = gm.sum(1) - log_e / q.exposure_sd**2
        g_lam[..., 1] = np.sum(g_mu * parts[:, 0], 1)
        g_lam[..., 1] += np.sum(resp * (means - log_a[..., None]) / sds**2, -1)
        g_lam[..., 2] = np.sum(g_mu * mu_sky, 1) - log_b / q.sky_sd**2
        for k in range(1, shapes):
            gk = np.sum(g_mu * (parts[:, 1 + k] - shape_w[:, None, :, k] * mu_sky), 1)
            g_lam[..., 2 + k] = gk + 1.0 - shapes * shape_w[..., k]
    grad[:, lay.frames] = g_lam[..., lay.free].reshape(c, -1)

    total = ll + lp
    bad = ~np.isfinite(total) | ~np.all(np.isfinite(grad), -1)
    total = np.where(bad, -np.inf, total)
    grad = np.where(bad[:, None], 0.0, grad)
    return total, grad


def hidden_step(state, hidden, data: il.JointData, lay: Layout, rng, pseudo=None) -> np.ndarray:
    """Each frame's hidden-sun indicator drawn from its conditional given the
    state (Gibbs), (C, T) of bool: shown, log a weighs in by the clear and
    dimmed components and the likelihood with the sun; hidden, by the
    hidden weight, the pseudo-prior (:func:`_sun_components`) and the
    likelihood without it. Frames are independent given the state (each
    facet's sigma is a coordinate)."""
    c, t = hidden.shape
    mod = _model(state, data, lay)
    log_sigma = mod["log_sigma"][0]
    parts = mod["parts"]
    mu_sky = parts[:, 1:].sum(1)
    ll_shown = _entry_log_likelihood(mu_sky + parts[:, 0], log_sigma, data)[0].sum(1)  # (C, T)
    ll_hidden = _entry_log_likelihood(mu_sky, log_sigma, data)[0].sum(1)
    o = lay.hyper.start
    q = data.frame_priors
    log_a, v = mod["lam"][..., 1], state[:, o + 2 : o + 4]
    shown_c = _sun_components(log_a, v, np.zeros((c, t), bool), q, pseudo)[0]
    hidden_c = _sun_components(log_a, v, np.ones((c, t), bool), q, pseudo)[0]
    p_shown = np.logaddexp(shown_c[..., 0], shown_c[..., 1]) + ll_shown
    p_hidden = hidden_c[..., 2] + ll_hidden
    with np.errstate(invalid="ignore", over="ignore"):
        prob_hidden = 1.0 / (1.0 + np.exp(np.clip(p_shown - p_hidden, -700, 700)))
    prob_hidden = np.where(np.isfinite(p_shown) | np.isfinite(p_hidden), prob_hidden, 0.0)
    prob_hidden = np.where(np.isnan(prob_hidden), hidden, prob_hidden)
    return rng.random((c, t)) < prob_hidden


# --------------------------------------------------------------------------
# starts


def dispersed_starts(data: il.JointData, lay: Layout, n_chains: int, rng):
    """States (C, D) from which the chains start: gamma stratified over
    (0.03, 0.97) and log n over its prior range, one per chain; every
    facet's scale and noise level fitted at that pair with the frames of
    :func:`~bayesgloss.sampling.joint.starting_frames`; the frames' latents
    jittered; m and tau from the scales; the day's sun weights even."""
    lam0 = starting_frames(data)
    c = n_chains
    gamma = (np.arange(c) + rng.random(c)) / c * 0.94 + 0.03
    lo, hi = lay.bounds["log_n"]
    log_n = lo + (hi - lo) * (0.1 + 0.8 * rng.permutation((np.arange(c) + rng.random(c)) / c))
    th = np.zeros((c, lay.f, 4))
    th[..., 0], th[..., 1] = gamma[:, None], log_n[:, None]
    lam = np.broadcast_to(lam0, (c, *lam0.shape)).copy()
    lam[..., lay.free] += 0.05 * rng.standard_normal(lam[..., lay.free].shape)
    unit = il.predict(th[:, :, None, :3] * [1, 1, 0], lam[:, None], data)[:, :, 0]  # s = 1
    wts = data.relative_weights[None]
    num = np.sum(wts * data.y[None] * unit, -1)
    den = np.maximum(np.sum(wts * unit * unit, -1), 1e-300)
    scale = np.maximum(num / den, 1e-300)
    th[..., 2] = np.log(scale) + 0.02 * rng.standard_normal(scale.shape)
    mu = scale[..., None] * unit
    z = np.where(data.valid, (data.y - mu) / (mu + data.floor[:, None]), 0.0)
    rms = np.sqrt(np.sum(z * z, -1) / np.maximum(data.valid.sum(1), 1))
    lo_s, hi_s = lay.bounds["log_sigma"]
    th[..., 3] = np.clip(np.log(np.maximum(rms, 1e-4)), lo_s + 0.1, hi_s - 0.1)
    hyper = np.zeros((c, 4))
    hyper[:, 0] = th[..., 2].mean(1)
    lo_t, hi_t = lay.bounds["log_tau"]
    hyper[:, 1] = np.clip(np.log(np.maximum(th[..., 2].std(1), 1e-3)), lo_t + 0.1, hi_t - 0.1)
    return state_of(th, hyper, lam, lay)


# --------------------------------------------------------------------------
# the sampler


class _DualAveraging:
    """Step-size adaptation of Hoffman & Gelman (2014), algorithm 5."""

    def __init__(self, step: float):
        self.restart(step)

    def restart(self, step: float) -> None:
        self.mu = np.log(10 * step)
        self.h_bar, self.log_bar, self.count = 0.0, np.log(step), 0
        self.step = step

    def update(self, acceptance: float) -> None:
        self.count += 1
        n = self.count
        eta = 1.0 / (n + 10)
        self.h_bar = (1 - eta) * self.h_bar + eta * (TARGET_ACCEPTANCE - acceptance)
        log_step = self.mu - np.sqrt(n) / 0.05 * self.h_bar
        weight = n**-0.75
        self.log_bar = weight * log_step + (1 - weight) * self.log_bar
        self.step = float(np.exp(log_step))

    @property
    def final(self) -> float:
        return float(np.exp(self.log_bar))


def _transition(z, lp, gz, chol, center, step, n_leap, data, lay, hidden, pseudo, rng):
    """One HMC iteration of every chain in whitened coordinates z (C, D)
    (x = center + z chol^T), the hidden suns fixed: (z, lp, grad_z,
    acceptance probability (C,))."""

    def density(zz):
        value, gx = log_density_and_gradient(center + zz @ chol.T, data, lay, hidden, pseudo)
        return value, gx @ chol

    p = rng.standard_normal(z.shape)
    h0 = lp - 0.5 * np.sum(p * p, -1)
    zn, gn = z.copy(), gz.copy()
    p = p + 0.5 * step * gn
    for i in range(n_leap):
        zn = zn + step * p
        lpn, gn = density(zn)
        if i < n_leap - 1:
            p = p + step * gn
    p = p + 0.5 * step * gn
    h1 = lpn - 0.5 * np.sum(p * p, -1)
    with np.errstate(invalid="ignore", over="ignore"):
        log_accept = np.where(np.isfinite(h1), np.minimum(h1 - h0, 0.0), -np.inf)
    prob = np.exp(log_accept)
    ok = np.log(rng.random(len(z))) < log_accept
    return (
        np.where(ok[:, None], zn, z),
        np.where(ok, lpn, lp),
        np.where(ok[:, None], gn, gz),
        prob,
    )


def _diagonal_scale(x, data, lay, hidden):
    """A first metric: each coordinate's sd from the curvature of the log
    density at the chains' starts (finite differences of the gradient), (D,)."""
    d = x.shape[1]
    curv = np.zeros(d)
    for i in range(d):
        hstep = 1e-4 * max(1.0, float(np.mean(np.abs(x[:, i]))))
        xp, xm = x.copy(), x.copy()
        xp[:, i] += hstep
        xm[:, i] -= hstep
        gp = log_density_and_gradient(xp, data, lay, hidden)[1][:, i]
        gm = log_density_and_gradient(xm, data, lay, hidden)[1][:, i]
        curv[i] = np.median(-(gp - gm) / (2 * hstep))
    return 1.0 / np.sqrt(np.clip(curv, 1e-2, 1e10))


def _pseudo_prior(log_a, hidden, previous, min_shown: int = 20):
    """Each frame's pseudo-prior of log a where its sun is hidden, from a
    window's draws (S, C, T): the normal of its draws where the sun shows
    (sd at least 0.02), so that log a has about the same spread whichever
    state a chain is in (the dense metric is shared by all chains: a frame
    hidden in some chains and pinned by the data in others made log a's
    metric variance ~1e5 times its curvature in those, and the step size
    fell to 0.004); frames shown in fewer than ``min_shown`` draws keep the
    previous one."""
    shown = ~hidden
    n = shown.sum((0, 1))
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(shown, log_a, 0.0).sum((0, 1)) / n
        var = np.where(shown, (log_a - mean) ** 2, 0.0).sum((0, 1)) / np.maximum(n - 1, 1)
    ok = n >= min_shown
    return (
        np.where(ok, mean, previous[0]),
        np.where(ok, np.maximum(np.sqrt(var), 0.02), previous[1]),
    )


def _draw(pseudo, shape, rng):
    """Draws of log a from the pseudo-priors, (..., T)."""
    return pseudo[0] + pseudo[1] * rng.standard_normal(shape)


def _metric(draws, previous):
    """The dense metric's Cholesky factor from a window's draws (S, C, D):
    their within-chain covariance, shrunk toward its diagonal as Stan
    does, n / (n + 5) S + 1e-3 5 / (n + 5) diag."""
    x = draws - draws.mean(0, keepdims=True)
    n = x.shape[0] * x.shape[1]
    cov = np.einsum("scd,sce->de", x, x) / max(n - x.shape[1], 1)
    diag = np.diag(np.diag(cov))
    cov = n / (n + 5.0) * cov + 5.0 / (n + 5.0) * (1e-3 * diag + 1e-9 * np.eye(len(cov)))
    try:
        return np.linalg.cholesky(cov)
    except np.linalg.LinAlgError:
        return previous


def sample_material_hmc(
    data: il.JointData,
    *,
    n_chains: int = 8,
    min_draws: int = 400,
    max_draws: int = 4000,
    chunk: int = 200,
    draws_per_chain: int = 500,
    seed: int | None = 0,
    progress=None,
) -> JointSamples:
    """Sample the one-material model by Hamiltonian Monte Carlo (module docstring).

    Parameters
    ----------
    data : bayesgloss.illumination.JointData
    n_chains : int
        Chains from dispersed starts (R-hat needs several).
    min_draws, max_draws : int
        Iterations per chain after the warm-up: at least ``min_draws``, then
        ``chunk`` more at a time until converged, at most ``max_draws``.
    draws_per_chain : int
        Draws kept per chain (evenly thinned).
    seed : int or None
    progress : callable(done, total) or None

    Returns
    -------
    JointSamples
        ``draws`` (F, C, S, 4): gamma and log n shared, each facet's log s
        and log sigma; ``frames`` (C, S, T, L); ``material`` (C, S, 4): m,
        log tau, the day's sun weights v; ``rhat``, ``ess_bulk``,
        ``ess_tail`` of gamma, then every frame's log a, then log b; the
        rule also covers the log posterior (``acceptance["lp_rhat"]``);
        ``acceptance`` holds the mean acceptance probability, the step size
        and leapfrog steps per iteration.
    """
    if n_chains < 2:
        raise ValueError(f"need at least 2 chains, got {n_chains}")
    rng = np.random.default_rng(seed)
    t0 = time.perf_counter()
    lay = layout(data)
    x = dispersed_starts(data, lay, n_chains, rng)
    hidden = np.zeros((n_chains, lay.t), bool)
    q = data.frame_priors
    pseudo = (np.full(lay.t, q.sun_cloud_mean), np.full(lay.t, q.sun_cloud_sd))
    a_index = lay.frames.start + int(lay.free[0]) + np.arange(lay.t) * lay.k  # each log a
    center = np.zeros(lay.size)
    chol = np.diag(_diagonal_scale(x, data, lay, hidden))

    def whiten(xx):
        return np.linalg.solve(chol, (xx - center).T).T

    def evaluate(zz):
        value, gx = log_density_and_gradient(center + zz @ chol.T, data, lay, hidden, pseudo)
        return value, gx @ chol

    z = whiten(x)
    lp, gz = evaluate(z)
    adapt = _DualAveraging(0.1)
    accepted = []
    iteration = 0

    def leapfrogs(step):
        n = TRAJECTORY / step
        return int(
            np.clip(rng.integers(max(1, int(0.6 * n)), max(2, int(1.4 * n) + 1)), 1, MAX_LEAPFROG)
        )

    def run(n_iter, adapting, keep=None):
        nonlocal z, lp, gz, iteration, hidden
        for _ in range(n_iter):
            step = (adapt.step if adapting else adapt.final) * rng.uniform(0.9, 1.1)
            z, lp, gz, prob = _transition(
                z, lp, gz, chol, center, step, leapfrogs(step), data, lay, hidden, pseudo, rng
            )
            hidden = hidden_step(center + z @ chol.T, hidden, data, lay, rng, pseudo)
            lp, gz = evaluate(z)
            if adapting:
                adapt.update(float(np.mean(prob)))
            else:
                accepted.append(float(np.mean(prob)))
            if keep is not None:
                keep.append((center + z @ chol.T, hidden.copy()))
            iteration += 1

    # warm-up
    for k, length in enumerate(WARMUP_WINDOWS):
        window = []
        run(length, True, window)
        if k >= 1 or length >= 50:
            part = window[len(window) // 2 :] if k == 0 else window
            xs = np.stack([w for w, _ in part])
            hs = np.stack([h for _, h in part])
            pseudo = _pseudo_prior(xs[..., a_index], hs, pseudo)
            # a hidden sun's log a is its pseudo-prior's draw: drawn anew
            # from the new one, in the window (for the metric) and the state
            xs[..., a_index] = np.where(hs, _draw(pseudo, hs.shape, rng), xs[..., a_index])
            new_chol = _metric(xs, chol)
            x_now = center + z @ chol.T
            x_now[:, a_index] = np.where(
                hidden, _draw(pseudo, hidden.shape, rng), x_now[:, a_index]
            )
            center, chol = xs.reshape(-1, lay.size).mean(0), new_chol
            z = whiten(x_now)
            lp, gz = evaluate(z)
            adapt.restart(adapt.final)
    run(WARMUP_TAIL, True)
    warmup = iteration

    # sampling
    kept = []
    diag = None
    while True:
        run(chunk, False, kept)
        if progress:
            progress(len(kept), max_draws)
        if len(kept) >= min_draws:
            diag = _diagnose(kept, data, lay, pseudo)
            if diag[3] or len(kept) >= max_draws:
                break
    xs = np.stack([x for x, _ in kept])  # (S, C, D)
    hs = np.stack([h for _, h in kept])  # (S, C, T)
    pick = np.linspace(0, len(xs) - 1, min(len(xs), draws_per_chain)).round().astype(int)
    xs, hs = xs[pick], hs[pick]
    s, c = xs.shape[:2]
    th, hyper, lam = natural(xs.reshape(s * c, -1), lay, data)
    lam[..., 1] = np.where(hs.reshape(s * c, -1), -np.inf, lam[..., 1])
    th = th.reshape(s, c, lay.f, 4).transpose(2, 1, 0, 3)  # (F, C, S, 4)
    lam = lam.reshape(s, c, lay.t, -1).transpose(1, 0, 2, 3)  # (C, S, T, L)
    hyper = hyper.reshape(s, c, 4).transpose(1, 0, 2)
    rhat, ess_bulk, ess_tail, converged, lp_rhat = diag
    return JointSamples(
        th,
        lam,
        rhat,
        ess_bulk,
        ess_tail,
        bool(converged),
        iteration,
        {
            "hmc": float(np.mean(accepted)) if accepted else float("nan"),
            "step": adapt.final,
            "leapfrog": TRAJECTORY / adapt.final,
            "warmup": warmup,
            "lp_rhat": lp_rhat,
        },
        time.perf_counter() - t0,
        material=hyper,
    )


def _diagnose(kept, data, lay, pseudo):
    """The convergence rule over the kept (state, hidden) pairs (S of (C, D)
    and (C, T)), for gamma, every frame's sun a (0 where hidden) and log b,
    and the log posterior: (rhat, ess_bulk, ess_tail of gamma, the frames'
    a, then log b; whether the rule holds for all of them (a quantity that
    never changes, a sun hidden in every draw, holds it) and the log
    posterior; R-hat of the log posterior)."""
    xs = np.stack([x for x, _ in kept])
    hs = np.stack([h for _, h in kept])
    s, c, _ = xs.shape
    flat, flat_h = xs.reshape(s * c, -1), hs.reshape(s * c, -1)
    th, _, lam = natural(flat, lay, data)
    sun = np.where(flat_h, 0.0, np.exp(lam[..., 1]))
    gamma = th[:, 0, 0].reshape(s, c).T[None]
    lat = np.stack([sun, lam[..., 2]]).reshape(2, s, c, lay.t).transpose(0, 3, 2, 1)
    lp = log_density_and_gradient(flat, data, lay, flat_h, pseudo)[0].reshape(s, c).T[None]
    x = np.concatenate([gamma, lat.reshape(2 * lay.t, c, s), lp])
    rhat, eb, et, ok = diagnostics.diagnose(x)
    ok |= np.ptp(x, axis=(1, 2)) == 0
    return rhat[:-1], eb[:-1], et[:-1], bool(np.all(ok)), float(rhat[-1])

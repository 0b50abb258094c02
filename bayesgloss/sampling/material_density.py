"""The one-material model's log density and gradient in unconstrained coordinates.

For :mod:`bayesgloss.sampling.hamiltonian`: the state of a chain as one
vector (:class:`Layout`), bounded coordinates (gamma, log n, each facet's
log sigma, log tau) as logits, x = lo + (hi - lo) / (1 + e^-eta), with the
Jacobian log((hi - lo) sigma(eta) (1 - sigma(eta))) in the density; the
model that of :mod:`bayesgloss.illumination` (one material,
:func:`~bayesgloss.illumination.log_prior_material`; each frame's latents,
:func:`~bayesgloss.illumination.log_prior_frames` with ``point_mass``: a
hidden sun is a = 0), each facet's sigma a coordinate so that the density is
a sum over entries; its gradient in closed form from the bilinear model
(:func:`log_density_and_gradient`); each frame's hidden-sun indicator drawn
from its conditional (:func:`hidden_step`); dispersed starts
(:func:`dispersed_starts`).

Its noise is a sigma for each facet, the one-material model as it was in
stop 24; the default sampler's model has had one sigma for all facets
since (:func:`bayesgloss.illumination.log_likelihood_shared_sigma` says
why), which this module does not follow yet.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import illumination as il
from .. import likelihood as lk
from .joint import starting_frames

__all__ = [
    "Layout",
    "layout",
    "natural",
    "state_of",
    "log_density_and_gradient",
    "hidden_step",
    "dispersed_starts",
]


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
    return th, hyper, _frame_latents(state, lay, data)


def _frame_latents(state, lay: Layout, data: il.JointData):
    """Each frame's latents of states (C, D), (C, T, L): the free ones from
    the state, a known exposure from the data (other fixed slots 0)."""
    lam = np.zeros((state.shape[0], lay.t, len(lay.free)))
    lam[..., lay.free] = state[:, lay.frames].reshape(state.shape[0], lay.t, lay.k)
    if data.exposure_known:
        lam[..., 0] = data.log_exposure
    return lam


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
    lam = _frame_latents(state, lay, data)
    log_e = lam[..., 0]
    shapes = data.shapes
    sources = 1 + shapes if shapes >= 2 else 2
    gamma = out["gamma"][0]
    grid = data.log_n_grid
    h = grid[1] - grid[0]
    j, w = lk.grid_position(out["log_n"][0], grid)
    w = w[:, None, None, None]
    g_lo = np.moveaxis(data.glossy[:sources][:, :, j, :], 2, 0)  # (C, P, F, T)
    g_hi = np.moveaxis(data.glossy[:sources][:, :, j + 1, :], 2, 0)
    d = data.diffuse[:sources][None]
    g_n = g_lo + w * (g_hi - g_lo)
    gam = gamma[:, None, None, None]
    out["du_dgamma"] = g_n - d
    out["du_dlogn"] = gam * (g_hi - g_lo) / h
    unit = d + gam * out["du_dgamma"]
    if shapes >= 2:
        shape_w = np.exp(il.log_shape_weights(lam))  # (C, T, K)
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


def _sun_components(log_a, hyper, hidden, q, pseudo=None):
    """Each frame's sun prior by component, (C, T, 3), given the day's weights
    (:func:`~bayesgloss.illumination.log_sun_weights` of ``hyper``): clear
    and dimmed where the sun shows, and where it is hidden the hidden
    weight with the pseudo-prior of log a (``pseudo``, each frame's mean
    and sd, (T,) each; None: the dimmed component's normal): log a is then
    a coordinate the likelihood ignores (Carlin & Chib 1995, "Bayesian
    model choice via Markov chain Monte Carlo", JRSS B 57); -inf for the
    components the frame is not in; and the means and sds of log a by
    component, (T, 3) each, and the day's log weights."""
    log_day = il.log_sun_weights(hyper)  # (C, 3)
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
    m = state[:, o]
    log_tau, dlt, jt, djt = _bounded(state[:, o + 1], lay.bounds["log_tau"])
    tau2 = np.exp(2 * log_tau)
    dev = log_s - m[:, None]
    c0 = il.material_m_center(data)
    lp = -0.5 * np.sum(dev**2, 1) / tau2 - f * log_tau
    lp -= 0.5 * ((m - c0) / il.MATERIAL_M_SD) ** 2
    comp, means, sds, log_day = _sun_components(log_a, state[:, lay.hyper], hidden, q, pseudo)
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
    q = data.frame_priors
    log_a, hyper = mod["lam"][..., 1], state[:, lay.hyper]
    shown_c = _sun_components(log_a, hyper, np.zeros((c, t), bool), q, pseudo)[0]
    hidden_c = _sun_components(log_a, hyper, np.ones((c, t), bool), q, pseudo)[0]
    p_shown = np.logaddexp(shown_c[..., 0], shown_c[..., 1]) + ll_shown
    p_hidden = hidden_c[..., 2] + ll_hidden
    with np.errstate(invalid="ignore", over="ignore"):
        prob_hidden = 1.0 / (1.0 + np.exp(np.clip(p_shown - p_hidden, -700, 700)))
    prob_hidden = np.where(np.isfinite(p_shown) | np.isfinite(p_hidden), prob_hidden, 0.0)
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

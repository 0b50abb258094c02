"""Starting walkers: spread over the profile likelihood of n, never flat.

A vectorised start for every facet: least squares on the exponent grid
(:func:`bayesgloss.sampling.coordinates.node_fits`), walkers spread over the
profile likelihood of n (so that a second mode in n is populated from the
start), and bounded coordinates reflected into their range, so that no
ensemble starts in a flat subspace that moves built from walker differences
never leave. :func:`starting_material` is the one-material sampler's start
(:mod:`bayesgloss.sampling.material`): one (gamma, n) for every facet on a
grid, and each facet's scale at it.
"""

from __future__ import annotations

import numpy as np

from .. import fresnel as fr
from .. import illumination as il
from .. import likelihood as lk
from .coordinates import node_fits

__all__ = ["initial_ensemble", "starting_material", "start_theta", "START_FRESNEL_GRID"]

#: The Fresnel strengths k and normal-incidence albedos A over which
#: :func:`starting_material` profiles gamma and n where the data carry
#: Fresnel terms; the one-material chain's walkers start about the best.
START_FRESNEL_GRID = tuple(
    (k, a) for k in (0.0, 0.5, 1.0) for a in (0.03, 0.06, 0.12, 0.25, 0.5, 1.0)
)


def initial_ensemble(data: lk.CurveData, n_walkers: int, rng) -> np.ndarray:
    """Starting walkers (B, W, P) near the likelihood's optimum.

    For each exponent on the basis grid, weighted least squares
    (:func:`node_fits`) gives gamma and s in closed form; walkers are spread
    over the grid's exponents in proportion to the profile likelihood of n
    (so that a second mode in n is populated from the start), with a small
    ball in every coordinate. A fit with no positive scale (a curve of pure
    noise) starts from the prior centre of s.
    """
    a, bb, rms = node_fits(data)
    s_fit = a + bb
    s = np.where(s_fit > 0, s_fit, np.exp(data.log_s_center)[:, None])
    gamma = np.where(s_fit > 0, np.clip(bb / np.maximum(s_fit, 1e-300), 0.0, 1.0), 0.5)
    n_valid = np.maximum(data.valid.sum(1), 1)[:, None]
    if data.noise == "gaussian":
        sig = np.maximum(rms, 1e-12)
    else:
        sig = np.clip(
            rms, np.exp(data.priors.log_sigma[0]) * 1.5, np.exp(data.priors.log_sigma[1]) * 0.5
        )
    profile = -n_valid * np.log(np.maximum(sig, 1e-300))  # (B, N)
    prob = np.exp(profile - profile.max(1, keepdims=True))
    prob /= prob.sum(1, keepdims=True)
    b_count = len(data.y)
    cum = np.cumsum(prob, axis=1)
    u = rng.random((b_count, n_walkers))
    node = np.minimum((u[..., None] > cum[:, None, :]).sum(-1), prob.shape[1] - 1)  # (B, W)
    take = np.take_along_axis
    p = data.n_params
    th = np.empty((b_count, n_walkers, p))
    dx = data.log_n_grid[1] - data.log_n_grid[0]
    # bounded coordinates are reflected into their range, never clipped: walkers
    # clipped onto one value (gamma = 0 for a matt fit) would leave the ensemble
    # in a flat subspace that its moves, built from walker differences, never leave
    th[..., 0] = _reflect(take(gamma, node, 1) + 0.02 * rng.standard_normal(node.shape), 0.0, 1.0)
    th[..., 1] = _reflect(
        data.log_n_grid[node] + 0.3 * dx * rng.standard_normal(node.shape), *data.priors.log_n
    )
    th[..., 2] = np.log(take(s, node, 1)) + 0.02 * rng.standard_normal(node.shape)
    th[..., 3] = _reflect(
        np.log(take(sig, node, 1)) + 0.05 * rng.standard_normal(node.shape),
        *data.priors.log_sigma,
    )
    if p == 5:
        th[..., 4] = 0.05 + 0.02 * rng.random(node.shape)
    return th


def _reflect(x, lo: float, hi: float):
    """x folded into (lo, hi) by reflection at the bounds (distinct values stay
    distinct), kept 1e-9 of the width inside them."""
    width = hi - lo
    u = np.mod(x - lo, 2.0 * width)
    u = np.where(u > width, 2.0 * width - u, u)
    return lo + np.clip(u, 1e-9 * width, (1 - 1e-9) * width)


def _robust_scales(s, axis: int = 0, spread: float = 6.0) -> np.ndarray:
    """Least-squares scales kept within e^+-``spread`` of their median along
    ``axis`` (the facets): a facet whose noise swamps its curve can have a
    scale <= 0 by least squares, which a floor at 1e-300 turned into log s =
    -690, a start no walker left (found on a third of the one-material SBC's
    prior draws, where sigma reaches 2)."""
    ok = np.isfinite(s) & (s > 0)
    log_s = np.log(np.where(ok, s, 1.0))
    # the median of the positive scales (0 where none is): sorted with the
    # others pushed to +inf, taken at the middle of each row's positive count
    count = ok.sum(axis=axis, keepdims=True)
    ordered = np.sort(np.where(ok, log_s, np.inf), axis=axis)
    middle = np.take_along_axis(ordered, np.maximum(count - 1, 0) // 2, axis=axis)
    mid = np.where(count > 0, middle, 0.0)
    log_s = np.where(ok, np.clip(log_s, mid - spread, mid + spread), mid)
    return np.exp(log_s)


def starting_material(data: il.JointData, lam) -> tuple[float, float, np.ndarray, tuple | None]:
    """One material's best (gamma, log n) on a grid given the frames ``lam``
    (T, L), each facet's log s at it, (F,), and where the data carry Fresnel
    terms the best strength and normal-incidence albedo (k, A) of
    :data:`START_FRESNEL_GRID` (else None): weighted least squares of every
    facet's scale at each grid point, the point with the smallest total
    weighted residual kept.

    The Fresnel model's own predictions, not the lobe's without a rise: a
    Fresnel-free start takes a coating's grazing rise for gloss (0.9 for a
    true 0.35 on a seen box, stop 74), and so does one at a k and A far from
    the data's (0.8 there at k 1/2, A 0.3); a chain slow to leave its start
    then reads high."""
    n = len(data.log_n_grid)
    gam = np.linspace(0.0, 1.0, 41)
    frames = lam[None, None].repeat(n, 1)
    w = data.relative_weights
    best, best_r = (0.5, data.log_n_grid[n // 2], data.log_s_center.copy(), None), np.inf
    for fresnel in START_FRESNEL_GRID if data.fresnel is not None else (None,):
        for g, mu in zip(gam, _grid_predictions(data, frames, gam, fresnel), strict=True):
            num = np.sum(w[:, None] * data.y[:, None] * mu, -1)
            den = np.maximum(np.sum(w[:, None] * mu * mu, -1), 1e-300)
            s = _robust_scales(num / den)
            r = np.sum(w[:, None] * (data.y[:, None] - s[..., None] * mu) ** 2, -1).sum(0)  # (N,)
            j = int(np.argmin(r))
            if r[j] < best_r:
                best_r = r[j]
                best = (float(g), float(data.log_n_grid[j]), np.log(s[:, j]), fresnel)
    g, log_n, log_s, fresnel = best
    return min(max(g, 0.01), 0.99), log_n, log_s, fresnel


def _grid_predictions(data: il.JointData, frames, gam, fresnel):
    """mu (F, N, T) at each gamma of ``gam`` over the exponent grid, with the
    Fresnel (k, A) ``fresnel`` (None: no Fresnel columns): mu is affine in
    gamma at a fixed k and A (:func:`bayesgloss.fresnel.fresnel_parts` and
    :func:`~bayesgloss.fresnel.fresnel_parts_in_lobe` are), so two predictions
    suffice."""
    f, n = data.shape[0], len(data.log_n_grid)
    th = start_theta(f, n, fresnel)
    th[..., 1] = data.log_n_grid[None, None, :]
    ends = []
    for g in (0.0, 1.0):
        th[..., 0] = g
        ends.append(il.predict(th, frames, data)[0])
    for g in gam:
        yield (1 - g) * ends[0] + g * ends[1]


def start_theta(f: int, w: int, fresnel: tuple | None = None) -> np.ndarray:
    """Zeros (1, F, W, C) of the model's coordinates: 3, or 6 with the
    Fresnel strength and normal-incidence albedo ``fresnel`` = (k, A) in
    their columns (:data:`bayesgloss.fresnel.FRESNEL_COLUMNS`)."""
    if fresnel is None:
        return np.zeros((1, f, w, 3))
    th = np.zeros((1, f, w, 6))
    k_col, a_col = fr.FRESNEL_COLUMNS
    th[..., k_col], th[..., a_col] = fresnel[0], np.log(fresnel[1])
    return th

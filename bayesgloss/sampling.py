"""Posterior sampling: emcee's ensemble moves, batched over many facets at once.

The paper's study alone needs thousands of facet posteriors. Stock emcee
runs one problem at a time and its per-step overhead dominates for a
19-frame likelihood. :class:`BatchedEnsemble` runs B independent problems
(facets, or independent ensembles of one facet) in lockstep through one
vectorised log-probability call per half-step:

- ``stretch``: the affine-invariant stretch move of Goodman & Weare (2010),
  as emcee's ``StretchMove`` implements it: walkers split at random into two
  halves; a walker X_k of one half moves to Y = X_j + z (X_k - X_j) with X_j
  drawn from the other half and z from g(z) ~ 1/sqrt(z) on [1/a, a], a = 2,
  accepted with probability min(1, z^(P-1) p(Y) / p(X_k));
- ``de``: differential evolution (ter Braak 2006; Nelson et al. 2013, as
  emcee's ``DEMove``): Y = X_k + gamma (X_i - X_j) for two distinct walkers
  of the other half, gamma = gamma0 (1 + 1e-5 N(0, 1)), gamma0 = 2.38 /
  sqrt(2 P): efficient along banana-shaped ridges;
- ``de-jump``: the same with gamma0 = 1, which carries walkers between modes;
- ``n-jump``: an independence proposal in log n from each facet's
  posterior of log n on cells (:class:`ExponentJump`), for posteriors with
  separated modes in n, which the moves above, built from walker
  differences, rarely cross;
- ``ridge-jump``: for facets in :class:`RidgeCoordinates`, an independence
  proposal of the whole point (log n as the n-jump draws it, the ridge
  offsets from a bivariate t about the least-squares fit at that n); for
  the others the n-jump with probability ``PLAIN_JUMP`` = 1/3, DE otherwise.

The mix is chosen per step for all problems, as emcee chooses one move per
step: ``DEFAULT_MOVES`` (stretch 0.2, de 0.7, de-jump 0.1) for any target,
``FACET_MOVES`` (stretch 0.2, de 0.4, de-jump 0.1, ridge-jump 0.3) for
facets, which is (stretch 0.2, de 0.6, de-jump 0.1, n-jump 0.1) for a facet
in plain coordinates. On the paper's facets the median integrated
autocorrelation time was 62 steps with the stretch move alone, 29 with
(0.5, 0.4, 0.1) and 21-23 with DE-dominated mixes. On 600 facets drawn
from the prior, the n-jump (with starts reflected, not clipped, into
bounded ranges) took the facets at the 8000-step cap from 14 to 1 and the
99th percentile of the run length from 8000 to 2350 steps; the ridge-jump
took the median autocorrelation time of facets in ridge coordinates from
13.7 to 5.5 steps, and the mean run of the paper's facets from 1230 to 430
steps. The randomness comes from one ``numpy.random.Generator``; problems
never share walkers, so each problem's chain is a chain of emcee's
algorithm for it with the same moves.

:func:`sample_posterior` drives it, per facet:

1. what it samples: for Gaussian noise with a linear camera, sigma is
   integrated out exactly (:func:`bayesgloss.likelihood.log_likelihood_sigma_marginal`)
   and drawn afterwards from its conditional posterior, so the ensembles
   explore (gamma, log n, log s) only; facets whose curves leave a relative
   rms below 100 % are sampled in :class:`RidgeCoordinates`, which straighten
   the thin curved ridge along log n that low noise makes (on prior draws,
   the 90th percentile of the autocorrelation time fell from 66 to 35
   steps, and facets stopped at the step cap from 8 % to 1 %) and the
   funnel of a near-matt facet, whose gamma is pinned near 0 more tightly
   at some exponents than at others (raising the threshold from 5 % to
   30 % took the paper's facets at the step cap from 2 to 0 and their 99th
   percentile of run length from 3770 to 3350 steps; with the ridge-jump,
   from 30 % to 100 % cut the mean run of the facets above 30 % by a
   quarter on prior draws and by 45 % on the paper's);
2. a vectorised start (least squares on the exponent grid, walkers spread
   over the profile likelihood of n, bounded coordinates reflected into
   their range so that no ensemble starts flat);
3. facets in plain coordinates (the broadest posteriors, the longest runs)
   first, so that they run beside the others rather than at the end in a
   nearly empty batch; burn-in of at least 5 autocorrelation times;
4. production until the run is at least ``min_tau_multiple`` integrated
   autocorrelation times (emcee's estimator: walker-averaged autocorrelation,
   Sokal's window c = 5, pooled over the facet's ensembles) and gamma has
   converged across several independent ensembles by ArviZ's criteria
   (R-hat < 1.01, bulk and tail ESS >= 400; :func:`rank_diagnostics`
   computes ArviZ's statistics for all facets due at once), or to the step
   cap, flagged.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from scipy import special

from . import likelihood as lk

__all__ = [
    "BatchedEnsemble",
    "gamma_converged",
    "rank_diagnostics",
    "integrated_time",
    "initial_ensemble",
    "sample_posterior",
    "PosteriorSamples",
    "RidgeCoordinates",
    "DEFAULT_MOVES",
    "FACET_MOVES",
    "ExponentJump",
]

DEFAULT_MOVES = (("stretch", 0.2), ("de", 0.7), ("de-jump", 0.1))
#: The facet sampler's mix: the default plus independence jumps in log n
#: between the modes of its profile posterior (:class:`ExponentJump`).
FACET_MOVES = (("stretch", 0.2), ("de", 0.4), ("de-jump", 0.1), ("ridge-jump", 0.3))
#: In plain coordinates ``"ridge-jump"`` is the n-jump with this probability
#: and DE otherwise: there the facet mix is stretch 0.2, DE 0.6, DE-jump 0.1,
#: n-jump 0.1.
PLAIN_JUMP = 1.0 / 3.0


class BatchedEnsemble:
    """B independent affine-invariant ensembles advanced together.

    Parameters
    ----------
    log_prob : callable
        theta (B, K, P) -> log density (B, K); must accept any K.
    moves : sequence of (name, weight)
        From ``"stretch"``, ``"de"``, ``"de-jump"``, ``"n-jump"`` and
        ``"ridge-jump"`` (the last two need ``jump``).
    rng : numpy.random.Generator
    stretch_a : float
        Scale of the stretch move (emcee's default 2).
    jump : ExponentJump, optional
        The independence proposals of the ``"n-jump"`` and ``"ridge-jump"``
        moves, one per problem.
    """

    def __init__(self, log_prob, moves=DEFAULT_MOVES, rng=None, stretch_a: float = 2.0, jump=None):
        self.log_prob = log_prob
        self.jump = jump
        names = [m for m, _ in moves]
        bad = set(names) - {"stretch", "de", "de-jump", "n-jump", "ridge-jump"}
        if bad:
            raise ValueError(
                f"unknown move(s) {sorted(bad)}; valid: stretch, de, de-jump, n-jump, ridge-jump"
            )
        w = np.array([float(x) for _, x in moves])
        self.moves, self.weights = names, w / w.sum()
        # Generator.choice(p=...) draws one uniform and searches this cdf
        self._cdf = np.cumsum(self.weights)
        self._cdf /= self._cdf[-1]
        self.rng = rng if rng is not None else np.random.default_rng()
        self.a = stretch_a

    def _propose(self, move, s, c):
        """Proposals for walkers s (B, H, P) from the complementary half c (B, C, P).

        Walker indices are drawn as floor(u C) from uniforms (exactly uniform
        integers up to 2^-53), the cheapest draw for many small problems.
        """
        b, h, p = s.shape
        nc = c.shape[1]
        rng = self.rng
        if move == "n-jump":
            return self.jump.propose(s, rng)
        if move == "ridge-jump":  # whole-point jumps in ridge rows; n-jump or DE in others
            y, f = self.jump.propose(s, rng, fresh=True)
            yd, fd = self._propose("de", s, c)
            take = (self.jump.column == 0) | (rng.random(len(s)) < PLAIN_JUMP)
            return np.where(take[:, None, None], y, yd), np.where(take[:, None], f, fd)
        flat = c.reshape(b * nc, p)
        base = (np.arange(b) * nc)[:, None]  # first row of each problem in flat
        u = rng.random((2, b, h))
        if move == "stretch":
            z = ((self.a - 1.0) * u[0] + 1.0) ** 2 / self.a
            cj = np.take(flat, base + (u[1] * nc).astype(np.intp), axis=0)
            return cj - (cj - s) * z[..., None], (p - 1.0) * np.log(z)
        g0 = 1.0 if move == "de-jump" else 2.38 / np.sqrt(2.0 * p)
        i = (u[0] * nc).astype(np.intp)
        j = (i + 1 + (u[1] * (nc - 1)).astype(np.intp)) % nc  # distinct from i
        gamma = g0 * (1.0 + 1e-5 * rng.standard_normal((b, h, 1)))
        diff = np.take(flat, base + i, axis=0) - np.take(flat, base + j, axis=0)
        return s + gamma * diff, np.zeros((b, h))

    def step(self, coords, log_p, blob=None):
        """One step (both halves) in place; returns the acceptance mask (B, W).

        The random split into halves is shared by the B problems (it only
        decides which walkers move first); every other random number is
        drawn per problem and walker. Where ``log_prob`` returns (log p,
        blob), ``blob`` (B, W) keeps the blob of every walker's position.
        """
        w = coords.shape[1]
        # = rng.choice(len(moves), p=weights), the same draw without its overhead
        move = self.moves[int(self._cdf.searchsorted(self.rng.random(), side="right"))]
        order = self.rng.permutation(w)
        halves = (order[: w // 2], order[w // 2 :])
        accepted = np.zeros(log_p.shape, dtype=bool)
        for k in (0, 1):
            idx, cidx = halves[k], halves[1 - k]
            s = coords[:, idx]
            q, factor = self._propose(move, s, coords[:, cidx])
            lp_new = self.log_prob(q)
            if isinstance(lp_new, tuple):
                lp_new, blob_new = lp_new
            lp_old = log_p[:, idx]
            with np.errstate(invalid="ignore"):
                acc = np.log(self.rng.random(lp_new.shape)) < factor + lp_new - lp_old
            coords[:, idx] = np.where(acc[..., None], q, s)
            log_p[:, idx] = np.where(acc, lp_new, lp_old)
            if blob is not None:
                blob[:, idx] = np.where(acc, blob_new, blob[:, idx])
            accepted[:, idx] = acc
        return accepted

    def run(self, coords, n_steps: int, log_p=None, blob=None):
        """Advance ``n_steps``; returns (chain (n, B, W, P), log_p (n, B, W), acc rate (B,)).

        Where ``log_prob`` returns (log p, blob), the blobs of the chain's
        positions are left in ``self.blobs`` (n, B, W); pass the blobs of the
        starting positions with their ``log_p``.
        """
        coords = np.array(coords, dtype=float)
        if log_p is None:
            log_p, blob = _with_blob(self.log_prob(coords))
        log_p = np.array(log_p)
        blob = None if blob is None else np.array(blob, dtype=float)
        b, w, p = coords.shape
        if w < 2 * p or w % 2:
            raise ValueError(f"need an even number of walkers >= 2 x {p} dims, got {w}")
        chain = np.empty((n_steps, b, w, p))
        lps = np.empty((n_steps, b, w))
        self.blobs = None if blob is None else np.empty((n_steps, b, w))
        acc = np.zeros((b, w))
        for t in range(n_steps):
            acc += self.step(coords, log_p, blob)
            chain[t] = coords
            lps[t] = log_p
            if blob is not None:
                self.blobs[t] = blob
        return chain, lps, acc.mean(axis=1) / max(n_steps, 1)


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
    f = np.fft.rfft(x, n=_fast_length(2 * n), axis=-1)
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


def _fast_length(n: int) -> int:
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


def _node_fits(data: lk.CurveData, weights: bool = False):
    """Weighted least squares of the curve on (D, G_n) at every exponent node.

    mu = a D + b G_n with a, b >= 0 (the best single basis where the joint
    fit leaves the quadrant), i.e. gamma = b / (a + b), s = a + b. Weights:
    1 for gaussian noise; for relative noise 1 / (m + s f)^2, f the noise
    floor at unit scale, with m the model curve of a first pass (weighted by
    the diffuse curve at the prior centre of s), so that noisy or negative
    observations cannot drive the weights.

    Returns
    -------
    a, b, rms : ndarray (B, N)
        Coefficients and the weighted rms residual (relative for relative noise).
    w : ndarray (B, N, T)
        The final weights (with ``weights=True``).
    """
    y, valid = data.y, data.valid
    if data.camera == "power":
        y = np.maximum(y, 0.0)  # start from g = 1: code values treated as linear
    d = data.diffuse[:, None, :]
    g = data.glossy  # (B, N, T)
    floor = lk.FLOOR_FRACTION * data.diffuse_peak[:, None, None]
    s0 = np.exp(data.log_s_center)[:, None, None]
    if data.noise == "gaussian":
        w = np.broadcast_to(valid[:, None, :].astype(float), g.shape)
    else:
        w = np.broadcast_to(
            np.where(valid[:, None, :], 1.0 / (s0 * (d + floor)) ** 2, 0.0), g.shape
        )
    for _ in range(2 if data.noise != "gaussian" else 1):
        a, b = _nonnegative_pair(y[:, None, :], d, g, w)
        if data.noise != "gaussian":  # second pass: weights of the fitted curve
            fit = (a + b > 0)[..., None]
            s = np.where(fit, (a + b)[..., None], s0)
            m = np.where(fit, a[..., None] * d + b[..., None] * g, s0 * d)
            w = np.where(valid[:, None, :], 1.0 / (m + s * floor) ** 2, 0.0)
    mu = a[..., None] * d + b[..., None] * g
    n_valid = np.maximum(valid.sum(1), 1)[:, None]
    rms = np.sqrt(np.sum(w * (y[:, None, :] - mu) ** 2, -1) / n_valid)
    return (a, b, rms, w) if weights else (a, b, rms)


def _nonnegative_pair(y, d, g, w):
    """Weighted least squares y ~ a d + b g with a, b >= 0, closed form (last axis)."""
    dd = np.sum(w * d * d, -1)
    gg = np.sum(w * g * g, -1)
    dg = np.sum(w * d * g, -1)
    yd = np.sum(w * y * d, -1)
    yg = np.sum(w * y * g, -1)
    det = dd * gg - dg * dg
    with np.errstate(divide="ignore", invalid="ignore"):
        a = (yd * gg - yg * dg) / det
        b = (yg * dd - yd * dg) / det
        a_only = np.maximum(yd / dd, 0.0)
        b_only = np.maximum(yg / gg, 0.0)
    a_only, b_only = np.nan_to_num(a_only), np.nan_to_num(b_only)
    bad = ~np.isfinite(a) | ~np.isfinite(b) | (a < 0) | (b < 0)
    sse_a = np.sum(w * (y - a_only[..., None] * d) ** 2, -1)
    sse_b = np.sum(w * (y - b_only[..., None] * g) ** 2, -1)
    pick_a = sse_a <= sse_b
    a = np.where(bad, np.where(pick_a, a_only, 0.0), a)
    b = np.where(bad, np.where(pick_a, 0.0, b_only), b)
    return a, b


def initial_ensemble(data: lk.CurveData, n_walkers: int, rng) -> np.ndarray:
    """Starting walkers (B, W, P) near the likelihood's optimum.

    For each exponent on the basis grid, weighted least squares
    (:func:`_node_fits`) gives gamma and s in closed form; walkers are spread
    over the grid's exponents in proportion to the profile likelihood of n
    (so that a second mode in n is populated from the start), with a small
    ball in every coordinate. A fit with no positive scale (a curve of pure
    noise) starts from the prior centre of s.
    """
    a, bb, rms = _node_fits(data)
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


RIDGE_MAX_RMS = 1.0
#: The first convergence check comes after this many times ``min_tau_multiple``
#: steps (facets in ridge coordinates mix in about 5.5 steps, the others slower).
FIRST_CHECK_TAUS = 5.0


@dataclass(frozen=True)
class RidgeCoordinates:
    """Sampling coordinates that straighten a facet's posterior ridge.

    With little noise, gamma and s are known to a fraction of a percent at
    each exponent n but shift with n: the posterior is a thin curved ridge
    along log n, which the affine-invariant moves cross slowly (integrated
    autocorrelation times of hundreds of steps). Writing the curve as
    mu = a D + b G(n), a = s (1 - gamma), b = s gamma, and, at each node of
    the exponent grid, (a, b) = c(n) + L(n) (u1, u2) with c(n) the weighted
    least-squares fit and L(n) the Cholesky factor of its covariance (at the
    best node's residual scale, the same for every n, and a weak ridge of
    sd s0 on a and b), both interpolated linearly in log n, gives
    coordinates x = (log n, u1, u2) in which that ridge is straight and of
    constant width. The map is exact and its Jacobian is carried:

        log p(x) = log p(theta) + log |L11 L22| - 2 log s,

    (d(gamma, log s) / d(a, b) has determinant -1 / s^2). Further
    coordinates (log sigma, log g) pass through unchanged. Facets whose best
    fit leaves a relative rms above ``max_rms`` (prior-dominated, broad
    posteriors) keep the plain coordinates x = theta; so do curves whose
    best fit is zero (noise above the signal: the rms of a zero curve says
    nothing of the noise) and curves with a non-linear camera.

    Attributes
    ----------
    log_n_grid : ndarray (N,)
    center : ndarray (B, N, 2)
        c(n) at the nodes.
    factor : ndarray (B, N, 3)
        L11, L21, L22 at the nodes.
    active : ndarray (B,) of bool
        Facets sampled in ridge coordinates.
    rms : ndarray (B,)
        The best node's weighted rms residual, the scale of L.
    """

    log_n_grid: np.ndarray
    center: np.ndarray
    factor: np.ndarray
    active: np.ndarray
    rms: np.ndarray

    @classmethod
    def of(cls, data: lk.CurveData, max_rms: float = RIDGE_MAX_RMS) -> RidgeCoordinates:
        """Coordinates for every facet of ``data`` (:func:`_node_fits` at each node)."""
        a, b, rms, w = _node_fits(data, weights=True)
        y = data.y[:, None, :]
        d, g = data.diffuse[:, None, :], data.glossy
        dd, gg, dg = np.sum(w * d * d, -1), np.sum(w * g * g, -1), np.sum(w * d * g, -1)
        yd, yg = np.sum(w * y * d, -1), np.sum(w * y * g, -1)
        best = np.argmin(rms, axis=1)[:, None]
        r2 = np.maximum(np.take_along_axis(rms, best, 1) ** 2, 1e-24)  # (B, 1)
        s_fit = np.take_along_axis(a + b, best, 1)
        s0 = np.where(s_fit > 0, s_fit, np.exp(data.log_s_center)[:, None])
        i11, i22, i12 = dd / r2 + s0**-2, gg / r2 + s0**-2, dg / r2
        det = i11 * i22 - i12 * i12
        c11, c22, c12 = i22 / det, i11 / det, -i12 / det  # covariance of (a, b)
        center = np.stack([c11 * yd + c12 * yg, c12 * yd + c22 * yg], axis=-1) / r2[..., None]
        l11 = np.sqrt(c11)
        l21 = c12 / l11
        l22 = np.sqrt(np.maximum(c22 - l21 * l21, 1e-30 * c22))
        factor = np.stack([l11, l21, l22], axis=-1)
        active = (
            (np.sqrt(r2[:, 0]) < max_rms)
            & (s_fit[:, 0] > 0)  # a curve the fit explains by nothing has no ridge
            & np.all(np.isfinite(center), axis=(1, 2))
            & np.all(np.isfinite(factor) & (factor[..., [0, 2]] > 0).all(-1)[..., None], (1, 2))
        )
        if data.camera != "linear":
            active[:] = False
        return cls(np.asarray(data.log_n_grid), center, factor, active, np.sqrt(r2[:, 0]))

    def take(self, index) -> RidgeCoordinates:
        idx = np.asarray(index)
        return RidgeCoordinates(
            self.log_n_grid, self.center[idx], self.factor[idx], self.active[idx], self.rms[idx]
        )

    @property
    def _nodes(self) -> tuple:
        """(c1, c2, L11, L21, L22) at every node, and their steps to the next
        node, each (5, B*N) (one contiguous row per quantity)."""
        nodes = self.__dict__.get("_nodes_cache")
        if nodes is None:
            v = np.concatenate([self.center, self.factor], axis=-1)  # (B, N, 5)
            nxt = np.concatenate([v[:, 1:], v[:, -1:]], axis=1)
            nodes = (
                np.ascontiguousarray(v.reshape(-1, 5).T),
                np.ascontiguousarray((nxt - v).reshape(-1, 5).T),
            )
            object.__setattr__(self, "_nodes_cache", nodes)
        return nodes

    @property
    def _offsets(self) -> np.ndarray:
        """First node row of each facet in :attr:`_nodes`, (B, 1)."""
        off = self.__dict__.get("_offsets_cache")
        if off is None:
            off = (np.arange(len(self.active)) * len(self.log_n_grid))[:, None]
            object.__setattr__(self, "_offsets_cache", off)
        return off

    def _at(self, log_n):
        """(c1, c2, L11, L21, L22) interpolated at log n (B, K): (5, B, K)."""
        b, k = log_n.shape
        j, w = lk.grid_position(log_n, self.log_n_grid)
        idx = (j + self._offsets).ravel()
        value, step = self._nodes
        v = np.take(value, idx, axis=1)
        v += w.ravel() * np.take(step, idx, axis=1)
        return v.reshape(5, b, k)

    @property
    def _active_flags(self) -> tuple[bool, bool]:
        """Whether any, and whether all, facets use ridge coordinates."""
        flags = self.__dict__.get("_flags")
        if flags is None:
            flags = (bool(self.active.any()), bool(self.active.all()))
            object.__setattr__(self, "_flags", flags)
        return flags

    def to_theta(self, x):
        """theta (B, K, P) and log |d theta / d x| (B, K) at x (B, K, P);
        NaN where x maps to no scale s > 0 (the caller's density is then -inf)."""
        x = np.asarray(x, dtype=float)
        any_active, all_active = self._active_flags
        if not any_active:
            return x, np.zeros(x.shape[:2])
        v = self._at(x[..., 0])
        a = v[0] + v[2] * x[..., 1]
        b = v[1] + v[3] * x[..., 1] + v[4] * x[..., 2]
        with np.errstate(invalid="ignore", divide="ignore"):
            s = a + b
            log_s = np.log(s)  # NaN (or -inf) where s <= 0
            th = np.empty(x.shape)
            th[..., 0] = b / s
            th[..., 1] = x[..., 0]
            th[..., 2] = log_s
            th[..., 3:] = x[..., 3:]
            log_jac = np.log(v[2] * v[4]) - 2.0 * log_s
        if all_active:
            return th, log_jac
        act = self.active[:, None, None]
        return np.where(act, th, x), np.where(act[..., 0], log_jac, 0.0)

    def from_theta(self, theta):
        """x (B, K, P) at theta (B, K, P) (the inverse of :meth:`to_theta`)."""
        th = np.asarray(theta, dtype=float)
        v = self._at(th[..., 1])
        s = np.exp(th[..., 2])
        a, b = s * (1.0 - th[..., 0]), s * th[..., 0]
        u1 = (a - v[0]) / v[2]
        u2 = (b - v[1] - v[3] * u1) / v[4]
        act = self.active[:, None]
        x = th.copy()
        x[..., 0] = np.where(act, th[..., 1], th[..., 0])
        x[..., 1] = np.where(act, u1, th[..., 1])
        x[..., 2] = np.where(act, u2, th[..., 2])
        return x

    def log_prob(self, log_prob, data: lk.CurveData):
        """The log density in these coordinates of a density ``log_prob(theta, data)``."""

        def in_x(x):
            th, log_jac = self.to_theta(x)
            out, blob = _with_blob(log_prob(th, data))  # a blob passes through
            with np.errstate(invalid="ignore"):
                out = out + log_jac  # NaN where s <= 0
            out = np.where(np.isnan(out), -np.inf, out)
            return out if blob is None else (out, blob)

        return in_x


@dataclass(frozen=True)
class ExponentJump:
    """Independence proposals in log n, for posteriors with several modes in n
    or a ridge along it.

    With a few frames a day, the glossy peak of a sharp lobe can fall
    between frames, and curves of quite different exponents fit almost
    equally well: the posterior of log n then has separated modes, which
    the ensemble moves (built from differences of walkers) rarely cross.
    This move proposes each walker's log n afresh from a fixed density q
    built from the facet's posterior of log n approximated on cells:

        q(x) = (1 - eps) q_m / h + eps / (prior width of log n),

    for x in cell m of a window of M cells of width h, q_m proportional to
    exp(l_m), l_m the log posterior density at the cell centre with gamma
    and s (and sigma, where it is sampled) at their weighted least-squares
    values c_m there; in ridge coordinates l_m also carries the Laplace
    volume of (gamma, log s) at that exponent, log |L11 L22| - 2 log s
    (:class:`RidgeCoordinates`), so that q follows the marginal, not the
    profile, posterior. The window is found on M cells over the prior range
    of log n and then spans the cells with density above e^-25 of the
    highest, plus one cell each side, on which l is computed again: a
    posterior narrower than a cell of the prior range (log n to 0.005 with
    little noise) is then resolved. The floor eps keeps every exponent
    reachable.

    The walker's other coordinates follow the fit: z' = z + c(m') - c(m) for
    a move from cell m to m' (in ridge coordinates c = 0: they already are
    offsets from the ridge at n). Given the two exponents this is a
    translation, whose reverse is the reverse move's, so Metropolis-Hastings
    with the independence factor q(x_n) / q(y_n) leaves the posterior
    invariant (Tierney 1994, "Markov chains for exploring posterior
    distributions", Ann. Stat. 22, sec. 2.3.3). With ``fresh``, the ridge
    offsets (u1, u2) of ridge-coordinate walkers are drawn afresh too, from
    a bivariate t with ``nu`` degrees of freedom (their conditional
    posterior is close to standard normal there), which makes the move an
    independence sampler of the whole point.

    Attributes
    ----------
    bounds : tuple of float
        The prior range of log n.
    floor : float
        eps.
    lo, width : ndarray (B,)
        Left edge of each window and its cell width h [log n].
    log_q : ndarray (B, M)
        log((1 - eps) q_m / h), the window part of log q in each cell.
    cdf : ndarray (B, M)
        Cumulative cell probabilities q_m (last exactly 1).
    fit : ndarray (B, M, P)
        c_m in each row's sampling coordinates (the log n column unused):
        plain ones from :meth:`of`; :meth:`take` puts ``ridge_fit`` in the
        rows it marks as ridge coordinates.
    column : ndarray (B,) of int
        The sampling coordinate that holds log n (0 in ridge coordinates,
        1 in plain ones).
    ridge_fit : ndarray (B, M, 3) or None
        c_m in ridge coordinates, (log n, u1, u2) (from :meth:`of` with
        ``ridge``; None after :meth:`take`).
    spread : ndarray (B,) or None
        Scale of the fresh ridge offsets: the noise (rms) at the best fine
        cell over the best node's, at most 1 (None: 1).
    """

    bounds: tuple
    floor: float
    lo: np.ndarray
    width: np.ndarray
    log_q: np.ndarray
    cdf: np.ndarray
    fit: np.ndarray
    column: np.ndarray
    ridge_fit: np.ndarray | None = None
    spread: np.ndarray | None = None

    @classmethod
    def of(
        cls,
        data: lk.CurveData,
        marginal: bool,
        cells: int = 400,
        floor: float = 0.1,
        block: int = 64,
        ridge: RidgeCoordinates | None = None,
    ) -> ExponentJump:
        """The proposal of every facet of ``data`` (plain coordinates; see
        :meth:`take` for ridge ones; ``ridge`` adds the Laplace volume to
        the facets it samples in ridge coordinates)."""
        lo0, hi0 = data.priors.log_n
        b = len(data.y)
        w_nodes = _node_fits(data, weights=True)[3]  # the fits' weights, once for both passes

        def on_cells(edges):
            """Cell width, relative posterior density (B, M), fits and Q at the
            centres of M cells between each row's edges."""
            width = (edges[:, 1] - edges[:, 0]) / cells
            centres = edges[:, :1] + width[:, None] * (np.arange(cells) + 0.5)
            parts = [
                _profile_log_posterior(
                    data.take(np.arange(i, min(i + block, b))), c, marginal, w_nodes[i : i + block]
                )
                for i, c in ((i, centres[i : i + block]) for i in range(0, b, block))
            ]
            log_post = np.concatenate([lp for (lp, _), _ in parts])
            fit = np.concatenate([th for _, th in parts])
            q = np.concatenate([q for (_, q), _ in parts]) if marginal else None
            if ridge is not None:  # the Laplace volume of (gamma, log s) at each n
                v = ridge._at(centres)
                with np.errstate(invalid="ignore", divide="ignore"):
                    volume = np.log(v[2] * v[4]) - 2.0 * fit[..., 2]
                log_post = np.where(ridge.active[:, None], log_post + volume, log_post)
            with np.errstate(invalid="ignore"):
                w = np.exp(log_post - np.max(log_post, axis=1, keepdims=True))
            return width, np.where(np.isfinite(w), w, 0.0), fit, q

        # the prior range first, then the cells above e^-25 of the peak and one each side
        width, w, _, _ = on_cells(np.tile([lo0, hi0], (b, 1)))
        keep = w > np.exp(-25.0)
        first = np.where(keep.any(1), np.argmax(keep, 1) - 1, 0)
        last = np.where(keep.any(1), cells - np.argmax(keep[:, ::-1], 1) + 1, cells)
        span = np.stack([np.maximum(first, 0), np.minimum(last, cells)], 1)
        edges = lo0 + width[:, None] * span
        width, w, fit, q = on_cells(edges)
        tot = w.sum(axis=1, keepdims=True)
        w = np.where(tot > 0, w / np.where(tot > 0, tot, 1.0), 1.0 / cells)
        cdf = np.cumsum(w, axis=1)
        cdf /= cdf[:, -1:]
        with np.errstate(divide="ignore"):
            log_q = np.log((1.0 - floor) * w / width[:, None])
        column = np.ones(b, dtype=int)
        ridge_fit = np.zeros(fit.shape[:2] + (3,))
        spread = np.ones(b)
        if ridge is not None and marginal:
            # the fits in ridge coordinates, and the scale of the offsets: the
            # noise at the best fine cell against the best node's, which the
            # node grid's interpolation error inflates
            with np.errstate(invalid="ignore", divide="ignore"):
                ridge_fit = ridge.from_theta(fit[..., :3])
                q_min = np.min(q, axis=1)
                n_valid = np.maximum(data.valid.sum(1), 1)
                spread = np.sqrt(q_min / n_valid) / ridge.rms
            ok = np.all(np.isfinite(ridge_fit), axis=(1, 2)) & np.isfinite(spread) & (spread > 0)
            ridge_fit = np.where(ok[:, None, None], ridge_fit, 0.0)
            spread = np.where(ok, np.clip(spread, 1e-3, 1.0), 1.0)
        return cls(
            (float(lo0), float(hi0)),
            float(floor),
            edges[:, 0],
            width,
            log_q,
            cdf,
            fit,
            column,
            ridge_fit,
            spread,
        )

    def take(self, index, ridge=None) -> ExponentJump:
        """Rows ``index``; ``ridge`` (bool per row) marks ridge coordinates."""
        idx = np.asarray(index)
        col = self.column[idx] if ridge is None else np.where(ridge, 0, 1)
        fit = self.fit[idx]
        spread = None if self.spread is None else self.spread[idx]
        if ridge is not None:
            r = np.asarray(ridge)[:, None, None]
            fit = np.where(r, 0.0 if self.ridge_fit is None else self.ridge_fit[idx], fit)
        return ExponentJump(
            self.bounds,
            self.floor,
            self.lo[idx],
            self.width[idx],
            self.log_q[idx],
            self.cdf[idx],
            fit,
            col,
            None,
            spread,
        )

    def _log_density(self, x):
        """log q at x (B, H) and the (clipped) cell of x in its row's window."""
        b, m = self.cdf.shape
        pos = np.floor((x - self.lo[:, None]) / self.width[:, None])
        inside = (pos >= 0) & (pos < m)
        cell = np.clip(pos, 0, m - 1).astype(np.intp) + (np.arange(b) * m)[:, None]
        window = np.where(inside, np.exp(np.take(self.log_q, cell)), 0.0)
        return np.log(window + self.floor / (self.bounds[1] - self.bounds[0])), cell

    def propose(self, s, rng, fresh: bool = False, nu: float = 4.0):
        """Proposals (B, H, P) for walkers s and the log factor log q(x) - log q(y)
        (``fresh``: ridge offsets drawn afresh, see the class docstring)."""
        b, h, p = s.shape
        m = self.cdf.shape[1]
        u = rng.random((3, b, h))
        row = np.arange(b)[:, None]
        # every row's cdf lifted by its row number: one sorted array to search
        cell = np.searchsorted((self.cdf + row).ravel(), u[0] + row, side="right") - row * m
        lo0, hi0 = self.bounds
        new = np.where(
            u[2] < self.floor,
            lo0 + u[1] * (hi0 - lo0),
            self.lo[:, None] + (np.minimum(cell, m - 1) + u[1]) * self.width[:, None],
        )
        old = np.take_along_axis(s, self.column[:, None, None], axis=2)[..., 0]
        log_q_old, cell_old = self._log_density(old)
        log_q_new, cell_new = self._log_density(new)
        factor = log_q_old - log_q_new
        fit = self.fit.reshape(b * m, -1)[:, :p]
        fit_old, fit_new = np.take(fit, cell_old, 0), np.take(fit, cell_new, 0)
        moved = s + fit_new - fit_old
        out = np.where((self.column[:, None, None] == np.arange(p)), new[..., None], moved)
        if fresh:  # ridge offsets from a bivariate t about the fit, in ridge rows
            ridge = (self.column == 0)[:, None]
            scale = (np.ones(b) if self.spread is None else self.spread)[:, None, None]
            t = rng.standard_normal((b, h, 2)) / np.sqrt(rng.chisquare(nu, (b, h, 1)) / nu)

            def log_t(v):
                return -0.5 * (nu + 2.0) * np.log1p(np.sum(v * v, -1) / nu)

            t_old = (s[..., 1:3] - fit_old[..., 1:3]) / scale
            factor += np.where(ridge, log_t(t_old) - log_t(t), 0.0)
            fresh_u = fit_new[..., 1:3] + scale * t
            out[..., 1:3] = np.where(ridge[..., None], fresh_u, out[..., 1:3])
        return out, factor


def _profile_log_posterior(data: lk.CurveData, log_n, marginal: bool, w_nodes):
    """Log posterior density at each log n (B, M), with gamma and s (and sigma)
    at their weighted least-squares values there, and those values (B, M, P)
    (see :class:`ExponentJump`); ``log_n`` (M,) or one row per facet (B, M);
    ``w_nodes`` the weights of :func:`_node_fits` (B, N, T)."""
    log_n = np.broadcast_to(log_n, (len(data.y), np.shape(log_n)[-1]))
    j, frac = lk.grid_position(log_n, data.log_n_grid)
    rows = np.arange(len(data.y))[:, None]
    g = data.glossy[rows, j] + frac[..., None] * (data.glossy[rows, j + 1] - data.glossy[rows, j])
    w = w_nodes[rows, np.rint(j + frac).astype(np.intp)]  # weights of the nearest node
    y, d = data.y[:, None, :], data.diffuse[:, None, :]
    y = np.maximum(y, 0.0) if data.camera == "power" else y
    a, b = _nonnegative_pair(y, d, g, w)
    s = a + b
    ok = s > 0
    th = np.empty(a.shape + (3 if marginal else data.n_params,))
    th[..., 0] = np.where(ok, b / np.where(ok, s, 1.0), 0.5)
    th[..., 1] = log_n
    th[..., 2] = np.where(ok, np.log(np.where(ok, s, 1.0)), data.log_s_center[:, None])
    if marginal:
        return lk.log_probability_sigma_marginal(th, data, with_q=True), th
    n_valid = np.maximum(data.valid.sum(1), 1)[:, None]
    mu = a[..., None] * d + b[..., None] * g
    rms = np.sqrt(np.sum(w * (y - mu) ** 2, -1) / n_valid)
    lo_s, hi_s = data.priors.log_sigma
    th[..., 3] = np.clip(np.log(np.maximum(rms, 1e-300)), lo_s + 1e-6, hi_s - 1e-6)
    if data.n_params == 5:
        th[..., 4] = 0.0  # g = 1
    return (lk.log_probability(th, data), None), th


@dataclass
class PosteriorSamples:
    """Draws per facet from several independent ensembles.

    Attributes
    ----------
    draws : ndarray (F, E, S, P)
        F facets, E ensembles, S draws each (each walker's trajectory
        thinned evenly, walkers one after another), P parameters (:func:`likelihood.PARAMETERS`).
    tau : ndarray (F, E, P)
        Integrated autocorrelation times [steps], pooled over the facet's
        ensembles (the same value for each); NaN for log sigma when it was
        integrated out and drawn afterwards.
    n_steps : ndarray (F,)
        Production steps run.
    acceptance : ndarray (F, E)
    seconds : float
    """

    draws: np.ndarray
    tau: np.ndarray
    n_steps: np.ndarray
    acceptance: np.ndarray
    seconds: float
    parameters: tuple


def sample_posterior(
    data: lk.CurveData,
    *,
    n_ensembles: int = 4,
    n_walkers: int | None = None,
    burn: int = 100,
    burn_taus: float = 5.0,
    chunk: int = 50,
    min_tau_multiple: float = 50.0,
    max_steps: int = 8000,
    draws_per_ensemble: int = 1000,
    moves=FACET_MOVES,
    seed: int | None = 0,
    jobs: int = 1,
    stream_size: int = 1200,
    min_streams: int = 2,
    slots: int = 256,
    marginalise_sigma: bool = True,
    ridge: float | None = RIDGE_MAX_RMS,
    progress=None,
) -> PosteriorSamples:
    """Sample every facet's posterior with the batched ensemble sampler.

    Facets are dealt, in order, into streams of at most ``stream_size``
    (and at least ``min_streams`` streams, so that two processes share even
    a small set);
    stream i draws its random numbers from ``SeedSequence(seed).spawn(n)[i]``
    and runs its facets through ``slots`` vectorised places: a facet that has
    converged leaves its place to the next one waiting, so the batch stays
    full and slow facets do not run alone. Results depend on the seed,
    ``stream_size`` and ``slots``, never on ``jobs``, which only spreads the
    streams over processes.

    Parameters
    ----------
    data : likelihood.CurveData
        F facets.
    n_ensembles : int
        Independent ensembles per facet (R-hat needs several).
    n_walkers : int, optional
        Walkers per ensemble (even, >= 2 P); default 2 P.
    burn : int
        Steps discarded after the start (rounded up to whole chunks).
    burn_taus : float
        Discard at least this many integrated autocorrelation times in all:
        where ``burn`` was shorter, the start of the production run is
        dropped too (at most half of it) before the run is measured and
        thinned into draws.
    chunk : int
        Steps between convergence checks.
    min_tau_multiple : float
        Run at least this many integrated autocorrelation times.
    max_steps : int
        Production steps at most (facets that need more are returned as run
        and the diagnostics flag them).
    draws_per_ensemble : int
        Draws kept per ensemble (rounded down to a multiple of the walkers):
        every walker's trajectory thinned evenly.
    moves : sequence of (name, weight)
        :class:`BatchedEnsemble`'s moves; ``"n-jump"`` and ``"ridge-jump"``
        propose from each facet's :class:`ExponentJump` where sigma is
        integrated out (3 coordinates) and are replaced by ``"de"``
        elsewhere (with sigma or a
        camera exponent sampled, jumps in log n that keep the other
        coordinates were mostly rejected and lengthened the runs).
    seed : int or None
    jobs : int
        Worker processes.
    stream_size, slots : int
        Facets per stream at most, and facets sampled at once within a
        stream. Every stream ends with a tail of its slowest facets run in a
        nearly empty batch, so fewer, longer streams cost less.
    min_streams : int
        Streams at least (where there are that many facets).
    marginalise_sigma : bool
        Where the likelihood allows it
        (:func:`bayesgloss.likelihood.sigma_marginal_supported`), sample
        (gamma, log n, log s) from the posterior with sigma integrated out
        exactly, and draw log sigma for every kept draw from its conditional
        posterior (:func:`bayesgloss.likelihood.draw_log_sigma`): one
        dimension fewer for the ensembles, the same joint posterior. The
        autocorrelation time of log sigma is then reported as NaN.
    ridge : float or None
        Sample facets whose best fit leaves a relative rms below this in
        :class:`RidgeCoordinates` (None: plain coordinates for all).
    progress : callable, optional
        Called with (facets done, facets in all) as streams finish.

    Notes
    -----
    A facet stops when its production run is at least ``min_tau_multiple``
    integrated autocorrelation times of every sampled parameter in every
    ensemble and ArviZ finds gamma converged across the ensembles (R-hat <
    1.01, bulk and tail ESS >= 400), or at ``max_steps``.
    """
    t0 = time.perf_counter()
    n_f = len(data.y)
    marginal = marginalise_sigma and lk.sigma_marginal_supported(data)
    p = 3 if marginal else data.n_params  # dimensions the ensembles explore
    walkers = 2 * p if n_walkers is None else int(n_walkers)
    n_streams = max(min(min_streams, n_f), -(-n_f // stream_size), 1)
    bounds = np.linspace(0, n_f, n_streams + 1).round().astype(int)
    seeds = np.random.SeedSequence(seed).spawn(n_streams)
    args = dict(
        n_ensembles=n_ensembles,
        n_walkers=walkers,
        burn=burn,
        burn_taus=burn_taus,
        chunk=chunk,
        min_tau_multiple=min_tau_multiple,
        max_steps=max_steps,
        draws_per_ensemble=draws_per_ensemble,
        moves=moves,
        slots=slots,
        marginal=marginal,
        ridge=ridge,
    )
    tasks = [
        (i, data.take(np.arange(bounds[i], bounds[i + 1])), seeds[i]) for i in range(n_streams)
    ]
    parts = [None] * n_streams
    done = 0
    if jobs > 1 and n_streams > 1:
        from concurrent.futures import as_completed

        from .runner import process_pool

        with process_pool(jobs) as pool:
            futs = {pool.submit(_sample_stream, d, sd, **args): i for i, d, sd in tasks}
            for fut in as_completed(futs):
                parts[futs[fut]] = fut.result()
                done += len(parts[futs[fut]][0])
                if progress:
                    progress(done, n_f)
    else:
        for i, d, sd in tasks:
            parts[i] = _sample_stream(d, sd, **args)
            done += len(parts[i][0])
            if progress:
                progress(done, n_f)
    draws, tau, steps, acc = (np.concatenate([pt[k] for pt in parts]) for k in range(4))
    return PosteriorSamples(
        draws, tau, steps, acc, time.perf_counter() - t0, lk.PARAMETERS(data.camera)
    )


def _sample_stream(
    data,
    seed_seq,
    *,
    n_ensembles,
    n_walkers,
    burn,
    burn_taus,
    chunk,
    min_tau_multiple,
    max_steps,
    draws_per_ensemble,
    moves,
    slots,
    marginal,
    ridge,
):
    """One stream of facets through ``slots`` places, E ensembles each (see above)."""
    rng = np.random.default_rng(seed_seq)
    n_f, e, p = len(data.y), n_ensembles, (3 if marginal else data.n_params)
    if marginal:  # the density also hands back Q, kept to draw sigma from at the end

        def log_prob(theta, d):
            return lk.log_probability_sigma_marginal(theta, d, with_q=True)

    else:
        log_prob = lk.log_probability
    n_keep = p + 1 if marginal else p  # kept chains carry Q as a last column
    coords_of = RidgeCoordinates.of(data, max_rms=ridge if ridge else -1.0)
    jump = None
    if {"n-jump", "ridge-jump"} & {m for m, _ in moves}:
        if marginal:
            jump = ExponentJump.of(data, marginal, ridge=coords_of)
        else:  # jumps in log n alone rarely fit 4-5 free coordinates: DE instead
            moves = tuple((("de" if m in ("n-jump", "ridge-jump") else m), w) for m, w in moves)
    burn_chunks = -(-burn // chunk)
    draws_per_ensemble = n_walkers * max(1, draws_per_ensemble // n_walkers)
    out = np.empty((n_f, e, draws_per_ensemble, n_keep))
    tau_out = np.full((n_f, e, p), np.nan)
    steps_out = np.zeros(n_f, dtype=int)
    acc_out = np.zeros((n_f, e))

    # facets in plain coordinates (broad posteriors, the longest runs) first, so
    # that they run beside the others rather than in a nearly empty batch at the end
    waiting = list(np.argsort(coords_of.active, kind="stable"))
    facets: list[int] = []  # facet of each place
    coords = np.empty((0, n_walkers, p))
    logp = np.empty((0, n_walkers))
    blob = np.empty((0, n_walkers)) if marginal else None  # Q at every walker
    age = np.empty(0, dtype=int)  # chunks run, per place
    next_check = np.empty(0)  # production steps at which to estimate tau next
    thin = 2  # stored chains keep every 2nd step (tau >> 2 steps here)
    kept: dict[int, list[np.ndarray]] = {}
    # kept chains are float32 offsets from each facet's first kept mean, so that
    # they resolve posteriors far narrower than the parameters' values
    origin: dict[int, np.ndarray] = {}
    acc_sum = np.empty((0, e))
    first_check = max(chunk, FIRST_CHECK_TAUS * min_tau_multiple)
    sampler = BatchedEnsemble(None, moves, rng)
    while waiting or facets:
        # fill free places with waiting facets
        new = waiting[: max(0, slots - len(facets))]
        waiting = waiting[len(new) :]
        if new:
            rows = np.repeat(new, e)
            sub = data.take(rows)
            start = initial_ensemble(sub, n_walkers, rng)[..., :p]
            x = coords_of.take(rows).from_theta(start)
            lp, q0 = _with_blob(coords_of.take(rows).log_prob(log_prob, sub)(x))
            # a start the ridge map cannot represent: that facet keeps plain coordinates
            plain_ok = np.isfinite(_with_blob(log_prob(start, sub))[0])
            lost = np.any(~np.isfinite(lp) & plain_ok, axis=1)
            if np.any(lost):
                coords_of.active[np.unique(rows[lost])] = False
                x = coords_of.take(rows).from_theta(start)
                lp, q0 = _with_blob(coords_of.take(rows).log_prob(log_prob, sub)(x))
            facets += new
            coords = np.concatenate([coords, x])
            logp = np.concatenate([logp, lp])
            if marginal:
                blob = np.concatenate([blob, q0])
            age = np.concatenate([age, np.zeros(len(new), dtype=int)])
            next_check = np.concatenate([next_check, np.full(len(new), first_check)])
            acc_sum = np.concatenate([acc_sum, np.zeros((len(new), e))])
            for f in new:
                kept[f] = []
        rows = np.repeat(facets, e)
        batch_coords = coords_of.take(rows)
        sampler.log_prob = batch_coords.log_prob(log_prob, data.take(rows))
        if jump is not None:
            sampler.jump = jump.take(rows, batch_coords.active)
        ch, lp, acc = sampler.run(coords, chunk, logp, blob)
        coords, logp = ch[-1].copy(), lp[-1].copy()
        if marginal:
            blob = sampler.blobs[-1].copy()
        age += 1
        a = len(facets)
        kept_steps = ch[::thin]  # sampling coordinates to parameters, (n, a E, W, P)
        n_kept = len(kept_steps)
        th = batch_coords.to_theta(
            kept_steps.transpose(1, 0, 2, 3).reshape(a * e, n_kept * n_walkers, p)
        )[0]
        ch = th.reshape(a * e, n_kept, n_walkers, p).transpose(1, 0, 2, 3)
        if marginal:
            ch = np.concatenate([ch, sampler.blobs[::thin][..., None]], axis=-1)
        ch = ch.reshape(n_kept, a, e, n_walkers, n_keep)
        acc = acc.reshape(a, e)
        finished = np.zeros(a, dtype=bool)
        due = []  # places whose run is measured now
        for k, f in enumerate(facets):
            if age[k] <= burn_chunks:
                continue
            if f not in origin:
                origin[f] = ch[0, k].mean(axis=(0, 1))
                origin[f][p:] = 0.0  # Q (a positive sum of squares) as it is
            kept[f].append((ch[:, k] - origin[f]).astype(np.float32))
            acc_sum[k] += acc[k]
            n_steps = (age[k] - burn_chunks) * chunk
            if n_steps >= next_check[k] or n_steps >= max_steps:
                kept[f] = [np.concatenate(kept[f])]  # (N / thin, E, W, P)
                due.append(k)
        # one autocorrelation function averaged over the walkers of every
        # ensemble (the same sampler on the same target), per parameter;
        # runs of the same length share one transform
        taus = {}
        for n_kept in {len(kept[facets[k]][0]) for k in due}:
            group = [k for k in due if len(kept[facets[k]][0]) == n_kept]
            runs = np.stack([kept[facets[k]][0] for k in group], axis=1)
            runs = runs[..., :p].reshape(n_kept, len(group), e * n_walkers, p)
            # every 2nd kept step (4th step) suffices for tau >> 4 steps and
            # halves the transforms (for small tau it errs long, never short)
            t = 2 * thin * integrated_time(runs[::2])
            taus.update(zip(group, t, strict=True))
        checks = {}
        for k in due:
            run, t = kept[facets[k]][0], taus[k]
            t_max = np.nan_to_num(t, nan=np.inf).max()
            # burn-in of at least burn_taus tau: where the fixed burn was shorter,
            # the start of the production run is discarded too
            drop = burn_taus * t_max - burn_chunks * chunk
            drop = int(np.ceil(drop / thin)) if np.isfinite(drop) and drop > 0 else 0
            run = run[min(drop, len(run) // 2) :]
            enough = len(run) * thin >= t_max * min_tau_multiple
            need = t_max * min_tau_multiple + drop * thin
            draws = _ensemble_draws(run, draws_per_ensemble) + origin[facets[k]]  # (E, S, P)
            checks[k] = (draws, enough, need)
        # R-hat and ESS of gamma for every run long enough, at once
        ready = [k for k in due if checks[k][1]]
        converged = {}
        if ready:
            gammas = np.stack([checks[k][0][..., 0] for k in ready])
            converged = dict(zip(ready, gamma_converged(gammas), strict=True))
        for k in due:
            f, (draws, enough, need) = facets[k], checks[k]
            n_steps = (age[k] - burn_chunks) * chunk
            if converged.get(k, False) or n_steps >= max_steps:
                out[f] = draws
                tau_out[f], steps_out[f] = taus[k], n_steps
                acc_out[f] = acc_sum[k] / (age[k] - burn_chunks)
                del kept[f], origin[f]
                finished[k] = True
            elif enough:  # long enough but not yet converged: 25 % more steps
                next_check[k] = n_steps + max(chunk, 0.25 * n_steps)
            else:  # check again when the estimate says it may be enough
                next_check[k] = max(need, n_steps + chunk)
        if np.any(finished):
            keep_places = ~finished
            facets = [f for f, k in zip(facets, keep_places, strict=True) if k]
            rows = np.repeat(keep_places, e)
            coords, logp = coords[rows], logp[rows]
            if marginal:
                blob = blob[rows]
            age, acc_sum = age[keep_places], acc_sum[keep_places]
            next_check = next_check[keep_places]
    if marginal:  # log sigma from its conditional posterior at every kept draw
        out, q = out[..., :p], out[..., p].reshape(n_f, e * draws_per_ensemble)
        th = out.reshape(n_f, e * draws_per_ensemble, p)
        log_sigma = lk.draw_log_sigma(th, data, rng, q=q)
        out = np.concatenate([out, log_sigma.reshape(n_f, e, draws_per_ensemble, 1)], axis=-1)
        tau_out = np.concatenate([tau_out, np.full((n_f, e, 1), np.nan)], axis=-1)
    return out, tau_out, steps_out, acc_out


def _with_blob(value):
    """(log p, blob) from a density that may or may not return a blob."""
    return value if isinstance(value, tuple) else (value, None)


def _ensemble_draws(run, n_draws: int) -> np.ndarray:
    """Draws per ensemble, (E, S, P): each walker's trajectory thinned evenly,
    walkers one after the other (so that every stretch of a chain is one
    walker's Markov chain, as ArviZ's R-hat and ESS assume)."""
    n, e, w, p = run.shape
    per = max(1, n_draws // w)
    idx = np.linspace(0, n - 1, per).round().astype(int)
    return run[idx].transpose(1, 2, 0, 3).reshape(e, w * per, p).astype(float)


def gamma_converged(draws, rhat_max: float = 1.01, ess_min: float = 400.0) -> np.ndarray:
    """ArviZ's convergence criteria for many parameters at once: rank-normalised
    R-hat < 1.01 and bulk and tail ESS >= 400 (Vehtari et al. 2021).

    Parameters
    ----------
    draws : array_like (F, C, S)
        F parameters (here, one facet's gamma each), C chains of S draws.

    Returns
    -------
    ndarray (F,) of bool
        False where a draw is not finite or all draws are equal.
    """
    x = np.asarray(draws, dtype=float)
    ok = np.isfinite(x).all(axis=(1, 2)) & (np.ptp(x, axis=(1, 2)) > 0)
    if not ok.any():
        return ok
    rhat, ess_bulk, ess_tail = rank_diagnostics(x[ok])
    ok[ok] = (rhat < rhat_max) & (ess_bulk >= ess_min) & (ess_tail >= ess_min)
    return ok


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
    spec = np.fft.rfft(d, n=_fast_length(2 * s), axis=2)
    acov = np.fft.irfft(spec.real**2 + spec.imag**2, n=_fast_length(2 * s), axis=2)[..., :s] / s
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

"""Sampling coordinates that straighten a facet's posterior, and the fits they rest on.

:func:`node_fits` is the weighted least-squares fit of a facet's curve on
the diffuse basis and the glossy basis at every node of the exponent table
(closed form, gamma and s at each n); :class:`RidgeCoordinates` uses it to
map (gamma, log n, log s) to coordinates (log n, u1, u2) in which the thin
curved ridge that low noise makes along log n is straight and of constant
width. Facets whose curves leave a relative rms below
:data:`RIDGE_MAX_RMS` are sampled in them (on prior draws, the 90th
percentile of the autocorrelation time fell from 66 to 35 steps, and facets
stopped at the step cap from 8 % to 1 %); they also straighten the funnel
of a near-matt facet, whose gamma is pinned near 0 more tightly at some
exponents than at others (raising the threshold from 5 % to 30 % took the
paper's facets at the step cap from 2 to 0; with the ridge-jump, from 30 %
to 100 % cut the mean run of the facets above 30 % by a quarter on prior
draws and by 45 % on the paper's).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import likelihood as lk
from .ensemble import with_blob

__all__ = ["node_fits", "nonnegative_pair", "RidgeCoordinates", "RIDGE_MAX_RMS"]


def node_fits(data: lk.CurveData, weights: bool = False):
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
        a, b = nonnegative_pair(y[:, None, :], d, g, w)
        if data.noise != "gaussian":  # second pass: weights of the fitted curve
            fit = (a + b > 0)[..., None]
            s = np.where(fit, (a + b)[..., None], s0)
            m = np.where(fit, a[..., None] * d + b[..., None] * g, s0 * d)
            w = np.where(valid[:, None, :], 1.0 / (m + s * floor) ** 2, 0.0)
    mu = a[..., None] * d + b[..., None] * g
    n_valid = np.maximum(valid.sum(1), 1)[:, None]
    rms = np.sqrt(np.sum(w * (y[:, None, :] - mu) ** 2, -1) / n_valid)
    return (a, b, rms, w) if weights else (a, b, rms)


def nonnegative_pair(y, d, g, w):
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


#: Facets whose best fit leaves a relative rms below this use ridge coordinates.
RIDGE_MAX_RMS = 1.0


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
        """Coordinates for every facet of ``data`` (:func:`node_fits` at each node)."""
        a, b, rms, w = node_fits(data, weights=True)
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
            out, blob = with_blob(log_prob(th, data))  # a blob passes through
            with np.errstate(invalid="ignore"):
                out = out + log_jac  # NaN where s <= 0
            out = np.where(np.isnan(out), -np.inf, out)
            return out if blob is None else (out, blob)

        return in_x

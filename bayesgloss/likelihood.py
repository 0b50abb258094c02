"""Likelihood of whole facet luminance curves under Lambert plus glossy lobe.

The model for facet f in frame t (paper, eq. 4, with the bases of
:mod:`bayesgloss.render`):

    mu_ft = s_f [(1 - gamma_f) D_ft + gamma_f G_ft(n_f)],

observed through a camera response and noise:

- ``camera="linear"``: y_ft = mu_ft + noise (a known response, e.g. sRGB or
  gamma G, is undone by the bundle reader before this point);
- ``camera="power"``: code values y_ft = mu_ft^(1/g) + noise with an unknown
  response exponent g (a parameter), for bundles whose encoding is
  ``unknown``;
- values at the top code of an integer image are censored: they say only
  that the true value is at least that large, and enter through the normal
  survival function.

Noise (``noise=``): ``"relative"`` (default) sd = sigma (m_ft + floor_f);
``"gaussian"`` sd = sigma; ``"student"`` relative scale with 4 degrees of
freedom (heavier tails), where m is the noiseless prediction on the observed
scale and floor_f = 1 % of s_f max_t D_ft, the peak of the facet's diffuse
radiance at the current scale (so that dark frames do not get zero noise),
on the observed scale: for ``camera="power"`` 1 % of (s_f max_t D_ft)^(1/g),
a code value as m is.
Frames flagged invalid by the reader are left out.

Parameters, per facet: ``gamma`` in [0, 1] (fraction of reflected energy in
the glossy lobe), ``log_n`` (natural log of the exponent), ``log_s``
(natural log of the scale s, which absorbs albedo, exposure and units),
``log_sigma`` (noise scale), and with ``camera="power"`` ``log_g``.

The noise scale sigma enters the Gaussian models only through
Q = sum_t ((y_t - m_t) / v_t)^2 (v_t the sd per unit sigma), so under its
log-uniform prior it can be integrated out exactly
(:func:`log_likelihood_sigma_marginal`) and drawn afterwards from its
conditional posterior (:func:`draw_log_sigma`); the sampler then explores
(gamma, log n, log s) only.

Priors (:class:`Priors`, documented defaults, all overridable): gamma
uniform on [0, 1]; log n uniform on [log 1, log 1e4] (the exponent table of
the glossy basis: Phong's "typically 1 to 200" with room for near-mirrors);
log s normal about a reference scale with sd 3 (a factor of 20 at 1 sd,
``log_s_center`` defaults to the data's scale relative to D); log sigma
uniform on [log 1e-4, log 2]; log g uniform on [log 1, log 3].
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np
from scipy import special

from .gamma_interval import log_gamma_interval, tail_cuts

__all__ = [
    "Priors",
    "CurveData",
    "curve_data",
    "PARAMETERS",
    "log_prior",
    "log_likelihood",
    "log_probability",
    "predict",
    "simulate",
    "sample_prior",
    "sigma_marginal_supported",
    "log_likelihood_sigma_marginal",
    "log_probability_sigma_marginal",
    "draw_log_sigma",
    "NOISE_MODELS",
    "CAMERA_MODELS",
]

NOISE_MODELS = ("relative", "gaussian", "student")
CAMERA_MODELS = ("linear", "power")
STUDENT_DOF = 4.0
FLOOR_FRACTION = 0.01


def PARAMETERS(camera: str = "linear") -> tuple[str, ...]:  # noqa: N802 - a constant by use
    """Parameter names, in the order of the last axis of theta."""
    base = ("gamma", "log_n", "log_s", "log_sigma")
    return base + ("log_g",) if camera == "power" else base


@dataclass(frozen=True)
class Priors:
    """Prior bounds and widths (module docstring). Log quantities are natural logs."""

    log_n: tuple[float, float] = (0.0, float(np.log(1e4)))
    log_s_sd: float = 3.0
    log_s_center: float | None = None  # None: per facet from the data
    log_sigma: tuple[float, float] = (float(np.log(1e-4)), float(np.log(2.0)))
    log_g: tuple[float, float] = (0.0, float(np.log(3.0)))


@dataclass(frozen=True)
class _FastTables:
    """The default likelihood's tables in float32, rows contiguous, invalid
    frames zeroed (their residual is then 0 and their log(m' + f') the
    constant log f', subtracted in ``log_floor_invalid``)."""

    g0: np.ndarray  # (B*N, T) G_j - D
    dg: np.ndarray  # (B*N, T) G_j+1 - G_j
    d: np.ndarray  # (B, T) D
    y: np.ndarray  # (B, T)
    floor: np.ndarray  # (B,) f' = FLOOR_FRACTION max_t D
    log_floor_invalid: np.ndarray  # (B,) (T - T_valid) log f'
    n_valid: np.ndarray  # (B,)
    ones: np.ndarray  # (T,)
    offsets: np.ndarray  # (B, 1) first table row of each facet, b N

    @classmethod
    def of(cls, data: CurveData) -> _FastTables:
        v = data.valid
        t = v.shape[1]
        g = np.where(v[:, None, :], data.glossy, 0.0)
        d = np.where(v, data.diffuse, 0.0)
        nxt = np.concatenate([g[:, 1:], g[:, -1:]], axis=1)
        floor = np.maximum(FLOOR_FRACTION * data.diffuse_peak, 1e-30)
        f32 = np.float32
        return cls(
            np.ascontiguousarray((g - d[:, None, :]).reshape(-1, t), dtype=f32),
            np.ascontiguousarray((nxt - g).reshape(-1, t), dtype=f32),
            d.astype(f32),
            np.where(v, data.y, 0.0).astype(f32),
            floor.astype(f32),
            (t - v.sum(axis=1)) * np.log(floor.astype(f32)).astype(float),
            v.sum(axis=1),
            np.ones(t, dtype=f32),
            (np.arange(len(v)) * data.glossy.shape[1])[:, None],
        )


@dataclass(frozen=True)
class CurveData:
    """Observations and forward-model tables of B facets (or facet copies).

    Attributes
    ----------
    y : ndarray (B, T)
        Observations on the observed scale (0 where invalid).
    valid : ndarray (B, T) of bool
    censored : ndarray (B, T) of bool
        At the top code: y is a lower bound.
    diffuse : ndarray (B, T)
        D_f(t).
    glossy : ndarray (B, N, T)
        G_f(t; n) on a grid uniform in log n.
    log_n_grid : ndarray (N,)
        Uniform grid of log n.
    log_s_center : ndarray (B,)
        Prior centre of log s.
    noise, camera : str
    priors : Priors
    """

    y: np.ndarray
    valid: np.ndarray
    censored: np.ndarray
    diffuse: np.ndarray
    glossy: np.ndarray
    log_n_grid: np.ndarray
    log_s_center: np.ndarray
    noise: str = "relative"
    camera: str = "linear"
    priors: Priors = field(default_factory=Priors)

    @property
    def n_params(self) -> int:
        return len(PARAMETERS(self.camera))

    @functools.cached_property
    def diffuse_peak(self) -> np.ndarray:
        """max_t D_ft over valid frames, (B,)."""
        return np.max(np.where(self.valid, self.diffuse, 0.0), axis=1)

    @functools.cached_property
    def any_censored(self) -> bool:
        return bool(self.censored.any())

    @functools.cached_property
    def glossy_pairs(self) -> np.ndarray:
        """Rows (G_j, G_j+1 - G_j) for linear interpolation in log n, (B*N, 2, T)."""
        g = self.glossy
        nxt = np.concatenate([g[:, 1:], g[:, -1:]], axis=1)
        return np.ascontiguousarray(np.stack([g, nxt - g], axis=2).reshape(-1, 2, g.shape[-1]))

    @functools.cached_property
    def sigma_marginal_constants(self) -> tuple:
        """Per-facet constants of :func:`log_likelihood_sigma_marginal`."""
        return _sigma_marginal_constants(self)

    @functools.cached_property
    def fast_tables(self) -> _FastTables:
        """float32 tables of the default likelihood (:func:`_fast_relative_terms`)."""
        return _FastTables.of(self)

    def take(self, index) -> CurveData:
        """The data of a subset (or repetition) of facets."""
        idx = np.asarray(index)
        return CurveData(
            self.y[idx],
            self.valid[idx],
            self.censored[idx],
            self.diffuse[idx],
            self.glossy[idx],
            self.log_n_grid,
            self.log_s_center[idx],
            self.noise,
            self.camera,
            self.priors,
        )


def curve_data(
    y,
    valid,
    bases,
    *,
    censored=None,
    noise: str = "relative",
    camera: str = "linear",
    priors: Priors | None = None,
) -> CurveData:
    """Assemble the likelihood's inputs from observations and forward-model bases.

    Parameters
    ----------
    y : array_like (F, T)
        Facet observations (linear luminance, or code values for
        ``camera="power"``).
    valid : array_like (F, T) of bool
    bases : bayesgloss.render.FacetBases
        Diffuse and glossy bases whose exponent table is uniform in log n.
    censored : array_like (F, T) of bool, optional
    noise : {"relative", "gaussian", "student"}
    camera : {"linear", "power"}
    priors : Priors, optional
    """
    if noise not in NOISE_MODELS:
        raise ValueError(f"unknown noise model {noise!r}; valid: {', '.join(NOISE_MODELS)}")
    if camera not in CAMERA_MODELS:
        raise ValueError(f"unknown camera model {camera!r}; valid: {', '.join(CAMERA_MODELS)}")
    priors = priors or Priors()
    y = np.asarray(y, dtype=float)
    valid = np.asarray(valid, dtype=bool) & np.isfinite(y)
    cens = np.zeros_like(valid) if censored is None else np.asarray(censored, bool) & valid
    log_n = np.log(np.asarray(bases.exponents, dtype=float))
    step = np.diff(log_n)
    if len(log_n) < 2 or not np.allclose(step, step[0], rtol=1e-6):
        raise ValueError("the glossy basis needs an exponent table uniform in log n")
    y0 = np.where(valid, y, 0.0)
    if priors.log_s_center is not None:
        center = np.full(len(y), float(priors.log_s_center))
    else:
        # data scale relative to the diffuse basis (robust: ratio of sums)
        obs = np.sum(np.where(valid, np.abs(y), 0.0), axis=1)
        ref = np.sum(np.where(valid, bases.diffuse, 0.0), axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            center = np.log(np.where((obs > 0) & (ref > 0), obs / ref, 1.0))
        if camera == "power":
            center = np.zeros(len(y))  # code values: scale of order one
    return CurveData(
        y0,
        valid,
        cens,
        np.asarray(bases.diffuse, float),
        np.asarray(bases.glossy, float),
        log_n,
        center,
        noise,
        camera,
        priors,
    )


def _noise_floor(theta, data: CurveData) -> np.ndarray:
    """floor_f on the observed scale, (B, K, 1): FLOOR_FRACTION of the facet's
    peak diffuse value s max_t D_ft, through the response for ``"power"``
    (a code value, as m is), > 0."""
    peak = data.diffuse_peak[:, None, None]
    if data.camera == "power":
        floor = FLOOR_FRACTION * (peak * np.exp(theta[..., 2:3])) ** np.exp(-theta[..., 4:5])
    else:  # in this order, as the simulated data of the committed studies were made
        floor = FLOOR_FRACTION * peak * np.exp(theta[..., 2:3])
    return np.maximum(floor, 1e-300)


def _noise_sd(m, theta, data: CurveData) -> np.ndarray:
    """Noise standard deviation on the observed scale (module docstring)."""
    sigma = np.exp(theta[..., 3:4])
    if data.noise == "gaussian":
        return sigma * np.ones_like(m)
    return sigma * (np.abs(m) + _noise_floor(theta, data))


def log_prior(theta, data: CurveData) -> np.ndarray:
    """Log prior density, (B, K) for theta (B, K, P); -inf outside the support."""
    th = np.asarray(theta, dtype=float)
    p = data.priors
    gamma, log_n, log_s, log_sigma = th[..., 0], th[..., 1], th[..., 2], th[..., 3]
    inside = (
        (gamma >= 0)
        & (gamma <= 1)
        & (log_n >= p.log_n[0])
        & (log_n <= p.log_n[1])
        & (log_sigma >= p.log_sigma[0])
        & (log_sigma <= p.log_sigma[1])
    )
    if data.camera == "power":
        log_g = th[..., 4]
        inside &= (log_g >= p.log_g[0]) & (log_g <= p.log_g[1])
    center = data.log_s_center[:, None] if th.ndim == 3 else data.log_s_center
    lp = -0.5 * ((log_s - center) / p.log_s_sd) ** 2
    return np.where(inside, lp, -np.inf)


def grid_position(log_n, log_n_grid):
    """Cell j and fraction w of log n on a uniform grid, clamped to the grid:
    a value at node j + w lies between nodes j and j + 1 (j <= N - 2).

    Returns
    -------
    j : ndarray of intp, w : ndarray
        On the shape of ``log_n``.
    """
    grid = log_n_grid
    last = len(grid) - 1.000001
    pos = np.minimum(np.maximum(log_n - grid[0], 0.0) / (grid[1] - grid[0]), last)
    j = pos.astype(np.intp)
    return j, pos - j


def predict(theta, data: CurveData) -> np.ndarray:
    """Noiseless prediction on the observed scale, (B, K, T) for theta (B, K, P)."""
    th = np.asarray(theta, dtype=float)
    b, k = th.shape[:2]
    n = len(data.log_n_grid)
    j, w = grid_position(th[..., 1], data.log_n_grid)  # (B, K)
    w = w[..., None]
    # one gather of the bracketing table rows (G_j, G_j+1 - G_j) per (b, k)
    rows = data.glossy_pairs[(np.arange(b)[:, None] * n + j).ravel()].reshape(b, k, 2, -1)
    glossy = rows[:, :, 0] + w * rows[:, :, 1]
    gamma = th[..., 0:1]
    mu = (1.0 - gamma) * data.diffuse[:, None, :]
    mu += gamma * glossy
    mu *= np.exp(th[..., 2:3])
    if data.camera == "power":
        mu = np.maximum(mu, 0.0) ** np.exp(-th[..., 4:5])
    return mu


def _fast_relative_terms(th, data: CurveData, with_log: bool = True):
    """(Q, sum_t log(m'_t + f'_t)) over valid frames for the default model
    (linear camera, relative noise), in float32 with the scale factored out
    (the second term None without ``with_log``).

    r_t = (y_t / s - m'_t) / (m'_t + f'_t), Q = sum_t r_t^2, with m' =
    D + gamma (G(n) - D) the prediction at unit scale and f' = FLOOR_FRACTION
    max_t D_t; the noise sd is sigma s (m'_t + f'_t). Vectorised over (B, K)
    as 2-D row operations (the fastest layout for short curves).
    """
    tab = data.fast_tables
    b, k = th.shape[:2]
    t = tab.y.shape[1]
    f32 = np.float32
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        j, w = grid_position(th[..., 1], data.log_n_grid)
        rows = (j + tab.offsets).ravel()
        m = np.take(tab.dg, rows, axis=0)
        m *= w.astype(f32).reshape(-1, 1)
        m += np.take(tab.g0, rows, axis=0)  # G(n) - D, linear in log n
        m *= th[..., 0].astype(f32).reshape(-1, 1)
        m3 = m.reshape(b, k, t)
        m3 += tab.d[:, None, :]  # m' = D + gamma (G - D)
        r3 = tab.y[:, None, :] * np.exp(-th[..., 2:3]).astype(f32)
        r3 -= m3
        m3 += tab.floor[:, None, None]  # m' + f'
        r3 /= m3
        r = r3.reshape(-1, t)
        r *= r
        q = (r @ tab.ones).reshape(b, k).astype(np.float64)
        if not with_log:
            return q, None
        np.log(m, out=m)
        log_m = (m @ tab.ones).reshape(b, k).astype(np.float64)
    return q, log_m - tab.log_floor_invalid[:, None]


def _fast_relative(th, data: CurveData) -> np.ndarray:
    """Summed log likelihood of the default model (:func:`_fast_relative_terms`)."""
    q, log_m = _fast_relative_terms(th, data)
    n_valid = data.fast_tables.n_valid[:, None]
    with np.errstate(over="ignore"):
        return (
            -0.5 * q * np.exp(-2.0 * th[..., 3])
            - log_m
            - n_valid * (th[..., 2] + th[..., 3] + 0.5 * np.log(2 * np.pi))
        )


def _residual_parts(th, data: CurveData, with_log: bool = True):
    """(Q, sum_t log v_t) over valid frames for the Gaussian noise models,
    where the noise sd is sigma v_t (v_t = 1 for ``"gaussian"``); the second
    None without ``with_log``."""
    if data.noise == "relative":
        q, log_m = _fast_relative_terms(th, data, with_log)
        if not with_log:
            return q, None
        return q, log_m + data.fast_tables.n_valid[:, None] * th[..., 2]
    m = predict(th[..., :3], data)
    q = np.sum(np.where(data.valid[:, None, :], (data.y[:, None, :] - m) ** 2, 0.0), axis=-1)
    return q, np.zeros(q.shape)


def sigma_marginal_supported(data: CurveData) -> bool:
    """Whether sigma can be integrated out exactly: Gaussian noise (relative or
    constant), a linear camera and no censored entries."""
    return (
        data.noise in ("relative", "gaussian")
        and data.camera == "linear"
        and not (data.any_censored)
    )


def _sigma_marginal_constants(data: CurveData):
    """Per-facet constants of :func:`log_likelihood_sigma_marginal`, (B, 1)
    each: k = T/2, the tail cuts of :func:`bayesgloss.gamma_interval.log_gamma_interval`, and
    -k log(2 pi) + log Gamma(k) + k log 2 - log(2 log(b/a))."""
    la, lb = data.priors.log_sigma
    k = 0.5 * data.valid.sum(axis=1)[:, None].astype(float)
    with np.errstate(divide="ignore", invalid="ignore"):
        const = -k * np.log(np.pi) + special.gammaln(k) - np.log(2.0 * (lb - la))
    return (k, *tail_cuts(k), const)


def log_likelihood_sigma_marginal(theta, data: CurveData, with_q: bool = False):
    """Log likelihood with sigma integrated out under its prior, (B, K).

    With noise sd sigma v_t and Q = sum_t ((y_t - m_t) / v_t)^2 over the T
    valid frames, the prior log sigma ~ U[log a, log b] gives exactly

        int L p(sigma) d sigma = (2 pi)^(-T/2) (prod_t v_t)^-1 Gamma(T/2)
            (2 / Q)^(T/2) [P(T/2, Q / 2a^2) - P(T/2, Q / 2b^2)] / (2 log(b/a)),

    P the regularised lower incomplete gamma function (substitute
    x = Q / 2 sigma^2 in the integral).

    Parameters
    ----------
    theta : array_like (B, K, >= 3)
        gamma, log n, log s (further columns ignored).
    data : CurveData
        With :func:`sigma_marginal_supported`.
    with_q : bool
        Also return Q (B, K), which :func:`draw_log_sigma` needs.
    """
    if not sigma_marginal_supported(data):
        raise ValueError(
            "sigma can be integrated out only for relative or gaussian noise, a linear "
            f"camera and no censoring (got noise={data.noise!r}, camera={data.camera!r}, "
            f"censored={data.any_censored})"
        )
    th = np.asarray(theta, dtype=float)
    la, lb = data.priors.log_sigma
    k, lo_cut, hi_cut, const = data.sigma_marginal_constants
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        q, log_v = _residual_parts(th, data)
        q = np.maximum(q, 1e-300)
        log_int = log_gamma_interval(
            k, q * (0.5 * np.exp(-2 * lb)), q * (0.5 * np.exp(-2 * la)), (lo_cut, hi_cut)
        )
        ll = const - log_v - k * np.log(q) + log_int
    ll = np.where(k > 0, ll, 0.0)
    return (ll, q) if with_q else ll


def log_probability_sigma_marginal(theta, data: CurveData, with_q: bool = False):
    """Log posterior density of (gamma, log n, log s) with sigma integrated
    out, up to a constant, (B, K) for theta (B, K, 3); with ``with_q`` also
    Q (see :func:`log_likelihood_sigma_marginal`)."""
    th = np.asarray(theta, dtype=float)
    p = data.priors
    gamma, log_n, log_s = th[..., 0], th[..., 1], th[..., 2]
    inside = (gamma >= 0) & (gamma <= 1) & (log_n >= p.log_n[0]) & (log_n <= p.log_n[1])
    center = data.log_s_center[:, None] if th.ndim == 3 else data.log_s_center
    lp = -0.5 * ((log_s - center) / p.log_s_sd) ** 2
    ll, q = log_likelihood_sigma_marginal(th, data, with_q=True)
    out = np.where(inside, lp + ll, -np.inf)
    out = np.where(np.isnan(out), -np.inf, out)
    return (out, q) if with_q else out


def draw_log_sigma(theta, data: CurveData, rng: np.random.Generator, q=None) -> np.ndarray:
    """Draws of log sigma from its conditional posterior given (gamma, log n, log s).

    x = Q / 2 sigma^2 is Gamma(T/2, 1) truncated to [Q / 2b^2, Q / 2a^2]
    (see :func:`log_likelihood_sigma_marginal`). Drawn exactly: from the
    untruncated gamma, kept when inside the interval (almost always, as the
    prior's bounds are far from the posterior), otherwise by inverting the
    truncated distribution's incomplete gamma function (for an interval so
    deep in a tail that the function underflows: its asymptotic tail,
    exponential above the mode, x^(T/2 - 1) below it).

    Parameters
    ----------
    theta : array_like (B, K, >= 3)
    data : CurveData
    rng : numpy.random.Generator
    q : array_like (B, K), optional
        Q at theta, where already known (the sampler keeps it).

    Returns
    -------
    ndarray (B, K)
    """
    th = np.asarray(theta, dtype=float)
    la, lb = data.priors.log_sigma
    k = 0.5 * data.valid.sum(axis=1)[:, None].astype(float)
    k = np.broadcast_to(k, th.shape[:2])
    if q is None:
        q, _ = _residual_parts(th, data, with_log=False)
    q = np.maximum(np.asarray(q, dtype=float), 1e-300)
    x_lo, x_hi = q * (0.5 * np.exp(-2 * lb)), q * (0.5 * np.exp(-2 * la))
    x = rng.standard_gamma(k)
    out = ~((x >= x_lo) & (x <= x_hi))
    if np.any(out):
        kk, lo, hi = k[out], x_lo[out], x_hi[out]
        u = rng.random(kk.shape)
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            upper = lo > kk
            c_lo, c_hi = special.gammaincc(kk, lo), special.gammaincc(kk, hi)
            p_lo, p_hi = special.gammainc(kk, lo), special.gammainc(kk, hi)
            inv = np.where(
                upper,
                special.gammainccinv(kk, c_hi + u * (c_lo - c_hi)),
                special.gammaincinv(kk, p_lo + u * (p_hi - p_lo)),
            )
            tiny = np.where(upper, c_lo - c_hi, p_hi - p_lo) <= 1e-250
            tail_up = lo - np.log1p(-u * (1.0 - np.exp(lo - hi)))
            tail_lo = hi * u ** (1.0 / kk)
            x[out] = np.clip(np.where(tiny, np.where(upper, tail_up, tail_lo), inv), lo, hi)
    return np.clip(0.5 * (np.log(q) - np.log(2.0 * x)), la, lb)


def log_likelihood(theta, data: CurveData, pointwise: bool = False) -> np.ndarray:
    """Log likelihood of the valid frames, (B, K) or pointwise (B, K, T)."""
    th = np.asarray(theta, dtype=float)
    if (
        not pointwise
        and data.camera == "linear"
        and data.noise == "relative"
        and not data.any_censored
    ):
        return _fast_relative(th, data)
    m = predict(th, data)
    valid = data.valid[:, None, :]
    log_sigma = th[..., 3:4]
    if data.noise == "gaussian":
        z = (data.y[:, None, :] - m) * np.exp(-log_sigma)
        log_sd = np.broadcast_to(log_sigma, m.shape)
    else:
        scale = np.abs(m) + _noise_floor(th, data)
        z = (data.y[:, None, :] - m) / scale * np.exp(-log_sigma)
        log_sd = np.log(scale) + log_sigma
    if data.noise == "student":
        nu = STUDENT_DOF
        const = special.gammaln((nu + 1) / 2) - special.gammaln(nu / 2) - 0.5 * np.log(nu * np.pi)
        ll = const - 0.5 * (nu + 1) * np.log1p(z * z / nu) - log_sd
    else:
        ll = -0.5 * z * z - log_sd - 0.5 * np.log(2 * np.pi)
    if data.any_censored:
        cens = data.censored[:, None, :]
        if data.noise == "student":
            surv = np.log(np.maximum(special.stdtr(STUDENT_DOF, -z), 1e-300))
        else:
            surv = special.log_ndtr(-z)
        ll = np.where(cens, surv, ll)
    ll *= valid  # invalid frames contribute nothing
    return ll if pointwise else ll.sum(axis=-1)


def log_probability(theta, data: CurveData) -> np.ndarray:
    """Log posterior density up to a constant, (B, K) for theta (B, K, P)."""
    th = np.asarray(theta, dtype=float)
    lp = log_prior(th, data)
    ok = np.isfinite(lp)
    out = np.full(lp.shape, -np.inf)
    if np.any(ok):
        # evaluate the likelihood where the prior allows (clip keeps the rest finite)
        ll = log_likelihood(th, data)
        out = np.where(ok, lp + ll, -np.inf)
    return np.where(np.isnan(out), -np.inf, out)


def sample_prior(data: CurveData, size: int, rng: np.random.Generator) -> np.ndarray:
    """Draws from the prior, (B, size, P)."""
    p = data.priors
    b = len(data.y)
    th = np.empty((b, size, data.n_params))
    th[..., 0] = rng.uniform(0, 1, (b, size))
    th[..., 1] = rng.uniform(*p.log_n, (b, size))
    th[..., 2] = data.log_s_center[:, None] + p.log_s_sd * rng.standard_normal((b, size))
    th[..., 3] = rng.uniform(*p.log_sigma, (b, size))
    if data.camera == "power":
        th[..., 4] = rng.uniform(*p.log_g, (b, size))
    return th


def simulate(theta, data: CurveData, rng: np.random.Generator) -> np.ndarray:
    """Observations drawn from the model at theta (B, K, P), (B, K, T).

    Censoring is not simulated (callers clip and flag if they want it).
    """
    th = np.asarray(theta, dtype=float)
    m = predict(th, data)
    sd = _noise_sd(m, th, data)
    if data.noise == "student":
        eps = rng.standard_t(STUDENT_DOF, m.shape)
    else:
        eps = rng.standard_normal(m.shape)
    return m + sd * eps

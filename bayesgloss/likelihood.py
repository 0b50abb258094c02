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
radiance at the current scale (so that dark frames do not get zero noise).
Frames flagged invalid by the reader are left out.

Parameters, per facet: ``gamma`` in [0, 1] (fraction of reflected energy in
the glossy lobe), ``log_n`` (natural log of the exponent), ``log_s``
(natural log of the scale s, which absorbs albedo, exposure and units),
``log_sigma`` (noise scale), and with ``camera="power"`` ``log_g``.

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

    @property
    def any_censored(self) -> bool:
        return bool(self.censored.any())

    @functools.cached_property
    def glossy_pairs(self) -> np.ndarray:
        """Rows (G_j, G_j+1 - G_j) for linear interpolation in log n, (B*N, 2, T)."""
        g = self.glossy
        nxt = np.concatenate([g[:, 1:], g[:, -1:]], axis=1)
        return np.ascontiguousarray(np.stack([g, nxt - g], axis=2).reshape(-1, 2, g.shape[-1]))

    # float32 tables of the fast default likelihood (_fast_relative)
    @functools.cached_property
    def fast_pairs(self) -> np.ndarray:
        """Rows (G_j - D, G_j+1 - G_j) in float32, (B*N, 2, T)."""
        pairs = self.glossy_pairs.reshape(len(self.y), -1, 2, self.y.shape[1]).copy()
        pairs[:, :, 0] -= self.diffuse[:, None, :]
        return pairs.reshape(-1, 2, self.y.shape[1]).astype(np.float32)

    @functools.cached_property
    def fast_diffuse(self) -> np.ndarray:
        return self.diffuse.astype(np.float32)

    @functools.cached_property
    def fast_y(self) -> np.ndarray:
        return self.y.astype(np.float32)

    @functools.cached_property
    def fast_valid(self) -> np.ndarray:
        return self.valid.astype(np.float32)

    @functools.cached_property
    def fast_floor(self) -> np.ndarray:
        return np.maximum(FLOOR_FRACTION * self.diffuse_peak, 1e-30).astype(np.float32)

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


def _noise_sd(m, theta, data: CurveData) -> np.ndarray:
    """Noise standard deviation on the observed scale (module docstring)."""
    sigma = np.exp(theta[..., 3:4])
    if data.noise == "gaussian":
        return sigma * np.ones_like(m)
    floor = FLOOR_FRACTION * data.diffuse_peak[:, None, None] * np.exp(theta[..., 2:3])
    return sigma * (np.abs(m) + np.maximum(floor, 1e-300))


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


def predict(theta, data: CurveData) -> np.ndarray:
    """Noiseless prediction on the observed scale, (B, K, T) for theta (B, K, P)."""
    th = np.asarray(theta, dtype=float)
    b, k = th.shape[:2]
    grid = data.log_n_grid
    n = len(grid)
    pos = np.clip((th[..., 1] - grid[0]) / (grid[1] - grid[0]), 0.0, n - 1.000001)
    j = pos.astype(np.intp)  # (B, K)
    w = (pos - j)[..., None]
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


def _fast_relative(th, data: CurveData) -> np.ndarray:
    """Summed log likelihood for the default model (linear camera, relative
    noise, nothing censored), in float32 with the scale factored out:
    z = (y / s - m') / (m' + f') / sigma, log sd = log s + log(m' + f') + log sigma,
    m' the prediction at unit scale, f' = FLOOR_FRACTION max_t D_ft."""
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        return _fast_relative_core(th, data)


def _fast_relative_core(th, data: CurveData) -> np.ndarray:
    b, k = th.shape[:2]
    f32 = np.float32
    grid = data.log_n_grid
    n = len(grid)
    pos = np.clip((th[..., 1] - grid[0]) / (grid[1] - grid[0]), 0.0, n - 1.000001)
    j = pos.astype(np.intp)
    w = (pos - j).astype(f32)[..., None]
    rows = data.fast_pairs[(np.arange(b)[:, None] * n + j).ravel()].reshape(b, k, 2, -1)
    m = rows[:, :, 1] * w
    m += rows[:, :, 0]  # G(n) - D
    m *= th[..., 0:1].astype(f32)
    m += data.fast_diffuse[:, None, :]  # m' = D + gamma (G - D)
    r = data.fast_y[:, None, :] * np.exp(-th[..., 2:3]).astype(f32)
    r -= m
    m += data.fast_floor[:, None, None]  # m' + f'
    r /= m
    r *= r
    np.log(m, out=m)
    r *= np.exp(-2.0 * th[..., 3:4]).astype(f32) * f32(0.5)
    r += m
    r *= data.fast_valid[:, None, :]
    total = r.sum(axis=-1, dtype=np.float64)
    n_valid = data.valid.sum(axis=1)[:, None]
    return -total - n_valid * (th[..., 2] + th[..., 3] + 0.5 * np.log(2 * np.pi))


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
        floor = FLOOR_FRACTION * data.diffuse_peak[:, None, None] * np.exp(th[..., 2:3])
        scale = np.abs(m) + np.maximum(floor, 1e-300)
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

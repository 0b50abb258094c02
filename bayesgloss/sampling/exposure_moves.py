"""Moves of the one-material sampler for the day-level exposure.

Where each frame's unknown exposure is drawn about the day's
(``IlluminationPriors.day_exposure``: log e_t ~ N(mu_e, sd_e^2)), a frame's
exposure is tied to the others, and the moves that change one frame at a
time (the frame moves, the exposure ridge of
:mod:`bayesgloss.sampling.material`) hardly move the day's level or spread.
Two exact moves change them with the likelihood unchanged, each frame's sun
and sky taking the change of its exposure (the curves depend on e_t a_t
and e_t b_t only):

- :func:`level_ridge`: every frame's log exposure and mu_e up by c, every
  frame's log sun and log sky down by c; c drawn on a lattice from the
  conditional the priors make (:func:`bayesgloss.sampling.ridge.lattice_shift`);
- :func:`spread_move`: every frame's departure from mu_e and sd_e scaled by
  e^delta (a Metropolis move with the Jacobian e^(T delta)).

On Mitsuba holdout 4 the day-level exposure without them ran 1.27 times as
long as the default, with 14 runs unconverged against 8, every frame's sun
and sky among the quantities that had not converged.
"""

from __future__ import annotations

import numpy as np

from .. import illumination as il
from . import ridge

__all__ = ["level_ridge", "spread_move", "mean_shifted", "LEVEL_REACH"]

#: The reach of the level ridge's lattice, in steps
#: (:func:`~bayesgloss.sampling.ridge.lattice_shift`).
LEVEL_REACH = 4


def mean_shifted(hyper, c) -> np.ndarray:
    """The hyper (..., 6) with the day's mean log exposure mu_e up by c,
    broadcast (c's shape, then hyper's)."""
    c = np.asarray(c, dtype=float)
    return hyper + c[..., None] * np.eye(hyper.shape[-1])[4]


def level_ridge(chain) -> None:
    """Every frame's log exposure and the day's mean up by c, every frame's
    log sun and log sky down by c, c drawn on a lattice of spacing u x the
    conditional's Gaussian width (u uniform on [0.2, 0.6], fresh each
    sweep): the priors of the frames' suns and skies and of mu_e make it."""
    q, direction = chain.data.frame_priors, chain.data.exposure_direction
    width = 1.0 / np.sqrt(chain.t * (1 / q.sun_clear_sd**2 + 1 / q.sky_sd**2))
    h = width * chain.rng.uniform(0.2, 0.6)
    c = ridge.lattice_offsets(LEVEL_REACH)[:, None, None] * h  # (K, E, W)
    hyper = mean_shifted(chain.hyper[None], c)
    lp = chain._frame_prior_along(c[..., None], direction, hyper).sum(-1)
    lp = lp + il.log_prior_exposure_mean(hyper, chain.data)
    moved = ridge.lattice_shift(lp, LEVEL_REACH, chain.rng) * h  # (E, W)
    chain.lam = chain.lam + moved[..., None, None] * direction
    chain.hyper[..., 4] += moved


def spread_move(chain, tries: int = 2, step: float = 0.3) -> None:
    """The day's exposure spread and every frame's departure from the day's
    mean scaled together, d_t = log e_t - mu_e to d_t e^delta and log sd_e
    to log sd_e + delta, each frame's sun and sky down by the change of its
    exposure, delta ~ N(0, ``step``^2); accepted by the priors' ratio and the
    Jacobian e^(T delta)."""
    rng, lo, hi = chain.rng, *il.EXPOSURE_LOG_SPREAD
    cur = chain._frame_prior(chain.lam).sum(-1)
    for _ in range(tries):
        delta = step * rng.standard_normal(cur.shape)  # (E, W)
        hyper = chain.hyper.copy()
        hyper[..., 5] += delta
        d = chain.lam[..., 0] - chain.hyper[..., 4][..., None]
        step_e = d * np.expm1(delta)[..., None]  # each frame's change of log exposure
        lam = chain.lam + step_e[..., None] * chain.data.exposure_direction
        new = chain._frame_prior(lam, hyper=hyper).sum(-1)
        inside = (hyper[..., 5] >= lo) & (hyper[..., 5] <= hi)
        ok = inside & (np.log(rng.random(new.shape)) < new - cur + chain.t * delta)
        chain.hyper = np.where(ok[..., None], hyper, chain.hyper)
        chain.lam = np.where(ok[..., None, None], lam, chain.lam)
        cur = np.where(ok, new, cur)

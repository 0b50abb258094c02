"""Each facet's own posterior given the object's illumination.

The object's answer is the one-material model's
(:mod:`bayesgloss.sampling.material`); beside it, every facet's own gamma,
n and scale are sampled alone with the frames fixed at draws of that
model's posterior, the copies pooled (:func:`facets_given_frames`).
"""

from __future__ import annotations

import numpy as np

from .. import illumination as il
from .joint import _curve_data_at
from .posterior import sample_posterior

__all__ = ["facets_given_frames"]


def facets_given_frames(data: il.JointData, frames, *, copies: int = 2, seed: int = 0, **options):
    """Each facet's own (gamma, log n, log s, log sigma) given the object's
    illumination, (F, E, S, 4), for the one-material model's frame draws
    ``frames`` (E, S, T, L).

    The per-facet answers beside the object's: every facet sampled alone
    (its own gamma, n and scale, :func:`bayesgloss.sampling.sample_posterior`)
    with the frames fixed at ``copies`` draws of each ensemble of the
    object's posterior, the copies' draws pooled (multiple imputation: the
    facet's posterior averaged over the illumination's, which the one
    material decided; a facet's departure from the material does not feed
    back into the light). Chain e of the result pools the copies from
    ensemble e, so R-hat across chains sees the illumination's spread too.
    ``options`` go to :func:`~bayesgloss.sampling.sample_posterior`.

    Returns
    -------
    draws : ndarray (F, E, S, 4)
    samples : bayesgloss.sampling.PosteriorSamples
        The facet sampler's run over the E ``copies`` F facet copies.
    """
    e, s = frames.shape[:2]
    f = data.shape[0]
    picks = np.linspace(0, s - 1, copies + 2)[1:-1].round().astype(int)
    parts = [_curve_data_at(data, frames[i, j]) for i in range(e) for j in picks]
    first = parts[0]
    stacked = type(first)(
        np.concatenate([p.y for p in parts]),
        np.concatenate([p.valid for p in parts]),
        np.concatenate([p.censored for p in parts]),
        np.concatenate([p.diffuse for p in parts]),
        np.concatenate([p.glossy for p in parts]),
        first.log_n_grid,
        np.concatenate([p.log_s_center for p in parts]),
        priors=first.priors,
    )
    out = sample_posterior(stacked, seed=seed, **options)
    draws = out.draws  # (E copies F, E', S', 4)
    draws = draws.reshape(e, copies, f, -1, draws.shape[-1])  # (E, copies, F, E' S', 4)
    pooled = draws.transpose(2, 0, 1, 3, 4).reshape(f, e, -1, draws.shape[-1])
    rng = np.random.default_rng(seed)
    take = np.sort(rng.choice(pooled.shape[2], size=s, replace=pooled.shape[2] < s))
    return pooled[:, :, take], out

"""Facet posteriors: every facet of a set sampled to convergence.

:func:`sample_posterior` drives the facet sampler, per facet:

1. what it samples: where the likelihood allows it (Gaussian noise, relative
   or constant, with a linear camera), sigma is integrated out exactly
   (:func:`bayesgloss.likelihood.log_likelihood_sigma_marginal`) and drawn
   afterwards from its conditional posterior, so the ensembles explore
   (gamma, log n, log s) only; facets whose curves leave a relative rms
   below 100 % are sampled in ridge coordinates
   (:class:`bayesgloss.sampling.coordinates.RidgeCoordinates`);
2. a vectorised start (:func:`bayesgloss.sampling.starts.initial_ensemble`);
3. the moves of :data:`bayesgloss.sampling.moves.FACET_MOVES`, facets
   scheduled through streams of vectorised places
   (:class:`bayesgloss.sampling.streams.FacetStream`); burn-in of at least 5
   autocorrelation times;
4. production until the run is at least ``min_tau_multiple`` integrated
   autocorrelation times (emcee's estimator, pooled over the facet's
   ensembles) and gamma has converged across the independent ensembles by
   the rule of :mod:`bayesgloss.diagnostics` (R-hat < 1.01, bulk and tail
   ESS >= 400), or to the step cap, flagged.
"""

from __future__ import annotations

import functools
import time
from dataclasses import dataclass

import numpy as np

from .. import likelihood as lk
from .coordinates import RIDGE_MAX_RMS
from .moves import FACET_MOVES
from .streams import FacetStream

__all__ = ["PosteriorSamples", "sample_posterior"]


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
    pool=None,
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
    ``stream_size`` and ``slots``, never on ``pool``, which only spreads the
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
    pool : optional
        An object with a ``map`` method like the built-in one (a
        :class:`concurrent.futures.Executor`, e.g.
        :func:`bayesgloss.pool.process_pool`), over which the streams are
        spread, as emcee's ``EnsembleSampler`` takes a ``pool``; None runs
        them one after another in this process.
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
    if n_f == 0:
        raise ValueError("no facets to sample: the curve data hold no facet")
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
    tasks = [data.take(np.arange(bounds[i], bounds[i + 1])) for i in range(n_streams)]
    run = functools.partial(_run_stream, **args)
    parts, done = [], 0
    for part in (map if pool is None else pool.map)(run, tasks, seeds):
        parts.append(part)
        done += len(part[0])
        if progress:
            progress(done, n_f)
    draws, tau, steps, acc = (np.concatenate([pt[k] for pt in parts]) for k in range(4))
    return PosteriorSamples(
        draws, tau, steps, acc, time.perf_counter() - t0, lk.PARAMETERS(data.camera)
    )


def _run_stream(data, seed_seq, **settings):
    """One stream's facets (:class:`FacetStream`), from its own seed."""
    return FacetStream(data, np.random.default_rng(seed_seq), **settings).run()

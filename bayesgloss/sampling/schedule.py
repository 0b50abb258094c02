"""The chain's schedule: burn-in, sweeps in chunks until the stopping rule holds, kept draws.

:func:`run_chain` runs a chain of :mod:`bayesgloss.sampling.joint`'s
scheme (or :mod:`bayesgloss.sampling.material`'s): burn-in in rounds, the
collective directions adapted after each; then sweeps in chunks of
``chunk``, every THIN-th state kept, until over the kept second half gamma
and every frame's sun and sky latents have converged across the ensembles
by the rule of :mod:`bayesgloss.diagnostics` (R-hat < 1.01, bulk and tail
ESS >= 400), checked from ``min_sweeps`` on, or ``max_sweeps`` is reached
(flagged). The kept second half is thinned to :class:`JointSamples`.

A run stopped at its cap unconverged carries its state (:class:`ChainRun`),
and ``run_chain(..., resume=samples.run)`` runs the same chain on: the draws
are those of one run with the larger cap, sweep for sweep (the sky
families' screen, :func:`bayesgloss.sky_families.fit_families`, runs
every family to its first check and only those in reach on).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from .. import diagnostics
from .. import illumination as il

__all__ = ["JointSamples", "ChainRun", "run_chain", "first_check", "THIN", "BURN_ROUNDS"]

#: Kept chains hold every THIN-th sweep.
THIN = 4
#: Names of the draws' Fresnel columns (:data:`bayesgloss.fresnel.FRESNEL_COLUMNS`).
FRESNEL_PARAMETERS = ("fresnel_strength", "log_normal_albedo")
#: Burn-in sweeps, in rounds between which the collective directions are adapted
#: (the one-material sampler's are shorter: :mod:`.material`).
BURN_ROUNDS = (200, 200, 200)


@dataclass
class JointSamples:
    """Draws of the joint model.

    Attributes
    ----------
    draws : ndarray (F, E, S, 4) or (F, E, S, 6)
        Facets' gamma, log n, log s, log sigma (and, where the one-material
        model has a Fresnel term, its strength k and log A: ``parameters``);
        F facets, E ensembles, S draws each (each walker's trajectory thinned
        evenly, walkers one after another).
    frames : ndarray (E, S, T, L)
        Each frame's latents (:func:`bayesgloss.illumination.latent_names`)
        at the same draws.
    rhat, ess_bulk, ess_tail : ndarray (F + 2 T,)
        Diagnostics of gamma per facet, then log a and log b per frame.
    converged : bool
    n_sweeps : int
    acceptance : dict
        Acceptance rates of the facet and frame moves.
    seconds : float
    material : ndarray (E, S, 2) or None
        The one-material model's m and log tau (:mod:`bayesgloss.sampling.material`).
    data : bayesgloss.illumination.JointData or None
        The data sampled (set by :func:`bayesgloss.joint_estimate.joint_fit`).
    facets : bayesgloss.sampling.PosteriorSamples or None
        The run of each facet's own sampler given these draws
        (:func:`facets_given_frames`), where it was run.
    run : ChainRun or None
        Where the run stopped at its cap unconverged, its state, from which
        :func:`run_chain` (``resume``) runs it on; None once converged.
    """

    draws: np.ndarray
    frames: np.ndarray
    rhat: np.ndarray
    ess_bulk: np.ndarray
    ess_tail: np.ndarray
    converged: bool
    n_sweeps: int
    acceptance: dict
    seconds: float
    parameters: tuple = ("gamma", "log_n", "log_s", "log_sigma")  # + FRESNEL_PARAMETERS
    material: np.ndarray | None = None
    data: object = None
    facets: object = None
    run: object = None


@dataclass
class ChainRun:
    """A chain between chunks: the chain object (its random generator
    inside), the burn-in's sweeps, the states kept so far and the seconds
    spent."""

    chain: object
    burn: int
    th_kept: list = field(default_factory=list)
    lam_kept: list = field(default_factory=list)
    hyper_kept: list = field(default_factory=list)
    seconds: float = 0.0


def _diagnosed(th_kept, lam_kept):
    """(rhat, ess_bulk, ess_tail, ok) of gamma per facet and log a, log b per
    frame, for kept chains (n, E, F, W, 3) and (n, E, W, T, 4)."""
    n, e, f, w, _ = th_kept.shape
    t = lam_kept.shape[3]
    gamma = th_kept[..., 0].transpose(2, 1, 3, 0).reshape(f, e, w * n)
    lat = lam_kept[..., 1:3].transpose(4, 3, 1, 2, 0).reshape(2 * t, e, w * n)  # a's, then b's
    return diagnostics.diagnose(np.concatenate([gamma, lat]).astype(float))


def _rule_checked(kept: int, sweeps: int, min_sweeps: int, needed: int) -> bool:
    """Whether a run with ``kept`` states kept ``sweeps`` sweeps after
    burn-in checks its stopping rule: from ``min_sweeps`` on, once the kept
    half holds ``needed`` states a walker (every fit keeps the same number of
    draws: the stacks mix them draw by draw)."""
    return sweeps >= min_sweeps and kept - kept // 2 >= needed


def first_check(
    *,
    burn_rounds: tuple[int, ...],
    chunk: int,
    min_sweeps: int,
    draws_per_ensemble: int,
    n_walkers: int,
) -> int:
    """The sweeps after burn-in at which :func:`run_chain` with these
    arguments first checks its stopping rule. A run capped there stops where
    an uncapped one would have checked, with the same chain and draws."""
    burn, sweeps = sum(burn_rounds), chunk
    while not _rule_checked(
        (burn + sweeps) // THIN - burn // THIN, sweeps, min_sweeps, draws_per_ensemble // n_walkers
    ):
        sweeps += chunk
    return sweeps


def run_chain(
    chain_class,
    data: il.JointData,
    *,
    n_ensembles: int,
    n_walkers: int,
    chunk: int,
    min_sweeps: int,
    max_sweeps: int,
    draws_per_ensemble: int,
    seed: int | None,
    progress,
    diagnosed_facets: int | None = None,
    burn_rounds: tuple[int, ...] = BURN_ROUNDS,
    resume: ChainRun | None = None,
) -> JointSamples:
    """Run a chain of ``chain_class`` (:class:`~.joint._JointChain` or a
    subclass): burn-in (adapting the collective directions), then sweeps in
    chunks until converged or ``max_sweeps``; the kept second half thinned
    to :class:`JointSamples` (``material`` from the chain's ``hyper``, if
    any). ``diagnosed_facets``: the facets whose gamma the rule checks
    (None: all; 1 where gamma is shared). ``resume``: a run stopped at its
    cap (:attr:`JointSamples.run`), run on to this ``max_sweeps`` (the
    other arguments must be the first run's)."""
    if n_walkers < 6 or n_walkers % 2:
        raise ValueError(f"need an even number of walkers >= 6, got {n_walkers}")
    t0 = time.perf_counter()
    if resume is None:
        chain = chain_class(data, n_ensembles, n_walkers, np.random.default_rng(seed))
        for length in burn_rounds:
            states = []
            for _ in range(length):
                chain.sweep()
                if chain.sweeps % THIN == 0:
                    states.append(chain.state())
            chain.adapt(np.stack(states[len(states) // 2 :]))
        resume = ChainRun(chain, chain.sweeps)
    chain, burn = resume.chain, resume.burn
    hyper = getattr(chain, "hyper", None)
    th_kept, lam_kept, hyper_kept = resume.th_kept, resume.lam_kept, resume.hyper_kept
    pick = slice(None) if diagnosed_facets is None else slice(0, diagnosed_facets)
    diag = None
    while chain.sweeps < burn + max_sweeps:
        for _ in range(chunk):
            chain.sweep()
            if chain.sweeps % THIN == 0:
                th_kept.append(chain.th.astype(np.float32))
                lam_kept.append(chain.lam.astype(np.float32))
                if hyper is not None:
                    hyper_kept.append(chain.hyper.copy())
        if progress:
            progress(chain.sweeps - burn, max_sweeps)
        if _rule_checked(
            len(th_kept), chain.sweeps - burn, min_sweeps, draws_per_ensemble // n_walkers
        ):
            half = len(th_kept) // 2
            diag = _diagnosed(
                np.stack([x[:, pick] for x in th_kept[half:]]), np.stack(lam_kept[half:])
            )
            if np.all(diag[3]):
                break
    half = len(th_kept) // 2
    th = np.stack(th_kept[half:]).astype(float)  # (n, E, F, W, C): C = 3, or 6 with Fresnel
    lam = np.stack(lam_kept[half:]).astype(float)  # (n, E, W, T, L)
    if diag is None:
        diag = _diagnosed(th[:, :, pick], lam)
    n = len(th)
    keep = np.linspace(0, n - 1, max(1, min(n, draws_per_ensemble // n_walkers))).round()
    keep = keep.astype(int)
    th, lam = th[keep], lam[keep]
    m = len(th)
    e, f, w = n_ensembles, data.shape[0], n_walkers
    # (m, E, F, W, C) -> (F, E, W m, C), walkers one after another
    draws3 = th.transpose(2, 1, 3, 0, 4).reshape(f, e, w * m, th.shape[-1])
    frames = lam.transpose(1, 2, 0, 3, 4).reshape(e, w * m, data.shape[1], data.n_latents)
    material = None
    if hyper is not None:  # (m, E, W, 2) -> (E, W m, 2)
        hk = np.stack(hyper_kept[half:])[keep]
        material = hk.transpose(1, 2, 0, 3).reshape(e, w * m, -1)
    # log sigma from its conditional at every draw
    th_e = draws3.transpose(1, 0, 2, 3)  # (E, F, S, C)
    _, q = il.log_likelihood_sigma_marginal(th_e, frames, data, with_q=True)
    state = chain.rng.bit_generator.state  # a run run on goes on from the chain's own draws
    ls = chain._draw_log_sigma(q)  # (E, F, S), the chain's own noise model
    chain.rng.bit_generator.state = state
    # log sigma in column 3; the Fresnel k and log A (columns 4, 5) after it
    draws = np.concatenate([draws3[..., :3], ls.transpose(1, 0, 2)[..., None], draws3[..., 4:]], -1)
    parameters = JointSamples.parameters + (FRESNEL_PARAMETERS if draws.shape[-1] > 4 else ())
    sweeps = max(chain.sweeps, 1)
    resume.seconds += time.perf_counter() - t0
    return JointSamples(
        draws,
        frames,
        diag[0],
        diag[1],
        diag[2],
        bool(np.all(diag[3])),
        chain.sweeps,
        {k: v / sweeps for k, v in chain.accepted.items()},
        resume.seconds,
        parameters=parameters,
        material=material,
        run=None if np.all(diag[3]) else resume,
    )

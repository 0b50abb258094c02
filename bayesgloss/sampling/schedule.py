"""The chain's schedule: burn-in, sweeps in chunks until the stopping rule holds, kept draws.

:func:`run_chain` runs a chain of :mod:`bayesgloss.sampling.joint`'s
scheme (or :mod:`bayesgloss.sampling.material`'s): burn-in in rounds, the
collective directions adapted after each; then sweeps in chunks of
``chunk``, every THIN-th state kept, until over the kept second half gamma
and every frame's sun and sky latents have converged across the ensembles
by the rule of :mod:`bayesgloss.diagnostics` (R-hat < 1.01, bulk and tail
ESS >= 400), checked from ``min_sweeps`` on, or ``max_sweeps`` is reached
(flagged). The kept second half is thinned to :class:`JointSamples`.

The ensembles run in :data:`GROUPS` groups, each a chain of its own with
its own random generator spawned from the seed (:func:`group_sizes`), so
that two worker processes can run them at once (``jobs``); the rule is
checked on all groups' draws together, and the draws do not depend on
``jobs``.

A run stopped at its cap unconverged carries its state (:class:`ChainRun`),
and ``run_chain(..., resume=samples.run)`` runs the same chain on: the draws
are those of one run with the larger cap, sweep for sweep (the sky
families' screen, :func:`bayesgloss.sky_families.fit_families`, runs
every family to its first check and only those in reach on).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np

from .. import diagnostics
from .. import illumination as il
from ..pool import process_pool

__all__ = [
    "JointSamples",
    "ChainRun",
    "GroupRun",
    "run_chain",
    "group_sizes",
    "first_check",
    "THIN",
    "BURN_ROUNDS",
]

#: Kept chains hold every THIN-th sweep.
THIN = 4
#: Names of the draws' Fresnel columns (:data:`bayesgloss.fresnel.FRESNEL_COLUMNS`).
FRESNEL_PARAMETERS = ("fresnel_strength", "log_normal_albedo")
#: The ensembles run in this many groups, each a chain with its own random
#: generator, so that as many processes can run them at once (:func:`run_chain`).
GROUPS = 2
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
    material : ndarray (E, S, H) or None
        The one-material model's day-level coordinates
        (:data:`bayesgloss.illumination.HYPER`: m, log tau, the sun weights'
        log ratios, and where the exposure is day-level its mean and log spread).
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
class GroupRun:
    """One group of ensembles between chunks: the chain object (its random
    generator inside), the burn-in's sweeps and the states kept so far."""

    chain: object
    burn: int
    th_kept: list = field(default_factory=list)
    lam_kept: list = field(default_factory=list)
    hyper_kept: list = field(default_factory=list)


@dataclass
class ChainRun:
    """A run between chunks: each group's :class:`GroupRun`, the sweeps done
    after burn-in and the seconds spent."""

    groups: list
    sweeps: int = 0
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


def _kept(burn: int, sweeps: int) -> int:
    """States kept (every THIN-th sweep) ``sweeps`` sweeps after a burn-in of ``burn``."""
    return (burn + sweeps) // THIN - burn // THIN


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
        _kept(burn, sweeps), sweeps, min_sweeps, draws_per_ensemble // n_walkers
    ):
        sweeps += chunk
    return sweeps


def group_sizes(n_ensembles: int) -> list[int]:
    """The ensembles of each of :data:`GROUPS` groups (fewer where there are
    fewer ensembles), as even as can be."""
    g = max(1, min(GROUPS, n_ensembles))
    return [n_ensembles // g + (k < n_ensembles % g) for k in range(g)]


def _advance(chain_class, data, group, size, n_walkers, seed, burn_rounds, until) -> GroupRun:
    """One group's chain run to ``until`` sweeps after burn-in, every THIN-th
    state kept: from the start (``group`` None: a chain of ``size``
    ensembles with the generator of ``seed``, a :class:`numpy.random.SeedSequence`,
    and its burn-in, adapting the collective directions after each round)
    or from where ``group`` stopped. A function of its arguments alone, so
    that a worker process can run it (:func:`run_chain`'s ``jobs``)."""
    if group is None:
        chain = chain_class(data, size, n_walkers, np.random.default_rng(seed))
        for length in burn_rounds:
            states = []
            for _ in range(length):
                chain.sweep()
                if chain.sweeps % THIN == 0:
                    states.append(chain.state())
            chain.adapt(np.stack(states[len(states) // 2 :]))
        group = GroupRun(chain, chain.sweeps)
    chain = group.chain
    hyper = getattr(chain, "hyper", None) is not None
    while chain.sweeps < group.burn + until:
        chain.sweep()
        if chain.sweeps % THIN == 0:
            group.th_kept.append(chain.th.astype(np.float32))
            group.lam_kept.append(chain.lam.astype(np.float32))
            if hyper:
                group.hyper_kept.append(chain.hyper.copy())
    return group


def _joined(group: GroupRun | None, new: GroupRun) -> GroupRun:
    """``group`` with the chain and the states kept of its advance ``new``
    (:func:`_advance`), or ``new`` where the group had not started."""
    if group is None:
        return new
    group.chain = new.chain
    group.th_kept += new.th_kept
    group.lam_kept += new.lam_kept
    group.hyper_kept += new.hyper_kept
    return group


def _kept_half(groups, key: str, pick=slice(None)) -> np.ndarray:
    """The kept second half of every group's states ``key``, the groups'
    ensembles side by side: (n, E, ...)."""
    out = []
    for g in groups:
        kept = getattr(g, key)
        out.append(np.stack([x[:, pick] for x in kept[len(kept) // 2 :]]))
    return np.concatenate(out, axis=1)


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
    jobs: int = 1,
) -> JointSamples:
    """Run a chain of ``chain_class`` (:class:`~.joint._JointChain` or a
    subclass): burn-in (adapting the collective directions), then sweeps in
    chunks until converged or ``max_sweeps``; the kept second half thinned
    to :class:`JointSamples` (``material`` from the chain's ``hyper``, if
    any). ``diagnosed_facets``: the facets whose gamma the rule checks
    (None: all; 1 where gamma is shared). ``resume``: a run stopped at its
    cap (:attr:`JointSamples.run`), run on to this ``max_sweeps`` (the
    other arguments must be the first run's).

    The ensembles run in groups (:func:`group_sizes`), each a chain of its
    own with its own generator spawned from ``seed``; the rule is checked
    on all groups' draws together. ``jobs`` > 1 runs the groups at once in
    worker processes (:func:`bayesgloss.pool.process_pool`) between checks;
    the draws are the same whatever ``jobs``.
    """
    if n_walkers < 6 or n_walkers % 2:
        raise ValueError(f"need an even number of walkers >= 6, got {n_walkers}")
    t0 = time.perf_counter()
    sizes = group_sizes(n_ensembles)
    seeds = np.random.SeedSequence(seed).spawn(len(sizes))
    run = resume if resume is not None else ChainRun([None] * len(sizes))
    pick = slice(None) if diagnosed_facets is None else slice(0, diagnosed_facets)
    needed = draws_per_ensemble // n_walkers
    burn = sum(burn_rounds) if resume is None else resume.groups[0].burn
    diag = None
    pool = process_pool(min(jobs, len(sizes))) if jobs > 1 and len(sizes) > 1 else None
    try:
        while run.sweeps < max_sweeps:
            until = run.sweeps + chunk
            # a group that has started carries its data in its chain, and
            # goes to the worker without its kept states: only the new come back
            sent = [None if g is None else GroupRun(g.chain, g.burn) for g in run.groups]
            args = [
                (chain_class, None if g else data, g, size, n_walkers, sd, burn_rounds, until)
                for g, size, sd in zip(sent, sizes, seeds, strict=True)
            ]
            if pool is None:
                done = [_advance(*a) for a in args]
            else:
                done = list(pool.map(_advance, *zip(*args, strict=True)))
            run.groups = [_joined(g, new) for g, new in zip(run.groups, done, strict=True)]
            run.sweeps = until
            if progress:
                progress(run.sweeps, max_sweeps)
            if _rule_checked(_kept(burn, run.sweeps), run.sweeps, min_sweeps, needed):
                diag = _diagnosed(
                    _kept_half(run.groups, "th_kept", pick), _kept_half(run.groups, "lam_kept")
                )
                if np.all(diag[3]):
                    break
    finally:
        if pool is not None:
            pool.shutdown()
    # (n, E, F, W, C): C = 3, or 6 with Fresnel
    th = _kept_half(run.groups, "th_kept").astype(float)
    lam = _kept_half(run.groups, "lam_kept").astype(float)  # (n, E, W, T, L)
    if diag is None:
        diag = _diagnosed(th[:, :, pick], lam)
    n = len(th)
    keep = np.linspace(0, n - 1, max(1, min(n, needed))).round()
    keep = keep.astype(int)
    th, lam = th[keep], lam[keep]
    m = len(th)
    e, f, w = n_ensembles, data.shape[0], n_walkers
    # (m, E, F, W, C) -> (F, E, W m, C), walkers one after another
    draws3 = th.transpose(2, 1, 3, 0, 4).reshape(f, e, w * m, th.shape[-1])
    frames = lam.transpose(1, 2, 0, 3, 4).reshape(e, w * m, data.shape[1], data.n_latents)
    chains = [g.chain for g in run.groups]
    material = None
    if getattr(chains[0], "hyper", None) is not None:  # (m, E, W, 2) -> (E, W m, 2)
        hk = _kept_half(run.groups, "hyper_kept")[keep]
        material = hk.transpose(1, 2, 0, 3).reshape(e, w * m, -1)
    # log sigma from its conditional at every draw, each group's from its own
    # generator; given the entries not clipped (a clipped one's completed
    # value is not kept)
    th_e = draws3.transpose(1, 0, 2, 3)  # (E, F, S, C)
    measured = data
    if data.censored is not None:
        measured = replace(data, valid=data.valid & ~data.censored, censored=None)
    ls, start = [], 0
    for chain, size in zip(chains, sizes, strict=True):
        group = slice(start, start + size)
        start += size
        _, q = il.log_likelihood_sigma_marginal(th_e[group], frames[group], measured, with_q=True)
        state = chain.rng.bit_generator.state  # a run run on goes on from the chain's own draws
        ls.append(chain._draw_log_sigma(q, measured))  # (E, F, S), the chain's own noise model
        chain.rng.bit_generator.state = state
    ls = np.concatenate(ls)
    # log sigma in column 3; the Fresnel k and log A (columns 4, 5) after it
    draws = np.concatenate([draws3[..., :3], ls.transpose(1, 0, 2)[..., None], draws3[..., 4:]], -1)
    parameters = JointSamples.parameters + (FRESNEL_PARAMETERS if draws.shape[-1] > 4 else ())
    sweeps = max(chains[0].sweeps, 1)
    accepted = {
        k: sum(c.accepted[k] * size for c, size in zip(chains, sizes, strict=True)) / e / sweeps
        for k in chains[0].accepted
    }
    run.seconds += time.perf_counter() - t0
    return JointSamples(
        draws,
        frames,
        diag[0],
        diag[1],
        diag[2],
        bool(np.all(diag[3])),
        chains[0].sweeps,
        accepted,
        run.seconds,
        parameters=parameters,
        material=material,
        run=None if np.all(diag[3]) else run,
    )

"""A stream of facets through a fixed number of vectorised places.

:class:`FacetStream` is the facet sampler's scheduler. Its facets wait in a
queue (those in plain coordinates, the broadest posteriors and the longest
runs, first, so that they run beside the others rather than at the end in a
nearly empty batch); ``slots`` of them at a time hold a place, E independent
ensembles each, and advance together through one
:class:`bayesgloss.sampling.ensemble.BatchedEnsemble`. One round is

1. :meth:`~FacetStream.fill`: waiting facets take the free places (a start
   from :func:`bayesgloss.sampling.starts.initial_ensemble`, in each
   facet's coordinates);
2. :meth:`~FacetStream.advance`: every place runs ``chunk`` steps; after the
   burn-in, every 2nd step is kept (in parameters, as float32 offsets from
   the facet's first kept mean, so that they resolve posteriors far
   narrower than the parameters' values);
3. :meth:`~FacetStream.measure`: places whose run has reached their next
   check get their integrated autocorrelation times (runs of one length
   share one transform) and, when long enough, ArviZ's R-hat and ESS of
   gamma (:func:`bayesgloss.diagnostics.converged`, all due facets at once);
4. :meth:`~FacetStream.retire`: converged facets (or those at the step cap)
   leave with their draws, and their places are free for the next round.

The per-place state (walkers, log densities, blobs, ages, next checks,
acceptance sums) lives in one :class:`_Places` record, so that places join
and leave all arrays together.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import diagnostics
from .. import likelihood as lk
from .coordinates import RidgeCoordinates
from .ensemble import BatchedEnsemble, with_blob
from .jumps import ExponentJump
from .starts import initial_ensemble

__all__ = ["FacetStream", "FIRST_CHECK_TAUS"]

#: The first convergence check comes after this many times ``min_tau_multiple``
#: steps (facets in ridge coordinates mix in about 5.5 steps, the others slower).
FIRST_CHECK_TAUS = 5.0
#: Kept chains hold every 2nd step (tau >> 2 steps here).
THIN = 2


@dataclass
class _Places:
    """The state of the places of a stream, A places of E ensembles.

    Attributes
    ----------
    facet : list of int
        The facet in each place, (A,).
    coords, log_p : ndarray (A E, W, P) and (A E, W)
        Walkers in sampling coordinates and their log densities.
    blob : ndarray (A E, W) or None
        The density's blob (Q where sigma is integrated out) at every walker.
    age : ndarray (A,) of int
        Chunks run.
    next_check : ndarray (A,)
        Production steps at which to estimate tau next.
    acc_sum : ndarray (A, E)
        Summed acceptance rates of the production chunks.
    """

    facet: list
    coords: np.ndarray
    log_p: np.ndarray
    blob: np.ndarray | None
    age: np.ndarray
    next_check: np.ndarray
    acc_sum: np.ndarray

    def join(self, other: _Places) -> None:
        """Append the places of ``other``."""
        self.facet = self.facet + other.facet
        self.coords = np.concatenate([self.coords, other.coords])
        self.log_p = np.concatenate([self.log_p, other.log_p])
        if self.blob is not None:
            self.blob = np.concatenate([self.blob, other.blob])
        self.age = np.concatenate([self.age, other.age])
        self.next_check = np.concatenate([self.next_check, other.next_check])
        self.acc_sum = np.concatenate([self.acc_sum, other.acc_sum])

    def keep(self, keep, n_ensembles: int) -> None:
        """Keep the places where ``keep`` (A,) is True."""
        self.facet = [f for f, k in zip(self.facet, keep, strict=True) if k]
        rows = np.repeat(keep, n_ensembles)
        self.coords, self.log_p = self.coords[rows], self.log_p[rows]
        if self.blob is not None:
            self.blob = self.blob[rows]
        self.age, self.acc_sum = self.age[keep], self.acc_sum[keep]
        self.next_check = self.next_check[keep]


class FacetStream:
    """One stream of facets, sampled E independent ensembles each (module docstring).

    Parameters: those of :func:`bayesgloss.sampling.sample_posterior`, and
    ``marginal`` (sigma integrated out) and the stream's ``rng``.
    """

    def __init__(
        self,
        data: lk.CurveData,
        rng: np.random.Generator,
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
        self.data, self.rng = data, rng
        self.n_ensembles, self.n_walkers = n_ensembles, n_walkers
        self.chunk, self.slots = chunk, slots
        self.burn_taus, self.min_tau_multiple, self.max_steps = (
            burn_taus,
            min_tau_multiple,
            max_steps,
        )
        self.marginal = marginal
        n_f, e = len(data.y), n_ensembles
        self.p = p = 3 if marginal else data.n_params  # dimensions the ensembles explore
        if marginal:  # the density also hands back Q, kept to draw sigma from at the end

            def log_prob(theta, d):
                return lk.log_probability_sigma_marginal(theta, d, with_q=True)

        else:
            log_prob = lk.log_probability
        self.log_prob = log_prob
        self.n_keep = p + 1 if marginal else p  # kept chains carry Q as a last column
        self.coords_of = RidgeCoordinates.of(data, max_rms=ridge if ridge else -1.0)
        self.jump = None
        if {"n-jump", "ridge-jump"} & {m for m, _ in moves}:
            if marginal:
                self.jump = ExponentJump.of(data, marginal, ridge=self.coords_of)
            else:  # jumps in log n alone rarely fit 4-5 free coordinates: DE instead
                moves = tuple((("de" if m in ("n-jump", "ridge-jump") else m), w) for m, w in moves)
        self.burn_chunks = -(-burn // chunk)
        self.draws_per_ensemble = n_walkers * max(1, draws_per_ensemble // n_walkers)
        self.out = np.empty((n_f, e, self.draws_per_ensemble, self.n_keep))
        self.tau_out = np.full((n_f, e, p), np.nan)
        self.steps_out = np.zeros(n_f, dtype=int)
        self.acc_out = np.zeros((n_f, e))
        # facets in plain coordinates (broad posteriors, the longest runs) first, so
        # that they run beside the others rather than in a nearly empty batch at the end
        self.waiting = list(np.argsort(self.coords_of.active, kind="stable"))
        self.places = _Places(
            [],
            np.empty((0, n_walkers, p)),
            np.empty((0, n_walkers)),
            np.empty((0, n_walkers)) if marginal else None,
            np.empty(0, dtype=int),
            np.empty(0),
            np.empty((0, e)),
        )
        self.kept: dict[int, list[np.ndarray]] = {}  # kept chains per facet
        self.origin: dict[int, np.ndarray] = {}  # each facet's first kept mean
        self.first_check = max(chunk, FIRST_CHECK_TAUS * min_tau_multiple)
        self.sampler = BatchedEnsemble(None, moves, rng)

    @property
    def busy(self) -> bool:
        """Whether facets are waiting or running."""
        return bool(self.waiting or self.places.facet)

    def fill(self) -> None:
        """Waiting facets take the free places."""
        e, p, data = self.n_ensembles, self.p, self.data
        new = self.waiting[: max(0, self.slots - len(self.places.facet))]
        self.waiting = self.waiting[len(new) :]
        if not new:
            return
        rows = np.repeat(new, e)
        sub = data.take(rows)
        start = initial_ensemble(sub, self.n_walkers, self.rng)[..., :p]
        x, lp, q0 = self._start(rows, sub, start)
        # a start the ridge map cannot represent: that facet keeps plain coordinates
        plain_ok = np.isfinite(with_blob(self.log_prob(start, sub))[0])
        lost = np.any(~np.isfinite(lp) & plain_ok, axis=1)
        if np.any(lost):
            self.coords_of.active[np.unique(rows[lost])] = False
            x, lp, q0 = self._start(rows, sub, start)
        self.places.join(
            _Places(
                list(new),
                x,
                lp,
                q0 if self.marginal else None,
                np.zeros(len(new), dtype=int),
                np.full(len(new), self.first_check),
                np.zeros((len(new), e)),
            )
        )
        for f in new:
            self.kept[f] = []

    def _start(self, rows, sub, start):
        """Starting walkers in each row's sampling coordinates, their log density and blob."""
        coords = self.coords_of.take(rows)
        x = coords.from_theta(start)
        lp, q0 = with_blob(coords.log_prob(self.log_prob, sub)(x))
        return x, lp, q0

    def advance(self) -> list[int]:
        """Run every place ``chunk`` steps and keep its chain; returns the
        places due for a check."""
        e, p, w, pl = self.n_ensembles, self.p, self.n_walkers, self.places
        rows = np.repeat(pl.facet, e)
        batch_coords = self.coords_of.take(rows)
        sampler = self.sampler
        sampler.log_prob = batch_coords.log_prob(self.log_prob, self.data.take(rows))
        if self.jump is not None:
            sampler.jump = self.jump.take(rows, batch_coords.active)
        ch, lp, acc = sampler.run(pl.coords, self.chunk, pl.log_p, pl.blob)
        pl.coords, pl.log_p = ch[-1].copy(), lp[-1].copy()
        if self.marginal:
            pl.blob = sampler.blobs[-1].copy()
        pl.age += 1
        a = len(pl.facet)
        kept_steps = ch[::THIN]  # sampling coordinates to parameters, (n, a E, W, P)
        n_kept = len(kept_steps)
        th = batch_coords.to_theta(kept_steps.transpose(1, 0, 2, 3).reshape(a * e, n_kept * w, p))[
            0
        ]
        ch = th.reshape(a * e, n_kept, w, p).transpose(1, 0, 2, 3)
        if self.marginal:
            ch = np.concatenate([ch, sampler.blobs[::THIN][..., None]], axis=-1)
        ch = ch.reshape(n_kept, a, e, w, self.n_keep)
        acc = acc.reshape(a, e)
        due = []
        for k, f in enumerate(pl.facet):
            if pl.age[k] <= self.burn_chunks:
                continue
            if f not in self.origin:
                self.origin[f] = ch[0, k].mean(axis=(0, 1))
                self.origin[f][p:] = 0.0  # Q (a positive sum of squares) as it is
            self.kept[f].append((ch[:, k] - self.origin[f]).astype(np.float32))
            pl.acc_sum[k] += acc[k]
            n_steps = self._steps(k)
            if n_steps >= pl.next_check[k] or n_steps >= self.max_steps:
                self.kept[f] = [np.concatenate(self.kept[f])]  # (N / thin, E, W, P)
                due.append(k)
        return due

    def _steps(self, k: int) -> int:
        """Production steps run by place k."""
        return (self.places.age[k] - self.burn_chunks) * self.chunk

    def measure(self, due: list[int]) -> dict:
        """Check the places ``due``; returns ``place -> (draws, tau)`` of those
        that finished (converged, or at the step cap) and schedules the next
        check of the others."""
        pl, p, chunk = self.places, self.p, self.chunk
        # one autocorrelation function averaged over the walkers of every
        # ensemble (the same sampler on the same target), per parameter;
        # runs of the same length share one transform
        taus = {}
        for n_kept in {len(self.kept[pl.facet[k]][0]) for k in due}:
            group = [k for k in due if len(self.kept[pl.facet[k]][0]) == n_kept]
            runs = np.stack([self.kept[pl.facet[k]][0] for k in group], axis=1)
            runs = runs[..., :p].reshape(n_kept, len(group), self.n_ensembles * self.n_walkers, p)
            # every 2nd kept step (4th step) suffices for tau >> 4 steps and
            # halves the transforms (for small tau it errs long, never short)
            t = 2 * THIN * diagnostics.integrated_time(runs[::2])
            taus.update(zip(group, t, strict=True))
        checks = {}
        for k in due:
            run, t = self.kept[pl.facet[k]][0], taus[k]
            t_max = np.nan_to_num(t, nan=np.inf).max()
            # burn-in of at least burn_taus tau: where the fixed burn was shorter,
            # the start of the production run is discarded too
            drop = self.burn_taus * t_max - self.burn_chunks * chunk
            drop = int(np.ceil(drop / THIN)) if np.isfinite(drop) and drop > 0 else 0
            run = run[min(drop, len(run) // 2) :]
            enough = len(run) * THIN >= t_max * self.min_tau_multiple
            need = t_max * self.min_tau_multiple + drop * THIN
            draws = _ensemble_draws(run, self.draws_per_ensemble) + self.origin[pl.facet[k]]
            checks[k] = (draws, enough, need)
        # R-hat and ESS of gamma for every run long enough, at once
        ready = [k for k in due if checks[k][1]]
        converged = {}
        if ready:
            gammas = np.stack([checks[k][0][..., 0] for k in ready])
            converged = dict(zip(ready, diagnostics.converged(gammas), strict=True))
        finished = {}
        for k in due:
            draws, enough, need = checks[k]
            n_steps = self._steps(k)
            if converged.get(k, False) or n_steps >= self.max_steps:
                finished[k] = (draws, taus[k])
            elif enough:  # long enough but not yet converged: 25 % more steps
                pl.next_check[k] = n_steps + max(chunk, 0.25 * n_steps)
            else:  # check again when the estimate says it may be enough
                pl.next_check[k] = max(need, n_steps + chunk)
        return finished

    def retire(self, finished: dict) -> None:
        """Store the draws of the finished places and free them."""
        pl = self.places
        if not finished:
            return
        for k, (draws, tau) in finished.items():
            f = pl.facet[k]
            self.out[f] = draws
            self.tau_out[f], self.steps_out[f] = tau, self._steps(k)
            self.acc_out[f] = pl.acc_sum[k] / (pl.age[k] - self.burn_chunks)
            del self.kept[f], self.origin[f]
        keep = np.ones(len(pl.facet), dtype=bool)
        keep[list(finished)] = False
        pl.keep(keep, self.n_ensembles)

    def run(self):
        """Sample every facet; returns (draws (F, E, S, P'), tau (F, E, P'),
        steps (F,), acceptance (F, E)), with log sigma drawn last where it was
        integrated out."""
        while self.busy:
            self.fill()
            self.retire(self.measure(self.advance()))
        out, tau_out, p = self.out, self.tau_out, self.p
        if self.marginal:  # log sigma from its conditional posterior at every kept draw
            n_f, e, s = out.shape[:3]
            out, q = out[..., :p], out[..., p].reshape(n_f, e * s)
            th = out.reshape(n_f, e * s, p)
            log_sigma = lk.draw_log_sigma(th, self.data, self.rng, q=q)
            out = np.concatenate([out, log_sigma.reshape(n_f, e, s, 1)], axis=-1)
            tau_out = np.concatenate([tau_out, np.full((n_f, e, 1), np.nan)], axis=-1)
        return out, tau_out, self.steps_out, self.acc_out


def _ensemble_draws(run, n_draws: int) -> np.ndarray:
    """Draws per ensemble, (E, S, P): each walker's trajectory thinned evenly,
    walkers one after the other (so that every stretch of a chain is one
    walker's Markov chain, as ArviZ's R-hat and ESS assume)."""
    n, e, w, p = run.shape
    per = max(1, n_draws // w)
    idx = np.linspace(0, n - 1, per).round().astype(int)
    return run[idx].transpose(1, 2, 0, 3).reshape(e, w * per, p).astype(float)

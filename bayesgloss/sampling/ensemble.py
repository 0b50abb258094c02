"""B independent affine-invariant ensembles advanced together.

Stock emcee runs one problem at a time and its per-step overhead dominates
for a 19-frame likelihood. :class:`BatchedEnsemble` runs B independent
problems (facets, or independent ensembles of one facet) in lockstep through
one vectorised log-probability call per half-step, with emcee's scheme: the
walkers split at random into two halves, each half moved in turn from the
other (:mod:`bayesgloss.sampling.moves`), each proposal accepted with
probability min(1, factor x p(Y) / p(X)). The randomness comes from one
``numpy.random.Generator``; problems never share walkers, so each problem's
chain is a chain of emcee's algorithm for it with the same moves.
"""

from __future__ import annotations

import numpy as np

from .moves import DEFAULT_MOVES, MOVE_NAMES, move_named

__all__ = ["BatchedEnsemble", "with_blob", "fold_copies", "unfold_copies"]


def with_blob(value):
    """(log p, blob) from a density that may or may not return a blob."""
    return value if isinstance(value, tuple) else (value, None)


class BatchedEnsemble:
    """B independent affine-invariant ensembles advanced together.

    Parameters
    ----------
    log_prob : callable
        theta (B, K, P) -> log density (B, K), or (log density, blob); must
        accept any K.
    moves : sequence of (name, weight)
        From :data:`bayesgloss.sampling.moves.MOVE_NAMES` (``"n-jump"`` and
        ``"ridge-jump"`` need ``jump``).
    rng : numpy.random.Generator
    stretch_a : float
        Scale of the stretch move (emcee's default 2).
    jump : ExponentJump, optional
        The independence proposals of the ``"n-jump"`` and ``"ridge-jump"``
        moves, one per problem.
    pass_walkers : bool
        Call ``log_prob(theta, walkers)`` with the indices (H,) of the
        walkers ``theta`` proposes for, for densities that differ by walker
        (the conditional of a block in a Gibbs sampler whose other blocks
        each walker carries, :mod:`bayesgloss.sampling.joint`).
    """

    def __init__(
        self,
        log_prob,
        moves=DEFAULT_MOVES,
        rng=None,
        stretch_a: float = 2.0,
        jump=None,
        pass_walkers: bool = False,
    ):
        self.log_prob = log_prob
        self.jump = jump
        self.pass_walkers = pass_walkers
        names = [m for m, _ in moves]
        bad = set(names) - set(MOVE_NAMES)
        if bad:
            raise ValueError(f"unknown move(s) {sorted(bad)}; valid: {', '.join(MOVE_NAMES)}")
        w = np.array([float(x) for _, x in moves])
        self.moves, self.weights = names, w / w.sum()
        self._moves = [move_named(m, stretch_a) for m in names]
        # Generator.choice(p=...) draws one uniform and searches this cdf
        self._cdf = np.cumsum(self.weights)
        self._cdf /= self._cdf[-1]
        self.rng = rng if rng is not None else np.random.default_rng()
        self.a = stretch_a

    def step(self, coords, log_p, blob=None):
        """One step (both halves) in place; returns the acceptance mask (B, W).

        The random split into halves is shared by the B problems (it only
        decides which walkers move first); every other random number is
        drawn per problem and walker. Where ``log_prob`` returns (log p,
        blob), ``blob`` (B, W) keeps the blob of every walker's position.
        """
        w = coords.shape[1]
        # = rng.choice(len(moves), p=weights), the same draw without its overhead
        move = self._moves[int(self._cdf.searchsorted(self.rng.random(), side="right"))]
        order = self.rng.permutation(w)
        halves = (order[: w // 2], order[w // 2 :])
        accepted = np.zeros(log_p.shape, dtype=bool)
        for k in (0, 1):
            idx, cidx = halves[k], halves[1 - k]
            s = coords[:, idx]
            q, factor = move.propose(s, coords[:, cidx], self.rng, self.jump)
            lp_new = self.log_prob(q, idx) if self.pass_walkers else self.log_prob(q)
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
            log_p, blob = with_blob(self.log_prob(coords))
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


def fold_copies(theta, copies: int) -> np.ndarray:
    """(C*B, W, P) -> (B, C*W, P): C copies of B problems side by side in the
    walker axis, so that one density call serves all copies."""
    cb, w, p = theta.shape
    th = theta.reshape(copies, cb // copies, w, p).transpose(1, 0, 2, 3)
    return th.reshape(-1, copies * w, p)


def unfold_copies(values, copies: int) -> np.ndarray:
    """(B, C*W) -> (C*B, W): the inverse of :func:`fold_copies` for values per walker."""
    b, cw = values.shape
    return values.reshape(b, copies, cw // copies).transpose(1, 0, 2).reshape(copies * b, -1)

"""Ensemble moves, batched over B independent problems, as small classes.

Each move proposes new positions for the walkers ``s`` (B, H, P) of one half
of every ensemble from the complementary half ``c`` (B, C, P), and returns
the proposals with the log of their Metropolis-Hastings factor (B, H), as
emcee's moves do (one class per move, ``emcee.moves``):

- :class:`StretchMove` (``"stretch"``): the affine-invariant stretch move of
  Goodman & Weare (2010, eq. 7): Y = X_j + z (X_k - X_j) with X_j drawn from
  the other half and z from g(z) ~ 1/sqrt(z) on [1/a, a], a = 2; factor
  z^(P-1);
- :class:`DEMove` (``"de"``): differential evolution (ter Braak 2006; Nelson
  et al. 2013, as emcee's ``DEMove``): Y = X_k + gamma (X_i - X_j) for two
  distinct walkers of the other half, gamma = gamma0 (1 + 1e-5 N(0, 1)),
  gamma0 = 2.38 / sqrt(2 P), efficient along banana-shaped ridges;
  ``"de-jump"`` is the same with gamma0 = 1, which carries walkers between
  modes;
- :class:`ExponentJumpMove` (``"n-jump"``): an independence proposal in
  log n from each problem's :class:`bayesgloss.sampling.jumps.ExponentJump`;
- :class:`RidgeJumpMove` (``"ridge-jump"``): for problems in ridge
  coordinates an independence proposal of the whole point; for the others
  the n-jump with probability :data:`PLAIN_JUMP`, DE otherwise.

Walker indices are drawn as floor(u C) from uniforms (exactly uniform
integers up to 2^-53), the cheapest draw for many small problems.

Mixes are sequences of (name, weight); one move is chosen per step for all
problems, as emcee chooses one move per step.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "StretchMove",
    "DEMove",
    "ExponentJumpMove",
    "RidgeJumpMove",
    "MOVE_NAMES",
    "move_named",
    "DEFAULT_MOVES",
    "proposal_square_root",
    "FACET_MOVES",
    "PLAIN_JUMP",
]

#: The mix for any target: stretch 0.2, DE 0.7, DE-jump 0.1.
DEFAULT_MOVES = (("stretch", 0.2), ("de", 0.7), ("de-jump", 0.1))
#: The facet sampler's mix: the default plus independence jumps in log n
#: between the modes of its profile posterior (:class:`RidgeJumpMove`).
FACET_MOVES = (("stretch", 0.2), ("de", 0.4), ("de-jump", 0.1), ("ridge-jump", 0.3))
#: In plain coordinates ``"ridge-jump"`` is the n-jump with this probability
#: and DE otherwise: there the facet mix is stretch 0.2, DE 0.6, DE-jump 0.1,
#: n-jump 0.1.
PLAIN_JUMP = 1.0 / 3.0


def _walkers(c, index) -> np.ndarray:
    """Walkers ``index`` (B, H) of each problem's half ``c`` (B, C, P), (B, H, P)."""
    b, nc, p = c.shape
    base = (np.arange(b) * nc)[:, None]  # first row of each problem in the flat half
    return np.take(c.reshape(b * nc, p), base + index, axis=0)


class StretchMove:
    """Goodman & Weare's stretch move of scale ``a`` (emcee's ``StretchMove``)."""

    needs_jump = False

    def __init__(self, a: float = 2.0):
        self.a = float(a)

    def propose(self, s, c, rng, jump=None):
        b, h, p = s.shape
        u = rng.random((2, b, h))
        z = ((self.a - 1.0) * u[0] + 1.0) ** 2 / self.a
        cj = _walkers(c, (u[1] * c.shape[1]).astype(np.intp))
        return cj - (cj - s) * z[..., None], (p - 1.0) * np.log(z)


class DEMove:
    """Differential evolution; ``gamma0`` None is 2.38 / sqrt(2 P) (emcee's ``DEMove``)."""

    needs_jump = False

    def __init__(self, gamma0: float | None = None):
        self.gamma0 = gamma0

    def propose(self, s, c, rng, jump=None):
        b, h, p = s.shape
        nc = c.shape[1]
        u = rng.random((2, b, h))
        g0 = 2.38 / np.sqrt(2.0 * p) if self.gamma0 is None else self.gamma0
        i = (u[0] * nc).astype(np.intp)
        j = (i + 1 + (u[1] * (nc - 1)).astype(np.intp)) % nc  # distinct from i
        gamma = g0 * (1.0 + 1e-5 * rng.standard_normal((b, h, 1)))
        diff = _walkers(c, i) - _walkers(c, j)
        return s + gamma * diff, np.zeros((b, h))


class ExponentJumpMove:
    """Independence proposals in log n (:meth:`ExponentJump.propose`)."""

    needs_jump = True

    def propose(self, s, c, rng, jump):
        return jump.propose(s, rng)


class RidgeJumpMove:
    """Whole-point independence proposals in ridge rows; in plain rows the
    n-jump with probability :data:`PLAIN_JUMP`, DE otherwise."""

    needs_jump = True

    def __init__(self):
        self.de = DEMove()

    def propose(self, s, c, rng, jump):
        y, f = jump.propose(s, rng, fresh=True)
        yd, fd = self.de.propose(s, c, rng)
        take = (jump.column == 0) | (rng.random(len(s)) < PLAIN_JUMP)
        return np.where(take[:, None, None], y, yd), np.where(take[:, None], f, fd)


#: Move names of the mixes.
MOVE_NAMES = ("stretch", "de", "de-jump", "n-jump", "ridge-jump")


def move_named(name: str, stretch_a: float = 2.0):
    """The move of a mix's name (:data:`MOVE_NAMES`)."""
    if name == "stretch":
        return StretchMove(stretch_a)
    if name == "de":
        return DEMove()
    if name == "de-jump":
        return DEMove(1.0)
    if name == "n-jump":
        return ExponentJumpMove()
    if name == "ridge-jump":
        return RidgeJumpMove()
    raise ValueError(f"unknown move {name!r}; valid: {', '.join(MOVE_NAMES)}")


def proposal_square_root(info, prior) -> np.ndarray:
    """A square root M of (info + diag(prior))^-1 (M M^T the inverse), (..., L, L).

    ``info`` is a Gauss-Newton information matrix of the data (positive
    semi-definite in exact arithmetic) and ``prior`` the positive diagonal
    of the priors' precisions, (L,) or (..., L) broadcasting with ``info``'s
    leading axes. The Cholesky factor of the inverse where it
    exists; where rounding made a matrix indefinite (a huge precision for a
    latent held fixed beside data of another scale: a holdout sequence
    under a fixed gensky shape stopped a run, stop 28), or ``info`` is not
    finite, the
    symmetric square root from the eigendecomposition with every eigenvalue
    floored at the smallest prior precision, the least the exact matrix can
    have (non-finite entries of ``info`` set to 0 first).
    """
    prior = np.asarray(prior, dtype=float)
    diag = prior[..., :, None] * np.eye(prior.shape[-1])
    full = info + diag
    try:
        return np.linalg.cholesky(np.linalg.inv(full))
    except np.linalg.LinAlgError:
        pass
    info = np.where(np.isfinite(info), info, 0.0)
    full = 0.5 * (info + np.swapaxes(info, -1, -2)) + diag
    values, vectors = np.linalg.eigh(full)
    values = np.maximum(values, np.min(prior, axis=-1, keepdims=True))
    return vectors / np.sqrt(values)[..., None, :]

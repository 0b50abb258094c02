"""Exact moves along a ridge whose conditional the priors alone decide.

Where the likelihood is flat along a direction of the state (the scale
ridge of the one-material model: every facet's albedo down by c and every
frame's light up by c; the exposure ridge of one frame: its exposure up by
c, its sun and sky down by c), the conditional along that direction is a
product of priors. Under the sun's mixture prior (clear, dimmed, hidden:
:func:`bayesgloss.illumination.log_prior_frames`) it can have two modes
about 1.3 apart in log brightness (a clear but hazy sun under a bright
sky, or a dimmed sun under the model's sky), and a random-walk step of the
ridge's Gaussian width rarely crosses between them (``studies/README.md``,
"Stop 41: why most answers on renders say `not-converged`").

:func:`lattice_shift` draws the shift from the conditional evaluated on a
lattice around the current point and accepts it with the ratio of the two
windows' sums (a multiple-try move on a lattice, which leaves the target
invariant for any lattice spacing drawn independently of the state: Liu,
Liang & Wong 2000, *J. Am. Stat. Assoc.* 95, 121; Liu & Sabatti 2000,
*Biometrika* 87, 353, for moves along a group). Each lattice point costs
one evaluation of the priors only, never of the likelihood.
"""

from __future__ import annotations

import numpy as np

__all__ = ["lattice_offsets", "lattice_shift"]


def lattice_offsets(reach: int) -> np.ndarray:
    """The integer offsets at which :func:`lattice_shift` evaluates the
    density: -2 reach, ..., 2 reach (the current window and every window a
    draw can move to)."""
    return np.arange(-2 * reach, 2 * reach + 1)


def lattice_shift(log_density_at, reach: int, rng) -> np.ndarray:
    """One multiple-try lattice move of many independent ridges at once.

    Parameters
    ----------
    log_density_at : ndarray (2 * reach + 1 + 2 * reach, ...)
        The log conditional density (up to a constant) at the current point
        shifted by each of :func:`lattice_offsets` times the lattice spacing,
        along the first axis; the other axes are independent ridges (walkers,
        frames). -inf where a shift leaves the support.
    reach : int
        The window's half width: a draw moves by at most ``reach`` steps.
    rng : numpy.random.Generator

    Returns
    -------
    ndarray of int, shape ``log_density_at.shape[1:]``
        The accepted offset of each ridge, in lattice steps (0 where the
        move was refused).

    Notes
    -----
    From x, the proposal picks x + j h, |j| <= reach, with probability
    pi(x + j h) / Z(x), Z(x) = sum_{|i| <= reach} pi(x + i h); the reverse
    move picks x from x + j h's window with probability pi(x) / Z(x + j h),
    so the Metropolis-Hastings ratio is Z(x) / Z(x + j h).
    """
    lp = np.asarray(log_density_at, float)
    k = 2 * reach + 1
    if lp.shape[0] != 4 * reach + 1:
        raise ValueError(f"expected {4 * reach + 1} lattice points, got {lp.shape[0]}")
    top = np.max(lp, axis=0)
    top = np.where(np.isfinite(top), top, 0.0)
    p = np.exp(lp - top)
    # window[s]: the sum over offsets s - 2 reach .. s, the window centred on s - reach
    window = np.stack([p[s : s + k].sum(axis=0) for s in range(k)])
    inner = p[reach : reach + k]  # the current window, offsets -reach .. reach
    cdf = np.cumsum(inner, axis=0)
    u = rng.random(lp.shape[1:]) * cdf[-1]
    j = np.minimum(np.sum(cdf < u, axis=0), k - 1)  # index into the window
    z_new = np.take_along_axis(window, j[None], 0)[0]
    z_cur = window[reach]
    with np.errstate(divide="ignore", invalid="ignore"):
        log_ratio = np.log(z_cur) - np.log(z_new)
    ok = np.log(rng.random(lp.shape[1:])) < log_ratio
    ok &= np.isfinite(np.take_along_axis(lp[reach : reach + k], j[None], 0)[0])
    return np.where(ok, j - reach, 0)

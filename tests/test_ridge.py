"""The lattice move along a ridge (bayesgloss.sampling.ridge)."""

import numpy as np
import pytest
from scipy import stats

from bayesgloss.sampling import ridge


def _bimodal(x):
    # two modes 1.3 apart, unequal masses (0.75 / 0.25), sds 0.3 and 0.5:
    # the shape of the scale ridge's conditional under the sun's mixture prior
    return np.logaddexp(
        np.log(0.75) + stats.norm.logpdf(x, 0.0, 0.3),
        np.log(0.25) + stats.norm.logpdf(x, -1.3, 0.5),
    )


def _cdf(x):
    return 0.75 * stats.norm.cdf(x, 0.0, 0.3) + 0.25 * stats.norm.cdf(x, -1.3, 0.5)


def _move(x, reach, rng, h=None):
    h = rng.uniform(0.05, 0.15) if h is None else h
    points = x[None] + ridge.lattice_offsets(reach)[:, None] * h
    return x + ridge.lattice_shift(_bimodal(points), reach, rng) * h


def test_lattice_move_leaves_its_target_invariant():
    # 40000 independent draws of the target, one move each: the moved draws
    # must still follow the target (KS at alpha 1e-3; the move changes most
    # of them, so a wrong acceptance ratio, e.g. none at all, which favours
    # the heavier mode, fails this by far), and they must have moved
    rng = np.random.default_rng(3)
    n = 40000
    x = np.where(
        rng.random(n) < 0.75, 0.3 * rng.standard_normal(n), -1.3 + 0.5 * rng.standard_normal(n)
    )
    y = _move(x, 4, rng, h=0.2)
    assert np.mean(y != x) > 0.5
    assert stats.kstest(y, _cdf).pvalue > 1e-3


def test_lattice_move_without_its_acceptance_step_would_be_biased():
    # the same check made able to fail: always taking the lattice draw (no
    # window ratio) moves mass between the modes; its KS p-value is tiny
    rng = np.random.default_rng(3)
    n = 40000
    x = np.where(
        rng.random(n) < 0.75, 0.3 * rng.standard_normal(n), -1.3 + 0.5 * rng.standard_normal(n)
    )
    reach, h = 4, 0.2
    points = x[None] + ridge.lattice_offsets(reach)[:, None] * h
    lp = _bimodal(points)[reach : 3 * reach + 1]
    p = np.exp(lp - lp.max(0))
    cdf = np.cumsum(p, 0) / p.sum(0)
    j = (rng.random(n) > cdf).sum(0)
    y = x + (j - reach) * h
    assert stats.kstest(y, _cdf).pvalue < 1e-6


def test_lattice_chain_crosses_between_modes():
    # a chain of these moves alone (spacing drawn afresh, so it is not stuck on
    # one lattice) started in the lighter mode reaches the target: 2000 chains,
    # 300 moves, KS at alpha 1e-3 (a random walk of step 0.1, the scale
    # ridge's step, from the same start had 62 % of the chains in the heavier
    # mode after 300 steps, not 75 %: KS p-value 5e-34)
    rng = np.random.default_rng(8)
    x = np.full(2000, -1.3)
    for _ in range(300):
        x = _move(x, 4, rng)
    assert stats.kstest(x, _cdf).pvalue > 1e-3


def test_lattice_shift_refuses_the_outside_of_the_support():
    rng = np.random.default_rng(0)
    lp = np.zeros((9, 1000))
    lp[5:] = -np.inf  # every shift beyond +1 step leaves the support
    j = ridge.lattice_shift(lp, 2, rng)
    assert j.max() <= 1 and j.min() >= -2
    with pytest.raises(ValueError, match="lattice points"):
        ridge.lattice_shift(np.zeros((8, 3)), 2, rng)

import warnings

import numpy as np
import pytest

from bayesgloss import intervals


def _arviz_hdi(x, prob):
    import arviz as az

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return np.asarray(az.hdi(np.asarray(x), hdi_prob=prob))


@pytest.mark.parametrize("prob", [0.5, 0.9, 0.95])
def test_hdi_is_arviz_hdi(prob):
    # ArviZ's hdi (nobody here wrote it) on skewed, edge-piled and symmetric draws
    rng = np.random.default_rng(5)
    for x in (rng.beta(1.0, 12.0, 3001), rng.gamma(2.0, 1.0, 2000), rng.normal(size=999)):
        np.testing.assert_allclose(intervals.highest_density_interval(x, prob), _arviz_hdi(x, prob))


def test_hdi_is_vectorised_over_other_axes():
    rng = np.random.default_rng(6)
    x = rng.beta(2.0, 5.0, size=(1500, 4))
    both = intervals.highest_density_interval(x)
    for k in range(4):
        np.testing.assert_allclose(both[:, k], intervals.highest_density_interval(x[:, k]))
    np.testing.assert_allclose(intervals.highest_density_interval(x.T, axis=1), both)


def test_hdi_reaches_the_edge_a_matt_posterior_piles_against():
    # gamma ~ Beta(1, 30): density highest at 0. The equal-tailed interval
    # excludes 0 (q05 = 1 - 0.95^(1/30) = 0.0017); the HDI starts at the
    # smallest draws (within the draws' spacing near 0, ~1e-4 for 8000 draws)
    # and is shorter; its upper end is the 90 % quantile, 0.0739
    rng = np.random.default_rng(7)
    x = rng.beta(1.0, 30.0, 8000)
    q = intervals.posterior_quantiles(x)
    lo, hi = q["hdi90"]
    assert q["q05"] > 0.0012
    assert lo < 2e-4
    assert hi - lo < q["q95"] - q["q05"]
    assert abs(hi - (1 - 0.1 ** (1 / 30))) < 0.004


def test_hdi_of_a_symmetric_posterior_is_the_equal_tailed_interval():
    rng = np.random.default_rng(8)
    q = intervals.posterior_quantiles(rng.normal(0.5, 0.01, 20000))
    np.testing.assert_allclose(q["hdi90"], [q["q05"], q["q95"]], atol=5e-4)  # 0.03 sd


def test_hdi_rejects_a_mass_outside_zero_one():
    with pytest.raises(ValueError, match="prob"):
        intervals.highest_density_interval([0.1, 0.2], prob=1.0)


def test_hdi_of_a_matt_posterior_reaches_zero_with_bounds():
    # draws never sit exactly on gamma = 0; given the support, a window that
    # starts at the smallest draw reaches the edge. A posterior with its mode
    # inside (Beta(8, 8)) keeps the window of its draws: the rule must not
    # widen it.
    rng = np.random.default_rng(9)
    x = rng.beta(1.0, 30.0, 4000)
    lo, hi = intervals.highest_density_interval(x, bounds=(0.0, 1.0))
    assert lo == 0.0 and hi == intervals.highest_density_interval(x)[1]
    y = rng.beta(8.0, 8.0, 4000)
    np.testing.assert_array_equal(
        intervals.highest_density_interval(y, bounds=(0.0, 1.0)),
        intervals.highest_density_interval(y),
    )
    top = intervals.posterior_quantiles(1.0 - x, bounds=(0.0, 1.0))
    assert top["hdi90"][1] == 1.0 and top["q95"] < 1.0


def test_reported_width_is_the_hdi_and_falls_back_to_the_quantiles():
    # the width of the interval bayesgloss reports: the HDI where a summary
    # has one, the equal-tailed quantiles in one written before it had
    assert intervals.reported_width({"hdi90": [0.1, 0.4], "q05": 0.0, "q95": 0.9}) == 0.4 - 0.1
    assert intervals.reported_width({"q05": 0.2, "q95": 0.7}) == 0.7 - 0.2

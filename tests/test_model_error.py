"""Tests of bayesgloss.model_error: the facets' disagreement and the model's error."""

import numpy as np
import pytest

from bayesgloss import model_error as me


def test_paule_mandel_equal_sds_is_the_excess_variance():
    # with one sd s for every facet the estimating equation is solved by
    # tau^2 = var(m, ddof=1) - s^2 (DerSimonian and Kacker 2007)
    rng = np.random.default_rng(1)
    m = rng.normal(0.4, 0.1, 25)
    s = np.full(25, 0.03)
    expect = np.sqrt(np.var(m, ddof=1) - 0.03**2)
    assert me.paule_mandel_tau(m, s) == pytest.approx(expect, rel=1e-6)


def test_paule_mandel_solves_its_equation_with_unequal_sds():
    rng = np.random.default_rng(2)
    s = rng.uniform(0.005, 0.2, 30)
    m = 0.5 + rng.normal(0, np.hypot(s, 0.07))
    tau = me.paule_mandel_tau(m, s)
    w = 1 / (s**2 + tau**2)
    mw = np.sum(w * m) / w.sum()
    assert np.sum(w * (m - mw) ** 2) == pytest.approx(29, rel=1e-6)


def test_paule_mandel_recovers_a_known_spread_and_is_zero_when_facets_agree():
    # 4000 facets: the estimate's sampling sd is about 0.002 at tau 0.05, so
    # 0.005 is a 2.5-sd tolerance; a method that divided by sqrt(k) or
    # ignored the facets' own sds would be off by far more
    rng = np.random.default_rng(3)
    s = rng.uniform(0.01, 0.1, 4000)
    m = 0.5 + rng.normal(0, np.hypot(s, 0.05))
    assert me.paule_mandel_tau(m, s) == pytest.approx(0.05, abs=0.005)
    agree = 0.5 + rng.normal(0, s)  # no spread beyond the facets' own
    assert me.paule_mandel_tau(agree, s) < 0.005
    assert me.paule_mandel_tau([0.3], [0.1]) == 0.0  # one facet tells nothing
    # a flat facet (sd of a uniform) barely counts; NaN and sd 0 are left out
    assert me.paule_mandel_tau([0.5, 0.5, 0.9, np.nan], [0.01, 0.01, 0.29, 0.1]) == 0.0


def test_model_error_sd_adds_floor_and_facets_in_quadrature():
    m, s = np.array([0.2, 0.4, 0.6]), np.full(3, 0.01)
    e = me.model_error_sd(m, s, floor=0.03)
    assert e["facets_sd"] == pytest.approx(np.sqrt(0.04 - 0.0001), rel=1e-6)
    assert e["sd"] == pytest.approx(np.hypot(0.03, e["facets_sd"]))
    assert e["facets"] == 3 and e["floor"] == 0.03


def test_model_error_floor_follows_the_count_of_measuring_facets():
    # three facets measuring gamma keep the few-facets floor, four take the
    # lower one; a facet with no measurement (NaN, sd 0) does not count
    agree = np.full(4, 0.5), np.full(4, 0.02)  # no disagreement: sd = floor
    three = me.model_error_sd(agree[0][:3], agree[1][:3])
    four = me.model_error_sd(*agree)
    assert three["facets"] == 3 and three["sd"] == pytest.approx(me.FEW_FACETS_FLOOR)
    assert four["facets"] == 4 and four["sd"] == pytest.approx(me.MODEL_ERROR_FLOOR)
    assert me.FEW_FACETS == 3 and me.FEW_FACETS_FLOOR > me.MODEL_ERROR_FLOOR
    unmeasured = me.model_error_sd([0.5, 0.5, 0.5, np.nan, 0.5], [0.02, 0.02, 0.02, 0.02, 0.0])
    assert unmeasured["facets"] == 3 and unmeasured["floor"] == me.FEW_FACETS_FLOOR
    assert me.model_error_sd(*agree, floor=0.1)["floor"] == 0.1  # a number fixes it


def test_with_model_error_widens_and_clips_at_the_bounds():
    rng = np.random.default_rng(4)
    mid = me.with_model_error(np.full(200_000, 0.5), 0.1, rng)
    assert mid.std() == pytest.approx(0.1, rel=0.01)  # 200k draws: sd's error 0.2 %
    edge = me.with_model_error(np.full(200_000, 0.99), 0.1, rng)
    # P(N(0.99, 0.1) > 1) = 1 - Phi(0.1) = 0.4602: the mass at the bound
    assert np.mean(edge == 1.0) == pytest.approx(0.4602, abs=0.005)
    assert edge.min() >= 0.0 and edge.max() <= 1.0
    same = me.with_model_error(np.array([0.3, 0.7]), 0.0, rng)
    assert np.array_equal(same, [0.3, 0.7])


def test_choice_spread_is_the_weighted_sd_of_the_medians_and_mixes_by_weight():
    # three choices whose draws sit at 0.1, 0.5 and 0.9 (medians exactly
    # those); weights 0.5, 0.5, 0: the third is left out, the sd is that of
    # {0.1, 0.5} with equal weights, 0.2, and the mixture's draws are half
    # from each of the first two (binomial sd of the share at 4000 draws
    # 0.008, so 0.04 is five sd)
    rng = np.random.default_rng(3)
    draws = {
        "a": 0.1 + 0.01 * rng.standard_normal(4000),
        "b": 0.5 + 0.01 * rng.standard_normal(4000),
        "c": np.full(4000, 0.9),
    }
    draws = {k: v - np.median(v) + {"a": 0.1, "b": 0.5, "c": 0.9}[k] for k, v in draws.items()}
    out = me.choice_spread(draws, {"a": 0.5, "b": 0.5, "c": 0.0}, np.random.default_rng(4))
    assert out["sd"] == pytest.approx(0.2, abs=1e-12)
    x = out["mixture"]
    assert x.size == 4000 and not np.any(x > 0.8)
    assert np.mean(x < 0.3) == pytest.approx(0.5, abs=0.04)
    # one choice alone: no spread, its own draws
    one = me.choice_spread(draws, {"a": 1.0}, np.random.default_rng(4))
    assert one["sd"] == 0.0 and np.all(np.isin(one["mixture"], draws["a"]))


def test_model_error_sd_adds_the_choices_spread_in_quadrature():
    mean, sd = np.array([0.3, 0.32, 0.35, 0.31]), np.full(4, 0.01)
    plain = me.model_error_sd(mean, sd)
    assert me.model_error_sd(mean, sd, choices_sd=0.0)["sd"] == plain["sd"]  # bit for bit
    wide = me.model_error_sd(mean, sd, choices_sd=0.3)
    assert wide["sd"] ** 2 == pytest.approx(plain["sd"] ** 2 + 0.09)
    assert wide["choices_sd"] == 0.3

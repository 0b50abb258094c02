"""Tests of bayesgloss.sampling.censored: clipped entries in the one-material sampler."""

import dataclasses

import numpy as np
import pytest
from conftest import study_script
from scipy import stats

from bayesgloss import illumination as il
from bayesgloss.sampling import censored, sample_joint, sample_material


@pytest.mark.parametrize("a", [-1.5, 0.0, 2.5, 8.0])
def test_truncated_normal_draws_are_the_cut_normal(a):
    # KS against scipy's truncated normal at 20 000 draws (alpha 1e-3: a
    # correct sampler fails one run in 1000); a = 8 is where the inverse of
    # the plain CDF loses every digit (1 - Phi(8) ~ 6e-16)
    rng = np.random.default_rng(11)
    x = censored.truncated_normal_above(np.full(20000, 2.0), 0.5, 2.0 + 0.5 * a, rng)
    assert x.min() >= 2.0 + 0.5 * a
    p = stats.kstest((x - 2.0) / 0.5, stats.truncnorm(a, np.inf).cdf).pvalue
    assert p > 1e-3, p


def test_truncated_normal_far_in_the_tail():
    # 40 sd above the mean the cut normal is the bound plus an exponential of
    # mean sd^2 / (bound - mean) (Mills' ratio): 1 / 40 sd here, to 1 %
    rng = np.random.default_rng(12)
    x = censored.truncated_normal_above(np.zeros(40000), 1.0, 40.0, rng)
    assert np.all(np.isfinite(x)) and x.min() >= 40.0
    assert abs(np.mean(x - 40.0) * 40.0 - 1.0) < 0.03


@pytest.fixture(scope="module")
def clipped_object(paper_three_skies):
    """A prior-predictive object of 6 facets over 6 frames with its values
    above the design's top code (the 80 % point) clipped: (ref, data, truth)."""
    study, _ = study_script("sbc_material")
    ref = study.sbc_design(paper_three_skies, facets=6, frames=6)
    top = study.top_code(ref, 0.8, n=60)
    rng = np.random.default_rng([5, 3])
    for _ in range(50):  # the first object with a few, not all, values clipped
        th, hyper, lam, y = study.prior_predictive(ref, rng)
        if 2 <= np.sum(y >= top) <= 12 and th[0, 0, 3] < np.log(0.1):
            break
    else:
        raise AssertionError("no prior draw with a few values clipped and small noise")
    data = dataclasses.replace(ref, y=np.minimum(y, top), censored=y >= top)
    return ref, data, (th, hyper, lam)


def test_a_clipped_entry_counts_by_its_survival(clipped_object):
    # the pointwise likelihood (PSIS-LOO, the stacks) and the sampler's
    # differ by the normal constant on measured entries only; a clipped
    # entry's is log P(value >= bound), scipy's normal log-survival
    ref, data, (th, hyper, lam) = clipped_object
    theta = th.transpose(1, 0, 2)[:, :, None, :]  # (1, F, 1, 4)
    point = il.pointwise_log_likelihood(theta, lam[:, None], data)[0, :, 0]
    entry = il.entry_log_likelihood(theta, lam[:, None], theta[..., 3], data)[0, :, 0]
    cut = data.censored
    assert np.allclose(point[~cut], entry[~cut] - 0.5 * np.log(2 * np.pi))
    mu = il.predict(theta, lam[:, None], data)[0, :, 0]
    sd = np.exp(th[0, 0, 3]) * (mu + data.floor[:, None])
    expected = stats.norm.logsf(data.y, loc=mu, scale=sd)
    assert np.allclose(point[cut], expected[cut]) and np.allclose(entry[cut], expected[cut])


def test_clipped_entries_are_fitted_above_their_bounds(clipped_object):
    # the clipped entries are the brightest and lower bounds: fitted as
    # bounds, the posterior brightness there sits above them; read as exact
    # values (the bug the module mends, short of leaving them out) it sits
    # at them. An object of small noise (sigma < 0.1), so that the bounds
    # bind the fit
    _, data, _ = clipped_object
    cut = data.censored

    def fitted(d):
        res = sample_material(d, n_ensembles=2, n_walkers=12, max_sweeps=300, seed=1)
        mu = il.predict(res.draws.transpose(1, 0, 2, 3), res.frames, d)  # (E, F, S, T)
        return np.median(mu, axis=(0, 2))[cut] / data.y[cut]

    as_bounds = fitted(data)
    as_values = fitted(dataclasses.replace(data, censored=None))
    assert np.mean(as_bounds > 1.0) > 0.5, as_bounds
    assert np.mean(as_bounds) > np.mean(as_values) + 0.02, (as_bounds, as_values)


def test_the_per_facet_joint_sampler_refuses_clipped_entries(clipped_object):
    # it has no survival term: silently reading bounds as values is the bug
    # this module mends
    _, data, _ = clipped_object
    with pytest.raises(ValueError, match="clipped"):
        sample_joint(data, n_ensembles=1, n_walkers=8, max_sweeps=10)


def test_joint_data_checks_the_censored_mask(paper_three_skies):
    bases, up = paper_three_skies
    f, t = bases.diffuse.shape[1], int(up.sum())
    b = bases.take(np.arange(f), np.flatnonzero(up))
    with pytest.raises(ValueError, match="censored must have the shape"):
        il.joint_data(np.ones((f, t)), np.ones((f, t), bool), b, censored=np.ones((f, t + 1), bool))
    none = il.joint_data(np.ones((f, t)), np.ones((f, t), bool), b, censored=np.zeros((f, t), bool))
    assert none.censored is None  # nothing clipped: the sampler's closed form, unchanged


@pytest.mark.slow
def test_one_material_sbc_with_clipped_entries(paper_three_skies):
    # Simulation-based calibration (Talts et al. 2018) of the sampler with
    # clipped entries: 60 prior-predictive objects of 6 facets over 6 frames,
    # every value above one top code for the design (the median object's 85 %
    # point: about half the objects clip, some most of their entries) clipped
    # and fitted as censored, estimate's rule capped at 1500 sweeps. Ranks of
    # gamma, log tau and a mid frame's log sun among 99 draws: chi-square over
    # 10 bins at alpha 1e-3; gamma's 90 % interval must hold the truth in
    # 46-59 of 60 (the 99.9 % binomial range at 0.9). The first version of
    # the completion (gloss fitted to the completed values) stayed where it
    # started, at the bounds.
    from bayesgloss.pool import process_pool
    from bayesgloss.runner import script_unit

    study, path = study_script("sbc_material")
    ref = study.sbc_design(paper_three_skies, facets=6, frames=6)
    top = study.top_code(ref, 0.85)
    with process_pool(2) as pool:
        futures = [
            pool.submit(
                script_unit,
                path,
                "sbc_object",
                ref=ref,
                seed=2042,
                index=i,
                max_sweeps=1500,
                top=top,
            )  # fmt: skip
            for i in range(60)
        ]
        rows = [f.result() for f in futures]
    assert sum(r["clipped"] > 0 for r in rows) >= 15  # the test is about clipped objects
    names = study.rank_names(ref)
    out = study.rank_summary(rows, names)
    assert study.rank_summary_passes(out, names, held90=(46, 59)), out

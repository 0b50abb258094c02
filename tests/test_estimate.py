"""Posterior calibration (simulation-based calibration, interval coverage) and
the estimate pipeline on a real Radiance bundle."""

import json

import numpy as np
import pytest
from scipy import stats

from bayesgloss import likelihood as lk
from bayesgloss import render, sampling, scene


@pytest.fixture(scope="module")
def paper_bases():
    seq = scene.paper_sequence(view="SW")
    seen = seq.geometry.cos_view > 0.1
    g = render.ViewGeometry(
        seq.geometry.normal[seen],
        seq.geometry.view_direction[seen],
        seq.geometry.center[seen],
        seq.geometry.occluder,
    )
    valid = np.broadcast_to(seq.sky.sun_direction[:, 2] > 0.02, (int(seen.sum()), 19)).copy()
    return render.facet_bases(g, seq.sky), valid


def _simulate_from_prior(paper_bases, n_rep, seed):
    """Replicates: facets of the paper scene with parameters drawn from the prior."""
    bases, valid = paper_bases
    idx = np.arange(n_rep) % len(valid)
    priors = lk.Priors(log_s_center=float(np.log(179 * 0.5)))
    design = lk.curve_data(np.ones_like(valid, float), valid, bases, priors=priors).take(idx)
    rng = np.random.default_rng(seed)
    truth = lk.sample_prior(design, 1, rng)[:, 0]
    y = lk.simulate(truth[:, None], design, rng)[:, 0]
    data = lk.curve_data(
        y,
        valid[idx],
        render.FacetBases(bases.diffuse[idx], bases.glossy[idx], bases.exponents),
        priors=priors,
    )
    return truth, data


def _sbc(paper_bases, n_rep, seed):
    truth, data = _simulate_from_prior(paper_bases, n_rep, seed)
    post = sampling.sample_posterior(data, seed=seed, jobs=2)
    draws = post.draws.reshape(n_rep, -1, data.n_params)
    thin = draws[:, :: draws.shape[1] // 99][:, :99]  # L = 99 draws: ranks 0..99
    ranks = np.sum(thin < truth[:, None, :], axis=1)  # (R, P)
    return truth, draws, ranks


def _check_uniform_ranks(ranks, n_bins=10, alpha=1e-3):
    """Chi-square test of uniform ranks per parameter (gamma, log n, log s)."""
    pvals = []
    for k in range(3):
        counts = np.bincount(ranks[:, k] * n_bins // 100, minlength=n_bins)
        pvals.append(stats.chisquare(counts).pvalue)
    assert min(pvals) > alpha, pvals
    return pvals


def _check_coverage(truth, draws):
    """50 % and 90 % central intervals cover at their nominal rates, each within
    its binomial 99.9 % interval for the number of replicates."""
    n = len(truth)
    for level in (0.5, 0.9):
        lo, hi = np.quantile(draws, [(1 - level) / 2, (1 + level) / 2], axis=1)
        for k in range(3):
            cover = np.mean((lo[:, k] <= truth[:, k]) & (truth[:, k] <= hi[:, k]))
            bounds = stats.binom.ppf([0.0005, 0.9995], n, level) / n
            assert bounds[0] <= cover <= bounds[1], (level, k, cover, bounds)


def test_simulation_based_calibration(paper_bases):
    # Talts et al. 2018: the rank of the truth among L posterior draws is uniform
    # when inference is right. 240 replicates x 10 bins (24 expected per bin):
    # a chi-square test at 1e-3 detects a systematic shift of the posterior by
    # ~0.3 posterior sd, or a width wrong by ~25 %.
    truth, draws, ranks = _sbc(paper_bases, 240, seed=11)
    _check_uniform_ranks(ranks)
    _check_coverage(truth, draws)


@pytest.mark.slow
def test_simulation_based_calibration_long(paper_bases):
    # the same with 1000 replicates (100 expected per bin)
    truth, draws, ranks = _sbc(paper_bases, 1000, seed=12)
    _check_uniform_ranks(ranks)
    _check_coverage(truth, draws)


def test_sbc_detects_a_wrong_posterior(paper_bases):
    # power check: the same machinery rejects a posterior computed with the
    # noise scale fixed 3x too small (overconfident) on the same replicates
    truth, data = _simulate_from_prior(paper_bases, 240, seed=13)
    post = sampling.sample_posterior(data, seed=13, jobs=2)
    draws = post.draws.reshape(240, -1, data.n_params)
    centre = np.median(draws, axis=1, keepdims=True)
    shrunk = centre + (draws - centre) / 3.0
    thin = shrunk[:, :: shrunk.shape[1] // 99][:, :99]
    ranks = np.sum(thin < truth[:, None, :], axis=1)
    with pytest.raises(AssertionError):
        _check_uniform_ranks(ranks)


@pytest.mark.radiance
def test_estimate_cli_json_on_a_rendered_bundle(tmp_path):
    # a small matt hemisphere rendered by Radiance: the JSON has the promised
    # shape and the object comes out matt
    from bayesgloss import cli, sequences

    cfg = sequences.SequenceConfig(
        name="est",
        n_rings=3,
        n_segments=8,
        image_size=48,
        view="SW",
        solar_hours=tuple(float(h) for h in range(5, 21)),
    )
    (path,) = sequences.render_bundles([cfg], tmp_path, progress=False)
    out = tmp_path / "out"
    import contextlib
    import io

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        code = cli.main(["estimate", str(path), "--json", "--quiet", "--out", str(out)])
    assert code == 0
    res = json.loads(buf.getvalue())
    assert set(res["object"]["gamma"]) >= {"median", "q05", "q95"}
    assert "converged" in res["object"] and "n" in res["object"]
    facet = res["facets"][0]
    assert {"id", "gamma", "converged", "flags"} <= set(facet)
    assert res["object"]["gamma"]["median"] < 0.05  # truth: matt plastic, gamma 0
    assert (out / "posterior.nc").exists()
    import arviz as az

    idata = az.from_netcdf(out / "posterior.nc")
    for group in (
        "posterior",
        "log_likelihood",
        "observed_data",
        "posterior_predictive",
        "sample_stats",
    ):
        assert group in idata.groups()
    assert idata.log_likelihood["y"].dims[-2:] == ("facet", "frame")

"""Posterior calibration (simulation-based calibration, interval coverage) and
the estimate pipeline on a real Radiance bundle."""

import json

import numpy as np
import pytest
from scipy import stats

from bayesgloss import estimate, render, sampling, scene
from bayesgloss import likelihood as lk
from bayesgloss.pool import process_pool


@pytest.fixture(scope="module")
def paper_bases():
    seq = scene.paper_sequence(view="SW")
    g = scene.seen_geometry(seq)
    valid = np.broadcast_to(seq.sky.sun_direction[:, 2] > 0.02, (len(g.normal), 19)).copy()
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
    with process_pool(2) as pool:
        post = sampling.sample_posterior(data, seed=seed, pool=pool)
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
    with process_pool(2) as pool:
        post = sampling.sample_posterior(data, seed=13, pool=pool)
    draws = post.draws.reshape(240, -1, data.n_params)
    centre = np.median(draws, axis=1, keepdims=True)
    shrunk = centre + (draws - centre) / 3.0
    thin = shrunk[:, :: shrunk.shape[1] // 99][:, :99]
    ranks = np.sum(thin < truth[:, None, :], axis=1)
    with pytest.raises(AssertionError):
        _check_uniform_ranks(ranks)


@pytest.mark.long
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
    assert set(res["object"]["gamma"]) >= {"median", "q05", "q95", "hdi90"}
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


# ---------------------------------------------------------------------------
# end to end on synthetic bundles: unknown camera response, censored pixels
# ---------------------------------------------------------------------------


def _fresnel_truth(b, specularity=0.5):
    """The object's true gloss as the forward model made it.

    make_synthetic_bundle renders grey (0.5) Radiance plastic of roughness 0
    with render.radiance_material_prediction, whose mirror part carries
    Radiance's Fresnel raise at each facet's view angle: the true gamma is
    reflectance.gloss_of_radiance_material_fresnel per facet, averaged over
    the facets (as studies/recovery_paper60.py scores Radiance renderings).
    """
    from bayesgloss import reflectance

    cos_view = b.view_geometry().cos_view
    return float(
        np.mean(
            reflectance.gloss_of_radiance_material_fresnel("plastic", specularity, 0.5, cos_view)
        )
    )


@pytest.fixture(scope="module")
def unknown_response_bundle(tmp_path_factory):
    from conftest import make_synthetic_bundle

    # 16-bit codes = (radiance / exposure)^(1 / 2.2), nothing clipped (the
    # default exposure is 1.25 x the brightest facet), encoding "unknown"
    return make_synthetic_bundle(
        tmp_path_factory.mktemp("unknown") / "b",
        specularity=0.5,
        encoding="unknown",
        response_gamma=2.2,
        bits=16,
    )


def test_default_sky_follows_whether_the_joint_model_applies(unknown_response_bundle, tmp_path):
    # one rule for estimate_bundle and the several-bundle command line's units:
    # an unknown pixel response or a non-relative noise model rules the joint
    # model out, and with it the stacked sky families (naming 'auto' for such a
    # bundle made its unit fail)
    from conftest import make_synthetic_bundle

    from bayesgloss import bundle

    unknown = bundle.read_bundle(unknown_response_bundle)
    known = bundle.read_bundle(make_synthetic_bundle(tmp_path / "b"))
    assert estimate.default_illumination(known) == "families"
    assert estimate.default_illumination(unknown) == "gensky-clear"
    assert estimate.default_illumination(unknown, camera="linear") == "families"
    assert estimate.default_illumination(known, per_frame=False) == "gensky-clear"
    assert estimate.default_illumination(known, noise="student") == "gensky-clear"


def test_unknown_response_recovered_end_to_end(unknown_response_bundle):
    from bayesgloss import bundle

    b = bundle.read_bundle(unknown_response_bundle)
    assert not b.response_known
    truth = _fresnel_truth(b)  # 0.711 for these 8 facets
    res = estimate.estimate_bundle(b, camera="auto", seed=0, per_frame=False)
    assert res.summary["camera"] == "power"
    # with the exponent g free, a facet's posterior can have a small second
    # mode (log n ~ 2, gamma ~ 0.25 beside log n ~ 8.7, gamma ~ 0.69) that one
    # ensemble finds and the others do not; R-hat then flags that facet as
    # not converged, as it should, which seed and batch layout decide
    # (measured over the estimate's seeds 0-4: 6, 8, 7, 7, 7 of 8 converged)
    assert res.summary["object"]["facets"] == 8
    assert res.summary["object"]["facets_converged"] >= 6

    g = res.idata.posterior["g"].values  # (chains, draws, facets)
    g = g.reshape(-1, g.shape[-1])
    lo, med, hi = np.quantile(g, [0.05, 0.5, 0.95], axis=0)
    held = (lo <= 2.2) & (2.2 <= hi)
    # measured (seeds 0-2 of the data): 6-7 of 8 facets' 90 % intervals hold
    # 2.2; the two that miss do so by < 0.04 in every seed, a model mismatch
    # (Radiance plastic's Fresnel-reduced diffuse vs. the Lambert basis) that
    # g partly absorbs on the facets with the narrowest intervals. At least 5
    # of 8: with honest 90 % intervals P(<= 4 of 8) = 0.5 %.
    assert held.sum() >= 5, (lo, hi)
    # median of facet medians, measured 2.16-2.17: its sampling sd is ~0.02
    # (facet posterior sd ~0.07 over 8 facets) and the mismatch above pulls it
    # ~0.03 low; 0.1 is ~3 such sds past that and still excludes g = 1 (linear)
    # and the prior median sqrt(3) = 1.73
    assert abs(np.median(med) - 2.2) < 0.1, med

    # the model's own interval (the reported one adds the model's error)
    gam = res.summary["object"]["gamma_within_model"]  # measured [0.700, 0.740], median 0.722
    assert gam["q05"] <= truth <= gam["q95"], (gam, truth)

    # the response matters: the same codes taken as linear values (g = 1,
    # the response ignored) give a curve shape the Lambert-plus-lobe model
    # can only match with far more gloss: measured [0.893, 0.938], biased up
    # by ~0.2, the interval's lower end 0.18 above the truth
    lin = estimate.estimate_bundle(b, camera="linear", seed=0, per_frame=False)
    lin = lin.summary["object"]["gamma_within_model"]
    assert lin["q05"] > truth + 0.1, (lin, truth)


@pytest.fixture(scope="module")
def clipped_bundle(tmp_path_factory):
    from conftest import make_synthetic_bundle

    # 16-bit gamma:2.2 codes with the top code at 25 W sr^-1 m^-2, about 40 %
    # of the brightest facet's peak (63) and below every facet's peak (34-63):
    # the broad sky-mirror highlights of all 8 facets clip, in 5-9 frames
    # each (58 of the 120 sunlit entries)
    return make_synthetic_bundle(
        tmp_path_factory.mktemp("clipped") / "b",
        specularity=0.5,
        encoding="gamma:2.2",
        bits=16,
        exposure=25.0,
    )


def test_observations_censor_facets_saturated_in_every_pixel(clipped_bundle):
    # every pixel of a clipped facet is at the top code (the synthetic facets
    # are uniform): the entry must enter censored at the top code's linear
    # value (1), not be dropped for want of unsaturated pixels
    from bayesgloss import bundle

    curves = bundle.facet_curves(clipped_bundle)
    sat = curves.flagged("saturated")
    assert sat.sum() == 58 and sat.any(axis=1).all()
    assert np.all(curves.n_saturated[sat] == curves.n_pixels[np.nonzero(sat)[0]])
    y, usable, censored = estimate.observations(curves)
    np.testing.assert_array_equal(censored, sat)
    np.testing.assert_array_equal(usable, curves.valid | sat)
    np.testing.assert_allclose(y[censored], 1.0)
    assert np.all(y[curves.valid] < 1.0)


def test_censored_highlights_end_to_end(clipped_bundle, monkeypatch):
    from bayesgloss import bundle

    b = bundle.read_bundle(clipped_bundle)
    truth = _fresnel_truth(b)
    # censoring is the fixed-brightness model's (the joint one leaves such entries out)
    res = estimate.estimate_bundle(b, seed=0, per_frame=False)
    assert res.summary["camera"] == "linear"
    assert int(res.idata.observed_data["censored"].sum()) == 58
    obj = res.summary["object"]
    assert obj["facets_converged"] == obj["facets"] == 8
    # measured [0.699, 0.744], median 0.723 (truth 0.711); the uncensored
    # float bundle of the same seed gives [0.681, 0.732]
    own = obj["gamma_within_model"]  # the model's own (the reported one adds its error)
    assert own["q05"] <= truth <= own["q95"], (own, truth)

    # the same data with the clipped entries taken as exact values (the top
    # code): the flattened peaks bias gamma up, measured [0.764, 0.807],
    # median 0.788; 0.03 is ~1.5 interval half-widths clear of the truth.
    # (Leaving the clipped entries out instead is unbiased here, measured
    # [0.708, 0.750]: the unclipped flanks of the broad highlights still fix
    # the lobe; censoring is the model that uses every entry without bias.)
    observe = estimate.observations

    def exact(curves):
        y, usable, _ = observe(curves)
        return y, usable, np.zeros_like(usable)

    monkeypatch.setattr(estimate, "observations", exact)
    naive = estimate.estimate_bundle(b, seed=0, per_frame=False).summary["object"]
    naive = naive["gamma_within_model"]  # the model's own (a model's bias, its error aside)
    assert naive["q05"] > truth + 0.03, (naive, truth)
    assert naive["median"] > obj["gamma"]["median"] + 0.03


def test_per_frame_estimate_writes_frames_and_reports(tmp_path):
    # estimate --per-frame end to end on a small synthetic bundle (the sky model
    # is the truth, so every frame's sun and sky should read about 1): the
    # summary lists each frame's sun and sky, the InferenceData holds them per
    # frame, the result folder reads back, and the report draws their panel
    from conftest import make_synthetic_bundle

    from bayesgloss import bundle as bundle_io
    from bayesgloss import report

    path = make_synthetic_bundle(tmp_path / "b", specularity=0.5, noise=0.01, seed=4)
    res = estimate.estimate_bundle(
        path,
        per_frame=True,
        illumination="gensky-clear",
        lobe="phong",  # one fit: this test is about the frames' records, not the lobe
        sampler_options={"max_steps": 400},
    )
    s = res.summary
    assert s["per_frame_illumination"] and s["sampler"]["model"] == "joint"
    b = bundle_io.read_bundle(path)
    up = int(np.sum(b.sun_up))
    assert len(s["frames"]) == up == res.idata.posterior["sun"].shape[-1]
    sun = np.array([f["sun"]["median"] for f in s["frames"]])
    # away from dawn and dusk the sun's course over the day reads the model's
    # within 40 %, its level (which only the priors of the frames and of the
    # albedo tie to the facets' scale) within 25 %. Not closer: the frames are
    # Radiance plastic (Fresnel, Ward-like lobe) fitted with Phong, and the
    # sun's course takes up some of that misfit (measured 0.82-1.26 about a
    # level of 1.12, gamma 0.79 for 0.67; the issue "Gloss that means the
    # material's gloss"). A sampler stuck at its start read 15 % (stop 21's,
    # whose shared move was accepted 3 % of the time). A frame whose sun is
    # read from the sky's part of the curves is off by a factor of 3 or more
    # (the sky's share of a sun-lit facet's diffuse light here: median 0.15)
    level = np.median(sun[2:-2])
    assert abs(np.log(level)) < np.log(1.25), sun
    assert np.all(np.abs(np.log(sun[2:-2] / level)) < np.log(1.4)), sun
    assert s["object"]["model"].startswith("one material")
    # a glossy object under a clear sun: whether the sun shone is told in
    # every frame, so the object is not flagged sun-not-identifiable
    assert s["object"]["sun_unidentified_share"] <= 0.2, s["frames"]
    assert "sun-not-identifiable" not in s["object"]["flags"]
    # the run's own convergence, frame by frame, and the object's record of it agree
    c = s["object"]["convergence"]
    assert c["frames_not_converged"] == [f["frame"] for f in s["frames"] if not f["converged"]]
    assert ("not-converged" in s["object"]["flags"]) == (not res.samples.converged)
    # each facet's own sampler converged given the object's light; R-hat across
    # the pooled chains (different illumination draws by design) once flagged
    # every facet of the demo not-converged
    assert s["object"]["facets_converged"] == s["object"]["facets"] > 0
    assert all(f["rhat"] < 1.01 for f in s["facets"] if f["gamma"])
    assert "gamma_object" in res.idata.posterior and "sun_state_weight" in res.idata.posterior
    assert "exposure" not in res.idata.posterior  # linear-radiance: exposure known
    # the reported interval is the model's own widened by the model error: it
    # holds the model's (up to the error draws' Monte Carlo, < 0.005 here at
    # 4000+ draws), by about 1.645 sd more on each side away from the bounds
    o = s["object"]
    err = o["model_error"]
    assert err["sd"] == pytest.approx(np.hypot(err["floor"], err["facets_sd"]))
    (lo, hi), (wlo, whi) = (o[k]["hdi90"] for k in ("gamma", "gamma_within_model"))
    assert lo <= wlo + 0.005 and hi >= whi - 0.005
    if err["sd"] > 0.02 and 0.1 < o["gamma"]["median"] < 0.9:
        assert (hi - lo) > (whi - wlo) + 2 * err["sd"]
    material = res.idata.posterior["gamma_material"].values
    assert material.shape == res.idata.posterior["gamma_object"].shape
    assert np.std(material) >= np.std(res.idata.posterior["gamma_object"].values)
    assert all("gamma_within_model" in f for f in s["facets"] if f["gamma"])
    # the posterior's facets are the label image's ids (the report paints by
    # them; they were 0..F-1 once, and every panel painted the wrong facets)
    seen = [f["id"] for f in s["facets"] if f["gamma"]]
    assert list(res.idata.posterior["facet"].values) == seen
    assert list(res.idata.observed_data["facet"].values) == seen
    estimate.write_result(tmp_path / "out", res)
    back = estimate.read_result(tmp_path / "out")
    png = report.posterior_report(b, back, path=tmp_path / "out" / "report.png")
    assert png.stat().st_size > 10_000


def test_mostly_saturated_facets_and_object_are_flagged(tmp_path):
    # an exposure at which most sun-up entries clip: every facet whose usable
    # entries are mostly lower bounds (saturated) is flagged, and so is the
    # object when most entries over the facets used are; the others are not
    from conftest import make_synthetic_bundle

    from bayesgloss import bundle

    curves = bundle.facet_curves(make_synthetic_bundle(tmp_path / "float"))
    up = curves.luminance[:, bundle.read_bundle(tmp_path / "float").sun_up]
    # radiance at the top code: the 40th percentile of the sun-up luminances
    # (grey, so luminance = 179 x radiance)
    top = np.quantile(up, 0.4) / 179.0
    path = make_synthetic_bundle(tmp_path / "clipped", encoding="linear", exposure=top)
    y, usable, censored = estimate.observations(bundle.facet_curves(path))
    fraction = censored.sum(1) / usable.sum(1)
    assert (fraction > 0.5).any() and (fraction <= 0.5).any()  # both kinds present
    res = estimate.estimate_bundle(path, per_frame=False, sampler_options={"max_steps": 100})
    flagged = {f["id"]: "mostly-saturated" in f["flags"] for f in res.summary["facets"]}
    keep = (usable.sum(1) >= estimate.MIN_FRAMES) & ((usable & ~censored).sum(1) >= 2)
    ids = bundle.read_bundle(path).facets.ids
    for fid, k, frac in zip(ids, keep, fraction, strict=True):
        if k:
            assert flagged[fid] == (frac > 0.5), (fid, frac)
    overall = censored[keep].sum() / usable[keep].sum()
    assert ("mostly-saturated" in res.summary["object"]["flags"]) == (overall > 0.5), overall

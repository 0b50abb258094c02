"""The one-material model (bayesgloss.illumination.log_prior_material) and its
sampler (bayesgloss.sampling.material)."""

import numpy as np
import pytest
from scipy import stats

from bayesgloss import illumination as il
from bayesgloss.sampling import populations, sample_material


@pytest.mark.parametrize(
    "seed, bounds, cases",
    [
        # the albedo's log tau given the facets' scales: spread inside the
        # range, far below it (mass piled at the lower bound), few facets
        (5, il.MATERIAL_LOG_TAU, ((24, 0.1), (24, 0.001), (3, 0.5))),
        # the day's log exposure spread given the frames' log exposures: a
        # camera that kept its exposure, one whose exposure jittered, few frames
        (6, il.EXPOSURE_LOG_SPREAD, ((12, 0.001), (12, 0.2), (4, 1.0))),
    ],
    ids=["albedo", "exposure"],
)
def test_log_spread_draw_is_its_conditional(seed, bounds, cases):
    # log tau given the sum of squares SS of n values about their mean:
    # density tau^-n exp(-SS / 2 tau^2) on the prior's range; the
    # inverse-CDF draws must match a numerical CDF of it (KS test on 4000
    # draws at alpha 1e-3 for each case)
    rng = np.random.default_rng(seed)
    for n, sd in cases:
        ss = n * sd**2
        draws = populations.draw_log_spread(np.full(4000, ss), n, rng, bounds)
        _assert_log_spread_conditional(draws, ss, n, bounds)


def _assert_log_spread_conditional(draws, ss, f, bounds):
    """KS test of draws of log tau against tau^-f exp(-ss / 2 tau^2) on bounds."""
    lo, hi = bounds
    grid = np.linspace(lo, hi, 20001)
    log_dens = -f * grid - 0.5 * ss * np.exp(-2 * grid)
    cdf = np.cumsum(np.exp(log_dens - log_dens.max()))
    cdf /= cdf[-1]
    p = stats.kstest(draws, lambda x: np.interp(x, grid, cdf)).pvalue
    assert p > 1e-3, (f, ss, p)
    assert np.all((draws >= lo) & (draws <= hi))


@pytest.mark.long
@pytest.mark.parametrize("exposure_known", [True, False])
def test_without_data_the_one_material_sampler_draws_its_prior(paper_three_skies, exposure_known):
    # no usable observation: the posterior is the prior, gamma uniform (mean
    # 1/2, 10 % below 0.1), log tau uniform on its range, the day's sun
    # weights uniform on the simplex (mean 1/3 each), and, with the exposure
    # unknown, the day's log exposure mean N(0, 2^2) and log spread uniform on
    # its range (each frame's log exposure then of sd sqrt(4 + E sd_e^2) =
    # 2.19). A missing Jacobian, a
    # wrong conditional of tau or m, or a move that is not reversible (the
    # ridge moves' lattices, the sun's jumps) pulls these off. Tolerances:
    # ~15000 autocorrelated draws, ESS of a few hundred
    full, up = paper_three_skies
    bases = full.take(slice(0, 5), np.flatnonzero(up)[3:9])
    f, t = bases.diffuse.shape[1:]
    exposure = np.ones(t) if exposure_known else None
    data = il.joint_data(np.ones((f, t)), np.zeros((f, t), bool), bases, exposure=exposure)
    res = sample_material(data, seed=3, min_sweeps=1200, max_sweeps=1200)
    g = res.draws[0, ..., 0].ravel()
    assert abs(g.mean() - 0.5) < 0.06
    assert abs(np.mean(g < 0.1) - 0.1) < 0.05
    lo, hi = il.MATERIAL_LOG_TAU
    log_tau = res.material[..., 1].ravel()
    assert abs((log_tau.mean() - lo) / (hi - lo) - 0.5) < 0.08
    w = np.exp(il.log_sun_weights(res.material)).reshape(-1, 3)
    np.testing.assert_allclose(w.mean(axis=0), 1 / 3, atol=0.06)
    # each frame's log sun: the mixture at weights uniform on the simplex has
    # mean (0 - 2.5 - 9) / 3 = -3.83. The mean over frames has sd 2.4 and ESS
    # ~2700 here (standard error 0.05), so 0.2 is 4 standard errors; its
    # modes (clear, dimmed, hidden) are 2.5-9 apart, and before the sun's
    # jumps (stop 41) the frame moves' random walk crossed them so rarely
    # (ESS 170-340 per frame) that the mean read -4.07 and -3.43. The sun's
    # jumps mix them: ESS > 2000
    q = data.frame_priors
    mean_sun = (0.0 + q.sun_cloud_mean + q.sun_hidden_mean) / 3
    assert abs(res.frames[..., 1].mean() - mean_sun) < 0.2
    assert res.ess_bulk[1 : 1 + t].min() > 2000, res.ess_bulk[1 : 1 + t]
    if not exposure_known:
        log_e = res.frames[..., 0]
        lo, hi = il.EXPOSURE_LOG_SPREAD
        sd = np.sqrt(q.exposure_sd**2 + (np.exp(2 * hi) - np.exp(2 * lo)) / (2 * (hi - lo) * 2))
        assert abs(log_e.mean()) < 0.3 and abs(log_e.std() - sd) < 0.3, (log_e.std(), sd)
        spread = res.material[..., 5].ravel()
        assert abs((spread.mean() - lo) / (hi - lo) - 0.5) < 0.08
        assert abs(res.material[..., 4].mean()) < 0.3


@pytest.mark.long
def test_one_material_reads_gloss_albedo_spread_and_clouded_frames(paper_three_skies):
    # one material (gamma 0.3, n 100) whose facets' albedos spread by 10 %,
    # under the intermediate sky, the sun hidden in two frames: the object's
    # gamma within 0.05 and its 90 % interval holding it, the spread read
    # within a factor 2, and the two clouded frames' suns below a tenth of the
    # others' (per-facet models read such skies 0.3-0.7 high before the
    # intermediate shape; a population of facet posteriors tied by shared
    # frames was overconfident)
    full, up = paper_three_skies
    bases = full.take(slice(None), up)
    f, t = bases.diffuse.shape[1:]
    rng = np.random.default_rng(12)
    lam = np.zeros((1, 1, t, 5))
    lam[..., 3], lam[..., 4] = 8.0, 0.0  # w = (~0, ~1, ~0): intermediate
    lam[..., 1] = np.log(0.15)  # the intermediate sky's own dim sun
    lam[0, 0, [4, 9], 1] = np.log(0.15) - 6.0
    th = np.zeros((1, f, 1, 4))
    th[..., 0], th[..., 1], th[..., 3] = 0.3, np.log(100.0), np.log(0.02)
    th[0, :, 0, 2] = np.log(0.5) + 0.1 * rng.standard_normal(f)
    valid = np.ones((f, t), bool)
    ref = il.joint_data(np.ones((f, t)), valid, bases, exposure=np.ones(t))
    y = il.simulate(th, lam, ref, rng)[0, :, 0]
    data = il.joint_data(y, valid, bases, exposure=np.ones(t))
    res = sample_material(data, seed=4, min_sweeps=1000, max_sweeps=1000)
    g = res.draws[0, ..., 0].ravel()
    q05, q50, q95 = np.quantile(g, [0.05, 0.5, 0.95])
    assert abs(q50 - 0.3) < 0.05 and q05 <= 0.3 <= q95, (q05, q50, q95)
    tau = np.median(np.exp(res.material[..., 1]))
    assert 0.05 < tau < 0.2, tau
    log_a = np.median(res.frames[..., 1], axis=(0, 1))
    others = np.delete(log_a, [4, 9])
    assert np.all(log_a[[4, 9]] < np.min(others) - np.log(10)), log_a


@pytest.mark.slow
@pytest.mark.parametrize(
    ("fresnel", "lobe", "exposure_known"),
    [
        ("none", "phong", True),
        ("radiance", "phong", True),
        ("none", "ggx", True),
        ("none", "ward", True),
        ("none", "phong", False),
    ],
)
def test_one_material_sbc(paper_three_skies, fresnel, lobe, exposure_known):
    # Simulation-based calibration of the default object model (Talts et al.
    # 2018) with the study's code (studies/sbc_material.py) on a smaller
    # design: 60 objects of 6 facets over 6 frames drawn from the prior,
    # fitted with estimate's stopping rule capped at 1500 sweeps (objects that
    # stop unconverged are kept, as SBC must). Ranks of gamma, log tau and a
    # mid frame's log sun among 99 draws: chi-square over 10 bins at alpha
    # 1e-3 (a correct sampler fails 1 run in 1000 per quantity). gamma's 90 %
    # interval (ranks 5-94) must hold the truth in 46-59 of 60: the 99.9 %
    # binomial range at 0.9; an interval 30 % too narrow holds it in about
    # 45 of 60 (stop 24's unmixed walkers held it in 79 of 100). With the
    # Fresnel raise (bayesgloss.fresnel) its strength k is drawn from its
    # prior with the rest, and its ranks are tested too. With the GGX or the
    # Ward lobe (bayesgloss.lobes) the tables are that family's, the sampler
    # the same. With the exposure unknown, each frame's log exposure is drawn
    # about the day's (IlluminationPriors.day_exposure), and the ranks of the
    # day's log exposure spread are tested too.
    from conftest import study_script

    from bayesgloss.pool import process_pool
    from bayesgloss.runner import script_unit

    study, path = study_script("sbc_material")
    bases = paper_three_skies if lobe == "phong" else study.paper_three_skies(lobe)
    ref = study.sbc_design(
        bases, facets=6, frames=6, fresnel=fresnel, exposure_known=exposure_known
    )
    with process_pool(2) as pool:  # the study's objects, importable in every worker
        futures = [
            pool.submit(
                script_unit, path, "sbc_object", ref=ref, seed=2028, index=i, max_sweeps=1500
            )
            for i in range(60)
        ]
        rows = [f.result() for f in futures]
    names = study.rank_names(ref)
    out = study.rank_summary(rows, names)
    assert study.rank_summary_passes(out, names, held90=(46, 59)), out


@pytest.mark.long
def test_a_kept_exposure_ties_the_frames_and_a_varied_one_is_read(paper_three_skies):
    # the day-level exposure (IlluminationPriors.day_exposure). A single facet
    # (gamma 0.3, n 100, clear sky) seen by a camera that kept its unknown
    # exposure: with each frame's exposure free, the curve's level in each
    # frame tells nothing and gamma's 90 % interval is most of [0, 1] (0.82
    # wide on this seed); drawn about the day's, the frames are tied, the
    # interval holds 0.3 and is at most 0.7 times as wide, and the spread
    # sd_e reads below 0.1. Five facets whose camera varied its exposure by
    # sd 0.3: gamma's interval still holds 0.3. (The spread itself is not
    # read there: a frame's exposure and its sun and sky changed together
    # make the same curve, and the sun's and sky's priors take the change;
    # sd_e read [0.01, 0.20] on this seed.)
    full, up = paper_three_skies
    rng = np.random.default_rng(12)

    def fit(facets, log_e, day):
        bases = full.take(facets, up)
        f, t = bases.diffuse.shape[1:]
        lam = np.zeros((1, 1, t, 5))
        lam[..., 3], lam[..., 4] = -8.0, -8.0  # the clear sky's shape
        lam[..., 0] = log_e(t)
        th = np.zeros((1, f, 1, 4))
        th[..., 0], th[..., 1], th[..., 3] = 0.3, np.log(100.0), np.log(0.02)
        th[..., 2] = np.log(0.5)
        ref = il.joint_data(np.ones((f, t)), np.ones((f, t), bool), bases)
        y = il.simulate(th, lam, ref, np.random.default_rng(7))[0, :, 0]
        priors = il.IlluminationPriors(day_exposure=day)
        data = il.joint_data(y, np.ones((f, t), bool), bases, frame_priors=priors)
        return sample_material(data, seed=4, min_sweeps=1000, max_sweeps=1000)

    def kept(t):
        return np.zeros(t)

    free, tied = (fit(slice(0, 1), kept, day) for day in (False, True))
    q_free = np.quantile(free.draws[0, ..., 0], [0.05, 0.95])
    q_tied = np.quantile(tied.draws[0, ..., 0], [0.05, 0.95])
    assert q_tied[0] <= 0.3 <= q_tied[1], q_tied
    assert np.diff(q_tied)[0] <= 0.7 * np.diff(q_free)[0], (q_tied, q_free)
    assert np.median(np.exp(tied.material[..., 5])) < 0.1
    jitter = rng.normal(0.0, 0.3, 200)
    varied = fit(slice(0, 5), lambda t: jitter[:t] - jitter[:t].mean(), True)
    q_varied = np.quantile(varied.draws[0, ..., 0], [0.05, 0.95])
    assert q_varied[0] <= 0.3 <= q_varied[1], q_varied

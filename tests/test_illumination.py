"""The per-frame illumination model (bayesgloss.illumination) and its joint
sampler (bayesgloss.sampling.joint)."""

import numpy as np
import pytest

from bayesgloss import illumination as il
from bayesgloss import likelihood as lk
from bayesgloss import render, scene
from bayesgloss.sampling import sample_joint


@pytest.fixture(scope="module")
def paper_split():
    """Split bases of the paper scene's facets seen from the SW, sun-up frames."""
    seq = scene.paper_sequence(view="SW")
    g = scene.seen_geometry(seq)
    up = seq.sky.sun_direction[:, 2] > 0.02
    full = il.illumination_bases(g, seq.sky)
    total = render.facet_bases(g, seq.sky)
    return full, total, up


def test_sun_and_sky_parts_sum_to_the_whole(paper_split):
    # the forward model is linear in radiance: the parts must add up to the
    # bases of the whole sky (ground plane lit by both, object's shadow included)
    full, total, up = paper_split
    np.testing.assert_allclose(full.total().diffuse, total.diffuse, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(full.total().glossy, total.glossy, rtol=1e-12, atol=1e-12)
    # and neither part is empty or the whole: a clear noon sun gives most of D
    noon = np.argmax(np.where(up, total.diffuse.max(0), 0))
    share = full.diffuse[0, :, noon].sum() / total.diffuse[:, noon].sum()
    assert 0.5 < share < 0.95


def test_frame_prior_is_the_documented_mixture():
    data = il.JointData(
        np.ones((1, 1)),
        np.ones((1, 1), bool),
        np.ones(1),
        np.ones((2, 1, 1)),
        np.ones((2, 1, 2, 1)),
        np.array([0.0, 1.0]),
        np.zeros(1),
        np.zeros(1),
    )
    x = np.linspace(-12, 6, 20001)
    lam = np.zeros((len(x), 4))
    lam[:, 1] = x
    dens = np.exp(il.log_prior_frames(lam, data) - 0.5 * np.log(2 * np.pi))
    # the sun's prior, without 1/sqrt(2 pi), integrates to 1 (the sky at its mode adds 0)
    assert abs(np.trapezoid(dens, x) - 1.0) < 1e-6
    # a hidden sun (log a = -3) is far more probable than a clear-only prior allows
    p = il.IlluminationPriors()
    assert dens[np.searchsorted(x, -3.0)] > 50 * np.exp(-0.5 * (3 / p.sun_clear_sd) ** 2)


@pytest.mark.parametrize("exposure_known", [True, False])
def test_frame_prior_along_a_direction_is_the_moved_prior_bit_for_bit(
    paper_three_skies, exposure_known
):
    # log_prior_frames_along computes each term of the frames' prior on the
    # moved latents only where the direction moves them, and must give the
    # same numbers, bit for bit, as log_prior_frames of the moved array (the
    # samplers' draws depend on it): checked for the three ridges' directions,
    # a day-level exposure with the offsets' axis, and a direction that moves
    # the sky shapes too. A version that left a moved latent unmoved would
    # differ by the shift's effect on its term (shown below to be large).
    full, up = paper_three_skies
    bases = full.take(slice(0, 3), up)
    f, t = bases.diffuse.shape[1:]
    exposure = np.ones(t) if exposure_known else None
    data = il.joint_data(np.ones((f, t)), np.ones((f, t), bool), bases, exposure=exposure)
    rng = np.random.default_rng(5)
    e, w, n_l = 2, 6, data.n_latents
    lam = rng.normal(0.0, 0.8, (e, w, t, n_l))
    hyper = rng.normal(0.0, 0.5, (e, w, 6))
    weights = il.log_sun_weights(hyper)
    shapes_too = np.arange(n_l, dtype=float) - 1.5
    directions = [data.exposure_direction, np.eye(n_l)[0], np.eye(n_l)[1] + np.eye(n_l)[2]]
    for direction in directions + [shapes_too]:
        c = 0.3 * np.arange(-4, 5)[:, None, None] * rng.uniform(0.5, 1.5, (e, w))  # (K, E, W)
        day = hyper[None] + c[..., None] * np.eye(6)[4]  # the day's mean moved with them
        moved = lam[None] + c[..., None, None] * direction
        want = il.log_prior_frames(moved, data, weights, exposure=il.exposure_day(day))
        got = il.log_prior_frames_along(
            lam, c[..., None], direction, data, weights, exposure=il.exposure_day(day)
        )
        assert got.shape == want.shape == (9, e, w, t)
        np.testing.assert_array_equal(got, want)
    unmoved = il.log_prior_frames(lam[None], data, weights, exposure=il.exposure_day(hyper))
    assert np.max(np.abs(want - unmoved)) > 1.0


def test_joint_model_finds_two_clouded_frames(paper_split):
    # an object simulated by the forward model, its sun cut to 5 % in two frames
    # and the sky 1.8x there; the joint sampler must find both, and gloss
    full, _, up = paper_split
    rng = np.random.default_rng(7)
    facets = np.arange(full.diffuse.shape[1])
    bases = full.take(facets, up)
    f, t = bases.diffuse.shape[1:]
    lam = np.zeros((1, 1, t, 4))
    lam[..., 1], lam[..., 2] = np.log(0.9), np.log(1.2)
    clouded = [5, 9]
    lam[0, 0, clouded, 1], lam[0, 0, clouded, 2] = np.log(0.05), np.log(1.8)
    th = np.zeros((1, f, 1, 4))
    th[..., 0], th[..., 1], th[..., 2], th[..., 3] = 0.5, np.log(200.0), np.log(0.5), np.log(0.03)
    valid = np.ones((f, t), bool)
    ref = il.joint_data(np.ones((f, t)), valid, bases, exposure=np.ones(t))
    y = il.simulate(th, lam, ref, rng)[0, :, 0]
    data = il.joint_data(y, valid, bases, exposure=np.ones(t))
    res = sample_joint(data, seed=1, min_sweeps=1200, max_sweeps=1200)
    sun = np.exp(res.frames[..., 1].reshape(-1, t))
    lo, hi = np.quantile(sun, [0.05, 0.95], axis=0)
    # both clouded frames: interval near 0.05, far from a clear sun
    assert np.all(hi[clouded] < 0.15) and np.all(lo[clouded] > 0.01)
    clear = np.setdiff1d(np.arange(t), clouded)
    # clear frames: the truth (0.9) inside nearly every 90 % interval; away from
    # dawn and dusk (where the low sun barely lights the facets) never near 0
    assert np.sum((lo[clear] < 0.9) & (hi[clear] > 0.9)) >= len(clear) - 2
    assert np.all(lo[clear[1:-1]] > 0.6)
    gamma = np.median(res.draws[..., 0].reshape(f, -1), axis=1)
    # the facets' gloss right despite the unknown brightnesses (the mean's
    # posterior sd is ~0.005 here; 0.02 allows for a short run)
    assert abs(np.median(gamma) - 0.5) < 0.02


def test_known_exposure_is_fixed_and_unknown_is_inferred(paper_split):
    full, _, up = paper_split
    bases = full.take(slice(0, 6), up)
    t = bases.diffuse.shape[-1]
    y = np.ones((6, t))
    known = il.joint_data(y, np.ones((6, t), bool), bases, exposure=2.0 ** np.arange(t))
    assert known.exposure_known
    # stored relative to the mean log: only ratios matter
    np.testing.assert_allclose(np.diff(known.log_exposure), np.log(2.0))
    free = il.joint_data(y, np.ones((6, t), bool), bases)
    lam = np.zeros((1, 1, t, 4))
    lam[..., 0] = 1.0
    # the same latents predict e x more with a free exposure, ignore it when known
    th = np.zeros((1, 6, 1, 3))
    th[..., 0], th[..., 1] = 0.3, 2.0
    ratio = il.predict(th, lam, free) / il.predict(th, lam * [0, 1, 1, 1], free)
    np.testing.assert_allclose(ratio, np.e)
    with pytest.raises(ValueError, match="positive"):
        il.joint_data(y, np.ones((6, t), bool), bases, exposure=-np.ones(t))


def test_sky_model_weights_are_uniform_on_the_simplex_a_priori(paper_three_skies):
    # with no usable observation the joint sampler must draw the prior: each
    # frame's three sky-model weights Dirichlet(1, 1, 1), so each weight has
    # mean 1/3 and P(w < 0.1) = 1 - 0.9^2 = 0.19 (a sampler or prior with the
    # Jacobian of the log-ratio coordinates wrong gives other values: without
    # it, the weights pile at the simplex's corners)
    full, up = paper_three_skies
    bases = full.take(slice(0, 4), np.flatnonzero(up)[3:9])
    f, t = bases.diffuse.shape[1:]
    data = il.joint_data(np.ones((f, t)), np.zeros((f, t), bool), bases, exposure=np.ones(t))
    assert data.shapes == 3 and data.n_latents == 5 and data.free.tolist() == [False] + [True] * 4
    res = sample_joint(data, seed=3, min_sweeps=1200, max_sweeps=1200)
    w = np.exp(il.log_shape_weights(res.frames)).reshape(-1, 3)
    # 4 x 16 walkers x 6 frames, thinned 4: ~15000 draws, autocorrelated;
    # the sd of a mean of uniform-simplex weights is 0.24 / sqrt(ESS ~ 500)
    np.testing.assert_allclose(w.mean(axis=0), 1 / 3, atol=0.04)
    np.testing.assert_allclose(np.mean(w < 0.1, axis=0), 0.19, atol=0.05)


@pytest.mark.long
def test_joint_model_tells_an_intermediate_sky(paper_three_skies):
    # an object simulated under the intermediate sky alone (its circumsolar
    # brightening is what a glossy lobe would otherwise be fitted to): the
    # mixture must give that shape most of the weight, and the gloss right
    full, up = paper_three_skies
    bases = full.take(slice(None), up)
    f, t = bases.diffuse.shape[1:]
    lam = np.zeros((1, 1, t, 5))
    lam[..., 3], lam[..., 4] = 8.0, 0.0  # w = (~0, ~1, ~0): intermediate
    th = np.zeros((1, f, 1, 4))
    th[..., 0], th[..., 1], th[..., 2], th[..., 3] = 0.3, np.log(100.0), np.log(0.5), np.log(0.02)
    valid = np.ones((f, t), bool)
    ref = il.joint_data(np.ones((f, t)), valid, bases, exposure=np.ones(t))
    y = il.simulate(th, lam, ref, np.random.default_rng(11))[0, :, 0]
    data = il.joint_data(y, valid, bases, exposure=np.ones(t))
    res = sample_joint(data, seed=4, min_sweeps=1000, max_sweeps=1000)
    w = np.exp(il.log_shape_weights(res.frames)).mean(axis=(0, 1))  # (T, 3)
    # averaged over the day, the intermediate sky has most of the weight (the
    # uniform prior gives 1/3); a low sun's frame may barely tell the shapes
    # apart (measured: 1 of 15 frames a near tie, 0.46 against 0.40)
    assert w.mean(axis=0)[1] > 0.7, w
    assert np.sum(np.argmax(w, axis=1) != 1) <= 2, w
    gamma = np.median(res.draws[..., 0].reshape(f, -1), axis=1)
    # the clear-overcast mixture of the previous stop read such objects ~0.3-0.7 high
    assert abs(np.median(gamma) - 0.3) < 0.03


def _sbc_ranks(paper_split, n_rep, seed, n_draws=99):
    """Simulation-based calibration of the joint model (Talts et al. 2018): objects
    of 8 facets over 8 frames, facets and frames drawn from the joint prior
    (a fixed prior centre of log s and a fixed noise floor, so that the
    likelihood fitted is exactly the one simulated), fitted by the joint
    sampler; ranks of the truth among ``n_draws`` posterior draws."""
    import dataclasses

    full, total, up = paper_split
    frames = np.flatnonzero(up)[2:-2][::2][:8]
    facets = np.linspace(0, full.diffuse.shape[1] - 1, 8).round().astype(int)
    bases = full.take(facets, frames)
    f, t = bases.diffuse.shape[1:]
    valid = np.ones((f, t), bool)
    ref = il.joint_data(
        np.ones((f, t)), valid, bases, exposure=np.ones(t), priors=lk.Priors(log_s_center=0.0)
    )
    ref = dataclasses.replace(ref, floor=0.01 * bases.total().diffuse.max(axis=1))
    rng = np.random.default_rng(seed)
    ranks = []
    for i in range(n_rep):
        th, lam = il.sample_prior(ref, 1, rng)
        y = il.simulate(th.transpose(1, 0, 2)[:, :, None, :], lam[:, None], ref, rng)[0, :, 0]
        data = dataclasses.replace(ref, y=y)
        res = sample_joint(
            data, n_ensembles=2, n_walkers=12, min_sweeps=1200, max_sweeps=1200, seed=i
        )
        g = res.draws[0, ..., 0].ravel()
        a = res.frames[..., t // 2, 1].ravel()
        b = res.frames[..., 0, 2].ravel()
        pick = np.linspace(0, len(g) - 1, n_draws).round().astype(int)
        truth = (th[0, 0, 0], lam[0, t // 2, 1], lam[0, 0, 2])
        ranks.append([int(np.sum(x[pick] < v)) for x, v in zip((g, a, b), truth, strict=True)])
    return np.array(ranks)


@pytest.mark.slow
def test_joint_model_sbc(paper_split):
    # 100 objects: ranks of gamma (a facet), the sun of a mid frame and the sky of
    # the first frame must be uniform on 0..99 (chi-square over 10 bins at
    # alpha 1e-3: a correct sampler fails 1 in 1000 runs per quantity; a
    # posterior 30 % too narrow fails with these 100 replicates)
    from scipy import stats

    ranks = _sbc_ranks(paper_split, 100, seed=2026)
    for k, name in enumerate(("gamma", "log_sun", "log_sky")):
        counts = np.bincount(ranks[:, k] * 10 // 100, minlength=10)
        p = stats.chisquare(counts).pvalue
        assert p > 1e-3, (name, counts)


def test_shared_sigma_marginal_is_the_integral_over_one_sigma(paper_split):
    # the one-material model's likelihood with one sigma for all facets: the
    # closed form against a quadrature over log sigma of the product of the
    # facets' normal likelihoods under the log-uniform prior; a per-facet
    # marginal (the sum over facets of their own integrals) differs by nats
    full, _, up = paper_split
    rng = np.random.default_rng(3)
    bases = full.take(np.arange(5), np.flatnonzero(up)[::3])
    f, t = bases.diffuse.shape[1:]
    valid = np.ones((f, t), bool)
    valid[1, 2] = False
    ref = il.joint_data(np.ones((f, t)), valid, bases, exposure=np.ones(t))
    th = np.zeros((1, f, 1, 4))
    th[..., 0], th[..., 1], th[..., 2], th[..., 3] = 0.4, np.log(50.0), 0.0, np.log(0.05)
    lam = np.zeros((1, 1, t, ref.n_latents))
    y = il.simulate(th, lam, ref, rng)[0, :, 0]
    data = il.joint_data(y, valid, bases, exposure=np.ones(t))
    th[..., 0] = 0.3  # away from the truth, so that Q is not the noise's alone
    ll = il.log_likelihood_shared_sigma(th, lam, data)[0, 0]
    la, lb = data.priors.log_sigma
    grid = np.linspace(la, lb, 200001)
    z, log_v = il._residuals(il.predict(th, lam, data), data)
    q, sum_log_v, n = np.sum(z * z), log_v.sum(), valid.sum()
    logl = -0.5 * q * np.exp(-2 * grid) - n * grid - sum_log_v - 0.5 * n * np.log(2 * np.pi)
    peak = logl.max()
    integral = peak + np.log(np.trapezoid(np.exp(logl - peak), grid) / (lb - la))
    assert abs(ll - integral) < 1e-6
    per_facet = il.log_likelihood_sigma_marginal(th, lam, data)[0, :, 0].sum()
    assert abs(per_facet - ll) > 1.0
    # and the draw of that sigma is its conditional: mean of sigma^-2 is 2k / Q
    _, q_f = il.log_likelihood_shared_sigma(th, lam, data, with_q=True)
    draws = il.draw_shared_log_sigma(np.repeat(q_f, 4000, axis=2), data, rng)
    assert np.all(draws[:, 0] == draws[:, -1])  # the same for every facet
    inv_var = np.exp(-2 * draws[0, 0])
    # Gamma(k, rate Q / 2): sd of the mean of 4000 is sqrt(k) / (Q / 2) / 63
    assert abs(inv_var.mean() - n / q) < 4 * np.sqrt(n / 2) / (q / 2) / np.sqrt(4000)


def test_bases_found_in_two_workers_are_the_bases_found_in_one(paper_three_skies):
    # jobs=2 splits the facets into two blocks, each block's bases of every
    # source found in a worker of its own, joined along the facets: each
    # facet's quadrature is its own, so the bases are the one process's
    # (the workers' one BLAS thread may change a matrix product's last bits:
    # rtol 1e-12, a million times finer than any basis difference the model
    # reads); also with the GGX lobe's Schlick rise, a third array to join
    from conftest import paper_three_skies_bases

    one, _ = paper_three_skies
    assert one.diffuse.shape[1] >= 16  # enough facets for two blocks
    two, _, _ = paper_three_skies_bases(jobs=2)
    for a, b in ((one.diffuse, two.diffuse), (one.glossy, two.glossy)):
        assert a.shape == b.shape
        np.testing.assert_allclose(b, a, rtol=1e-12, atol=1e-12 * a.max())
    np.testing.assert_array_equal(two.log_sun_ratio, one.log_sun_ratio)
    np.testing.assert_array_equal(two.fresnel.view, one.fresnel.view)
    kw = {"lobe_family": "ggx", "fresnel": "schlick-lobe", "exponents": [2.0, 30.0, 400.0]}
    rise_one, _, _ = paper_three_skies_bases(**kw)
    rise_two, _, _ = paper_three_skies_bases(jobs=2, **kw)
    a, b = rise_one.fresnel.glossy_rise, rise_two.fresnel.glossy_rise
    assert a.shape == b.shape and a.max() > 0
    np.testing.assert_allclose(b, a, rtol=1e-12, atol=1e-12 * a.max())


def test_bases_of_facet_blocks_join_to_the_bases_of_all(tmp_path):
    # the split of illumination_bases' workers, in one process: each block's
    # geometry (ViewGeometry.take) and mesh occlusion (Occlusion.take) give
    # its facets' rows of the whole's bases, on a bundle whose object_mesh
    # shades some facets (the occlusion's per-facet rays must follow their
    # facets into the block); to rounding: a product over fewer facets may
    # take another vector path and change the last bit (1.4e-14 of 80 on an
    # AMD EPYC at stop 70), so rtol 1e-12 as in the two-workers test above,
    # a million times finer than the mesh's effect checked below
    from test_visibility import read, write_mesh_bundle

    from bayesgloss import sky, visibility

    b = read(write_mesh_bundle(tmp_path, "mesh"))
    occ = visibility.bundle_occlusion(b)
    g = b.view_geometry()
    day = sky.daylight("gensky-clear", b.sun_direction, ground_reflectance=b.ground_albedo)
    other = sky.daylight("gensky-overcast", b.sun_direction, ground_reflectance=b.ground_albedo)
    args = (day, render.DEFAULT_EXPONENTS, (other,), "phong", False)
    kw = {"ground_reflectance": b.ground_albedo}
    whole = il._source_bases(g, *args, kw | {"occlusion": occ})
    assert (occ.sunlit_fraction == 0).any()  # the mesh shades something
    for rows in (np.array([0, 2]), np.array([1, 3])):
        part = il._source_bases(g.take(rows), *args, kw | {"occlusion": occ.take(rows)})
        np.testing.assert_allclose(part[0], whole[0][:, rows], rtol=1e-12, atol=0)
        np.testing.assert_allclose(part[1], whole[1][:, rows], rtol=1e-12, atol=0)
    # and a block of the convex model's own: the same rows
    plain = il._source_bases(g.take([1, 3]), *args, kw)
    assert not np.allclose(plain[0], whole[0][:, [1, 3]])  # the mesh matters here

"""The Fresnel raise of the one-material model (bayesgloss.fresnel)."""

import dataclasses

import numpy as np
import pytest

from bayesgloss import fresnel as fr
from bayesgloss import illumination as il
from bayesgloss import reflectance
from bayesgloss.sampling import sample_material


@pytest.mark.parametrize("kind", ["plastic", "metal"])
def test_fresnel_parts_are_radiance_materials(kind):
    # the transform of a unit part, times the normal-incidence albedo A, must
    # be what Radiance's normal.c reflects (reflectance.radiance_material, its
    # Fresnel raise at the view angle and dirnorm's at the sun's incidence)
    # for roughness-0 materials over a grid of colours, specularities and
    # angles; D and G arbitrary positive bases. A transform that forgot the
    # sun's diffuse factor, or divided by the wrong albedo, misses by > 1e-3
    rng = np.random.default_rng(0)
    for _ in range(40):
        rho, spec = rng.uniform(0.02, 0.9), rng.uniform(0.02, 0.98)
        c_view, c_sun = rng.uniform(0.02, 1.0), rng.uniform(0.02, 1.0)
        d_sky, d_sun, g_sky, g_sun = rng.uniform(0.1, 2.0, 4)
        m = reflectance.radiance_material(kind, rho, spec, 0.0, c_view, c_sun)
        gamma = float(reflectance.gloss_of_radiance_material(kind, spec, rho))
        albedo = spec + (1 - spec) * rho if kind == "plastic" else rho
        f_view = reflectance.fresnel_radiance(c_view)
        f_sun = reflectance.fresnel_radiance(c_sun)
        one = np.ones((1, 1, 1))
        k, log_a = one, np.log(albedo) * one
        sky = fr.fresnel_parts(
            (1 - gamma) * d_sky + gamma * g_sky * one, g_sky * one, k, log_a, np.array([f_view])
        )
        sun = fr.fresnel_parts(
            (1 - gamma) * d_sun + gamma * g_sun * one,
            g_sun * one,
            k,
            log_a,
            np.array([f_view]),
            np.array([[d_sun * f_sun]]),
            gamma * one,
        )
        want_sky = float(m.diffuse_ambient) * d_sky + float(m.specular) * g_sky
        want_sun = float(m.diffuse_direct) * d_sun + float(m.specular) * g_sun
        np.testing.assert_allclose(albedo * sky.ravel(), want_sky, rtol=1e-9)
        np.testing.assert_allclose(albedo * sun.ravel(), want_sun, rtol=1e-9)


def test_fresnel_terms_of_a_geometry(paper_three_skies):
    # F(c_f) of each facet's view cosine, and the direct sun's diffuse basis
    # times F at its incidence: the direct part of render.diffuse_components
    # (its E_sun cos_i / pi) weighted by normal.c's estimate
    from bayesgloss import render, scene

    seq = scene.paper_sequence(view="SW")
    g = scene.seen_geometry(seq)
    terms = fr.fresnel_terms(
        g,
        seq.sky.sun_direction,
        np.where(
            seq.sky.sun_direction[:, 2] > 0, seq.sky.solar_radiance * seq.sky.sun_solid_angle, 0.0
        ),
    )
    np.testing.assert_allclose(
        terms.view, reflectance.fresnel_radiance(np.maximum(g.cos_view, 0.001))
    )
    _, direct = render.diffuse_components(g, seq.sky)
    cos_i = np.maximum(g.normal @ seq.sky.sun_direction.T, 0.0)
    f_i = np.where(cos_i > 0, reflectance.fresnel_radiance(np.maximum(cos_i, 1e-9)), 0.0)
    np.testing.assert_allclose(terms.sun_direct, direct * f_i, rtol=1e-12, atol=1e-12)
    # the bases carry the same terms (split by facets and frames as the bases are)
    bases, up = paper_three_skies
    np.testing.assert_allclose(bases.fresnel.view, terms.view)
    np.testing.assert_allclose(
        bases.take(slice(0, 5), up).fresnel.sun_direct, terms.sun_direct[:5][:, up]
    )


def _exact_dielectric_fresnel(cos_i, eta):
    """Unpolarised Fresnel reflectance of a dielectric of relative index eta
    (Born and Wolf's s and p amplitudes, averaged in power)."""
    sin_t = np.sqrt(1 - cos_i**2) / eta
    cos_t = np.sqrt(1 - sin_t**2)
    rs = (cos_i - eta * cos_t) / (cos_i + eta * cos_t)
    rp = (eta * cos_i - cos_t) / (eta * cos_i + cos_t)
    return 0.5 * (rs**2 + rp**2)


def test_schlick_is_schlick_and_close_to_the_exact_fresnel():
    # Schlick (1994): exact at normal incidence and at grazing; within 0.04
    # of the exact unpolarised reflectance of glass (eta 1.5, F0 0.04) at
    # every angle (measured 0.036 at most, near 85 deg; 0.020 up to 78 deg).
    # A rise in (1 - c)^4 or ^6 misses by 0.10 and 0.055
    f0 = ((1.5 - 1) / (1.5 + 1)) ** 2
    assert reflectance.fresnel_schlick(1.0, f0) == pytest.approx(f0)
    assert reflectance.fresnel_schlick(0.0, f0) == pytest.approx(1.0)
    assert reflectance.fresnel_schlick(-0.5) == reflectance.fresnel_schlick(0.5) == 0.5**5
    c = np.linspace(0.02, 1.0, 200)
    err = np.abs(reflectance.fresnel_schlick(c, f0) - _exact_dielectric_fresnel(c, 1.5))
    assert err.max() < 0.04, err.max()
    assert err[c >= 0.2].max() < 0.025, err[c >= 0.2].max()


@pytest.fixture(scope="module")
def paper_three_skies_schlick():
    """paper_three_skies's bases with Schlick's Fresnel terms, and the geometry."""
    from conftest import paper_three_skies_bases

    return paper_three_skies_bases(fresnel="schlick")


def test_schlick_terms_of_the_bases(paper_three_skies, paper_three_skies_schlick):
    # the same geometry's terms with Schlick's rise: its view term is
    # (1 - c)^5 at each facet's view cosine, the sun's the Radiance terms'
    # with Radiance's rise swapped for Schlick's at each incidence
    radiance, _ = paper_three_skies
    schlick, up, g = paper_three_skies_schlick
    assert schlick.fresnel.model == "schlick" and radiance.fresnel.model == "radiance"
    np.testing.assert_allclose(
        schlick.fresnel.view, (1 - np.maximum(g.cos_view, 0.001)) ** 5, rtol=1e-12
    )
    lit = radiance.fresnel.sun_direct > 0
    assert np.array_equal(lit, schlick.fresnel.sun_direct > 0)
    assert not np.allclose(schlick.fresnel.sun_direct[lit], radiance.fresnel.sun_direct[lit])
    assert schlick.take(slice(0, 3), up).fresnel.model == "schlick"


def _simulated(bases, gamma, albedo, strength, rng, model="radiance"):
    f, t = bases.diffuse.shape[1:]
    lam = np.zeros((1, 1, t, 5))
    lam[..., 3:] = -8.0  # gensky's clear sky
    th = np.zeros((1, f, 1, 6))
    th[..., 0], th[..., 1], th[..., 3] = gamma, np.log(2000.0), np.log(0.01)
    th[0, :, 0, 2] = np.log(0.5) + 0.02 * rng.standard_normal(f)
    th[..., 4], th[..., 5] = strength, np.log(albedo)
    valid = np.ones((f, t), bool)
    ref = il.joint_data(np.ones((f, t)), valid, bases, exposure=np.ones(t), fresnel=model)
    return il.simulate(th, lam, ref, rng)[0, :, 0], valid


def test_dark_smooth_plastic_needs_the_fresnel_raise(paper_three_skies):
    # Radiance plastic of specularity 0.04 and colour 0.2 (gamma 0.171 at
    # normal incidence, A 0.232), Fresnel-raised as normal.c does it, seen
    # on every other facet of the paper's hemisphere (views up to F = 0.49):
    # without a Fresnel term the best one-material fit (the sampler's start,
    # a grid of gamma and n at the data's frames) takes the raise for gloss
    # (0.45 here, 0.75 on all facets; the holdout's vs02 read 0.60 for 0.17); the Fresnel model
    # must hold 0.171 in its 90 % interval within 0.02, its strength near 1
    # and its albedo within 20 %. 1 % noise; a short run (the medians move
    # by less than 0.005 between 600 and 1600 sweeps)
    from bayesgloss.sampling.joint import starting_frames
    from bayesgloss.sampling.starts import starting_material

    full, up = paper_three_skies
    bases = full.take(slice(0, None, 2), up)
    rng = np.random.default_rng(1)
    y, valid = _simulated(bases, 0.171, 0.232, 1.0, rng)
    t = y.shape[1]
    plain = il.joint_data(y, valid, bases, exposure=np.ones(t))
    gamma_plain = starting_material(plain, starting_frames(plain))[0]
    assert gamma_plain > 0.35, gamma_plain
    data = il.joint_data(y, valid, bases, exposure=np.ones(t), fresnel="radiance")
    res = sample_material(data, seed=4, min_sweeps=400, max_sweeps=400)
    assert res.parameters[4:] == ("fresnel_strength", "log_normal_albedo")
    g = res.draws[0, ..., 0].ravel()
    q05, q50, q95 = np.quantile(g, [0.05, 0.5, 0.95])
    assert q05 <= 0.171 <= q95 and abs(q50 - 0.171) < 0.02, (q05, q50, q95)
    assert np.median(res.draws[0, ..., 4]) > 0.9
    assert abs(np.exp(np.median(res.draws[0, ..., 5])) / 0.232 - 1) < 0.2


def test_the_fresnel_models_start_leaves_the_gloss_a_fresnel_free_start_reads(
    paper_three_skies,
):
    # the sampler's start (stop 74) on the Fresnel-raised dark plastic above
    # (gamma 0.171, A 0.232, k 1; 1 % noise): the Fresnel-free grid reads the
    # raise as gloss (> 0.35), and so does the Fresnel model's at the chain's
    # old fixed k 1/2 and A 0.3 (0.275 here; 0.8 for a true 0.35 on a seen
    # box). Profiled over k and A, the start must take k 1, the data's, and
    # a gamma below 0.2. (Not the truth's 0.171 itself: the start's sky is an
    # even mixture of the three shapes, the data's gensky clear alone; at the
    # true k and A it reads 0.025.)
    from bayesgloss.sampling.joint import starting_frames
    from bayesgloss.sampling.starts import START_FRESNEL_GRID, starting_material

    full, up = paper_three_skies
    bases = full.take(slice(0, None, 2), up)
    y, valid = _simulated(bases, 0.171, 0.232, 1.0, np.random.default_rng(1))
    t = y.shape[1]
    plain = il.joint_data(y, valid, bases, exposure=np.ones(t))
    gamma_plain, _, _, none = starting_material(plain, starting_frames(plain))
    assert gamma_plain > 0.35 and none is None
    data = il.joint_data(y, valid, bases, exposure=np.ones(t), fresnel="radiance")
    gamma0, _, _, fresnel0 = starting_material(data, starting_frames(data))
    assert fresnel0 in START_FRESNEL_GRID and fresnel0[0] == 1.0, fresnel0
    assert gamma0 < 0.2, gamma0


@pytest.mark.long
def test_a_dielectric_coating_is_read_with_schlicks_rise(paper_three_skies_schlick):
    # a dark dielectric-coated material (F0 0.04 over a diffuse base of 0.2:
    # gamma 0.04 / (0.04 + 0.96 x 0.2) = 0.172, A 0.232) with Schlick's rise
    # on the glossy and diffuse parts, as the model's own data (1 % noise):
    # --fresnel schlick must hold 0.172 in its 90 % interval within 0.02 and
    # read the strength near 1, as the Radiance model does on its own data;
    # without a Fresnel term the start takes the rise for gloss (> 0.35)
    from bayesgloss.sampling.joint import starting_frames
    from bayesgloss.sampling.starts import starting_material

    full, up, _ = paper_three_skies_schlick
    bases = full.take(slice(0, None, 2), up)
    rng = np.random.default_rng(2)
    y, valid = _simulated(bases, 0.172, 0.232, 1.0, rng, model="schlick")
    t = y.shape[1]
    plain = il.joint_data(y, valid, bases, exposure=np.ones(t))
    assert starting_material(plain, starting_frames(plain))[0] > 0.35
    data = il.joint_data(y, valid, bases, exposure=np.ones(t), fresnel="schlick")
    res = sample_material(data, seed=4, min_sweeps=400, max_sweeps=400)
    g = res.draws[0, ..., 0].ravel()
    q05, q50, q95 = np.quantile(g, [0.05, 0.5, 0.95])
    assert q05 <= 0.172 <= q95 and abs(q50 - 0.172) < 0.02, (q05, q50, q95)
    assert np.median(res.draws[0, ..., 4]) > 0.9


@pytest.mark.long
def test_without_data_the_fresnel_unknowns_keep_their_prior(paper_three_skies):
    # no usable observation: k uniform on [0, 1] (mean 1/2) and log A uniform
    # on its range; a move that is not reversible in the new coordinates, or
    # a prior left out, pulls these off. Tolerances: autocorrelated draws of
    # a few hundred effective samples
    full, up = paper_three_skies
    bases = full.take(slice(0, 5), np.flatnonzero(up)[3:9])
    f, t = bases.diffuse.shape[1:]
    data = il.joint_data(
        np.ones((f, t)), np.zeros((f, t), bool), bases, exposure=np.ones(t), fresnel="radiance"
    )
    res = sample_material(data, seed=3, min_sweeps=800, max_sweeps=800)
    k = res.draws[0, ..., 4].ravel()
    lo, hi = np.log(fr.NORMAL_ALBEDO_RANGE)
    u = (res.draws[0, ..., 5].ravel() - lo) / (hi - lo)
    assert abs(k.mean() - 0.5) < 0.08 and abs(np.mean(k < 0.2) - 0.2) < 0.08
    assert abs(u.mean() - 0.5) < 0.08 and abs(np.mean(u < 0.2) - 0.2) < 0.08
    assert abs(res.draws[0, ..., 0].mean() - 0.5) < 0.08


def test_unknown_fresnel_model_is_refused(paper_three_skies):
    full, up = paper_three_skies
    bases = full.take(slice(0, 3), up)
    f, t = bases.diffuse.shape[1:]
    with pytest.raises(ValueError, match="unknown Fresnel model 'cook-torrance'"):
        il.joint_data(np.ones((f, t)), np.ones((f, t), bool), bases, fresnel="cook-torrance")
    # a known model on bases that hold another model's terms
    with pytest.raises(ValueError, match="needs bases with its terms"):
        il.joint_data(np.ones((f, t)), np.ones((f, t), bool), bases, fresnel="schlick")


def test_estimate_with_the_fresnel_raise_reads_a_smooth_radiance_plastic(tmp_path):
    # estimate end to end on the synthetic bundle of conftest (Radiance's
    # plastic of specularity 0.5 and grey 0.5 by normal.c's coefficients,
    # roughness 0: gamma 2/3 at normal incidence, A 0.75; 1 % noise), the sky
    # named: with --fresnel radiance the object's 90 % interval holds 2/3 and
    # reads the strength near 1 and A within 15 %; the summary, the printed
    # line's fields and the InferenceData (attribute ``fresnel``, written and
    # read back) say which model ran. Without the raise the same run read
    # 0.802 [0.770, 0.837] (measured), the raise taken for gloss
    from conftest import make_synthetic_bundle

    from bayesgloss import estimate

    path = make_synthetic_bundle(tmp_path / "b", specularity=0.5, noise=0.01, seed=4)
    res = estimate.estimate_bundle(
        path,
        per_frame=True,
        illumination="gensky-clear",
        sampler_options={"max_steps": 400},
        fresnel="radiance",
    )
    o = res.summary["object"]
    own = o["gamma_within_model"]  # the model's own interval, its error aside
    lo, hi = own["hdi90"]
    assert lo <= 2 / 3 <= hi and abs(own["median"] - 2 / 3) < 0.03, own
    assert o["fresnel_strength"]["median"] > 0.8
    assert abs(o["normal_albedo"]["median"] / 0.75 - 1) < 0.15
    assert res.summary["fresnel"] == "radiance"
    estimate.write_result(tmp_path / "out", res)
    back = estimate.read_result(tmp_path / "out")
    assert back.idata.posterior.attrs["fresnel"] == "radiance"
    assert "normal_albedo" in back.idata.posterior
    with pytest.raises(ValueError, match="unknown Fresnel model"):
        estimate.estimate_bundle(path, fresnel="cook-torrance")


def test_several_bundles_carry_the_fresnel_model_into_their_units(tmp_path, monkeypatch):
    # estimate over several bundles runs each as a unit of work: --fresnel must
    # reach every unit's options (a unit without it would run the default
    # model silently), and be absent where not given (the units' keys of
    # earlier runs unchanged)
    from conftest import estimate_option_route

    route = estimate_option_route(monkeypatch, tmp_path, ["--fresnel", "radiance"], "fresnel")
    assert route["units"] == ["radiance", "radiance"]
    assert not route["plain_units_have_key"]
    assert route["estimate_bundle"] == ["radiance", None, "radiance"]  # None: the default


def test_the_rise_inside_the_lobe_is_the_view_rise_where_they_agree():
    # fresnel_parts_in_lobe with G^S = F_f G (a mirror's lobe, where every
    # direction's half vector is the view's) is fresnel_parts exactly, for
    # the sun's part and a sky's; with k = 0 it is the model without Fresnel
    rng = np.random.default_rng(5)
    f, w, t = 4, 3, 6
    d, g = rng.uniform(0.1, 2.0, (f, w, t)), rng.uniform(0.1, 5.0, (f, w, t))
    view = rng.uniform(0.0, 0.5, f)
    k, log_a = rng.uniform(0, 1, (1, w, 1)), np.log(rng.uniform(0.1, 1, (1, w, 1)))
    gamma, sun = rng.uniform(0, 1, (f, w, 1)), rng.uniform(0, 0.3, (f, t))
    rise = view[:, None, None] * g
    for s in (None, sun):
        old = fr.fresnel_parts((1 - gamma) * d + gamma * g, g, k, log_a, view, s, gamma)
        new = fr.fresnel_parts_in_lobe(d, g, rise, k, log_a, view, gamma, s)
        np.testing.assert_allclose(new, old, rtol=1e-12)
    zero = fr.fresnel_parts_in_lobe(d, g, rise, 0 * k, log_a, view, gamma, sun)
    np.testing.assert_allclose(zero, (1 - gamma) * d + gamma * g, rtol=1e-12)


@pytest.fixture(scope="module")
def paper_three_skies_in_lobe():
    """paper_three_skies's bases with the GGX lobe and Schlick's rise inside it."""
    from conftest import paper_three_skies_bases

    return paper_three_skies_bases(fresnel="schlick-lobe", lobe_family="ggx")


def test_in_lobe_terms_enter_the_likelihood_at_the_exponent(paper_three_skies_in_lobe):
    # the bases carry G^S of every source beside G (P, F, N, T), subsets keep
    # it, and the joint model's unit parts at an exponent on a table node are
    # fresnel_parts_in_lobe of that node's G and G^S: a likelihood that took
    # the view's rise (the "schlick" model) differs by more than 5 % there
    full, up, _ = paper_three_skies_in_lobe
    assert full.fresnel.model == "schlick-lobe"
    assert full.fresnel.glossy_rise.shape == full.glossy.shape
    bases = full.take(slice(0, None, 2), up)
    assert bases.fresnel.glossy_rise.shape == bases.glossy.shape
    f, t = bases.diffuse.shape[1:]
    data = il.joint_data(
        np.ones((f, t)), np.ones((f, t), bool), bases, exposure=np.ones(t), fresnel="schlick-lobe"
    )
    node = 14
    th = np.zeros((1, f, 1, 6))
    th[..., 0], th[..., 1] = 0.3, np.log(bases.exponents[node])
    th[..., 4], th[..., 5] = 1.0, np.log(0.3)
    parts = il.unit_parts(th, data)
    gamma, k, log_a = th[..., 0:1][0], th[..., 4:5][0], th[..., 5:6][0]
    plain = dataclasses.replace(bases.fresnel, glossy_rise=None)
    viewed = il.unit_parts(th, dataclasses.replace(data, fresnel=plain))
    for p in range(data.sources):
        expected = fr.fresnel_parts_in_lobe(
            bases.diffuse[p][:, None, :],
            bases.glossy[p][:, node][:, None, :],
            bases.fresnel.glossy_rise[p][:, node][:, None, :],
            k,
            log_a,
            bases.fresnel.view,
            gamma,
            bases.fresnel.sun_direct if p == 0 else None,
        )
        np.testing.assert_allclose(parts[p][0], expected, rtol=1e-9)
    # the sun's part: the view's rise in place of the rise inside
    assert np.max(np.abs(viewed[0] / parts[0] - 1)) > 0.05


def test_the_rise_inside_needs_the_ggx_lobe():
    from conftest import paper_three_skies_bases

    with pytest.raises(ValueError, match="inside the 'ggx' lobe, not the 'phong' lobe"):
        paper_three_skies_bases(fresnel="schlick-lobe")


def test_the_rise_inside_reads_mitsubas_rough_coating_under_a_uniform_sky():
    # Mitsuba's roughplastic (alpha 0.2; index 1.5 over diffuse 0.05, index
    # 1.8 over 0.3): its specular part's directional albedo by its own
    # importance sampling (4000 draws, seed 0; about 2 % noise) against the
    # model's glossy part under a uniform sky at the material's gamma and A,
    # k = 1. With the rise inside the lobe 0.85-1.35 of Mitsuba's at views of
    # 0-85 deg (seen: 0.94-1.19; Schlick's own error near 50 deg is the
    # excess); with the rise at the view angle Mitsuba's is under 0.45 of
    # the model's at 85 deg (seen: 0.33, 0.38), so this test fails the old model
    from conftest import UniformSky

    from bayesgloss import lobes, render
    from bayesgloss import mitsuba_render as mr

    luminance = np.asarray(reflectance.LUMINANCE_WEIGHTS)  # the bundle's weights
    uniform = UniformSky(np.ones(1), np.array([[0.0, 0.0, 1.0]]), np.zeros(1))
    angle = np.radians([0.0, 50.0, 70.0, 85.0])
    views = np.stack([np.sin(angle), 0 * angle, np.cos(angle)], -1)
    geometry = render.ViewGeometry(np.tile([0.0, 0.0, 1.0], (len(views), 1)), views)
    rise_view = reflectance.fresnel_schlick(views[:, 2])
    for eta, rho in ((1.5, 0.05), (1.8, 0.3)):
        mat = mr.MitsubaMaterial(kind="roughplastic", diffuse=rho, int_ior=eta, alpha=0.2)
        r_s, r_d = mr.mitsuba_albedos(mat)
        albedo = float(r_s @ luminance + r_d @ luminance)
        gamma = float(r_s @ luminance) / albedo
        rng = np.random.default_rng(0)
        spec = [mr.mitsuba_directional_albedo(mat, o, "specular", rng) @ luminance for o in views]
        n = [2.0 / 0.2**2 - 2.0]
        g = lobes.glossy_basis(geometry, uniform, n, family="ggx", ground="sky")[:, 0, 0]
        g_s = lobes.ggx_schlick_rise_basis(geometry, uniform, n, ground="sky")[:, 0, 0]
        one = np.ones((len(views), 1, 1))
        inside = fr.fresnel_parts_in_lobe(
            0 * one,
            g[:, None, None],
            g_s[:, None, None],
            one,
            np.log(albedo) * one,
            0 * rise_view,
            gamma * one,
        )[:, 0, 0]
        ratio = np.array(spec) / (albedo * inside)
        assert np.all((ratio > 0.85) & (ratio < 1.35)), (eta, ratio)
        at_view = albedo * (gamma * (1 - rise_view) + rise_view / albedo) * g
        assert spec[-1] / at_view[-1] < 0.45, (eta, spec[-1] / at_view[-1])


@pytest.mark.long
def test_a_rough_coating_is_read_with_the_rise_inside_the_lobe(paper_three_skies_in_lobe):
    # the dark coating of test_a_dielectric_coating_is_read_with_schlicks_rise
    # (gamma 0.172, A 0.232) on a rough GGX lobe (n 30, alpha 0.25), the
    # rise inside the lobe, as the model's own data (1 % noise): the 90 %
    # interval holds 0.172 within 0.03 and the strength reads near 1. The
    # same data fitted with the view's rise must read otherwise (its median
    # more than 0.02 away), or this test could not tell the two models apart
    full, up, _ = paper_three_skies_in_lobe
    bases = full.take(slice(0, None, 2), up)
    rng = np.random.default_rng(2)
    f, t = bases.diffuse.shape[1:]
    lam = np.zeros((1, 1, t, 5))
    lam[..., 3:] = -8.0  # gensky's clear sky
    th = np.zeros((1, f, 1, 6))
    th[..., 0], th[..., 1], th[..., 3] = 0.172, np.log(30.0), np.log(0.01)
    th[0, :, 0, 2] = np.log(0.5) + 0.02 * rng.standard_normal(f)
    th[..., 4], th[..., 5] = 1.0, np.log(0.232)
    valid = np.ones((f, t), bool)
    ref = il.joint_data(np.ones((f, t)), valid, bases, exposure=np.ones(t), fresnel="schlick-lobe")
    y = il.simulate(th, lam, ref, rng)[0, :, 0]
    medians = {}
    for model in ("schlick-lobe", "schlick"):
        terms = bases.fresnel
        if model == "schlick":
            terms = dataclasses.replace(terms, glossy_rise=None, model="schlick")
        data = il.joint_data(
            y, valid, dataclasses.replace(bases, fresnel=terms), exposure=np.ones(t), fresnel=model
        )
        res = sample_material(data, seed=4, min_sweeps=400, max_sweeps=400)
        g = res.draws[0, ..., 0].ravel()
        q05, medians[model], q95 = np.quantile(g, [0.05, 0.5, 0.95])
        if model == "schlick-lobe":
            assert q05 <= 0.172 <= q95 and abs(medians[model] - 0.172) < 0.03, (q05, q95)
            assert np.median(res.draws[0, ..., 4]) > 0.8
    assert abs(medians["schlick"] - 0.172) > 0.02, medians


@pytest.mark.long
def test_estimate_runs_the_rise_inside_the_lobe_end_to_end(tmp_path):
    # estimate --fresnel schlick-lobe on the synthetic bundle (smooth Radiance
    # plastic, gamma 2/3, A 0.75): the GGX lobe is taken, the summary and the
    # InferenceData name the model, and the Fresnel unknowns are reported
    # (plumbing only: without the GGX lobe taken by default the estimate
    # raises). Not asserted: its gamma. This smooth plastic under one
    # named sky reads 0.13 with GGX and either Schlick model (A 0.12-0.20
    # for 0.75: A weakly identified takes the gloss, fresnel's Limits;
    # measured stop 53), so the GGX coating is not a smooth material's model
    from conftest import make_synthetic_bundle

    from bayesgloss import estimate

    path = make_synthetic_bundle(tmp_path / "b", specularity=0.5, noise=0.01, seed=4)
    res = estimate.estimate_bundle(
        path,
        per_frame=True,
        illumination="gensky-clear",
        sampler_options={"max_steps": 300},
        fresnel="schlick-lobe",
    )
    o = res.summary["object"]
    assert res.summary["fresnel"] == "schlick-lobe"
    assert res.idata.posterior.attrs["lobe_family"] == "ggx"
    assert "fresnel_strength" in o and "normal_albedo" in o

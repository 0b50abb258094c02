"""Lobe families (bayesgloss.lobes) and their stacking (bayesgloss.lobe_families)."""

from __future__ import annotations

import numpy as np
import pytest

from bayesgloss import estimate, lobes, render, scene


class _SmoothSky:
    """A sky with a smooth radiance over the whole sphere and no sun (for
    brute-force integrals): L(d) = 1 + 2 max(z, 0) + 0.5 x."""

    sun_direction = np.array([[0.0, 0.0, 1.0]])
    solar_radiance = np.array([0.0])
    sun_solid_angle = 6.8e-5

    def radiance(self, d):
        d = np.asarray(d, dtype=float)
        return (1.0 + 2.0 * np.maximum(d[..., 2], 0.0) + 0.5 * d[..., 0])[..., None]


def _brute(f_of_dirs, resolution=0.25):
    """int f(d) d omega on the ring quadrature of the forward model at ``resolution`` deg."""
    d, w = render.sphere_quadrature(resolution)
    return float(np.sum(f_of_dirs(d) * w))


@pytest.mark.parametrize("alpha", [0.1, 0.3, 0.8])
def test_ggx_albedo_at_normal_incidence_is_the_brute_force_integral(alpha):
    # int f cos(theta_i) d omega_i over a 0.25 deg ring grid (3e6 cells): the
    # lobe is wide beside a cell for alpha >= 0.1, so 2e-4 is the grid's error.
    # A dropped Smith factor would give 1.0 at every alpha, a dropped
    # Jacobian 4 (h.o) a factor of 4
    n = np.array([0.0, 0.0, 1.0])
    brute = _brute(lambda d: lobes.ggx_smith(d, n, n, alpha) * np.maximum(d[:, 2], 0.0))
    assert lobes.ggx_normal_albedo(alpha) == pytest.approx(brute, rel=2e-4)


def test_ggx_albedo_falls_with_roughness_and_broadcasts():
    # Smith's single scattering loses more energy the rougher the surface
    # (Walter et al. 2007, fig. 7: about 0.43 left at alpha 0.8 by our integral)
    a = lobes.ggx_normal_albedo(np.array([[0.02, 0.2], [0.5, 0.8]]))
    assert a.shape == (2, 2)
    assert a[0, 0] > a[0, 1] > a[1, 0] > a[1, 1]
    assert a[0, 0] == pytest.approx(1.0, abs=1e-3)


@pytest.mark.parametrize("alpha", [0.05, 0.2, 0.5])
def test_ggx_basis_is_the_brute_force_reflectance_integral(alpha):
    # an oblique facet and view under a smooth sky: the basis (importance
    # nodes on the GGX density) against int f L cos / A on a 0.25 deg grid;
    # 0.3 % holds the grid's error at alpha 0.05 (the narrowest lobe)
    nrm = np.array([0.2, 0.1, 0.97]) / np.linalg.norm([0.2, 0.1, 0.97])
    view = np.array([0.6, -0.3, 0.74]) / np.linalg.norm([0.6, -0.3, 0.74])
    sky = _SmoothSky()
    g = lobes.ggx_glossy_basis(
        render.ViewGeometry(nrm[None], view[None]), sky, [alpha], ground="sky"
    )
    brute = _brute(
        lambda d: (
            lobes.ggx_smith(d, view, nrm, alpha) * np.maximum(d @ nrm, 0.0) * sky.radiance(d)[:, 0]
        )
    ) / float(lobes.ggx_normal_albedo(alpha))
    assert g[0, 0, 0] == pytest.approx(brute, rel=3e-3)


@pytest.mark.parametrize("alpha", [0.05, 0.2, 0.5])
def test_ggx_rise_basis_is_the_brute_force_integral_of_the_rise_inside(alpha):
    # G^S: each direction's light weighted by Schlick's rise at its own half
    # vector with the view, against the same 0.25 deg grid integral (0.3 %:
    # the grid's error, as for G). The view here is 68 deg from the normal,
    # where the rise at the view angle, S(c_o) G, is off from the rise
    # inside by more than 5 % at every alpha (6.5 % at 0.05, the narrowest;
    # asserted), over 15 times the tolerance: a basis that took the view's
    # rise, or left the rise out, fails
    nrm = np.array([0.2, 0.1, 0.97]) / np.linalg.norm([0.2, 0.1, 0.97])
    view = np.array([0.9, -0.3, 0.25]) / np.linalg.norm([0.9, -0.3, 0.25])
    sky = _SmoothSky()
    geometry = render.ViewGeometry(nrm[None], view[None])
    n = 2.0 / alpha**2 - 2.0  # the Phong-equivalent exponent of alpha
    rise = lobes.ggx_schlick_rise_basis(geometry, sky, [n], ground="sky")[0, 0, 0]

    def integrand(d):
        h = d + view
        h /= np.linalg.norm(h, axis=-1, keepdims=True)
        f = lobes.ggx_smith(d, view, nrm, alpha) * lobes.schlick_rise(h @ view)
        return f * np.maximum(d @ nrm, 0.0) * sky.radiance(d)[:, 0]

    brute = _brute(integrand) / float(lobes.ggx_normal_albedo(alpha))
    assert rise == pytest.approx(brute, rel=3e-3)
    g = lobes.ggx_glossy_basis(geometry, sky, [alpha], ground="sky")[0, 0, 0]
    at_view = float(lobes.schlick_rise(view @ nrm)) * g
    assert abs(at_view / brute - 1) > 0.05, at_view / brute


def test_ggx_rise_basis_weighs_the_sun_by_the_rise_at_its_half_vector():
    # a sun alone (point source): G^S / G is S(h.s) exactly, h the half
    # vector of the sun and the view, at every roughness
    class SunOnly(_SmoothSky):
        sun_direction = np.array([[0.5, 0.2, 0.84], [-0.3, 0.6, 0.74]])
        sun_direction = sun_direction / np.linalg.norm(sun_direction, axis=1, keepdims=True)
        solar_radiance = np.array([1.0e4, 2.0e4])

        def radiance(self, d):
            return np.zeros(np.shape(d)[:-1] + (2,))

    nrm = np.array([[0.0, 0.0, 1.0]])
    view = np.array([[-0.7, 0.1, 0.71]]) / np.linalg.norm([-0.7, 0.1, 0.71])
    geometry = render.ViewGeometry(nrm, view)
    n = np.array([10.0, 100.0, 1000.0])
    g = lobes.glossy_basis(geometry, SunOnly(), n, family="ggx", ground="sky")[0]
    rise = lobes.ggx_schlick_rise_basis(geometry, SunOnly(), n, ground="sky")[0]
    h = SunOnly.sun_direction + view
    h /= np.linalg.norm(h, axis=1, keepdims=True)
    expected = lobes.schlick_rise(np.sum(h * SunOnly.sun_direction, axis=1))
    assert np.all(g > 0)
    np.testing.assert_allclose(rise / g, np.broadcast_to(expected, g.shape), rtol=1e-12)


def test_normalised_ggx_lobe_returns_a_uniform_sky_at_normal_view():
    # white-furnace test: a uniform sky of radiance 1 seen along the normal is
    # reflected as 1 by a lobe of unit albedo at normal incidence, at every
    # roughness (unnormalised it would read A(alpha), 0.43 at alpha 0.8);
    # 0.5 %: the basis's 16 nodes in xi straddle the cut where i goes below
    # the surface (delta = 45 deg), the albedo's 96 end there (0.27 % seen)
    class Uniform(_SmoothSky):
        def radiance(self, d):
            return np.ones(np.shape(d)[:-1] + (1,))

    up = np.array([[0.0, 0.0, 1.0]])
    g = lobes.ggx_glossy_basis(
        render.ViewGeometry(up, up), Uniform(), [0.05, 0.3, 0.8], ground="sky"
    )
    np.testing.assert_allclose(g[0, :, 0], 1.0, rtol=5e-3)


def test_families_share_the_exponent_table_and_phong_is_unchanged():
    seq = scene.paper_sequence(view="SW")
    geom = scene.seen_geometry(seq)
    n = render.DEFAULT_EXPONENTS[::6]
    phong = lobes.facet_bases(geom, seq.sky, n, family="phong")
    direct = render.facet_bases(geom, seq.sky, n)
    assert np.array_equal(phong.glossy, direct.glossy)
    assert np.array_equal(phong.diffuse, direct.diffuse)
    ward = lobes.facet_bases(geom, seq.sky, n, family="ward")
    alpha = lobes.roughness_of_exponent(n)
    np.testing.assert_array_equal(ward.glossy, render.ward_glossy_basis(geom, seq.sky, alpha))
    np.testing.assert_array_equal(ward.exponents, n)
    # n = 2 / alpha^2 - 2 (Walter et al. 2007, section 5.2)
    np.testing.assert_allclose(2.0 / alpha**2 - 2.0, n, rtol=1e-12)
    with pytest.raises(ValueError, match="unknown lobe family 'blinn'; valid: phong, ward, ggx"):
        lobes.facet_bases(geom, seq.sky, n, family="blinn")
    with pytest.raises(ValueError, match="exponent must be finite"):
        lobes.roughness_of_exponent([-1.0])


def _lobe_bundle(path, family, exponent, gamma, seed=1):
    """A forward-model bundle (conftest's) of one material with ``family``'s
    lobe at the Phong-equivalent ``exponent``, 2 % relative noise."""
    from conftest import make_synthetic_bundle

    def radiance(geom, sky):
        fb = lobes.facet_bases(geom, sky, [exponent, exponent * 1.0001], family=family)
        return 0.4 * ((1 - gamma) * fb.diffuse + gamma * fb.glossy[:, 0])

    return make_synthetic_bundle(path, noise=0.02, seed=seed, radiance=radiance)


def _stacked_under_clear_sky(path, lobe="families"):
    """``estimate`` of a stack of lobes (``lobe``) under gensky's clear sky,
    named, 600 sweeps at most, two jobs; the ground sunlit everywhere, as
    conftest's forward-model bundles make it (they cast no ground shadow),
    so that the model fitted is the one that made the data."""
    return estimate.estimate_bundle(
        path,
        per_frame=True,
        illumination="gensky-clear",
        lobe=lobe,
        ground_shadow="none",
        jobs=2,
        sampler_options={"max_steps": 600},
    )


@pytest.mark.parametrize(
    ("family", "exponent", "gamma"), [("ward", 200.0, 0.5), ("ggx", 50.0, 0.3)]
)
@pytest.mark.long
def test_stacking_names_the_generating_lobe_family(tmp_path, family, exponent, gamma):
    # 2 % noise on a 16-facet object under a named clear sky: the generating
    # family's PSIS-LOO was 150+ nats above the others' in trials (phong read
    # 0.47 and 0.20 for these), so its weight must be near 1 and the
    # object's interval hold the truth
    res = _stacked_under_clear_sky(_lobe_bundle(tmp_path / family, family, exponent, gamma))
    s = res.summary
    assert s["lobe_families"][family]["weight"] > 0.95
    assert s["lobe_family"] == family
    g = s["object"]["gamma_within_model"]  # the model's own interval
    assert g["q05"] <= gamma <= g["q95"]
    alpha = float(lobes.roughness_of_exponent(exponent))
    r = s["lobe_families"][family]["roughness"]
    assert r["q05"] * 0.9 <= alpha <= r["q95"] * 1.1
    assert res.idata.posterior.attrs["lobe_family_most_weight"] == family


def _coated_bundle(path, gamma, albedo, exponent, seed=2):
    """A forward-model bundle of a dielectric coating over a diffuse base:
    the GGX lobe at the Phong-equivalent ``exponent`` with Schlick's rise
    inside it (each light's own half vector, G^S), the coating's (1 - F) at
    the view and the sun's incidence on the diffuse part
    (:func:`bayesgloss.fresnel.fresnel_parts_in_lobe` at strength 1), the
    normal-incidence albedo ``albedo``; 2 % relative noise."""
    from conftest import make_synthetic_bundle

    from bayesgloss import fresnel

    def radiance(geom, sky):
        pair = [exponent, exponent * 1.0001]
        fb = lobes.facet_bases(geom, sky, pair, family="ggx")
        glossy, rise = fb.glossy[:, 0], lobes.ggx_schlick_rise_basis(geom, sky, pair)[:, 0]
        terms = fresnel.fresnel_terms(
            geom, *render._sun_terms(sky), model="schlick"
        )  # F at the view, and the direct sun's diffuse basis times F at its incidence
        transmitted = (1 - terms.view[:, None]) * (1 - gamma)
        unit = transmitted * (fb.diffuse - terms.sun_direct) + gamma * (glossy - rise)
        return albedo * unit + rise  # glossy: F0 G + (1 - F0) G^S, F0 = A gamma

    return make_synthetic_bundle(path, noise=0.02, seed=seed, radiance=radiance)


def test_stacking_the_materials_names_a_dielectric_coating(tmp_path):
    # F0 0.04 over a diffuse base of 0.25 (gamma 0.04 / (0.04 + 0.96 x 0.25)
    # = 0.143, A 0.28), a GGX lobe of Phong-equivalent n 400, seen on the
    # 16-facet object under a named clear sky at 2 % noise: the lobes without
    # the Fresnel rise take it for gloss (at stop 55 Phong read 0.60, GGX
    # alone 0.48; the coating's PSIS-LOO 213 nats above theirs), so the
    # coating's weight must be near 1 and its gamma within 0.015 (it read
    # 0.151 [0.145, 0.158]: the GGX tables interpolated between their nodes
    # of n and a 600-sweep run), the reported interval holding the truth; the
    # summary names each fit's lobe and Fresnel model (the rise inside the
    # lobe since stop 55; data made with the view's rise read 0.162)
    gamma, albedo = 0.04 / (0.04 + 0.96 * 0.25), 0.04 + 0.96 * 0.25
    path = _coated_bundle(tmp_path / "coated", gamma, albedo, 400.0)
    s = _stacked_under_clear_sky(path, lobe="materials").summary
    assert list(s["lobe_families"]) == ["phong", "ward", "ggx", "ggx-schlick"]
    assert s["lobe_families"]["ggx-schlick"]["weight"] > 0.95
    assert s["lobe_families"]["ggx-schlick"]["fresnel"] == "schlick-lobe"
    assert s["lobe_family"] == "ggx-schlick" and s["fresnel"] == "schlick-lobe"
    # each fit with a Fresnel model reports its strength k and albedo A: the
    # data were made at k = 1, A = 0.28 (k's prior is uniform on [0, 1]; it
    # read 0.97 [0.93, 1.00]; A in its place, near 0.28, would fail)
    k = s["lobe_families"]["ggx-schlick"]["fresnel_strength"]
    assert k["q95"] > 0.95 and k["median"] > 0.85
    assert "fresnel_strength" not in s["lobe_families"]["ggx"]
    assert abs(s["object"]["gamma_within_model"]["median"] - gamma) < 0.015
    lo, hi = s["object"]["gamma"]["hdi90"]
    assert lo <= gamma <= hi
    assert s["lobe_families"]["phong"]["gamma"]["median"] > gamma + 0.2


def test_materials_choose_their_own_fresnel_model(tmp_path):
    from conftest import make_synthetic_bundle

    path = make_synthetic_bundle(tmp_path / "b")
    with pytest.raises(ValueError, match="lobe 'materials' chooses each fit's Fresnel model"):
        estimate.estimate_bundle(path, lobe="materials", fresnel="schlick")


def test_lobe_families_need_per_frame_illumination(tmp_path):
    from conftest import make_synthetic_bundle

    path = make_synthetic_bundle(tmp_path / "b")
    with pytest.raises(ValueError, match="lobe 'ggx' needs per-frame illumination"):
        estimate.estimate_bundle(path, per_frame=False, lobe="ggx")
    with pytest.raises(ValueError, match="unknown lobe family"):
        estimate.estimate_bundle(path, lobe="cook")


def test_ggx_basis_sees_what_the_mesh_hides():
    # the L building's occlusion map (bayesgloss.visibility): the GGX basis
    # with it against the sum over the map's own 3 deg cells of f cos L with
    # the blocked cells' light (render's Occlusion terms). The two quadratures
    # differ by up to 3.6 % for alpha 0.5 (the convex facet's 0.8 % shows the
    # nodes' share); the basis without the map is off by 15 % to a factor of
    # 8 on the shaded facets, so 5 % tells them apart. A map that hides
    # nothing gives the convex basis bit for bit.
    from test_render import L_SUNS, _l_building, _oblique_views, _open_occlusion, render_sun

    from bayesgloss import sky, visibility

    facets, mesh = _l_building()
    sun = np.array([render_sun(*s) for s in L_SUNS])
    occ = visibility.occlusion(mesh, facets.normal, facets.center, sun)
    g = render.ViewGeometry(facets.normal, _oblique_views(facets.normal), facets.center)
    day = sky.daylight("gensky-clear", sun)
    alpha = 0.5
    albedo = float(lobes.ggx_normal_albedo(alpha))
    got = lobes.ggx_glossy_basis(g, day, [alpha], occlusion=occ)[:, 0]
    convex = lobes.ggx_glossy_basis(g, day, [alpha])[:, 0]
    quad = render.sphere_quadrature(occ.resolution)
    dirs, omega = quad
    terms = render._occlusion_terms(occ, day, "plane", 0.2, quad)
    arriving = render._arriving_radiance(day, None, dirs, None)  # (K, T)
    want = np.empty_like(got)
    for f in range(len(facets.normal)):
        seen = render._occluded(arriving, dirs, np.full(len(dirs), f), terms, occ.resolution)
        lobe = lobes.ggx_smith(dirs, g.view_direction[f], g.normal[f], alpha)
        want[f] = (lobe * np.maximum(dirs @ g.normal[f], 0.0) * omega) @ seen / albedo
    sun_dir, e_sun = render._sun_terms(day)
    f_sun = lobes.ggx_smith(sun_dir[None], g.view_direction[:, None], g.normal[:, None], alpha)
    want += f_sun * np.maximum(g.normal @ sun_dir.T, 0.0) * occ.sunlit_fraction * e_sun / albedo
    np.testing.assert_allclose(got, want, rtol=0.05)
    assert np.sum(np.max(np.abs(convex / want - 1), axis=1) > 0.15) >= 3
    open_ = _open_occlusion(len(facets.normal), len(sun))
    np.testing.assert_array_equal(
        lobes.ggx_glossy_basis(g, day, [0.1, 0.5], occlusion=open_),
        lobes.ggx_glossy_basis(g, day, [0.1, 0.5]),
    )


def test_report_names_the_stacked_families_weights():
    from bayesgloss import report

    summary = {
        "sky_families": {"families": {"auto": {"weight": 0.25}, "gensky-clear": {"weight": 0.75}}},
        "lobe_families": {
            "phong": {"weight": 0.0},
            "ward": {"weight": 0.9},
            "ggx": {"weight": 0.1},
        },
    }
    text = report._model_weights(summary)
    assert text.splitlines() == [
        "sky: auto 0.25, gensky-clear 0.75",
        "lobe: phong 0.00, ward 0.90, ggx 0.10",
    ]
    assert report._model_weights({}) == ""


def test_the_default_lobe_is_the_material_stack_where_it_applies():
    # the stack where the estimate is the one the deciding holdouts scored:
    # the joint model under the stacked sky families, no Fresnel model named,
    # no object mesh. Phong where the fixed-brightness estimator runs, where
    # a Fresnel model or a sky is named (--sky auto keeps its speed), and for
    # a mesh bundle (its faces' albedo is the stack there)
    from bayesgloss.lobe_families import DEFAULT_LOBE, default_lobe

    assert DEFAULT_LOBE == "materials"
    assert default_lobe(True, "none", False, "families") == "materials"
    assert default_lobe(False, "none", False, "families") == "phong"
    assert default_lobe(True, "radiance", False, "families") == "phong"
    assert default_lobe(True, "none", True, "families") == "phong"
    for sky in ("auto", "gensky-clear", "measured"):
        assert default_lobe(True, "none", False, sky) == "phong"


def test_the_default_estimate_fits_the_material_stack(tmp_path, monkeypatch):
    # estimate_bundle with no options reaches the material stack under the sky
    # families (the fits themselves caught before they run), and with a named
    # sky the single Phong fit
    from conftest import make_synthetic_bundle

    from bayesgloss import estimate, lobe_families

    class Caught(Exception):
        pass

    def catch_stack(*args, materials=False, **kwargs):
        raise Caught("materials" if materials else "families", kwargs.get("illumination"))

    monkeypatch.setattr(lobe_families, "fit_lobe_families", catch_stack)
    path = make_synthetic_bundle(tmp_path / "b", seed=3)
    with pytest.raises(Caught) as caught:
        estimate.estimate_bundle(path)
    assert caught.value.args[0] == "materials"
    res = estimate.estimate_bundle(
        path, illumination="gensky-clear", sampler_options={"max_steps": 100}
    )
    assert "lobe_families" not in res.summary


def test_the_rise_inside_the_lobe_takes_its_lobe():
    # --fresnel schlick-lobe without --lobe fits GGX, the lobe its rise is
    # inside; another lobe or a stack of lobes with it is refused up front
    from bayesgloss import lobe_families

    assert lobe_families.default_lobe(True, "schlick-lobe") == "ggx"
    assert lobe_families.check_lobe("ggx", "schlick-lobe", True) == ("ggx", False)
    for lobe in ("phong", "ward", "families"):
        with pytest.raises(ValueError, match="inside the 'ggx' lobe; lobe '"):
            lobe_families.check_lobe(lobe, "schlick-lobe", True)


def test_a_sunless_day_answers_with_phong_and_carries_the_other_lobes_spread(tmp_path):
    # a forward-model object (specularity 0.5, Phong) under gensky's
    # overcast sky, named, the lobe families stacked as the default stacks
    # them: Phong answers alone (flagged lobe-family-not-stacked), the other
    # families are fitted beside it and their stack-weighted spread is in the
    # model error (choices_sd, recomputed here from the summary's weights and
    # the families' own medians), and the object is flagged
    # gloss-not-identifiable exactly where their mixture is wider than 0.6
    from conftest import make_synthetic_bundle

    path = make_synthetic_bundle(tmp_path / "overcast", sky_model="gensky-overcast", noise=0.02)
    res = estimate.estimate_bundle(
        path,
        per_frame=True,
        illumination="gensky-overcast",
        lobe="materials",
        ground_shadow="none",
        jobs=2,
        sampler_options={"max_steps": 300},
    )
    s = res.summary
    fam = s["lobe_families"]
    assert list(fam) == ["phong", "ward", "ggx", "ggx-schlick"]
    assert "lobe-family-not-stacked" in s["object"]["flags"]
    assert s["object"]["gamma_within_model"]["median"] == fam["phong"]["gamma"]["median"]
    w = np.array([fam[k]["weight"] for k in fam])
    assert w.sum() == pytest.approx(1.0)
    med = np.array([fam[k]["gamma"]["median"] for k in fam])  # under the named sky
    sd = np.sqrt(np.sum(w * (med - np.sum(w * med)) ** 2))
    error = s["object"]["model_error"]
    assert error["choices_sd"] == pytest.approx(sd, rel=1e-6, abs=1e-9)
    assert error["sd"] ** 2 == pytest.approx(error["floor"] ** 2 + error["facets_sd"] ** 2 + sd**2)
    mixture = s["object"]["lobe_mixture_gamma"]
    wide = np.ptp(mixture["hdi90"]) > estimate.NOT_IDENTIFIABLE_WIDTH
    own_wide = np.ptp(s["object"]["gamma_within_model"]["hdi90"]) > estimate.NOT_IDENTIFIABLE_WIDTH
    assert ("gloss-not-identifiable" in s["object"]["flags"]) == (wide or own_wide)

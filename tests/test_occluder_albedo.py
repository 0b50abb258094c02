"""The albedo of a non-convex object's own faces, stacked (bayesgloss.occluder_albedo),
and the stacking of one option's choices (bayesgloss.stacking, bayesgloss.sky_families)."""

import warnings

import numpy as np
import pytest
import xarray as xr
from test_visibility import FACET_CENTERS, FACET_NORMALS, TIMES, tall_and_low

from bayesgloss import bundle as bd
from bayesgloss import estimate, joint_estimate, render, sky, sky_families, visibility
from bayesgloss.geometry import Facets
from bayesgloss.occluder_albedo import OCCLUDER_ALBEDOS

pytestmark = pytest.mark.filterwarnings("ignore:.*object_mesh:bayesgloss.bundle.BundleWarning")

#: The simulated material: gloss, Phong exponent, scale of its radiance.
GAMMA, EXPONENT, SCALE = 0.4, 60.0, 0.4


def _write(path, frames, obj):
    labels = np.zeros((16, 16), int)
    for k in range(4):
        labels[4 * k : 4 * k + 4, 2:14] = k + 1
    return bd.write_bundle(
        path,
        site={"latitude": 40.0, "longitude": 0.0, "elevation": 0.0},
        camera_position=[12.0, -4.0, 9.0],
        pixel_encoding="linear-radiance",
        frames=frames,
        times=TIMES,
        facets=Facets(np.arange(1, 5), FACET_NORMALS, FACET_CENTERS),
        labels=labels,
        frame_format="tiff",
        object_mesh=obj,
    ), labels


def simulated_mesh_bundle(tmp_path, albedo, noise=0.01, seed=0):
    """test_visibility's tall and low boxes, each facet's frames the forward
    model's radiance (Lambert + Phong, gensky's clear sky, the mesh's
    occlusion with its faces at ``albedo``) with relative noise."""
    obj = tmp_path / "boxes.obj"
    tall_and_low().export(obj)
    blank = [np.ones((16, 16, 3), np.float32)] * len(TIMES)
    path, labels = _write(tmp_path / "draft", blank, obj)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        b = bd.read_bundle(path)
    occ = visibility.bundle_occlusion(b).replace(occluder_reflectance=albedo)
    day = sky.daylight("gensky-clear", b.sun_direction, ground_reflectance=b.ground_albedo)
    fb = render.facet_bases(b.view_geometry(), day, [EXPONENT, EXPONENT * 1.0001], occlusion=occ)
    radiance = SCALE * ((1 - GAMMA) * fb.diffuse + GAMMA * fb.glossy[:, 0])  # (F, T)
    rng = np.random.default_rng(seed)
    radiance = radiance * np.exp(noise * rng.standard_normal(radiance.shape))
    table = np.concatenate([np.zeros((1, len(TIMES))), radiance])  # label 0: background
    frames = [
        np.repeat(table[labels, t][..., None], 3, -1).astype(np.float32) for t in range(len(TIMES))
    ]
    return _write(tmp_path / f"albedo-{albedo:g}", frames, obj)[0]


@pytest.fixture(scope="module")
def bright_faces(tmp_path_factory):
    return simulated_mesh_bundle(tmp_path_factory.mktemp("occ"), 0.8)


def test_occluder_albedo_changes_only_the_facets_that_see_the_mesh(bright_faces):
    # the option reaches the bases: the tall box's east face and the low top see
    # the other box's faces, and brighter faces light them more; the tall top
    # sees none of the mesh, and its data are the same at any albedo
    b = bd.read_bundle(bright_faces)
    curves = estimate.bundle_curves(b)
    y, usable, censored = estimate.observations(curves)
    keep = np.arange(4)
    got = {
        a: joint_estimate.joint_inputs(
            b, y, usable, censored, keep, "gensky-clear", occluder_albedo=a
        )[0]
        for a in (0.2, 0.8)
    }
    lo, hi = (got[a].diffuse for a in (0.2, 0.8))  # (component, facet, frame)
    np.testing.assert_array_equal(lo[:, 1], hi[:, 1])  # the tall top
    sees = [2, 0]  # the tall box's east face, the low top: 22 % and 6.5 % more
    assert np.all(np.nanmedian(hi.sum(0)[sees] / lo.sum(0)[sees], axis=-1) > 1.04)


@pytest.mark.long
def test_stacking_names_the_albedo_of_the_faces(bright_faces, tmp_path):
    # the forward model's own data, faces at 0.8, 1 % noise: the 0.8 fit must
    # take nearly all the weight (in trials the others were 40+ nats behind),
    # and the object's own interval hold the truth. Were the option not passed
    # to the fits, they would be one fit thrice, each weight about 1/3.
    res = estimate.estimate_bundle(  # stacked: the default where the bundle has a mesh
        bright_faces,
        illumination="gensky-clear",
        jobs=2,
        sampler_options={"max_steps": 500},
    )
    s = res.summary
    weights = {k: v["weight"] for k, v in s["occluder_albedos"].items()}
    assert list(weights) == [f"{a:g}" for a in OCCLUDER_ALBEDOS]
    assert weights["0.8"] > 0.9
    assert res.idata.posterior.attrs["occluder_albedo_most_weight"] == "0.8"
    assert s["occluder_albedo"] == 0.8
    g = s["object"]["gamma_within_model"]
    assert g["q05"] <= GAMMA <= g["q95"]


def test_stacked_occluder_albedo_and_lobe_families_are_one_or_the_other(bright_faces):
    with pytest.raises(ValueError, match="occluder albedo 'stacked' and lobe 'families'"):
        estimate.estimate_bundle(bright_faces, occluder_albedo="stacked", lobe="families")
    with pytest.raises(ValueError, match="unknown occluder albedo 'auto'"):
        estimate.estimate_bundle(bright_faces, occluder_albedo="auto")


def test_mixture_keeps_each_draws_variables_together():
    # two components in which n is gamma + 10 k (k the component): a draw of the
    # mixture must keep its gamma and n from one component draw, so n - gamma is
    # 0 or 10 and never anything else (mixing each variable with its own choice
    # of draws, as the families once did, gives -10 and differences of draws)
    rng = np.random.default_rng(4)
    comps = []
    for k in range(2):
        g = rng.uniform(size=(4, 100))
        comps.append(
            xr.Dataset(
                {
                    v: (("chain", "draw"), x)
                    for v, x in (("gamma_object", g), ("n_object", g + 10 * k))
                }
            )
        )
    target = type("Idata", (), {"posterior": comps[0].copy(deep=True)})()
    sky_families.mix_posteriors(target, comps, ("gamma_object", "n_object"), [0.3, 0.7], rng)
    diff = target.posterior["n_object"].values - target.posterior["gamma_object"].values
    assert np.all(np.isclose(diff, 0) | np.isclose(diff, 10))
    share = np.isclose(diff, 10).mean()
    # 400 draws at 0.7: the binomial sd is 0.023, so 0.1 is over 4 sd
    assert abs(share - 0.7) < 0.1


def test_report_names_the_faces_albedo_weights():
    from bayesgloss import report

    summary = {
        "occluder_albedos": {"0.2": {"weight": 0.9}, "0.5": {"weight": 0.1}, "0.8": {"weight": 0.0}}
    }
    assert report._model_weights(summary) == "faces' albedo: 0.2 0.90, 0.5 0.10, 0.8 0.00"


def test_several_bundles_carry_the_occluder_albedo_into_their_units(tmp_path, monkeypatch):
    # estimate over several bundles runs each as a unit of work: the option must
    # reach each unit's options and, through estimate_unit, estimate_bundle (a
    # unit function without the parameter fails on the key)
    from conftest import estimate_option_route

    route = estimate_option_route(
        monkeypatch, tmp_path, ["--occluder-albedo", "fixed"], "occluder_albedo"
    )
    assert route["units"] == ["fixed", "fixed"]
    assert not route["plain_units_have_key"]
    assert route["estimate_bundle"] == ["fixed", None, "fixed"]  # None: the library's default

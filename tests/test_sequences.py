"""Radiance test sequences: labels, configs, and one small bundle rendered for real."""

import dataclasses
import json

import numpy as np
import pytest

from bayesgloss import sequences
from bayesgloss.sequences import SequenceConfig


def _small(**kw):
    base = dict(
        name="small",
        n_rings=3,
        n_segments=8,
        image_size=40,
        solar_hours=(5.0, 8.0, 12.0, 16.0, 21.5),
    )
    base.update(kw)
    return SequenceConfig(**base)


def _inside_convex(points, poly):
    """Points (N, 2) inside a convex polygon (V, 2), either orientation."""
    edges = np.roll(poly, -1, axis=0) - poly
    rel = points[:, None, :] - poly[None, :, :]
    cross = edges[None, :, 0] * rel[..., 1] - edges[None, :, 1] * rel[..., 0]
    return np.all(cross >= -1e-9, axis=1) | np.all(cross <= 1e-9, axis=1)


@pytest.mark.radiance
def test_labels_are_wholly_inside_their_facet():
    # independent check: project each facet polygon through the same pinhole and
    # test every corner of every labelled pixel against it
    cfg = _small(view="SW", image_size=48)
    facets = cfg.facets()
    labels = sequences.label_image(cfg, facets)
    assert labels.shape == (48, 48)
    cam, fwd, right, up, tan_half = sequences._camera_frame(cfg, facets)
    n = cfg.image_size
    labelled = np.unique(labels[labels > 0])
    assert len(labelled) >= 10
    for fid in labelled:
        poly = facets.polygons[fid - 1]
        rel = poly - cam
        depth = rel @ fwd
        px = ((rel @ right) / depth / tan_half + 1) * n / 2  # image x in pixels
        py = (1 - (rel @ up) / depth / tan_half) * n / 2  # image y, downward
        rows, cols = np.nonzero(labels == fid)
        corners = np.concatenate(
            [np.column_stack([cols + dx, rows + dy]) for dx in (0, 1) for dy in (0, 1)]
        )
        assert np.all(_inside_convex(corners.astype(float), np.column_stack([px, py])))
    # and facets facing away from the camera never appear
    facing = np.einsum("ij,ij->i", facets.normal, cfg.camera_position() - facets.center) > 0
    assert np.all(np.isin(labelled, facets.ids[facing]))


def test_paper_configs_are_the_sixty():
    cfgs = sequences.paper_configs()
    assert len(cfgs) == 60
    assert len({c.key() for c in cfgs}) == 60
    assert len({c.name for c in cfgs}) == 60
    # 12 scenes (material x specularity x sky), each seen from the five views
    assert len({c.scene_key() for c in cfgs}) == 12
    hours = cfgs[0].solar_hours
    assert hours[0] == 4.0 and hours[-1] == 22.0 and len(hours) == 19


def test_config_round_trip_and_validation():
    cfg = _small(specularity=0.5, material="metal")
    again = SequenceConfig.from_dict(json.loads(json.dumps(cfg.to_dict())))
    assert again == cfg and again.key() == cfg.key()
    with pytest.raises(ValueError, match="latitude 95"):
        SequenceConfig(latitude=95)
    with pytest.raises(ValueError, match="sky 'cloudy'"):
        SequenceConfig(sky="cloudy")
    with pytest.raises(ValueError, match="unknown sequence config field.*colour_rgb"):
        SequenceConfig.from_dict({"colour_rgb": 1})


def test_frame_times_from_solar_hours_and_civil_times():
    cfg = _small()
    t = cfg.frame_times()
    assert str(t.tz) == "UTC" and len(t) == 5
    civil = _small(times=("2001-03-21T12:00:00+01:00", "2001-03-21T15:30:00+01:00"))
    np.testing.assert_array_equal(civil.frame_times().hour, [11, 14])


@pytest.fixture(scope="module")
def small_bundle(tmp_path_factory):
    from bayesgloss import sequences

    cache = tmp_path_factory.mktemp("bundles")
    cfg = _small(view="SW", image_size=64)
    (path,) = sequences.render_bundles([cfg], cache, jobs=2, progress=False)
    return cfg, path, cache


@pytest.mark.radiance
def test_small_bundle_renders_and_matches_the_forward_model(small_bundle):
    # a real Radiance rendering read back through the bundle reader agrees with
    # the forward model (same scene: ground plane, object shadow) for matt facets
    from bayesgloss import bundle, render, sky

    cfg, path, _ = small_bundle
    b = bundle.read_bundle(path)
    assert b.truth["specularity"] == 0.0 and b.pixel_encoding == "linear-radiance"
    curves = bundle.facet_curves(b)
    # 21:30 solar is after sunset at 40 N in June: reported, left out
    assert not curves.valid[:, -1].any()
    assert all("sun-below-horizon" in f for f in curves.flags[:, -1])
    g = b.view_geometry(occluder=cfg.facets())
    day = sky.daylight(cfg.sky, b.sun_direction, ground_reflectance=cfg.ground_reflectance)
    sky_part, sun_part = render.diffuse_components(g, day)
    model = 179 * cfg.colour * (sky_part + sun_part)  # matt plastic: colour x E / pi
    ok = curves.valid & (b.sun_direction[:, 2] > 0.03)
    with np.errstate(invalid="ignore"):  # NaN luminance where a facet has no pixels
        rel = np.abs(curves.luminance / model - 1)
    sunlit = ok & (sun_part > 0.2 * sky_part)
    assert sunlit.sum() >= 20
    # sunlit: measured <= 1.7 % on the paper set (irradiance cache -aa 0.1 and
    # pixel averaging); facets in their own shadow see ground that the object
    # also hides from the sky, which the model ignores: up to 9 % there
    assert rel[sunlit].max() < 0.03, rel[sunlit].max()
    assert rel[ok].max() < 0.10, rel[ok].max()


@pytest.mark.radiance
def test_render_cache_reuses_finished_bundles(small_bundle):
    import time

    cfg, path, cache = small_bundle
    stamp = (path / "sequence.json").stat().st_mtime_ns
    t0 = time.perf_counter()
    (again,) = sequences.render_bundles([cfg], cache, progress=False)
    assert again == path
    assert (path / "sequence.json").stat().st_mtime_ns == stamp
    assert time.perf_counter() - t0 < 5.0
    # a changed configuration is a different bundle
    other = dataclasses.replace(cfg, specularity=0.5)
    assert sequences._bundle_dir(cache, other) != path


@pytest.mark.radiance
def test_render_cli_bad_config_has_no_traceback(tmp_path):
    import subprocess
    import sys

    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"latitude": 95, "sky": "gensky-clear"}))
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "bayesgloss.cli",
            "render",
            "--config",
            str(bad),
            "--out",
            str(tmp_path / "o"),
        ],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr
    assert "latitude 95" in proc.stderr and "bad.json" in proc.stderr

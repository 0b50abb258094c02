"""The paper's peak-frame baseline."""

import numpy as np
import pytest

from bayesgloss import baseline, render, sun
from bayesgloss.render import ViewGeometry


def _paper_day():
    times = sun.times_at_local_solar_time("1996-06-21", np.arange(4.0, 23.0), 0.0)
    return sun.sun_direction_at(times, 40.0, 0.0, refraction=False)


def _geom(normals, cameras):
    n = np.asarray(normals, float)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    v = np.asarray(cameras, float)
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    return ViewGeometry(n, v)


def seen_idx(res):
    return np.flatnonzero(res.observed_peak >= 0)


def test_recovers_the_generating_gloss_of_its_own_model():
    # data made by the paper's own model: the true gamma is among the gammas whose
    # predicted peak frame equals the observed one, and the estimate reproduces it
    rng = np.random.default_rng(11)
    sun_dir = _paper_day()
    normals = rng.normal(size=(40, 3)) * [1, 1, 0.5] + [0, 0, 0.6]
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    views = normals + 0.8 * rng.normal(size=(40, 3))  # cameras in front of each facet
    g = _geom(normals, views)
    truth = rng.uniform(0, 1, 40)
    n = baseline.DEFAULT_EXPONENT
    obs = render.paper_point_sun(g, sun_dir, truth[:, None], n)
    valid = np.broadcast_to(sun_dir[:, 2] > 0, obs.shape)
    res = baseline.peak_frame_gloss(obs, valid, g, sun_dir)
    # the plateau reported holds the truth
    assert np.all(
        (res.interval[seen_idx(res), 0] <= truth[seen_idx(res)] + 0.005)
        & (truth[seen_idx(res)] <= res.interval[seen_idx(res), 1] + 0.005)
    )
    seen = res.observed_peak >= 0
    assert seen.sum() >= 30
    idx = np.round(truth * 100).astype(int)
    assert np.all(res.predicted_peak[idx[seen], np.flatnonzero(seen)] == res.observed_peak[seen])
    est_idx = np.round(res.gloss[seen] * 100).astype(int)
    assert np.all(res.predicted_peak[est_idx, np.flatnonzero(seen)] == res.observed_peak[seen])


def test_mirror_degenerate_geometry_is_flagged():
    # a horizontal facet seen from the north at the noon sun's elevation: its mirror
    # direction points south at that elevation, where the sun stands at noon, so
    # Lambert (peak at noon) and Phong peak together. Seen from the south, the
    # camera low (20 deg) the mirror points low to the north and the glossy peak
    # moves to dawn or dusk.
    sun_dir = _paper_day()
    noon_alt = np.radians(73.4)
    from_north = [0.0, np.cos(noon_alt), np.sin(noon_alt)]
    low = np.radians(20.0)
    from_south = [0.0, -np.cos(low), np.sin(low)]
    g = _geom([[0, 0, 1], [0, 0, 1]], [from_north, from_south])
    obs = render.paper_point_sun(g, sun_dir, 0.0, 20.0)
    res = baseline.peak_frame_gloss(obs, obs > 0, g, sun_dir, exponent=20.0)
    assert "mirror-degenerate" in res.flags[0]
    assert "mirror-degenerate" not in res.flags[1]
    assert res.predicted_peak[0, 0] == 8  # noon is frame 8 (04:00 + 8 h)


def test_object_mean_uses_only_facets_with_direct_sun():
    sun_dir = _paper_day()
    # facet 3 faces straight down: the sun never lights it
    g = _geom([[0, -1, 0.3], [1, 0, 0.5], [0, 0, -1]], [[0, -1, 0.2], [1, 0, 0.2], [0, -1, 0.2]])
    obs = render.paper_point_sun(g, sun_dir, np.array([[0.0], [1.0], [0.5]]), 20.0)
    obs[2] = np.linspace(1, 2, obs.shape[1])  # something observed, but no direct sun
    valid = np.broadcast_to(sun_dir[:, 2] > 0, obs.shape)
    res = baseline.peak_frame_gloss(obs, valid, g, sun_dir)
    assert "no-direct-sun" in res.flags[2]
    assert res.object_gloss == pytest.approx(np.mean(res.gloss[:2]))
    j = res.to_json()
    assert set(j) == {"object", "facets"} and j["object"]["gamma"] == pytest.approx(
        res.object_gloss
    )
    assert [f["id"] for f in j["facets"]] == [1, 2, 3] and "flags" in j["facets"][0]


def test_no_valid_frames_and_bad_input():
    sun_dir = _paper_day()
    g = _geom([[0, -1, 0.3]], [[0, -1, 0.2]])
    obs = np.ones((1, len(sun_dir)))
    res = baseline.peak_frame_gloss(obs, np.zeros_like(obs, bool), g, sun_dir)
    assert np.isnan(res.gloss[0]) and res.flags[0] == ["no-valid-frames"]
    assert np.isnan(res.object_gloss)
    with pytest.raises(ValueError, match="gloss_grid"):
        baseline.peak_frame_gloss(obs, obs > 0, g, sun_dir, gloss_grid=[0.0, 1.5])
    with pytest.raises(ValueError, match=r"\(F, T\)"):
        baseline.peak_frame_gloss(obs[:, :5], obs[:, :5] > 0, g, sun_dir)

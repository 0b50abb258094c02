"""What a joint run reports of its own convergence (bayesgloss.joint_estimate)."""

from types import SimpleNamespace

import numpy as np
import pytest

from bayesgloss import cli
from bayesgloss.joint_estimate import frame_convergence, object_convergence


def _run(t: int, bad_sun=(), bad_sky=(), gamma_rhat=1.002):
    # the run's statistics: gamma's first, then each frame's log a, then log b
    rhat = np.full(1 + 2 * t, 1.001)
    ess = np.full(1 + 2 * t, 2000.0)
    rhat[0] = gamma_rhat
    for k in bad_sun:
        ess[1 + k] = 150.0  # bulk ESS short of 400
    for k in bad_sky:
        rhat[1 + t + k] = 1.03
    return SimpleNamespace(rhat=rhat, ess_bulk=ess, ess_tail=ess.copy())


def test_frames_short_of_the_rule_are_named_by_their_index_in_the_bundle():
    # 4 frames used of a bundle of 6 (frames 0 and 5 before sunrise, after
    # sunset); the run's frame 1 (bundle frame 2) fails on its sun, its frame
    # 3 (bundle frame 4) on its sky. Reading the statistics in the wrong order
    # (sky before sun, or gamma taken for a frame) names other frames
    used = np.array([False, True, True, True, True, False])
    run = _run(4, bad_sun=[1], bad_sky=[3])
    np.testing.assert_array_equal(frame_convergence(run, 4), [True, False, True, False])
    c = object_convergence(run, used)
    assert c["frames_not_converged"] == [2, 4]
    assert c["gamma"]["meets_rule"] and c["gamma"]["rhat"] == 1.002
    line = cli._convergence_line(c)
    assert "meets the rule" in line and "frames 2, 4" in line


def test_gloss_short_of_the_rule_is_said_so():
    used = np.ones(3, bool)
    c = object_convergence(_run(3, gamma_rhat=1.02), used)
    assert not c["gamma"]["meets_rule"] and c["frames_not_converged"] == []
    line = cli._convergence_line(c)
    assert "short of the rule" in line and "frame" not in line


def test_clipped_entries_enter_the_joint_model_as_bounds_only_where_asked(tmp_path):
    # a bundle whose brightest entries clip (16-bit gamma:2.2 codes, the top
    # code at 25 W sr^-1 m^-2, below every facet's sky-mirror highlight):
    # "drop" leaves them out of the joint model's data, "likelihood" keeps
    # them at their bound, marked censored; the frames used are the same
    from conftest import make_synthetic_bundle

    from bayesgloss import bundle as bundle_io
    from bayesgloss import estimate
    from bayesgloss.joint_estimate import joint_inputs

    path = make_synthetic_bundle(
        tmp_path / "b", specularity=0.5, encoding="gamma:2.2", bits=16, exposure=25.0
    )
    b = bundle_io.read_bundle(path)
    y, usable, cens = estimate.observations(estimate.bundle_curves(b))
    keep = bundle_io.usable_facets(b, usable, estimate.MIN_FRAMES, cens)
    dropped, used_d, _ = joint_inputs(b, y, usable, cens, keep, "gensky-clear")
    kept, used, _ = joint_inputs(b, y, usable, cens, keep, "gensky-clear", clipped="likelihood")
    np.testing.assert_array_equal(used_d, used)
    c = cens[keep][:, used]
    assert dropped.censored is None and c.sum() >= 20, c.sum()
    np.testing.assert_array_equal(kept.censored, c)
    np.testing.assert_array_equal(kept.valid, dropped.valid | c)
    np.testing.assert_allclose(kept.y[c], y[keep][:, used][c])  # the bound
    assert not np.any(dropped.valid & c)


def test_clipped_reaches_the_estimate_and_its_units(tmp_path, monkeypatch):
    # --clipped must reach each unit's options (absent where not given:
    # earlier runs keep their keys) and, through estimate_unit, estimate_bundle
    from conftest import estimate_option_route

    route = estimate_option_route(monkeypatch, tmp_path, ["--clipped", "likelihood"], "clipped")
    assert route["units"] == ["likelihood", "likelihood"]
    assert not route["plain_units_have_key"]
    assert route["estimate_bundle"] == ["likelihood", None, "likelihood"]


def test_an_unknown_clipped_treatment_is_refused_before_any_fit(tmp_path):
    from conftest import make_synthetic_bundle

    from bayesgloss import estimate

    path = make_synthetic_bundle(tmp_path / "b", seed=2)
    with pytest.raises(ValueError, match="clipped entries: unknown treatment 'keep'"):
        estimate.estimate_bundle(path, clipped="keep")


def test_sun_flags_flag_an_object_whose_frames_cannot_tell_a_hidden_from_a_clear_sun():
    # a frame's sun is not identified where its 90 % interval runs from below
    # 0.1 to above 0.5 of the model's: draws uniform on [0, 1.2] (5-95 %:
    # 0.06-1.14) are; a clear sun N(1, 0.05), a hidden one on [0, 0.05] and
    # a dimmed one on [0.2, 1.2] are not. More than half such frames flag
    # the object; exactly half does not
    import xarray as xr

    from bayesgloss.joint_estimate import sun_flags

    rng = np.random.default_rng(63)
    draws = {
        "unknown": rng.uniform(0.0, 1.2, (2, 500)),
        "clear": rng.normal(1.0, 0.05, (2, 500)),
        "hidden": rng.uniform(0.0, 0.05, (2, 500)),
        "dimmed": rng.uniform(0.2, 1.2, (2, 500)),
    }

    def idata(*frames):
        sun = np.stack([draws[f] for f in frames], axis=-1)
        return SimpleNamespace(posterior=xr.Dataset({"sun": (("chain", "draw", "frame"), sun)}))

    share, flags = sun_flags(idata("unknown", "unknown", "unknown", "clear"))
    assert share == 0.75 and flags == ["sun-not-identifiable"]
    share, flags = sun_flags(idata("unknown", "unknown", "hidden", "dimmed"))
    assert share == 0.5 and flags == []
    assert sun_flags(idata("clear", "hidden", "dimmed")) == (0.0, [])
    assert sun_flags(SimpleNamespace(posterior=xr.Dataset())) == (None, [])

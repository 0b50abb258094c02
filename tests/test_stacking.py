"""One fit per choice of a model's part, stacked (bayesgloss.stacking)."""

from types import SimpleNamespace

import numpy as np
import pytest

from bayesgloss import estimate, sky_families, stacking


def _fake_fits(monkeypatch, log_density: dict, spread: float):
    """stacking's joint_fit replaced by fits whose entries have log density
    ``log_density[value]`` spread over the draws with sd ``spread`` (sd 5:
    most Pareto k far above 0.7, as on an object of 1-3 facets; 0.05: all
    low), each fit's gamma its own (0.1 x its place in the calls)."""
    import arviz as az

    calls = []

    def fake_fit(b, curves, y, usable, censored, keep, name, seed, options, *rest, **kw):
        calls.append(options["lobe_family"])
        ll = np.full((2, 50, 3, 4), log_density.get(options["lobe_family"], -6.0))
        ll = ll + spread * np.random.default_rng(11).standard_normal(ll.shape)
        gamma = np.full((2, 50), 0.1 * len(calls))
        posterior = {"gamma_object": gamma, "n_object": np.ones((2, 50))}
        idata = az.from_dict(posterior=posterior, log_likelihood={"y": ll})
        return idata, SimpleNamespace(seconds=1.0, facets=SimpleNamespace(seconds=0.0)), None

    monkeypatch.setattr(stacking, "joint_fit", fake_fit)
    monkeypatch.setattr(stacking, "add_facet_posteriors", lambda *args: None)
    return calls


def _stack(**kw):
    return stacking.fit_stacked(
        *(None,) * 6,
        "gensky-clear",
        0,
        {},
        option="lobe_family",
        choices={"phong": "phong", "ward": "ward", "ggx": "ggx"},
        default="phong",
        attribute="lobe_family",
        **kw,
    )


def test_a_sky_not_identified_leaves_the_part_unstacked(monkeypatch):
    # where the sky families got equal weights (their PSIS-LOO unreliable),
    # the other lobes are not fitted under one sky: the answer is the
    # default lobe's sky mixture, recorded as not stacked (stop 35: a box's
    # answer narrowed to one sky's fit of the faces' albedo while flagged
    # sky-family-not-identifiable). Where the sky was identified, every lobe
    # is fitted under the most-weighted family and stacked
    import arviz as az

    def fake_families(*args, **kwargs):
        gamma = np.linspace(0.1, 0.9, 100).reshape(2, 50)  # the sky mixture's spread
        post = {"gamma_object": gamma, "n_object": np.ones((2, 50))}
        ll = np.full((2, 50, 3, 4), -6.0)
        idata = az.from_dict(posterior=post, log_likelihood={"y": ll})
        idata.posterior.attrs.update(
            sky_family_weights="{}",
            sky_family_most_weight="gensky-clear",
            sky_family_equal_weights=int(equal),
        )
        samples = SimpleNamespace(seconds=1.0, facets=SimpleNamespace(seconds=0.0))
        info = {"most_weight": "gensky-clear", "equal_weights": equal, "seconds": 4.0}
        return idata, samples, None, info

    monkeypatch.setattr(sky_families, "fit_families", fake_families)
    calls = _fake_fits(monkeypatch, {"ward": -1.0}, spread=0.05)
    args = (*(None,) * 6, "families", 0, {})
    kw = dict(option="lobe_family", default="phong", attribute="lobe_family")
    choices = {"phong": "phong", "ward": "ward", "ggx": "ggx"}
    equal = True
    alone = stacking.fit_stacked(*args, choices=choices, **kw)
    assert calls == [] and list(alone.own) == ["phong"]
    assert alone.record("k", {}, "b", alone.best)["stacked"] is False
    assert alone.idata.posterior.attrs["lobe_family_stacked"] == 0
    gamma = alone.idata.posterior["gamma_object"].values
    assert np.ptp(gamma) > 0.7  # the sky mixture's width kept
    equal = False
    stacked = stacking.fit_stacked(*args, choices=choices, **kw)
    assert calls == ["ward", "ggx"] and stacked.best == "ward"
    assert stacked.record("k", {}, "b", stacked.best)["stacked"] is True


def test_the_sky_options_reach_the_sky_families_under_a_second_stack(tmp_path, monkeypatch):
    # --lobe families (and the stacked occluder albedo, the default with a
    # mesh) stacks the sky families first: --unreliable-loo and
    # --overcast-variants must reach that stack (stop 35: they were dropped)
    from conftest import make_synthetic_bundle

    class Called(Exception):
        pass

    def spy(*args, **kwargs):
        raise Called(kwargs)

    monkeypatch.setattr(sky_families, "fit_families", spy)
    path = make_synthetic_bundle(tmp_path / "b", seed=1)
    for lobe in (None, "families"):
        with pytest.raises(Called) as got:
            estimate.estimate_bundle(
                path, lobe=lobe, unreliable_loo="stack", overcast_variants=True
            )
        assert got.value.args[0]["unreliable_loo"] == "stack", lobe
        assert got.value.args[0]["overcast_variants"] is True, lobe

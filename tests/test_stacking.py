"""One fit per choice of a model's part, stacked (bayesgloss.stacking)."""

import json
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
        fits = {"gensky-clear": (idata, samples, None)}
        return idata, samples, None, info | {"fits": fits, "posteriors": {}}

    monkeypatch.setattr(sky_families, "fit_families", fake_families)
    calls = _fake_fits(monkeypatch, {"ward": -1.0}, spread=0.05)
    args = (*(None,) * 6, "families", 0, {})
    kw = dict(option="lobe_family", default="phong", attribute="lobe_family")
    choices = {"phong": "phong", "ward": "ward", "ggx": "ggx"}
    equal = True
    alone = stacking.fit_stacked(*args, choices=choices, unidentified_sky="default-alone", **kw)
    assert calls == [] and list(alone.own) == ["phong"]
    assert alone.record("k", {}, "b", alone.best)["stacked"] is False
    assert alone.idata.posterior.attrs["lobe_family_stacked"] == 0
    gamma = alone.idata.posterior["gamma_object"].values
    assert np.ptp(gamma) > 0.7  # the sky mixture's width kept
    equal = False
    stacked = stacking.fit_stacked(*args, choices=choices, **kw)
    assert calls == ["ward", "ggx"] and stacked.best == "ward"
    assert stacked.record("k", {}, "b", stacked.best)["stacked"] is True
    with pytest.raises(ValueError, match="unknown unidentified_sky"):
        stacking.fit_stacked(*args, choices=choices, unidentified_sky="each", **kw)


def test_a_sky_not_identified_stacks_every_lobe_under_each_tied_sky(monkeypatch):
    # the default since stop 60's candidate (unidentified_sky="every-near-sky"):
    # where the sky families share the weight (two tied, A and B; C ruled
    # out), every other lobe is fitted under A and under B, not C; within
    # each sky the lobes' PSIS-LOO is as unreliable (log densities with sd 5
    # over the draws: Pareto k far above 0.7), so they share its weight; the
    # answer mixes the six (sky, lobe) fits at 1/6 each: gammas 0.1-0.6,
    # each in about 100 of 600 draws (at p = 1/6 fewer than 60 is a 1e-5 event)
    import arviz as az

    gamma_of = {("phong", "A"): 0.1, ("phong", "B"): 0.2, ("ward", "A"): 0.3}
    gamma_of |= {("ward", "B"): 0.4, ("ggx", "A"): 0.5, ("ggx", "B"): 0.6}
    shape = (2, 300)
    ll = 5 * np.random.default_rng(11).standard_normal((*shape, 3, 4)) - 6.0

    def idata_of(gamma):
        post = {"gamma_object": np.full(shape, gamma), "n_object": np.ones(shape)}
        return az.from_dict(posterior=post, log_likelihood={"y": ll})

    samples = SimpleNamespace(seconds=1.0, facets=SimpleNamespace(seconds=0.0))

    def fake_families(*args, **kwargs):
        assert kwargs["keep_fits"] is True
        fits = {sky: (idata_of(gamma_of["phong", sky]), samples, None) for sky in "AB"}
        fits["C"] = (idata_of(0.9), samples, None)
        mixture = idata_of(0.15)  # the default lobe's sky mixture, the idata returned
        mixture.posterior.attrs.update(
            sky_family_weights=json.dumps({"A": 0.5, "B": 0.5, "C": 0.0}),
            sky_family_most_weight="A",
            sky_family_equal_weights=1,
        )
        info = {"most_weight": "A", "equal_weights": True, "seconds": 3.0}
        posteriors = {sky: fit[0].posterior for sky, fit in fits.items()}
        return mixture, samples, None, info | {"fits": fits, "posteriors": posteriors}

    calls = []

    def fake_fit(b, curves, y, usable, censored, keep, sky, seed, options, *rest, **kw):
        calls.append((options["lobe_family"], sky))
        return idata_of(gamma_of[options["lobe_family"], sky]), samples, None

    monkeypatch.setattr(sky_families, "fit_families", fake_families)
    monkeypatch.setattr(stacking, "joint_fit", fake_fit)
    monkeypatch.setattr(stacking, "add_facet_posteriors", lambda *args: None)
    choices = {"phong": "phong", "ward": "ward", "ggx": "ggx"}
    kw = dict(option="lobe_family", default="phong", attribute="lobe_family", ties="spread")
    got = stacking.fit_stacked(*(None,) * 6, "families", 0, {}, choices=choices, **kw)
    assert sorted(calls) == sorted([(lobe, sky) for lobe in ("ward", "ggx") for sky in "AB"])
    weights = json.loads(got.idata.posterior.attrs["lobe_family_weights"])
    assert weights == pytest.approx({"phong": 1 / 3, "ward": 1 / 3, "ggx": 1 / 3})
    assert got.scores["ward"]["weight_by_sky"] == pytest.approx({"A": 1 / 6, "B": 1 / 6})
    assert got.record("k", {}, "b", got.best)["stacked"] is True
    assert got.idata.posterior.attrs["lobe_family_stacked"] == 1
    assert got.idata.posterior.attrs["sky_family_weights"] == json.dumps(
        {"A": 0.5, "B": 0.5, "C": 0.0}
    )  # the sky's record kept, whichever lobe's fit carries the answer
    gamma = np.round(got.idata.posterior["gamma_object"].values.ravel(), 6)
    for value in gamma_of.values():
        assert np.sum(gamma == value) >= 60, value
    assert not np.any(np.isin(gamma, [0.15, 0.9]))  # not the old mixture, not the ruled-out sky
    # each lobe's own answer is its fits mixed over the tied skies
    ward = np.round(got.own["ward"]["gamma_object"].values.ravel(), 6)
    assert set(ward) == {0.3, 0.4}


def test_a_sunless_day_leaves_the_lobes_unstacked(monkeypatch):
    # with sunless_default (the lobe families'), a day whose most-weighted
    # sky family is an overcast one, or a named overcast sky, is answered by
    # the default lobe alone: no other lobe is fitted (holdout 8's vs18, a
    # true 0 read 0.054 by the lobe stack and 0.012 by Phong). Without it,
    # and on a sun-lit day with it, every lobe is fitted and stacked
    import arviz as az

    def fake_families(*args, **kwargs):
        post = {"gamma_object": np.full((2, 50), 0.2), "n_object": np.ones((2, 50))}
        idata = az.from_dict(posterior=post, log_likelihood={"y": np.full((2, 50, 3, 4), -6.0)})
        idata.posterior.attrs.update(
            sky_family_weights="{}", sky_family_most_weight=sky, sky_family_equal_weights=0
        )
        samples = SimpleNamespace(seconds=1.0, facets=SimpleNamespace(seconds=0.0))
        info = {"most_weight": sky, "equal_weights": False, "seconds": 1.0}
        return idata, samples, None, info | {"fits": {}, "posteriors": {}}

    monkeypatch.setattr(sky_families, "fit_families", fake_families)
    calls = _fake_fits(monkeypatch, {"ward": -1.0}, spread=0.05)
    kw = dict(option="lobe_family", default="phong", attribute="lobe_family")
    choices = {"phong": "phong", "ward": "ward", "ggx": "ggx"}
    args = (*(None,) * 6, "families", 0, {})
    sky = "gensky-overcast"
    alone = stacking.fit_stacked(*args, choices=choices, sunless_default=True, **kw)
    assert calls == [] and list(alone.own) == ["phong"]
    assert alone.record("k", {}, "b", alone.best)["stacked"] is False
    stacked = stacking.fit_stacked(*args, choices=choices, **kw)  # the guard off
    assert calls == ["ward", "ggx"] and stacked.best == "ward"
    calls.clear()
    sky = "gensky-clear"
    sunlit = stacking.fit_stacked(*args, choices=choices, sunless_default=True, **kw)
    assert calls == ["ward", "ggx"] and len(sunlit.own) == 3
    calls.clear()
    named = (*(None,) * 6, "gensky-overcast", 0, {})
    alone = stacking.fit_stacked(*named, choices=choices, sunless_default=True, **kw)
    assert calls == ["phong"] and list(alone.own) == ["phong"]


def test_a_sunless_day_fits_the_other_lobes_beside_the_default_that_answers(monkeypatch):
    # with sunless_spread, a sunless day's other lobes are fitted beside
    # Phong under the day's sky and weighed as a stack would (here Ward
    # ahead by 5 nats a draw-entry, so alone), but the answer stays Phong's
    # own draws (0.2, the sky mixture's) and the record says not stacked;
    # the spread carries each lobe's own posterior under the day's sky
    import arviz as az

    sky = "gensky-overcast"

    def fake_families(*args, **kwargs):
        post = {"gamma_object": np.full((2, 50), 0.2), "n_object": np.ones((2, 50))}
        idata = az.from_dict(posterior=post, log_likelihood={"y": np.full((2, 50, 3, 4), -6.0)})
        idata.posterior.attrs.update(
            sky_family_weights="{}", sky_family_most_weight=sky, sky_family_equal_weights=0
        )
        under_sky = az.from_dict(posterior={"gamma_object": np.full((2, 50), 0.25)}).posterior
        samples = SimpleNamespace(seconds=1.0, facets=SimpleNamespace(seconds=0.0))
        info = {"most_weight": sky, "equal_weights": False, "seconds": 1.0}
        return idata, samples, None, info | {"fits": {}, "posteriors": {sky: under_sky}}

    monkeypatch.setattr(sky_families, "fit_families", fake_families)
    calls = _fake_fits(monkeypatch, {"ward": -1.0}, spread=0.05)
    kw = dict(option="lobe_family", default="phong", attribute="lobe_family")
    choices = {"phong": "phong", "ward": "ward", "ggx": "ggx"}
    args = (*(None,) * 6, "families", 0, {})
    out = stacking.fit_stacked(
        *args, choices=choices, sunless_default=True, sunless_spread=True, **kw
    )
    assert calls == ["ward", "ggx"] and out.best == "phong"
    assert np.all(out.idata.posterior["gamma_object"].values == 0.2)
    assert out.record("k", {}, "b", out.best)["stacked"] is False
    assert out.beside()["weights"]["ward"] == pytest.approx(1.0)
    assert float(out.beside()["own"]["phong"]["gamma_object"].mean()) == 0.25  # under the day's sky
    assert float(out.beside()["own"]["ggx"]["gamma_object"].mean()) == pytest.approx(0.2)
    # on a sun-lit day nothing is fitted beside: the lobes are stacked
    calls.clear()
    sky = "gensky-clear"
    sunlit = stacking.fit_stacked(
        *args, choices=choices, sunless_default=True, sunless_spread=True, **kw
    )
    assert calls == ["ward", "ggx"] and sunlit.beside() is None and sunlit.best == "ward"
    # a named overcast sky: the others fitted under it beside the default
    calls.clear()
    named = (*(None,) * 6, "gensky-overcast", 0, {})
    alone = stacking.fit_stacked(
        *named, choices=choices, sunless_default=True, sunless_spread=True, **kw
    )
    assert calls == ["phong", "ward", "ggx"] and alone.best == "phong"
    # the default first, then the others in the choices' order: the order the
    # spread's mixture draws from (model_error.choice_spread)
    assert list(alone.beside()["own"]) == ["phong", "ward", "ggx"]
    assert list(alone.beside()["weights"]) == ["phong", "ward", "ggx"]


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
    # not named: None reaches the stack, which fits the overcast shapes (the
    # default since holdout 21; test_sky_families); --no-overcast-variants: False
    for given, sent in ((None, None), (False, False)):
        with pytest.raises(Called) as got:
            estimate.estimate_bundle(path, overcast_variants=given)
        assert got.value.args[0]["overcast_variants"] is sent, given


def test_fits_tied_with_the_best_share_its_weight():
    # Mitsuba holdout 1, ms16 (stop 40): four equally predictive lobe fits of
    # an overcast day, Ward given weight 1.00 by the optimiser on an elpd
    # difference of 0.0; spread, the four share it. A fit 4 or more below
    # the best keeps its own stacking weight (ms05: the coating's 0.36)
    def scores(weight, diff):
        rows = zip("abcd", weight, diff, strict=True)
        return {k: {"weight": w, "elpd_diff": d} for k, w, d in rows}

    ms16 = stacking.spread_tied_weights(scores([0.0, 1.0, 0.0, 0.0], [0.24, 0.0, 0.11, 0.61]))
    assert [ms16[k]["weight"] for k in "abcd"] == [0.25] * 4
    assert ms16["b"]["stacking_weight"] == 1.0 and all(ms16[k]["tied"] for k in "abcd")
    ms05 = stacking.spread_tied_weights(scores([0.0, 0.64, 0.0, 0.36], [3.9, 0.0, 96.0, 71.0]))
    assert [ms05[k]["weight"] for k in "abcd"] == pytest.approx([0.32, 0.32, 0.0, 0.36])
    assert not ms05["d"]["tied"] and "stacking_weight" not in ms05["d"]
    clear = scores([0.0, 1.0, 0.0, 0.0], [200.0, 0.0, 131.0, 4.0])
    assert stacking.spread_tied_weights(clear) is clear  # one fit tied with itself


def test_a_spread_stack_carries_every_tied_fits_gamma(monkeypatch):
    # three fits whose log densities differ by 0.005-0.01 an entry (elpd
    # 0.06-0.12 apart) and gammas 0.1, 0.2, 0.3: stacking alone gives the
    # first all the weight; spread, the mixture's draws hold each in a third
    # (100 draws picked by weight: at p = 1/3 fewer than 20 is a 0.2 %
    # event); a clear winner (5 an entry above the others, 60 in elpd)
    # keeps weight 1
    calls = _fake_fits(monkeypatch, {"ward": -6.01, "ggx": -6.005}, spread=0.05)
    alone = _stack()
    assert alone.scores["phong"]["weight"] > 0.99
    calls.clear()
    tied = _stack(ties="spread")
    assert calls == ["phong", "ward", "ggx"]
    weights = json.loads(tied.idata.posterior.attrs["lobe_family_weights"])
    assert weights == pytest.approx({"phong": 1 / 3, "ward": 1 / 3, "ggx": 1 / 3})
    gamma = np.round(tied.idata.posterior["gamma_object"].values.ravel(), 6)
    for value in (0.1, 0.2, 0.3):
        assert np.sum(gamma == value) >= 20, value
    _fake_fits(monkeypatch, {"ward": -1.0}, spread=0.05)
    clear = _stack(ties="spread")
    assert clear.best == "ward" and clear.scores["ward"]["weight"] == pytest.approx(1.0)
    with pytest.raises(ValueError, match="unknown ties"):
        _stack(ties="even")


def test_the_lobe_stacks_spread_ties(monkeypatch):
    from bayesgloss import lobe_families

    class Called(Exception):
        pass

    def spy(*args, **kwargs):
        raise Called(kwargs)

    monkeypatch.setattr(lobe_families, "fit_stacked", spy)
    for materials in (False, True):
        with pytest.raises(Called) as got:
            lobe_families.fit_lobe_families(*(None,) * 6, "families", 0, {}, materials=materials)
        assert got.value.args[0]["ties"] == "spread"

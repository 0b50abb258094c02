"""The day's sky family stacked by PSIS-LOO (``estimate --sky families``)."""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pytest

from bayesgloss import estimate, sky_families


def test_mixture_draws_follow_the_weights():
    # two components of constant value: the share of each in every chain is
    # multinomial with the weights (s = 4000: sd of a share 0.007, so 0.03 is
    # 4 sd); a zero weight gives none of its draws
    rng = np.random.default_rng(3)
    a, b = np.zeros((4, 4000)), np.ones((4, 4000))
    mixed = sky_families.mixture_draws([a, b], [0.3, 0.7], rng)
    assert mixed.shape == (4, 4000)
    np.testing.assert_allclose(mixed.mean(axis=1), 0.7, atol=0.03)
    assert np.all(sky_families.mixture_draws([a, b], [0.0, 1.0], rng) == 1.0)


def test_loo_stacking_prefers_the_model_that_predicts(tmp_path):
    # fits of the same 60 entries: one whose draws of the log density are at
    # the data's, one 3 nats worse per entry; stacking puts its weight on the first
    import arviz as az

    rng = np.random.default_rng(4)
    good = -0.5 - 0.05 * rng.standard_normal((2, 200, 6, 10))
    bad = good - 3.0
    idatas = {
        name: az.from_dict(posterior={"x": np.zeros((2, 200))}, log_likelihood={"y": ll})
        for name, ll in (("good", good), ("bad", bad))
    }
    scores = sky_families.loo_stacking_weights(idatas)
    assert scores["good"]["weight"] > 0.99
    assert scores["good"]["elpd_loo"] - scores["bad"]["elpd_loo"] == pytest.approx(180, rel=0.01)


def _sky_families_of_a_forward_model_day(path, sky_model, **options):
    """The sky families' stack (Phong's lobe alone: the lobe stack is
    test_lobes') of a small bundle made at ``path`` by the forward model
    under ``sky_model``, on two worker processes (estimate's default
    --jobs): (bundle path, estimate)."""
    from conftest import make_synthetic_bundle

    path = make_synthetic_bundle(path, specularity=0.5, noise=0.01, seed=6, sky_model=sky_model)
    res = estimate.estimate_bundle(
        path,
        per_frame=True,
        illumination="families",
        lobe="phong",
        jobs=2,
        sampler_options={"max_steps": 400},
        **options,
    )
    return path, res


@pytest.mark.long
def test_overcast_day_is_told_overcast(tmp_path, capsys):
    # a small bundle made by the forward model under gensky's overcast sky: of
    # the six candidates the overcast fit must carry the weight (a wrong
    # family on an overcast day read gamma 0.008 for a true 0.88 on a
    # Radiance render, stop 27, and the per-frame mixture 1.00), and the
    # object's answer is its mixture. Two worker processes (estimate's
    # default --jobs), the weights kept in the result folder and shown
    from bayesgloss import bundle as bundle_io
    from bayesgloss import cli, report

    # Since stop 57 the other CIE overcast shapes are fitted where it wins and
    # share the overcast group's weight (the gradation is rarely told)
    path, res = _sky_families_of_a_forward_model_day(tmp_path / "b", "gensky-overcast")
    fam = res.summary["sky_families"]
    every = {*sky_families.FAMILIES, *sky_families.PEREZ_FAMILIES}
    assert set(fam["families"]) == every | set(sky_families.OVERCAST_VARIANTS)
    assert fam["most_weight"] in sky_families.OVERCAST_GROUP
    weights = {name: f["weight"] for name, f in fam["families"].items()}
    assert sum(weights.values()) == pytest.approx(1.0)
    assert sum(weights[name] for name in sky_families.OVERCAST_GROUP) > 0.9, fam
    # the shapes brightening toward the hidden sun (CIE 2, 4) are told apart
    assert weights["cie-2"] + weights["cie-4"] < 0.05, fam
    assert res.summary["sampler"]["model"].startswith("joint, one fit per sky family")
    gamma = res.idata.posterior["gamma_object"].values
    own = res.summary["object"]["gamma_within_model"]  # the stack's own, its error aside
    assert np.median(gamma) == pytest.approx(own["median"])
    # each facet's own posterior given the light: of the most-weighted fit only
    assert res.idata.posterior["gamma"].shape[-1] == res.summary["object"]["facets"]
    out = estimate.write_result(tmp_path / "out", res)
    back = estimate.read_result(out)
    stored = json.loads(back.idata.posterior.attrs["sky_family_weights"])
    assert stored == pytest.approx(weights)
    cli._print_estimate("b", res.summary)
    assert "sky families (stacking weight): auto" in capsys.readouterr().out
    png = report.posterior_report(bundle_io.read_bundle(path), back, path=tmp_path / "r.png")
    assert png.stat().st_size > 10_000


def test_stacking_weights_of_two_complementary_models():
    # model A predicts the first half of the entries (log density 0 against
    # -5), model B the second: the stacking optimum is 1/2 each, which neither
    # picking the best nor LOO weights by total elpd (A and B tie) would show
    # as a mixture; a third model worse everywhere gets nothing
    import arviz as az

    lp = np.full((40, 3), -5.0)
    lp[:20, 0] = 0.0
    lp[20:, 1] = 0.0
    lp[:, 2] = -8.0
    draws = np.broadcast_to(lp.T.reshape(3, 1, 1, 4, 10), (3, 2, 100, 4, 10))
    idatas = {
        name: az.from_dict(posterior={"x": np.zeros((2, 100))}, log_likelihood={"y": ll})
        for name, ll in zip("ABC", draws, strict=True)
    }
    scores = sky_families.loo_stacking_weights(idatas)
    w = [scores[name]["weight"] for name in "ABC"]
    np.testing.assert_allclose(w, [0.5, 0.5, 0.0], atol=1e-3)


def _fake_family_fits(
    monkeypatch, log_density: dict, spread: dict | None = None, unconverged=(), log=None
):
    """joint_fit replaced by fits whose every entry has the log density
    ``log_density[name]`` (default -6), spread over the draws with sd
    ``spread[name]`` (default 0.05: every Pareto k low; a constant log
    density gets k = inf from arviz), the same standard normal pattern in
    every fit (their differences exact): which families were fitted, in
    order. The families of ``unconverged`` stop unconverged at their first
    check; run on (``resume``), they converge. ``log``: a list to which each
    call's (name, max_sweeps, resumed) is added."""
    import arviz as az

    calls = []

    def fake_fit(b, curves, y, usable, censored, keep, name, seed, options, *rest, **kw):
        calls.append(name)
        if log is not None:
            log.append((name, options.get("max_sweeps"), kw.get("resume") is not None))
        ll = np.full((2, 50, 3, 4), log_density.get(name, -6.0))
        z = np.random.default_rng(11).standard_normal(ll.shape)
        ll = ll + (spread or {}).get(name, 0.05) * z
        gamma = np.full((2, 50), 0.1 * len(calls))  # each fit its own answer
        posterior = {"gamma_object": gamma, "n_object": np.ones((2, 50))}
        idata = az.from_dict(posterior=posterior, log_likelihood={"y": ll})
        converged = name not in unconverged or kw.get("resume") is not None
        samples = SimpleNamespace(
            seconds=1.0, facets=SimpleNamespace(seconds=0.0), converged=converged, run=None
        )
        return idata, samples, np.ones(4, bool)

    monkeypatch.setattr(sky_families, "joint_fit", fake_fit)
    monkeypatch.setattr(sky_families, "add_facet_posteriors", lambda *args: None)
    return calls


def test_far_behind_takes_only_unconverged_fits_far_behind():
    # 50 nats and 5 standard errors of the difference, a stacking weight
    # below 0.01, unconverged: a fit that converged is never cut short, a
    # close or uncertain gap or a weight that counts is run on
    scores = {
        "best": {"elpd_diff": 0.0, "dse": 0.0, "weight": 0.95},
        "far": {"elpd_diff": 60.0, "dse": 5.0, "weight": 0.001},
        "far, converged": {"elpd_diff": 600.0, "dse": 5.0, "weight": 0.0},
        "close": {"elpd_diff": 40.0, "dse": 1.0, "weight": 0.0},
        "uncertain": {"elpd_diff": 60.0, "dse": 20.0, "weight": 0.0},
        "weighed": {"elpd_diff": 60.0, "dse": 5.0, "weight": 0.049},
    }
    converged = dict.fromkeys(scores, False) | {"far, converged": True}
    assert sky_families.far_behind(scores, converged) == ["far"]


def test_families_far_behind_are_kept_at_their_first_check(monkeypatch):
    # gensky's clear sky predicts best; the overcast sky is 14 nats an entry
    # (168 nats) behind, the intermediate sky 1 nat an entry (12) behind;
    # auto, intermediate and overcast do not converge at their first check.
    # Every family is first run to the first check (500 sweeps after burn-in
    # by default); the overcast fit is kept there, auto and the intermediate
    # sky are run on from where they stopped, the clear sky is done
    from bayesgloss.sampling import first_check

    args = (None,) * 6 + (0, {})
    unconverged = ("auto", "gensky-intermediate", "gensky-overcast")
    densities = {"gensky-clear": -5.0, "gensky-overcast": -19.0}
    log = []
    _fake_family_fits(monkeypatch, densities, unconverged=unconverged, log=log)
    _, _, _, fam = sky_families.fit_families(*args, perez_families=False)
    first = first_check()
    assert log[:4] == [(name, first, False) for name in sky_families.FAMILIES]
    assert sorted(log[4:]) == [("auto", None, True), ("gensky-intermediate", None, True)]
    assert fam["stopped_early"] == ["gensky-overcast"]
    assert fam["families"]["gensky-overcast"]["stopped_early"]
    assert not fam["families"]["gensky-overcast"]["converged"]
    assert fam["families"]["gensky-clear"]["weight"] > 0.99

    # screen_families=False: every family run in full, once
    log.clear()
    _fake_family_fits(monkeypatch, densities, unconverged=unconverged, log=log)
    _, _, _, fam = sky_families.fit_families(
        *args[:-1], {"screen_families": False}, perez_families=False
    )
    assert log == [(name, None, False) for name in sky_families.FAMILIES]
    assert fam["stopped_early"] == []

    # weights that rest on unreliable PSIS-LOO are made equal: nothing is
    # kept early (a fit kept there would weigh a quarter)
    log.clear()
    spread = dict.fromkeys(sky_families.FAMILIES, 5.0)
    _fake_family_fits(monkeypatch, densities, spread, unconverged=unconverged, log=log)
    _, _, _, fam = sky_families.fit_families(*args, perez_families=False)
    assert fam["stopped_early"] == [] and fam["equal_weights"]
    assert sorted(n for n, _, resumed in log if resumed) == sorted(unconverged)


def test_overcast_variants_are_fitted_only_where_the_overcast_sky_wins(monkeypatch):
    # the data best predicted by a uniform sky: of the four families the
    # overcast one predicts them best, so the variants are fitted and the
    # uniform one takes the weight (an implementation that fitted the
    # variants always, never, or did not restack would fail one of these)
    args = (None,) * 6 + (0, {})
    first = [*sky_families.FAMILIES, *sky_families.FIRST_STACK_OVERCAST]
    rest = [n for n in sky_families.OVERCAST_VARIANTS if n not in first]
    assert rest == ["cie-3", "gensky-uniform"]  # since holdout 22, CIE 2 and 4 in the first stack
    calls = _fake_family_fits(monkeypatch, {"gensky-uniform": -1.0, "gensky-overcast": -2.0})
    idata, _, _, fam = sky_families.fit_families(
        *args, overcast_variants=True, perez_families=False
    )
    assert calls == [*first, *rest]
    assert fam["most_weight"] == "gensky-uniform"
    assert fam["families"]["gensky-uniform"]["weight"] > 0.99
    own = 0.1 * (calls.index("gensky-uniform") + 1)  # each fake fit's gamma: 0.1 x its place
    assert np.all(idata.posterior["gamma_object"].values == pytest.approx(own))  # its own draws
    # not named (None): the default, since holdout 21 the variants fitted
    calls.clear()
    sky_families.fit_families(*args, overcast_variants=None, perez_families=False)
    assert sky_families.DEFAULT_OVERCAST_VARIANTS is True
    assert calls == [*first, *rest]
    # the option off: the four only, the overcast sky chosen
    calls.clear()
    _, _, _, fam = sky_families.fit_families(*args, overcast_variants=False, perez_families=False)
    assert calls == list(sky_families.FAMILIES)
    assert fam["most_weight"] == "gensky-overcast"
    # a sun-lit day (the clear sky wins): only the first stack's shapes are fitted
    calls = _fake_family_fits(monkeypatch, {"gensky-clear": -1.0, "gensky-uniform": 0.0})
    _, _, _, fam = sky_families.fit_families(*args, overcast_variants=True, perez_families=False)
    assert calls == first
    assert set(fam["families"]) == set(first)


def test_first_stack_overcast_shapes_win_a_day_the_first_stack_misreads(monkeypatch):
    # the CIE types 2 and 4 fitted in the first stack (FIRST_STACK_OVERCAST;
    # holdout 22's candidate, the default since stop 58). A day best predicted by CIE type 2 and
    # next by the per-frame mixture (as holdout 21's vs06): without the
    # candidate the first stack never fits CIE 2 and auto wins; with it, CIE
    # 2 wins, so an overcast shape has the most weight and the rest of the
    # variants are fitted (once each) and share the group's weight; the
    # screen's early stop of CIE 4 (far behind, unconverged) is run on in
    # full, as the variants fitted after the first stack are
    from bayesgloss.sampling import first_check

    args = (None,) * 6 + (0, {})
    dens = {"cie-2": -1.0, "auto": -3.0, "cie-4": -19.0}
    assert sky_families.FIRST_STACK_OVERCAST == ("cie-2", "cie-4")  # the default since stop 58
    with monkeypatch.context() as before:  # as before holdout 22: not in the first stack
        before.setattr(sky_families, "FIRST_STACK_OVERCAST", ())
        _fake_family_fits(before, dens)
        _, _, _, fam = sky_families.fit_families(
            *args, overcast_variants=True, perez_families=False
        )
    assert fam["most_weight"] == "auto" and "cie-2" not in fam["families"]

    log = []
    _fake_family_fits(monkeypatch, dens, unconverged=("cie-4",), log=log)
    idata, _, _, fam = sky_families.fit_families(
        *args, overcast_variants=True, perez_families=False
    )
    first = first_check()
    names = [*sky_families.FAMILIES, "cie-2", "cie-4"]
    assert log[: len(names)] == [(name, first, False) for name in names]
    assert log[len(names) :] == [("cie-3", None, False), ("gensky-uniform", None, False)] + [
        ("cie-4", None, True)
    ]
    assert fam["most_weight"] == "cie-2" and fam["stopped_early"] == []
    assert set(fam["families"]) == set(names) | {"cie-3", "gensky-uniform"}
    assert fam["families"]["cie-2"]["weight"] > 0.99
    assert fam["families"]["cie-2"]["share"] > 0.99  # shared within the overcast group
    own = 0.1 * (names.index("cie-2") + 1)  # each fake fit's gamma: 0.1 x its place
    assert np.all(idata.posterior["gamma_object"].values == pytest.approx(own))
    # the option off: neither in the first stack nor after it
    calls = _fake_family_fits(monkeypatch, dens)
    sky_families.fit_families(*args, overcast_variants=False, perez_families=False)
    assert calls == list(sky_families.FAMILIES)


def test_cli_carries_overcast_variants_to_the_estimate(tmp_path, monkeypatch):
    # one bundle: the flag reaches estimate_bundle; several: each unit's options
    # (absent where not given, so that earlier runs keep their keys) and,
    # through estimate_unit, estimate_bundle
    from conftest import estimate_option_route

    route = estimate_option_route(
        monkeypatch, tmp_path, ["--overcast-variants"], "overcast_variants"
    )
    assert route["units"] == [True, True]
    assert not route["plain_units_have_key"]
    # without the flag estimate_bundle gets None, its default (on since holdout 21)
    assert route["estimate_bundle"] == [True, None, True]
    off = estimate_option_route(
        monkeypatch, tmp_path / "off", ["--no-overcast-variants"], "overcast_variants"
    )
    assert off["units"] == [False, False]
    assert off["estimate_bundle"] == [False, None, False]


def test_perez_families_are_fitted_and_stacked_unless_left_out(monkeypatch):
    # data best predicted by the turbid Perez sky: asked for, the Perez
    # shapes are fitted after the four and the turbid one takes the weight
    # and answers; not asked for, the four only (the clear sky then wins)
    args = (None,) * 6 + (0, {})
    densities = {"perez-turbid": -1.0, "gensky-clear": -2.0}
    calls = _fake_family_fits(monkeypatch, densities)
    idata, _, _, fam = sky_families.fit_families(*args, perez_families=True)
    assert calls == [*sky_families.FAMILIES, *sky_families.PEREZ_FAMILIES]
    assert fam["most_weight"] == "perez-turbid"
    assert fam["families"]["perez-turbid"]["weight"] > 0.99
    assert np.all(idata.posterior["gamma_object"].values == pytest.approx(0.6))  # its own draws
    calls.clear()
    _, _, _, fam = sky_families.fit_families(*args, perez_families=False)
    assert calls == list(sky_families.FAMILIES)
    assert fam["most_weight"] == "gensky-clear"
    # the default (since holdout 11): the six
    calls.clear()
    _, _, _, fam = sky_families.fit_families(*args)
    assert sky_families.DEFAULT_PEREZ_FAMILIES
    assert calls == [*sky_families.FAMILIES, *sky_families.PEREZ_FAMILIES]


def test_a_hazy_perez_day_is_told_hazy_perez(tmp_path):
    # a small bundle made by the forward model under the turbid Perez sky:
    # asked for, the Perez families are fitted and the turbid one carries
    # the weight (the shapes differ most in the circumsolar region, which a
    # glossy facet's curve samples near its mirror frame)
    _, res = _sky_families_of_a_forward_model_day(
        tmp_path / "b", "perez-turbid", perez_families=True
    )
    fam = res.summary["sky_families"]
    every = {*sky_families.FAMILIES, *sky_families.PEREZ_FAMILIES}
    assert set(fam["families"]) == every | set(sky_families.FIRST_STACK_OVERCAST)
    assert fam["most_weight"] == "perez-turbid", fam
    assert fam["families"]["perez-turbid"]["weight"] > 0.8, fam


def test_perez_families_sky_is_the_clear_sky_perez_of_the_bundle_date(tmp_path):
    # the joint model's sky for a Perez family: the Perez sky of the
    # clear-sky irradiance on the bundle's own dates (the Earth-sun
    # distance), not of day 0
    from conftest import make_synthetic_bundle

    from bayesgloss import bundle as bundle_io
    from bayesgloss import sky
    from bayesgloss.joint_estimate import bundle_sky

    b = bundle_io.read_bundle(make_synthetic_bundle(tmp_path / "b"))
    for name in (*sky_families.PEREZ_FAMILIES, "cie-7", "cie-12"):
        day = bundle_sky(b, name, 0.2)
        assert day.model == name
        want = sky.daylight(name, b.sun_direction, day_of_year=b.times.day_of_year)
        np.testing.assert_allclose(day.solar_radiance, want.solar_radiance)
        jan = sky.daylight(name, b.sun_direction, day_of_year=1)
        up = b.sun_up
        assert not np.allclose(day.solar_radiance[up], jan.solar_radiance[up], rtol=1e-3)


def test_perez_families_default_to_the_sky_families_only():
    assert sky_families.perez_families_for("families", None) is True
    assert sky_families.perez_families_for("families", False) is False
    assert sky_families.perez_families_for("gensky-clear", None) is False
    assert sky_families.perez_families_for("auto", False) is False
    with pytest.raises(ValueError, match="'auto'"):
        sky_families.perez_families_for("auto", True)


def test_perez_families_need_the_sky_families(tmp_path):
    from conftest import make_synthetic_bundle

    from bayesgloss.estimate import estimate_bundle

    path = make_synthetic_bundle(tmp_path / "b")
    with pytest.raises(ValueError, match="Perez sky families.*'gensky-clear'"):
        estimate_bundle(path, illumination="gensky-clear", per_frame=True, perez_families=True)


def test_cli_carries_perez_families_to_the_estimate(tmp_path, monkeypatch):
    from conftest import estimate_option_route

    # the flag named either way reaches the estimate and each unit's key; not
    # named, the estimate takes its default (None: the Perez shapes with the
    # sky families) and the units' keys stay those of earlier runs
    route = estimate_option_route(monkeypatch, tmp_path, ["--perez-families"], "perez_families")
    assert route["units"] == [True, True]
    assert not route["plain_units_have_key"]
    assert route["estimate_bundle"] == [True, None, True]
    route = estimate_option_route(
        monkeypatch, tmp_path / "no", ["--no-perez-families"], "perez_families"
    )
    assert route["units"] == [False, False]
    assert route["estimate_bundle"] == [False, None, False]


def test_tied_overcast_shapes_share_their_weight(monkeypatch):
    # the three overcast shapes predict every entry almost equally well (a
    # sunless day whose gradation the facets do not tell): the uniform sky
    # better by 0.001 nat an entry, 0.012 in all. Stacking alone puts the
    # group's whole weight on it (a dominating model takes it all: it did on
    # holdout 4, where the three were within 0.2 nats); sharing by
    # pseudo-BMA+ gives each about a third (exp(0.012) = 1.012), and the
    # object's answer mixes their gammas. The shapes brightening toward the
    # hidden sun (CIE 2 and 4) predict far worse (60 nats: the facets tell
    # the indicatrix, 235 nats on a seen day) and get nothing of the group's
    args = (None,) * 6 + (0, {})
    near = {"gensky-overcast": -1.002, "cie-3": -1.001, "gensky-uniform": -1.0}
    calls = _fake_family_fits(monkeypatch, near)
    idata, _, _, fam = sky_families.fit_families(
        *args, overcast_variants=True, perez_families=False
    )
    assert calls == [*sky_families.FAMILIES, "cie-2", "cie-4", "cie-3", "gensky-uniform"]
    assert sky_families.OVERCAST_GROUP == (
        "gensky-overcast", "cie-2", "cie-3", "cie-4", "gensky-uniform"
    )  # fmt: skip
    w = [fam["families"][name]["weight"] for name in sky_families.OVERCAST_GROUP]
    np.testing.assert_allclose(w, [1 / 3, 0, 1 / 3, 0, 1 / 3], atol=0.01)
    assert sum(f["weight"] for f in fam["families"].values()) == pytest.approx(1.0)
    # each fit's gamma is 0.1 x its place in the calls: 0.4 (overcast), 0.7
    # (CIE 3), 0.8 (uniform); CIE 2's 0.5 and CIE 4's 0.6 are not in the mixture
    gamma = idata.posterior["gamma_object"].values
    np.testing.assert_allclose(np.unique(gamma.round(9)), [0.4, 0.7, 0.8])
    # members far apart keep the better one's weight: 12 entries 1 nat apart each
    calls = _fake_family_fits(monkeypatch, {**near, "gensky-uniform": 0.0})
    _, _, _, fam = sky_families.fit_families(*args, overcast_variants=True, perez_families=False)
    assert fam["families"]["gensky-uniform"]["weight"] > 0.99


def test_high_k_share_weighs_each_fit_by_its_stacking_weight():
    # 90 % of the weight on a fit with 30 of 100 entries unreliable, 10 % on
    # one with none: 0.27 of what the weights rest on (an unweighted mean
    # would say 0.15, the winner's alone 0.30)
    scores = {
        "a": {"weight": 0.9, "high_k": 30, "entries": 100, "elpd_diff": 0.0, "dse": 0.0},
        "b": {"weight": 0.1, "high_k": 0, "entries": 100, "elpd_diff": 3.0, "dse": 2.0},
    }
    assert sky_families.high_k_share(scores) == pytest.approx(0.27)
    equal = sky_families.equal_when_unreliable(scores)
    assert [equal[n]["weight"] for n in "ab"] == [0.5, 0.5]
    assert [equal[n]["stacking_weight"] for n in "ab"] == [0.9, 0.1]
    # 5 of 100 on the winner: below one in ten, the weights are kept
    scores["a"]["high_k"] = 5
    assert sky_families.equal_when_unreliable(scores) is scores


def test_equal_weights_go_to_the_fits_not_shown_to_predict_worse():
    # where the guard acts, a fit shares the weight if it is within
    # UNRELIABLE_NEAR_NATS = 10 nats of the best (holdout 18's within-10,
    # whatever the standard error) or within UNRELIABLE_NEAR_DSE = 2
    # standard errors of the difference (stop 65's within-2se): 8 nats at
    # 1 se and 13 at 9.7 se (holdout 27's vs13, whose ggx-schlick fit held
    # the truth) are in; 40 at 1 se, 60 at 10 se and 25 at 12 se (beyond
    # both margins) are out. Stop 55's rule alone would leave c out too.
    row = {"high_k": 30, "entries": 100}
    scores = {
        "a": {**row, "weight": 0.6, "elpd_diff": 0.0, "dse": 0.0},
        "b": {**row, "weight": 0.0, "elpd_diff": 60.0, "dse": 10.0},
        "c": {**row, "weight": 0.1, "elpd_diff": 13.3, "dse": 9.7},
        "d": {**row, "weight": 0.1, "elpd_diff": 40.0, "dse": 1.0},
        "e": {**row, "weight": 0.1, "elpd_diff": 8.0, "dse": 1.0},
        "f": {**row, "weight": 0.1, "elpd_diff": 25.0, "dse": 12.0},
    }
    equal = sky_families.equal_when_unreliable(scores)
    third = 1.0 / 3.0
    assert [equal[n]["weight"] for n in "abcdef"] == pytest.approx(
        [third, 0.0, third, 0.0, third, 0.0]
    )
    assert [equal[n]["stacking_weight"] for n in "abcdef"] == [0.6, 0.0, 0.1, 0.1, 0.1, 0.1]


def test_unreliable_loo_gives_the_families_equal_weights(monkeypatch):
    # the clear sky predicts best by 1 nat an entry, but every entry's log
    # density spreads over the draws with sd 5 in every fit (PSIS's Pareto k
    # far above 0.7 for most entries: the situation of a 1-3 facet object,
    # whose frames' brightnesses rest on an entry or three). "stack" keeps
    # the clear sky's weight and flags the reliance; "equal" mixes the four
    # fits' answers equally (0.1-0.4, each fit's gamma 0.1 x its place), the
    # facets still the clear sky's, and flags the family as not identified
    args = (None,) * 6 + (0, {})
    spread = dict.fromkeys(sky_families.FAMILIES, 5.0)
    _fake_family_fits(monkeypatch, {"gensky-clear": -5.0}, spread)
    _, _, _, kept = sky_families.fit_families(*args, unreliable_loo="stack", perez_families=False)
    assert kept["high_k_share"] > 0.5
    assert not kept["equal_weights"]
    assert sky_families.stack_flags(kept) == ["loo-unreliable"]
    assert kept["families"]["gensky-clear"]["weight"] > 0.5  # the most, though noisy

    # 0.5 nat an entry over 12 entries: all four within 10 nats of the best
    _fake_family_fits(monkeypatch, {"gensky-clear": -5.5}, spread)
    idata, _, _, equal = sky_families.fit_families(
        *args, unreliable_loo="equal", perez_families=False
    )
    assert equal["equal_weights"]
    assert equal["most_weight"] == "gensky-clear"  # by its stacking weight
    assert [f["weight"] for f in equal["families"].values()] == [0.25] * 4
    assert equal["families"]["gensky-clear"]["stacking_weight"] > 0.5
    assert sky_families.stack_flags(equal) == ["sky-family-not-identifiable"]
    gamma = idata.posterior["gamma_object"].values
    shares = [np.mean(gamma.round(9) == g) for g in (0.1, 0.2, 0.3, 0.4)]
    np.testing.assert_allclose(shares, 0.25, atol=0.08)  # 100 draws: sd of a share 0.04
    # 1 nat an entry: the others 12 nats behind, the clear sky alone answers
    _fake_family_fits(monkeypatch, {"gensky-clear": -5.0}, spread)
    _, _, _, alone = sky_families.fit_families(*args, unreliable_loo="equal", perez_families=False)
    assert alone["equal_weights"]
    weights = {n: f["weight"] for n, f in alone["families"].items()}
    assert weights == {n: float(n == "gensky-clear") for n in sky_families.FAMILIES}

    # reliable entries (sd 0.05 over the draws: k well below 0.7): "equal"
    # keeps the stacking weights, no flag
    _fake_family_fits(monkeypatch, {"gensky-clear": -5.0})
    _, _, _, fam = sky_families.fit_families(*args, unreliable_loo="equal", perez_families=False)
    assert fam["high_k_share"] == 0.0 and not fam["equal_weights"]
    assert fam["families"]["gensky-clear"]["weight"] > 0.99
    assert sky_families.stack_flags(fam) == []
    with pytest.raises(ValueError, match="unreliable_loo"):
        sky_families.fit_families(*args, unreliable_loo="pseudo-bma", perez_families=False)


def test_cli_carries_unreliable_loo_to_the_estimate(tmp_path, monkeypatch):
    from conftest import estimate_option_route

    route = estimate_option_route(
        monkeypatch, tmp_path, ["--unreliable-loo", "stack"], "unreliable_loo"
    )
    assert route["units"] == ["stack", "stack"]
    assert not route["plain_units_have_key"]
    assert route["estimate_bundle"] == ["stack", "equal", "stack"]  # the default: equal weights


def test_printed_estimate_says_when_the_weights_are_equal(capsys):
    # the object's flags and the weights' kind reach the printed summary: a
    # user reading "stacking weight" beside equal weights would take the
    # guard's 1/4 for what the data said
    from bayesgloss import cli

    q = {"median": 0.5, "q05": 0.1, "q95": 0.9, "hdi90": [0.1, 0.9]}
    stack = {
        "families": {n: {"weight": 0.25} for n in sky_families.FAMILIES},
        "high_k_share": 0.62,
        "equal_weights": True,
    }
    summary = {
        "illumination": "families",
        "noise": "relative",
        "camera": "linear",
        "object": {
            "gamma": q,
            "facets_converged": 3,
            "facets": 3,
            "flags": ["sky-family-not-identifiable"],
        },
        "sky_families": stack,
        "facets": [],
    }
    cli._print_estimate("b", summary)
    out = capsys.readouterr().out
    assert "object flags: sky-family-not-identifiable" in out
    assert "sky families (equal weight): auto 0.25" in out
    assert "62% of the entries' PSIS-LOO unreliable" in out
    from bayesgloss import report

    assert report._model_weights(summary).startswith("sky (equal: PSIS-LOO unreliable): auto 0.25")

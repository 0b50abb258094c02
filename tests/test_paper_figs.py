"""The paper's figures: Love & Efford's findings checked on bayesgloss's results.

Figure 6 numbers (object gloss of the 60 sequences, Phong n = 2, plateau
median) are read from ``paper_figs/results/``; the slow test renders the 60
sequences afresh at 64 px and checks the same findings on them.

Findings of the paper that HOLD in our data (asserted as the paper states them):
- the method separates matt < intermediate < glossy in every view and sky
  (implicit in the paper's Fig. 6);
- intermediate metal is under-estimated under the clear sky (sec. 5.2);
- intermediate plastic is estimated above intermediate metal under the clear
  sky (the relative form of "over-estimated for plastic, under for metal");
- under the intermediate sky the south view has the largest error (sec. 5.2);
- mirror-degenerate facets cannot tell matt from glossy (sec. 3);
- under the intermediate sky the intermediate plastic's peak moves to the
  glossy plastic's frame (sec. 5.1; over all W-view facets).

Findings that do NOT hold; asserted is what we find instead:
- matt and glossy are not "well estimated" under the clear sky: matt lies at
  0.1-0.4, glossy at 0.5-0.8, with a spread over views > 0.1;
- intermediate plastic is not over-estimated: it lies below its true 2/3 and
  at most 0.05 above the nominal 0.5 in every view under the clear sky;
- intermediate skies are not markedly worse on average: the mean error
  changes by < 0.05; they are worse for matt and glossy and better for the
  intermediate materials.
"""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from bayesgloss import baseline, render, scene

ROOT = Path(__file__).resolve().parents[1]
FIGS = ROOT / "paper_figs"
RESULTS = FIGS / "results"
VIEWS = ("W", "SW", "S", "SE", "E")
CLEAR, INTER = "gensky-clear", "gensky-intermediate"


def _script(name: str):
    """Import a paper_figs script by path (they are scripts, not a package)."""
    spec = importlib.util.spec_from_file_location(f"paper_figs_{name}", FIGS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def object_table(sequences) -> pd.DataFrame:
    """Object gloss per (sky, material, specularity, view) with the true gloss."""
    rows = [
        {
            "sky": s["truth"]["sky"],
            "material": s["truth"]["material"],
            "spec": s["truth"]["specularity"],
            "view": s["view"],
            "est": s["object"]["gamma"],
            "true": s["truth"]["gloss"],
        }
        for s in sequences
    ]
    t = pd.DataFrame(rows).set_index(["sky", "material", "spec", "view"]).sort_index()
    t["err"] = (t.est - t.true).abs()
    return t


def est(t, sky, material, spec) -> np.ndarray:
    """Object gloss over the five views, in the order W SW S SE E."""
    return np.array([t.loc[(sky, material, spec, v), "est"] for v in VIEWS])


# -- the findings, shared by the fast (saved) and slow (fresh) tests -------------


def check_paper_findings_that_hold(t: pd.DataFrame) -> None:
    # 1. matt < intermediate < glossy in every view, sky and material: 20 strict
    # orderings. The smallest margin in the saved results is 0.03 (S view,
    # intermediate sky); a mix-up of materials, skies or views breaks it.
    for sky in (CLEAR, INTER):
        for material in ("plastic", "metal"):
            m, i, g = (est(t, sky, material, s) for s in (0.0, 0.5, 1.0))
            assert np.all(m < i) and np.all(i < g), (sky, material, m, i, g)
    # 2. intermediate metal (true 0.5) is under-estimated under the clear sky in
    # every view (saved: 0.24-0.41); an estimator recovering the truth would not.
    assert np.all(est(t, CLEAR, "metal", 0.5) < 0.5)
    # 3. intermediate plastic lies above intermediate metal under the clear sky in
    # every view, by at least 0.05 (saved: 0.10-0.14). Their true gammas differ by
    # 2/3 - 1/2 = 0.17: Radiance's plastic of spec 0.5 and grey 0.5 puts 2/3 of its
    # reflection in the mirror term, metal 1/2. Swapping the materials fails this.
    diff = est(t, CLEAR, "plastic", 0.5) - est(t, CLEAR, "metal", 0.5)
    assert np.all(diff >= 0.05), diff
    # 4. the south view has the largest mean |error| over the six materials under
    # the intermediate sky (saved: 0.33 against <= 0.25 for the others).
    err = t.loc[INTER].groupby("view").err.mean()
    assert err.idxmax() == "S", err.to_dict()


def check_degeneracy(sequences) -> None:
    # Sec. 3: where Lambert and Phong predict the same peak frame, the peak cannot
    # tell gloss. Every mirror-degenerate facet gets the same gamma for matt and
    # glossy (the whole grid matches), while the other facets separate them by
    # > 0.1 on average (saved: 0.11 S intermediate ... 0.52 W). Degenerate facets
    # are a minority (saved 8-14 % per view; 9-22 % at 64 px, where fewer facets
    # are resolved but the low, degenerate ones remain), so the bound is 30 %: an
    # all-degenerate flag fails it.
    by = {
        (s["truth"]["sky"], s["truth"]["material"], s["truth"]["specularity"], s["view"]): s
        for s in sequences
    }
    for sky in (CLEAR, INTER):
        for view in VIEWS:
            matt = by[(sky, "plastic", 0.0, view)]["facets"]
            gloss = by[(sky, "plastic", 1.0, view)]["facets"]
            assert [f["id"] for f in matt] == [f["id"] for f in gloss]
            used = [
                (f, g)
                for f, g in zip(matt, gloss, strict=True)
                if f["gamma"] is not None and "no-direct-sun" not in f["flags"]
            ]
            deg = np.array(["mirror-degenerate" in f["flags"] for f, _ in used])
            sep = np.array([abs(g["gamma"] - f["gamma"]) for f, g in used])
            assert 0 < deg.mean() < 0.3, (sky, view, deg.mean())
            assert np.all(sep[deg] == 0), (sky, view)
            assert sep[~deg].mean() > 0.1, (sky, view, sep[~deg].mean())


def check_what_we_find_instead(t: pd.DataFrame) -> None:
    # 1. "Matt and glossy well estimated under clear skies, little variance between
    # views" does not hold. With the plateau median, even noise-free data from the
    # paper's own model give matt 0.17-0.23 and glossy 0.74-0.80 (ideal.csv, and
    # test_the_median_rule_caps_matt_and_glossy below), so matt >= 0.1 and glossy
    # <= 0.8 are the method's own limits; saved: matt 0.17-0.32, glossy 0.54-0.76.
    # An estimator that took the plateau's lower edge (matt ~0.05) fails the first.
    for material in ("plastic", "metal"):
        m, g = est(t, CLEAR, material, 0.0), est(t, CLEAR, material, 1.0)
        assert np.all((m > 0.1) & (m < 0.4)), m
        assert np.all((g > 0.5) & (g < 0.8)), g
        # spread over views (saved: 0.15 and 0.22): the S view sees the least
        assert np.ptp(m) > 0.1 and np.ptp(g) > 0.1, (np.ptp(m), np.ptp(g))
    # 2. Intermediate plastic is not over-estimated: below its true 2/3 in every
    # view under the clear sky, and nowhere more than 0.05 above the paper's
    # nominal 0.5 (saved 0.35-0.53 at 128 px; 0.47-0.52 at 64 px, where fewer
    # facets are resolved). An estimator recovering the truth fails both.
    p = est(t, CLEAR, "plastic", 0.5)
    assert np.all(p < 2 / 3), p
    assert np.all(p < 0.55), p
    # 3. Intermediate skies are not markedly worse on average (saved mean |error|
    # 0.26 clear, 0.25 intermediate), but worse for matt and glossy (by 0.05 and
    # 0.04) and better for the spec-0.5 materials, whose peak the intermediate sky
    # pulls toward the glossy frame (see Fig. 5 and the peak-shift test).
    clear_err, inter_err = t.loc[CLEAR].err, t.loc[INTER].err
    assert abs(inter_err.mean() - clear_err.mean()) < 0.05
    by_spec = pd.DataFrame({"clear": clear_err, "inter": inter_err}).groupby(level="spec").mean()
    assert by_spec.loc[0.0, "inter"] > by_spec.loc[0.0, "clear"]
    assert by_spec.loc[1.0, "inter"] > by_spec.loc[1.0, "clear"]
    assert by_spec.loc[0.5, "inter"] < by_spec.loc[0.5, "clear"]


def check_peak_shift(stats: dict) -> None:
    # Sec. 5.1 over all W-view facets (Fig. 5d): under the clear sky matt,
    # intermediate and glossy plastic peak in three distinct frames on many facets
    # (saved 42 %), under the intermediate sky on few (6 %); the intermediate
    # plastic peaks in the glossy frame on 28 % of facets under the clear sky and
    # on 75 % under the intermediate sky. A swap of the skies fails both.
    clear, inter = stats["clear"], stats["intermediate"]
    assert clear["share_all_three_distinct"] > 0.25 > 0.15 > inter["share_all_three_distinct"]
    assert (
        inter["share_intermediate_at_glossy_frame"]
        > clear["share_intermediate_at_glossy_frame"] + 0.25
    )
    # the cause: under the intermediate sky the glossy facet's peak outshines the
    # matt facet's (median ratio saved 1.45), under the clear sky not (0.53)
    assert clear["median_ratio_glossy_peak_to_matt_peak"] < 1.0
    assert inter["median_ratio_glossy_peak_to_matt_peak"] > 1.0


# -- fast tests on the saved results ------------------------------------------


@pytest.fixture(scope="module")
def saved():
    return json.loads((RESULTS / "paper60.json").read_text())


def test_saved_results_are_the_60_sequences(saved):
    t = object_table(saved["sequences"])
    assert len(t) == 60 and t.index.is_unique
    assert saved["config"]["exponent"] == baseline.DEFAULT_EXPONENT
    # the estimand: plastic spec 0.5 of grey 0.5 is gamma 2/3, metal spec 0.5 is 1/2
    assert t.loc[(CLEAR, "plastic", 0.5, "W"), "true"] == pytest.approx(2 / 3)
    assert t.loc[(CLEAR, "metal", 0.5, "W"), "true"] == pytest.approx(0.5)


def test_fig6_paper_findings_that_hold(saved):
    check_paper_findings_that_hold(object_table(saved["sequences"]))
    check_degeneracy(saved["sequences"])


def test_fig6_what_we_find_instead_of_the_paper(saved):
    check_what_we_find_instead(object_table(saved["sequences"]))


def test_fig5_peak_shift_under_the_intermediate_sky():
    check_peak_shift(json.loads((RESULTS / "summary.json").read_text())["peak_stats"])


def test_saved_peak_stats_agree_with_the_saved_curves():
    # the summary is recomputed from curves.npz, so it is not merely trusted
    cr = _script("compute_results")
    with np.load(RESULTS / "curves.npz") as z:
        stats = cr.peak_stats(dict(z))
    saved = json.loads((RESULTS / "summary.json").read_text())["peak_stats"]
    for sky in ("clear", "intermediate"):
        for key, value in stats[sky].items():
            assert value == pytest.approx(saved[sky][key], abs=1e-12), (sky, key)


def test_sensitivity_plateau_rule_and_exponent():
    s = pd.read_csv(RESULTS / "sensitivity.csv")
    assert len(s) == 60 * 3 * 4  # sequences x exponents x plateau rules

    def views(rule, n, spec, material="plastic", sky=CLEAR):
        sel = s[
            (s.rule == rule)
            & (s.exponent == n)
            & (s.specularity == spec)
            & (s.material == material)
            & (s.sky == sky)
        ]
        return sel.set_index("view").loc[list(VIEWS), "object_gloss"].to_numpy()

    # the median rule reproduces paper60.json exactly
    t = object_table(json.loads((RESULTS / "paper60.json").read_text())["sequences"])
    np.testing.assert_allclose(views("median", 2.0, 0.0), est(t, CLEAR, "plastic", 0.0), atol=1e-8)
    # "matt well estimated" holds only under the lower-edge rule (saved <= 0.07),
    # and that rule then puts glossy at <= 0.55: no single rule gives both
    assert np.all(views("lower", 2.0, 0.0) < 0.1)
    assert np.all(views("lower", 2.0, 1.0) < 0.6)
    # the upper edge gets glossy near 1 (saved >= 0.78) but matt at >= 0.35
    assert np.all(views("upper", 2.0, 1.0) > 0.75)
    assert np.all(views("upper", 2.0, 0.0) > 0.3)
    # sharper lobes leave matt facets' plateaus nearly the whole grid: with the
    # median, matt drifts to ~0.5 at n = 200 (saved 0.47-0.50)
    m2, m20, m200 = (views("median", n, 0.0) for n in (2.0, 20.0, 200.0))
    assert np.all(m2 < m20) and np.all(m20 < m200)
    assert np.all(np.abs(m200 - 0.5) < 0.1)
    # glossy W facets mostly have no exact match at n = 2 (saved 92 %)
    w = s[(s.rule == "median") & (s.view == "W") & (s.specularity == 1.0) & (s.sky == CLEAR)]
    assert w.set_index("exponent").loc[2.0, "share_no_exact_match"].max() > 0.8


def test_the_median_rule_caps_matt_and_glossy():
    # Recomputed here from the paper's own model (no rendering, < 1 s): noise-free
    # curves of gamma 0 and 1 over the facets the W and S bundles see. The median
    # of each facet's plateau can never reach 0 or 1 unless the plateau is a single
    # grid point, so the object means stay inside [0.15, 0.85]; the saved ideal.csv
    # must agree with the recomputation.
    cr = _script("compute_results")
    seen = cr.seen_facets(json.loads((RESULTS / "paper60.json").read_text())["sequences"])
    ideal = pd.read_csv(RESULTS / "ideal.csv")
    for view in ("W", "S"):
        seq = scene.paper_sequence(view)
        keep = np.isin(seq.facets.ids, seen[view])
        geom = render.ViewGeometry(seq.geometry.normal[keep], seq.geometry.view_direction[keep])
        sun_dir = seq.sky.sun_direction
        for gamma, lo, hi in ((0.0, 0.15, 0.3), (1.0, 0.7, 0.85)):
            lum = render.paper_point_sun(geom, sun_dir, gamma, 2.0)
            valid = np.broadcast_to(sun_dir[:, 2] > 0, lum.shape)
            res = baseline.peak_frame_gloss(lum, valid, geom, sun_dir, frame_hours=seq.solar_hours)
            assert lo < res.object_gloss < hi, (view, gamma, res.object_gloss)
            row = ideal[
                (ideal.view == view)
                & (ideal.observed_exponent == 2.0)
                & (ideal.true_gloss == gamma)
                & (ideal.rule == "median")
            ]
            assert row.object_gloss.item() == pytest.approx(res.object_gloss, abs=1e-6)


def test_forward_model_check_is_close_to_radiance():
    # the scene-variant table rests on the forward model; at the default scene it
    # must reproduce the Radiance object gloss (saved max difference 0.03)
    check = json.loads((RESULTS / "summary.json").read_text())["forward_model_check"]
    assert check["max_abs_object_gloss_difference"] < 0.05
    assert check["mean_share_facets_same_gamma"] > 0.8


@pytest.mark.parametrize("name", ["fig3", "fig5", "fig6"])
def test_figure_script_writes_a_png(name, tmp_path):
    path = _script(name).main(["--out", str(tmp_path)])
    data = Path(path).read_bytes()
    assert Path(path).parent == tmp_path
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    assert 10_000 < len(data) < 200_000  # not blank, and small enough to commit


# -- slow: the same findings on freshly rendered bundles -------------------------


@pytest.mark.slow
@pytest.mark.radiance
def test_findings_hold_on_fresh_renders(tmp_path):
    # ~6-7 min on 2 cores: the 60 sequences at 64 px rendered with Radiance afresh,
    # the baseline run on them, and the same findings checked.
    from bayesgloss import sequences

    cr = _script("compute_results")
    configs = sequences.paper_configs(image_size=64)
    paths = sequences.render_bundles(configs, tmp_path / "bundles", jobs=2, progress=False)
    results, arrays, _ = cr.bundle_results(configs, paths, [baseline.DEFAULT_EXPONENT])
    t = object_table(results)
    check_paper_findings_that_hold(t)
    check_degeneracy(results)
    check_what_we_find_instead(t)
    check_peak_shift(cr.peak_stats(arrays))
    # and facet by facet the fresh estimates are the saved ones: on the facets both
    # resolutions see (64 px resolves 23 of the 36 sunlit facets per view) the
    # gammas were identical on all of them when this test was written. Allow 5 %
    # for peaks that RGBE ties or ambient noise can flip.
    saved = {
        s["name"]: {f["id"]: f["gamma"] for f in s["facets"]}
        for s in json.loads((RESULTS / "paper60.json").read_text())["sequences"]
    }
    same, count = 0, 0
    for s in results:
        for f in s["facets"]:
            old = saved[s["name"]].get(f["id"])
            if f["gamma"] is not None and old is not None:
                same += abs(f["gamma"] - old) < 1e-9
                count += 1
    assert count >= 60 * 20 and same >= 0.95 * count, (same, count)


def test_peak_attribution_air_mass_and_mirror():
    # Recomputed with the forward model (< 1 s) and compared with summary.json.
    # With the sun at constant radiance (the paper's assumption) a matt facet
    # peaks exactly where the paper predicts, on every facet: the forward model's
    # sun term is eq. 2's Lambert term. The air mass alone moves the peaks of the
    # W view's afternoon-facing facets toward noon (saved: 44 % still on time,
    # -0.83 h on average). A mirror peaks in the n = 2 gamma-1 frame on few facets
    # (saved 6 %) and in the n = 20 one on many more (56 %).
    cr = _script("compute_results")
    seen = cr.seen_facets(json.loads((RESULTS / "paper60.json").read_text())["sequences"])
    att = cr.peak_attribution(seen)
    saved = json.loads((RESULTS / "summary.json").read_text())["peak_attribution"]
    for sky, parts in att.items():
        for part, values in parts.items():
            assert values == pytest.approx(saved[sky][part], abs=1e-12), (sky, part)
    clear = att["clear"]
    assert clear["matt_sun_constant_radiance"]["share_at_predicted_gamma_0"] == 1.0
    assert clear["matt_sun_with_air_mass"]["share_at_predicted_gamma_0"] < 0.7
    assert clear["matt_sun_with_air_mass"]["mean_offset_frames"] < -0.5
    n2 = clear["mirror_vs_gamma_1_n2"]["share_at_predicted_gamma_1"]
    n20 = clear["mirror_vs_gamma_1_n20"]["share_at_predicted_gamma_1"]
    assert n2 < 0.2 < 0.4 < n20

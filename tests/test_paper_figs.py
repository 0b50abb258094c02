"""The paper's figures: Love & Efford's findings checked on bayesgloss's results.

The fast tests run the analysis code on small inputs: the W view's 12
sequences are re-estimated from their saved facet curves
(``paper_figs/results/curves.npz``; the facets, camera and sun come from the
sequence configurations, nothing is rendered) and must reproduce the saved
``paper60.json`` and ``sensitivity.csv`` entries of that view; the findings of
one view are checked on the recomputation. The forward model, the paper's own
model and the peak statistics are recomputed too. Only the W view's curves are
saved, so the findings that compare views (the south view worst, the spread
over views, the skies' mean errors) need fresh renders: the slow test renders
the 60 sequences at 64 px and checks every finding on them.

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

from bayesgloss import baseline, render, scene, sequences

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


def object_table(seqs) -> pd.DataFrame:
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
        for s in seqs
    ]
    t = pd.DataFrame(rows).set_index(["sky", "material", "spec", "view"]).sort_index()
    t["err"] = (t.est - t.true).abs()
    return t


def est(t, sky, material, spec, views=VIEWS) -> np.ndarray:
    """Object gloss over the views, in the order given (default W SW S SE E)."""
    return np.array([t.loc[(sky, material, spec, v), "est"] for v in views])


# -- the findings, shared by the fast (W view, recomputed) and slow (fresh) tests -
# Per-view findings take the views to check; the findings that compare views need
# all five and run in the slow test only (only the W view's curves are saved).


def check_paper_findings_that_hold(t: pd.DataFrame, views=VIEWS) -> None:
    # 1. matt < intermediate < glossy in every view, sky and material: 4 strict
    # orderings per view. The smallest margin at 128 px is 0.03 (S view,
    # intermediate sky; W: 0.09); a mix-up of materials, skies or views breaks it.
    for sky in (CLEAR, INTER):
        for material in ("plastic", "metal"):
            m, i, g = (est(t, sky, material, s, views) for s in (0.0, 0.5, 1.0))
            assert np.all(m < i) and np.all(i < g), (sky, material, m, i, g)
    # 2. intermediate metal (true 0.5) is under-estimated under the clear sky in
    # every view (128 px: 0.24-0.41, W 0.41); an estimator recovering the truth
    # would not.
    assert np.all(est(t, CLEAR, "metal", 0.5, views) < 0.5)
    # 3. intermediate plastic lies above intermediate metal under the clear sky in
    # every view, by at least 0.05 (128 px: 0.10-0.14, W 0.11). Their true gammas
    # differ by 2/3 - 1/2 = 0.17: Radiance's plastic of spec 0.5 and grey 0.5 puts
    # 2/3 of its reflection in the mirror term, metal 1/2. Swapping the materials
    # fails this.
    diff = est(t, CLEAR, "plastic", 0.5, views) - est(t, CLEAR, "metal", 0.5, views)
    assert np.all(diff >= 0.05), diff


def check_south_view_worst(t: pd.DataFrame) -> None:
    # The south view has the largest mean |error| over the six materials under
    # the intermediate sky (128 px: 0.33 against <= 0.25 for the others).
    err = t.loc[INTER].groupby("view").err.mean()
    assert err.idxmax() == "S", err.to_dict()


def check_degeneracy(seqs, views=VIEWS) -> None:
    # Sec. 3: where Lambert and Phong predict the same peak frame, the peak cannot
    # tell gloss. Every mirror-degenerate facet gets the same gamma for matt and
    # glossy (the whole grid matches), while the other facets separate them by
    # > 0.1 on average (128 px: 0.11 S intermediate ... 0.52 W). Degenerate facets
    # are a minority (8-14 % per view at 128 px, W 14 %; 9-22 % at 64 px, where
    # fewer facets are resolved but the low, degenerate ones remain), so the bound
    # is 30 %: an all-degenerate flag fails it.
    by = {
        (s["truth"]["sky"], s["truth"]["material"], s["truth"]["specularity"], s["view"]): s
        for s in seqs
    }
    for sky in (CLEAR, INTER):
        for view in views:
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


def check_what_we_find_instead(t: pd.DataFrame, views=VIEWS) -> None:
    # 1. "Matt and glossy well estimated under clear skies" does not hold. With the
    # plateau median, even noise-free data from the paper's own model give matt
    # 0.17-0.23 and glossy 0.74-0.80 (ideal.csv, and
    # test_the_median_rule_caps_matt_and_glossy below), so matt >= 0.1 and glossy
    # <= 0.8 are the method's own limits; 128 px: matt 0.17-0.32, glossy
    # 0.54-0.76 (W 0.32 and 0.76). An estimator that took the plateau's lower edge
    # (matt ~0.05) fails the first.
    for material in ("plastic", "metal"):
        m, g = est(t, CLEAR, material, 0.0, views), est(t, CLEAR, material, 1.0, views)
        assert np.all((m > 0.1) & (m < 0.4)), m
        assert np.all((g > 0.5) & (g < 0.8)), g
    # 2. Intermediate plastic is not over-estimated: below its true 2/3 in every
    # view under the clear sky, and nowhere more than 0.05 above the paper's
    # nominal 0.5 (0.35-0.53 at 128 px, W 0.53; 0.47-0.52 at 64 px, where fewer
    # facets are resolved). An estimator recovering the truth fails both.
    p = est(t, CLEAR, "plastic", 0.5, views)
    assert np.all(p < 2 / 3), p
    assert np.all(p < 0.55), p


def check_what_we_find_instead_across_views(t: pd.DataFrame) -> None:
    # 1. "... with little variance between views" does not hold either: the spread
    # of matt and glossy over the views (128 px: 0.15 and 0.22) exceeds 0.1; the
    # S view sees the least.
    for material in ("plastic", "metal"):
        m, g = est(t, CLEAR, material, 0.0), est(t, CLEAR, material, 1.0)
        assert np.ptp(m) > 0.1 and np.ptp(g) > 0.1, (np.ptp(m), np.ptp(g))
    # 2. Intermediate skies are not markedly worse on average (128 px: mean
    # |error| 0.26 clear, 0.25 intermediate), but worse for matt and glossy (by
    # 0.05 and 0.04) and better for the spec-0.5 materials, whose peak the
    # intermediate sky pulls toward the glossy frame (see Fig. 5 and the
    # peak-shift test).
    clear_err, inter_err = t.loc[CLEAR].err, t.loc[INTER].err
    assert abs(inter_err.mean() - clear_err.mean()) < 0.05
    by_spec = pd.DataFrame({"clear": clear_err, "inter": inter_err}).groupby(level="spec").mean()
    assert by_spec.loc[0.0, "inter"] > by_spec.loc[0.0, "clear"]
    assert by_spec.loc[1.0, "inter"] > by_spec.loc[1.0, "clear"]
    assert by_spec.loc[0.5, "inter"] < by_spec.loc[0.5, "clear"]


def check_peak_shift(stats: dict) -> None:
    # Sec. 5.1 over all W-view facets (Fig. 5d): under the clear sky matt,
    # intermediate and glossy plastic peak in three distinct frames on many facets
    # (128 px: 42 %), under the intermediate sky on few (6 %); the intermediate
    # plastic peaks in the glossy frame on 28 % of facets under the clear sky and
    # on 75 % under the intermediate sky. A swap of the skies fails both.
    clear, inter = stats["clear"], stats["intermediate"]
    assert clear["share_all_three_distinct"] > 0.25 > 0.15 > inter["share_all_three_distinct"]
    assert (
        inter["share_intermediate_at_glossy_frame"]
        > clear["share_intermediate_at_glossy_frame"] + 0.25
    )
    # the cause: under the intermediate sky the glossy facet's peak outshines the
    # matt facet's (median ratio 1.45 at 128 px), under the clear sky not (0.53)
    assert clear["median_ratio_glossy_peak_to_matt_peak"] < 1.0
    assert inter["median_ratio_glossy_peak_to_matt_peak"] > 1.0


# -- fast tests: the analysis rerun on small inputs ------------------------------


@pytest.fixture(scope="module")
def cr():
    return _script("compute_results")


@pytest.fixture(scope="module")
def saved():
    return json.loads((RESULTS / "paper60.json").read_text())


@pytest.fixture(scope="module")
def curves():
    with np.load(RESULTS / "curves.npz") as z:
        return dict(z)


@pytest.fixture(scope="module")
def recomputed(cr, curves):
    """The W view's 12 sequences re-estimated from their saved facet curves by
    compute_results' own analysis, at the three sensitivity exponents (~0.3 s):
    paper60.json's entries of the view and its sensitivity table."""
    return cr.curves_results(sequences.paper_configs(), curves, cr.CONFIG["sensitivity_exponents"])


def test_saved_results_are_the_60_sequences(saved, recomputed, cr):
    # paper60.json holds the 60 configured sequences with the truth the code
    # assigns them; its W entries are what the baseline computes from the saved
    # curves, exactly. A baseline that shifts, rounds or re-flags any facet, or a
    # wrong true gloss of a Radiance material, fails here.
    configs = sequences.paper_configs()
    seqs = saved["sequences"]
    assert [s["name"] for s in seqs] == [c.name for c in configs]
    for s, c in zip(seqs, configs, strict=True):
        truth = {k: v for k, v in c.truth().items() if k != "config"}
        assert s["view"] == c.view and s["truth"] == truth, s["name"]
    assert saved["config"]["exponent"] == baseline.DEFAULT_EXPONENT == cr.CONFIG["exponent"]
    # the estimand, from Radiance's plastic model: spec / (spec + (1 - spec) * colour)
    # with colour 0.5 gives 2/3 for plastic spec 0.5; metal's is its spec, 1/2
    gloss = {c.name: c.truth()["gloss"] for c in configs}
    assert gloss["paper-W-plastic-0.5-clear"] == pytest.approx(2 / 3)
    assert gloss["paper-W-metal-0.5-clear"] == pytest.approx(0.5)
    results, _ = recomputed
    by_name = {s["name"]: s for s in seqs}
    assert sorted(r["name"] for r in results) == sorted(n for n in by_name if "-W-" in n)
    for r in results:
        assert r == by_name[r["name"]], r["name"]


def test_fig6_paper_findings_that_hold(recomputed):
    # The W column of Fig. 6, recomputed. A baseline whose gammas drift (e.g.
    # +0.1 on every facet puts metal at 0.51) or that mixes materials up fails
    # the orderings or the bounds; one that flags every facet mirror-degenerate,
    # or stops giving degenerate facets the whole grid, fails the degeneracy check.
    # The south view's finding needs all views: slow test.
    results, _ = recomputed
    check_paper_findings_that_hold(object_table(results), views=("W",))
    check_degeneracy(results, views=("W",))


def test_fig6_what_we_find_instead_of_the_paper(recomputed):
    # The W column of Fig. 6, recomputed. A baseline taking the plateau's lower
    # edge (matt 0.07) or upper edge (glossy 0.97), or recovering the true 2/3 of
    # intermediate plastic, fails. The spread over views and the skies' mean
    # errors need all views: slow test.
    results, _ = recomputed
    check_what_we_find_instead(object_table(results), views=("W",))


def test_fig5_peak_shift_under_the_intermediate_sky(cr, curves):
    # Fig. 5d's statistics recomputed from the W view's saved curves; swapping the
    # skies, or comparing the wrong materials' peaks, fails check_peak_shift.
    check_peak_shift(cr.peak_stats(curves))


def test_saved_peak_stats_agree_with_the_saved_curves(cr, curves):
    # the summary is recomputed from curves.npz, so it is not merely trusted
    stats = cr.peak_stats(curves)
    saved = json.loads((RESULTS / "summary.json").read_text())["peak_stats"]
    for sky in ("clear", "intermediate"):
        for key, value in stats[sky].items():
            assert value == pytest.approx(saved[sky][key], abs=1e-12), (sky, key)


def test_sensitivity_plateau_rule_and_exponent(recomputed):
    # The W view's sensitivity rows, recomputed from the saved curves for n = 2,
    # 20, 200 and the four plateau rules, must be the saved rows of that view
    # byte for byte (written as compute_results.main writes them). A plateau rule
    # computed wrongly (e.g. lower and upper swapped: matt 0.57 under "lower"), or
    # an exponent that does not reach the baseline (m2 == m20), fails the findings.
    _, s = recomputed
    assert len(s) == 12 * 3 * 4  # sequences x exponents x plateau rules
    lines = (RESULTS / "sensitivity.csv").read_text().splitlines()
    ours = s.to_csv(index=False, float_format="%.9g").splitlines()
    assert ours[0] == lines[0]
    view_col = lines[0].split(",").index("view")
    assert ours[1:] == [line for line in lines[1:] if line.split(",")[view_col] == "W"]

    def w(rule, n, spec, material="plastic", sky=CLEAR, col="object_gloss"):
        sel = s[
            (s.rule == rule)
            & (s.exponent == n)
            & (s.specularity == spec)
            & (s.material == material)
            & (s.sky == sky)
        ]
        return sel[col].item()

    # the median rule is the baseline's own object gloss (paper60.json's)
    t = object_table(recomputed[0])
    assert w("median", 2.0, 0.0) == t.loc[(CLEAR, "plastic", 0.0, "W"), "est"]
    # "matt well estimated" holds only under the lower-edge rule (W 0.07; all views
    # <= 0.07), and that rule then puts glossy at <= 0.55: no rule gives both
    assert w("lower", 2.0, 0.0) < 0.1
    assert w("lower", 2.0, 1.0) < 0.6
    # the upper edge gets glossy near 1 (W 0.97; all views >= 0.78) but matt at
    # >= 0.35 (W 0.57)
    assert w("upper", 2.0, 1.0) > 0.75
    assert w("upper", 2.0, 0.0) > 0.3
    # sharper lobes leave matt facets' plateaus nearly the whole grid: with the
    # median, matt drifts to ~0.5 at n = 200 (W 0.32, 0.43, 0.50)
    m2, m20, m200 = (w("median", n, 0.0) for n in (2.0, 20.0, 200.0))
    assert m2 < m20 < m200
    assert abs(m200 - 0.5) < 0.1
    # glossy W facets mostly have no exact match at n = 2 (92 %), far fewer at
    # n = 20 (44 %): the mirror peaks outside the broad lobe's predictions
    assert w("median", 2.0, 1.0, col="share_no_exact_match") > 0.8
    assert w("median", 20.0, 1.0, col="share_no_exact_match") < 0.6


def test_the_median_rule_caps_matt_and_glossy(cr, saved):
    # Recomputed here from the paper's own model (no rendering, < 1 s): noise-free
    # curves of gamma 0 and 1 over the facets the W and S bundles see. The median
    # of each facet's plateau can never reach 0 or 1 unless the plateau is a single
    # grid point, so the object means stay inside [0.15, 0.85]; the saved ideal.csv
    # must agree with the recomputation.
    seen = cr.seen_facets(saved["sequences"])
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


def test_forward_model_check_is_close_to_radiance(cr, saved):
    # The scene-variant table rests on the forward model; at the default scene it
    # must reproduce the Radiance object gloss. Recomputed (~3 s): the forward model
    # (sun, sky and ground) of all 60 sequences, on the bundles' facets, through
    # the baseline, against the saved Radiance estimates; it must equal
    # summary.json's check. A forward model that loses its sky or sun term, or
    # mistakes metal for plastic, moves object gloss by more than 0.05 (max 0.03 as
    # it stands) and breaks the facet agreement (91 %).
    check = cr.forward_check(saved["sequences"])
    summary = json.loads((RESULTS / "summary.json").read_text())["forward_model_check"]
    for key, value in check.items():
        assert value == pytest.approx(summary[key], abs=1e-12), key
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
    cr = _script("compute_results")
    configs = sequences.paper_configs(image_size=64)
    paths = sequences.render_bundles(configs, tmp_path / "bundles", jobs=2, progress=False)
    results, arrays, _ = cr.bundle_results(configs, paths, [baseline.DEFAULT_EXPONENT])
    t = object_table(results)
    check_paper_findings_that_hold(t)
    check_south_view_worst(t)
    check_degeneracy(results)
    check_what_we_find_instead(t)
    check_what_we_find_instead_across_views(t)
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

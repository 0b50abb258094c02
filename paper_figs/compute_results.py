"""Compute everything the paper's figures and their comparison need, once.

Renders the paper's 60 Radiance sequences (or loads them from the bundle
cache), runs the paper's peak-frame baseline on them and writes, under
``paper_figs/results/``:

- ``paper60.json``: per sequence, the baseline at the default exponent
  (object gamma, per-facet gamma, plateau interval and flags), the truth
  (including the true gloss of the Radiance material) and the view.
- ``curves.npz``: the facet curves of the view the figures use (W), with
  each facet's labelled pixel count, and the frame hours.
- ``sensitivity.csv``: object gloss of every sequence for each Phong
  exponent in the config and each plateau rule (``lower``/``median``/
  ``upper`` edge of each facet's matching interval; ``median-exact``: the
  median rule over facets with an exact match only), with the share of
  sunlit facets flagged ``mirror-degenerate`` and ``no-exact-match`` and the
  mean plateau width.
- ``ideal.csv``: the method's ceiling: the baseline on noise-free curves
  made by the paper's own model (``render.paper_point_sun``) for true gamma
  0, 0.5, 1, with the observations' exponent equal to the method's (2) or
  sharp (200, a near-mirror), over the facets the bundles see.
- ``variants.csv``: the paper's unknowns (date, tessellation, camera
  distance and height, material colour): object gloss at the default
  exponent and median rule from bayesgloss's physical forward model
  (``scene.plastic_radiance``, sun + sky + ground), which is checked against
  the Radiance results at the default scene (``summary.json``).
- ``summary.json``: the facet chosen for Figs. 3 and 5 and why, peak-frame
  statistics of the W view (Fig. 5's claims over all facets), per-view
  leverage, and the forward-model check.
- ``tables.md``: the tables above in readable form.

Usage: python paper_figs/compute_results.py [--cache DIR] [--size N] [--jobs N] [--out DIR]
(cold rendering of the 60 bundles at 128 px takes ~6.5 min with 2 jobs).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pandas as pd

from bayesgloss import baseline, bundle, reflectance, render, scene, sequences, sun

HERE = Path(__file__).parent
CONFIG = json.loads((HERE / "config.json").read_text())
VIEWS = ("W", "SW", "S", "SE", "E")
SKIES = ("gensky-clear", "gensky-intermediate")
MATERIALS = ("plastic", "metal")
SPECULARITIES = (0.0, 0.5, 1.0)


# -- baseline on the Radiance bundles ------------------------------------------


def _object_rules(res: baseline.BaselineResult) -> dict:
    """Object gloss under each plateau rule, flag shares and plateau width."""
    used = res.direct_sun & np.isfinite(res.gloss)
    flags = [f for f, u in zip(res.flags, used, strict=True) if u]
    exact = np.array(["no-exact-match" not in f for f in res.flags])
    lo, hi = res.interval[used, 0], res.interval[used, 1]
    return {
        "rules": {
            "lower": float(np.mean(lo)),
            "median": float(np.mean(res.gloss[used])),
            "upper": float(np.mean(hi)),
            "median-exact": float(np.mean(res.gloss[used & exact]))
            if np.any(used & exact)
            else float("nan"),
        },
        "share_mirror_degenerate": float(np.mean(["mirror-degenerate" in f for f in flags])),
        "share_no_exact_match": float(np.mean(["no-exact-match" in f for f in flags])),
        "plateau_width": float(np.mean(hi - lo)),
        "facets_used": int(used.sum()),
    }


def peak_ties(luminance, valid, tolerance: float = 0.01) -> dict:
    """Share of observed facets whose largest valid luminance is reached in more
    than one frame exactly (the baseline then takes the earliest), or within
    ``tolerance`` (relative) of it."""
    masked = np.where(valid, luminance, -np.inf)
    top = masked.max(axis=1, keepdims=True)
    seen = np.isfinite(top[:, 0])
    exact = (masked == top).sum(axis=1) > 1
    near = (masked >= top * (1 - tolerance)).sum(axis=1) > 1
    return {
        "share_peak_tied": float(np.mean(exact[seen])),
        "share_peak_within_1pct": float(np.mean(near[seen])),
    }


def estimate_curves(luminance, valid, ids, geom, sun_direction, hours, exponents):
    """Baseline on one sequence's facet curves for each exponent.

    Returns the default exponent's :class:`bayesgloss.baseline.BaselineResult`
    and one summary per exponent (:func:`_object_rules` and :func:`peak_ties`).
    """
    res_default, per_exponent = None, {}
    for n in sorted({float(CONFIG["exponent"]), *map(float, exponents)}):
        res = baseline.peak_frame_gloss(
            luminance,
            valid,
            geom,
            sun_direction,
            ids=ids,
            exponent=n,
            frame_hours=hours,
        )
        per_exponent[n] = _object_rules(res) | peak_ties(luminance, valid)
        if n == float(CONFIG["exponent"]):
            res_default = res
    return res_default, per_exponent


def sequence_entry(res: baseline.BaselineResult, truth: dict, view: str) -> dict:
    """One sequence of ``paper60.json`` (without its name): the baseline's JSON,
    the truth (without the rendering config) and the view."""
    out = res.to_json()
    out["truth"] = {k: v for k, v in truth.items() if k != "config"}
    out["view"] = view
    out["degenerate_share"] = float(np.mean(["mirror-degenerate" in f for f in res.flags]))
    return out


def sensitivity_rows(cfg, true_gloss: float, per_exponent: dict) -> list[dict]:
    """``sensitivity.csv``'s rows of one sequence: one per exponent and plateau rule."""
    rows = []
    for n, summary in per_exponent.items():
        for rule, value in summary["rules"].items():
            rows.append(
                {
                    "name": cfg.name,
                    "sky": cfg.sky,
                    "material": cfg.material,
                    "specularity": cfg.specularity,
                    "view": cfg.view,
                    "true_gloss": true_gloss,
                    "exponent": n,
                    "rule": rule,
                    "object_gloss": value,
                    "share_mirror_degenerate": summary["share_mirror_degenerate"],
                    "share_no_exact_match": summary["share_no_exact_match"],
                    "plateau_width": summary["plateau_width"],
                    "facets_used": summary["facets_used"],
                    "share_peak_tied": summary["share_peak_tied"],
                    "share_peak_within_1pct": summary["share_peak_within_1pct"],
                }
            )
    return rows


def estimate(path, exponents):
    """Baseline on one bundle for each exponent.

    Returns the default exponent's JSON (as ``paper60.json`` stores it), the
    facet curves, the frame hours [h] and one summary per exponent.
    """
    b = bundle.read_bundle(path)
    curves = bundle.facet_curves(b)
    hours = np.unwrap(sun.local_solar_time(b.times, b.site.longitude), period=24)
    res, per_exponent = estimate_curves(
        curves.luminance,
        curves.valid,
        curves.ids,
        b.view_geometry(),
        b.sun_direction,
        hours,
        exponents,
    )
    out = sequence_entry(res, b.truth, b.truth["config"]["view"])
    return out, curves, hours, per_exponent


def bundle_results(configs, paths, exponents, figure_view=CONFIG["figure_view"]):
    """paper60.json's sequence list, the figure view's curves and the sensitivity table."""
    results, arrays, rows = [], {}, []
    for cfg, path in zip(configs, paths, strict=True):
        est, curves, hours, per_exponent = estimate(path, exponents)
        est["name"] = cfg.name
        results.append(est)
        rows += sensitivity_rows(cfg, est["truth"]["gloss"], per_exponent)
        if cfg.view == figure_view:
            arrays[f"{cfg.name}/luminance"] = curves.luminance
            arrays[f"{cfg.name}/valid"] = curves.valid
            arrays[f"{cfg.name}/ids"] = curves.ids
            arrays[f"{cfg.name}/n_pixels"] = curves.n_pixels
            arrays["hours"] = hours
    return results, arrays, pd.DataFrame(rows)


def curves_results(configs, arrays, exponents):
    """:func:`bundle_results` redone from saved curves (``curves.npz``), no Radiance.

    For each configuration whose curves ``arrays`` holds (the figure view's),
    the facets, camera and sun come from the configuration itself, as the
    bundle was rendered from it. Returns paper60.json's entries of these
    sequences and their sensitivity table.
    """
    results, rows = [], []
    for cfg in configs:
        if f"{cfg.name}/luminance" not in arrays:
            continue
        ids = arrays[f"{cfg.name}/ids"]
        facets = cfg.facets()
        geom = _subset(
            render.view_geometry(facets, cfg.camera_position()), np.searchsorted(facets.ids, ids)
        )
        res, per_exponent = estimate_curves(
            arrays[f"{cfg.name}/luminance"],
            arrays[f"{cfg.name}/valid"],
            ids,
            geom,
            cfg.sun_directions(),
            arrays["hours"],
            exponents,
        )
        truth = cfg.truth()
        results.append(sequence_entry(res, truth, cfg.view) | {"name": cfg.name})
        rows += sensitivity_rows(cfg, truth["gloss"], per_exponent)
    return results, pd.DataFrame(rows)


# -- the method's ceiling on its own model --------------------------------------


def _subset(geom: render.ViewGeometry, keep) -> render.ViewGeometry:
    return render.ViewGeometry(geom.normal[keep], geom.view_direction[keep], geom.center[keep])


def seen_facets(results) -> dict:
    """Per view, ids of the facets the bundles observe (some valid frame)."""
    out = {}
    for s in results:
        if s["view"] not in out:
            out[s["view"]] = [f["id"] for f in s["facets"] if "no-valid-frames" not in f["flags"]]
    return out


def ideal_rows(seen: dict) -> pd.DataFrame:
    """Baseline on noise-free curves of the paper's own model (no sky, point sun)."""
    rows = []
    for view in VIEWS:
        seq = scene.paper_sequence(view)
        geom = _subset(seq.geometry, np.isin(seq.facets.ids, seen[view]))
        sun_dir = seq.sky.sun_direction
        for n_obs in CONFIG["ideal_observed_exponents"]:
            for gamma in CONFIG["ideal_gloss"]:
                lum = render.paper_point_sun(geom, sun_dir, gamma, n_obs)
                valid = np.broadcast_to(sun_dir[:, 2] > 0, lum.shape)
                res = baseline.peak_frame_gloss(
                    lum,
                    valid,
                    geom,
                    sun_dir,
                    exponent=CONFIG["exponent"],
                    frame_hours=seq.solar_hours,
                )
                summary = _object_rules(res)
                for rule, value in summary["rules"].items():
                    rows.append(
                        {
                            "view": view,
                            "observed_exponent": n_obs,
                            "true_gloss": gamma,
                            "rule": rule,
                            "object_gloss": value,
                            "share_mirror_degenerate": summary["share_mirror_degenerate"],
                            "share_no_exact_match": summary["share_no_exact_match"],
                        }
                    )
    return pd.DataFrame(rows)


# -- the paper's unknowns, with the forward model --------------------------------


def forward_object_gloss(seq, geom, kind, spec, colour):
    """Baseline (default exponent) on the forward model's curves of a Radiance material."""
    lum = render.radiance_material_prediction(geom, seq.sky, kind, colour, spec)
    sun_dir = seq.sky.sun_direction
    valid = np.broadcast_to(sun_dir[:, 2] > 0, lum.shape)
    return baseline.peak_frame_gloss(
        lum, valid, geom, sun_dir, exponent=CONFIG["exponent"], frame_hours=seq.solar_hours
    )


def variant_rows() -> pd.DataFrame:
    """Object gloss from the forward model under each scene variant of the config."""
    rows = []
    for variant, overrides in CONFIG["variants"].items():
        colour = overrides.get("colour", scene.PAPER["colour"])
        geo_overrides = {k: v for k, v in overrides.items() if k != "colour"}
        for sky_name in SKIES:
            for view in VIEWS:
                seq = scene.paper_sequence(view, sky_name, **geo_overrides)
                keep = seq.geometry.cos_view > CONFIG["variant_min_cos_view"]
                geom = _subset(seq.geometry, keep)
                for kind in MATERIALS:
                    for spec in SPECULARITIES:
                        res = forward_object_gloss(seq, geom, kind, spec, colour)
                        s = _object_rules(res)
                        rows.append(
                            {
                                "variant": variant,
                                "sky": sky_name,
                                "material": kind,
                                "specularity": spec,
                                "view": view,
                                "true_gloss": float(
                                    reflectance.gloss_of_radiance_material(kind, spec, colour)
                                ),
                                "object_gloss": s["rules"]["median"],
                                "lower": s["rules"]["lower"],
                                "upper": s["rules"]["upper"],
                                "share_no_exact_match": s["share_no_exact_match"],
                                "facets_used": s["facets_used"],
                            }
                        )
    return pd.DataFrame(rows)


def forward_check(results) -> dict:
    """Forward model vs Radiance at the default scene, on the bundles' own facets."""
    diffs, agree = [], []
    for s in results:
        seq = scene.paper_sequence(s["view"], s["truth"]["sky"])
        ids = np.array([f["id"] for f in s["facets"]])
        keep = np.isin(seq.facets.ids, ids)
        geom = _subset(seq.geometry, keep)
        lum = scene.plastic_radiance(seq, s["truth"]["specularity"], kind=s["truth"]["material"])
        lum = lum[keep]
        none = np.array(["no-valid-frames" in f["flags"] for f in s["facets"]])
        valid = (seq.sky.sun_direction[:, 2] > 0)[None, :] & ~none[:, None]
        res = baseline.peak_frame_gloss(
            lum,
            valid,
            geom,
            seq.sky.sun_direction,
            ids=ids,
            exponent=CONFIG["exponent"],
            frame_hours=seq.solar_hours,
        )
        diffs.append(res.object_gloss - s["object"]["gamma"])
        rad = np.array([np.nan if f["gamma"] is None else f["gamma"] for f in s["facets"]])
        agree.append(np.mean(np.isclose(res.gloss, rad)[np.isfinite(rad)]))
    return {
        "max_abs_object_gloss_difference": float(np.max(np.abs(diffs))),
        "mean_abs_object_gloss_difference": float(np.mean(np.abs(diffs))),
        "mean_share_facets_same_gamma": float(np.mean(agree)),
    }


# -- Figs. 3 and 5: the facet and the W view's peak statistics -------------------


def figure_facet(arrays, name="paper-W-plastic-0-clear") -> dict:
    """The facet Figs. 3 and 5 show, by a rule on predictions and pixel counts only.

    Among the figure view's facets with at least ``figure_min_pixels``
    labelled pixels and direct sun, the one whose predicted peak frames for
    gamma 0, 0.2, ..., 1 (paper_point_sun, default exponent) are most
    distinct, as in the paper's Fig. 3; ties go to the facet with more pixels.
    The observations are not looked at.
    """
    ids, n_pix = arrays[f"{name}/ids"], arrays[f"{name}/n_pixels"]
    seq = scene.paper_sequence(CONFIG["figure_view"])
    sun_dir = seq.sky.sun_direction
    gammas = np.linspace(0.0, 1.0, 6)
    idx = np.searchsorted(seq.facets.ids, ids)
    geom = _subset(seq.geometry, idx)
    pred = render.paper_point_sun(geom, sun_dir, gammas[:, None, None], CONFIG["exponent"])
    peaks = np.argmax(pred, axis=-1)  # (6, F)
    distinct = np.array([len(set(peaks[:, f])) for f in range(len(ids))])
    lit = pred[0].max(axis=-1) > 0
    ok = (n_pix >= CONFIG["figure_min_pixels"]) & lit
    score = np.where(ok, distinct * 10_000 + n_pix, -1)
    f = int(np.argmax(score))
    normal = geom.normal[f]
    return {
        "view": CONFIG["figure_view"],
        "facet_id": int(ids[f]),
        "n_pixels": int(n_pix[f]),
        "normal": normal.tolist(),
        "normal_azimuth_deg": float(np.degrees(np.arctan2(normal[0], normal[1])) % 360),
        "normal_elevation_deg": float(np.degrees(np.arcsin(normal[2]))),
        "distinct_predicted_peaks": int(distinct[f]),
        "predicted_peak_frames_1based": (peaks[:, f] + 1).tolist(),
        "rule": figure_facet.__doc__.split("\n\n")[1].replace("\n    ", " ").strip(),
    }


def _peak(lum, valid):
    masked = np.where(valid, lum, -np.inf)
    return np.where(valid.any(axis=1), np.argmax(masked, axis=1), -1)


def peak_stats(arrays, view=CONFIG["figure_view"]) -> dict:
    """Fig. 5's claims over all facets of the view: observed peak frames of matt,
    intermediate and glossy plastic (and metal) under each sky, and how they
    compare with the paper's predicted peaks for gamma 0, 0.5 and 1 (signed
    offsets in frames = hours; negative: observed earlier)."""
    out = {}
    seq = scene.paper_sequence(view)
    for sky_name in SKIES:
        s = sky_name.split("-")[1]

        def get(kind, spec, s=s):
            key = f"paper-{view}-{kind}-{spec:g}-{s}"
            return arrays[f"{key}/luminance"], arrays[f"{key}/valid"]

        (lm, vm), (li, vi), (lg, vg), (lmi, vmi) = (
            get("plastic", 0.0),
            get("plastic", 0.5),
            get("plastic", 1.0),
            get("metal", 0.5),
        )
        pm, pi, pg, pmi = _peak(lm, vm), _peak(li, vi), _peak(lg, vg), _peak(lmi, vmi)
        ok = (pm >= 0) & (pi >= 0) & (pg >= 0)
        ratio = np.max(np.where(vg, lg, 0), axis=1)[ok] / np.max(np.where(vm, lm, 0), axis=1)[ok]
        ids = arrays[f"paper-{view}-plastic-0-{s}/ids"]
        geom = _subset(seq.geometry, np.searchsorted(seq.facets.ids, ids))
        gammas = np.array([0.0, 0.5, 1.0])[:, None, None]
        pred = render.paper_point_sun(geom, seq.sky.sun_direction, gammas, CONFIG["exponent"])
        q0, q5, q1 = (_peak(pr, vm & (pr > 0)) for pr in pred)
        out[s] = {
            "facets": int(ok.sum()),
            "share_all_three_distinct": float(np.mean(((pm != pi) & (pi != pg) & (pm != pg))[ok])),
            "share_intermediate_at_glossy_frame": float(np.mean((pi == pg)[ok])),
            "share_intermediate_at_matt_frame": float(np.mean((pi == pm)[ok])),
            "share_metal_intermediate_at_glossy_frame": float(np.mean((pmi == pg)[ok])),
            "median_ratio_glossy_peak_to_matt_peak": float(np.median(ratio)),
            "share_matt_at_predicted_gamma_0": float(np.mean((pm == q0)[ok])),
            "share_intermediate_at_predicted_gamma_0.5": float(np.mean((pi == q5)[ok])),
            "share_glossy_at_predicted_gamma_1": float(np.mean((pg == q1)[ok])),
            "mean_offset_matt_minus_predicted_gamma_0": float(np.mean((pm - q0)[ok])),
            "mean_offset_glossy_minus_predicted_gamma_1": float(np.mean((pg - q1)[ok])),
        }
    return out


def peak_attribution(seen: dict, view=CONFIG["figure_view"]) -> dict:
    """Why observed peaks miss the paper's predictions, with the forward model.

    Over the view's observed facets: how often a matt facet peaks in the frame
    the paper predicts for gamma 0 when lit by (i) the sun alone at constant
    radiance (the paper's assumption), (ii) the sun alone with its air-mass
    dependent radiance, (iii) sun, sky and ground (as Radiance renders it); and
    how often a mirror (roughness-0 glossy) facet peaks in the frame predicted
    for gamma 1 at each sensitivity exponent. Offsets: mean observed minus
    predicted frame (= hours).
    """
    out = {}
    for sky_name in SKIES:
        seq = scene.paper_sequence(view, sky_name)
        geom = _subset(seq.geometry, np.isin(seq.facets.ids, seen[view]))
        sun_dir = seq.sky.sun_direction
        up = sun_dir[:, 2] > 0
        valid = np.broadcast_to(up, (len(geom), len(sun_dir)))
        sky_part, sun_part = render.diffuse_components(geom, seq.sky)
        solar = np.asarray(seq.sky.solar_radiance, float)
        constant_sun = np.where(up, sun_part / np.where(solar > 0, solar, 1.0), 0.0)
        pred0 = _peak(render.paper_point_sun(geom, sun_dir, 0.0, 1.0), valid)
        lit = pred0 >= 0
        res = {}
        for name, lum in (
            ("matt_sun_constant_radiance", constant_sun),
            ("matt_sun_with_air_mass", sun_part),
            ("matt_sun_sky_ground", sun_part + sky_part),
        ):
            pk = _peak(lum, valid)
            res[name] = {
                "share_at_predicted_gamma_0": float(np.mean((pk == pred0)[lit])),
                "mean_offset_frames": float(np.mean((pk - pred0)[lit])),
            }
        mirror = _peak(render.mirror_radiance(geom, seq.sky), valid)
        for n in CONFIG["sensitivity_exponents"]:
            pred1 = _peak(render.paper_point_sun(geom, sun_dir, 1.0, n), valid)
            ok = lit & (pred1 >= 0)
            res[f"mirror_vs_gamma_1_n{n:g}"] = {
                "share_at_predicted_gamma_1": float(np.mean((mirror == pred1)[ok])),
                "mean_offset_frames": float(np.mean((mirror - pred1)[ok])),
            }
        out[sky_name.split("-")[1]] = res
    return out


def material_separation(results) -> dict:
    """Per sky and view: mean |gamma(glossy) - gamma(matt)| of plastic facets, over
    the mirror-degenerate and over the other sunlit facets."""
    by = {
        (s["truth"]["sky"], s["truth"]["material"], s["truth"]["specularity"], s["view"]): s
        for s in results
    }
    out = {}
    for sky_name in SKIES:
        for view in VIEWS:
            matt = by[(sky_name, "plastic", 0.0, view)]["facets"]
            gloss = by[(sky_name, "plastic", 1.0, view)]["facets"]
            deg, sep = [], []
            for f, g in zip(matt, gloss, strict=True):
                if f["gamma"] is None or "no-direct-sun" in f["flags"]:
                    continue
                deg.append("mirror-degenerate" in f["flags"])
                sep.append(abs(g["gamma"] - f["gamma"]))
            deg, sep = np.array(deg), np.array(sep)
            out[f"{sky_name.split('-')[1]}/{view}"] = {
                "share_mirror_degenerate": float(deg.mean()),
                "degenerate": float(sep[deg].mean()) if deg.any() else float("nan"),
                "other": float(sep[~deg].mean()),
            }
    return out


def view_leverage() -> dict:
    """Per view, the mean |frame of predicted peak at gamma 1 - at gamma 0| over the
    facets with direct sun (paper_point_sun, default exponent): how far apart the
    method's matt and glossy predictions lie, in frames."""
    out = {}
    for view in VIEWS:
        seq = scene.paper_sequence(view)
        geom = _subset(seq.geometry, seq.geometry.cos_view > CONFIG["variant_min_cos_view"])
        pred = render.paper_point_sun(
            geom, seq.sky.sun_direction, np.array([0.0, 1.0])[:, None, None], CONFIG["exponent"]
        )
        lit = pred[0].max(axis=-1) > 0
        pk = np.argmax(pred, axis=-1)
        out[view] = float(np.mean(np.abs(pk[1] - pk[0])[lit]))
    return out


# -- tables ---------------------------------------------------------------------


def _wide(df: pd.DataFrame, index, value="object_gloss") -> pd.DataFrame:
    t = df.pivot_table(index=index, columns="view", values=value, aggfunc="first")
    return t[[v for v in VIEWS if v in t.columns]]


def _markdown(t: pd.DataFrame) -> str:
    """A wide table as GitHub markdown (index levels first, values to 2 decimals)."""
    names = [str(n) for n in t.index.names] + [str(c) for c in t.columns]
    lines = ["| " + " | ".join(names) + " |", "|" + " --- |" * len(names)]
    for key, row in t.iterrows():
        key = key if isinstance(key, tuple) else (key,)
        cells = [f"{k:g}" if isinstance(k, float) else str(k) for k in key]
        cells += [f"{v:.2f}" for v in row]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def tables_markdown(sens: pd.DataFrame, ideal: pd.DataFrame, variants: pd.DataFrame) -> str:
    parts = ["# Tables (written by compute_results.py)\n"]
    parts.append("## Sensitivity: object gloss by exponent and plateau rule (Radiance bundles)\n")
    t = _wide(sens, ["sky", "material", "specularity", "true_gloss", "exponent", "rule"])
    parts.append(_markdown(t))
    parts.append("## Share of sunlit facets flagged, by exponent (Radiance bundles)\n")
    med = sens[sens.rule == "median"]
    cols = ("share_no_exact_match", "share_mirror_degenerate", "plateau_width")
    for col in cols + ("share_peak_tied", "share_peak_within_1pct"):
        parts.append(f"### {col}\n")
        index = ["sky", "material", "specularity"] + (["exponent"] if col in cols else [])
        t = _wide(med[med.exponent == CONFIG["exponent"]] if col not in cols else med, index, col)
        parts.append(_markdown(t))
    parts.append("## Ideal data: the paper's own model as observations, estimated with n = 2\n")
    t = _wide(ideal, ["observed_exponent", "true_gloss", "rule"])
    parts.append(_markdown(t))
    parts.append("## Scene variants (forward model, n = 2, median rule)\n")
    t = _wide(variants, ["variant", "sky", "material", "specularity", "true_gloss"])
    parts.append(_markdown(t))
    return "\n".join(parts)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--cache", default=CONFIG["cache"], help="bundle cache folder")
    p.add_argument("--size", type=int, default=CONFIG["image_size"], help="image size [px]")
    p.add_argument("--jobs", type=int, default=2, help="Radiance processes at once")
    p.add_argument("--out", default=str(HERE / "results"), help="results folder")
    args = p.parse_args(argv)
    configs = sequences.paper_configs(image_size=args.size)
    paths = sequences.render_bundles(configs, args.cache, jobs=args.jobs)
    results, arrays, sens = bundle_results(configs, paths, CONFIG["sensitivity_exponents"])
    ideal = ideal_rows(seen_facets(results))
    variants = variant_rows()
    summary = {
        "figure_facet": figure_facet(arrays),
        "peak_stats": peak_stats(arrays),
        "view_leverage_frames": view_leverage(),
        "peak_attribution": peak_attribution(seen_facets(results)),
        "material_separation": material_separation(results),
        "forward_model_check": forward_check(results),
    }
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    config = {"image_size": args.size, "exponent": CONFIG["exponent"]}
    (out / "paper60.json").write_text(
        json.dumps({"config": config, "sequences": results}, indent=1)
    )
    np.savez_compressed(out / "curves.npz", **arrays)
    sens.to_csv(out / "sensitivity.csv", index=False, float_format="%.9g")
    ideal.to_csv(out / "ideal.csv", index=False, float_format="%.9g")
    variants.to_csv(out / "variants.csv", index=False, float_format="%.9g")
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    (out / "tables.md").write_text(tables_markdown(sens, ideal, variants))
    print(f"wrote results to {out}")


if __name__ == "__main__":
    main()

"""The coating's forward model at the truth against Mitsuba's plastics, facet by facet (stop 52).

``forward_check.py`` asks of Radiance's renders whether the forward model
makes the light the renderer makes; this asks it of Mitsuba's
``plastic`` and ``roughplastic`` (a dielectric coating over a diffuse
base), where the lobe stack mostly gives its weight to ``ggx-schlick``
and the default reads many-facet plastics too glossy (seen Mitsuba
holdouts 4 and 5: +0.09 over 16). Each seen sequence is rendered again by
Mitsuba without what the estimator must infer (linear radiance, no
exposure change, no sensor noise: ``forward_check.clean_config``), and
each facet's luminance curve is divided by the forward model's prediction
for the true material under the true sky (:func:`bayesgloss.mitsuba_render.frame_skies`,
the sky Mitsuba's environment map and sun disc hold), with the convex
object's ground shadow (the estimator's default). A right model gives
every facet the same ratio in every frame; the spread of the log ratios
about one common value is what a fit must put into gloss, the sky's
latent brightnesses, or its residuals.

The material in the model's terms: gamma and A = R_s + R_d from the
material's luminance albedos at normal incidence (the bundle's truth),
GGX of the material's alpha (a smooth ``plastic`` at the exponent
table's end, alpha 0.014), Fresnel strength k = 1. Models compared (each
the GGX lobe with Smith shadowing, :mod:`bayesgloss.lobes`):

``none``
    no Fresnel term: A [(1 - gamma) D + gamma G] (``--lobe ggx``);
``view-rise``
    Schlick's rise at the view, :func:`bayesgloss.fresnel.fresnel_parts`
    (the lobe stack's ``ggx-schlick`` until stop 51);
``in-lobe``
    the rise inside the lobe, :func:`bayesgloss.fresnel.fresnel_parts_in_lobe`
    with the smooth coating's transmission 1 - S(c) (branch
    ``schlick-in-lobe``, holdout 18's second candidate; the default's
    ``ggx-schlick`` since stop 55).

Beside the spread at the truth, :func:`gamma_scan` finds the gamma whose
prediction leaves the least spread (the exposure free, the sky and its
brightness and the material's albedo and lobe the truth's): what a fit
told the light would read with no noise. ``--sequences SET/NAME ...``
checks other seen sequences (stop 68: Mitsuba's plastic boxes).

    python studies/forward_check_mitsuba.py [--threads 2] [--sequences SET/NAME ...] [--json FILE]
        [--lobe-scan]

``--lobe-scan`` (stop 74) adds, per sequence, :func:`lobe_scan`: for each
lobe the stack fits (Phong and GGX without Fresnel, GGX with the coating's
rise in the lobe), the exponent and gamma whose prediction under the true
light leaves the least spread, with one albedo for the object and with a
free albedo per facet (the freedom the one-material model's hierarchical
albedo gives a few-facet object).

Renders go to ``studies/out/forward_check_mitsuba/bundles`` (cached),
answers to ``studies/results/forward_check_mitsuba.json``. A development
tool on seen sequences: it decides nothing. (Stop 52's fourth model, the
rough coating's transmission, was on a branch never merged; the script
computes the three models main has.)
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import forward_check  # noqa: E402
import mitsuba_set  # noqa: E402
from code_under_test import check as check_code  # noqa: E402

from bayesgloss import bundle as bundle_io  # noqa: E402
from bayesgloss import fresnel as fr  # noqa: E402
from bayesgloss import illumination as il  # noqa: E402
from bayesgloss import mitsuba_render as mr  # noqa: E402
from bayesgloss import render  # noqa: E402
from bayesgloss.object_shadow import averaged_bases, shadow_points  # noqa: E402

CACHE = HERE / "out" / "forward_check_mitsuba" / "bundles"
RESULT = HERE / "results" / "forward_check_mitsuba.json"
#: Seen many-facet plastics of Mitsuba holdouts 4 and 5 (set, sequence name).
SEQUENCES = (
    ("mitsuba_holdout4", "ms01-rough-plastic"),
    ("mitsuba_holdout4", "ms04-smooth-plastic"),
    ("mitsuba_holdout4", "ms06-rough-plastic"),
    ("mitsuba_holdout4", "ms08-rough-plastic"),
    ("mitsuba_holdout4", "ms17-smooth-plastic"),
    ("mitsuba_holdout4", "ms22-smooth-plastic"),
    ("mitsuba_holdout5", "ms04-rough-plastic"),
    ("mitsuba_holdout5", "ms09-smooth-plastic"),
    ("mitsuba_holdout5", "ms16-rough-plastic"),
    ("mitsuba_holdout5", "ms17-smooth-plastic"),
    ("mitsuba_holdout5", "ms18-rough-plastic"),
)
#: The exponent of a smooth coating: the exponent table's end (alpha 0.014).
SMOOTH_EXPONENT = 1.0e4
#: The forward models compared; ``rough-transmission`` (stop 52's branch,
#: not merged) is no longer computed.
MODELS = ("none", "view-rise", "in-lobe")
#: gamma of the scan (:func:`gamma_scan`).
GAMMA_GRID = np.linspace(0.0, 1.0, 101)
#: The lobes of :func:`lobe_scan`: (lobe family, Fresnel model), as the
#: lobe stack fits them (:data:`bayesgloss.lobe_families.MATERIAL_FAMILIES`).
SCAN_LOBES = (("phong", "none"), ("ggx", "none"), ("ggx", "schlick-lobe"))


def clean_sequence(set_name: str, name: str) -> mr.MitsubaSequence:
    """The seen sequence with the clean camera of ``forward_check.clean_config``."""
    config = mitsuba_set.load_config(HERE / "configs" / f"{set_name}.json")
    item = next(s for s in mitsuba_set.draw_sequences(config) if s.config.name == name)
    clean = forward_check.clean_config(item.config.to_dict())
    return mr.MitsubaSequence(clean, item.material, item.spp, item.seed)


def true_material(b, sequence: mr.MitsubaSequence) -> tuple[float, float, float]:
    """The material in the model's terms from the bundle's truth: albedo A =
    R_s + R_d and gamma = R_s / A at normal incidence (luminance), and the
    Phong-equivalent exponent of its alpha (a smooth one at the table's end)."""
    y = np.asarray(mr._WEIGHTS)
    r_s = float(np.asarray(b.truth["albedo_specular"]) @ y)
    r_d = float(np.asarray(b.truth["albedo_diffuse"]) @ y)
    alpha = sequence.material.alpha
    n = SMOOTH_EXPONENT if alpha == 0 else 2.0 / alpha**2 - 2.0
    return r_s + r_d, r_s / (r_s + r_d), n


def true_bases(
    b,
    checked,
    sequence: mr.MitsubaSequence,
    exponents,
    lobes=(("ggx", "schlick-lobe"),),
) -> dict:
    """Bases of the ``checked`` facets under the true sky, tabulated on
    ``exponents``, for each (lobe family, Fresnel model) of ``lobes`` (GGX
    with Schlick's rise in the lobe by default; other families with the
    view's Schlick terms, which a lobe without Fresnel leaves unused), the
    convex ground shadow averaged over each facet's points; the sky and the
    points are made once for all lobes."""
    day = mr.frame_skies(sequence.config)
    points, owner = shadow_points(b.facets, b.camera_position, which=checked)
    out = {}
    for family, fresnel in lobes:
        bases = il.illumination_bases(
            points,
            day,
            exponents=exponents,
            lobe_family=family,
            fresnel="schlick-lobe" if family == "ggx" else "schlick",
            ground="plane",
            ground_reflectance=sequence.config.ground_reflectance,
        )
        out[family, fresnel] = averaged_bases(bases, owner, int(checked.sum()))
    return out


def model_predictions(bases, albedo: float, gamma) -> dict:
    """Each model's radiance of the facets for ``gamma`` (a scalar, or an
    array (G,) of them), (G, F, T), at the bases' first exponent, the
    Fresnel strength k = 1: ``none`` and ``in-lobe`` are
    :func:`lobe_predictions`' (without Fresnel, with the rise in the lobe)."""
    gamma = np.atleast_1d(np.asarray(gamma, float))
    terms = bases.fresnel
    view_rise = 0.0
    g4 = gamma[:, None, None, None]  # (G, 1, 1, 1)
    for p in (0, 1):  # the sun, the sky (one sky model: source 2 is its copy)
        d = bases.diffuse[p][:, None, :]  # (F, 1, T)
        g = bases.glossy[p][:, :1, :]
        sun = terms.sun_direct if p == 0 else None
        base = (1 - g4) * d + g4 * g
        view_rise = view_rise + albedo * fr.fresnel_parts(
            base, g, 1.0, np.log(albedo), terms.view, sun, g4
        )
    out = {
        "none": lobe_predictions(bases, albedo, "none", gamma),
        "view-rise": view_rise,
        "in-lobe": lobe_predictions(bases, albedo, "schlick-lobe", gamma),
    }
    return {m: out[m][:, :, 0, :] for m in MODELS}


def gamma_scan(y, bases, albedo: float) -> dict:
    """Per model, the gamma whose prediction leaves the least spread of log
    (y / model) about one common value (``forward_check.spreads``' object
    sd, as at the truth; the exposure, free in every fit):
    what a fit told the true sky, its brightness and the material's
    albedo and lobe would read with no noise. Its spread beside it."""
    out = {}
    for m, pred in model_predictions(bases, albedo, GAMMA_GRID).items():
        sd = np.array([forward_check.spreads(y, p)["object_sd"] for p in pred])
        best = int(np.nanargmin(sd))
        out[m] = {"gamma": float(GAMMA_GRID[best]), "object_sd": float(sd[best])}
    return out


def lobe_predictions(bases, albedo: float, fresnel: str, gamma) -> np.ndarray:
    """Radiance of the facets (G, F, K, T) for each gamma of ``gamma`` (G,)
    and each exponent K of ``bases``: the lobe without Fresnel, or with the
    coating's rise inside it (``"schlick-lobe"``), Fresnel strength k = 1."""
    gamma = np.asarray(gamma, float)[:, None, None, None]  # (G, 1, 1, 1)
    terms = bases.fresnel
    out = 0.0
    for p in (0, 1):  # the sun, the sky
        d = bases.diffuse[p][:, None, :]  # (F, 1, T)
        g = bases.glossy[p]  # (F, K, T)
        if fresnel == "none":
            out = out + albedo * ((1 - gamma) * d + gamma * g)
        else:
            sun = terms.sun_direct if p == 0 else None
            out = out + albedo * fr.fresnel_parts_in_lobe(
                d, g, terms.glossy_rise[p], 1.0, np.log(albedo), terms.view, gamma, sun
            )
    return out


def spread_one_and_per_facet(y, pred) -> tuple[np.ndarray, np.ndarray]:
    """The sd of log(y / pred) over all entries about one common value (one
    albedo and the exposure free) and about each facet's own value (a free
    albedo per facet), for ``pred`` (..., F, T) against ``y`` (F, T); entries
    where either is not positive are left out."""
    r = forward_check.log_ratio(y, pred)
    one = np.nanstd(r.reshape(*r.shape[:-2], -1), axis=-1)
    per = np.sqrt(np.nanmean((r - np.nanmean(r, axis=-1, keepdims=True)) ** 2, axis=(-2, -1)))
    return one, per


def lobe_scan(y, bases_by_lobe: dict, albedo: float, exponents) -> dict:
    """Per lobe of ``bases_by_lobe`` ((family, fresnel) -> bases tabulated on
    ``exponents``), the exponent and gamma (:data:`GAMMA_GRID`) of least
    spread with one albedo and with a free albedo per facet
    (:func:`spread_one_and_per_facet`): what the curves under the true
    light say of each lobe, before any light is inferred."""
    out = {}
    for (family, fresnel), bases in bases_by_lobe.items():
        pred = lobe_predictions(bases, albedo, fresnel, GAMMA_GRID)  # (G, F, K, T)
        one, per = spread_one_and_per_facet(y, np.moveaxis(pred, 2, 1))  # (G, K)
        row = {}
        for key, sd in (("one_albedo", one), ("albedo_per_facet", per)):
            g, k = np.unravel_index(int(np.nanargmin(sd)), sd.shape)
            row[key] = {
                "gamma": float(GAMMA_GRID[g]),
                "exponent": float(exponents[k]),
                "sd": float(sd[g, k]),
            }
        out[f"{family}-{fresnel}"] = row
    return out


def check(path: Path, sequence: mr.MitsubaSequence, scan_lobes: bool = False) -> dict:
    """One clean render against each model: the spread at the truth
    (``forward_check.spreads``) and the gamma scan."""
    b = bundle_io.read_bundle(path)
    y, checked, _ = forward_check.checked_entries(b)
    albedo, gamma, n = true_material(b, sequence)
    out = {
        "name": sequence.config.name.removesuffix("-clean"),
        "kind": sequence.material.kind,
        "shape": sequence.config.shape,
        "alpha": sequence.material.alpha,
        "gloss": b.truth["gloss"],
        "sky": sequence.config.sky,
        "facets": int(checked.sum()),
        "normal_z": np.asarray(b.facets.normal)[checked, 2].round(3).tolist(),
    }
    if checked.any():
        bases = true_bases(b, checked, sequence, [n])["ggx", "schlick-lobe"]
        at_truth = model_predictions(bases, albedo, gamma)
        for m in MODELS:
            out[m] = forward_check.spreads(y[checked], at_truth[m][0])
        out["scan"] = gamma_scan(y[checked], bases, albedo)
        if scan_lobes:
            ex = np.asarray(render.DEFAULT_EXPONENTS)
            out["lobe_scan"] = lobe_scan(
                y[checked], true_bases(b, checked, sequence, ex, SCAN_LOBES), albedo, ex
            )
    return out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument(
        "--sequences",
        nargs="*",
        default=None,
        metavar="SET/NAME",
        help="sequences to check, e.g. mitsuba_holdout14/ms15-smooth-plastic "
        "(default: the seen many-facet plastics of SEQUENCES)",
    )
    ap.add_argument("--json", type=Path, default=RESULT)
    ap.add_argument("--lobe-scan", action="store_true", help="add lobe_scan's answer per sequence")
    args = ap.parse_args(argv)
    check_code("forward_check_mitsuba")  # a candidate's worktree on PYTHONPATH is the code run
    chosen = [tuple(s.split("/", 1)) for s in args.sequences] if args.sequences else SEQUENCES
    rows = []
    for set_name, name in chosen:
        seq = clean_sequence(set_name, name)
        path = mr.render_bundles([seq], CACHE / set_name, threads=args.threads, progress=False)[0]
        r = check(Path(path), seq, args.lobe_scan)
        r["set"] = set_name
        rows.append(r)
        cells = " ".join(
            f"{m} {r[m]['object_sd']:.3f} (best gamma {r['scan'][m]['gamma']:.2f}, "
            f"{r['scan'][m]['object_sd']:.3f})"
            for m in MODELS
            if m in r
        )
        print(
            f"{set_name}/{r['name']:22s} {r['shape']:9s} gamma {r['gloss']:.3f} "
            f"F={r['facets']:3d} object sd at the truth: {cells}",
            flush=True,
        )
        for lobe, row in r.get("lobe_scan", {}).items():
            print("   ", lobe, *(f"{k}: {v}" for k, v in row.items()), flush=True)
        args.json.write_text(json.dumps({"sequences": rows}, indent=1) + "\n")
    for m in MODELS:
        sd = [r[m]["object_sd"] for r in rows if m in r]
        print(f"{m}: median object sd {np.median(sd):.3f} over {len(sd)}")


if __name__ == "__main__":
    main()

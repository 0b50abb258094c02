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
    ``schlick-in-lobe``, holdout 18's second candidate);
``rough-transmission``
    ``in-lobe`` with the rough coating's transmission 1 - E^S(c; alpha)
    at the view and the sun (:func:`bayesgloss.lobes.ggx_schlick_rise_albedo`).

Run with the code of a commit that has all four (branch
``rough-transmission``) on ``PYTHONPATH``::

    PYTHONPATH=<worktree> python studies/forward_check_mitsuba.py [--threads 2]

Renders go to ``studies/out/forward_check_mitsuba/bundles`` (cached),
answers to ``studies/results/forward_check_mitsuba.json``. A development
tool on seen sequences: it decides nothing.
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

from bayesgloss import bundle as bundle_io  # noqa: E402
from bayesgloss import fresnel as fr  # noqa: E402
from bayesgloss import illumination as il  # noqa: E402
from bayesgloss import mitsuba_render as mr  # noqa: E402
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
MODELS = ("none", "view-rise", "in-lobe", "rough-transmission")


def clean_sequence(set_name: str, name: str) -> mr.MitsubaSequence:
    """The seen sequence with the clean camera of ``forward_check.clean_config``."""
    config = mitsuba_set.load_config(HERE / "configs" / f"{set_name}.json")
    item = next(s for s in mitsuba_set.draw_sequences(config) if s.config.name == name)
    clean = forward_check.clean_config(item.config.to_dict())
    return mr.MitsubaSequence(clean, item.material, item.spp, item.seed)


def model_predictions(b, checked, sequence: mr.MitsubaSequence) -> dict:
    """Each model's radiance of the ``checked`` facets at the truth, (F, T)."""
    truth = b.truth
    y = np.asarray(mr._WEIGHTS)
    r_s, r_d = (
        float(np.asarray(truth["albedo_specular"]) @ y),
        float(np.asarray(truth["albedo_diffuse"]) @ y),
    )
    albedo, gamma = r_s + r_d, r_s / (r_s + r_d)
    alpha = sequence.material.alpha
    n = SMOOTH_EXPONENT if alpha == 0 else 2.0 / alpha**2 - 2.0
    day = mr.frame_skies(sequence.config)
    points, owner = shadow_points(b.facets, b.camera_position, which=checked)
    bases = il.illumination_bases(
        points,
        day,
        exponents=[n],
        lobe_family="ggx",
        fresnel="schlick",
        ground="plane",
        ground_reflectance=sequence.config.ground_reflectance,
    )
    bases = averaged_bases(bases, owner, int(checked.sum()))
    terms = bases.fresnel
    log_a = np.log(albedo)
    out = {m: 0.0 for m in MODELS}
    for p in (0, 1):  # the sun, the sky
        d = bases.diffuse[p][:, None, :]  # (F, 1, T)
        g = bases.glossy[p][:, :1, :]
        g_s = bases.glossy_rise[p][:, :1, :]
        sun = terms.sun_direct if p == 0 else None
        sun_rough = terms.sun_direct_nodes[:, 0] if p == 0 else None
        base = (1 - gamma) * d + gamma * g
        out["none"] = out["none"] + albedo * base
        out["view-rise"] = out["view-rise"] + albedo * fr.fresnel_parts(
            base, g, 1.0, log_a, terms.view, sun, gamma
        )
        out["in-lobe"] = out["in-lobe"] + albedo * fr.fresnel_parts_in_lobe(
            d, g, g_s, 1.0, log_a, terms.view, sun, gamma
        )
        out["rough-transmission"] = out["rough-transmission"] + albedo * fr.fresnel_parts_in_lobe(
            d, g, g_s, 1.0, log_a, terms.view_nodes[:, 0], sun_rough, gamma
        )
    return {m: v[:, 0, :] for m, v in out.items()}


def check(path: Path, sequence: mr.MitsubaSequence) -> dict:
    """One clean render against each model of :func:`model_predictions`."""
    b = bundle_io.read_bundle(path)
    y, checked, _ = forward_check.checked_entries(b)
    out = {
        "name": sequence.config.name.removesuffix("-clean"),
        "kind": sequence.material.kind,
        "alpha": sequence.material.alpha,
        "gloss": b.truth["gloss"],
        "sky": sequence.config.sky,
        "facets": int(checked.sum()),
    }
    if checked.any():
        for m, pred in model_predictions(b, checked, sequence).items():
            out[m] = forward_check.spreads(y[checked], pred)
    return out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--threads", type=int, default=1)
    args = ap.parse_args(argv)
    rows = []
    for set_name, name in SEQUENCES:
        seq = clean_sequence(set_name, name)
        path = mr.render_bundles([seq], CACHE / set_name, threads=args.threads, progress=False)[0]
        r = check(Path(path), seq)
        r["set"] = set_name
        rows.append(r)
        cells = " ".join(f"{m} {r[m]['object_sd']:.3f}" for m in MODELS if m in r)
        print(
            f"{set_name}/{r['name']:22s} {r['kind']:12s} F={r['facets']:3d} object sd: {cells}",
            flush=True,
        )
        RESULT.write_text(json.dumps({"sequences": rows}, indent=1) + "\n")
    for m in MODELS:
        sd = [r[m]["object_sd"] for r in rows if m in r]
        print(f"{m}: median object sd {np.median(sd):.3f} over {len(sd)}")


if __name__ == "__main__":
    main()

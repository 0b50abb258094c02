"""The gloss Mitsuba renders for a smooth metal blended with a diffuse base (stop 52).

:mod:`bayesgloss.mitsuba_render` makes a smooth metal's gloss below 1 by
``blendbsdf`` of a ``conductor`` (a delta lobe) and a Lambertian base, and
its "Smooth metals" says Mitsuba 3's ``blendbsdf`` weights a sample of the
delta lobe by the blend's mixture density, not by the blend weight w. The
bundle's truth (:func:`bayesgloss.mitsuba_render.true_gloss`) reads each
component on its own, a path without the fault. This script reads the
blend as the path tracer does, sampling every component at once at normal
incidence (20000 draws, seed 0: about 1 %), and calls gloss the sampled
delta part's share: the gloss of what the frames hold. A render of the
material itself agrees (:func:`rendered_gloss`: 0.096, 0.212 and 0.636
against the sampled 0.095, 0.210 and 0.624 at w = 0.054, 0.1 and 0.3, for
truths of 0.270, 0.416 and 0.733; its diffuse part is rendered right,
0.1352 against 0.1352 at w = 0.054). Printed per
smooth metal of each Mitsuba set given, beside the manifest's truth and
the default's answer where the set is scored::

    python studies/blend_truth.py mitsuba_holdout4 mitsuba_holdout7 [--json]

(``--json`` writes ``results/blend_truth_<set>.json``, which
``holdout_rule.py --blend-truth`` reads.)

A diagnosis on seen sets: the truth the sets are scored on is unchanged.
Since stop 53 a smooth metal is rendered with a narrow GGX lobe instead
(:mod:`bayesgloss.mitsuba_render`, "Smooth metals"); this script reads the
blends as the sets drawn before then were rendered (:func:`delta_blend`).
"""

import json
import sys
from pathlib import Path

import numpy as np

from bayesgloss import mitsuba_render as mr

RESULTS = Path(__file__).resolve().parent / "results"


def sampled_gloss(material: mr.MitsubaMaterial, n: int = 20000, seed: int = 0) -> float:
    """The delta lobe's share of the blend's sampled albedo at normal incidence [-]."""
    mi = mr._mitsuba()
    y = np.asarray(mr._WEIGHTS)
    bsdf = mi.load_dict(delta_blend(material))
    ctx = mi.BSDFContext()
    si = mi.SurfaceInteraction3f()
    si.wi = mi.Vector3f(0, 0, 1)
    rng = np.random.default_rng(seed)
    spec = diff = 0.0
    for a, b, c in rng.random((n, 3)):
        sample, weight = bsdf.sample(ctx, si, float(a), mi.Point2f(float(b), float(c)))
        value = float(np.array(weight).reshape(3) @ y)
        if mi.has_flag(sample.sampled_type, mi.BSDFFlags.Delta):
            spec += value
        else:
            diff += value
    return spec / (spec + diff)


def delta_blend(material: mr.MitsubaMaterial) -> dict:
    """The BSDF a smooth metal was rendered with before stop 53: the blend
    with Mitsuba's smooth ``conductor`` (a delta lobe) in place of the narrow
    GGX lobe :mod:`bayesgloss.mitsuba_render` renders it with now."""
    bsdf = material.bsdf()
    if material.kind == "conductor":
        metal = {k: v for k, v in bsdf["bsdf_1"].items() if k not in ("distribution", "alpha")}
        bsdf = {**bsdf, "bsdf_1": {**metal, "type": "conductor"}}
    return bsdf


def rendered_gloss(material: mr.MitsubaMaterial, spp: int = 4096) -> float:
    """The gloss the path tracer renders for the material as the sets of
    stops 35-52 rendered it (:func:`delta_blend`,
    :func:`bayesgloss.mitsuba_render.rendered_gloss`) [-]."""
    return mr.rendered_gloss(material, spp, bsdf=delta_blend(material))


def main(argv=None) -> None:
    args = list(sys.argv[1:] if argv is None else argv)
    write = "--json" in args
    for set_name in [a for a in args if a != "--json"]:
        sampled = {}
        manifest = json.loads((RESULTS / f"{set_name}.json").read_text())
        scored = RESULTS / f"validation_{set_name}.json"
        answers = {}
        if scored.exists():
            for s in json.loads(scored.read_text())["sequences"]:
                answers[s["bundle"].split("-")[0]] = s
        for item in manifest["sequences"]:
            mat = item["material"]
            if mat["kind"] != "conductor" or mat["weight"] >= 1:
                continue
            g = sampled_gloss(mr.MitsubaMaterial.from_dict(mat))
            key = item["name"].split("-")[0]
            sampled[key] = {
                "name": item["name"],
                "weight": mat["weight"],
                "truth": item["gloss"],
                "sampled": g,
            }
            line = f"{set_name} {item['name']} w {mat['weight']:.3f} truth {item['gloss']:.3f}"
            line += f" sampled {g:.3f}"
            s = answers.get(key)
            if s and "perez" in s:
                p = s["perez"]
                line += f" default {p['median']:.3f} [{p['hdi90'][0]:.2f}, {p['hdi90'][1]:.2f}]"
                line += f" sun-lit {s['direct_sun']}"
            print(line, flush=True)
        if write:  # for holdout_rule.py --blend-truth
            out = RESULTS / f"blend_truth_{set_name}.json"
            out.write_text(json.dumps({"set": set_name, "sequences": sampled}, indent=1) + "\n")
            print(f"wrote {out}")


if __name__ == "__main__":
    main()

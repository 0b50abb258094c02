"""The gloss Mitsuba renders for a smooth metal blended with a diffuse base (stop 52).

:mod:`bayesgloss.mitsuba_render` makes a smooth metal's gloss below 1 by
``blendbsdf`` of a ``conductor`` (a delta lobe) and a Lambertian base, and
its "Known limit" says Mitsuba 3's ``blendbsdf`` weights a sample of the
delta lobe by the blend's mixture density, not by the blend weight w. The
bundle's truth (:func:`bayesgloss.mitsuba_render.true_gloss`) reads each
component on its own, a path without the fault. This script reads the
blend as the path tracer does, sampling every component at once at normal
incidence (20000 draws, seed 0: about 1 %), and calls gloss the sampled
delta part's share: the gloss of what the frames hold, if the diffuse
part is rendered right (stop 35 measured it 9-31 % high on a rendered
plane at w = 0.1, so the frames may hold less gloss still). Printed per
smooth metal of each Mitsuba set given, beside the manifest's truth and
the default's answer where the set is scored::

    python studies/blend_truth.py mitsuba_holdout4 mitsuba_holdout7

A diagnosis on seen sets: the truth the sets are scored on is unchanged.
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
    bsdf = mi.load_dict(material.bsdf())
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


def main(argv=None) -> None:
    for set_name in argv if argv is not None else sys.argv[1:]:
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
            line = f"{set_name} {item['name']} w {mat['weight']:.3f} truth {item['gloss']:.3f}"
            line += f" rendered {g:.3f}"
            s = answers.get(item["name"].split("-")[0])
            if s and "perez" in s:
                p = s["perez"]
                line += f" default {p['median']:.3f} [{p['hdi90'][0]:.2f}, {p['hdi90'][1]:.2f}]"
                line += f" sun-lit {s['direct_sun']}"
            print(line, flush=True)


if __name__ == "__main__":
    main()

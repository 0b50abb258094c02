"""Calibration of the object's gamma pooled over unseen holdouts, per renderer and material class.

Each holdout holds 2-9 sun-lit sequences of a material class, too few for a
coverage to mean much (issue "Gloss that means the material's gloss" asks
for 85-97 % per renderer and class). This pools the committed scores of
the holdouts scored with one estimator (``--radiance``, ``--mitsuba``:
names of ``validate_radiance.SETS``; defaults, the sets scored with today's
default: Radiance holdouts 8, 9 and 10 (holdout 10 scored the lobe stack,
today's default, only), Mitsuba holdouts 2 and 3) and draws nominal against
observed coverage of the central
intervals per class (``validate_radiance.calibration_figure``: each
score's PIT, the reported posterior's CDF at the truth, with the model's
error), with the 90 % interval's cover and its binomial 90 % range beside.
Fits nothing.

    python studies/calibration_pooled.py [--radiance validation_holdout8 ...]
        [--mitsuba mitsuba_holdout2 ...] [--methods families materials] [--out FILE]

Writes ``results/calibration_pooled.json`` (or ``--out``) with the cover
per class and per sky type, and one figure per renderer,
``results/calibration_pooled_{radiance,mitsuba}.png`` (named after ``--out``).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from scipy import stats
from validate_radiance import RESULTS, SETS, _holds, calibration_figure

#: The holdouts scored with today's default estimator, per renderer. A
#: Mitsuba holdout 3 scored only in part is left out (its results say how
#: many of its bundles were scored; see ``complete``).
DEFAULT_SETS = {
    "radiance": ("validation_holdout8", "validation_holdout9", "validation_holdout10"),
    "mitsuba": ("mitsuba_holdout2", "mitsuba_holdout3"),
}
#: Sequences in each set (a set whose results hold fewer is partly scored).
SET_SIZE = 24


def load(set_name: str) -> list[dict] | None:
    """A set's committed scores, or None where it is not scored in full."""
    path = RESULTS / f"{SETS[set_name]}.json"
    if not path.exists():
        return None
    scores = json.loads(path.read_text())["sequences"]
    return scores if len(scores) >= SET_SIZE else None


def cover_table(scores: list[dict], method: str, key: str = "class") -> dict:
    """Per material class (``key="class"``) or sky type (``"category"``):
    sun-lit sequences, how many the reported 90 % interval holds, the
    share's 90 % Clopper-Pearson range, and the MAE of the median."""
    out = {}
    rows = [s for s in scores if s["direct_sun"] and s.get(key) and method in s]
    for cls in sorted({s[key] for s in rows}) + ["all"]:
        sub = [s for s in rows if cls in ("all", s[key])]
        held = sum(_holds(s[method], s["truth"]) for s in sub)
        n = len(sub)
        ci = stats.binomtest(held, n).proportion_ci(0.90) if n else None
        out[cls] = {
            "n": n,
            "held": int(held),
            "range90": [float(ci.low), float(ci.high)] if ci else None,
            "mae": float(np.mean([abs(s[method]["median"] - s["truth"]) for s in sub])),
        }
    return out


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--radiance", nargs="*", default=list(DEFAULT_SETS["radiance"]))
    ap.add_argument("--mitsuba", nargs="*", default=list(DEFAULT_SETS["mitsuba"]))
    ap.add_argument("--methods", nargs="*", default=["families", "materials"])
    ap.add_argument(
        "--out",
        default=str(RESULTS / "calibration_pooled.json"),
        help="the summary's file; the figures are named after it (<stem>_<renderer>.png)",
    )
    args = ap.parse_args(argv)
    out = Path(args.out)
    summary = {}
    for renderer, names in (("radiance", args.radiance), ("mitsuba", args.mitsuba)):
        scores, used, left_out = [], [], []
        for name in names:
            got = load(name)
            (left_out if got is None else used).append(name)
            scores += got or []
        if not scores:
            continue
        methods = [m for m in args.methods if any(m in s for s in scores)]
        figure = out.with_name(f"{out.stem}_{renderer}.png")
        summary[renderer] = {
            "sets": used,
            "not_scored_in_full": left_out,
            "cover90": {m: cover_table(scores, m) for m in methods},
            "cover90_by_sky_type": {m: cover_table(scores, m, "category") for m in methods},
            "calibration": calibration_figure(scores, figure, methods),
        }
        for table in ("cover90", "cover90_by_sky_type"):
            for m in methods:
                for group, row in summary[renderer][table][m].items():
                    print(renderer, m, group, f"{row['held']}/{row['n']}", f"MAE {row['mae']:.3f}")
    out.write_text(json.dumps(summary, indent=1))
    return summary


if __name__ == "__main__":
    main()

"""Where the sky families tie, which of them should share the weight? (stop 50, seen sets only)

Where PSIS-LOO is unreliable the default weighs the sky families equally
(:func:`bayesgloss.sky_families.equal_when_unreliable`). This script asks,
from the committed scores of sets already seen (each family's own answer
is cached in a score: its 5, 50 and 95 % points, its elpd difference from
the best), how the answer would read had the weight gone only to the
families within X nats of the best. Each family's posterior is taken as
the Beta through its three points, mixed with the weights, the score's
model error added (normal, its sd), clipped to [0, 1]; the 90 % HDI as
``estimate`` reports it. The first row (the default's guard) checks the
approximation against the reported answers.

    python studies/tied_sky_weights.py

A development tool: it reads seen sets only, and decides nothing (holdout
18's rule does; studies/README.md).
"""

from __future__ import annotations

import json
import sys
import warnings
from pathlib import Path

import numpy as np
from scipy import optimize, stats

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

from bayesgloss.intervals import GAMMA_BOUNDS, posterior_quantiles  # noqa: E402

#: The seen sets and the method that was the default when each was scored.
SEEN = {
    "validation_holdout11": "perez",
    "validation_holdout12": "perez",
    "validation_holdout13": "perez",
    "validation_holdout14": "perez",
    "validation_holdout15": "perez",
    "validation_holdout16": "ground-shadow",
    "validation_mitsuba_holdout4": "perez",
    "validation_mitsuba_holdout5": "perez",
}
MARGINS = (20.0, 10.0, 5.0)


def beta_through(q: dict) -> tuple[float, float]:
    """(a, b) of the Beta whose 5, 50 and 95 % points are nearest ``q``'s."""
    pts = np.clip([q["q05"], q["median"], q["q95"]], 1e-4, 1 - 1e-4)

    def loss(p):
        a, b = np.exp(p)
        return float(np.sum((stats.beta.ppf([0.05, 0.5, 0.95], a, b) - pts) ** 2))

    m = min(max(pts[1], 0.02), 0.98)
    s = max((pts[2] - pts[0]) / 3.3, 0.005)
    k = max(m * (1 - m) / s**2 - 1, 0.5)
    fit = optimize.minimize(loss, np.log([m * k, (1 - m) * k]), method="Nelder-Mead")
    return tuple(np.exp(fit.x))


def mixture_answer(betas, weights, sd, rng, n=4000) -> dict:
    """posterior_quantiles of the weighted Beta mixture plus N(0, sd^2), clipped."""
    w = np.asarray(weights, float)
    which = rng.choice(len(betas), size=n, p=w / w.sum())
    x = np.empty(n)
    for i, (a, b) in enumerate(betas):
        x[which == i] = rng.beta(a, b, np.count_nonzero(which == i))
    return posterior_quantiles(np.clip(x + sd * rng.standard_normal(n), 0, 1), GAMMA_BOUNDS)


def main() -> dict:
    warnings.simplefilter("ignore")
    rng = np.random.default_rng(1)
    rows = {"reported": [], "default's guard": [], "best alone": []}
    rows |= {f"within {x:g} nats": [] for x in MARGINS}
    for name, method in SEEN.items():
        for s in json.loads((HERE / "results" / f"{name}.json").read_text())["sequences"]:
            fams = (s.get(method) or {}).get("sky_families") or {}
            if not s["direct_sun"] or not fams.get("equal_weights"):
                continue
            fam = {k: e for k, e in fams["families"].items() if "gamma" in e}
            betas = [beta_through(e["gamma"]) for e in fam.values()]
            diff = np.array([e["elpd_diff"] for e in fam.values()])
            kept = np.array([e["weight"] for e in fam.values()]) > 0
            sd = (s[method].get("model_error") or {}).get("sd", 0.06)
            truth, few = s["truth"], s["facets"] <= 3
            lo, hi = s[method]["hdi90"]
            err = abs(s[method]["median"] - truth)
            rows["reported"].append((err, lo <= truth <= hi, hi - lo, few))
            weights = {"default's guard": kept, "best alone": diff == diff.min()}
            weights |= {f"within {x:g} nats": kept & (diff <= x) for x in MARGINS}
            for label, w in weights.items():
                q = mixture_answer(betas, w, sd, rng)
                lo, hi = q["hdi90"]
                rows[label].append((abs(q["median"] - truth), lo <= truth <= hi, hi - lo, few))
    out = {}
    for label, r in rows.items():
        err, held, width, few = (np.array(c) for c in zip(*r, strict=True))
        out[label] = {
            "sequences": len(r),
            "mae": float(err.mean()),
            "held": int(held.sum()),
            "median_width": float(np.median(width)),
            "held_1_3_facets": [int(held[few].sum()), int(few.sum())],
            "mae_1_3_facets": float(err[few].mean()),
            "mae_more_facets": float(err[~few].mean()),
        }
        print(
            f"{label:18s} MAE {err.mean():.3f}  held {held.sum()}/{len(r)}"
            f"  median width {np.median(width):.2f}  (1-3 facets: MAE {err[few].mean():.3f},"
            f" held {held[few].sum()}/{few.sum()}; more: MAE {err[~few].mean():.3f})"
        )
    return out


if __name__ == "__main__":
    main()

"""Schlick's Fresnel at the sun's half vector: the coating's fit on seen Mitsuba plastics (stop 51).

The lobe stack's ``ggx-schlick`` fit (GGX with Schlick's Fresnel raise,
:mod:`bayesgloss.fresnel`) raised the direct sun's glossy part by the
rise at each facet's view angle. A microfacet lobe's Fresnel factor is at
the half vector of the sun and the view, and against Mitsuba's own
``roughplastic`` BSDF the view's rise made the sun's light 0.34-1.74
times Mitsuba's over views of -75..75 degrees (``tests/test_fresnel.py``).
On the seen Mitsuba holdouts 4 and 5 the default read the many-facet
plastics glossier than they are (by 0.09 on average over 16, up to 0.34), mostly
where ``ggx-schlick`` had the weight. This script asks, on a few of those
seen sequences rendered again from their committed configs, what the
``ggx-schlick`` fit alone reads under the sky family the default weighed
most, with the code on ``PYTHONPATH`` (run it once per commit, ``--label``
naming it):

    PYTHONPATH=. python studies/schlick_half_vector.py --label view-rise
    PYTHONPATH=<worktree of schlick-half-vector> python studies/schlick_half_vector.py \
        --label half-vector
    PYTHONPATH=<worktree of schlick-in-lobe> python studies/schlick_half_vector.py \
        --label rise-inside
    python studies/schlick_half_vector.py --table view-rise half-vector rise-inside

(``half-vector``: the sun's rise at its half vector, branch
``schlick-half-vector``; ``rise-inside``: the rise inside the lobe's
integral for the sky and the sun, branch ``schlick-in-lobe``. Stop 51's
answers are in ``studies/results/schlick_half_vector/``.)

A development tool on seen sets: it decides nothing (a holdout's rule does;
studies/README.md). Bundles go to ``studies/out/schlick_half_vector/bundles``,
answers to ``studies/out/schlick_half_vector/<label>.json``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from code_under_test import check as check_code  # noqa: E402

OUT = HERE / "out" / "schlick_half_vector"
#: The seen sets' many-facet plastics with a sky family the default weighed
#: most (not the tied ones): (set config, sequence name, the score's method).
SEQUENCES = (
    ("mitsuba_holdout4", "ms01-rough-plastic", "perez"),
    ("mitsuba_holdout4", "ms04-smooth-plastic", "perez"),
    ("mitsuba_holdout4", "ms06-rough-plastic", "perez"),
    ("mitsuba_holdout4", "ms08-rough-plastic", "perez"),
    ("mitsuba_holdout4", "ms22-smooth-plastic", "perez"),
    ("mitsuba_holdout5", "ms04-rough-plastic", "day-exposure"),
    ("mitsuba_holdout5", "ms16-rough-plastic", "day-exposure"),
    ("mitsuba_holdout5", "ms18-rough-plastic", "day-exposure"),
)


def _score(set_name: str, name: str, method: str) -> dict:
    scores = json.loads((HERE / "results" / f"validation_{set_name}.json").read_text())
    return next(s for s in scores["sequences"] if s["bundle"].startswith(name + "-"))[method]


def most_weighted_sky(set_name: str, name: str, method: str) -> str:
    """The sky family the default of its time weighed most on a seen sequence."""
    families = _score(set_name, name, method)["sky_families"]["families"]
    return max(families, key=lambda k: families[k]["weight"])


def render(set_name: str, name: str, threads: int = 1) -> Path:
    """The seen sequence's bundle, rendered again from its committed config."""
    import mitsuba_set

    from bayesgloss import mitsuba_render as mr

    config = mitsuba_set.load_config(HERE / "configs" / f"{set_name}.json")
    item = next(s for s in mitsuba_set.draw_sequences(config) if s.config.name == name)
    return mr.render_bundles([item], OUT / "bundles" / set_name, threads=threads, progress=False)[0]


def fit(path: Path, sky: str, jobs: int = 1) -> dict:
    """``ggx-schlick`` alone under ``sky``: the object's gamma and the Fresnel strength k."""
    from bayesgloss import bundle as bundle_io
    from bayesgloss import estimate

    b = bundle_io.read_bundle(path)
    t0 = time.perf_counter()
    res = estimate.estimate_bundle(
        b, per_frame=True, illumination=sky, lobe="ggx", fresnel="schlick", jobs=jobs
    )
    post = res.idata.posterior
    g = res.summary["object"]["gamma"]
    out = {
        "truth": b.truth["gloss"],
        "sky": sky,
        "gamma": {k: g[k] for k in ("median", "q05", "q95")},
        "within_model": res.summary["object"].get("gamma_within_model"),
        "seconds": time.perf_counter() - t0,
    }
    if "fresnel_strength" in post:  # the Fresnel strength k, 1 for a real coating
        out["fresnel_strength"] = float(np.median(post["fresnel_strength"].values))
    return out


def table(labels) -> None:
    runs = {lab: json.loads((OUT / f"{lab}.json").read_text()) for lab in labels}
    names = sorted(set().union(*runs.values()))
    head = " | ".join(f"{lab}: gamma [90 %], k" for lab in labels)
    print(f"| sequence | truth | {head} |")
    errors = {lab: [] for lab in labels}
    for n in names:
        cells, truth = [], None
        for lab in labels:
            r = runs[lab].get(n)
            if r is None:
                cells.append("-")
                continue
            truth = r["truth"]
            g = r["gamma"]
            errors[lab].append(abs(g["median"] - truth))
            cells.append(
                f"{g['median']:.3f} [{g['q05']:.2f}, {g['q95']:.2f}], "
                f"{r.get('fresnel_strength', float('nan')):.2f}"
            )
        print(f"| {n} | {truth:.3f} | " + " | ".join(cells) + " |")
    for lab in labels:
        e = errors[lab]
        print(f"{lab}: MAE {np.mean(e):.3f} over {len(e)}")


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--label", help="name of this commit's answers")
    ap.add_argument("--table", nargs="*", help="print the answers of these labels side by side")
    ap.add_argument("--threads", type=int, default=1)
    args = ap.parse_args(argv)
    check_code("schlick_half_vector")  # a candidate's worktree on PYTHONPATH is the code run
    if args.table is not None:
        table(args.table or sorted(p.stem for p in OUT.glob("*.json")))
        return
    if not args.label:
        ap.error("--label or --table")
    warnings.simplefilter("ignore")
    OUT.mkdir(parents=True, exist_ok=True)
    target = OUT / f"{args.label}.json"
    done = json.loads(target.read_text()) if target.exists() else {}
    for set_name, name, method in SEQUENCES:
        key = f"{set_name}/{name}"
        if key in done:
            continue
        path = render(set_name, name, args.threads)
        done[key] = fit(path, most_weighted_sky(set_name, name, method))
        target.write_text(json.dumps(done, indent=1) + "\n")
        g = done[key]["gamma"]
        print(f"{key}: truth {done[key]['truth']:.3f} read {g['median']:.3f}", flush=True)


if __name__ == "__main__":
    main()

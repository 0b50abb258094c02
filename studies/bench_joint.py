"""Benchmark: ``estimate``'s default (per-frame illumination, sky families
stacked) and ``--sky auto``, in one run beside the fixed-brightness
estimate of the same bundle (issue 13's speed goal: ``--sky auto`` on a
30-facet, 20-frame bundle in at most 30 s).

The bundle: the paper's site and date (40 N, 21 June), a hemisphere of 6
rings of 18 segments (30-odd facets usable) of grey plastic of specularity
0.5, seen from the south-west, 20 frames from 5:00 to 18:18 local solar
time (every 42 min), rendered with Radiance under gensky's clear sky (cached
in ``studies/out/bench_joint/``). Each estimate runs ``--repeats`` times with
different seeds in one process (``--jobs 1`` by default: the joint sampler is
one process, the fixed model's batched sampler is given the same one core;
``--jobs 2`` runs the default's four fits two at a time), and the figures
are wall-clock seconds, sweeps, and whether the run met the convergence
rule, with the ratios of the medians measured in this run.

With ``--before`` the default and ``--sky auto`` are timed again as stop
36 ran them (:data:`BEFORE`: burn-in rounds of 200 sweeps, the rule
checked every 200 sweeps from 800 on, every sky family run in full),
interleaved with today's (rounds of 100, every 100 from 400 on, families
far behind at their first check kept there). With ``--lobes`` the
default estimate is timed again with ``--lobe families``
(:mod:`bayesgloss.lobe_families`: two fits more, the Ward and GGX lobes
under the most-weighted sky family).

Usage: python studies/bench_joint.py [--repeats 3] [--jobs 1] [--max-sweeps N] [--before] [--lobes]
"""

from __future__ import annotations

import argparse
import json
import time
import warnings
from pathlib import Path

import numpy as np

HERE = Path(__file__).parent
OUT = HERE / "out" / "bench_joint"


def bench_config():
    """The benchmark's sequence (module docstring)."""
    from bayesgloss import sequences

    return sequences.SequenceConfig(
        name="bench-joint",
        view="SW",
        material="plastic",
        specularity=0.5,
        n_rings=6,
        n_segments=18,
        image_size=128,
        sky="gensky-clear",
        solar_hours=tuple(float(h) for h in np.round(5.0 + 0.7 * np.arange(20), 2)),
    )


#: Stop 36's schedule of the one-material sampler, every sky family run in
#: full (sampler options).
BEFORE = {
    "burn_rounds": (200, 200, 200),
    "min_sweeps": 800,
    "chunk": 200,
    "screen_families": False,
}


def variants(before: bool, lobes: bool) -> list[tuple[str, dict]]:
    """(label, estimate_bundle's keywords) of each timed estimate."""
    out = [("fixed", {"per_frame": False, "illumination": "gensky-clear"})]
    for label, sky in (("auto", "auto"), ("default", None)):
        out.append((label, {"illumination": sky}))
        if before:
            out.append((f"{label}, stop 36", {"illumination": sky, "options": BEFORE}))
    if lobes:
        out.append(("default, lobe families", {"lobe": "families"}))
    return out


def run(repeats: int, max_sweeps: int, lobes: bool = False, before=False, jobs=1) -> dict:
    """Time each variant ``repeats`` times, seeds in turn; the rows and their medians."""
    from bayesgloss import bundle, estimate, sequences

    warnings.simplefilter("ignore")
    (path,) = sequences.render_bundles([bench_config()], OUT, jobs=2, progress=False)
    b = bundle.read_bundle(path)
    rows = []
    for seed in range(repeats):  # interleaved, so that a slow spell hits every variant
        for label, kw in variants(before, lobes):
            kw = dict(kw)
            options = dict(kw.pop("options", {}))
            if max_sweeps:
                options["max_steps"] = max_sweeps
            t0 = time.perf_counter()
            res = estimate.estimate_bundle(
                b, seed=seed, jobs=jobs, sampler_options=options or None, **kw
            )
            obj = res.summary["object"]
            rows.append(
                {
                    "variant": label,
                    "model": res.summary["sampler"]["model"],
                    "illumination": res.summary["illumination"],
                    "seed": seed,
                    "jobs": jobs,
                    "seconds": time.perf_counter() - t0,
                    "sweeps": res.summary["sampler"].get("sweeps"),
                    "converged": obj["converged"],
                    "facets": obj["facets"],
                    "frames": int(b.sun_up.sum()),
                    "gamma": obj["gamma"]["median"],
                    "hdi90": obj["gamma"]["hdi90"],
                    "stopped_early": res.summary.get("sky_families", {}).get("stopped_early"),
                }
            )
            print(json.dumps(rows[-1]))
    med = {
        v: float(np.median([r["seconds"] for r in rows if r["variant"] == v]))
        for v in dict.fromkeys(r["variant"] for r in rows)
    }
    return {"rows": rows, "median_seconds": med, "truth": b.truth["gloss"]}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument(
        "--before", action="store_true", help="also time stop 36's schedule, no screen (BEFORE)"
    )
    ap.add_argument(
        "--lobes", action="store_true", help="also time --lobe families (bayesgloss.lobe_families)"
    )
    ap.add_argument(
        "--max-sweeps", type=int, default=None, help="default: estimate's (2000 sweeps, 8000 steps)"
    )
    args = ap.parse_args(argv)
    out = run(args.repeats, args.max_sweeps, args.lobes, args.before, args.jobs)
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "bench_joint.json").write_text(json.dumps(out, indent=1))
    med = out["median_seconds"]
    print("median seconds:", json.dumps(med))
    for label, seconds in med.items():
        print(f"{label} / fixed: {seconds / med['fixed']:.1f}x")
        old = med.get(f"{label}, stop 36")
        if old is not None:
            print(f"{label}: stop 36 / today: {old / seconds:.2f}x")


if __name__ == "__main__":
    main()

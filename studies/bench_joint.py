"""Benchmark: ``estimate`` with per-frame illumination and the ``auto`` sky, in one run
beside the fixed-brightness estimate of the same bundle (issue 13's speed goal).

The bundle: the paper's site and date (40 N, 21 June), a hemisphere of 6
rings of 18 segments (30-odd facets usable) of grey plastic of specularity
0.5, seen from the south-west, 20 frames from 5:00 to 18:18 local solar
time (every 42 min), rendered with Radiance under gensky's clear sky (cached
in ``studies/out/bench_joint/``). Each estimate runs ``--repeats`` times with
different seeds in one process (``jobs=1``: the joint sampler is one
process; the fixed model's batched sampler is given the same one core), and
the figures are wall-clock seconds, sweeps, and whether the run met the
convergence rule, with the ratio of the medians measured in this run.

With ``--lobes`` the default estimate is timed again with ``--lobe
families`` (:mod:`bayesgloss.lobe_families`: two fits more, the Ward and
GGX lobes under the most-weighted sky family).

Usage: python studies/bench_joint.py [--repeats 3] [--max-sweeps N] [--lobes]
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


def run(repeats: int, max_sweeps: int, lobes: bool = False) -> dict:
    """Time both estimates ``repeats`` times; the rows and their medians."""
    from bayesgloss import bundle, estimate, sequences

    warnings.simplefilter("ignore")
    (path,) = sequences.render_bundles([bench_config()], OUT, jobs=2, progress=False)
    b = bundle.read_bundle(path)
    rows = []
    variants = [(False, None), (True, None)] + ([(True, "families")] if lobes else [])
    for per_frame, lobe in variants:
        for seed in range(repeats):
            t0 = time.perf_counter()
            res = estimate.estimate_bundle(
                b,
                per_frame=per_frame,
                illumination=None if per_frame else "gensky-clear",
                seed=seed,
                sampler_options={"max_steps": max_sweeps},
                lobe=lobe,
            )
            obj = res.summary["object"]
            rows.append(
                {
                    "model": res.summary["sampler"]["model"],
                    "illumination": res.summary["illumination"],
                    "seed": seed,
                    "seconds": time.perf_counter() - t0,
                    "sweeps": res.summary["sampler"].get("sweeps"),
                    "converged": obj["converged"],
                    "facets": obj["facets"],
                    "frames": int(b.sun_up.sum()),
                    "gamma": obj["gamma"]["median"],
                }
            )
            print(json.dumps(rows[-1]))
    med = {
        m: float(np.median([r["seconds"] for r in rows if r["model"] == m]))
        for m in {r["model"] for r in rows}
    }
    return {"rows": rows, "median_seconds": med, "truth": b.truth["gloss"]}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument(
        "--lobes", action="store_true", help="also time --lobe families (bayesgloss.lobe_families)"
    )
    ap.add_argument(
        "--max-sweeps", type=int, default=None, help="default: estimate's (2000 sweeps, 8000 steps)"
    )
    args = ap.parse_args(argv)
    out = run(args.repeats, args.max_sweeps, args.lobes)
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "bench_joint.json").write_text(json.dumps(out, indent=1))
    med = out["median_seconds"]
    print("median seconds:", json.dumps(med))
    if "joint" in med and "facets" in med:
        print(f"joint / fixed: {med['joint'] / med['facets']:.1f}x")
    for model, seconds in med.items():
        if "facets" in med:
            print(f"{model} / fixed: {seconds / med['facets']:.1f}x")


if __name__ == "__main__":
    main()

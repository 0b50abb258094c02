"""Benchmark: the one-material sampler's sweeps per CPU second, two checkouts in one run.

Scoring a validation set is slow because every fit runs thousands of sweeps
of :func:`bayesgloss.sampling.sample_material` on small arrays, where
Python's per-call overhead, not arithmetic, sets the cost (stop 76's
profile, ``results/profile_box_fit_stop76.txt``). This study times a fixed
number of sweeps (burn-in included) of that sampler on three designs of
``sbc_material.py``'s paper scene, each object drawn from the model's prior
under a fixed seed:

- ``box``: 3 facets over 12 frames, exposure unknown, Radiance's Fresnel
  (the shape of the boxes that take most of a set's time);
- ``box-known``: the same with the exposure known;
- ``many``: 24 facets over 12 frames, exposure unknown.

Each checkout (``--trees``, each a folder holding ``bayesgloss/``) runs each
design in its own process (``PYTHONPATH=<tree>``), the checkouts taking turns
``--repeats`` times, so that both see the same machine load; the CPU time
of the sampling alone is measured (``time.process_time``). Each run also
prints a fingerprint (SHA-1) of its draws: a change meant to leave the
answers alone must give the same fingerprint on every design.

    python studies/bench_sweep.py --trees <before> <after> [--sweeps 100] [--repeats 3] [--out FILE]

The ratios are meaningful within one run on one machine only.
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

DESIGNS = {  # name: (facets, frames, Fresnel model, exposure known)
    "box": (3, 12, "radiance", False),
    "box-known": (3, 12, "radiance", True),
    "many": (24, 12, "radiance", False),
}
#: The objects' stream (each design's object is the first draw of it).
SEED = 7
#: The sampler's seed.
CHAIN_SEED = 3


def run_design(name: str, sweeps: int) -> dict:
    """Time ``sweeps`` sweeps after burn-in of the sampler on design ``name``
    (in this process, with whichever bayesgloss it imports)."""
    from sbc_material import paper_three_skies, prior_predictive, sbc_design

    from bayesgloss.sampling import sample_material

    facets, frames, fresnel, known = DESIGNS[name]
    ref = sbc_design(paper_three_skies(), facets, frames, fresnel=fresnel, exposure_known=known)
    y = prior_predictive(ref, np.random.default_rng(SEED))[3]
    data = dataclasses.replace(ref, y=y)
    start = time.process_time()
    res = sample_material(data, min_sweeps=sweeps, max_sweeps=sweeps, seed=CHAIN_SEED)
    seconds = time.process_time() - start
    arrays = (res.draws, res.frames, res.material)
    digest = hashlib.sha1(b"".join(np.ascontiguousarray(a).tobytes() for a in arrays))
    return {
        "design": name,
        "sweeps": int(res.n_sweeps),
        "cpu_seconds": seconds,
        "fingerprint": digest.hexdigest()[:16],
    }


def run_in(tree: Path, name: str, sweeps: int) -> dict:
    """:func:`run_design` in a fresh process importing ``tree``'s bayesgloss."""
    env = dict(os.environ, PYTHONPATH=str(tree))
    cmd = [sys.executable, __file__, "--worker", name, "--sweeps", str(sweeps)]
    out = subprocess.run(cmd, env=env, capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trees", nargs=2, type=Path, metavar=("BEFORE", "AFTER"))
    ap.add_argument("--sweeps", type=int, default=100)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--designs", nargs="+", default=list(DESIGNS), choices=list(DESIGNS))
    ap.add_argument("--worker", choices=list(DESIGNS), help=argparse.SUPPRESS)
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    if args.worker:
        from code_under_test import check

        check("bench_sweep")  # the tree on PYTHONPATH is the one timed
        print(json.dumps(run_design(args.worker, args.sweeps)))
        return {}
    if not args.trees:
        ap.error("--trees BEFORE AFTER is required")
    rows = []
    for rep in range(args.repeats):
        for name in args.designs:
            for label, tree in zip(("before", "after"), args.trees, strict=True):
                row = run_in(tree.resolve(), name, args.sweeps) | {"tree": label, "repeat": rep}
                rows.append(row)
                print(json.dumps(row), flush=True)
    summary = {}
    for name in args.designs:
        cpu = {
            label: [r["cpu_seconds"] for r in rows if r["design"] == name and r["tree"] == label]
            for label in ("before", "after")
        }
        ratios = [b / a for b, a in zip(cpu["before"], cpu["after"], strict=True)]
        prints = {r["fingerprint"] for r in rows if r["design"] == name}
        summary[name] = {
            "sweeps": next(r["sweeps"] for r in rows if r["design"] == name),
            "before_cpu_seconds": cpu["before"],
            "after_cpu_seconds": cpu["after"],
            "speedup_each_repeat": [round(x, 3) for x in ratios],
            "median_speedup": float(np.median(ratios)),
            "same_draws": len(prints) == 1,
        }
    print(json.dumps(summary, indent=1))
    if args.out:
        Path(args.out).write_text(json.dumps({"summary": summary, "runs": rows}, indent=1) + "\n")
    return summary


if __name__ == "__main__":
    main()

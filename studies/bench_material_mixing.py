"""How often the one-material sampler converges, and at what cost (a benchmark).

Objects of 24 facets over 12 frames of the paper scene under the ``auto``
mixture of sky shapes, drawn from the model's prior
(:func:`bayesgloss.illumination.sample_prior_material`: clear, hazy, dimmed
and hidden suns, skies of every brightness the prior allows), simulated by
its likelihood and fitted by :func:`bayesgloss.sampling.sample_material`
with ``estimate``'s stopping rule and cap (R-hat < 1.01, bulk and tail ESS
>= 400 of gamma and of every frame's sun and sky, at most
:data:`~bayesgloss.joint_estimate.JOINT_MAX_SWEEPS` after burn-in). Half
the objects have a known exposure, half an unknown one (the exposure ridge).
For each object: converged or not, sweeps, seconds, and the smallest bulk ESS
over the diagnosed quantities per second. The data are the model's own, so
this measures the sampler, not the model (``sbc_material.py`` checks that
its draws are right; ``validate_radiance.py`` that the model is).

    python studies/bench_material_mixing.py [--n 16] [--seed 4242] [--jobs 2] [--out FILE]

Run it on two versions of the code (``PYTHONPATH=<checkout>``) to compare
them; the ratios are only meaningful within one run on one machine.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import json
import time

import numpy as np
from code_under_test import check as check_code  # a sibling study (studies/ on sys.path)

from bayesgloss import illumination as il
from bayesgloss.joint_estimate import JOINT_MAX_SWEEPS
from bayesgloss.pool import process_pool
from bayesgloss.sampling import sample_material

FACETS, FRAMES = 24, 12


@functools.lru_cache(maxsize=2)
def design(exposure_known: bool):
    """The reference data: ``FACETS`` facets and ``FRAMES`` sun-up frames of
    the paper scene under the ``auto`` mixture (``sbc_material.py``'s design)."""
    from sbc_material import paper_three_skies, sbc_design

    return sbc_design(paper_three_skies(), FACETS, FRAMES, exposure_known=exposure_known)


def fit_object(seed: int, index: int) -> dict:
    """Object ``index`` of stream ``seed``: drawn, simulated, fitted."""
    known = index % 2 == 0
    ref = design(known)
    rng = np.random.default_rng([seed, index])
    th, hyper, lam = il.sample_prior_material(ref, 1, rng)
    y = il.simulate(th.transpose(1, 0, 2)[:, :, None, :], lam[:, None], ref, rng)[0, :, 0]
    data = dataclasses.replace(ref, y=y)
    t0 = time.perf_counter()
    res = sample_material(data, max_sweeps=JOINT_MAX_SWEEPS, seed=index)
    seconds = time.perf_counter() - t0
    ess = np.minimum(res.ess_bulk, res.ess_tail)
    return {
        "index": index,
        "exposure_known": known,
        "converged": bool(res.converged),
        "sweeps": int(res.n_sweeps),
        "seconds": seconds,
        "min_ess": float(ess.min()),
        "min_ess_per_second": float(ess.min() / seconds),
        "gamma_ess_per_second": float(res.ess_bulk[0] / seconds),
        "max_rhat": float(res.rhat.max()),
    }


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=16)
    ap.add_argument("--seed", type=int, default=4242)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    check_code("bench_material_mixing")  # a candidate's worktree on PYTHONPATH is the code run
    with process_pool(args.jobs) as pool:
        rows = list(pool.map(fit_object, [args.seed] * args.n, range(args.n)))
    summary = {
        "objects": args.n,
        "converged": sum(r["converged"] for r in rows),
        "median_sweeps": float(np.median([r["sweeps"] for r in rows])),
        "median_seconds": float(np.median([r["seconds"] for r in rows])),
        "total_seconds": float(np.sum([r["seconds"] for r in rows])),
        "median_min_ess_per_second": float(np.median([r["min_ess_per_second"] for r in rows])),
        "median_gamma_ess_per_second": float(np.median([r["gamma_ess_per_second"] for r in rows])),
    }
    out = {"summary": summary, "objects": rows}
    print(json.dumps(summary, indent=1))
    if args.out:
        with open(args.out, "w") as fh:
            json.dump(out, fh, indent=1)
    return out


if __name__ == "__main__":
    main()

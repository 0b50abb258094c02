"""Simulation-based calibration of the one-material model (bayesgloss.sampling.material).

Objects of 8 facets over 8 frames of the paper scene under the ``auto``
mixture of sky shapes, drawn from the model's prior
(:func:`bayesgloss.illumination.sample_prior_material`), simulated by its
likelihood and fitted by :func:`bayesgloss.sampling.sample_material`; the
ranks of the true gamma, log tau and a mid frame's log sun among 99
posterior draws must be uniform (chi-square over 10 bins, alpha 1e-3)
(Talts et al. 2018), and the share of objects whose 90 % interval holds
the truth is reported. 100 objects took 31 min on one core (stop 23; figures
in studies/README.md), too long for the test suite.

    python studies/sbc_material.py [--n 100] [--seed 2027] [--out studies/results/sbc_material.json]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path

import numpy as np
from scipy import stats

from bayesgloss import illumination as il
from bayesgloss import likelihood as lk
from bayesgloss import scene, sky
from bayesgloss.sampling import sample_material


def paper_three_skies():
    """Split bases of the paper scene (SW) under the ``auto`` mixture, sun-up frames."""
    seq = scene.paper_sequence(view="SW")
    g = scene.seen_geometry(seq)
    up = seq.sky.sun_direction[:, 2] > 0.02
    others = [
        sky.daylight(name, seq.sky.sun_direction, ground_reflectance=0.2)
        for name in ("gensky-intermediate", "gensky-overcast")
    ]
    return il.illumination_bases(g, seq.sky, others=others), up


def sbc_ranks(paper_three_skies, n_rep, seed, n_draws=99):
    """Simulation-based calibration of the one-material model (Talts et al. 2018):
    objects of 8 facets over 8 frames drawn from its prior (a fixed prior
    centre of log s and a fixed noise floor, so the likelihood fitted is the
    one simulated), fitted by :func:`sample_material`; ranks of the truth among
    ``n_draws`` posterior draws."""
    full, up = paper_three_skies
    frames = np.flatnonzero(up)[2:-2][::2][:8]
    facets = np.linspace(0, full.diffuse.shape[1] - 1, 8).round().astype(int)
    bases = full.take(facets, frames)
    f, t = bases.diffuse.shape[1:]
    valid = np.ones((f, t), bool)
    ref = il.joint_data(
        np.ones((f, t)), valid, bases, exposure=np.ones(t), priors=lk.Priors(log_s_center=0.0)
    )
    ref = dataclasses.replace(ref, floor=0.01 * bases.total().diffuse.max(axis=1))
    rng = np.random.default_rng(seed)
    ranks = []
    for i in range(n_rep):
        th, hyper, lam = il.sample_prior_material(ref, 1, rng)
        y = il.simulate(th.transpose(1, 0, 2)[:, :, None, :], lam[:, None], ref, rng)[0, :, 0]
        data = dataclasses.replace(ref, y=y)
        res = sample_material(
            data, n_ensembles=2, n_walkers=12, min_sweeps=1200, max_sweeps=1200, seed=i
        )
        draws = (
            res.draws[0, ..., 0].ravel(),
            res.material[..., 1].ravel(),
            res.frames[..., t // 2, 1].ravel(),
        )
        pick = np.linspace(0, len(draws[0]) - 1, n_draws).round().astype(int)
        truth = (th[0, 0, 0], hyper[0, 1], lam[0, t // 2, 1])
        ranks.append([int(np.sum(x[pick] < v)) for x, v in zip(draws, truth, strict=True)])
    return np.array(ranks)


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=100)
    ap.add_argument("--seed", type=int, default=2027)
    ap.add_argument("--out", default="studies/results/sbc_material.json")
    args = ap.parse_args(argv)
    t0 = time.time()
    ranks = sbc_ranks(paper_three_skies(), args.n, seed=args.seed)
    out = {"n": args.n, "seed": args.seed, "draws": 99, "minutes": (time.time() - t0) / 60}
    for k, name in enumerate(("gamma", "log_tau", "log_sun")):
        counts = np.bincount(ranks[:, k] * 10 // 100, minlength=10)
        out[name] = {"counts": counts.tolist(), "p": float(stats.chisquare(counts).pvalue)}
        # the 90 % central interval of 99 draws (5 below it, 5 above) holds the
        # truth where 5 <= rank <= 94: 90 of the 100 ranks
        out[name]["covered_90"] = float(np.mean((ranks[:, k] >= 5) & (ranks[:, k] <= 94)))
    out["ranks"] = ranks.tolist()
    print(json.dumps({k: v for k, v in out.items() if k != "ranks"}, indent=1))
    if args.out:
        Path(args.out).write_text(json.dumps(out, indent=1) + "\n")
    return out


if __name__ == "__main__":
    main()

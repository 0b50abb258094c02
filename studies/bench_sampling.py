"""Benchmark: converged facet posteriors per second, batched sampler against stock
emcee on the same facets, in one run.

Facets: the paper hemisphere seen from its five views under gensky's clear
sky (the forward-model bases), with gloss, exponent, scale and noise drawn
from the prior, observations simulated from the likelihood. Both samplers
run the protocol bayesgloss uses: 4 independent ensembles of 8 walkers per
facet, 300 burn-in steps, production until every ensemble has run 50
integrated autocorrelation times and ArviZ finds gamma converged (R-hat <
1.01, bulk and tail ESS >= 400). Stock emcee runs each ensemble of each
facet as its own ``EnsembleSampler`` (vectorize=True, the same move mix).

Usage: python studies/bench_sampling.py [--facets 1200] [--emcee-facets 12] [--jobs 2]
"""

from __future__ import annotations

import argparse
import json
import logging
import time
from pathlib import Path

import arviz as az
import emcee
import numpy as np

from bayesgloss import likelihood as lk
from bayesgloss import render, sampling, scene

logging.getLogger("emcee").setLevel(logging.ERROR)  # its short-chain warnings, every check

CONFIG = {"seed": 2026, "walkers": None, "ensembles": 4, "burn": 300, "tau_multiple": 50}


def facet_set(n: int, seed: int):
    blocks = []
    for view in ("W", "SW", "S", "SE", "E"):
        seq = scene.paper_sequence(view=view)
        seen = seq.geometry.cos_view > 0.1
        g = render.ViewGeometry(
            seq.geometry.normal[seen],
            seq.geometry.view_direction[seen],
            seq.geometry.center[seen],
            seq.geometry.occluder,
        )
        b = render.facet_bases(g, seq.sky)
        valid = np.broadcast_to(seq.sky.sun_direction[:, 2] > 0.02, b.diffuse.shape)
        blocks.append((b, valid))
    d = np.concatenate([b.diffuse for b, _ in blocks])
    gl = np.concatenate([b.glossy for b, _ in blocks])
    v = np.concatenate([v for _, v in blocks])
    idx = np.arange(n) % len(d)
    bases = render.FacetBases(d[idx], gl[idx], blocks[0][0].exponents)
    priors = lk.Priors(log_s_center=float(np.log(179 * 0.5)))
    design = lk.curve_data(np.ones((n, d.shape[1])), v[idx], bases, priors=priors)
    rng = np.random.default_rng(seed)
    truth = lk.sample_prior(design, 1, rng)
    y = lk.simulate(truth, design, rng)[:, 0]
    return lk.curve_data(y, v[idx], bases, priors=priors), truth[:, 0]


def stock_emcee_facet(data: lk.CurveData, seed: int) -> tuple[bool, int]:
    """One facet with stock emcee: E samplers run to the same stopping rule."""
    # the same target as the batched sampler: sigma integrated out where possible
    marginal = lk.sigma_marginal_supported(data)
    log_prob = lk.log_probability_sigma_marginal if marginal else lk.log_probability
    p = 3 if marginal else data.n_params
    w, e = CONFIG["walkers"] or 2 * p, CONFIG["ensembles"]
    rng = np.random.default_rng(seed)
    moves = [
        (emcee.moves.StretchMove(), 0.2),
        (emcee.moves.DEMove(), 0.7),
        (emcee.moves.DEMove(gamma0=1.0), 0.1),
    ]
    samplers = []
    for k in range(e):
        start = sampling.initial_ensemble(data, w, rng)[0, :, :p]
        s = emcee.EnsembleSampler(
            w, p, lambda th: log_prob(th[None], data)[0], vectorize=True, moves=moves
        )
        s.random_state = np.random.RandomState(seed * 10 + k).get_state()
        s.run_mcmc(start, CONFIG["burn"])
        s.reset()
        samplers.append(s)
    steps = 0
    while True:
        for s in samplers:
            s.run_mcmc(None, 100)
        steps += 100
        tau = max(
            np.max(emcee.autocorr.integrated_time(s.get_chain(), quiet=True)) for s in samplers
        )
        if steps >= CONFIG["tau_multiple"] * tau or steps >= 8000:
            per = max(1, 1000 // w)
            idx = np.linspace(0, steps - 1, per).round().astype(int)
            g = np.stack([s.get_chain()[idx, :, 0].T.ravel() for s in samplers])
            ok = (
                az.rhat(g) < 1.01
                and az.ess(g, method="bulk") >= 400
                and az.ess(g, method="tail") >= 400
            )
            if ok or steps >= 8000:
                return bool(ok), steps


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--facets", type=int, default=1200)
    ap.add_argument("--emcee-facets", type=int, default=12)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--out", default="studies/out/bench_sampling")
    args = ap.parse_args(argv)
    data, truth = facet_set(args.facets, CONFIG["seed"])

    t0 = time.perf_counter()
    post = sampling.sample_posterior(
        data,
        seed=CONFIG["seed"],
        jobs=args.jobs,
        n_ensembles=CONFIG["ensembles"],
        n_walkers=CONFIG["walkers"],
        burn=CONFIG["burn"],
        min_tau_multiple=CONFIG["tau_multiple"],
    )
    t_batched = time.perf_counter() - t0
    g = post.draws[..., 0]  # (F, E, S)
    conv = np.array(
        [
            az.rhat(x) < 1.01
            and az.ess(x, method="bulk") >= 400
            and az.ess(x, method="tail") >= 400
            for x in g
        ]
    )
    rate_batched = conv.sum() / t_batched

    t0 = time.perf_counter()
    stock = [
        stock_emcee_facet(data.take([i]), CONFIG["seed"] + i) for i in range(args.emcee_facets)
    ]
    t_stock = time.perf_counter() - t0
    rate_stock = sum(ok for ok, _ in stock) / t_stock

    q = np.quantile(g.reshape(len(g), -1), [0.05, 0.95], axis=1)
    cover = float(np.mean((q[0] <= truth[:, 0]) & (truth[:, 0] <= q[1])))
    res = {
        "facets": args.facets,
        "jobs": args.jobs,
        "batched_seconds": t_batched,
        "batched_converged": int(conv.sum()),
        "batched_converged_per_s": rate_batched,
        "stock_emcee_facets": args.emcee_facets,
        "stock_seconds": t_stock,
        "stock_converged": int(sum(ok for ok, _ in stock)),
        "stock_converged_per_s": rate_stock,
        "ratio": rate_batched / rate_stock,
        "median_steps_batched": float(np.median(post.n_steps)),
        "median_steps_stock": float(np.median([s for _, s in stock])),
        "gamma_90_coverage": cover,
    }
    print(
        f"batched: {conv.sum()}/{args.facets} converged in {t_batched:.1f} s = "
        f"{rate_batched:.1f} converged facets/s ({args.jobs} processes)"
    )
    print(
        f"stock emcee: {res['stock_converged']}/{args.emcee_facets} converged in "
        f"{t_stock:.1f} s = {rate_stock:.2f} converged facets/s (1 process)"
    )
    print(f"ratio {res['ratio']:.0f}x; gamma 90 % interval coverage {cover:.3f}")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "bench_sampling.json").write_text(json.dumps(res, indent=2))
    return res


if __name__ == "__main__":
    main()

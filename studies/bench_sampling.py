"""Benchmark: converged facet posteriors per second, the batched sampler against
stock emcee on the same facets, in one run.

Facet sets (``--facets-from``):

- ``prior``: the paper hemisphere seen from its five views under gensky's
  clear sky (the forward-model bases), gloss, exponent, scale and noise drawn
  from the likelihood's prior (noise from 0.01 % to 200 %), curves simulated
  from the likelihood;
- ``paper60``: every facet of the paper's 60 Radiance sequences (the study
  the goal is about), each under the sky model that rendered it, as
  :func:`bayesgloss.estimate.estimate_bundle` sets them up.

Both samplers run the protocol of :func:`bayesgloss.sampling.sample_posterior`
with its defaults: sigma integrated out, ridge coordinates for low-noise
facets, 4 independent ensembles of 2 P walkers, the same move mix (stretch,
DE, DE with gamma 1, and the independence jumps as an emcee ``MHMove``), burn-in of
at least 5 integrated autocorrelation times, production until the pooled
autocorrelation time says 50 tau and ArviZ finds gamma converged (R-hat <
1.01, bulk and tail ESS >= 400), at most 8000 steps. Stock emcee runs each
ensemble of each facet as its own ``EnsembleSampler`` (``vectorize=True``) on
the same log density, one facet after another, in one process; the batched
sampler uses ``--jobs`` processes, and so does stock emcee. A facet counts as converged when ArviZ's
R-hat and ESS criteria hold for its gamma draws.

Like is compared with like: both samplers run on ``--jobs`` worker processes
(the batched sampler's streams, and stock emcee's facets, one facet a task,
spread over a process pool of the same size), so the printed ratio is that
of converged facets per second on the same cores; the rates per core are
printed beside it.

Usage: python studies/bench_sampling.py [--facets-from prior|paper60] [--facets 1200]
       [--emcee-facets 24] [--jobs 2] [--cache /tmp/paper60]
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

from bayesgloss import estimate, render, sampling, scene, sequences
from bayesgloss import likelihood as lk
from bayesgloss.pool import process_pool

logging.getLogger("emcee").setLevel(logging.ERROR)  # its short-chain warnings, every check

SEED = 2026
PROTOCOL = {  # sample_posterior's defaults, repeated for the stock emcee replica
    "ensembles": 4,
    "burn": 100,
    "burn_taus": 5.0,
    "chunk": 50,
    "tau_multiple": 50.0,
    "max_steps": 8000,
    "draws": 1000,
}


def prior_facets(n: int, seed: int) -> tuple[lk.CurveData, np.ndarray]:
    """``n`` facets of the paper scene with parameters drawn from the prior."""
    blocks = []
    for view in ("W", "SW", "S", "SE", "E"):
        seq = scene.paper_sequence(view=view)
        g = scene.seen_geometry(seq)
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


def paper60_facets(cache: str) -> lk.CurveData:
    """Every facet with at least 4 usable frames of the paper's 60 Radiance
    sequences, under the sky model that rendered each."""
    from bayesgloss import bundle as bundle_io

    configs = sequences.paper_configs()
    paths = sequences.render_bundles(configs, cache, progress=False)
    parts = []
    for cfg, path in zip(configs, paths, strict=True):
        b = bundle_io.read_bundle(path)
        y, usable, cens = estimate.observations(bundle_io.facet_curves(b))
        keep = usable.sum(axis=1) >= 4
        bases = estimate.bundle_bases(b, cfg.sky)
        sub = render.FacetBases(bases.diffuse[keep], bases.glossy[keep], bases.exponents)
        parts.append(lk.curve_data(y[keep], usable[keep], sub, censored=cens[keep]))
    cat = {
        k: np.concatenate([getattr(d, k) for d in parts])
        for k in ("y", "valid", "censored", "diffuse", "glossy")
    }
    exps = np.exp(parts[0].log_n_grid)
    bases = render.FacetBases(cat["diffuse"], cat["glossy"], exps)
    return lk.curve_data(cat["y"], cat["valid"], bases, censored=cat["censored"])


def gamma_converged(gamma) -> bool:
    """ArviZ's R-hat < 1.01 and bulk and tail ESS >= 400 on (chains, draws)."""
    return bool(
        az.rhat(gamma) < 1.01
        and az.ess(gamma, method="bulk") >= 400
        and az.ess(gamma, method="tail") >= 400
    )


def stock_emcee_facet(data: lk.CurveData, seed: int) -> tuple[bool, int]:
    """One facet with stock emcee, the batched sampler's protocol replayed:
    E samplers on the same log density in the same coordinates."""
    pr = PROTOCOL
    marginal = lk.sigma_marginal_supported(data)
    density = lk.log_probability_sigma_marginal if marginal else lk.log_probability
    p = 3 if marginal else data.n_params
    w, e = 2 * p, pr["ensembles"]
    coords = sampling.RidgeCoordinates.of(data)
    log_prob = coords.log_prob(density, data)
    rng = np.random.default_rng(seed)
    jump = sampling.ExponentJump.of(data, marginal, ridge=coords).take([0], coords.active)
    ridge = bool(coords.active[0])

    def exponent_jump(x, random):  # the jumps as an emcee Metropolis-Hastings move
        y, factor = jump.propose(x[None], random, fresh=ridge)
        return y[0], factor[0]

    if ridge:  # sampling.FACET_MOVES in ridge coordinates
        mix = [(emcee.moves.DEMove(), 0.4), (emcee.moves.MHMove(exponent_jump), 0.3)]
    else:  # ... and in plain ones (sampling.PLAIN_JUMP)
        mix = [(emcee.moves.DEMove(), 0.6), (emcee.moves.MHMove(exponent_jump), 0.1)]
    moves = [(emcee.moves.StretchMove(), 0.2), (emcee.moves.DEMove(gamma0=1.0), 0.1), *mix]
    samplers = []
    for k in range(e):
        start = coords.from_theta(sampling.initial_ensemble(data, w, rng)[..., :p])[0]
        s = emcee.EnsembleSampler(w, p, lambda x: log_prob(x[None])[0], vectorize=True, moves=moves)
        s.random_state = np.random.RandomState(seed * 10 + k).get_state()
        s.run_mcmc(start, pr["burn"])
        s.reset()
        samplers.append(s)
    steps, next_check = 0, max(pr["chunk"], sampling.FIRST_CHECK_TAUS * pr["tau_multiple"])
    while True:
        for s in samplers:
            s.run_mcmc(None, pr["chunk"])
        steps += pr["chunk"]
        if steps < next_check and steps < pr["max_steps"]:
            continue
        x = np.concatenate([s.get_chain() for s in samplers], axis=1)  # (N, E W, P)
        th = coords.to_theta(x.transpose(1, 0, 2).reshape(1, -1, p))[0]
        th = th.reshape(e * w, steps, p).transpose(1, 0, 2)
        tau = np.max(emcee.autocorr.integrated_time(th, quiet=True))
        drop = int(np.ceil(max(0.0, pr["burn_taus"] * tau - pr["burn"])))
        drop = min(drop, steps // 2)
        used = th[drop:]
        per = max(1, pr["draws"] // w)
        idx = np.linspace(0, len(used) - 1, per).round().astype(int)
        g = used[idx, :, 0].T.reshape(e, w * per)
        enough = len(used) >= pr["tau_multiple"] * tau
        if (enough and gamma_converged(g)) or steps >= pr["max_steps"]:
            return gamma_converged(g), steps
        if enough:  # the same schedule of looks as sample_posterior
            next_check = steps + max(pr["chunk"], 0.25 * steps)
        else:
            next_check = max(pr["tau_multiple"] * tau + drop, steps + pr["chunk"])


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--facets-from", choices=["prior", "paper60"], default="prior")
    ap.add_argument("--facets", type=int, default=1200, help="prior set size")
    ap.add_argument("--emcee-facets", type=int, default=24)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--cache", default="/tmp/paper60", help="paper60: bundle cache")
    ap.add_argument("--out", default="studies/out/bench_sampling")
    args = ap.parse_args(argv)
    truth = None
    if args.facets_from == "prior":
        data, truth = prior_facets(args.facets, SEED)
    else:
        data = paper60_facets(args.cache)
    n = len(data.y)

    t0 = time.perf_counter()
    with process_pool(args.jobs) as pool:
        post = sampling.sample_posterior(data, seed=SEED, pool=pool)
    t_batched = time.perf_counter() - t0
    g = post.draws[..., 0]  # (F, E, S)
    conv = np.array([gamma_converged(x) for x in g])
    rate_batched = conv.sum() / t_batched

    # stock emcee on facets spread evenly over the set, on as many processes
    pick = np.linspace(0, n - 1, args.emcee_facets).round().astype(int)
    t0 = time.perf_counter()
    with process_pool(args.jobs) as pool:
        stock = list(
            pool.map(
                stock_emcee_facet, [data.take([i]) for i in pick], [SEED + int(i) for i in pick]
            )
        )
    t_stock = time.perf_counter() - t0
    rate_stock = sum(ok for ok, _ in stock) / t_stock

    res = {
        "facets_from": args.facets_from,
        "facets": n,
        "jobs": args.jobs,
        "batched_seconds": t_batched,
        "batched_converged": int(conv.sum()),
        "batched_converged_per_s": rate_batched,
        "stock_emcee_facets": args.emcee_facets,
        "stock_seconds": t_stock,
        "stock_converged": int(sum(ok for ok, _ in stock)),
        "stock_converged_per_s": rate_stock,
        "ratio": rate_batched / rate_stock,
        "batched_converged_per_s_per_core": rate_batched / args.jobs,
        "stock_converged_per_s_per_core": rate_stock / args.jobs,
        "median_steps_batched": float(np.median(post.n_steps)),
        "capped_batched": int(np.sum(post.n_steps >= PROTOCOL["max_steps"])),
        "median_steps_stock": float(np.median([s for _, s in stock])),
        "median_steps_batched_same_facets": float(np.median(post.n_steps[pick])),
    }
    if truth is not None:
        q = np.quantile(g.reshape(n, -1), [0.05, 0.95], axis=1)
        res["gamma_90_coverage"] = float(np.mean((q[0] <= truth[:, 0]) & (truth[:, 0] <= q[1])))
    print(
        f"[{args.facets_from}] batched: {conv.sum()}/{n} converged in {t_batched:.1f} s = "
        f"{rate_batched:.1f} converged facets/s ({args.jobs} processes); "
        f"median steps {res['median_steps_batched']:.0f}, {res['capped_batched']} at the cap"
    )
    print(
        f"stock emcee: {res['stock_converged']}/{args.emcee_facets} converged in "
        f"{t_stock:.1f} s = {rate_stock:.2f} converged facets/s ({args.jobs} processes); "
        f"median steps {res['median_steps_stock']:.0f} "
        f"(batched on the same facets: {res['median_steps_batched_same_facets']:.0f})"
    )
    line = (
        f"ratio {res['ratio']:.0f}x on the same {args.jobs} processes (per core: batched "
        f"{res['batched_converged_per_s_per_core']:.1f}/s, stock emcee "
        f"{res['stock_converged_per_s_per_core']:.2f}/s)"
    )
    if truth is not None:
        line += f"; gamma 90 % interval coverage {res['gamma_90_coverage']:.3f}"
    print(line)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / f"bench_sampling_{args.facets_from}.json").write_text(json.dumps(res, indent=2))
    return res


if __name__ == "__main__":
    main()

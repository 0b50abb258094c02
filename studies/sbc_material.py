"""Simulation-based calibration of the one-material model (bayesgloss.sampling.material).

Objects of 12 facets over 8 frames of the paper scene under the ``auto``
mixture of sky shapes, drawn from the model's prior
(:func:`bayesgloss.illumination.sample_prior_material`), simulated by its
likelihood and fitted by :func:`bayesgloss.sampling.sample_material` with
the stopping rule ``estimate`` uses (R-hat < 1.01, ESS >= 400, at most
``--max-sweeps``; objects that stop unconverged are kept, as SBC must);
the ranks of the true gamma, log tau and a mid frame's log sun among 99
posterior draws must be uniform (chi-square over 10 bins, alpha 1e-3)
(Talts et al. 2018), and the share of objects whose 90 % interval holds
the truth is reported, with gamma's R-hat over the walkers (each walker a
chain), which tells a sampler that has not mixed from a model that is
wrong (stop 24: 1.7-6.4 with a sigma per facet; figures in
studies/README.md). Too long for the test suite.

    python studies/sbc_material.py [--n 100] [--seed 2027] [--jobs 2]
        [--max-sweeps 4000] [--out studies/results/sbc_material.json]
        [--fresnel radiance --out studies/results/sbc_material_fresnel.json]
        [--lobe ggx --out studies/results/sbc_material_ggx.json]
        [--clip 0.9 --out studies/results/sbc_material_clipped.json]

With ``--fresnel radiance`` the model has the Fresnel raise
(:mod:`bayesgloss.fresnel`), its strength k and normal-incidence albedo A
drawn from their prior with the rest, and k's rank is tested too. With
``--lobe ward`` or ``ggx`` the glossy basis is that family's
(:mod:`bayesgloss.lobes`), on the same Phong-equivalent exponent axis.
With ``--clip Q`` every value above one top code for the whole design
(:func:`top_code`: the median over prior-predictive objects of their
Q-quantile) is clipped to it and fitted as censored
(:mod:`bayesgloss.sampling.censored`).
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import json
import time
from pathlib import Path

import numpy as np
from scipy import stats

from bayesgloss import diagnostics, scene, sky
from bayesgloss import illumination as il
from bayesgloss import likelihood as lk
from bayesgloss.pool import process_pool
from bayesgloss.sampling import sample_material


def paper_three_skies(lobe_family: str = "phong"):
    """Split bases of the paper scene (SW) under the ``auto`` mixture, sun-up
    frames, with the glossy lobe of ``lobe_family`` (:mod:`bayesgloss.lobes`)."""
    seq = scene.paper_sequence(view="SW")
    g = scene.seen_geometry(seq)
    up = seq.sky.sun_direction[:, 2] > 0.02
    others = [
        sky.daylight(name, seq.sky.sun_direction, ground_reflectance=0.2)
        for name in ("gensky-intermediate", "gensky-overcast")
    ]
    return il.illumination_bases(g, seq.sky, others=others, lobe_family=lobe_family), up


def sbc_design(
    paper_three_skies,
    facets: int = 12,
    frames: int = 8,
    fresnel: str = "none",
    exposure_known: bool = True,
):
    """The reference data of the SBC objects: ``facets`` facets spread over the
    paper scene's, ``frames`` sun-up frames spread over the day, a fixed prior
    centre of log s and a fixed noise floor (so the likelihood fitted is the
    one simulated); ``fresnel`` the Fresnel model (:mod:`bayesgloss.fresnel`);
    ``exposure_known`` False: each frame's exposure inferred."""
    full, up = paper_three_skies
    sun_up = np.flatnonzero(up)[1:-1]
    pick_t = sun_up[np.linspace(0, len(sun_up) - 1, frames).round().astype(int)]
    pick_f = np.linspace(0, full.diffuse.shape[1] - 1, facets).round().astype(int)
    bases = full.take(pick_f, pick_t)
    f, t = bases.diffuse.shape[1:]
    ref = il.joint_data(
        np.ones((f, t)),
        np.ones((f, t), bool),
        bases,
        exposure=np.ones(t) if exposure_known else None,
        priors=lk.Priors(log_s_center=0.0),
        fresnel=fresnel,
    )
    return dataclasses.replace(ref, floor=0.01 * bases.total().diffuse.max(axis=1))


def prior_predictive(ref, rng) -> tuple:
    """One object from the model's prior and its simulated data: (theta,
    hyper, lam, y (F, T))."""
    th, hyper, lam = il.sample_prior_material(ref, 1, rng)
    y = il.simulate(th.transpose(1, 0, 2)[:, :, None, :], lam[:, None], ref, rng)[0, :, 0]
    return th, hyper, lam, y


def top_code(ref, quantile: float = 0.9, n: int = 200, seed: int = 1) -> float:
    """A top code for the clipped objects: the median over ``n`` objects of
    the prior predictive (their own stream, ``seed``) of each one's
    ``quantile`` of its values. One number for the whole design, as a
    camera's top code is: clipping at a level taken from an object's own
    data or parameters would be another model than the one fitted."""
    rng = np.random.default_rng(seed)
    return float(
        np.median([np.quantile(prior_predictive(ref, rng)[3], quantile) for _ in range(n)])
    )


def sbc_object(
    ref, seed: int, index: int, max_sweeps: int = 4000, n_draws: int = 99, top: float | None = None
) -> dict:
    """Object ``index`` of the SBC stream ``seed``: drawn from the prior,
    simulated, fitted; the ranks of the truth among ``n_draws`` draws picked
    evenly over the kept ones, and the run's diagnostics. ``top``: values
    above it clipped to it and fitted as censored (:mod:`bayesgloss.sampling.censored`)."""
    rng = np.random.default_rng([seed, index])
    t = ref.shape[1]
    th, hyper, lam, y = prior_predictive(ref, rng)
    data = dataclasses.replace(ref, y=y)
    clipped = 0
    if top is not None and np.any(y >= top):
        clipped = int(np.sum(y >= top))
        data = dataclasses.replace(ref, y=np.minimum(y, top), censored=y >= top)
    e, w = 2, 12
    res = sample_material(data, n_ensembles=e, n_walkers=w, max_sweeps=max_sweeps, seed=index)
    gamma = res.draws[0, ..., 0]  # (E, W m), each walker's draws one after another
    draws = (gamma.ravel(), res.material[..., 1].ravel(), res.frames[..., t // 2, 1].ravel())
    truth = (th[0, 0, 0], hyper[0, 1], lam[0, t // 2, 1])
    if ref.fresnel is not None:  # the Fresnel strength k too
        draws, truth = (*draws, res.draws[0, ..., 4].ravel()), (*truth, th[0, 0, 4])
    if hyper.shape[-1] > 4:  # the day's exposure spread, where it is day-level (rank_names)
        draws, truth = (*draws, res.material[..., 5].ravel()), (*truth, hyper[0, 5])
    pick = np.linspace(0, len(draws[0]) - 1, n_draws).round().astype(int)
    walkers = gamma.reshape(e * w, -1)[None]
    rhat_walkers = float(diagnostics.diagnose(walkers.astype(float))[0][0])
    return {
        "index": index,
        "ranks": [int(np.sum(x[pick] < v)) for x, v in zip(draws, truth, strict=True)],
        "gamma": float(truth[0]),
        "sigma": float(np.exp(th[0, 0, 3])),
        "clipped": clipped,
        "converged": bool(res.converged),
        "rhat": float(res.rhat[0]),
        "rhat_walkers": rhat_walkers,
        "sweeps": int(res.n_sweeps),
        "seconds": float(res.seconds),
    }


def rank_names(ref) -> tuple[str, ...]:
    """The quantities whose ranks :func:`sbc_object` returns, in its order:
    gamma, log tau and a mid frame's log sun; the Fresnel strength k where
    the design has the Fresnel raise; the day's log exposure spread where
    the exposure is day-level (:func:`bayesgloss.illumination.hyper_size`)."""
    names = ("gamma", "log_tau", "log_sun")
    names += ("fresnel_strength",) * (ref.fresnel is not None)
    return names + ("log_exposure_spread",) * (il.hyper_size(ref) > 4)


def rank_summary(rows: list[dict], names) -> dict:
    """The SBC check of each ranked quantity (Talts et al. 2018) over the
    objects' ``rows``: the counts of its ranks (0-99 among 99 draws) in 10
    bins, their chi-square p, and how many objects' central 90 % interval
    holds the truth (``held90``: 5 <= rank <= 94, 90 of the 100 ranks) and
    what share (``covered_90``)."""
    ranks = np.array([r["ranks"] for r in rows])
    if ranks.ndim != 2 or ranks.shape[1] != len(names):
        raise ValueError(f"rank_summary: ranks of shape {ranks.shape} for {len(names)} names")
    out = {}
    for k, name in enumerate(names):
        counts = np.bincount(ranks[:, k] * 10 // 100, minlength=10)
        held = int(np.sum((ranks[:, k] >= 5) & (ranks[:, k] <= 94)))
        out[name] = {
            "counts": counts.tolist(),
            "p": float(stats.chisquare(counts).pvalue),
            "held90": held,
            "covered_90": held / len(rows),
        }
    return out


def rank_summary_passes(summary: dict, names, held90: tuple[int, int]) -> bool:
    """Whether every quantity's chi-square p is above 1e-3 (a right sampler
    fails 1 run in 1000 a quantity) and gamma's ``held90`` is within the
    range ``held90`` (for 60 objects 46-59: the 99.9 % binomial range at 0.9)."""
    low, high = held90
    return bool(
        all(summary[n]["p"] > 1e-3 for n in names) and low <= summary["gamma"]["held90"] <= high
    )


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=100)
    ap.add_argument("--seed", type=int, default=2027)
    ap.add_argument("--max-sweeps", type=int, default=4000)
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--out", default="studies/results/sbc_material.json")
    ap.add_argument("--fresnel", default="none", choices=("none", "radiance"))
    ap.add_argument("--lobe", default="phong", choices=("phong", "ward", "ggx"))
    ap.add_argument(
        "--clip",
        type=float,
        default=None,
        metavar="QUANTILE",
        help="clip values above the design's top code (top_code at this quantile) and fit "
        "them as censored",
    )
    args = ap.parse_args(argv)
    t0 = time.time()
    ref = sbc_design(paper_three_skies(args.lobe), fresnel=args.fresnel)
    top = None if args.clip is None else top_code(ref, args.clip)
    run = functools.partial(sbc_object, ref, args.seed, max_sweeps=args.max_sweeps, top=top)
    rows = []
    with process_pool(args.jobs) as pool:
        for row in pool.map(run, range(args.n)):
            rows.append(row)
            print(json.dumps(row), flush=True)  # each object as it ends
    out = {"n": args.n, "seed": args.seed, "draws": 99, "minutes": (time.time() - t0) / 60}
    out["design"] = {"facets": ref.shape[0], "frames": ref.shape[1], "max_sweeps": args.max_sweeps}
    out["design"]["fresnel"] = args.fresnel
    out["design"]["lobe_family"] = args.lobe
    out["design"]["top_code"] = top
    out["converged"] = float(np.mean([r["converged"] for r in rows]))
    out["rhat_walkers_quantiles"] = np.quantile(
        [r["rhat_walkers"] for r in rows], [0.5, 0.9, 1.0]
    ).tolist()
    out.update(rank_summary(rows, rank_names(ref)))
    out["objects"] = rows
    print(json.dumps({k: v for k, v in out.items() if k != "objects"}, indent=1))
    if args.out:
        Path(args.out).write_text(json.dumps(out, indent=1) + "\n")
    return out


if __name__ == "__main__":
    main()

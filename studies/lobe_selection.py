"""Which lobe family do the stacking weights name? Objects simulated by each family.

For each family of :data:`bayesgloss.lobes.LOBE_FAMILIES`, ``--n`` objects:
the paper scene's facets seen from the south-west (``scene.seen_geometry``),
its sun-up frames under gensky's clear sky at the model's brightness, one
material of gamma ~ U(0.1, 0.9) and Phong-equivalent exponent n
log-uniform on [10, 3000] (alpha 0.45 to 0.026), each facet's albedo scale
log-normal about 1 (sd 0.2), 2 % relative noise (``--noise``), the exposure
known (a linear-radiance bundle). Each object is fitted by the one-material
model (:func:`bayesgloss.sampling.sample_material`, the sky named, each
frame's sun and sky brightness inferred) with every family's tables, and
the fits are stacked by PSIS-LOO (:func:`bayesgloss.sky_families.loo_stacking_weights`),
as ``estimate --lobe families`` does.

Reported (``studies/results/lobe_selection.json``): per generating family the
share of objects whose own family has the highest weight (issue 14's goal:
at least 90 % at 2 % noise), the confusion table, the mean weights, and
how often the stacked mixture's 90 % interval of gamma holds the truth.
The seed is committed (``--seed``); every object's draws follow from it.

    python studies/lobe_selection.py [--n 10] [--seed 2029] [--jobs 2] [--max-sweeps 1000]
"""

from __future__ import annotations

import argparse
import functools
import json
import time
import warnings
from pathlib import Path

import numpy as np

from bayesgloss import illumination as il
from bayesgloss import scene
from bayesgloss.intervals import GAMMA_BOUNDS, posterior_quantiles
from bayesgloss.lobes import LOBE_FAMILIES
from bayesgloss.pool import process_pool
from bayesgloss.sampling import sample_material
from bayesgloss.sky_families import loo_stacking_weights, mixture_draws

HERE = Path(__file__).parent


@functools.lru_cache(maxsize=1)
def family_bases() -> dict:
    """Each family's split bases of the paper scene (SW), sun-up frames."""
    seq = scene.paper_sequence(view="SW")
    g = scene.seen_geometry(seq)
    up = seq.sky.sun_direction[:, 2] > 0.02
    return {
        f: il.illumination_bases(g, seq.sky, lobe_family=f).take(slice(None), up)
        for f in LOBE_FAMILIES
    }


def simulate(family: str, rng: np.random.Generator, noise: float):
    """One object's observations (F, T) and its truth."""
    bases = family_bases()[family]
    total = bases.total()
    gamma = rng.uniform(0.1, 0.9)
    log_n = rng.uniform(np.log(10.0), np.log(3000.0))
    scale = np.exp(0.2 * rng.standard_normal(len(total.diffuse)))[:, None]
    mu = scale * total.predict(gamma, float(np.exp(log_n)))
    y = mu * (1.0 + noise * rng.standard_normal(mu.shape))
    return y, {"family": family, "gamma": float(gamma), "n": float(np.exp(log_n))}


def fit(y, family: str, seed: int, max_sweeps: int):
    """The one-material fit with ``family``'s tables: (pointwise log likelihood
    (E, S, N), gamma draws (E, S), converged)."""
    import arviz as az

    bases = family_bases()[family]
    valid = np.isfinite(y) & (y > 0)
    data = il.joint_data(y, valid, bases, exposure=np.ones(y.shape[1]))
    res = sample_material(data, seed=seed, max_sweeps=max_sweeps)
    th = res.draws.transpose(1, 0, 2, 3)  # (E, F, S, 4)
    ll = il.pointwise_log_likelihood(th, res.frames, data).transpose(0, 2, 1, 3)
    ll = ll.reshape(*ll.shape[:2], -1)
    ll = ll[..., np.all(np.isfinite(ll), axis=(0, 1))]
    idata = az.from_dict(
        posterior={"gamma": th[:, 0, :, 0]},
        log_likelihood={"y": ll[:, :, :, None]},
    )
    return idata, th[:, 0, :, 0], bool(res.converged)


def replicate(family: str, index: int, seed: int, noise: float, max_sweeps: int) -> dict:
    """One object of ``family`` fitted with every family and stacked."""
    warnings.simplefilter("ignore")
    rng = np.random.default_rng([seed, LOBE_FAMILIES.index(family), index])
    y, truth = simulate(family, rng, noise)
    t0 = time.perf_counter()
    fits = {f: fit(y, f, seed + index, max_sweeps) for f in LOBE_FAMILIES}
    scores = loo_stacking_weights({f: fits[f][0] for f in LOBE_FAMILIES})
    weights = np.array([scores[f]["weight"] for f in LOBE_FAMILIES])
    mixed = mixture_draws([fits[f][1] for f in LOBE_FAMILIES], weights, rng)
    q = posterior_quantiles(mixed, GAMMA_BOUNDS)
    lo, hi = q["hdi90"]
    return {
        **truth,
        "index": index,
        "weights": {f: float(w) for f, w in zip(LOBE_FAMILIES, weights, strict=True)},
        "elpd_loo": {f: float(scores[f]["elpd_loo"]) for f in LOBE_FAMILIES},
        "chosen": LOBE_FAMILIES[int(np.argmax(weights))],
        "gamma_stacked": q,
        "gamma_own": {
            f: posterior_quantiles(fits[f][1], GAMMA_BOUNDS)["median"] for f in LOBE_FAMILIES
        },
        "holds": bool(lo <= truth["gamma"] <= hi),
        "converged": {f: fits[f][2] for f in LOBE_FAMILIES},
        "seconds": time.perf_counter() - t0,
    }


def summarise(rows: list[dict]) -> dict:
    out = {}
    for f in LOBE_FAMILIES:
        mine = [r for r in rows if r["family"] == f]
        if not mine:
            continue
        out[f] = {
            "objects": len(mine),
            "named_right": float(np.mean([r["chosen"] == f for r in mine])),
            "chosen": {g: sum(r["chosen"] == g for r in mine) for g in LOBE_FAMILIES},
            "mean_weight": {
                g: float(np.mean([r["weights"][g] for r in mine])) for g in LOBE_FAMILIES
            },
            "coverage90": float(np.mean([r["holds"] for r in mine])),
            "mae_stacked": float(
                np.mean([abs(r["gamma_stacked"]["median"] - r["gamma"]) for r in mine])
            ),
        }
    return out


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=10, help="objects per family")
    ap.add_argument("--seed", type=int, default=2029)
    ap.add_argument("--noise", type=float, default=0.02)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--max-sweeps", type=int, default=1000)
    ap.add_argument("--out", default=str(HERE / "results" / "lobe_selection.json"))
    args = ap.parse_args(argv)
    tasks = [(f, i) for i in range(args.n) for f in LOBE_FAMILIES]
    rows = []
    design = {k: getattr(args, k) for k in ("n", "seed", "noise", "max_sweeps")}

    def write():  # after every object: a run cut short keeps what it finished
        out = {"design": design, "summary": summarise(rows), "objects": rows}
        Path(args.out).write_text(json.dumps(out, indent=1))
        return out

    with process_pool(args.jobs) as pool:
        futures = [
            pool.submit(replicate, f, i, args.seed, args.noise, args.max_sweeps) for f, i in tasks
        ]
        for fut in futures:
            rows.append(fut.result())
            r = rows[-1]
            print(r["family"], r["index"], r["chosen"], f"{r['seconds']:.0f} s", flush=True)
            out = write()
    print(json.dumps(out["summary"], indent=1))
    return out


if __name__ == "__main__":
    main()

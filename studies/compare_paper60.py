"""Model comparison on known answers: simulated facets, and the paper's 60 Radiance sequences.

Part ``simulated``: facets of the paper scene (west view, gensky clear sky,
the facets whose curve shows a highlight), data simulated from each
reflectance model at relative noise sigma = 0.05; every candidate model's
evidence by thermodynamic integration; the decision is the model of highest
evidence. Replicates: facets x noise seeds.

Part ``objects``: the same question at the object level (one material for
all of an object's facets, ``level="object"``), the way a user asks "Phong
or Ward?" of one object. A replicate is one object: a random subset of
``object_facets`` of the facets that one of the paper's five views sees
(cos view > 0.2) and the sun lights at some hour, from the analytic scene
(:func:`bayesgloss.scene.paper_sequence`, gensky clear sky, sun-up frames);
``objects_per_view`` subsets per view. Data are simulated from each
generating model at relative noise sigma = 0.05 with the material of a
parameter set (two sets: lobes matched in width by n = 2 / alpha^2 - 2,
so that Phong and Ward differ in shape only); every candidate's evidence by
thermodynamic integration and its PSIS-LOO (leave-one-facet-out) are
recorded; decisions: highest evidence, highest elpd_loo, and the
one-standard-error LOO rule (:func:`bayesgloss.loo.select_parsimonious`).

Part ``paper60``: each Radiance sequence compared at the object level
(one material for all facets) across reflectance {lambert, lambert+phong}
and skies {gensky-clear, gensky-intermediate}: is the matt object Lambertian,
the glossy one not, and which sky made it (posterior probabilities with equal
priors, evidence summed over the two reflectance models); confusion table.

Usage: python studies/compare_paper60.py [simulated|objects|paper60] [--cache /tmp/paper60]
Writes studies/results/compare_simulated_noise<sigma>.json,
compare_objects_<set>_noise<sigma>.json, compare_paper60.json.
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from scipy import special

from bayesgloss import compare, evidence, loo, sequences
from bayesgloss import likelihood as lk

CONFIG = {
    "seed": 11,
    "noise_sigma": 0.05,
    "noise_seeds": 4,
    "sim_bundle": "paper-W-plastic-0-clear",
    "sim_sky": "gensky-clear",
    "truth": {
        "lambert": {"gamma": 0.0, "log_n": 0.0},
        "phong": {"gamma": 1.0, "log_n": float(np.log(200.0))},
        "lambert+phong": {"gamma": 0.5, "log_n": float(np.log(200.0))},
        "lambert+ward": {"gamma": 0.5, "log_n": float(np.log(0.1))},
    },
    "evidence": {"burn": 300, "steps": 600, "n_walkers": 8},
    "paper_evidence": {"burn": 300, "steps": 600, "n_walkers": 8, "n_rungs": 40},
    "paper_skies": ["gensky-clear", "gensky-intermediate"],
    "paper_reflectance": ["lambert", "lambert+phong"],
    # part "objects"
    "object_views": ["W", "SW", "S", "SE", "E"],
    "objects_per_view": 6,
    "object_facets": 15,
    "object_log_s": float(np.log(0.5)),  # the paper's grey material colour
    "object_truth": {
        "A": {
            "lambert": {"gamma": 0.0, "log_n": 0.0},
            "phong": {"gamma": 1.0, "log_n": float(np.log(200.0))},
            "lambert+phong": {"gamma": 0.5, "log_n": float(np.log(200.0))},
            "lambert+ward": {"gamma": 0.5, "log_n": float(np.log(0.1))},
        },
        "B": {
            "lambert": {"gamma": 0.0, "log_n": 0.0},
            "phong": {"gamma": 1.0, "log_n": float(np.log(48.0))},
            "lambert+phong": {"gamma": 0.3, "log_n": float(np.log(48.0))},
            "lambert+ward": {"gamma": 0.3, "log_n": float(np.log(0.2))},
        },
    },
    "object_evidence": {"burn": 200, "steps": 400, "n_walkers": 8, "n_rungs": 24},
    "object_fit": {"burn": 300, "steps": 600, "n_walkers": 8, "n_ensembles": 4},
}


def binomial_lower(k: int, n: int, level: float = 0.95) -> float:
    """One-sided Clopper-Pearson lower confidence bound of a proportion."""
    from scipy import stats

    return 0.0 if k == 0 else float(stats.beta.ppf(1 - level, k, n - k + 1))


def _paths(cache):
    configs = sequences.paper_configs()
    return configs, sequences.render_bundles(configs, cache, progress=False)


def simulated(cache: str, out: Path, noise: float) -> dict:
    configs, paths = _paths(cache)
    path = dict(zip([c.name for c in configs], paths, strict=True))[CONFIG["sim_bundle"]]
    models = compare.bundle_models(path, illumination=(CONFIG["sim_sky"],))
    d = models[("lambert+phong", CONFIG["sim_sky"])].data
    # facets with a visible highlight: G(n = 200) peaks above twice D's peak
    g200 = d.glossy[:, np.searchsorted(d.log_n_grid, np.log(200.0))]
    sel = np.nonzero(g200.max(1) > 2 * d.diffuse.max(1))[0]
    reps = np.tile(sel, CONFIG["noise_seeds"])  # replicates: facets x noise draws
    rng = np.random.default_rng(CONFIG["seed"])
    rows = []
    for gen, truth in CONFIG["truth"].items():
        data = models[(gen, CONFIG["sim_sky"])].data.take(reps)
        th = np.zeros((len(reps), 1, 4))
        th[..., 0], th[..., 1] = truth["gamma"], truth["log_n"]
        th[..., 2] = data.log_s_center[:, None]
        th[..., 3] = np.log(noise)
        y = lk.simulate(th, data, rng)[:, 0]
        y = np.maximum(y, 1e-6 * y.max(1, keepdims=True))
        log_z, se = {}, {}
        for cand, m in models.items():
            dm = m.data.take(reps)
            dm = replace(dm, y=np.where(dm.valid, y, 0.0))
            t0 = time.perf_counter()
            ev = compare.model_evidence(
                replace(m, data=dm), seed=rng, betas=evidence.power_ladder(40), **CONFIG["evidence"]
            )
            log_z[cand[0]], se[cand[0]] = ev.log_z, ev.se
            print(f"gen {gen:14s} cand {cand[0]:14s} {time.perf_counter() - t0:5.1f} s", flush=True)
        names = list(log_z)
        z = np.stack([log_z[n] for n in names])  # (M, R)
        pick = np.argmax(z, axis=0)
        for k, f in enumerate(reps):
            rows.append(
                {
                    "generating": gen,
                    "facet": int(f),
                    "replicate": k,
                    "chosen": names[pick[k]],
                    "log_z": {n: float(log_z[n][k]) for n in names},
                    "se": {n: float(se[n][k]) for n in names},
                }
            )
    summary = {}
    for gen in CONFIG["truth"]:
        r = [x for x in rows if x["generating"] == gen]
        counts = {n: sum(x["chosen"] == n for x in r) for n in CONFIG["truth"]}
        summary[gen] = {"replicates": len(r), "correct": counts[gen], "chosen": counts}
        print(gen, summary[gen], flush=True)
    res = {
        "config": CONFIG,
        "noise_sigma": noise,
        "facets": sel.tolist(),
        "summary": summary,
        "rows": rows,
    }
    (out / f"compare_simulated_noise{noise:g}.json").write_text(json.dumps(res, indent=1))
    return res


def scene_objects(rng: np.random.Generator, views, per_view: int, size: int):
    """Phong and Ward bases of ``per_view`` random objects of ``size`` facets
    per view of the paper's scene (facets seen at cos view > 0.2 and sunlit
    at some hour), stacked object after object; sun-up frames valid."""
    from bayesgloss import render
    from bayesgloss.scene import paper_sequence

    phong, ward, ids = [], [], []
    for view in views:
        seq = paper_sequence(view=view, sky_model=CONFIG["sim_sky"])
        g = seq.geometry
        lit = (g.normal @ seq.sky.sun_direction.T).max(axis=1) > 0
        cand = np.nonzero((g.cos_view > 0.2) & lit)[0]
        geom = render.ViewGeometry(g.normal[cand], g.view_direction[cand])
        ph = render.facet_bases(geom, seq.sky)
        wd = render.ward_facet_bases(geom, seq.sky, diffuse=ph.diffuse)
        up = seq.sky.sun_direction[:, 2] > 0
        for _ in range(per_view):
            pick = np.sort(rng.choice(len(cand), size, replace=False))
            phong.append((ph.diffuse[pick], ph.glossy[pick]))
            ward.append(wd.glossy[pick])
            ids.append({"view": view, "facets": cand[pick].tolist()})
    diffuse = np.concatenate([d for d, _ in phong])
    bases = {
        "phong": render.FacetBases(diffuse, np.concatenate([g for _, g in phong]), ph.exponents),
        "ward": render.FacetBases(diffuse, np.concatenate(ward), wd.exponents),
    }
    valid = np.broadcast_to(up, diffuse.shape)
    return bases, valid, ids


def objects(out: Path, noise: float, parameter_set: str) -> dict:
    """Object-level model choice on simulated objects (module docstring)."""
    rng = np.random.default_rng([CONFIG["seed"], ord(parameter_set)])
    size = CONFIG["object_facets"]
    bases, valid, ids = scene_objects(rng, CONFIG["object_views"], CONFIG["objects_per_view"], size)
    names = compare.REFLECTANCE_MODELS
    n_params = {}

    def model(r, y):
        b = bases["ward" if r == "lambert+ward" else "phong"]
        m = compare.comparison_model(
            r, CONFIG["sim_sky"], y, valid, b, level="object", object_size=size
        )
        n_params[r] = m.n_params
        return m

    ev_opts = dict(CONFIG["object_evidence"])
    betas = evidence.power_ladder(ev_opts.pop("n_rungs"))
    rows = []
    for gen, truth in CONFIG["object_truth"][parameter_set].items():
        gm = model(gen, np.maximum(bases["phong"].diffuse, 1e-3))
        th = np.zeros((len(valid), 1, 4))
        th[..., 0], th[..., 1] = truth["gamma"], truth["log_n"]
        th[..., 2], th[..., 3] = CONFIG["object_log_s"], np.log(noise)
        y = lk.simulate(th, gm.data, rng)[:, 0]
        y = np.maximum(y, 1e-6 * y.max(1, keepdims=True))
        log_z, se, fits = {}, {}, {}
        for cand in names:
            m = model(cand, y)
            t0 = time.perf_counter()
            ev = compare.model_evidence(m, seed=rng, betas=betas, **ev_opts)
            t1 = time.perf_counter()
            fits[cand] = compare.fit_model(m, seed=rng, **CONFIG["object_fit"])
            log_z[cand], se[cand] = ev.log_z, ev.se
            print(
                f"{parameter_set} gen {gen:14s} cand {cand:14s} TI {t1 - t0:5.1f} s, "
                f"fit {time.perf_counter() - t1:5.1f} s",
                flush=True,
            )
        z = np.stack([log_z[n] for n in names])  # (M, objects)
        for k, obj in enumerate(ids):
            loo_k = loo.loo_compare(fits, problem=k)
            table = loo_k["table"]
            srt = np.sort(z[:, k])
            rows.append(
                {
                    "generating": gen,
                    "object": k,
                    **obj,
                    "chosen_evidence": names[int(np.argmax(z[:, k]))],
                    "log_bf_best_vs_next": float(srt[-1] - srt[-2]),
                    "chosen_loo": min(table, key=lambda r: r["rank"])["model"],
                    "chosen_loo_parsimonious": loo.select_parsimonious(table, n_params),
                    "log_z": {n: float(log_z[n][k]) for n in names},
                    "log_z_se": {n: float(se[n][k]) for n in names},
                    "loo": {
                        r["model"]: {
                            key: r[key]
                            for key in ("elpd_loo", "se", "elpd_diff", "dse", "pareto_k_max")
                        }
                        for r in table
                    },
                    "rhat_max": {n: float(np.max(f.rhat[k])) for n, f in fits.items()},
                }
            )
    summary = {}
    for rule in ("chosen_evidence", "chosen_loo", "chosen_loo_parsimonious"):
        summary[rule] = {}
        for gen in names:
            r = [x for x in rows if x["generating"] == gen]
            counts = {n: sum(x[rule] == n for x in r) for n in names}
            summary[rule][gen] = {
                "replicates": len(r),
                "correct": counts[gen],
                "fraction": counts[gen] / len(r),
                "lower95": binomial_lower(counts[gen], len(r)),
                "chosen": counts,
            }
        print(rule, {g: v["chosen"] for g, v in summary[rule].items()}, flush=True)
    res = {
        "config": CONFIG,
        "parameter_set": parameter_set,
        "noise_sigma": noise,
        "summary": summary,
        "rows": rows,
    }
    name = f"compare_objects_{parameter_set}_noise{noise:g}.json"
    (out / name).write_text(json.dumps(res, indent=1))
    return res


def _paper_one(cfg, path) -> dict:
    """Object-level evidence of every (reflectance, sky) model of one sequence."""
    t0 = time.perf_counter()
    models = compare.bundle_models(
        path,
        reflectance=CONFIG["paper_reflectance"],
        illumination=tuple(CONFIG["paper_skies"]),
        level="object",
    )
    opts = dict(CONFIG["paper_evidence"])
    betas = evidence.power_ladder(opts.pop("n_rungs"))
    log_z, se = {}, {}
    for (r, s), m in models.items():
        ev = compare.model_evidence(m, seed=CONFIG["seed"], betas=betas, **opts)
        log_z[(r, s)], se[(r, s)] = float(ev.log_z[0]), float(ev.se[0])
    sky_z = {
        s: float(
            special.logsumexp([log_z[(r, s)] for r in CONFIG["paper_reflectance"]])
            - np.log(len(CONFIG["paper_reflectance"]))
        )
        for s in CONFIG["paper_skies"]
    }
    sky = evidence.sky_posterior(sky_z)
    best_sky = sky["best"]
    lam = log_z[("lambert", best_sky)] - log_z[("lambert+phong", best_sky)]
    fit = compare.fit_model(models[("lambert+phong", best_sky)], seed=CONFIG["seed"], steps=800)
    sd = evidence.savage_dickey(fit.draws[0, ..., 0].ravel())
    row = {
        "name": cfg.name,
        "view": cfg.view,
        "material": cfg.material,
        "specularity": cfg.specularity,
        "sky": cfg.sky,
        "sky_prob": sky["prob"],
        "sky_best": best_sky,
        "log_bf_sky_best_vs_next": sky["log_bf_best_vs_next"],
        "log_bf_lambert_ti": lam,
        "log_bf_lambert_ti_se": float(
            np.hypot(se[("lambert", best_sky)], se[("lambert+phong", best_sky)])
        ),
        "log_bf_lambert_sd": sd["log_bf01"],
        "sd_bound": sd["bound"],
        "lambertian": bool(lam > 0),
        "gamma_median": float(np.median(fit.draws[0, ..., 0])),
        "rhat_max": float(np.max(fit.rhat)),
        "log_z": {f"{r}/{s}": v for (r, s), v in log_z.items()},
        "log_z_se": {f"{r}/{s}": v for (r, s), v in se.items()},
        "seconds": time.perf_counter() - t0,
    }
    print(
        f"{cfg.name:34s} sky {best_sky:20s} p(true)={sky['prob'][cfg.sky]:.3f} "
        f"lnBF01(TI) {lam:9.1f} lnBF01(SD) {sd['log_bf01']:7.2f} "
        f"gamma {row['gamma_median']:.3f} {row['seconds']:.0f}s",
        flush=True,
    )
    return row


def paper60(cache: str, out: Path, jobs: int = 2) -> dict:
    from concurrent.futures import ProcessPoolExecutor

    configs, paths = _paths(cache)
    with ProcessPoolExecutor(max_workers=jobs) as pool:
        rows = list(pool.map(_paper_one, configs, paths))
    confusion = {
        t: {
            p: sum(r["sky"] == t and r["sky_best"] == p for r in rows)
            for p in CONFIG["paper_skies"]
        }
        for t in CONFIG["paper_skies"]
    }
    lambert = {}
    for spec in (0.0, 0.5, 1.0):
        sel = [r for r in rows if r["specularity"] == spec]
        lambert[f"{spec:g}"] = {"lambertian": sum(r["lambertian"] for r in sel), "of": len(sel)}
    res = {"config": CONFIG, "confusion": confusion, "lambertian": lambert, "rows": rows}
    (out / "compare_paper60.json").write_text(json.dumps(res, indent=1))
    print("sky confusion (true -> chosen):", confusion)
    print("Lambertian by specularity:", lambert)
    return res


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("part", choices=["simulated", "objects", "paper60"])
    ap.add_argument("--cache", default="/tmp/paper60")
    ap.add_argument("--out", default="studies/results")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--noise", type=float, default=CONFIG["noise_sigma"], help="relative noise")
    ap.add_argument("--set", default="A", choices=sorted(CONFIG["object_truth"]))
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if args.part == "simulated":
        return simulated(args.cache, out, args.noise)
    if args.part == "objects":
        return objects(out, args.noise, args.set)
    return paper60(args.cache, out, args.jobs)


if __name__ == "__main__":
    main()

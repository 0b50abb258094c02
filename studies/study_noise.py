"""Noise study: how does the signal-to-noise ratio of the facet curves limit
the object's gloss, for the peak-frame baseline and for the posterior?

Objects of one material (gamma in the config, exponent n) on the paper's
hemisphere seen from one view under one sky; curves simulated through the
forward model with relative noise of sd 0.3 % ... 30 % (the likelihood's
noise model), a few noise replicates per cell. The same curves go to the
posterior (population gloss of the facet draws) and to the baseline.

Usage: python studies/study_noise.py [--quick] [--jobs 2 | --scheduler ADDRESS] [--out DIR]
Writes studies/out/noise/{objects.csv, facets.csv, summary.json, noise.png}
and one folder per (gamma, noise) cell under units/ (a rerun skips them).
"""

from __future__ import annotations

import json
from pathlib import Path

import _common as C
import numpy as np

NAME = "noise"


#: Config entries the study is cut along: one unit per (gamma, noise), its replicates together.
AXES = ("gammas", "noise")


def units(cfg: dict) -> list[tuple[str, dict]]:
    """(name, options) of every unit, in the tables' order."""
    return [
        (
            C.unit_name(NAME, f"g{gamma:g}", f"noise{noise:g}"),
            C.unit_options(cfg, AXES, gamma=gamma, noise=noise),
        )
        for gamma in cfg["gammas"]
        for noise in cfg["noise"]
    ]


def unit(cfg: dict, gamma: float, noise: float) -> dict[str, bytes]:
    """The replicates of one (gamma, noise) cell, fitted in one sampler call:
    rows of ``objects.csv`` and ``facets.csv``."""
    idx = C.facet_choice(cfg["view"], cfg["facets"], cfg["seed"])
    sc = C.paper_scene(cfg["view"], cfg["sky"], tuple(idx))
    cells, groups = [], []
    for rep in range(cfg["replicates"]):
        rng = np.random.default_rng(C.unit_seed(cfg["seed"], "data", gamma, noise, rep))
        y = C.simulate(sc, gamma, cfg["exponent"], noise, rng)
        cells.append((rep, C.baseline_fit(sc, y)))
        groups.append({"y": y, "valid": sc.valid, "bases": sc.bases})
    fits = C.fit_groups(groups, cfg, C.unit_seed(cfg["seed"], "fit", gamma, noise))
    objects, facets = [], []
    for (rep, base), fit in zip(cells, fits, strict=True):
        objects.append(
            {
                "true_gamma": gamma,
                "noise": noise,
                "replicate": rep,
                "post_median": fit.median,
                "post_q05": fit.q05,
                "post_q95": fit.q95,
                "post_error": fit.median - gamma,
                "post_width": fit.q95 - fit.q05,
                "baseline": base.object_gloss,
                "baseline_error": base.object_gloss - gamma,
                "converged_fraction": fit.converged,
            }
        )
        for k, f in enumerate(sc.facet_index):
            facets.append(
                {
                    "true_gamma": gamma,
                    "noise": noise,
                    "replicate": rep,
                    "facet": int(f),
                    "post_median": fit.facet_median[k],
                    "post_width": fit.facet_q95[k] - fit.facet_q05[k],
                    "baseline": base.gloss[k],
                    "baseline_width": base.interval[k, 1] - base.interval[k, 0],
                }
            )
    return C.unit_files({"objects.csv": objects, "facets.csv": facets})


def summarise(objects, facets) -> dict:
    out = {}
    for noise in sorted({r["noise"] for r in objects}):
        o = [r for r in objects if r["noise"] == noise]
        f = [r for r in facets if r["noise"] == noise]
        out[f"{noise:g}"] = {
            "object_post_mean_abs_error": float(np.mean([abs(r["post_error"]) for r in o])),
            "object_post_mean_width90": float(np.mean([r["post_width"] for r in o])),
            "object_post_coverage90": float(
                np.mean([r["post_q05"] <= r["true_gamma"] <= r["post_q95"] for r in o])
            ),
            "object_baseline_mean_abs_error": float(np.mean([abs(r["baseline_error"]) for r in o])),
            "facet_post_median_abs_error": float(
                np.median([abs(r["post_median"] - r["true_gamma"]) for r in f])
            ),
            "facet_baseline_median_abs_error": float(
                np.nanmedian([abs(r["baseline"] - r["true_gamma"]) for r in f])
            ),
            "facet_post_median_width90": float(np.median([r["post_width"] for r in f])),
        }
    return out


def plot(out: Path) -> None:
    """The figure, from the saved tables only."""
    plt = C.plt()
    objects = C.read_table(out / "objects.csv")
    summary = json.loads((out / "summary.json").read_text())
    gammas = sorted({r["true_gamma"] for r in objects})
    fig, axes = plt.subplots(1, len(gammas) + 1, figsize=(3.3 * (len(gammas) + 1), 3.4))
    for ax, g in zip(axes, gammas, strict=False):
        o = [r for r in objects if r["true_gamma"] == g]
        x = np.array([r["noise"] for r in o]) * 100
        jit = 1.0 + 0.06 * (np.array([r["replicate"] for r in o]) - 0.5)
        med = np.array([r["post_median"] for r in o])
        err = [med - [r["post_q05"] for r in o], [r["post_q95"] for r in o] - med]
        ax.errorbar(x * jit, med, yerr=err, fmt="o", ms=4, color="C0", label="posterior (90 %)")
        ax.plot(x / jit, [r["baseline"] for r in o], "s", ms=4, color="C3", label="baseline")
        ax.axhline(g, color="k", lw=0.8, ls="--", label="truth")
        ax.set_xscale("log")
        ax.set_ylim(-0.05, 1.05)
        ax.set_title(f"true gamma {g:g}")
        ax.set_xlabel("relative noise [%]")
    axes[0].set_ylabel("object gloss gamma")
    axes[0].legend(fontsize=7, loc="upper left")
    ax = axes[-1]
    lv = sorted(summary["summary"], key=float)
    x = [float(k) * 100 for k in lv]
    s = summary["summary"]
    ax.plot(
        x, [s[k]["facet_post_median_abs_error"] for k in lv], "o-", c="C0", label="posterior |err|"
    )
    ax.plot(
        x,
        [s[k]["facet_post_median_width90"] for k in lv],
        "o:",
        c="C0",
        label="posterior 90 % width",
    )
    ax.plot(
        x,
        [s[k]["facet_baseline_median_abs_error"] for k in lv],
        "s-",
        c="C3",
        label="baseline |err|",
    )
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("relative noise [%]")
    ax.set_title("per facet (median over facets)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    C.save_figure(fig, out / f"{NAME}.png")


def main(argv=None, config: dict | None = None) -> dict:
    args = C.parse_args(NAME, argv, __doc__)
    cfg = C.load_config(NAME, args.quick, config)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    tables = C.run_units(NAME, units(cfg), out, args)
    return C.finish(
        NAME,
        out,
        args.results,
        cfg,
        tables,
        summarise(tables["objects.csv"], tables["facets.csv"]),
        plot,
        published=["objects.csv"],
    )


if __name__ == "__main__":
    main()

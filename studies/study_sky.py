"""Sky study: how much does the illumination model matter? Data made under
one sky, estimated with the matching sky, with gensky's clear sky whatever
the weather, and with the paper's point sun.

Curves of one material on the paper's hemisphere (one view, 1 % relative
noise) under gensky clear, intermediate and overcast, some of the 15 CIE
general skies and the Perez (gendaylit) sky; each estimated under every
illumination model of the config; the baseline on the same curves.

Usage: python studies/study_sky.py [--quick] [--jobs 2 | --scheduler ADDRESS] [--out DIR]
Writes studies/out/sky/{objects.csv, summary.json, sky.png} and one folder
per (gamma, data sky) under units/ (a rerun skips them).
"""

from __future__ import annotations

from pathlib import Path

import _common as C
import numpy as np

NAME = "sky"


#: Config entries the study is cut along: one unit per (gamma, data sky), all models.
AXES = ("gammas", "data_skies")


def units(cfg: dict) -> list[tuple[str, dict]]:
    """(name, options) of every unit, in the table's order."""
    return [
        (
            C.unit_name(NAME, f"g{gamma:g}", data_sky),
            C.unit_options(cfg, AXES, gamma=gamma, data_sky=data_sky),
        )
        for gamma in cfg["gammas"]
        for data_sky in cfg["data_skies"]
    ]


def unit(cfg: dict, gamma: float, data_sky: str) -> dict[str, bytes]:
    """One object's curves under ``data_sky``, estimated under every model
    of the config in one sampler call: its ``objects.csv`` rows."""
    idx = tuple(C.facet_choice(cfg["view"], cfg["facets"], cfg["seed"]))
    sc = C.paper_scene(cfg["view"], data_sky, idx)
    rng = np.random.default_rng(C.unit_seed(cfg["seed"], "data", gamma, data_sky))
    y = C.simulate(sc, gamma, cfg["exponent"], cfg["noise"], rng)
    base = C.baseline_fit(sc, y)
    est_skies = [data_sky if model == "matching" else model for model in cfg["models"]]
    groups = [
        {"y": y, "valid": sc.valid, "bases": C.paper_scene(cfg["view"], s, idx).bases}
        for s in est_skies
    ]
    fits = C.fit_groups(groups, cfg, C.unit_seed(cfg["seed"], "fit", gamma, data_sky))
    rows = []
    for model, est_sky, f in zip(cfg["models"], est_skies, fits, strict=True):
        rows.append(
            {
                "true_gamma": gamma,
                "data_sky": data_sky,
                "model": model,
                "model_sky": est_sky,
                "post_median": f.median,
                "post_q05": f.q05,
                "post_q95": f.q95,
                "post_error": f.median - gamma,
                "converged_fraction": f.converged,
                "baseline": base.object_gloss,
                "baseline_error": base.object_gloss - gamma,
            }
        )
    return C.unit_files({"objects.csv": rows})


def summarise(rows) -> dict:
    out = {}
    for model in dict.fromkeys(r["model"] for r in rows):
        sel = [r for r in rows if r["model"] == model]
        out[model] = {
            "mean_abs_error": float(np.mean([abs(r["post_error"]) for r in sel])),
            "max_abs_error": float(np.max([abs(r["post_error"]) for r in sel])),
            "covered": int(sum(r["post_q05"] <= r["true_gamma"] <= r["post_q95"] for r in sel)),
            "objects": len(sel),
            "per_sky_mean_abs_error": {
                s: float(np.mean([abs(r["post_error"]) for r in sel if r["data_sky"] == s]))
                for s in dict.fromkeys(r["data_sky"] for r in sel)
            },
        }
    first = [r for r in rows if r["model"] == rows[0]["model"]]
    out["baseline"] = {
        "mean_abs_error": float(np.mean([abs(r["baseline_error"]) for r in first])),
        "max_abs_error": float(np.max([abs(r["baseline_error"]) for r in first])),
        "per_sky_mean_abs_error": {
            s: float(np.mean([abs(r["baseline_error"]) for r in first if r["data_sky"] == s]))
            for s in dict.fromkeys(r["data_sky"] for r in first)
        },
    }
    return out


def plot(out: Path) -> None:
    """The figure, from the saved table only."""
    plt = C.plt()
    rows = C.read_table(out / "objects.csv")
    gammas = sorted({r["true_gamma"] for r in rows})
    skies = list(dict.fromkeys(r["data_sky"] for r in rows))
    models = list(dict.fromkeys(r["model"] for r in rows))
    colours = {"matching": "C0", "gensky-clear": "C2", "point-sun": "C1"}
    fig, axes = plt.subplots(
        len(gammas), 1, figsize=(9, 2.8 * len(gammas) + 0.7), squeeze=False, sharex=True
    )
    x = np.arange(len(skies))
    for ax, g in zip(axes[:, 0], gammas, strict=True):
        for j, m in enumerate(models):
            sel = {r["data_sky"]: r for r in rows if r["true_gamma"] == g and r["model"] == m}
            med = np.array([sel[s]["post_median"] for s in skies])
            err = [
                med - [sel[s]["post_q05"] for s in skies],
                [sel[s]["post_q95"] for s in skies] - med,
            ]
            ax.errorbar(
                x + 0.15 * (j - 1),
                med,
                yerr=err,
                fmt="o",
                ms=4,
                color=colours.get(m, f"C{j + 4}"),
                label=f"posterior, model {m}",
            )
        sel = {r["data_sky"]: r for r in rows if r["true_gamma"] == g and r["model"] == models[0]}
        ax.plot(x + 0.3, [sel[s]["baseline"] for s in skies], "s", ms=4, c="C3", label="baseline")
        ax.axhline(g, color="k", lw=0.8, ls="--")
        ax.set_ylabel(f"gamma (true {g:g})")
        ax.set_ylim(-0.02, 1.02)
        ax.grid(axis="y", alpha=0.3)
    axes[0, 0].legend(fontsize=7, ncol=4, loc="lower left")
    axes[-1, 0].set_xticks(x, skies, rotation=15, fontsize=8)
    axes[-1, 0].set_xlabel("sky that made the data")
    axes[0, 0].set_title("object gloss under matching and mismatched illumination models")
    fig.tight_layout()
    C.save_figure(fig, out / f"{NAME}.png")


def main(argv=None, config: dict | None = None) -> dict:
    args = C.parse_args(NAME, argv, __doc__)
    cfg = C.load_config(NAME, args.quick, config)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    tables = C.run_units(NAME, units(cfg), out, args)
    return C.finish(NAME, out, args.results, cfg, tables, summarise(tables["objects.csv"]), plot)


if __name__ == "__main__":
    main()

"""Frame-sampling study: how many frames a day does gloss need, and is part
of a day enough?

Frames evenly spread in local solar time over the sunlit day (05:00-19:00
on 21 June at 40 N) at 5 ... 100 a day, and mornings or afternoons alone;
one material on the paper's hemisphere (one view, 1 % relative noise,
gensky's clear sky); posterior and baseline on the same curves.

Usage: python studies/study_frames.py [--quick] [--jobs 2 | --scheduler ADDRESS] [--out DIR]
Writes studies/out/frames/{objects.csv, summary.json, frames.png} and one
folder per (gamma, sampling) under units/ (a rerun skips them).
"""

from __future__ import annotations

from pathlib import Path

import _common as C
import numpy as np

NAME = "frames"


def hours_of(cond) -> tuple:
    return tuple(float(h) for h in np.linspace(cond["start"], cond["end"], cond["frames"]))


#: Config entries the study is cut along: one unit per (gamma, frame sampling).
AXES = ("gammas", "conditions")


def units(cfg: dict) -> list[tuple[str, dict]]:
    """(name, options) of every unit, in the table's order."""
    return [
        (
            C.unit_name(NAME, f"g{gamma:g}", cond["label"]),
            C.unit_options(cfg, AXES, gamma=gamma, cond=cond),
        )
        for gamma in cfg["gammas"]
        for cond in cfg["conditions"]
    ]


def unit(cfg: dict, gamma: float, cond: dict) -> dict[str, bytes]:
    """One object seen at the frames of ``cond``: its ``objects.csv`` row."""
    idx = tuple(C.facet_choice(cfg["view"], cfg["facets"], cfg["seed"]))
    sc = C.paper_scene(cfg["view"], cfg["sky"], idx, hours_of(cond))
    rng = np.random.default_rng(C.unit_seed(cfg["seed"], "data", gamma, cond["label"]))
    y = C.simulate(sc, gamma, cfg["exponent"], cfg["noise"], rng)
    base = C.baseline_fit(sc, y)
    seed = C.unit_seed(cfg["seed"], "fit", gamma, cond["label"])
    (f,) = C.fit_groups([{"y": y, "valid": sc.valid, "bases": sc.bases}], cfg, seed)
    row = {
        "true_gamma": gamma,
        "condition": cond["label"],
        "frames": cond["frames"],
        "start": cond["start"],
        "end": cond["end"],
        "post_median": f.median,
        "post_q05": f.q05,
        "post_q95": f.q95,
        "post_error": f.median - gamma,
        "post_facet_median_abs_error": float(np.median(np.abs(f.facet_median - gamma))),
        "post_facet_median_width90": float(np.median(f.facet_q95 - f.facet_q05)),
        "converged_fraction": f.converged,
        "baseline": base.object_gloss,
        "baseline_error": base.object_gloss - gamma,
        "baseline_facet_median_abs_error": float(np.nanmedian(np.abs(base.gloss - gamma))),
    }
    return C.unit_files({"objects.csv": [row]})


def summarise(rows) -> dict:
    out = {}
    for cond in dict.fromkeys(r["condition"] for r in rows):
        sel = [r for r in rows if r["condition"] == cond]
        out[cond] = {
            "object_post_mean_abs_error": float(np.mean([abs(r["post_error"]) for r in sel])),
            "object_post_mean_width90": float(
                np.mean([r["post_q95"] - r["post_q05"] for r in sel])
            ),
            "object_baseline_mean_abs_error": float(
                np.mean([abs(r["baseline_error"]) for r in sel])
            ),
            "facet_post_median_abs_error": float(
                np.mean([r["post_facet_median_abs_error"] for r in sel])
            ),
            "facet_post_median_width90": float(
                np.mean([r["post_facet_median_width90"] for r in sel])
            ),
        }
    return out


def plot(out: Path) -> None:
    """The figure, from the saved table only."""
    plt = C.plt()
    rows = C.read_table(out / "objects.csv")
    gammas = sorted({r["true_gamma"] for r in rows})
    labels = list(dict.fromkeys(r["condition"] for r in rows))
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(11, 3.8))
    x = np.arange(len(labels))
    for g, marker in zip(gammas, "o^", strict=False):
        sel = {r["condition"]: r for r in rows if r["true_gamma"] == g}
        med = np.array([sel[c]["post_median"] for c in labels])
        err = [
            med - [sel[c]["post_q05"] for c in labels],
            [sel[c]["post_q95"] for c in labels] - med,
        ]
        ax.errorbar(
            x - 0.12, med, yerr=err, fmt=marker, ms=4, c="C0", label=f"posterior, true {g:g}"
        )
        ax.plot(
            x + 0.12,
            [sel[c]["baseline"] for c in labels],
            marker,
            ms=4,
            c="C3",
            label=f"baseline, true {g:g}",
        )
        ax.axhline(g, color="k", lw=0.8, ls="--")
        ax2.plot(
            x,
            [sel[c]["post_facet_median_width90"] for c in labels],
            marker + "-",
            c="C0",
            label=f"posterior 90 % width, true {g:g}",
        )
        ax2.plot(
            x,
            [sel[c]["post_facet_median_abs_error"] for c in labels],
            marker + ":",
            c="C0",
            label=f"posterior |err|, true {g:g}",
        )
        ax2.plot(
            x,
            [sel[c]["baseline_facet_median_abs_error"] for c in labels],
            marker + "-",
            c="C3",
            label=f"baseline |err|, true {g:g}",
        )
    ax.set_xticks(x, labels, rotation=20, fontsize=8)
    ax.set_ylim(0, 1.02)
    ax.set_ylabel("object gloss gamma")
    ax.set_title("object gloss (90 % intervals); dashed: truth", fontsize=9)
    ax.legend(fontsize=6, loc="lower left")
    ax2.set_xticks(x, labels, rotation=20, fontsize=8)
    ax2.set_yscale("log")
    ax2.set_title("per facet (median over facets)", fontsize=9)
    ax2.legend(fontsize=6)
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

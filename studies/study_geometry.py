"""Viewing-geometry study: how do the five paper views, and facets in the
mirror-degenerate arrangement, change the error of each facet's gloss?

Every facet of the paper's hemisphere that a view sees (cos > 0.1) and the
sun lights at some time (``facets`` caps their number), one material, 1 %
relative noise, gensky's clear sky. Per facet: the posterior median and
90 % interval and the baseline's estimate, with the baseline's flag
``mirror-degenerate`` (its Lambert and Phong predictions peak in the same
frame: the sun's path passes the camera's mirror direction, so the peak
frame cannot tell gloss).

Usage: python studies/study_geometry.py [--quick] [--jobs 2 | --scheduler ADDRESS] [--out DIR]
Writes studies/out/geometry/{facets.csv, objects.csv, summary.json, geometry.png}
and one folder per (view, gamma) under units/ (a rerun skips them).
"""

from __future__ import annotations

from pathlib import Path

import _common as C
import numpy as np

NAME = "geometry"


#: Config entries the study is cut along: one unit per (view, gamma).
AXES = ("views", "gammas")


def units(cfg: dict) -> list[tuple[str, dict]]:
    """(name, options) of every unit, in the tables' order."""
    return [
        (
            C.unit_name(NAME, view, f"g{gamma:g}"),
            C.unit_options(cfg, AXES, view=view, gamma=gamma),
        )
        for view in cfg["views"]
        for gamma in cfg["gammas"]
    ]


def unit(cfg: dict, view: str, gamma: float) -> dict[str, bytes]:
    """One object seen from ``view``: its ``facets.csv`` and ``objects.csv`` rows."""
    idx = tuple(C.facet_choice(view, cfg["facets"], cfg["seed"]))
    sc = C.paper_scene(view, cfg["sky"], idx)
    rng = np.random.default_rng(C.unit_seed(cfg["seed"], "data", view, gamma))
    y = C.simulate(sc, gamma, cfg["exponent"], cfg["noise"], rng)
    base = C.baseline_fit(sc, y)
    seed = C.unit_seed(cfg["seed"], "fit", view, gamma)
    (f,) = C.fit_groups([{"y": y, "valid": sc.valid, "bases": sc.bases}], cfg, seed)
    degenerate = np.array(["mirror-degenerate" in fl for fl in base.flags])
    cos_view = sc.geometry.cos_view
    facets = []
    for k, fid in enumerate(sc.facet_index):
        n = sc.geometry.normal[k]
        facets.append(
            {
                "view": view,
                "true_gamma": gamma,
                "facet": int(fid),
                "normal_azimuth": float(np.degrees(np.arctan2(n[0], n[1])) % 360),
                "normal_elevation": float(np.degrees(np.arcsin(np.clip(n[2], -1, 1)))),
                "cos_view": float(cos_view[k]),
                "mirror_degenerate": bool(degenerate[k]),
                "post_median": f.facet_median[k],
                "post_q05": f.facet_q05[k],
                "post_q95": f.facet_q95[k],
                "post_error": f.facet_median[k] - gamma,
                "baseline": base.gloss[k],
                "baseline_error": base.gloss[k] - gamma,
            }
        )
    obj = {
        "view": view,
        "true_gamma": gamma,
        "facets": len(sc.facet_index),
        "mirror_degenerate": int(degenerate.sum()),
        "post_median": f.median,
        "post_q05": f.q05,
        "post_q95": f.q95,
        "baseline": base.object_gloss,
        "converged_fraction": f.converged,
    }
    return C.unit_files({"facets.csv": facets, "objects.csv": [obj]})


def summarise(facets) -> dict:
    out = {}
    for view in dict.fromkeys(r["view"] for r in facets):
        d = {}
        for label, deg in (("ordinary", False), ("mirror_degenerate", True)):
            sel = [r for r in facets if r["view"] == view and r["mirror_degenerate"] == deg]
            if not sel:
                continue
            d[label] = {
                "facets": len(sel),
                "post_median_abs_error": float(np.median([abs(r["post_error"]) for r in sel])),
                "post_max_abs_error": float(np.max([abs(r["post_error"]) for r in sel])),
                "post_median_width90": float(
                    np.median([r["post_q95"] - r["post_q05"] for r in sel])
                ),
                "post_coverage90": float(
                    np.mean([r["post_q05"] <= r["true_gamma"] <= r["post_q95"] for r in sel])
                ),
                "baseline_median_abs_error": float(
                    np.nanmedian([abs(r["baseline_error"]) for r in sel])
                ),
            }
        out[view] = d
    return out


def plot(out: Path) -> None:
    """The figure, from the saved tables only."""
    plt = C.plt()
    facets = C.read_table(out / "facets.csv")
    objects = C.read_table(out / "objects.csv")
    views = list(dict.fromkeys(r["view"] for r in facets))
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(11, 3.8), gridspec_kw={"width_ratios": [2.2, 1]})
    rng = np.random.default_rng(0)
    for i, v in enumerate(views):
        for j, (key, colour) in enumerate((("post_error", "C0"), ("baseline_error", "C3"))):
            for deg, marker in ((False, "o"), (True, "x")):
                sel = [
                    r
                    for r in facets
                    if r["view"] == v and (r["mirror_degenerate"] == "True") == deg
                ]
                e = np.abs([r[key] for r in sel])
                xs = i + (j - 0.5) * 0.4 + rng.uniform(-0.12, 0.12, len(e))
                ax.plot(
                    xs,
                    np.maximum(e, 1e-4),
                    marker,
                    ms=3 if not deg else 6,
                    color=colour,
                    alpha=0.5 if not deg else 1.0,
                    mfc="none" if not deg else colour,
                )
    ax.set_yscale("log")
    ax.set_ylim(1e-4, 1.5)
    ax.set_xticks(range(len(views)), views)
    ax.set_xlabel("camera view")
    ax.set_ylabel("|facet gamma error| (floored at 1e-4)")
    ax.set_title("per facet: posterior median (blue), baseline (red); x = mirror-degenerate")
    ax.title.set_fontsize(9)
    for g, marker in zip(sorted({r["true_gamma"] for r in objects}), "o^", strict=False):
        sel = [r for r in objects if r["true_gamma"] == g]
        x = np.arange(len(sel))
        med = np.array([r["post_median"] for r in sel])
        err = [med - [r["post_q05"] for r in sel], [r["post_q95"] for r in sel] - med]
        ax2.errorbar(
            x - 0.1, med, yerr=err, fmt=marker, ms=4, c="C0", label=f"posterior, true {g:g}"
        )
        ax2.plot(
            x + 0.1,
            [r["baseline"] for r in sel],
            marker,
            ms=4,
            c="C3",
            label=f"baseline, true {g:g}",
        )
        ax2.axhline(g, color="k", lw=0.8, ls="--")
    ax2.set_xticks(range(len(views)), views)
    ax2.set_ylim(0, 1.02)
    ax2.set_title("object gloss per view")
    ax2.title.set_fontsize(9)
    ax2.legend(fontsize=6, loc="lower right")
    fig.tight_layout()
    C.save_figure(fig, out / f"{NAME}.png")


def main(argv=None, config: dict | None = None) -> dict:
    args = C.parse_args(NAME, argv, __doc__)
    cfg = C.load_config(NAME, args.quick, config)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    tables = C.run_units(NAME, units(cfg), out, args)
    return C.finish(NAME, out, args.results, cfg, tables, summarise(tables["facets.csv"]), plot)


if __name__ == "__main__":
    main()

"""Model-mismatch study: what does the Lambert + Phong model make of
materials it does not describe, Radiance's rough plastic and metal?

Real Radiance renders (:func:`bayesgloss.sequences.render_bundles`, small
images, the paper's hemisphere from one view under gensky's clear sky, 19
hourly frames) of plastic and metal of specularity 0.5 and roughness 0,
0.05 and 0.15 (Radiance's Ward-type lobe; roughness 0 is a mirror, the case
the forward model was checked against), estimated with
:func:`bayesgloss.estimate.estimate_bundle` (matching sky, Phong lobe) and
the peak-frame baseline on the same bundle. Truth: the energy fraction of
the material's specular part (:func:`bayesgloss.reflectance.gloss_of_radiance_material`;
plastic 0.5 on grey 0.5: 2/3, metal 0.5: 0.5), and for roughness 0 also with
Radiance's Fresnel raise at each facet's view angle.

Usage: python studies/study_mismatch.py [--quick] [--jobs 2 | --scheduler ADDRESS]
[--out DIR] [--cache DIR]
Writes studies/out/mismatch/{objects.csv, summary.json, mismatch.png} and one
folder per material under units/ (a rerun skips them); rendered bundles are
cached in --cache.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import _common as C
import numpy as np

from bayesgloss import baseline, bundle, estimate, reflectance, sequences, sun

NAME = "mismatch"


def sequence_config(cfg: dict, material: str, roughness: float) -> sequences.SequenceConfig:
    return sequences.SequenceConfig(
        name=f"mismatch-{cfg['view']}-{material}-{cfg['specularity']:g}-r{roughness:g}",
        view=cfg["view"],
        material=material,
        specularity=cfg["specularity"],
        roughness=roughness,
        sky=cfg["sky"],
        image_size=cfg["image_size"],
    )


#: Config entries the study is cut along: one unit per (material, roughness).
AXES = ("materials", "roughness")


def units(cfg: dict) -> list[tuple[str, dict]]:
    """(name, options) of every unit, in the table's order."""
    return [
        (
            C.unit_name(NAME, kind, f"r{rough:g}"),
            C.unit_options(cfg, AXES, material=kind, roughness=rough),
        )
        for kind in cfg["materials"]
        for rough in cfg["roughness"]
    ]


def unit(cfg: dict, material: str, roughness: float, cache: str) -> dict[str, bytes]:
    """One material rendered (or taken from the bundle cache ``cache``) and
    estimated: its ``objects.csv`` row."""
    sc = sequence_config(cfg, material, roughness)
    (path,) = sequences.render_bundles([sc], cache, jobs=1, progress=False)
    b = bundle.read_bundle(path)
    res = estimate.estimate_bundle(
        b,
        illumination=sc.sky,
        per_frame=False,  # the sky and its brightness told: the lobe's mismatch alone
        seed=C.seed_int(C.unit_seed(cfg["seed"], "fit", material, roughness)),
        jobs=1,
        sampler_options=cfg.get("sampler"),
    )
    curves = bundle.facet_curves(b)
    hours = np.unwrap(sun.local_solar_time(b.times, b.site.longitude), period=24)
    base = baseline.peak_frame_gloss(
        curves.luminance,
        curves.valid,
        b.view_geometry(),
        b.sun_direction,
        ids=curves.ids,
        frame_hours=hours,
    )
    o = res.summary["object"]
    fres = reflectance.gloss_of_radiance_material_fresnel(
        sc.material, sc.specularity, sc.colour, b.view_geometry().cos_view
    )
    row = {
        "material": sc.material,
        "specularity": sc.specularity,
        "roughness": sc.roughness,
        "true_gamma": b.truth["gloss"],
        "true_gamma_fresnel": float(np.mean(fres)),
        "post_median": o["gamma"]["median"],
        "post_q05": o["gamma"]["q05"],
        "post_q95": o["gamma"]["q95"],
        "post_n_median": o["n"]["median"],
        "facets": o["facets"],
        "facets_converged": o["facets_converged"],
        "baseline": base.object_gloss,
        "sampler_seconds": res.summary["sampler"]["seconds"],
    }
    return C.unit_files({"objects.csv": [row]})


def plot(out: Path) -> None:
    """The figure, from the saved table only."""
    plt = C.plt()
    rows = C.read_table(out / "objects.csv")
    mats = list(dict.fromkeys(r["material"] for r in rows))
    fig, axes = plt.subplots(1, len(mats) + 1, figsize=(3.6 * (len(mats) + 1), 3.6))
    for ax, m in zip(axes, mats, strict=False):
        sel = [r for r in rows if r["material"] == m]
        x = np.array([r["roughness"] for r in sel])
        med = np.array([r["post_median"] for r in sel])
        err = [med - [r["post_q05"] for r in sel], [r["post_q95"] for r in sel] - med]
        ax.errorbar(x - 0.003, med, yerr=err, fmt="o", c="C0", ms=5, label="posterior (90 %)")
        ax.plot(x + 0.003, [r["baseline"] for r in sel], "s", c="C3", ms=5, label="baseline")
        ax.axhline(sel[0]["true_gamma"], color="k", ls="--", lw=0.8, label="truth (no Fresnel)")
        ax.plot(
            x[x == 0],
            [r["true_gamma_fresnel"] for r in sel if r["roughness"] == 0],
            "k_",
            ms=14,
            label="truth with Fresnel (r = 0)",
        )
        ax.set_title(f"{m}, specularity {sel[0]['specularity']:g}", fontsize=9)
        ax.set_xlabel("Radiance roughness")
        vals = [v for r in sel for v in (r["post_q05"], r["post_q95"], r["baseline"])]
        ax.set_ylim(max(0.0, min(vals) - 0.08), min(1.02, max(vals) + 0.08))
        ax.grid(axis="y", alpha=0.3)
    axes[0].set_ylabel("object gloss gamma")
    axes[0].legend(fontsize=6, loc="lower left")
    ax = axes[-1]
    for j, m in enumerate(mats):
        sel = [r for r in rows if r["material"] == m]
        ax.plot(
            [r["roughness"] for r in sel],
            [r["post_n_median"] for r in sel],
            "o-",
            c=f"C{j}",
            label=m,
        )
    ax.set_yscale("log")
    ax.set_xlabel("Radiance roughness")
    ax.set_title("fitted Phong exponent n (shared-material median)", fontsize=9)
    ax.legend(fontsize=7)
    fig.tight_layout()
    C.save_figure(fig, out / f"{NAME}.png")


def main(argv=None, config: dict | None = None) -> dict:
    extra = [a for a in (argv or sys.argv[1:])]
    cache = Path(C.STUDIES.parent / "out" / "bundles")
    if "--cache" in extra:
        i = extra.index("--cache")
        cache = Path(extra[i + 1])
        del extra[i : i + 2]
    args = C.parse_args(NAME, extra, __doc__)
    cfg = C.load_config(NAME, args.quick, config)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows = C.run_units(NAME, units(cfg), out, args, cache=str(cache.resolve()))["objects.csv"]
    C.write_table(out / "objects.csv", rows)
    summary = {
        "config": cfg,
        "summary": {
            f"{r['material']} r={r['roughness']:g}": {
                "true": r["true_gamma"],
                "post_median": r["post_median"],
                "post_interval90": [r["post_q05"], r["post_q95"]],
                "post_error": r["post_median"] - r["true_gamma"],
                "baseline_error": r["baseline"] - r["true_gamma"],
                "n_median": r["post_n_median"],
            }
            for r in rows
        },
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    plot(out)
    C.publish(out, args.results, ["objects.csv", "summary.json", f"{NAME}.png"])
    return summary


if __name__ == "__main__":
    main()

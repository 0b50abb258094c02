"""Camera study: how much does a nonlinear, quantised, saturating camera
bias the object's gloss, and does modelling the response remove the bias?

Linear facet radiance from the forward model (1 % relative noise) is exposed
so that the object's brightest value sits at ``exposure`` x the top code (values above it clip),
clipped, passed through a response (power 1/g with g = 1 ... 2.4, or sRGB)
and quantised to 8, 10 or 12 bits. Three ways to estimate from the codes:

- ``ignored``: codes treated as linear radiance, clipped values as exact;
- ``modelled``: the likelihood's ``camera="power"`` with the exponent g
  unknown, values at the top code censored;
- ``undone``: the known response inverted first, then the linear model,
  values at the top code censored.

The baseline sees the codes (only the frame of the peak matters to it).

Usage: python studies/study_camera.py [--quick] [--jobs 2 | --scheduler ADDRESS] [--out DIR]
Writes studies/out/camera/{objects.csv, summary.json, camera.png} and one
folder per (gamma, camera) under units/ (a rerun skips them).
"""

from __future__ import annotations

import json
from pathlib import Path

import _common as C
import numpy as np

NAME = "camera"


def encode(v, response):
    """Relative linear value in [0, 1] -> response output in [0, 1]."""
    v = np.clip(v, 0.0, 1.0)
    if response == "srgb":  # IEC 61966-2-1
        return np.where(v <= 0.0031308, 12.92 * v, 1.055 * v ** (1 / 2.4) - 0.055)
    return v ** (1.0 / float(response))


def decode(c, response):
    """Inverse of :func:`encode`."""
    c = np.clip(c, 0.0, 1.0)
    if response == "srgb":
        return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    return c ** float(response)


def camera_codes(y, valid, cond):
    """Codes in [0, 1] (F, T) and the mask of values at the top code."""
    top = 2 ** int(cond["bits"]) - 1
    peak = np.max(np.where(valid, y, 0.0))
    v = cond["exposure"] * y / peak
    codes = np.round(encode(v, cond["response"]) * top) / top
    return codes, (codes >= 1.0) & valid


#: Config entries the study is cut along: one unit per (gamma, condition), all methods.
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
    """One object of one material seen by one camera, estimated every way of
    ``methods`` (the linear ones in one sampler call): its ``objects.csv`` row.

    The linear curves are drawn from a seed of gamma alone, so every camera
    sees the same noisy curves of one material (a paired comparison)."""
    idx = C.facet_choice(cfg["view"], cfg["facets"], cfg["seed"])
    sc = C.paper_scene(cfg["view"], cfg["sky"], tuple(idx))
    rng = np.random.default_rng(C.unit_seed(cfg["seed"], "data", gamma))
    y_lin = C.simulate(sc, gamma, cfg["exponent"], cfg["noise"], rng)
    codes, top = camera_codes(y_lin, sc.valid, cond)
    base = C.baseline_fit(sc, codes)
    groups = {
        "ignored": {"y": codes, "valid": sc.valid, "bases": sc.bases},
        "modelled": {"y": codes, "valid": sc.valid, "bases": sc.bases, "censored": top},
        "undone": {
            "y": decode(codes, cond["response"]),
            "valid": sc.valid,
            "bases": sc.bases,
            "censored": top,
        },
    }
    fits = {}
    for camera in ("linear", "power"):
        ms = [m for m in cfg["methods"] if (m == "modelled") == (camera == "power")]
        seed = C.unit_seed(cfg["seed"], "fit", gamma, cond["label"], camera)
        fits.update(zip(ms, C.fit_groups([groups[m] for m in ms], cfg, seed, camera), strict=True))
    row = {
        "true_gamma": gamma,
        "condition": cond["label"],
        "response": cond["response"],
        "bits": cond["bits"],
        "exposure": cond["exposure"],
        "clipped_fraction": float(top.mean()),
        "baseline": base.object_gloss,
    }
    for m in cfg["methods"]:
        f = fits[m]
        row[f"{m}_median"] = f.median
        row[f"{m}_q05"] = f.q05
        row[f"{m}_q95"] = f.q95
        row[f"{m}_converged"] = f.converged
    return C.unit_files({"objects.csv": [row]})


def summarise(rows, methods) -> dict:
    out = {}
    for cond in dict.fromkeys(r["condition"] for r in rows):
        sel = [r for r in rows if r["condition"] == cond]
        d = {
            "baseline_mean_abs_error": float(
                np.mean([abs(r["baseline"] - r["true_gamma"]) for r in sel])
            )
        }
        for m in methods:
            d[f"{m}_mean_abs_error"] = float(
                np.mean([abs(r[f"{m}_median"] - r["true_gamma"]) for r in sel])
            )
            d[f"{m}_covered"] = int(
                sum(r[f"{m}_q05"] <= r["true_gamma"] <= r[f"{m}_q95"] for r in sel)
            )
        d["objects"] = len(sel)
        out[cond] = d
    return out


def plot(out: Path) -> None:
    """The figure, from the saved table only."""
    plt = C.plt()
    rows = C.read_table(out / "objects.csv")
    methods = json.loads((out / "summary.json").read_text())["config"]["methods"]
    gammas = sorted({r["true_gamma"] for r in rows})
    labels = list(dict.fromkeys(r["condition"] for r in rows))
    fig, axes = plt.subplots(
        len(gammas), 1, figsize=(9, 2.9 * len(gammas) + 0.6), squeeze=False, sharex=True
    )
    colours = {"ignored": "C1", "modelled": "C0", "undone": "C2"}
    for ax, g in zip(axes[:, 0], gammas, strict=True):
        sel = {r["condition"]: r for r in rows if r["true_gamma"] == g}
        x = np.arange(len(labels))
        for j, m in enumerate(methods):
            med = np.array([sel[c][f"{m}_median"] for c in labels])
            lo = med - [sel[c][f"{m}_q05"] for c in labels]
            hi = [sel[c][f"{m}_q95"] for c in labels] - med
            ax.errorbar(
                x + 0.15 * (j - 1),
                med,
                yerr=[lo, hi],
                fmt="o",
                ms=4,
                color=colours[m],
                label=f"posterior, response {m}",
            )
        ax.plot(x + 0.3, [sel[c]["baseline"] for c in labels], "s", ms=4, c="C3", label="baseline")
        ax.axhline(g, color="k", lw=0.8, ls="--")
        ax.set_ylabel(f"gamma (true {g:g})")
        ax.set_ylim(-0.02, 1.02)
        ax.grid(axis="y", alpha=0.3)
    axes[0, 0].legend(fontsize=7, ncol=4, loc="lower left")
    axes[-1, 0].set_xticks(np.arange(len(labels)), labels, rotation=20, fontsize=8)
    axes[0, 0].set_title("object gloss from camera codes (90 % intervals); dashed: truth")
    fig.tight_layout()
    C.save_figure(fig, out / f"{NAME}.png")


def main(argv=None, config: dict | None = None) -> dict:
    args = C.parse_args(NAME, argv, __doc__)
    cfg = C.load_config(NAME, args.quick, config)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    tables = C.run_units(NAME, units(cfg), out, args)
    summary = summarise(tables["objects.csv"], cfg["methods"])
    return C.finish(NAME, out, args.results, cfg, tables, summary, plot)


if __name__ == "__main__":
    main()

"""Fig. 6 of Love & Efford: estimated object gloss of the tessellated
hemisphere for the five views, (a) plastic and (b) metal under the clear
sky, (c) plastic and (d) metal under the intermediate sky, for matt,
intermediate and glossy materials (Radiance specularity 0, 0.5, 1).

Markers: the baseline's object gloss (``results/paper60.json``: the mean
over sunlit facets of each facet's plateau median, Phong n = 2). Bars: the
same mean with each facet's lower and upper plateau edge instead of the
median (``results/sensitivity.csv``), i.e. how much the plateau rule alone
can move the estimate. Solid lines: the true gloss of each Radiance material
(plastic spec / (spec + (1 - spec) 0.5) for colour 0.5, so 0, 2/3, 1; metal
spec); dashed grey lines: the paper's nominal 0, 0.5, 1.

Usage: python paper_figs/fig6.py [--results DIR] [--out DIR]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402

from bayesgloss import report  # noqa: E402

HERE = Path(__file__).parent
VIEWS = ("W", "SW", "S", "SE", "E")
SPECS = ((0.0, "matt (spec 0)"), (0.5, "intermediate (spec 0.5)"), (1.0, "glossy (spec 1)"))
COLOURS = ("tab:brown", "tab:purple", "tab:cyan")
MARKERS = ("o", "s", "^")
PANELS = (
    ("gensky-clear", "plastic", "(a) plastic, clear sky"),
    ("gensky-clear", "metal", "(b) metal, clear sky"),
    ("gensky-intermediate", "plastic", "(c) plastic, intermediate sky"),
    ("gensky-intermediate", "metal", "(d) metal, intermediate sky"),
)


def object_table(results: Path) -> pd.DataFrame:
    """One row per sequence: sky, material, specularity, view, object and true gloss."""
    seqs = json.loads((results / "paper60.json").read_text())["sequences"]
    rows = [
        {
            "sky": s["truth"]["sky"],
            "material": s["truth"]["material"],
            "specularity": s["truth"]["specularity"],
            "view": s["view"],
            "object_gloss": s["object"]["gamma"],
            "true_gloss": s["truth"]["gloss"],
            "exponent": s["object"]["exponent"],
        }
        for s in seqs
    ]
    return pd.DataFrame(rows)


def rule_range(results: Path, exponent: float) -> pd.DataFrame:
    """Object gloss under the lower and upper plateau-edge rules at one exponent."""
    sens = pd.read_csv(results / "sensitivity.csv")
    sens = sens[np.isclose(sens.exponent, exponent) & sens.rule.isin(["lower", "upper"])]
    return sens.pivot_table(
        index=["sky", "material", "specularity", "view"], columns="rule", values="object_gloss"
    )


def _panel(ax, table, ranges, sky, material, title):
    x = np.arange(len(VIEWS))
    for i, ((spec, _), c, m) in enumerate(zip(SPECS, COLOURS, MARKERS, strict=True)):
        sel = table[(table.sky == sky) & (table.material == material) & (table.specularity == spec)]
        sel = sel.set_index("view").loc[list(VIEWS)]
        true = float(sel.true_gloss.iloc[0])
        ax.axhline(spec, color="0.45", ls="--", lw=1.0, zorder=1)
        ax.axhline(true, color=c, ls="-", lw=1.6, alpha=0.8, zorder=1)
        if not np.isclose(true, spec):
            ax.text(
                -0.77, true + 0.012, f"true {true:.2f}", color=c, fontsize=8, ha="left", va="bottom"
            )
            ax.text(
                -0.77,
                spec + 0.012,
                f"nominal {spec:g}",
                color="0.35",
                fontsize=8,
                ha="left",
                va="bottom",
            )
        dx = (i - 1) * 0.18
        lo_hi = ranges.loc[[(sky, material, spec, v) for v in VIEWS]]
        est = sel.object_gloss.to_numpy()
        ax.errorbar(
            x + dx,
            est,
            yerr=[est - lo_hi["lower"].to_numpy(), lo_hi["upper"].to_numpy() - est],
            fmt="none",
            ecolor=c,
            elinewidth=1.0,
            capsize=3,
            alpha=0.6,
            zorder=2,
        )
        ax.plot(x + dx, est, m, color=c, ms=8, mec="k", mew=0.7, zorder=3)
    ax.set_xticks(x, VIEWS)
    ax.set_xlim(-0.8, len(VIEWS) - 0.4)
    ax.set_ylim(-0.05, 1.08)
    ax.set_xlabel("camera position")
    if material == "plastic":
        ax.set_ylabel("estimated object gloss γ [-]")
    ax.set_title(title, fontsize=10)
    ax.grid(alpha=0.3, axis="y")


def main(argv=None) -> Path:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--results", default=str(HERE / "results"), help="saved results folder")
    p.add_argument("--out", default=str(HERE / "figures"), help="figure folder")
    args = p.parse_args(argv)
    results = Path(args.results)
    table = object_table(results)
    exponent = float(table.exponent.iloc[0])
    ranges = rule_range(results, exponent)

    fig, axes = plt.subplots(2, 2, figsize=(11, 9), sharey=True)
    for ax, (sky, material, title) in zip(axes.ravel(), PANELS, strict=True):
        _panel(ax, table, ranges, sky, material, title)
    handles = [
        Line2D([], [], ls="none", marker=m, color=c, mec="k", ms=8, label=lab)
        for (_, lab), c, m in zip(SPECS, COLOURS, MARKERS, strict=True)
    ]
    handles += [
        Line2D([], [], color="0.3", lw=1.6, label="true γ of the Radiance material (colour)"),
        Line2D([], [], color="0.45", ls="--", lw=1.0, label="paper's nominal γ: 0, 0.5, 1"),
        Line2D(
            [],
            [],
            color="0.3",
            marker="|",
            ms=12,
            ls="none",
            label="bar: lower to upper plateau edge",
        ),
    ]
    fig.legend(handles=handles, loc="lower center", ncol=3, fontsize=9, frameon=False)
    fig.suptitle(
        "Fig. 6 reproduced: object gloss by the paper's peak-frame method "
        f"(Phong n = {exponent:g}, plateau median, mean over sunlit facets), 60 Radiance sequences",
        fontsize=10,
    )
    fig.tight_layout(rect=(0, 0.07, 1, 1))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    path = out / "fig6.png"
    report.save_png(fig, path)
    return path


if __name__ == "__main__":
    print(main())

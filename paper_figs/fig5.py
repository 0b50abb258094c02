"""Fig. 5 of Love & Efford: one facet of matt, intermediate and glossy grey
plastic seen from the west, observed under (a) the clear and (b) the
intermediate sky, and (c) predicted by the paper's model for gamma 0, 0.5, 1.

The facet is the one ``compute_results.py`` chose for Figs. 3 and 5 (in
``results/summary.json``): W-view facet 55 (normal azimuth 304 deg,
elevation 52 deg, 43 labelled pixels, sunlit from 08:00), picked from
predictions and pixel counts only. Observed luminance is the facet's mean
pixel luminance from the Radiance bundles (``results/curves.npz``); the
predictions are ``render.paper_point_sun`` with the baseline's exponent.
Panel (d) puts the single facet in context: over all sunlit W-view facets,
how often the three peaks fall in distinct frames and how often the
intermediate plastic peaks in the glossy plastic's frame
(``summary.json``'s ``peak_stats``).

Usage: python paper_figs/fig5.py [--results DIR] [--out DIR]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from bayesgloss import render, report, scene  # noqa: E402

HERE = Path(__file__).parent
MATERIALS = (("0", "matt (spec 0)"), ("0.5", "intermediate (spec 0.5)"), ("1", "glossy (spec 1)"))
COLOURS = ("tab:brown", "tab:purple", "tab:cyan")
MARKERS = ("o", "s", "^")


def observed(curves, view: str, sky: str, spec: str, facet_id: int):
    """Luminance [cd m^-2] of one facet over the frames, NaN where invalid."""
    key = f"paper-{view}-plastic-{spec}-{sky}"
    f = int(np.flatnonzero(curves[f"{key}/ids"] == facet_id)[0])
    return np.where(curves[f"{key}/valid"][f], curves[f"{key}/luminance"][f], np.nan)


def predicted(view: str, facet_id: int, gammas, exponent: float):
    """paper_point_sun of the facet, (G, T) [relative to a sun of unit radiance]."""
    seq = scene.paper_sequence(view)
    i = int(np.flatnonzero(seq.facets.ids == facet_id)[0])
    geom = render.ViewGeometry(seq.geometry.normal[[i]], seq.geometry.view_direction[[i]])
    g = np.asarray(gammas, float)[:, None, None]
    return render.paper_point_sun(geom, seq.sky.sun_direction, g, exponent)[:, 0, :]


def _frames_axis(ax, n):
    ax.set_xticks(np.arange(1, n + 1))
    ax.set_xlim(0.5, n + 0.5)
    ax.set_xlabel("frame (hourly, 04:00 to 22:00 local solar time; 9 = noon)")
    ax.grid(alpha=0.3)


def _curves(ax, curves, labels, scale=1.0):
    frames = np.arange(1, curves.shape[1] + 1)
    for y, label, c, m in zip(curves, labels, COLOURS, MARKERS, strict=True):
        k = int(np.nanargmax(y))
        ax.plot(frames, y * scale, "-", color=c, lw=1.6, label=f"{label}: peak frame {k + 1}")
        ax.plot(frames[k], y[k] * scale, m, color=c, ms=9, mec="k", mew=0.7)
        ax.axvline(frames[k], color=c, lw=0.8, ls="--", alpha=0.7)
    _frames_axis(ax, curves.shape[1])
    ax.set_ylim(0, 1.35 * np.nanmax(curves) * scale)  # room for the legend
    ax.legend(fontsize=8, loc="upper left")


def main(argv=None) -> Path:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--results", default=str(HERE / "results"), help="saved results folder")
    p.add_argument("--out", default=str(HERE / "figures"), help="figure folder")
    args = p.parse_args(argv)
    results = Path(args.results)
    summary = json.loads((results / "summary.json").read_text())
    facet = summary["figure_facet"]
    view, fid = facet["view"], facet["facet_id"]
    exponent = json.loads((results / "paper60.json").read_text())["config"]["exponent"]
    with np.load(results / "curves.npz") as z:
        curves = dict(z)

    fig, axes = plt.subplots(2, 2, figsize=(12, 9))
    labels = [lab for _, lab in MATERIALS]
    for ax, sky, tag in zip(axes[0], ("clear", "intermediate"), "ab", strict=True):
        obs = np.array([observed(curves, view, sky, s, fid) for s, _ in MATERIALS])
        _curves(ax, obs, labels, scale=1e-3)
        ax.set_ylabel("facet luminance [kcd m$^{-2}$]")
        ax.set_title(f"({tag}) observed, CIE {sky} sky with sun (Radiance)", fontsize=10)

    gammas = (0.0, 0.5, 1.0)
    pred = predicted(view, fid, gammas, exponent)
    _curves(axes[1, 0], pred, [f"γ = {g:g}" for g in gammas])
    axes[1, 0].set_ylabel("predicted radiance [relative to a sun of unit radiance]")
    axes[1, 0].set_title(
        f"(c) predicted by eq. 2: point sun, no sky, Phong n = {exponent:g}", fontsize=10
    )

    ax = axes[1, 1]
    stats = summary["peak_stats"]
    rows = (
        ("share_all_three_distinct", "matt, intermediate, glossy\npeak in 3 distinct frames"),
        ("share_intermediate_at_glossy_frame", "intermediate peaks in\nthe glossy frame"),
        ("share_intermediate_at_matt_frame", "intermediate peaks in\nthe matt frame"),
    )
    y = np.arange(len(rows))
    for dy, sky, c in ((-0.2, "clear", "tab:orange"), (0.2, "intermediate", "tab:gray")):
        vals = [100 * stats[sky][k] for k, _ in rows]
        bars = ax.barh(
            y + dy, vals, height=0.38, color=c, label=f"{sky} sky ({stats[sky]['facets']} facets)"
        )
        ax.bar_label(bars, fmt="%.0f %%", fontsize=8, padding=2)
    ax.set_yticks(y, [lab for _, lab in rows], fontsize=9)
    ax.invert_yaxis()
    ax.set_xlim(0, 100)
    ax.set_xlabel(
        "share of sunlit W-view facets [%] (grey plastic)\n"
        "(the last two overlap where matt and glossy peak in the same frame)"
    )
    ax.set_title("(d) the same comparison over all W-view facets", fontsize=10)
    ax.legend(fontsize=8, loc="lower right")
    ax.grid(alpha=0.3, axis="x")

    fig.suptitle(
        f"Fig. 5 reproduced: {view}-view facet {fid} (normal azimuth "
        f"{facet['normal_azimuth_deg']:.0f}°, elevation {facet['normal_elevation_deg']:.0f}°) "
        "of grey plastic (colour 0.5), 21 June, 40° N",
        fontsize=11,
    )
    fig.tight_layout()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    path = out / "fig5.png"
    report.save_png(fig, path)
    return path


if __name__ == "__main__":
    print(main())

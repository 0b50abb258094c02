"""Fig. 3 of Love & Efford: predicted radiance of one planar facet over the 19
frames for gloss factors 0, 0.2, ..., 1 (eq. 2 with eqs. 4-6, point sun of
unit radiance, no sky).

The facet is the one ``compute_results.py`` chose for Figs. 3 and 5 (saved
in ``results/summary.json``): of the W view's well-seen, sunlit facets, the
one whose six predicted peaks are most distinct (facet 55, normal azimuth
304 deg, elevation 52 deg). Frames are 04:00 ... 22:00 local solar time, so
frame 9 is solar noon, as in the paper. Panel (a) uses the baseline's
exponent n = 2; panel (b) shows the same facet at n = 20, where the six
curves collapse onto two peak frames.

These are predictions of the paper's model, computed here; nothing is sampled.

Usage: python paper_figs/fig3.py [--results DIR] [--out DIR]
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
GAMMAS = np.round(np.linspace(0.0, 1.0, 6), 1)
NOON_FRAME = 9  # 1-based: frames at 04:00 ... 22:00, so frame 9 is 12:00


def facet_predictions(view: str, facet_id: int, exponent: float):
    """paper_point_sun for the six gloss factors, (6, T), and the frame hours [h]."""
    seq = scene.paper_sequence(view)
    i = int(np.flatnonzero(seq.facets.ids == facet_id)[0])
    geom = render.ViewGeometry(seq.geometry.normal[[i]], seq.geometry.view_direction[[i]])
    pred = render.paper_point_sun(geom, seq.sky.sun_direction, GAMMAS[:, None, None], exponent)
    return pred[:, 0, :], seq.solar_hours


def _panel(ax, pred, exponent, title):
    frames = np.arange(1, pred.shape[1] + 1)
    colours = plt.get_cmap("viridis")(np.linspace(0.0, 0.9, len(GAMMAS)))
    for g, curve, c in zip(GAMMAS, pred, colours, strict=True):
        k = int(np.argmax(curve))
        ax.plot(frames, curve, "-", color=c, lw=1.6, label=f"γ = {g:.1f} (peak: frame {k + 1})")
        ax.plot(frames[k], curve[k], "o", color=c, ms=7, mec="k", mew=0.6)
        if curve[k] < 0.05 * pred.max():  # a lobe too narrow to see at this scale
            ax.annotate(
                f"γ = {g:.1f}: peak {curve[k]:.3f}\n(narrow lobe), frame {k + 1}",
                (frames[k], curve[k]),
                xytext=(0.8, 0.4 * pred.max()),
                fontsize=8,
                arrowprops={"arrowstyle": "->", "color": c},
            )
    ax.axvline(NOON_FRAME, color="0.5", ls=":", lw=1)
    ax.text(
        NOON_FRAME + 0.15,
        0.02,
        "solar noon",
        color="0.35",
        fontsize=8,
        transform=ax.get_xaxis_transform(),
    )
    ax.set_xticks(frames)
    ax.set_xlim(0.5, frames[-1] + 0.5)
    ax.set_ylim(bottom=0)
    ax.set_xlabel("frame (hourly, 04:00 to 22:00 local solar time)")
    ax.set_ylabel("predicted radiance [relative to a sun of unit radiance]")
    ax.set_title(title, fontsize=10)
    ax.legend(
        fontsize=8, loc="upper left", title=f"Phong exponent n = {exponent:g}", title_fontsize=8
    )
    ax.grid(alpha=0.3)


def main(argv=None) -> Path:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--results", default=str(HERE / "results"), help="saved results folder")
    p.add_argument("--out", default=str(HERE / "figures"), help="figure folder")
    args = p.parse_args(argv)
    results = Path(args.results)
    facet = json.loads((results / "summary.json").read_text())["figure_facet"]
    exponent = json.loads((results / "paper60.json").read_text())["config"]["exponent"]

    fig, axes = plt.subplots(1, 2, figsize=(12, 4.8), sharey=False)
    for ax, n, tag in zip(axes, (exponent, 10 * exponent), "ab", strict=True):
        pred, _ = facet_predictions(facet["view"], facet["facet_id"], n)
        _panel(ax, pred, n, f"({tag}) n = {n:g}")
    fig.suptitle(
        f"Fig. 3 reproduced: radiance of {facet['view']}-view facet {facet['facet_id']} "
        f"(normal azimuth {facet['normal_azimuth_deg']:.0f}°, elevation "
        f"{facet['normal_elevation_deg']:.0f}°) by eq. 2, point sun, no sky, 21 June, 40° N",
        fontsize=10,
    )
    fig.tight_layout()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    path = out / "fig3.png"
    report.save_png(fig, path)
    return path


if __name__ == "__main__":
    print(main())

"""Posterior report: one page of figures per bundle, readable at a glance.

Panels: (a) a frame of the sequence, (b) gamma painted on the image per
facet (posterior median) and (c) the width of its 90 % interval, (d) the
object's gloss (population posterior) beside the paper's baseline, (e) the
data of three facets (least, middle, most glossy) with posterior predictive
bands, (f) convergence diagnostics of every facet (R-hat, bulk ESS), (g) a
corner plot of the middle facet's parameters, (h) the model comparison
table when one was run.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .intervals import GAMMA_BOUNDS, highest_density_interval, reported_interval

__all__ = ["posterior_report", "save_png", "format_comparison"]


def save_png(fig, path, dpi: int = 120) -> Path:
    """Save a figure as a 256-colour PNG (a fraction of an RGBA one's size) and close it."""
    import io

    import matplotlib.pyplot as plt
    from PIL import Image

    buf = io.BytesIO()
    fig.savefig(buf, dpi=dpi, format="png")
    plt.close(fig)
    buf.seek(0)
    path = Path(path)
    with Image.open(buf) as im:
        im.convert("RGB").quantize(colors=256).save(path, optimize=True)
    return path


def _tone_map(rgb: np.ndarray) -> np.ndarray:
    """Display a linear frame: luminance scaled to its 99th percentile, gamma 1/2.2."""
    y = np.nanpercentile(rgb, 99)
    return np.clip(np.nan_to_num(rgb / max(y, 1e-12)), 0, 1) ** (1 / 2.2)


def _crop(labels: np.ndarray, margin: int = 4):
    """Row and column slices around the labelled facets."""
    rows, cols = np.nonzero(labels > 0)
    if len(rows) == 0:
        return slice(None), slice(None)
    r0, r1 = max(rows.min() - margin, 0), rows.max() + margin + 1
    c0, c1 = max(cols.min() - margin, 0), cols.max() + margin + 1
    return slice(r0, r1), slice(c0, c1)


def _paint(labels: np.ndarray, ids: np.ndarray, values: np.ndarray) -> np.ndarray:
    """An image of per-facet values on the label image (NaN on background)."""
    lut = np.full(int(labels.max()) + 1, np.nan)
    lut[np.asarray(ids, int)] = values
    return lut[labels]


def _corner(fig, cell, idata, k, plt) -> None:
    """Pairwise posterior of one facet's parameters (a corner plot)."""
    names = [v for v in ("gamma", "n", "s", "sigma") if v in idata.posterior]
    draws = [idata.posterior[v].values[..., k].ravel() for v in names]
    logs = {"n", "s", "sigma"}
    draws = [np.log10(d) if v in logs else d for v, d in zip(names, draws, strict=True)]
    labels = [f"log10 {v}" if v in logs else v for v in names]
    # axes span the central 99 % of each parameter, so a few stray draws of a
    # not-yet-converged chain do not squash the picture
    lims = []
    for d in draws:
        lo, hi = np.quantile(d, [0.005, 0.995])
        pad = 0.05 * (hi - lo) or 1e-6
        lims.append((lo - pad, hi + pad))
    sub = cell.subgridspec(len(names), len(names), wspace=0.05, hspace=0.05)
    fid = idata.posterior["facet"].values[k]
    for i in range(len(names)):
        for j in range(i + 1):
            ax = fig.add_subplot(sub[i, j])
            if i == j:
                ax.hist(draws[i], bins=40, range=lims[i], color="tab:blue", alpha=0.7)
                ax.set_yticks([])
            else:
                ax.hist2d(draws[j], draws[i], bins=40, range=[lims[j], lims[i]], cmap="Blues")
            if i == len(names) - 1:
                ax.set_xlabel(labels[j], fontsize=8)
            else:
                ax.set_xticklabels([])
            if j == 0 and i > 0:
                ax.set_ylabel(labels[i], fontsize=8)
            elif j > 0:
                ax.set_yticklabels([])
            ax.tick_params(labelsize=7)
            if i == 0 and j == 0:
                ax.set_title(f"(g) corner plot, facet {fid}", fontsize=10, loc="left")


def _comparison_table(ax, comparison) -> None:
    """The model comparison table, as text (or a note that none was run)."""
    ax.axis("off")
    ax.set_title("(h) model comparison (k!: a Pareto k above 0.7)", loc="left")
    if not comparison:
        ax.text(
            0.0,
            0.9,
            "no model comparison in this run\n(bayesgloss compare BUNDLE)",
            va="top",
            family="monospace",
            fontsize=9,
        )
        return
    lines = [
        line.replace("  WARNING: Pareto k > 0.7", "  k!") for line in str(comparison).splitlines()
    ]
    text = ax.text(
        0.0,
        0.95,
        "\n".join(line[:118] for line in lines),
        va="top",
        family="monospace",
        fontsize=6.5,
        transform=ax.transAxes,
    )
    text.set_in_layout(False)  # a wide table must not squeeze the figures above


def posterior_report(
    bundle, result, baseline=None, path="report.png", title=None, comparison=None
) -> Path:
    """Write the one-page posterior report of a bundle as a PNG.

    Parameters
    ----------
    bundle : bayesgloss.bundle.Bundle
    result : bayesgloss.estimate.EstimateResult
    baseline : bayesgloss.baseline.BaselineResult, optional
    path : path
        Output PNG.
    title : str, optional
    comparison : str or pandas.DataFrame, optional
        A model comparison table to show (panel h).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    idata, summary = result.idata, result.summary
    ids = idata.posterior["facet"].values
    gamma = idata.posterior["gamma"].values  # (E, S, F)
    flat = gamma.reshape(-1, gamma.shape[-1])
    med = np.median(flat, axis=0)
    # each facet's reported interval: its posterior with the model's error
    reported = {f["id"]: reported_interval(f["gamma"]) for f in summary["facets"] if f["gamma"]}
    if all(int(i) in reported for i in ids):
        lo90, hi90 = (np.array([reported[int(i)][j] for i in ids]) for j in (0, 1))
    else:  # a summary from before the model error
        lo90, hi90 = highest_density_interval(flat, bounds=GAMMA_BOUNDS)

    fig = plt.figure(figsize=(15, 14.5), constrained_layout=True)
    grid = fig.add_gridspec(3, 4, height_ratios=[1, 1, 1.15])
    # the brightest frame, as the bundle numbers it (a joint model keeps a subset)
    t_mid = int(np.argmax(np.nansum(idata.observed_data["y"].values, axis=0)))
    t_mid = int(idata.observed_data["frame"].values[t_mid])
    frame, _ = bundle.linear_frame(t_mid)
    crop = _crop(bundle.labels)
    ax = fig.add_subplot(grid[0, 0])
    ax.imshow(_tone_map(np.asarray(frame))[crop])
    ax.set_title(f"(a) frame {t_mid} ({bundle.times[t_mid]:%H:%M} UTC)")
    ax.axis("off")

    ax = fig.add_subplot(grid[0, 1])
    im = ax.imshow(_paint(bundle.labels, ids, med)[crop], cmap="viridis", vmin=0, vmax=1)
    ax.set_title("(b) gamma per facet (median)")
    ax.axis("off")
    fig.colorbar(im, ax=ax, shrink=0.8, label="gamma [-]")

    ax = fig.add_subplot(grid[0, 2])
    im = ax.imshow(
        _paint(bundle.labels, ids, hi90 - lo90)[crop],
        cmap="magma_r",
        vmin=0,
        vmax=max(0.05, float(np.max(hi90 - lo90))),
    )
    ax.set_title("(c) reported 90 % width")
    ax.axis("off")
    fig.colorbar(im, ax=ax, shrink=0.8, label="highest-density interval width [-]")

    ax = fig.add_subplot(grid[0, 3])
    obj = summary["object"]["gamma"]
    obj_lo, obj_hi = reported_interval(obj)
    ax.hist(med, bins=np.linspace(0, 1, 41), color="0.75", label="facet medians")
    ax.axvspan(
        obj_lo,
        obj_hi,
        color="tab:blue",
        alpha=0.2,
        label=f"object 90 %: {obj_lo:.3f}-{obj_hi:.3f}",
    )
    if "gamma_within_model" in summary["object"]:  # the model's own interval, error aside
        w_lo, w_hi = reported_interval(summary["object"]["gamma_within_model"])
        tau = summary["object"]["model_error"]["sd"]
        ax.axvspan(
            w_lo,
            w_hi,
            color="tab:blue",
            alpha=0.35,
            label=f"within the model: {w_lo:.3f}-{w_hi:.3f} (model error sd {tau:.3f})",
        )
    ax.axvline(obj["median"], color="tab:blue", lw=2, label=f"object median {obj['median']:.3f}")
    if baseline is not None and np.isfinite(baseline.object_gloss):
        ax.axvline(
            baseline.object_gloss,
            color="tab:red",
            ls="--",
            lw=2,
            label=f"baseline (peak frame) {baseline.object_gloss:.3f}",
        )
    ax.set(xlabel="gamma [-]", ylabel="facets", title="(d) object gloss", xlim=(0, 1))
    ax.legend(fontsize=8, loc="upper center")
    weights = _model_weights(summary)
    if obj_flags := summary["object"].get("flags"):
        weights = "\n".join(filter(None, [weights, "object: " + ", ".join(obj_flags)]))
    if weights:  # the stacked sky, lobe and faces' albedo weights, the object's flags
        ax.text(0.02, 0.02, weights, transform=ax.transAxes, fontsize=7, va="bottom", ha="left")

    # (e) three facets: the least and most glossy and the middle one, with bands
    order = np.argsort(med)
    pick = order[np.linspace(0, len(order) - 1, 3).round().astype(int)]
    y = idata.observed_data["y"].values
    pp = idata.posterior_predictive["y"].values.reshape(-1, *y.shape)
    frames = np.arange(y.shape[1])
    for j, k in enumerate(pick):
        ax = fig.add_subplot(grid[1, j])
        lo, mid, hi = np.quantile(pp[:, k], [0.05, 0.5, 0.95], axis=0)
        ax.fill_between(frames, lo, hi, color="tab:blue", alpha=0.25, label="90 % predictive")
        ax.plot(frames, mid, color="tab:blue", lw=1.5, label="predictive median")
        ax.plot(frames, y[k], "ko", ms=4, label="observed")
        ax.set_title(
            f"(e) facet {ids[k]}: gamma {med[k]:.2f} [{lo90[k]:.2f}, {hi90[k]:.2f}]", fontsize=9
        )
        ax.set(xlabel="frame", ylabel=f"luminance [{summary.get('unit', 'relative')}]")
        if j == 0:
            ax.legend(fontsize=8)

    ax = fig.add_subplot(grid[1, 3])
    rhat = np.array([f.get("rhat", np.nan) for f in summary["facets"] if f["gamma"]])
    ess = np.array([f.get("ess_bulk", np.nan) for f in summary["facets"] if f["gamma"]])
    conv = np.array([f["converged"] for f in summary["facets"] if f["gamma"]])
    ax.scatter(ess, rhat, c=np.where(conv, "tab:green", "tab:red"), s=18)
    ax.axhline(1.01, color="0.4", ls="--")
    ax.axvline(400, color="0.4", ls="--")
    ax.set(
        xscale="log",
        xlabel="bulk ESS of gamma",
        ylabel="R-hat of gamma",
    )
    ax.set_title(f"(f) converged: {conv.sum()}/{len(conv)} (green)", fontsize=9)
    _corner(fig, grid[2, :2], idata, pick[1], plt)
    if comparison is None and "sun" in idata.posterior:
        _illumination_panel(fig.add_subplot(grid[2, 2:]), idata)
    else:
        _comparison_table(fig.add_subplot(grid[2, 2:]), comparison)
    fig.suptitle(
        title
        or f"{Path(str(bundle.path)).name}: posterior gloss "
        f"({summary['illumination']}, {summary['noise']} noise)"
    )
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def _model_weights(summary) -> str:
    """Lines of the stacking weights of the sky families, the lobe families and
    a mesh's faces' albedos (``estimate``'s ``sky_families``, ``lobe_families``
    and ``occluder_albedos``), empty where none."""
    lines = []
    sky = summary.get("sky_families", {}).get("families")
    if sky:
        equal = summary["sky_families"].get("equal_weights")
        label = "sky (equal: PSIS-LOO unreliable)" if equal else "sky"
        lines.append(f"{label}: " + ", ".join(f"{k} {v['weight']:.2f}" for k, v in sky.items()))
    lobes = summary.get("lobe_families")
    if lobes:
        lines.append("lobe: " + ", ".join(f"{k} {v['weight']:.2f}" for k, v in lobes.items()))
    faces = summary.get("occluder_albedos")
    if faces:
        lines.append(
            "faces' albedo: " + ", ".join(f"{k} {v['weight']:.2f}" for k, v in faces.items())
        )
    return "\n".join(lines)


def _illumination_panel(ax, idata) -> None:
    """(h) each frame's inferred sun and sky brightness (relative to the sky
    model's), and exposure where it was unknown: medians and 90 % intervals."""
    frames = idata.posterior["frame"].values
    styles = {"sun": "tab:orange", "sky": "tab:blue", "exposure": "0.4"}
    for name, colour in styles.items():
        if name not in idata.posterior:
            continue
        x = idata.posterior[name].values.reshape(-1, len(frames))
        lo, mid, hi = np.quantile(x, [0.05, 0.5, 0.95], axis=0)
        ax.fill_between(frames, lo, hi, color=colour, alpha=0.2)
        ax.plot(frames, mid, "o-", color=colour, ms=3, label=f"{name} (x model)")
    ax.set_yscale("log")
    ax.set(xlabel="frame", ylabel="relative to the sky model [-]")
    title = "(h) each frame's illumination, inferred with the facets (90 %)"
    if "sky_family_weights" in idata.posterior.attrs:  # stacked day-level families
        weights = json.loads(idata.posterior.attrs["sky_family_weights"])
        kind = "equal" if idata.posterior.attrs.get("sky_family_equal_weights") else "stacking"
        title += f"\nsky families ({kind} weight): " + ", ".join(
            f"{name} {w:.2f}" for name, w in weights.items()
        )
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=8, loc="lower left")
    if "sky_weight" in idata.posterior:  # the sky models' weights, posterior means
        weights = idata.posterior["sky_weight"]
        twin = ax.twinx()
        mean = weights.values.mean(axis=(0, 1))  # (T, K)
        for k, name in enumerate(weights["sky_model"].values):
            twin.plot(frames, mean[:, k], "--", lw=1, label=f"weight: {name}")
        twin.set(ylim=(0, 1), ylabel="sky model weight (mean) [-]")
        twin.legend(fontsize=7, loc="lower right")


def format_comparison(res: dict, name, level: str = "object") -> str:
    """The comparison table of :func:`bayesgloss.compare.compare_bundle` as text
    (printed by ``bayesgloss compare`` and drawn into the report)."""
    out = [
        f"{name}: model comparison, {level} level, {len(res['facets'])} facets (PSIS-LOO: "
        + ("leave-one-facet-out" if level == "object" else "leave-one-frame-out")
        + ")",
        f"{'model':36s} {'elpd_loo':>10} {'se':>7} {'d_elpd':>8} {'dse':>7} "
        f"{'weight':>6} {'k_max':>6} {'k>0.7':>6}  {'ln Z':>10} {'se':>6} {'ln BF':>8}",
    ]
    ev = {e["model"]: e for e in res["evidence"]}
    for r in res["loo"]["table"]:
        e = ev[r["model"]]
        flag = "  WARNING: Pareto k > 0.7" if r["warning"] else ""
        out.append(
            f"{r['model']:36s} {r['elpd_loo']:10.1f} {r['se']:7.1f} {r['elpd_diff']:8.1f} "
            f"{r['dse']:7.1f} {r['weight']:6.3f} {r['pareto_k_max']:6.2f} "
            f"{r['pareto_k_high']:>3}/{r['n_terms']:<3} {e['log_z']:10.1f} {e['se']:6.2f} "
            f"{e['log_bf_vs_best']:8.1f}{flag}"
        )
    out.append("ln BF: ln Z of the model minus ln Z of the best (thermodynamic integration)")
    for sky_name, rows in res["savage_dickey"].items():
        vals = ", ".join(("<= " if r["bound"] else "") + f"{r['log_bf01']:.2f}" for r in rows[:10])
        more = " ..." if len(rows) > 10 else ""
        out.append(f"Savage-Dickey ln BF(lambert : lambert+phong), {sky_name}: {vals}{more}")
    probs = ", ".join(f"{k} {v:.3f}" for k, v in res["sky"]["prob"].items())
    out.append(f"sky posterior (equal priors): {probs}")
    not_conv = [k for k, v in res["converged"].items() if not v]
    if not_conv:
        out.append(
            f"WARNING: not converged (R-hat >= 1.01 or run < 50 autocorrelation times): "
            f"{', '.join(not_conv)}"
        )
    return "\n".join(out)

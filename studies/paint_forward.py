"""A rendered sequence repainted with the forward model's own light, to fit.

Where an answer is wrong on a render, three causes are possible: the
renderer makes light the forward model does not (``forward_check.py``
measures that at the truth), the fit's model averaging chose the wrong sky
or lobe, or the posterior itself is wrong for data the model made. This
probe isolates the last: each facet's pixels in each frame are scaled so
that its luminance curve is the forward model's prediction
(:func:`forward_check.predictions`, the convex ground shadow, the default)
for the true material with its specularity replaced by ``--specularity``,
under the true sky, in the render's units. Everything else of the bundle
(geometry, times, encoding) is the render's, so the estimator sees data
its own forward model made, with the sequence's design.

Usage::

    python studies/paint_forward.py --set validation_holdout27 --which 13 \\
        --specularity 0.0365 --out /tmp/vs13-painted
    bayesgloss estimate /tmp/vs13-painted --sky cie-2 --lobe phong --json

Only the facets the estimator fits by default are repainted
(:func:`forward_check.checked_entries`); it reads the set's bundle from
``studies/out/<set>/bundles``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import shutil
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent))

import forward_check  # noqa: E402

from bayesgloss import bundle as bundle_io  # noqa: E402


def painted_luminance(y, truth_model, model) -> np.ndarray:
    """Target luminances (F, T): ``model`` in the render's units, the unit
    being the render's median ratio to ``truth_model`` (the forward model
    at the true material; Radiance's 179 lm/W, near enough)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        unit = np.exp(np.nanmedian(np.log(y / truth_model)))
    return model * unit


def paint(source: Path, out: Path, config: dict, specularity: float) -> dict:
    """Copy the bundle ``source`` to ``out`` with its fitted facets'
    pixels scaled to the forward model at ``specularity``; the figures of
    the repaint (the render's spread about the truth's prediction)."""
    clean = forward_check.clean_config(config)
    b = bundle_io.read_bundle(source)
    y, checked, _ = forward_check.checked_entries(b)
    day = forward_check.true_sky(clean, b.sun_direction)
    truth_model = forward_check.predictions(b, day, clean, checked)["convex"]
    other = dataclasses.replace(clean, specularity=specularity)
    model = forward_check.predictions(b, day, other, checked)["convex"]
    seen = y[checked]
    target = painted_luminance(seen, truth_model, model)
    shutil.rmtree(out, ignore_errors=True)
    shutil.copytree(source, out)
    labels = bundle_io.read_labels(out / "facets.png")
    ids = np.asarray(b.facets.ids)[checked]
    frames = json.loads((out / "sequence.json").read_text())["frames"]
    for t, frame in enumerate(frames):
        path = out / frame["file"]
        image = bundle_io.read_hdr(path).astype(np.float64)
        for j, facet in enumerate(ids):
            if np.isfinite(seen[j, t]) and seen[j, t] > 0:
                image[labels == facet] *= target[j, t] / seen[j, t]
        bundle_io.write_hdr(path, image.astype(np.float32))
    with np.errstate(divide="ignore", invalid="ignore"):
        spread = float(np.nanstd(np.log(seen / truth_model)))
    return {"facets": int(checked.sum()), "render_sd_about_truth": spread}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--set", required=True, help="a set with results/<set>_configs.json")
    ap.add_argument("--which", type=int, required=True, help="the sequence's index")
    ap.add_argument("--specularity", type=float, required=True)
    ap.add_argument("--out", required=True, help="the repainted bundle's folder")
    args = ap.parse_args(argv)
    path = HERE / "results" / f"{args.set}_configs.json"
    if not path.exists():
        raise SystemExit(f"paint_forward: {path}: no drawn configs for set {args.set!r}")
    sequences = json.loads(path.read_text())["sequences"]
    if not 0 <= args.which < len(sequences):
        raise SystemExit(
            f"paint_forward: {path}: --which {args.which}: the set has sequences "
            f"0-{len(sequences) - 1}"
        )
    entry = sequences[args.which]
    bundles = HERE / "out" / args.set / "bundles"
    source = bundles / f"{entry['name']}-{entry['key']}"
    if not (source / "sequence.json").exists():
        raise SystemExit(f"paint_forward: {source}: not rendered (validation_set.py first)")
    if entry["config"]["pixel_encoding"] != "linear-radiance":
        raise SystemExit(f"paint_forward: {source}: only linear-radiance bundles are repainted")
    out = paint(source, Path(args.out), entry["config"], args.specularity)
    print(json.dumps(out))
    return out


if __name__ == "__main__":
    main()

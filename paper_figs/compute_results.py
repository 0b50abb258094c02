"""Render (or load from the cache) the paper's 60 Radiance sequences and save
what the figure scripts need: per-sequence facet curves and baseline estimates.

Usage: python paper_figs/compute_results.py [--cache out/bundles] [--size 128]
Writes paper_figs/results/paper60.json (small, committed) and
paper_figs/results/curves.npz (facet curves of the W-view bundles for Fig. 5).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from bayesgloss import baseline, bundle, sequences, sun

HERE = Path(__file__).parent
CONFIG = {"image_size": 128, "exponent": baseline.DEFAULT_EXPONENT}


def estimate(path: Path, exponent: float) -> dict:
    b = bundle.read_bundle(path)
    curves = bundle.facet_curves(b)
    hours = np.unwrap(sun.local_solar_time(b.times, b.site.longitude), period=24)
    res = baseline.peak_frame_gloss(
        curves.luminance, curves.valid, b.view_geometry(), b.sun_direction,
        ids=curves.ids, exponent=exponent, frame_hours=hours,
    )
    out = res.to_json()
    out["truth"] = {k: v for k, v in b.truth.items() if k != "config"}
    out["view"] = b.truth["config"]["view"]
    out["degenerate_share"] = float(np.mean(["mirror-degenerate" in f for f in res.flags]))
    return out, curves, hours


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--cache", default="out/bundles")
    p.add_argument("--size", type=int, default=CONFIG["image_size"])
    p.add_argument("--jobs", type=int, default=2)
    args = p.parse_args(argv)
    configs = sequences.paper_configs(image_size=args.size)
    paths = sequences.render_bundles(configs, args.cache, jobs=args.jobs)
    results, arrays = [], {}
    for cfg, path in zip(configs, paths, strict=True):
        est, curves, hours = estimate(path, CONFIG["exponent"])
        est["name"] = cfg.name
        results.append(est)
        if cfg.view == "W":
            arrays[f"{cfg.name}/luminance"] = curves.luminance
            arrays[f"{cfg.name}/valid"] = curves.valid
            arrays[f"{cfg.name}/ids"] = curves.ids
            arrays["hours"] = hours
    out = HERE / "results"
    out.mkdir(exist_ok=True)
    (out / "paper60.json").write_text(json.dumps(
        {"config": {**CONFIG, "image_size": args.size}, "sequences": results}, indent=1))
    np.savez_compressed(out / "curves.npz", **arrays)
    print(f"wrote {out / 'paper60.json'} and {out / 'curves.npz'}")


if __name__ == "__main__":
    main()

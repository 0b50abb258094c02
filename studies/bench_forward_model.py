"""Benchmark: the forward model against Radiance's rtrace, side by side in one run.

For every facet of the paper's hemisphere that faces the camera and every one
of the 19 frames, both compute the radiance toward the camera of matt
(specularity 0) and glossy (specularity 1) grey plastic under gensky's clear
sky with sun. rtrace runs with the settings the agreement tests use (one
ambient bounce to the sky and ground glow, no irradiance cache, 4096
stratified samples); the forward model with its defaults. Printed: wall
times, their ratio, and the agreement (the issue's criteria: matt within 3 %
with the sun up, glossy peak frame and height within 10 %).

Usage: python studies/bench_forward_model.py [--view W] [--sky clear] [--out DIR]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from bayesgloss import radiance, render, scene, sky


def _rtrace_day(seq, facets, kind, spec, sky_type):
    mat = radiance.material("mat", kind, scene.PAPER["colour"], spec, 0.0)
    obj = mat + radiance.polygons(facets.polygons, "mat")
    dirs = facets.center - seq.camera_position
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    origins = np.tile(seq.camera_position, (len(facets), 1))
    out = np.empty((len(facets), len(seq.times)))
    for t, s in enumerate(seq.sky.sun_direction):
        text = radiance.gensky_ang(s, sky_type) + radiance.sky_glow(ground=True) + obj
        out[:, t] = radiance.rtrace_scene(text, origins, dirs)[:, 1]
    return out


def _model_day(seq, geom, kind, spec, sky_type):
    day = sky.daylight(f"gensky-{sky_type}", seq.sky.sun_direction)
    return render.radiance_material_prediction(
        geom, day, kind, scene.PAPER["colour"], spec, ground="sky"
    )


def _best_of(fn, repeat):
    times, result = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - t0)
    return min(times), result


def main(argv=None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--view", default="W")
    p.add_argument("--sky", default="clear", choices=["clear", "intermediate"])
    p.add_argument("--out", default="studies/out/bench_forward_model")
    args = p.parse_args(argv)

    seq = scene.paper_sequence(view=args.view, sky_model=f"gensky-{args.sky}")
    facing = np.flatnonzero(seq.geometry.cos_view > 0.05)
    facets = seq.facets.subset(facing)
    geom = render.view_geometry(facets, seq.camera_position)
    n_pairs = len(facets) * len(seq.times)
    sun_up = seq.sky.sun_direction[:, 2] > 0.02

    results = {"facets": len(facets), "frames": len(seq.times), "view": args.view, "sky": args.sky}
    for label, spec in (("matt", 0.0), ("glossy", 1.0)):
        t_rad, ref = _best_of(lambda s=spec: _rtrace_day(seq, facets, "plastic", s, args.sky), 1)
        t_fm, model = _best_of(lambda s=spec: _model_day(seq, geom, "plastic", s, args.sky), 5)
        rel = np.abs(model[:, sun_up] / ref[:, sun_up] - 1)
        peak_match = float(np.mean(np.argmax(model, 1) == np.argmax(ref, 1)))
        peak_height = float(np.max(np.abs(model.max(1) / ref.max(1) - 1)))
        results[label] = {
            "rtrace_s": t_rad,
            "model_s": t_fm,
            "ratio": t_rad / t_fm,
            "max_rel_sun_up": float(rel.max()),
            "median_rel_sun_up": float(np.median(rel)),
            "peak_frame_match": peak_match,
            "peak_height_max_rel": peak_height,
        }
        print(
            f"{label:6s}: rtrace {t_rad:7.2f} s, forward model {t_fm * 1e3:7.1f} ms "
            f"({n_pairs} facet-frames): ratio {t_rad / t_fm:7.0f}x; "
            f"max |rel| sun up {rel.max():.4f}, peak frames equal {peak_match:.0%}, "
            f"peak height within {peak_height:.4f}"
        )

    # rtrace at the cheapest setting that still meets the 3 % criterion here
    # (measured once: -ad 512 gave 1.6 %, -ad 1024 2.4 %, -ad 256 6.5 %)
    cheap = ("-ab", "1", "-aa", "0", "-ad", "1024", "-as", "512", "-lr", "6", "-lw", "1e-5", "-u-")
    t0 = time.perf_counter()
    mat = radiance.material("mat", "plastic", scene.PAPER["colour"], 0.0, 0.0)
    obj = mat + radiance.polygons(facets.polygons, "mat")
    dirs = facets.center - seq.camera_position
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    for s in seq.sky.sun_direction:
        text = radiance.gensky_ang(s, args.sky) + radiance.sky_glow(ground=True) + obj
        radiance.rtrace_scene(text, np.tile(seq.camera_position, (len(facets), 1)), dirs, cheap)
    t_cheap = time.perf_counter() - t0
    results["matt_rtrace_ad1024_s"] = t_cheap
    print(
        f"matt  : rtrace -ad 1024 {t_cheap:.2f} s: "
        f"ratio {t_cheap / results['matt']['model_s']:.0f}x"
    )

    # the likelihood's tables: D and G on the default 25 exponents, built once,
    # then each prediction is a weighted sum of table rows
    day = sky.daylight(f"gensky-{args.sky}", seq.sky.sun_direction)
    t_b, bases = _best_of(lambda: render.facet_bases(geom, day, ground="sky"), 3)
    t_p, _ = _best_of(lambda: bases.predict(0.4, 150.0, 2.0), 200)
    results["bases_s"] = t_b
    results["predict_from_bases_s"] = t_p
    print(
        f"bases : D and G(n) on {len(render.DEFAULT_EXPONENTS)} exponents for {n_pairs} "
        f"facet-frames in {t_b * 1e3:.0f} ms; a prediction from them {t_p * 1e6:.0f} us "
        f"(ratio to rtrace {results['matt']['rtrace_s'] / t_p:.0f}x)"
    )
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / f"bench_{args.view}_{args.sky}.json").write_text(json.dumps(results, indent=2))
    return results


if __name__ == "__main__":
    main()

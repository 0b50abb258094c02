"""Benchmark: what a non-convex object's mesh costs the forward model.

A mesh of 20,492 triangles (a subdivided icosphere of radius 1 m standing
0.2 m above the ground beside a 4 x 0.3 x 3 m wall), 100 of its faces as
facets (drawn with the seed), 20 frames of suns from east to west. Timed, best
of ``--repeat``: ``visibility.facet_visibility`` (the sunlit fractions and sky
views that flag shadowed entries), ``visibility.occlusion`` (the forward
model's map: 8 rays a facet and quadrature direction, the sun tests of the
points they meet, 2 rays from each of those for its own view), and
``render.facet_bases`` with and without it (25 exponents, gensky's clear
sky). Written to ``--out``/bench_occlusion.json.

Usage: python studies/bench_occlusion.py [--repeat 3] [--seed 1] [--out DIR]
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np


def _mesh():
    import trimesh

    ball = trimesh.creation.icosphere(subdivisions=5, radius=1.0)
    ball.apply_translation([0.0, 0.0, 1.2])
    wall = trimesh.creation.box(extents=[4.0, 0.3, 3.0])
    wall.apply_translation([0.0, 1.8, 1.5])
    return ball, trimesh.util.concatenate([ball, wall])


def _best_of(fn, repeat):
    times, result = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - t0)
    return min(times), result


def main(argv=None) -> dict:
    from bayesgloss import render, sky, sun, visibility
    from bayesgloss.geometry import view_directions

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--out", default="studies/out/bench_occlusion")
    args = p.parse_args(argv)

    ball, mesh = _mesh()
    pick = np.random.default_rng(args.seed).choice(len(ball.faces), 100, replace=False)
    normal, center = ball.face_normals[pick], ball.triangles_center[pick]
    suns = sun.sun_direction(np.linspace(80.0, 20.0, 20), np.linspace(90.0, 270.0, 20))
    geom = render.ViewGeometry(
        normal, view_directions(center, np.array([-10.0, -10.0, 3.0])), center
    )
    day = sky.daylight("gensky-clear", suns)

    n = args.repeat
    t_vis, _ = _best_of(lambda: visibility.facet_visibility(mesh, normal, center, suns), n)
    t_occ, occ = _best_of(lambda: visibility.occlusion(mesh, normal, center, suns), n)
    t_convex, convex = _best_of(lambda: render.facet_bases(geom, day), args.repeat)

    def with_occlusion():
        render._TERMS.clear()  # each run computes the map's radiance terms anew
        return render.facet_bases(geom, day, occlusion=occ)

    t_bases, bases = _best_of(with_occlusion, n)
    result = {
        "mesh_faces": len(mesh.faces),
        "facets": len(normal),
        "frames": len(suns),
        "cpu_count": os.cpu_count(),
        "seconds": {
            "facet_visibility": round(t_vis, 3),
            "occlusion": round(t_occ, 3),
            "facet_bases_convex": round(t_convex, 3),
            "facet_bases_with_occlusion": round(t_bases, 3),
        },
        "pairs": {"ground": len(occ.ground_facet), "blocked": len(occ.hit_facet)},
        "mean_open_fraction_above_facets": float(
            np.mean(
                [
                    occ.open_fraction[f][render.sphere_quadrature(3.0)[0] @ normal[f] > 0].mean()
                    for f in range(len(normal))
                ]
            )
        ),
        "diffuse_ratio_median": float(np.median(bases.diffuse / convex.diffuse)),
    }
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "bench_occlusion.json").write_text(json.dumps(result, indent=2) + "\n")
    s = result["seconds"]
    print(
        f"{result['mesh_faces']} faces, {result['facets']} facets, {result['frames']} frames: "
        f"facet_visibility {s['facet_visibility']:.2f} s, occlusion {s['occlusion']:.2f} s, "
        f"facet_bases {s['facet_bases_convex']:.2f} s convex, "
        f"{s['facet_bases_with_occlusion']:.2f} s with the occlusion"
    )
    return result


if __name__ == "__main__":
    main()

"""Study: estimate on a non-convex object with its mesh's occlusion, and the albedo it assumes.

Radiance renders :func:`bayesgloss.geometry.l_building` (its OBJ as
``SequenceConfig(shape="mesh")``, so the bundle carries ``object_mesh``) in
two grey plastics with a mirror part, seen from the south-west under gensky's
clear sky, linear radiance, rtrace at -ab 3. ``estimate`` (the joint model,
``--sky gensky-clear``, ``--max-steps`` 600) then runs with the mesh's
occlusion at several albedos of the mesh's own faces
(``visibility.bundle_occlusion(occluder_reflectance=...)``; 0.5 is the
default), and with the model of before the occlusion entered it (the convex
forward model, entries wholly in the mesh's shadow left out), by replacing
``joint_estimate.bundle_occlusion`` and ``estimate.shadow_flags`` in this
process. Written: each run's object gamma (median, 90 % HDI) beside the truth.

Usage: python studies/occlusion_estimate.py [--out DIR] [--quick]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import shutil
import warnings
from pathlib import Path

import numpy as np

#: (colour, specularity) of the two plastics (roughness 0); gamma =
#: s / (s + (1 - s) colour), total reflectance about (1 - s) colour + s.
MATERIALS = {"matt-ish": (0.3, 0.1), "shiny": (0.5, 0.5)}
#: Albedos of the mesh's faces tried; None: the model of before.
ALBEDOS = (0.2, 0.5, "own", None)
AMBIENT = ("-ab", "3", "-aa", "0.1", "-ar", "512", "-ad", "512", "-as", "256", "-lr", "6",
           "-lw", "1e-4", "-u-")  # fmt: skip


def _config(mesh, colour, spec, quick):
    from bayesgloss import sequences

    hours = (6.0, 9.0, 12.0, 15.0, 18.0) if quick else tuple(float(h) for h in range(5, 20))
    return sequences.SequenceConfig(
        name=f"lbuilding-{colour}-{spec}",
        shape="mesh",
        mesh_file=str(mesh),
        view="SW",
        camera_height=4.0,
        image_size=64 if quick else 96,
        solar_hours=hours,
        pixel_encoding="linear-radiance",
        colour=colour,
        specularity=spec,
        roughness=0.0,
        ambient=AMBIENT,
    )


def _estimate(path, out, albedo, steps):
    from bayesgloss import bundle as bd
    from bayesgloss import cli, estimate, joint_estimate, visibility

    saved = joint_estimate.bundle_occlusion, estimate.shadow_flags
    try:
        if albedo is None:  # before: convex bases, wholly shadowed entries left out
            joint_estimate.bundle_occlusion = lambda b, **k: None

            def flags(bundle, curves, _=None):
                c = saved[1](bundle, curves)
                v = visibility.bundle_visibility(bundle)
                bit = bd.FLAG_REASONS.index("shadowed-by-object")
                return dataclasses.replace(
                    c, flag_bits=c.flag_bits | (v.shadowed_by_object.astype(np.uint8) << bit)
                )

            estimate.shadow_flags = flags
        else:
            joint_estimate.bundle_occlusion = lambda b, **k: visibility.bundle_occlusion(
                b, occluder_reflectance=albedo
            )
        args = ["estimate", str(path), "--sky", "gensky-clear", "--max-steps", str(steps)]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            code = cli.main([*args, "--jobs", "1", "--out", str(out), "--quiet"])
        if code != 0:
            raise RuntimeError(f"estimate exited {code}")
    finally:
        joint_estimate.bundle_occlusion, estimate.shadow_flags = saved
    gamma = json.loads((out / "summary.json").read_text())["object"]["gamma"]
    return {"median": round(gamma["median"], 4), "hdi90": [round(x, 4) for x in gamma["hdi90"]]}


def main(argv=None) -> dict:
    from bayesgloss import geometry, sequences

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default="studies/out/occlusion_estimate")
    p.add_argument("--quick", action="store_true", help="test size; nothing copied to results/")
    args = p.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    mesh = out / "building.obj"
    geometry.write_obj(geometry.l_building(), mesh)
    steps = 200 if args.quick else 600
    rows = []
    for name, (colour, spec) in MATERIALS.items():
        cfg = _config(mesh, colour, spec, args.quick)
        (path,) = sequences.render_bundles([cfg], out / "cache", jobs=2, progress=False)
        truth = spec / (spec + (1 - spec) * colour)
        own = round((1 - spec) * colour + spec, 3)
        for albedo in ALBEDOS:
            rho = own if albedo == "own" else albedo
            label = "before" if rho is None else f"albedo {rho}"
            shutil.rmtree(out / "runs" / f"{name}-{label}", ignore_errors=True)
            g = _estimate(path, out / "runs" / f"{name}-{label}", rho, steps)
            lo, hi = g["hdi90"]
            rows.append(
                {
                    "material": name,
                    "truth": round(truth, 4),
                    "model": label,
                    **g,
                    "covered": bool(lo <= truth <= hi),
                }  # fmt: skip
            )
            print(f"{name:9s} truth {truth:.3f}  {label:12s} {g['median']:.3f} "
                  f"[{lo:.3f}, {hi:.3f}]{'' if lo <= truth <= hi else '  missed'}")  # fmt: skip
    result = {"rows": rows, "max_steps": steps, "quick": args.quick}
    (out / "summary.json").write_text(json.dumps(result, indent=1) + "\n")
    if not args.quick:
        results = Path("studies/results")
        results.mkdir(exist_ok=True)
        shutil.copy(out / "summary.json", results / "occlusion_estimate.json")
    return result


if __name__ == "__main__":
    main()

"""Study: the mesh's own faces' albedo fixed at 0.5 or stacked, on L buildings nobody tuned to.

Six L-shaped buildings (:func:`bayesgloss.geometry.l_building`, each written
as an OBJ and rendered by Radiance from it, ``SequenceConfig(shape="mesh")``,
so each bundle carries its ``object_mesh``) are drawn under the committed
seed :data:`SEED`, in one fixed order (:func:`draw_configs`):

- footprint 2.5-4 m, wing width 0.25-0.45 of it, north wing 0.8-1.6 m high,
  east wing 0-1 m taller, turned 0-360 deg;
- a camera 8-14 m away, 2-6 m high, at a bearing within 50 deg of the
  direction the L's inner corner opens to (its shadowed walls in view);
- a site at |latitude| 25-50 deg in either hemisphere (half each), any
  longitude, a date through the year, frames at 5:00-19:00 local apparent
  solar time hourly (frames with the sun down are dropped by the reader);
- grey Radiance plastic of colour 0.1-0.9 and specularity 0.02-0.4, half of
  them rough (0.02-0.08);
- gensky's clear sky, linear radiance, rtrace at -ab 3 (the faces' light on
  each other rendered, not modelled) and -st 0 (every rough specular
  reflection traced; :data:`AMBIENT`).

Each bundle is scored once with ``estimate --sky gensky-clear`` (the sky is
not what this tests) and default sampler options, with the faces' albedo
``fixed`` (0.5) and ``stacked`` (:mod:`bayesgloss.occluder_albedo`); the
rule is in ``studies/README.md`` ("Occluder albedo"), written before any of
these was rendered. Written: ``studies/results/occluder_set.json`` (the
drawn configs, each score, the totals).

Usage: python studies/occluder_set.py [--render-only] [--jobs 2] [--out DIR]
"""

from __future__ import annotations

import argparse
import json
import time
import warnings
from pathlib import Path

import numpy as np

#: The set's seed, committed before it was drawn.
SEED = 20261128
#: Sequences in the set.
N_SEQUENCES = 6
#: Radiance's ambient options: -ab 3 so the faces light each other, and -st 0 so
#: that every rough specular reflection is traced. The first run (stop 31,
#: ``results/occluder_set_st015.json``, ``--specular-threshold 0.15``) left
#: rtrace's default -st 0.15: Radiance's ``normal.c`` then renders the sky's
#: and ground's reflection of a rough material of specularity <= 0.15 as
#: Lambertian (only the sun keeps its lobe), which made three of its six
#: plastics (occ01, occ03, occ05) matt in every frame but the sun's highlight.
AMBIENT = ("-ab", "3", "-aa", "0.1", "-ar", "512", "-ad", "512", "-as", "256", "-lr", "6",
           "-lw", "1e-4", "-u-", "-st", "0")  # fmt: skip
METHODS = ("fixed", "stacked")
#: What of each config the results file keeps.
CONFIG_FIELDS = ("name", "latitude", "longitude", "date", "view", "camera_distance",
                 "camera_height", "colour", "specularity", "roughness")  # fmt: skip
HERE = Path(__file__).parent


def _ambient(specular_threshold: float) -> tuple:
    """:data:`AMBIENT` at rtrace's ``-st specular_threshold`` (0.15, rtrace's
    default, as the first run wrote it: without ``-st``)."""
    if specular_threshold == 0.15:
        return AMBIENT[:-2]
    return (*AMBIENT[:-1], f"{specular_threshold:g}")


def draw_configs(out: Path, specular_threshold: float = 0.0) -> list:
    """The set's sequences (module docstring), their OBJ files written into
    ``out``, rendered with rtrace's ``-st specular_threshold``."""
    from bayesgloss import geometry, sequences

    rng = np.random.default_rng(SEED)
    out.mkdir(parents=True, exist_ok=True)
    configs = []
    for i in range(N_SEQUENCES):
        length = rng.uniform(2.5, 4.0)
        width = rng.uniform(0.25, 0.45) * length
        low = rng.uniform(0.8, 1.6)
        heights = (low, low + rng.uniform(0.0, 1.0))
        turn = rng.uniform(0.0, 360.0)
        # the inner corner opens to the south-west before the turn
        bearing = (225.0 + turn + rng.uniform(-50.0, 50.0)) % 360.0
        distance, height = rng.uniform(8.0, 14.0), rng.uniform(2.0, 6.0)
        latitude = rng.uniform(25.0, 50.0) * (1 if i % 2 == 0 else -1)
        longitude = rng.uniform(-180.0, 180.0)
        day = int(rng.integers(0, 365))
        colour, spec = rng.uniform(0.1, 0.9), rng.uniform(0.02, 0.4)
        rough = rng.uniform(0.02, 0.08) if rng.random() < 0.5 else 0.0
        mesh = out / f"building-{i:02d}.obj"
        facets = geometry.l_building(length, width, heights, azimuth=turn)
        geometry.write_obj(facets, mesh)
        date = np.datetime64("2025-01-01") + np.timedelta64(day, "D")
        configs.append(
            sequences.SequenceConfig(
                name=f"occ{i:02d}",
                latitude=round(latitude, 3),
                longitude=round(longitude, 3),
                date=str(date),
                solar_hours=tuple(float(h) for h in range(5, 20)),
                shape="mesh",
                mesh_file=str(mesh),
                view=round(bearing, 2),
                camera_distance=round(distance, 2),
                camera_height=round(height, 2),
                image_size=96,
                colour=round(colour, 3),
                specularity=round(spec, 3),
                roughness=round(rough, 3),
                pixel_encoding="linear-radiance",
                ambient=_ambient(specular_threshold),
            )
        )
    return configs


def _score(path, method: str, seed: int, jobs: int) -> dict:
    """Object gamma of one estimate: median, reported and own 90 % HDI, albedo weights."""
    from bayesgloss import estimate

    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = estimate.estimate_bundle(
            path, illumination="gensky-clear", seed=seed, jobs=jobs, occluder_albedo=method
        )
    obj = result.summary["object"]
    row = {
        "median": round(obj["gamma"]["median"], 4),
        "hdi90": [round(x, 4) for x in obj["gamma"]["hdi90"]],
        "within_median": round(obj["gamma_within_model"]["median"], 4),
        "within_hdi90": [round(x, 4) for x in obj["gamma_within_model"]["hdi90"]],
        "flags": obj.get("flags", []),
        "seconds": round(time.perf_counter() - start, 1),
    }
    if "occluder_albedos" in result.summary:
        row["albedo_weights"] = {
            k: round(v["weight"], 3) for k, v in result.summary["occluder_albedos"].items()
        }
    return row


def _held(q, truth) -> bool:
    return bool(q[0] <= truth <= q[1])


def totals(rows) -> dict:
    """Per method: MAE, own and reported 90 % cover, median widths."""
    out = {}
    for m in METHODS:
        err = [abs(r[m]["median"] - r["truth"]) for r in rows]
        out[m] = {
            "mae": round(float(np.mean(err)), 4),
            "within_cover": sum(_held(r[m]["within_hdi90"], r["truth"]) for r in rows),
            "reported_cover": sum(_held(r[m]["hdi90"], r["truth"]) for r in rows),
            "within_width": round(
                float(np.median([np.ptp(r[m]["within_hdi90"]) for r in rows])), 4
            ),
            "reported_width": round(float(np.median([np.ptp(r[m]["hdi90"]) for r in rows])), 4),
            "n": len(rows),
        }
    return out


def main(argv=None) -> dict:
    from bayesgloss import bundle, sequences

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default=str(HERE / "out" / "occluder_set"))
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--render-only", action="store_true")
    p.add_argument(
        "--specular-threshold",
        type=float,
        default=0.0,
        help="rtrace's -st (default 0: every rough specular reflection traced; the first "
        "run's 0.15 writes results/occluder_set_st015.json)",
    )
    args = p.parse_args(argv)
    out = Path(args.out)
    configs = draw_configs(out / "meshes", args.specular_threshold)
    paths = sequences.render_bundles(configs, out / "bundles", jobs=args.jobs)
    if args.render_only:
        return {}
    rows = []
    for cfg, path in zip(configs, paths, strict=True):
        b = bundle.read_bundle(path)
        truth = float(b.truth["gloss"])
        reflectance = (1 - cfg.specularity) * cfg.colour + cfg.specularity
        row = {"name": cfg.name, "truth": round(truth, 4), "reflectance": round(reflectance, 3)}
        for m in METHODS:
            row[m] = _score(path, m, seed=0, jobs=args.jobs)
        rows.append(row)
        print(json.dumps(row), flush=True)
    result = {
        "seed": SEED,
        "specular_threshold": args.specular_threshold,
        "configs": [
            {k: getattr(c, k) for k in CONFIG_FIELDS} | {"mesh_file": Path(c.mesh_file).name}
            for c in configs
        ],
        "rows": rows,
        "totals": totals(rows),
    }
    results = HERE / "results"
    results.mkdir(exist_ok=True)
    name = "occluder_set"
    if args.specular_threshold != 0:
        name += f"_st{args.specular_threshold:g}".replace(".", "")
    (results / f"{name}.json").write_text(json.dumps(result, indent=1) + "\n")
    print(json.dumps(result["totals"], indent=1))
    return result


if __name__ == "__main__":
    main()

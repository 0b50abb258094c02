"""The forward model at the truth against Radiance, facet by facet and frame by frame.

A validation set's answer can be wrong because the sampler, the priors or
the model averaging are wrong, or because the forward model itself does
not make the light Radiance makes. This study separates the last: each
sequence of a set's configs is rendered again without what the estimator
must infer (linear radiance, no exposure change, no sensor noise), and
each facet's luminance curve is divided by the forward model's prediction
for the true material under the true sky (the renderer's own sky: gensky
with its turbidity, gendaylit's Perez or a CIE sky from the frames' DNI
and DHI). One material lit by one sky, with a right model, gives every
facet the same ratio in every frame (the camera's luminance unit, 179 for
Radiance's lm/W); what the ratio does over the frames is what a fit must
put into gloss, the sky's latent brightnesses, or its residuals.

Forward models checked: the default's until stop 49 (facet centres, the
ground sunlit everywhere, ``estimate --ground-shadow none``) and the convex
object's shadow on the ground (``--ground-shadow convex``, the default
since stop 49: the object the
facets bound shadows the ground at its foot, bases averaged over points of
each facet, :mod:`bayesgloss.object_shadow`), that shadow in the diffuse
part only, and the shadow with a rough material's lobe by Radiance's own
rules (:mod:`bayesgloss.radiance_ward`) in place of the integrated Ward
lobe the estimator fits. Materials as Radiance makes
them: plastic (white specular part of specularity s, coloured diffuse part
(1 - s) colour) and metal (both parts coloured), rough ones with the Ward
lobe of Radiance's normalisation (:func:`bayesgloss.render.ward_facet_bases`),
roughness-0 ones with Radiance's Fresnel-raised mirror
(:func:`bayesgloss.render.radiance_material_prediction`). The material's
colour enters as its luminance, which the ratio's constant absorbs.

Reported per sequence (``results/forward_check_<set>.json``): per facet
the spread of the log ratio over frames with the sun up (max - min, and
its standard deviation) over the facets the estimator fits by default (at
least 4 such frames, not facing the ground: :mod:`bayesgloss.ground_facing`),
and the spread of all facets' log ratios about
one common value (the object's one albedo: a facet lit wrongly on average
shows here, not in its own spread); per forward model.

Usage::

    python studies/forward_check.py --set validation_holdout15 [--which 5,7] [--jobs 2]

Renders go to ``studies/out/forward_check/bundles`` (cached by config).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

from bayesgloss import bundle as bundle_io  # noqa: E402
from bayesgloss import render, sequences, sky  # noqa: E402
from bayesgloss.ground_facing import GROUND_FACING_NZ  # noqa: E402
from bayesgloss.object_shadow import facet_mean, shadow_points  # noqa: E402
from bayesgloss.radiance_ward import radiance_ward_glossy_basis  # noqa: E402

#: Radiance's luminance of an RGB triple (its ``bright`` macro), [-].
RADIANCE_LUMINANCE = np.array([0.265, 0.670, 0.065])
#: Fewest frames with the sun up and a valid value for a facet to be checked.
MIN_FRAMES = 4
CACHE = HERE / "out" / "forward_check" / "bundles"
RESULTS = HERE / "results"


def clean_config(config: dict) -> sequences.SequenceConfig:
    """The sequence's config rendered as the model's own data: linear
    radiance, no exposure change, no sensor noise, no white scale."""
    c = {k: tuple(v) if isinstance(v, list) else v for k, v in config.items()}
    c.update(
        name=c["name"] + "-clean",
        pixel_encoding="linear-radiance",
        bit_depth=None,
        sensor_noise=0.0,
        white_scale=1.0,
        exposure=None,
        exposure_jitter=0.0,
    )
    return sequences.SequenceConfig(**c)


def true_sky(config: sequences.SequenceConfig, sun_direction):
    """The sky the renderer drew each frame from (``sequences._sky_text``'s)."""
    rho = config.ground_reflectance
    if config.sky.startswith("gensky-"):
        return sky.daylight(
            config.sky, sun_direction, turbidity=config.turbidity, ground_reflectance=rho
        )
    dni, dhi = config.irradiances()
    day = int(config.frame_times()[0].day_of_year)
    return sky.daylight(
        config.sky,
        sun_direction,
        direct_normal_irradiance=dni,
        diffuse_horizontal_irradiance=dhi,
        ground_reflectance=rho,
        day_of_year=day,
    )


def material_prediction(
    geometry, day, config: sequences.SequenceConfig, glossy_geometry=None, rough="integrated"
):
    """Radiance toward the camera of the true material, (F, T), in the
    material's luminance (the colour's luminance times the parts); the
    glossy part on ``glossy_geometry`` where given (the same points, e.g.
    without the occluder), else on ``geometry``; a rough material's lobe
    ``"integrated"`` (:func:`bayesgloss.render.ward_glossy_basis`, the
    estimator's Ward family) or ``"radiance"`` (Radiance's own rules,
    :mod:`bayesgloss.radiance_ward`)."""
    glossy_geometry = geometry if glossy_geometry is None else glossy_geometry
    colour = np.broadcast_to(np.asarray(config.colour, dtype=float), 3)
    lum = float(RADIANCE_LUMINANCE @ colour)
    s, alpha, rho = config.specularity, config.roughness, config.ground_reflectance
    common = dict(ground="plane", ground_reflectance=rho)
    if alpha == 0:  # Radiance's mirror materials
        return render.radiance_material_prediction(
            geometry,
            day,
            config.material,
            lum,
            s,
            0.0,
            ground_reflectance=rho,
            mirror_geometry=glossy_geometry,
        )
    diffuse = render.diffuse_basis(geometry, day, **common)
    lobe = render.ward_glossy_basis if rough == "integrated" else radiance_ward_glossy_basis
    glossy = lobe(glossy_geometry, day, [alpha], **common)[:, 0, :]
    specular = s * (lum if config.material == "metal" else 1.0)
    return lum * (1.0 - s) * diffuse + specular * glossy


def predictions(b, day, config, checked) -> dict:
    """The forward model's prediction of the ``checked`` facets, (F, T):
    ``none`` (facet centres, no shadow: the default until stop 49),
    ``convex`` (points over each facet, the convex object's ground shadow in
    both parts: the default since) and
    ``convex-diffuse`` (the shadow in the diffuse part only), and
    ``convex-radiance`` (``convex`` with Radiance's own rough-specular rules)."""
    geometry = b.view_geometry()
    idx = np.flatnonzero(checked)
    plain = render.ViewGeometry(
        geometry.normal[idx], geometry.view_direction[idx], geometry.center[idx], None
    )
    points, owner = shadow_points(b.facets, b.camera_position, which=checked)
    unshadowed = dataclasses.replace(points, occluder=None)

    def per_facet(at_points):
        return facet_mean(at_points, owner, len(idx))

    return {
        "none": material_prediction(plain, day, config),
        "convex": per_facet(material_prediction(points, day, config)),
        "convex-diffuse": per_facet(material_prediction(points, day, config, unshadowed)),
        "convex-radiance": per_facet(material_prediction(points, day, config, rough="radiance")),
    }


def log_ratio(y, model) -> np.ndarray:
    """log(y / model), NaN where either is not positive (or not finite)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.log(y / model)
    return np.where(np.isfinite(r), r, np.nan)


def spreads(y, model) -> dict:
    """Spread of log(y / model) over the frames, per facet and about one
    value common to all facets (entries where either is not positive left out)."""
    r = log_ratio(y, model)
    per = np.nanmax(r, axis=1) - np.nanmin(r, axis=1)
    sd = np.nanstd(r, axis=1)
    common = float(np.nanstd(r))
    return {
        "ratio_median": float(np.exp(np.nanmedian(r))),
        "facet_range": per.tolist(),
        "facet_sd": sd.tolist(),
        "object_sd": common,
        "max_facet_range": float(np.nanmax(per)),
    }


def checked_entries(b):
    """A bundle's luminances with the sun up (NaN elsewhere), (F, T), the
    facets the estimator fits by default (at least :data:`MIN_FRAMES` such
    frames, not facing the ground), (F,), and those facing the ground."""
    curves = bundle_io.facet_curves(b)
    y = np.where(curves.valid & b.sun_up[None, :], curves.luminance, np.nan)
    facing_down = np.asarray(b.facets.normal)[:, 2] < GROUND_FACING_NZ
    checked = (np.isfinite(y).sum(axis=1) >= MIN_FRAMES) & ~facing_down
    return y, checked, facing_down


def check(path: Path, config: sequences.SequenceConfig) -> dict:
    """One rendered sequence against each forward model of :func:`predictions`."""
    b = bundle_io.read_bundle(path)
    y, checked, facing_down = checked_entries(b)
    day = true_sky(config, b.sun_direction)
    out = {
        "name": config.name.removesuffix("-clean"),
        "shape": config.shape,
        "material": config.material,
        "specularity": config.specularity,
        "roughness": config.roughness,
        "sky": config.sky,
        "facets": int(checked.sum()),
        "facing_ground_left_out": int(facing_down.sum()),
        "normal_z": np.asarray(b.facets.normal)[checked, 2].round(3).tolist(),
    }
    if not checked.any():
        return out
    for name, model in predictions(b, day, config, checked).items():
        out[name] = spreads(y[checked], model)
    return out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--set", required=True, help="a set with results/<set>_configs.json")
    ap.add_argument("--which", default=None, help="comma-separated sequence indices (all)")
    ap.add_argument("--jobs", type=int, default=1)
    args = ap.parse_args(argv)
    drawn = json.loads((RESULTS / f"{args.set}_configs.json").read_text())["sequences"]
    which = range(len(drawn)) if args.which is None else map(int, args.which.split(","))
    configs = [clean_config(drawn[i]["config"]) for i in which]
    paths = sequences.render_bundles(configs, CACHE, jobs=args.jobs, progress=False)
    rows = [check(Path(p), c) for p, c in zip(paths, configs, strict=True)]
    for r in rows:
        if "none" not in r:
            print(f"{r['name']}: no facet with {MIN_FRAMES} sun-up frames")
            continue
        print(
            f"{r['name']:28s} {r['shape']:10s} {r['material']:7s} F={r['facets']:3d} "
            f"max range none {r['none']['max_facet_range']:.3f} convex "
            f"{r['convex']['max_facet_range']:.3f} diffuse-only "
            f"{r['convex-diffuse']['max_facet_range']:.3f}; object sd none "
            f"{r['none']['object_sd']:.3f} convex {r['convex']['object_sd']:.3f} "
            f"diffuse-only {r['convex-diffuse']['object_sd']:.3f} "
            f"radiance rules {r['convex-radiance']['object_sd']:.3f}"
        )
    suffix = "" if args.which is None else "_" + args.which.replace(",", "-")
    out = RESULTS / f"forward_check_{args.set}{suffix}.json"
    out.write_text(json.dumps({"set": args.set, "sequences": rows}, indent=1))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()

"""Command line: ``bayesgloss <command>``.

Commands
--------
demo
    The main job on the built-in default sequence: the paper's hemisphere of
    grey plastic of specularity 0.5, seen from the south-west under gensky's
    clear sky with sun, 19 hourly frames in local solar time on 21 June at
    40 N, rendered with Radiance (cached after the first run). Runs the
    paper's baseline, the posterior and a model comparison (Lambert against
    Lambert plus Phong, clear against intermediate sky), and writes
    summary.json, posterior.nc, comparison.txt and the report figure
    report.png.
compare BUNDLE
    Compare reflectance models (Lambert, Phong, Lambert plus Phong or Ward)
    and skies on a bundle: PSIS-LOO with Pareto-k warnings, evidence by
    thermodynamic integration, Savage-Dickey Bayes factors of Lambert, and
    the skies' posterior probabilities.
curves BUNDLE
    Read a sequence bundle and print each facet's luminance per frame
    (``-`` marks entries left out: sun below the horizon, NaN or saturated
    pixels, too few pixels), or write them as CSV with ``--csv FILE``.
"""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

__all__ = ["main"]


def _demo(args: argparse.Namespace) -> int:
    """The main job on the built-in default sequence (see module docstring)."""
    import time

    from . import baseline, bundle, estimate, reflectance, report, sequences

    t0 = time.perf_counter()
    out = estimate.check_result_folder(args.out)
    out.mkdir(parents=True, exist_ok=True)
    cfg = sequences.SequenceConfig(
        name="demo",
        view=args.view,
        material="plastic",
        specularity=0.5,
        image_size=96,
        sky="gensky-clear",
    )
    print(
        f"bayesgloss demo: {cfg.material} of specularity {cfg.specularity} seen from "
        f"{cfg.view}, {cfg.sky}, {len(cfg.solar_hours)} frames (rendering with Radiance "
        "the first time, then cached)",
        file=sys.stderr,
    )
    (path,) = sequences.render_bundles(
        [cfg], out / "bundles", jobs=args.jobs, progress=not args.quiet
    )
    b = bundle.read_bundle(path)
    base = baseline.bundle_peak_frame_gloss(b)
    # default options, as a user's bundle gets them: the sky's shape and each
    # frame's brightness inferred, not told
    res = estimate.estimate_bundle(b, jobs=args.jobs, seed=0)
    summary = {
        **res.summary,
        "baseline": base.to_json(),
        "truth (scoring only)": {"gloss": b.truth["gloss"]},
    }
    estimate.write_result(out, estimate.EstimateResult(res.idata, summary, res.samples))
    from . import compare

    cmp = compare.compare_bundle_quick(
        b.path,
        reflectance=("lambert", "lambert+phong"),
        illumination=(cfg.sky, "gensky-intermediate"),
        seed=0,
    )
    table = report.format_comparison(cmp, b.path.name, "object")
    (out / "comparison.txt").write_text(table + "\n")
    fig = report.posterior_report(b, res, base, out / "report.png", comparison=table)
    g = res.summary["object"]["gamma"]
    fresnel = reflectance.gloss_of_radiance_material_fresnel(
        cfg.material, cfg.specularity, cfg.colour, b.view_geometry().cos_view
    ).mean()
    print(
        f"object gloss: posterior {g['median']:.3f} [90 %: {_interval(g)}], "
        f"baseline (peak frame) {base.object_gloss:.3f}; the material's true gamma "
        f"{b.truth['gloss']:.3f} at normal view, {fresnel:.3f} over the facets' view angles "
        "with Radiance's Fresnel raise"
    )
    print(
        f"{res.summary['object']['facets_converged']}/{res.summary['object']['facets']} "
        f"facet posteriors converged; report {fig}; posterior {out / 'posterior.nc'}; "
        f"{time.perf_counter() - t0:.0f} s"
    )
    return 0


def _format_curves(curves, bundle_path) -> str:
    """Facet curves as a fixed-width table, one row per facet, '-' for invalid entries."""
    import numpy as np

    from .bundle import FLAG_REASONS

    n_facets, n_frames = curves.luminance.shape
    width = 9
    lines = [
        f"bundle {bundle_path}: {n_facets} facets x {n_frames} frames, "
        f"{curves.statistic} luminance [{curves.unit}], frame times UTC"
        + ("" if curves.response_known else " (camera response unknown)"),
    ]
    header = f"{'facet':>6} {'pixels':>7}" + "".join(
        f" {t:>{width}}" for t in curves.times.strftime("%H:%M")
    )
    lines += [f"{'':>14}" + "".join(f" {f'[{i}]':>{width}}" for i in range(n_frames)), header]
    valid = curves.valid
    for f in range(n_facets):
        cells = [
            f"{curves.luminance[f, t]:>{width}.4g}" if valid[f, t] else f"{'-':>{width}}"
            for t in range(n_frames)
        ]
        lines.append(f"{curves.ids[f]:>6} {curves.n_pixels[f]:>7} " + " ".join(cells))
    counts = [
        f"{reason} {int(np.count_nonzero(curves.flagged(reason)))}" for reason in FLAG_REASONS
    ]
    lines.append(
        f"left out ('-'): {np.count_nonzero(~valid)} of {valid.size}; " + ", ".join(counts)
    )
    return "\n".join(lines)


def _curves(args: argparse.Namespace) -> int:
    import warnings

    from . import bundle as bundle_io
    from .visibility import shadow_flags

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", bundle_io.BundleWarning)
        bundle = bundle_io.read_bundle(args.bundle)
    for w in caught:
        print(f"bayesgloss curves: warning: {w.message}", file=sys.stderr)
    curves = bundle_io.facet_curves(bundle, statistic=args.statistic, min_pixels=args.min_pixels)
    curves = shadow_flags(bundle, curves)  # where the bundle has an object_mesh
    if args.csv == "-":
        curves.to_csv(sys.stdout)
    elif args.csv:
        curves.to_csv(args.csv)
        print(f"bayesgloss curves: {curves.luminance.size} rows written to {args.csv}")
    else:
        print(_format_curves(curves, args.bundle))
    return 0


def _render(args: argparse.Namespace) -> int:
    import json

    from . import sequences

    configs = []
    if args.paper:
        configs += sequences.paper_configs(image_size=args.size)
    for path in args.config or []:
        try:
            data = json.loads(Path(path).read_text())
        except (OSError, json.JSONDecodeError) as err:
            raise ValueError(f"config file '{path}': {err}") from None
        items = data.get("sequences", [data]) if isinstance(data, dict) else data
        if not isinstance(items, list) or not all(isinstance(i, dict) for i in items):
            raise ValueError(
                f"config file '{path}': expected an object, a list of objects, or "
                '{"sequences": [...]}'
            )
        for i, item in enumerate(items):
            try:
                configs.append(sequences.SequenceConfig.from_dict(item))
            except (TypeError, ValueError) as err:
                raise ValueError(f"config file '{path}': sequence {i}: {err}") from None
    if not configs:
        raise ValueError("nothing to render: give --paper and/or --config FILE")
    paths = sequences.render_bundles(configs, args.out, jobs=args.jobs, progress=not args.quiet)
    for p in paths:
        print(p)
    return 0


def _baseline(args: argparse.Namespace) -> int:
    import json

    import numpy as np

    from . import baseline

    res = baseline.bundle_peak_frame_gloss(args.bundle, exponent=args.exponent)
    if args.json:
        print(json.dumps(res.to_json(), indent=2))
        return 0
    print(f"{args.bundle}: peak-frame baseline (Love & Efford), Phong n = {args.exponent:g}")
    used = int(np.sum(res.direct_sun & np.isfinite(res.gloss)))
    if used:
        print(f"object gloss (mean over {used} facets with direct sun): {res.object_gloss:.3f}")
    else:
        print(
            "object gloss: none (no facet has direct sun at its peak frame, and the "
            "peak-frame method reads gloss from the sun's highlight; try bayesgloss estimate)"
        )
    print(f"{'facet':>6} {'gamma':>6}  {'peak frame':>10}  flags")
    for i, g, pk, fl in zip(res.ids, res.gloss, res.observed_peak, res.flags, strict=True):
        gs = "   -  " if not np.isfinite(g) else f"{g:6.3f}"
        print(f"{int(i):>6} {gs}  {int(pk):>10}  {', '.join(fl)}")
    return 0


def _estimate(args: argparse.Namespace) -> int:
    import json

    from . import estimate

    def progress(done, total, what="sweeps at most" if args.per_frame else "facets"):
        if not args.quiet:
            print(
                f"\rbayesgloss estimate: {done}/{total} {what}", end="", file=sys.stderr, flush=True
            )

    if args.irradiance and (len(args.bundle) > 1 or args.scheduler):
        raise ValueError("--irradiance FILE goes with one bundle (its times)")
    if len(args.bundle) > 1 or args.scheduler:
        return _estimate_many(args, progress)
    if args.out:  # a bad --out is said before the computation, not after
        estimate.check_result_folder(args.out)
    target = args.bundle[0]
    if args.irradiance:  # measurements from a file, for the bundle's frame times
        import dataclasses

        from . import bundle as bundle_io
        from .irradiance import read_irradiance_csv

        target = bundle_io.read_bundle(target)
        measured = read_irradiance_csv(args.irradiance, target.times)
        target = dataclasses.replace(target, irradiance=measured)
    res = estimate.estimate_bundle(
        target,
        illumination=args.sky,
        noise=args.noise,
        camera=args.camera,
        seed=args.seed,
        jobs=args.jobs,
        progress=progress,
        per_frame=args.per_frame,
        sampler_options={"max_steps": args.max_steps},
        fresnel=args.fresnel,
        lobe=args.lobe,
        occluder_albedo=args.occluder_albedo,
        ground_facing=args.ground_facing,
        overcast_variants=args.overcast_variants,
        perez_families=args.perez_families,
        unreliable_loo=args.unreliable_loo or "equal",
        ground_shadow=args.ground_shadow,
        clipped=args.clipped,
    )
    if not args.quiet:
        print(file=sys.stderr)
    if args.out:
        estimate.write_result(args.out, res)
    if args.json:
        print(json.dumps(res.summary, indent=2))
        return 0
    _print_estimate(args.bundle[0], res.summary)
    return 0


def _interval(q: dict) -> str:
    """The reported 90 % interval of a summary entry, as printed."""
    from .intervals import reported_interval

    lo, hi = reported_interval(q)
    return f"{lo:.3f}, {hi:.3f}"


def _convergence_line(c: dict) -> str:
    """What a run flagged ``not-converged`` did not meet: gloss, the frames' light, or both."""
    g = c["gamma"]
    gloss = (
        f"gloss R-hat {g['rhat']:.3f}, ESS {g['ess_bulk']:.0f}/{g['ess_tail']:.0f} (bulk/tail), "
        + ("meets the rule" if g["meets_rule"] else "short of the rule (R-hat < 1.01, ESS >= 400)")
    )
    frames = c["frames_not_converged"]
    if not frames:
        return f"not converged: {gloss}"
    light = f"the sun or sky of frame{'s' if len(frames) > 1 else ''} {', '.join(map(str, frames))}"
    return f"not converged: {gloss}; {light} short of the rule"


def _print_estimate(name, summary) -> None:
    o = summary["object"]
    g = o["gamma"]
    print(
        f"{name}: posterior gloss ({summary['illumination']}, {summary['noise']} noise, "
        f"{summary['camera']} camera)"
    )
    print(
        f"object gamma {g['median']:.3f} [90 %: {_interval(g)}], "
        f"{o['facets_converged']}/{o['facets']} facets converged"
    )
    if "gamma_within_model" in o:  # the interval is the model's plus its error
        e = o["model_error"]
        print(
            f"  within the model [90 %: {_interval(o['gamma_within_model'])}]; model error sd "
            f"{e['sd']:.3f} (floor {e['floor']:.3f}, facets' disagreement {e['facets_sd']:.3f})"
        )
    if o.get("flags"):
        print(f"  object flags: {', '.join(o['flags'])}")
    if "not-converged" in o.get("flags", ()) and "convergence" in o:
        print(f"  {_convergence_line(o['convergence'])}")
    if "sky_families" in summary:  # the stacked day-level sky families
        stack = summary["sky_families"]
        fam = stack["families"]
        weights = ", ".join(f"{name} {f['weight']:.2f}" for name, f in fam.items())
        kind = "equal weight" if stack.get("equal_weights") else "stacking weight"
        print(f"sky families ({kind}): {weights}")
        if stack.get("stopped_early"):
            print(f"  kept at their first check, far behind: {', '.join(stack['stopped_early'])}")
        if "high_k_share" in stack:
            print(
                f"  {stack['high_k_share']:.0%} of the entries' PSIS-LOO unreliable "
                "(Pareto k > 0.7, weighted by the families' stacking weights)"
            )
    if "lobe_families" in summary:  # the stacked lobes (the default, or --lobe families)
        fam = summary["lobe_families"]
        weights = ", ".join(f"{name} {f['weight']:.2f}" for name, f in fam.items())
        print(f"lobe families (stacking weight): {weights}")
    elif summary.get("lobe_family", "phong") != "phong":
        print(f"lobe family: {summary['lobe_family']}")
    if "occluder_albedos" in summary:  # estimate --occluder-albedo stacked, with a mesh
        fam = summary["occluder_albedos"]
        weights = ", ".join(f"{name} {f['weight']:.2f}" for name, f in fam.items())
        print(f"albedo of the object's own faces (stacking weight): {weights}")
    if "fresnel_strength" in o:  # the Fresnel raise's unknowns (estimate --fresnel radiance)
        k, a = o["fresnel_strength"], o["normal_albedo"]
        print(
            f"Fresnel strength {k['median']:.2f} [{k['q05']:.2f}, {k['q95']:.2f}], "
            f"normal-incidence albedo {a['median']:.2f} [{a['q05']:.2f}, {a['q95']:.2f}]"
        )
    print(f"{'facet':>6} {'gamma':>6} {'90 % interval':>13}  flags")
    for f in summary["facets"]:
        if f["gamma"] is None:
            print(f"{f['id']:>6}      - {'-':>13}  {', '.join(f['flags'])}")
            continue
        fg = f["gamma"]
        print(f"{f['id']:>6} {fg['median']:6.3f} {_interval(fg):>13}  {', '.join(f['flags'])}")


def _estimate_many(args, progress) -> int:
    """Several bundles: one unit each, resumable, local processes or a Dask cluster."""
    import json

    from . import bundle as bundle_io
    from . import estimate, runner
    from .joint_estimate import JOINT_MAX_SWEEPS

    if not args.out:
        raise ValueError("several bundles (or --scheduler) need --out DIR for the results")
    skies, contents = [], []
    for b in args.bundle:  # reject bad bundles before any work starts
        bundle = bundle_io.read_bundle(b)
        contents.append(bundle_io.bundle_digest(bundle))  # a finished unit is this content's
        # each unit names its sky: the one estimate_bundle would choose
        skies.append(
            args.sky
            or estimate.default_illumination(
                bundle, per_frame=args.per_frame, noise=args.noise, camera=args.camera
            )
        )
    units = [
        (
            Path(b).name,
            {
                "bundle": str(Path(b).resolve()),
                "illumination": sky_name,
                "noise": args.noise,
                "camera": args.camera,
                "seed": args.seed,
                "max_steps": args.max_steps or (JOINT_MAX_SWEEPS if args.per_frame else 8000),
                # only where set, so that other runs keep their units' keys
                **({"per_frame": True} if args.per_frame else {}),
                **({"fresnel": args.fresnel} if args.fresnel else {}),
                **({"lobe": args.lobe} if args.lobe else {}),
                **({"occluder_albedo": args.occluder_albedo} if args.occluder_albedo else {}),
                **({"ground_facing": args.ground_facing} if args.ground_facing else {}),
                **(
                    {"overcast_variants": args.overcast_variants}
                    if args.overcast_variants is not None
                    else {}
                ),
                **(
                    {"perez_families": args.perez_families}
                    if args.perez_families is not None
                    else {}
                ),
                **({"unreliable_loo": args.unreliable_loo} if args.unreliable_loo else {}),
                **({"ground_shadow": args.ground_shadow} if args.ground_shadow else {}),
                **({"clipped": args.clipped} if args.clipped else {}),
                "bundle_content": content,
            },
        )
        for b, sky_name, content in zip(args.bundle, skies, contents, strict=True)
    ]
    folders = runner.run_units(
        estimate.estimate_unit,
        units,
        args.out,
        jobs=args.jobs,
        scheduler=args.scheduler,
        progress=lambda d, t: progress(d, t, "bundles"),
    )
    if not args.quiet:
        print(file=sys.stderr)
    summaries = {
        b: json.loads((f / "summary.json").read_text())
        for b, f in zip(args.bundle, folders, strict=True)
    }
    if args.json:
        print(json.dumps(summaries, indent=2))
        return 0
    for b, f in zip(args.bundle, folders, strict=True):
        g = summaries[b]["object"]["gamma"]
        print(f"{b}: object gamma {g['median']:.3f} [90 %: {_interval(g)}] -> {f}")
    return 0


def _compare(args: argparse.Namespace) -> int:
    import json

    from . import compare, report

    res = compare.compare_bundle_quick(
        args.bundle,
        reflectance=tuple(args.models.split(",")),
        illumination=tuple(args.skies.split(",")),
        level=args.level,
        seed=args.seed,
        steps=args.steps,
        rungs=args.rungs,
    )
    if args.json:
        print(json.dumps(res, indent=2))
        return 0
    print(report.format_comparison(res, args.bundle, args.level))
    return 0


def _report(args: argparse.Namespace) -> int:
    """The one-page posterior report of a saved estimate (``estimate --out``)."""
    from . import baseline, estimate, report
    from . import bundle as bundle_io

    result = Path(args.result)
    res = estimate.read_result(result)
    b = bundle_io.read_bundle(args.bundle or res.summary["bundle"])
    made_from = res.summary.get("bundle_content")
    if not args.bundle and made_from and bundle_io.bundle_digest(b) != made_from:
        raise ValueError(
            f"result '{result}': its bundle '{b.path}' has changed since the estimate (manifest, "
            "labels or frames differ from what summary.json records): run the estimate again, "
            "or name a bundle with --bundle"
        )
    comparison = (
        (result / "comparison.txt").read_text() if (result / "comparison.txt").exists() else None
    )
    out = report.posterior_report(
        b,
        res,
        baseline.bundle_peak_frame_gloss(b),
        Path(args.out) if args.out else result / "report.png",
        comparison=comparison,
    )
    print(out)
    return 0


def _bundle_make(args: argparse.Namespace) -> int:
    """``bundle make``: a sequence bundle from a mesh, a camera file and photos."""
    import time

    import numpy as np

    from . import capture

    transform = None
    if args.mesh_transform:
        transform = _transform(args.mesh_transform)
    if args.mesh_north is not None:  # the file's frame -> site-local -> world
        north = capture.site_frame(args.mesh_north)
        transform = north if transform is None else north @ transform
    t0 = time.perf_counter()
    made = capture.make_bundle(
        args.mesh,
        args.camera,
        args.photos,
        args.out,
        utc_offset=args.utc_offset,
        latitude=args.latitude,
        longitude=args.longitude,
        elevation=args.elevation,
        facet_angle=args.facet_angle,
        min_facet_pixels=args.min_facet_pixels,
        transform=transform,
        pixel_encoding=args.pixel_encoding,
        overwrite=args.overwrite,
    )
    labelled = int(np.count_nonzero(made.labels))
    if args.overlay:
        import json

        from PIL import Image

        from .bundle import MANIFEST, read_image

        middle = len(made.times) // 2  # a frame of the day's middle: the sun up
        manifest = json.loads((made.path / MANIFEST).read_text(encoding="utf-8"))
        pixels, top = read_image(made.path / manifest["frames"][middle]["file"])
        if manifest["camera"]["pixel_encoding"] == "linear":  # RAW: sRGB's curve to look at
            from .images import linear_to_srgb

            pixels = linear_to_srgb(np.clip(pixels / float(top or np.max(pixels)), 0, 1))
        Image.fromarray(capture.label_overlay(pixels, made.labels)).save(args.overlay)
        print(f"labels over frame {middle}: {args.overlay}")
    print(
        f"bundle {made.path}: {len(made.times)} frames "
        f"({made.times[0].isoformat()} to {made.times[-1].isoformat()} UTC), "
        f"{len(made.facets)} facets seen of {made.regions} near-planar regions, "
        f"{labelled} labelled pixels, exposure "
        + ("from EXIF" if made.exposure is not None else "unknown")
        + f"; {time.perf_counter() - t0:.1f} s"
    )
    return 0


def _transform(text: str):
    """A 4 x 4 transform: 16 comma-separated numbers (row by row) or a JSON file of them."""
    import json

    import numpy as np

    from .capture import CaptureError

    path = Path(text)
    try:
        if path.is_file():
            values = json.loads(path.read_text(encoding="utf-8"))
        else:
            values = [float(v) for v in text.split(",")]
        matrix = np.asarray(values, dtype=float).reshape(4, 4)
    except (ValueError, TypeError, OSError) as err:
        raise CaptureError(
            "transform", text, "--mesh-transform", f"not 16 numbers (a 4 x 4 matrix): {err}"
        ) from None
    return matrix


def _parser() -> argparse.ArgumentParser:
    from . import sky
    from .fresnel import FRESNEL_MODELS
    from .ground_facing import DEFAULT_GROUND_FACING, GROUND_FACING_MODES, GROUND_FACING_NZ
    from .joint_estimate import CLIPPED, DEFAULT_FRESNEL
    from .lobes import LOBE_FAMILIES
    from .object_shadow import GROUND_SHADOWS
    from .occluder_albedo import DEFAULT_OCCLUDER_ALBEDO, OCCLUDER_ALBEDO_MODES, OCCLUDER_ALBEDOS
    from .render import OCCLUDER_REFLECTANCE
    from .sky_families import OVERCAST_VARIANTS, PEREZ_FAMILIES, UNRELIABLE_LOO_SHARE

    p = argparse.ArgumentParser(prog="bayesgloss", description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="command", required=True)
    d = sub.add_parser("demo", help="the main job on the built-in default sequence")
    d.add_argument("--out", default="out/demo", help="output folder (default: out/demo)")
    d.add_argument("--view", default="SW", choices=["W", "SW", "S", "SE", "E"])
    d.add_argument("--jobs", type=int, default=2, help="processes")
    d.add_argument("--quiet", action="store_true", help="no progress line")
    d.set_defaults(func=_demo)
    c = sub.add_parser("curves", help="facet luminance curves of a sequence bundle")
    c.add_argument("bundle", help="sequence bundle folder (holding sequence.json)")
    c.add_argument("--csv", metavar="FILE", help="write CSV to FILE ('-' for stdout)")
    c.add_argument("--statistic", default="mean", choices=["mean", "median"])
    c.add_argument(
        "--min-pixels",
        type=int,
        default=4,
        help="facets with fewer pixels are left out (default: 4)",
    )
    c.set_defaults(func=_curves)
    r = sub.add_parser("render", help="render test sequences with Radiance into bundles")
    r.add_argument("--paper", action="store_true", help="the paper's 60 sequences")
    r.add_argument(
        "--config", action="append", metavar="FILE", help="JSON sequence config(s) (repeatable)"
    )
    r.add_argument("--out", default="out/bundles", help="bundle cache folder")
    r.add_argument("--size", type=int, default=128, help="image size for --paper [pixels]")
    r.add_argument("--jobs", type=int, default=2, help="Radiance processes at once")
    r.add_argument("--quiet", action="store_true", help="no progress line")
    r.set_defaults(func=_render)
    b = sub.add_parser("baseline", help="the paper's peak-frame gloss estimate of a bundle")
    b.add_argument("bundle", help="sequence bundle folder")
    b.add_argument("--json", action="store_true", help="machine-readable output")
    b.add_argument("--exponent", type=float, default=2.0, help="Phong exponent n (eq. 6)")
    b.set_defaults(func=_baseline)
    es = sub.add_parser("estimate", help="posterior gloss per facet and for the object")
    es.add_argument("bundle", nargs="+", help="sequence bundle folder(s)")
    es.add_argument(
        "--sky",
        default=None,
        choices=("auto", "families", "measured", *sky.sky_models()),
        metavar="SKY",
        help="the sky's shape (default: 'measured', the Perez sky of the bundle's "
        "frames[].irradiance, where it has them; else 'families': the object fitted with "
        "each frame's sky a mixture of gensky's clear, intermediate and overcast skies "
        "('auto'), under each of the three all day, under the clear and turbid Perez "
        "skies (--no-perez-families: not these two) and under CIE's overcast types 2 "
        "and 4 (--no-overcast-variants: not these), the fits stacked by PSIS-LOO "
        "(bayesgloss.sky_families); gensky-clear with --fixed-brightness; or one of "
        + ", ".join(sky.sky_models())
        + ")",
    )
    es.add_argument("--camera", default="auto", choices=["auto", "linear", "power"])
    es.add_argument("--noise", default="relative", choices=["relative", "gaussian", "student"])
    es.add_argument("--jobs", type=int, default=2, help="worker processes")
    es.add_argument(
        "--scheduler",
        help="Dask scheduler address (tcp://host:8786): run "
        "bundles on a Dask cluster instead of local processes",
    )
    es.add_argument("--seed", type=int, default=0)
    es.add_argument(
        "--max-steps",
        type=int,
        default=None,
        help="production steps at most per facet, or sweeps of the joint sampler "
        "(default 8000 and 2000; unconverged runs are flagged)",
    )
    es.add_argument(
        "--irradiance",
        metavar="FILE",
        help="CSV of measured irradiance (columns time, and any of ghi, dni, dhi in W m^-2; "
        "a row for every frame's time): the sky of each frame becomes gendaylit's Perez sky "
        "of these values",
    )
    es.add_argument(
        "--per-frame",
        action="store_true",
        default=True,
        help="(the default) infer each frame's sun and sky brightness (and the exposure, "
        "unless the bundle gives it) jointly with the facets (see bayesgloss.illumination)",
    )
    es.add_argument(
        "--fixed-brightness",
        dest="per_frame",
        action="store_false",
        help="fix each frame's sun and sky brightness (and exposure) to the sky model's and "
        "sample the facets alone (the estimator before per-frame illumination; seconds, "
        "not a minute, and confidently wrong when the day was not the sky model's)",
    )
    es.add_argument(
        "--fresnel",
        default=None,
        choices=FRESNEL_MODELS,
        help="the one-material model's Fresnel term (default "
        f"{DEFAULT_FRESNEL!r}): 'radiance' raises the glossy part toward grazing views by "
        "Radiance's Fresnel estimate, with its strength (0: Radiance's rough materials, "
        "1: smooth ones and real surfaces) and the normal-incidence albedo inferred; "
        "'schlick' the same with Schlick's rise (1 - cos)^5, a dielectric coating's; "
        "'schlick-lobe' Schlick's rise inside the GGX lobe, at each light's half vector "
        "(a rough coating's; lobe 'ggx') (bayesgloss.fresnel)",
    )
    es.add_argument(
        "--lobe",
        default=None,
        choices=(*LOBE_FAMILIES, "families", "materials"),
        help="the glossy lobe: 'materials' (the default with per-frame illumination and no "
        "--fresnel): Phong, Radiance's Ward, GGX with Smith shadowing and GGX with Schlick's "
        "Fresnel (a dielectric coating), one fit each, stacked by PSIS-LOO "
        "(bayesgloss.lobe_families); 'families': the first three; or one of them alone "
        "('phong', the default otherwise; 'ward'; 'ggx')",
    )
    es.add_argument(
        "--occluder-albedo",
        default=None,
        choices=OCCLUDER_ALBEDO_MODES,
        help="for a bundle with an object_mesh, the albedo of the object's own faces that "
        f"light its other facets (default {DEFAULT_OCCLUDER_ALBEDO!r}): 'fixed' at "
        f"{OCCLUDER_REFLECTANCE:g}, or 'stacked': one fit per albedo of "
        f"{', '.join(f'{a:g}' for a in OCCLUDER_ALBEDOS)}, stacked by PSIS-LOO "
        "(bayesgloss.occluder_albedo)",
    )
    es.add_argument(
        "--ground-facing",
        default=None,
        choices=GROUND_FACING_MODES,
        help=f"facets facing the ground (normal z below {GROUND_FACING_NZ:g}) in a bundle "
        f"without an object_mesh (default {DEFAULT_GROUND_FACING!r}): 'leave-out' (flagged "
        "faces-ground: the object's shadow on the ground they see is not known) or 'keep' "
        "(bayesgloss.ground_facing)",
    )
    es.add_argument(
        "--overcast-variants",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="with the sky families (the default sky): also fit the CIE overcast shapes "
        f"{', '.join(OVERCAST_VARIANTS)}, types 2 and 4 in the first stack (since holdout 22) "
        "and the rest where an overcast shape wins it, their weight shared by pseudo-BMA+ "
        "(bayesgloss.sky_families; the default since holdout 21, 16 unseen sunless days; "
        "--no-overcast-variants: gensky's overcast shape alone)",
    )
    es.add_argument(
        "--perez-families",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="with the sky families (the default sky): also fit the clear-sky Perez shapes "
        f"{', '.join(PEREZ_FAMILIES)} (a clean and a hazy day's, Linke turbidity 3 and "
        f"{sky.TURBID_LINKE_TURBIDITY:g}), stacked with the others (the default since stop "
        "43, bayesgloss.sky_families; --no-perez-families: the four without them)",
    )
    es.add_argument(
        "--unreliable-loo",
        default=None,
        choices=("equal", "stack"),
        help="with the sky families: where more than "
        f"{100 * UNRELIABLE_LOO_SHARE:g} %% of the entries' PSIS-LOO is unreliable "
        "(Pareto k > 0.7, as on objects of 1-3 facets), average the families with equal "
        "weights and flag sky-family-not-identifiable (default 'equal'), or keep the "
        "stacking weights and flag loo-unreliable ('stack'; bayesgloss.sky_families)",
    )
    es.add_argument(
        "--ground-shadow",
        default=None,
        choices=GROUND_SHADOWS,
        help="without an object_mesh: the ground shadowed by the convex object the facets "
        "bound ('convex', the default with per-frame illumination; bayesgloss.object_shadow), "
        "or sunlit everywhere ('none', the only choice with the sky's brightness fixed)",
    )
    es.add_argument(
        "--clipped",
        default=None,
        choices=CLIPPED,
        help="per-frame illumination: facet values whose pixels clipped at the top code "
        "left out (default 'drop'), or kept as lower bounds ('likelihood'; "
        "bayesgloss.sampling.censored)",
    )
    es.add_argument("--out", help="folder for posterior.nc (InferenceData) and summary.json")
    es.add_argument("--json", action="store_true", help="machine-readable output")
    es.add_argument("--quiet", action="store_true", help="no progress line")
    es.set_defaults(func=_estimate)
    rp = sub.add_parser("report", help="one-page posterior report of a saved estimate")
    rp.add_argument("result", help="folder written by `bayesgloss estimate BUNDLE --out DIR`")
    rp.add_argument("--bundle", help="the bundle (default: the one named in summary.json)")
    rp.add_argument("--out", help="PNG to write (default: RESULT/report.png)")
    rp.set_defaults(func=_report)
    cm = sub.add_parser("compare", help="Bayesian comparison of reflectance and sky models")
    cm.add_argument("bundle", help="sequence bundle folder")
    cm.add_argument(
        "--skies",
        default="gensky-clear,gensky-intermediate",
        help="comma-separated illumination models (default: gensky-clear,gensky-intermediate; "
        "any of " + ", ".join(sky.sky_models()) + ")",
    )
    cm.add_argument(
        "--models",
        default="lambert,phong,lambert+phong,lambert+ward",
        help="comma-separated reflectance models (default: all four)",
    )
    cm.add_argument("--level", default="object", choices=["object", "facet"])
    cm.add_argument("--steps", type=int, default=800, help="sampler steps kept per run")
    cm.add_argument(
        "--rungs", type=int, default=40, help="temperature rungs of the evidence (even)"
    )
    cm.add_argument("--seed", type=int, default=0)
    cm.add_argument("--json", action="store_true", help="machine-readable output")
    cm.set_defaults(func=_compare)
    bu = sub.add_parser("bundle", help="make sequence bundles")
    bsub = bu.add_subparsers(dest="action", required=True)
    mk = bsub.add_parser(
        "make",
        help="a bundle from a mesh, a camera file and photos with EXIF times",
        description="Write a sequence bundle from a triangle mesh of the object, an OpenCV "
        "camera file (JSON) and photos with EXIF times (bayesgloss.capture).",
    )
    mk.add_argument(
        "--mesh",
        required=True,
        help="OBJ, PLY or STL, world frame (x east, y north, z up, metres) unless --mesh-transform",
    )
    mk.add_argument(
        "--camera",
        required=True,
        help="camera JSON file (fx, fy, cx, cy, width, height, distortion, rotation, position; "
        "see bayesgloss.camera_model), or a COLMAP sparse model folder of the photos (in the "
        "mesh's frame: --mesh-transform and --mesh-north move it too)",
    )
    mk.add_argument(
        "--photos",
        required=True,
        nargs="+",
        metavar="DIR_OR_FILE",
        help="photo files or folders of them (JPEG, PNG, TIFF, or camera RAW: DNG, NEF, CR2, "
        "CR3, ARW, RAF, ... decoded linearly with rawpy, pip install 'bayesgloss[raw]')",
    )
    mk.add_argument("--out", required=True, help="the bundle folder to write")
    mk.add_argument(
        "--utc-offset",
        metavar="+HH:MM",
        help="the camera clock's UTC offset, for photos whose EXIF has none (a negative one "
        "as --utc-offset=-05:00)",
    )
    mk.add_argument("--latitude", type=float, help="site, deg north (default: EXIF GPS)")
    mk.add_argument("--longitude", type=float, help="site, deg east (default: EXIF GPS)")
    mk.add_argument("--elevation", type=float, help="site, m (default: EXIF GPS, else 0)")
    mk.add_argument(
        "--facet-angle",
        type=float,
        default=10.0,
        metavar="DEG",
        help="largest angle between a facet's faces and its seed face (default: 10 deg)",
    )
    mk.add_argument(
        "--min-facet-pixels",
        type=int,
        default=10,
        metavar="N",
        help="facets with fewer whole, unoccluded pixels are dropped (default: 10)",
    )
    mk.add_argument(
        "--mesh-transform",
        metavar="M",
        help="mesh to world: 16 comma-separated numbers, row by row, or a JSON file "
        "of a 4 x 4 matrix",
    )
    mk.add_argument(
        "--mesh-north",
        type=float,
        metavar="DEG",
        help="the mesh (after --mesh-transform) is z up in a site-local frame whose +y axis "
        "points toward this bearing, deg clockwise from true north",
    )
    mk.add_argument(
        "--pixel-encoding",
        default="srgb",
        help="of PNG and TIFF photos (default: srgb; JPEGs are srgb, camera RAW linear)",
    )
    mk.add_argument(
        "--overlay",
        metavar="PNG",
        help="also write the label image over the middle frame, to check the mesh's "
        "registration by eye",
    )
    mk.add_argument("--overwrite", action="store_true", help="replace an existing bundle")
    mk.set_defaults(func=_bundle_make)
    return p


def _one_line_warnings(command: str):
    """A ``warnings.showwarning`` that prints each warning as one line on stderr."""

    def show(message, category, filename, lineno, file=None, line=None):
        print(f"bayesgloss {command}: warning: {message}", file=sys.stderr)

    return show


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    with warnings.catch_warnings():
        warnings.showwarning = _one_line_warnings(args.command)
        return _run(args)


def _run(args: argparse.Namespace) -> int:
    """The command of ``args``; a bad input is one line on stderr and exit 2."""
    try:
        return args.func(args)
    except BrokenPipeError:  # the reader went away (e.g. `| head`): stop quietly
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except (ValueError, FileNotFoundError, RuntimeError) as err:
        print(f"bayesgloss {args.command}: error: {err}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())

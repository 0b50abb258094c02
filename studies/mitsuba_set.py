"""A set of sequences rendered with Mitsuba 3 in materials Radiance does not make (issue 14).

The set's size and every distribution are in the committed config
``studies/configs/mitsuba_set.json`` (seed included), fixed before anything
was estimated on it. :func:`draw_sequences` draws the sequences from
``numpy.random.default_rng(seed)`` in one fixed order; :func:`main` writes
the manifest ``studies/results/mitsuba_set.json`` (committed: per sequence
its config, material, class, true gamma, albedos and bundle folder), renders
the bundles with :func:`bayesgloss.mitsuba_render.render_bundles` into
``studies/out/mitsuba_set/bundles/`` (git-ignored; a bundle already there is
not rendered again), measures the Monte Carlo noise (one frame of the first
sequence of each class rendered again with another seed) and adds the render
time and the noise to the manifest.

What is drawn (counts exact, values at random):

- a material class, 6 each: smooth plastic (Mitsuba ``plastic``), rough
  plastic (``roughplastic``, GGX), smooth metal (``conductor``) and rough
  metal (``roughconductor``, GGX), the metals blended with a Lambertian base
  by ``blendbsdf`` of weight 0.05-1; alpha log-uniform on [0.02, 0.3], the
  plastics' index 1.3-1.8, the conductors Mitsuba's Au, Cu, Al, Ag or (2 of
  12) an RGB eta in [0.1, 2] and k in [1.5, 6]; the diffuse reflectance
  grey (12 of 24) or RGB, each channel log-uniform on [0.02, 0.8] for the
  plastics and on [0.1, 0.8] for the metals' base;
- everything else as ``studies/validation_set.py`` draws it, with its
  helpers: a sky category (gensky clear, intermediate, overcast; a CIE
  general sky; Perez clear or hazy; broken cloud; auto exposure), a pixel
  encoding, a site in either hemisphere, a date, civil frame times (at most
  16 frames), a camera and a hemisphere, box or gem.

The true gamma of each material is :func:`bayesgloss.mitsuba_render.true_gloss`,
the fraction of the reflected energy in the specular part at normal
incidence from Mitsuba's own BSDF integrated numerically.

Usage: python studies/mitsuba_set.py [--draw-only] [--threads 2] [--cache DIR]
[--manifest FILE] [--no-noise-check] [--only msNN ...]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from validation_set import (  # the same draws as the Radiance validation set
    _camera,
    _camera_response,
    _cie_types,
    _encodings,
    _flags,
    _labels,
    _object,
    _site_and_times,
    _sky_of,
    _uniform,
    sky_category,
)

from bayesgloss import mitsuba_render as mr
from bayesgloss import reflectance, sequences

NAME = "mitsuba_set"
STUDIES = Path(__file__).resolve().parent
CONFIG = STUDIES / "configs" / f"{NAME}.json"
CACHE = STUDIES / "out" / NAME / "bundles"
MANIFEST = STUDIES / "results" / f"{NAME}.json"
#: Class -> Mitsuba material kind.
KINDS = {v: k for k, v in mr.MATERIAL_CLASSES.items()}


def load_config(path: str | Path = CONFIG) -> dict:
    return json.loads(Path(path).read_text())


def _diffuse(rng, bounds, grey: bool):
    lo, hi = np.log(bounds)
    if grey:
        return round(float(np.exp(rng.uniform(lo, hi))), 4)
    return tuple(round(float(v), 4) for v in np.exp(rng.uniform(lo, hi, 3)))


def _material(rng, m: dict, material_class: str, grey: bool, custom: bool) -> mr.MitsubaMaterial:
    kind = KINDS[material_class]
    bounds = m["diffuse_log_range" if kind.endswith("plastic") else "metal_diffuse_log_range"]
    fields: dict = dict(kind=kind, diffuse=_diffuse(rng, bounds, grey))
    if kind.startswith("rough"):
        lo, hi = m["alpha"]
        alpha = np.exp(rng.uniform(np.log(lo), np.log(hi))) if m["alpha_log_uniform"] else None
        fields["alpha"] = round(float(alpha if alpha is not None else rng.uniform(lo, hi)), 4)
    if kind.endswith("plastic"):
        fields["int_ior"] = round(_uniform(rng, m["int_ior"]), 4)
    else:
        if custom:
            fields["eta"] = tuple(round(float(v), 4) for v in rng.uniform(*m["custom_eta"], 3))
            fields["k"] = tuple(round(float(v), 4) for v in rng.uniform(*m["custom_k"], 3))
        else:
            fields["conductor"] = str(m["conductors"][int(rng.integers(len(m["conductors"])))])
        fields["weight"] = round(_uniform(rng, m["metal_weight"]), 4)
    return mr.MitsubaMaterial(**fields)


def draw_sequences(cfg: dict) -> list[mr.MitsubaSequence]:
    """The set's sequences, drawn from ``default_rng(cfg["seed"])``.

    Parameters
    ----------
    cfg : dict
        The config (``studies/configs/mitsuba_set.json``).

    Returns
    -------
    list of MitsubaSequence
        ``cfg["n_sequences"]`` sequences named ``ms<i>-<class>``; the
        config's ``category`` is the sky category (as in the validation set).
    """
    rng = np.random.default_rng(cfg["seed"])
    n = cfg["n_sequences"]
    classes = _labels(rng, cfg["classes"], n)
    categories = _labels(rng, cfg["categories"], n)
    encodings = _encodings(rng, cfg, categories)
    north = _flags(rng, cfg["site"]["north"], n)
    high = _flags(rng, cfg["site"]["high_latitude"], n)
    schemes = _labels(rng, cfg["times"]["schemes"], n)
    shapes = _labels(rng, cfg["objects"]["shapes"], n)
    m = cfg["materials"]
    grey = _flags(rng, m["grey"], n)
    metals = [i for i in range(n) if classes[i].endswith("metal")]
    custom = set(int(i) for i in rng.permutation(metals)[: m["custom_conductor"]])
    groups = [list(rng.permutation(g)) for g in cfg["sky"]["cie_type_groups"]]
    cie_types = _cie_types(groups)

    out = []
    for i in range(n):
        category = categories[i]
        base = _site_and_times(rng, cfg, bool(north[i]), bool(high[i]), schemes[i])
        sky_fields = _sky_of(rng, cfg, category, base, cie_types)
        camera = _camera(rng, cfg)
        obj = _object(rng, cfg, shapes[i])
        material = _material(rng, m, classes[i], bool(grey[i]), i in custom)
        response = _camera_response(rng, cfg, encodings[i], category)
        config = sequences.SequenceConfig(
            name=f"ms{i:02d}-{classes[i]}",
            category=category,
            shape=shapes[i],
            ground_reflectance=round(_uniform(rng, cfg["ground_reflectance"]), 4),
            image_size=cfg["image_size"],
            **base,
            **sky_fields,
            **camera,
            **obj,
            **response,
        )
        seed = cfg["seed"] + 1000 * i
        out.append(mr.MitsubaSequence(config, material, spp=cfg["spp"], seed=seed))
    return out


def manifest(items, cache: Path, extra: dict | None = None) -> dict:
    """Per sequence: name, class, category, true gamma, albedos, material,
    config, spp, seed, key and bundle folder; plus the set's composition."""
    rows = []
    for s in items:
        r_spec, r_diff = mr.mitsuba_albedos(s.material)
        rows.append(
            {
                "name": s.config.name,
                "class": s.material.material_class,
                "category": s.config.category,
                "sky_category": sky_category(s.config),
                "gloss": mr.gloss_of_albedos(r_spec, r_diff),
                "albedo_specular": [float(v) for v in r_spec],
                "albedo_diffuse": [float(v) for v in r_diff],
                "material": s.material.to_dict(),
                "spp": s.spp,
                "seed": s.seed,
                "key": s.key(),
                "bundle": str(mr.bundle_path(cache, s).relative_to(STUDIES.parent))
                if mr.bundle_path(cache, s).is_relative_to(STUDIES.parent)
                else str(mr.bundle_path(cache, s)),
                "config": s.config.to_dict(),
            }
        )
    gloss = [r["gloss"] for r in rows]

    def count(values):
        out: dict = {}
        for v in values:
            out[v] = out.get(v, 0) + 1
        return dict(sorted(out.items()))

    composition = {
        "class": count(r["class"] for r in rows),
        "category": count(r["category"] for r in rows),
        "shape": count(s.config.shape for s in items),
        "pixel_encoding": count(s.config.pixel_encoding for s in items),
        "hemisphere": count("north" if s.config.latitude >= 0 else "south" for s in items),
        "gloss_range": [min(gloss), max(gloss)],
        "gloss_by_class": {
            c: [
                min(g for r, g in zip(rows, gloss, strict=True) if r["class"] == c),
                max(g for r, g in zip(rows, gloss, strict=True) if r["class"] == c),
            ]
            for c in sorted({r["class"] for r in rows})
        },  # fmt: skip
        "total_frames": sum(s.config.n_frames for s in items),
    }
    return {
        "n_sequences": len(rows),
        "renderer": mr.renderer_name(),
        "composition": composition,
        **(extra or {}),
        "sequences": rows,
    }


def noise_check(items, cfg: dict, threads: int) -> dict:
    """Monte Carlo noise of facet means: the first sequence of each class,
    its frame with the highest sun rendered with its own seed and with
    ``seed + seed_offset``; per facet of at least ``bundle.MIN_PIXELS``
    labelled pixels, |a / b - 1| / sqrt(2) estimates one render's relative sd."""
    from bayesgloss import bundle

    weights = np.asarray(reflectance.LUMINANCE_WEIGHTS)
    chosen, seen = [], set()
    for s in items:
        if s.material.material_class not in seen:
            seen.add(s.material.material_class)
            chosen.append(s)
    chosen = chosen[: cfg["noise_check"]["sequences"]]
    out, all_rel = {}, []
    for s in chosen:
        t = int(np.argmax(s.config.sun_directions()[:, 2]))
        labels = sequences.label_image(s.config, s.config.facets())
        a, b = (
            mr.render_frames(
                s.config, s.material, spp=s.spp, seed=seed, frames=[t], threads=threads
            )[0]
            @ weights
            for seed in (s.seed, s.seed + cfg["noise_check"]["seed_offset"])
        )
        ids, n_pix = np.unique(labels[labels > 0], return_counts=True)
        keep = ids[n_pix >= bundle.MIN_PIXELS]
        ma = np.array([a[labels == k].mean() for k in keep])
        mb = np.array([b[labels == k].mean() for k in keep])
        lit = (ma > 0) & (mb > 0)
        rel = np.abs(ma[lit] / mb[lit] - 1) / np.sqrt(2)
        all_rel.append(rel)
        out[s.config.name] = {
            "frame": t,
            "facets": int(lit.sum()),
            "median": float(np.median(rel)),
            "p90": float(np.percentile(rel, 90)),
            "max": float(rel.max()),
        }
    rel = np.concatenate(all_rel)
    return {
        "sequences": out,
        "all": {
            "facets": int(rel.size),
            "median": float(np.median(rel)),
            "p90": float(np.percentile(rel, 90)),
            "below_1pct": float(np.mean(rel < 0.01)),
            "max": float(rel.max()),
        },
    }


def render_only(items, prefixes, cache: Path, threads: int) -> list[Path]:
    """Render the sequences of ``items`` whose names start with one of
    ``prefixes`` (msNN) into ``cache``: the same draws and bundle keys as the
    whole set's, for a probe that needs a few of a set's sequences."""
    by_prefix = {s.config.name.split("-")[0]: s for s in items}
    missing = set(prefixes) - set(by_prefix)
    if missing:
        raise SystemExit(f"mitsuba_set: no sequence {', '.join(sorted(missing))} in the config")
    wanted = [s for p, s in by_prefix.items() if p in set(prefixes)]  # the set's order
    paths = mr.render_bundles(wanted, cache, threads=threads)
    print(f"{len(paths)} bundles in {cache}")
    return paths


def main(argv=None) -> list[Path]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default=str(CONFIG))
    ap.add_argument("--cache", default=str(CACHE), help="bundle folder (default %(default)s)")
    ap.add_argument("--manifest", default=str(MANIFEST))
    ap.add_argument("--threads", type=int, default=2, help="Mitsuba threads (default 2)")
    ap.add_argument("--draw-only", action="store_true", help="write the manifest, render nothing")
    ap.add_argument("--no-noise-check", action="store_true")
    ap.add_argument(
        "--only",
        nargs="+",
        metavar="msNN",
        help="render these sequences of the set alone (a probe's), leaving the manifest as it is",
    )
    args = ap.parse_args(argv)
    cfg = load_config(args.config)
    items = draw_sequences(cfg)
    cache = Path(args.cache).resolve()
    if args.only:
        return render_only(items, args.only, cache, args.threads)
    out = Path(args.manifest)
    out.parent.mkdir(parents=True, exist_ok=True)
    old = json.loads(out.read_text()) if out.exists() else {}
    measured = ("render_seconds", "render_threads", "rendered", "mc_noise")
    kept = {k: old[k] for k in measured if k in old}  # a redraw keeps the measurements
    data = manifest(items, cache, kept)
    out.write_text(json.dumps(data, indent=1) + "\n")
    print(json.dumps(data["composition"], indent=1))
    if args.draw_only:
        return []
    todo = [s for s in items if not (mr.bundle_path(cache, s) / "sequence.json").exists()]
    start = time.perf_counter()
    paths = mr.render_bundles(items, cache, threads=args.threads)
    seconds = time.perf_counter() - start
    print(f"{len(paths)} bundles in {cache} ({seconds:.0f} s, {len(todo)} rendered)")
    extra = dict(kept)
    if len(todo) == len(items) or "render_seconds" not in kept:
        extra.update(render_seconds=round(seconds, 1), render_threads=args.threads)
        extra["rendered"] = len(todo)
    # else: the timed run rendered the set; its time is kept
    if not args.no_noise_check:
        extra["mc_noise"] = noise_check(items, cfg, args.threads)
        print(json.dumps(extra["mc_noise"]["all"], indent=1))
    out.write_text(json.dumps(manifest(items, cache, extra), indent=1) + "\n")
    return paths


if __name__ == "__main__":
    sys.exit(0 if main() is not None else 1)

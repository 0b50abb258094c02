"""A validation set of Radiance-rendered sequences nobody tuned the estimator to (issue 13).

The set's size and every distribution are in the committed config
``studies/configs/validation_set.json`` (seed included), fixed before any
estimate was run. :func:`draw_configs` draws the sequences from
``numpy.random.default_rng(seed)`` in one fixed order, so the same config
always gives the same set; :func:`main` writes the drawn configurations to
``studies/results/validation_set_configs.json`` (committed, so the set can be
reviewed) and renders them with :func:`bayesgloss.sequences.render_bundles`
(one Radiance process) into ``studies/out/validation_set/bundles/``
(git-ignored; a bundle already there is not rendered again).

What is drawn (counts are exact, values at random):

- a scoring category (``truth["category"]``): gensky clear, intermediate and
  overcast; a CIE general sky (types drawn without replacement; types 1-5
  overcast without beam, DHI a fraction of the clear sky's global; 6-11
  partly cloudy, DNI cut and DHI raised; 12-15 clear sky; the three groups
  in turn, a type drawn without replacement within each); gendaylit Perez
  from pvlib's clear sky at a Linke turbidity of 2-7, or hazy (7-9.5);
  broken cloud (Perez, the beam cut to 0-20 % in a random 20-50 % of the
  frames with the sun up and the DHI raised 1.3-2x there); and auto
  exposure (any of the other seven, with "auto" gains: inverse to each
  frame's mean luminance, times a log-normal jitter);
- a pixel encoding: linear-radiance HDR, linear 16-bit, sRGB 8-bit (with
  sensor noise and a white low enough to clip highlights) or gamma 2.2
  16-bit; auto exposure never goes with linear-radiance (radiance is
  radiance whatever the gain; with the other encodings the gains are not
  written, so the estimator meets an unknown exposure, as the spec says);
- a site in either hemisphere (exact count north), a quarter of them at
  |latitude| 50-65 deg, any longitude, the civil UTC offset round(lon / 15)
  h (a fifth of them a half-hour offset), a date through the year;
- frame times in civil time with that offset: a full day (sunrise - 1 h to
  sunset + 1 h) hourly or at random times, or a 4-6 h window every 30 min
  or at random times; frames with the sun down are kept (the reader drops
  them), at least 6 with the sun above ``min_sun_z``, at most ``max_frames``;
- a camera at any bearing, 0.5-6 m high, 6-20 m away;
- an object: a hemisphere of 4-8 rings and 8-24 segments, a box of random
  size and azimuth, or the brilliant-cut-like gem on its culet or its table;
- a material: plastic or metal, specularity exactly 0, high (0.85-1) or
  uniform on [0, 1], roughness 0 or uniform on [0, 0.15], grey or RGB colour.

Usage: python studies/validation_set.py [--draw-only] [--jobs 1] [--cache DIR]
[--configs-out FILE]
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

from bayesgloss import sequences, sun

NAME = "validation_set"
STUDIES = Path(__file__).resolve().parent
CONFIG = STUDIES / "configs" / f"{NAME}.json"
CACHE = STUDIES / "out" / NAME / "bundles"
CONFIGS_OUT = STUDIES / "results" / f"{NAME}_configs.json"
#: Sky categories an auto-exposure sequence draws its sky from.
BASE_CATEGORIES = (
    "gensky-clear",
    "gensky-intermediate",
    "gensky-overcast",
    "cie-general",
    "perez-clear",
    "perez-hazy",
    "broken-cloud",
)


def load_config(path: str | Path = CONFIG) -> dict:
    return json.loads(Path(path).read_text())


def _uniform(rng: np.random.Generator, bounds) -> float:
    lo, hi = bounds
    return float(rng.uniform(lo, hi))


def _labels(rng: np.random.Generator, counts: dict, n: int) -> list[str]:
    """``counts`` labels (label -> count, summing to n) in a random order."""
    items = [k for k, c in counts.items() for _ in range(c)]
    if len(items) != n:
        raise ValueError(f"counts {counts} sum to {len(items)}, not {n}")
    return [items[i] for i in rng.permutation(n)]


def _flags(rng: np.random.Generator, k: int, n: int) -> np.ndarray:
    """n booleans, exactly k of them True, at random places."""
    out = np.zeros(n, bool)
    out[rng.permutation(n)[:k]] = True
    return out


def _encodings(rng: np.random.Generator, cfg: dict, categories: list[str]) -> list[str]:
    """Encodings with the config's counts; auto exposure never linear-radiance."""
    n = cfg["n_sequences"]
    enc = _labels(rng, {k: v["count"] for k, v in cfg["encodings"].items()}, n)
    for i in range(n):  # swap a clash with the first eligible sequence
        if categories[i] == "auto-exposure" and enc[i] == "linear-radiance":
            j = next(
                j
                for j in range(n)
                if categories[j] != "auto-exposure" and enc[j] != "linear-radiance"
            )
            enc[i], enc[j] = enc[j], enc[i]
    return enc


def _utc_offset_hours(rng: np.random.Generator, longitude: float, half_fraction: float) -> float:
    """Civil offset round(lon / 15) h, or a half-hour offset next to it [h]."""
    if rng.uniform() < half_fraction:
        offset = np.floor(longitude / 15.0) + 0.5
    else:
        offset = float(np.round(longitude / 15.0))
    return float(np.clip(offset, -12.0, 14.0))


def _sun_z(local: pd.DatetimeIndex, latitude: float, longitude: float) -> np.ndarray:
    return sun.sun_direction_at(local.tz_convert("UTC"), latitude, longitude)[:, 2]


def _frame_times(rng, tcfg: dict, scheme: str, date, tz, latitude, longitude):
    """Civil frame times (DatetimeIndex with the offset) of one sequence, or None."""
    day = pd.Timestamp(date).tz_localize(tz)
    grid = day + pd.to_timedelta(np.arange(0, 24 * 60, 5), unit="min")
    up = _sun_z(grid, latitude, longitude) > tcfg["min_sun_z"]
    if not up.any():
        return None
    rise, set_ = grid[up][0], grid[up][-1]
    hour = pd.Timedelta(hours=1)
    if scheme == "full-hourly":
        start = (rise - tcfg["full_margin_hours"] * hour).floor("h")
        stop = (set_ + tcfg["full_margin_hours"] * hour).ceil("h")
        n = int(round((stop - start) / hour)) + 1
        step = max(1.0, (n - 1) / (tcfg["max_frames"] - 1))
        times = start + pd.to_timedelta(np.arange(0, (n - 1) + 1e-9, step), unit="h")
    elif scheme == "full-irregular":
        margin = tcfg["irregular_margin_hours"] * hour
        k = int(rng.integers(tcfg["irregular_frames"][0], tcfg["irregular_frames"][1] + 1))
        span = (set_ - rise + 2 * margin) / hour
        offsets = np.sort(rng.uniform(0, span, k))
        times = (rise - margin) + pd.to_timedelta(offsets, unit="h")
    else:
        width = _uniform(rng, tcfg["partial_window_hours"])
        room = max((set_ - rise) / hour - width, 0.0)
        start = rise + pd.to_timedelta(rng.uniform(0, room), unit="h")
        if scheme == "partial-regular":
            step = tcfg["partial_step_hours"]
            times = start.ceil("15min") + pd.to_timedelta(
                np.arange(0, width + 1e-9, step), unit="h"
            )
        else:
            k = int(rng.integers(tcfg["irregular_frames"][0], tcfg["irregular_frames"][1] + 1))
            times = start + pd.to_timedelta(np.sort(rng.uniform(0, width, k)), unit="h")
    times = pd.DatetimeIndex(times).round("min")[: tcfg["max_frames"]]
    if len(times) != len(times.unique()):
        return None
    if np.sum(_sun_z(times, latitude, longitude) > tcfg["min_sun_z"]) < tcfg["min_sun_up_frames"]:
        return None
    return times


def _site_and_times(rng, cfg: dict, north: bool, high: bool, scheme: str) -> dict:
    """Latitude, longitude and civil frame times; a date is redrawn until the
    frames have enough sun (the draws stay in the one generator's order)."""
    scfg, tcfg = cfg["site"], cfg["times"]
    for _ in range(200):
        abs_lat = _uniform(rng, scfg["abs_latitude_high"] if high else scfg["abs_latitude"])
        latitude = abs_lat if north else -abs_lat
        longitude = _uniform(rng, scfg["longitude"])
        offset = _utc_offset_hours(rng, longitude, scfg["half_hour_offset_fraction"])
        tz = dt.timezone(dt.timedelta(hours=offset))
        date = dt.date(cfg["year"], 1, 1) + dt.timedelta(days=int(rng.integers(0, 365)))
        times = _frame_times(rng, tcfg, scheme, date, tz, latitude, longitude)
        if times is not None:
            return dict(
                latitude=round(latitude, 4),
                longitude=round(longitude, 4),
                date=date.isoformat(),
                times=tuple(t.isoformat() for t in times),
            )
    raise RuntimeError("no site with enough sunny frames in 200 draws")


def _sky(rng, cfg: dict, category: str, base: dict) -> dict:
    """Sky fields of one sequence (``base`` holds site and times)."""
    k = cfg["sky"]
    if category.startswith("gensky-"):
        return dict(sky=category, turbidity=round(_uniform(rng, k["gensky_turbidity"]), 3))
    if category in ("perez-clear", "perez-hazy"):
        bounds = k["perez_clear_linke"] if category == "perez-clear" else k["perez_hazy_linke"]
        return dict(sky="perez", linke_turbidity=round(_uniform(rng, bounds), 3))
    if category == "broken-cloud":
        linke = round(_uniform(rng, k["broken_linke"]), 3)
        probe = sequences.SequenceConfig(sky="perez", linke_turbidity=linke, **base)
        dni, dhi = probe.irradiances()
        up = np.flatnonzero(probe.sun_directions()[:, 2] > 0.0)
        n_cut = max(1, int(round(_uniform(rng, k["broken_frame_fraction"]) * len(up))))
        cut = rng.choice(up, n_cut, replace=False)
        dni, dhi = dni.copy(), dhi.copy()
        dni[cut] *= rng.uniform(*k["broken_dni_factor"], n_cut)
        dhi[cut] *= rng.uniform(*k["broken_dhi_factor"], n_cut)
        return dict(
            sky="perez",
            linke_turbidity=linke,
            dni=tuple(round(float(v), 3) for v in dni),
            dhi=tuple(round(float(v), 3) for v in dhi),
        )
    if category == "cie-general":
        raise AssertionError("cie types are drawn by the caller")
    raise ValueError(f"unknown category {category!r}")


def _cie_sky(rng, cfg: dict, sky_type: int, base: dict) -> dict:
    k = cfg["sky"]
    name = f"cie-{sky_type}"
    if sky_type >= 12:  # clear skies: pvlib's clear sky at a drawn turbidity
        return dict(sky=name, linke_turbidity=round(_uniform(rng, k["cie_clear_linke"]), 3))
    probe = sequences.SequenceConfig(sky=name, **base)
    dni, dhi = probe.irradiances()
    sun_z = np.maximum(probe.sun_directions()[:, 2], 0.0)
    if sky_type <= 5:  # overcast: no beam, the diffuse a fraction of the clear global
        frac = _uniform(rng, k["cie_overcast_dhi_of_clear_ghi"])
        dhi, dni = frac * (dhi + dni * sun_z), np.zeros_like(dni)
    else:  # partly cloudy
        dni = dni * _uniform(rng, k["cie_partly_dni_factor"])
        dhi = dhi * _uniform(rng, k["cie_partly_dhi_factor"])
    return dict(
        sky=name,
        dni=tuple(round(float(v), 3) for v in dni),
        dhi=tuple(round(float(v), 3) for v in dhi),
    )


def _cie_types(groups):
    """The CIE sky types in the order the set hands them out: the groups
    (overcast, partly cloudy, clear) in turn, each group's types in its
    drawn order (no random draw)."""
    n = 0
    while True:
        group = groups[n % len(groups)]
        yield int(group[(n // len(groups)) % len(group)])
        n += 1


def _sky_of(rng, cfg: dict, category: str, base: dict, cie_types) -> dict:
    """A sequence's sky fields: an auto-exposure day's sky category drawn
    first, then the category's sky (``cie_types``, :func:`_cie_types`)."""
    sky_category = category
    if category == "auto-exposure":
        sky_category = BASE_CATEGORIES[int(rng.integers(len(BASE_CATEGORIES)))]
    if sky_category == "cie-general":
        return _cie_sky(rng, cfg, next(cie_types), base)
    return _sky(rng, cfg, sky_category, base)


def _camera(rng, cfg: dict) -> dict:
    """A sequence's camera bearing, height and distance."""
    cam = cfg["camera"]
    return dict(
        view=round(_uniform(rng, cam["bearing"]), 2),
        camera_height=round(_uniform(rng, cam["height"]), 3),
        camera_distance=round(_uniform(rng, cam["distance"]), 3),
    )


def _object(rng, cfg: dict, shape: str) -> dict:
    """A sequence's object fields of ``shape`` (hemisphere, box or gem)."""
    o = cfg["objects"]
    if shape == "hemisphere":
        return dict(
            n_rings=int(rng.integers(o["n_rings"][0], o["n_rings"][1] + 1)),
            n_segments=int(rng.integers(o["n_segments"][0], o["n_segments"][1] + 1)),
        )
    if shape == "box":
        return dict(
            box_size=tuple(round(float(v), 3) for v in rng.uniform(*o["box_size"], 3)),
            box_azimuth=round(_uniform(rng, o["box_azimuth"]), 2),
        )
    return dict(
        gem_stand=str(o["gem_stand"][int(rng.integers(len(o["gem_stand"])))]),
        gem_azimuth=round(_uniform(rng, o["gem_azimuth"]), 2),
    )


def _camera_response(rng, cfg: dict, encoding: str, category: str) -> dict:
    """A sequence's pixel encoding, sensor noise and white scale, and an
    auto-exposure day's exposure jitter."""
    e = cfg["encodings"][encoding]
    response = dict(
        pixel_encoding=encoding,
        bit_depth=e["bit_depth"],
        sensor_noise=round(_uniform(rng, e["sensor_noise"]), 5),
        white_scale=round(_uniform(rng, e["white_scale"]), 4),
    )
    if category == "auto-exposure":
        jitter = round(_uniform(rng, cfg["sky"]["auto_exposure_jitter"]), 4)
        response.update(exposure="auto", exposure_jitter=jitter)
    return response


def draw_configs(cfg: dict) -> list[sequences.SequenceConfig]:
    """The validation set's sequences, drawn from ``default_rng(cfg["seed"])``.

    Parameters
    ----------
    cfg : dict
        The config (``studies/configs/validation_set.json``).

    Returns
    -------
    list of SequenceConfig
        ``cfg["n_sequences"]`` configurations, named ``vs<i>-<category>``.
    """
    rng = np.random.default_rng(cfg["seed"])
    n = cfg["n_sequences"]
    categories = _labels(rng, cfg["categories"], n)
    encodings = _encodings(rng, cfg, categories)
    north = _flags(rng, cfg["site"]["north"], n)
    high = _flags(rng, cfg["site"]["high_latitude"], n)
    schemes = _labels(rng, cfg["times"]["schemes"], n)
    shapes = _labels(rng, cfg["objects"]["shapes"], n)
    m = cfg["material"]
    kinds = _labels(rng, m["kinds"], n)
    spec_kind = _labels(
        rng,
        {
            "zero": m["specularity_zero"],
            "high": m["specularity_high"],
            "uniform": n - m["specularity_zero"] - m["specularity_high"],
        },
        n,
    )
    rough_zero = _flags(rng, m["roughness_zero"], n)
    grey = _flags(rng, m["grey"], n)
    groups = [list(rng.permutation(g)) for g in cfg["sky"]["cie_type_groups"]]
    cie_types = _cie_types(groups)
    ambient = cfg["ambient"]
    if isinstance(ambient, str):  # a name of bayesgloss.sequences' settings
        if not ambient.endswith("_AMBIENT") or not hasattr(sequences, ambient):
            names = [n for n in sequences.__all__ if n.endswith("_AMBIENT")]
            raise SystemExit(
                f"validation config: field 'ambient': {ambient!r} is not one of "
                f"{', '.join(names)} nor a list of rtrace options"
            )
        ambient = getattr(sequences, ambient)

    out = []
    for i in range(n):
        category = categories[i]
        base = _site_and_times(rng, cfg, bool(north[i]), bool(high[i]), schemes[i])
        sky_fields = _sky_of(rng, cfg, category, base, cie_types)
        camera = _camera(rng, cfg)
        shape = shapes[i]
        obj = _object(rng, cfg, shape)

        if spec_kind[i] == "zero":
            spec = 0.0
        elif spec_kind[i] == "high":
            spec = _uniform(rng, m["specularity_high_range"])
        else:
            spec = float(rng.uniform())
        rough = 0.0 if rough_zero[i] else _uniform(rng, m["roughness"])
        if grey[i]:
            colour = round(_uniform(rng, m["grey_range"]), 4)
        else:
            colour = tuple(round(float(v), 4) for v in rng.uniform(*m["rgb_range"], 3))

        camera_response = _camera_response(rng, cfg, encodings[i], category)

        out.append(
            sequences.SequenceConfig(
                name=f"vs{i:02d}-{category}",
                category=category,
                shape=shape,
                material=kinds[i],
                specularity=round(spec, 4),
                roughness=round(rough, 4),
                colour=colour,
                ground_reflectance=round(_uniform(rng, cfg["ground_reflectance"]), 4),
                image_size=cfg["image_size"],
                ambient=tuple(ambient),
                **base,
                **sky_fields,
                **camera,
                **obj,
                **camera_response,
            )
        )
    return out


def sky_category(config: sequences.SequenceConfig) -> str:
    """The sky's category, also for auto-exposure sequences (whose category is
    "auto-exposure"): gensky-*, cie-general, broken-cloud (Perez with given
    irradiances), perez-hazy (Linke turbidity >= 7) or perez-clear."""
    if config.sky.startswith("gensky-"):
        return config.sky
    if config.sky.startswith("cie-"):
        return "cie-general"
    if config.dni is not None:
        return "broken-cloud"
    return "perez-hazy" if config.linke_turbidity >= 7.0 else "perez-clear"


def configs_json(configs) -> str:
    """The drawn set as JSON text: name, key, sky category and every field of each sequence."""
    rows = [
        {"name": c.name, "key": c.key(), "sky_category": sky_category(c), "config": c.to_dict()}
        for c in configs
    ]
    return json.dumps({"n_sequences": len(rows), "sequences": rows}, indent=1) + "\n"


def composition(configs) -> dict:
    """Counts by category, sky, encoding, shape, hemisphere; latitude range."""

    def count(values):
        out: dict = {}
        for v in values:
            out[v] = out.get(v, 0) + 1
        return dict(sorted(out.items()))

    lat = np.array([c.latitude for c in configs])
    sun_up = [int(np.sum(c.sun_directions()[:, 2] > 0.0)) for c in configs]
    return {
        "category": count(c.category for c in configs),
        "sky_category": count(sky_category(c) for c in configs),
        "sky": count(c.sky for c in configs),
        "pixel_encoding": count(c.pixel_encoding for c in configs),
        "shape": count(c.shape for c in configs),
        "material": count(c.material for c in configs),
        "hemisphere": count("north" if c.latitude >= 0 else "south" for c in configs),
        "abs_latitude_above_50": int(np.sum(np.abs(lat) > 50)),
        "latitude_range": [float(lat.min()), float(lat.max())],
        "frames": [min(c.n_frames for c in configs), max(c.n_frames for c in configs)],
        "frames_sun_up_min": min(sun_up),
        "total_frames": sum(c.n_frames for c in configs),
    }


def main(argv=None) -> list[Path]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default=str(CONFIG))
    ap.add_argument("--cache", default=str(CACHE), help="bundle folder (default %(default)s)")
    ap.add_argument("--configs-out", default=str(CONFIGS_OUT))
    ap.add_argument("--jobs", type=int, default=1, help="Radiance processes (default 1)")
    ap.add_argument("--draw-only", action="store_true", help="write the configs, render nothing")
    args = ap.parse_args(argv)
    configs = draw_configs(load_config(args.config))
    out = Path(args.configs_out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(configs_json(configs))
    print(json.dumps(composition(configs), indent=1))
    if args.draw_only:
        return []
    start = time.perf_counter()
    paths = sequences.render_bundles(configs, args.cache, jobs=args.jobs)
    print(f"{len(paths)} bundles in {args.cache} ({time.perf_counter() - start:.0f} s)")
    return paths


if __name__ == "__main__":
    sys.exit(0 if main() is not None else 1)

"""Calibration of the per-frame illumination ("joint") model where its lobe is right.

Objects are simulated by the forward model itself (:mod:`bayesgloss.render`),
so the glossy lobe, the noise model and the camera response are the
estimator's own, and only the illumination departs from what the model
assumes: the sky's shape comes from one of several families (gensky
clear, intermediate or overcast, CIE general skies, Perez), which the
estimator's default per-frame mixture of sky shapes
(:data:`bayesgloss.estimate.AUTO_SKIES`) matches only roughly, the sun is
dimmed by haze in every frame, some objects have broken cloud, and some
cameras change their exposure from frame to frame without saying so. Each
object is written as a sequence bundle (:func:`bayesgloss.bundle.write_bundle`)
and fitted through the real reader with
``estimate_bundle(path, per_frame=True, seed=index)`` and otherwise default
options. The question (the issue's): do the object's 90 % intervals hold the
true gloss in 85-97 % of at least 200 objects?

What is drawn (``configs/calibration_joint.json``, seed 20261125; counts are
exact, values at random, all from one ``numpy.random.default_rng(seed)`` in a
fixed order by :func:`draw_objects`):

- a sky family and its options: gensky clear, intermediate and overcast
  (turbidity 2-4), CIE general skies (types from a list, balanced; DNI and
  DHI from pvlib's clear sky at a Linke turbidity of 2-9; types 1-5 have no
  sun), Perez (gendaylit, the same clear sky);
- per-frame departures, applied per source (:func:`bayesgloss.illumination.split_sky`):
  haze in every frame, the sun's part times exp(N(0, 0.3^2)); broken cloud in
  a share of the objects whose sky has a sun, the sun cut to 0-20 % and the
  sky raised 1.3-2x in a random 20-50 % of the frames; auto exposure in half
  of the ``linear`` objects, a per-frame gain exp(N(0, 0.5^2)) that is not
  written to the bundle (``linear-radiance`` objects keep their radiance: the
  estimator takes their exposure as known);
- a site in either hemisphere (|latitude| up to 65 deg, any longitude, civil
  UTC offset round(lon / 15) h, some half-hour offsets), a date in the year,
  10-16 frames all with the sun above ``min_sun_z``: spread evenly over the
  day, at random times over the day, on consecutive whole hours, or at
  random times in a 4-6 h window;
- an object: a tessellated hemisphere (4-6 rings, 8-16 segments), a gem or
  a box, a camera at any bearing, 0.5-6 m high and 6-20 m away; at most
  ``max_facets`` of the facets it sees (with ``min_pixels`` labelled pixels)
  are written, chosen at random;
- a material: one gamma (uniform on [0, 1]) and one exponent (log n uniform
  on the prior's range, :class:`bayesgloss.likelihood.Priors`) for the
  object; facet scales s_f = albedo x exp(N(0, 0.1^2)); relative noise of sd
  1-5 % on (value + 1 % of the facet's largest value), the likelihood's own
  noise model;
- an encoding: ``linear-radiance`` (float TIFF) or ``linear`` (16-bit PNG
  or float TIFF, normalised by a white 1.1-1.5x the largest value, so that
  nothing clips).

Each facet's value in a frame is

    mu_ft = g_t s_f [a_t ((1 - gamma) D^sun_ft + gamma G^sun_ft(n))
                     + b_t ((1 - gamma) D^sky_ft + gamma G^sky_ft(n))],

with D, G the bases of :func:`bayesgloss.render.facet_bases` of the sun and
the sky parts of the true sky (ground plane of the bundle's reflectance, no
ground shadow, as the estimator computes them), G linear in log n between
the nodes of the exponent table (:func:`bayesgloss.likelihood.grid_position`,
as the model interpolates), a_t the haze and cloud factor of the sun, b_t
the cloud factor of the sky, g_t the camera's gain. Every labelled pixel of
a facet holds its value (grey RGB); the background holds half the frame's
median facet value.

Recorded per object: the truth, the object's gamma (median, 5 and 95 %
points, 90 % HDI: the model's own, ``summary["object"]["gamma_within_model"]``,
which this study checks; the reported one with the model's error,
:mod:`bayesgloss.model_error`, beside it as ``object_reported``),
the shared-material gamma, flags, convergence and time; the truth's place
in the object's posterior (the fraction of population-mean draws below it,
recomputed with :func:`bayesgloss.pooling.population_gloss` as
:func:`bayesgloss.estimate.estimate_bundle` computes it, and checked against
its summary) and the object's quantiles at ``quantile_levels``; per facet
its interval and the truth's place in its draws.

Every object is one unit of :func:`bayesgloss.runner.run_units`: its record
is cached in ``studies/out/calibration_joint/objects/`` under a key that
hashes its config, the fit options and the source of bayesgloss and of this
script's simulation and fit, so a rerun resumes and a changed estimator
computes everything again. The bundles stay in
``studies/out/calibration_joint/bundles/`` (git-ignored).

Usage: python studies/calibration_joint.py [--n N] [--jobs 2] [--out DIR]
[--max-sweeps S] [--draw-only] [--plot-only]
"""

from __future__ import annotations

import argparse
import datetime as dt
import functools
import hashlib
import inspect
import json
import sys
import time
import warnings
from pathlib import Path

import _common
import numpy as np
import pandas as pd
from code_under_test import check as check_code  # a sibling study (studies/ on sys.path)
from validation_set import _labels, _sun_z, _uniform, _utc_offset_hours  # the same draws

from bayesgloss import bundle as bundle_io
from bayesgloss import diagnostics, estimate, pooling, render, runner, sequences, sky, sun
from bayesgloss import illumination as il
from bayesgloss import likelihood as lk

NAME = "calibration_joint"
STUDIES = Path(__file__).resolve().parent
CONFIG = STUDIES / "configs" / f"{NAME}.json"
CACHE = STUDIES / "out" / NAME
RESULTS = STUDIES / "results"
#: Sky families whose skies have a sun (CIE: types 6-15).
SUNNY_FAMILIES = ("gensky-clear", "gensky-intermediate", "perez")
#: Reporting groups of the sky, in the table's order.
SKY_GROUPS = (
    "gensky-clear",
    "gensky-intermediate",
    "gensky-overcast",
    "cie-overcast",
    "cie-partly",
    "cie-clear",
    "perez",
)
#: A facet has direct sun when the sun lights it (cos > this, sun not cut
#: below 5 %) in at least two frames.
SUNLIT_COS = 0.05


# ---------------------------------------------------------------------------
# drawing the objects
# ---------------------------------------------------------------------------


def _chosen(rng: np.random.Generator, candidates: np.ndarray, k: int, n: int) -> np.ndarray:
    """n booleans, True at ``k`` of the ``candidates`` indices drawn at random."""
    out = np.zeros(n, bool)
    out[rng.permutation(candidates)[:k]] = True
    return out


def has_sun(family: str, cie_type: int | None) -> bool:
    """Whether the true sky has a solar disc (gensky overcast and CIE 1-5 do not)."""
    return family in SUNNY_FAMILIES or (family == "cie" and cie_type >= 6)


def sky_group(obj: dict) -> str:
    """The object's reporting group of :data:`SKY_GROUPS`."""
    if obj["family"] != "cie":
        return obj["family"]
    t = int(obj["sky"].split("-")[1])
    return "cie-overcast" if t <= 5 else "cie-partly" if t <= 11 else "cie-clear"


def _frame_times(rng, tcfg: dict, scheme: str, date, tz, latitude, longitude, k: int):
    """``k`` civil frame times with the sun above ``min_sun_z`` (fewer, at
    least ``frames[0]``, for ``hourly``), or None where the day cannot give
    them (the caller draws another site and date)."""
    day = pd.Timestamp(date).tz_localize(tz)
    grid = day + pd.to_timedelta(np.arange(0, 24 * 60, 5), unit="min")
    up = _sun_z(grid, latitude, longitude) > tcfg["min_sun_z"]
    if up.sum() < 3:
        return None
    first, last = np.flatnonzero(up)[[0, -1]]
    if not up[first : last + 1].all():  # one sunny stretch within the civil day
        return None
    rise, set_ = grid[first] + pd.Timedelta(minutes=5), grid[last] - pd.Timedelta(minutes=5)
    span = (set_ - rise) / pd.Timedelta(hours=1)
    if scheme == "full-even":
        times = rise + pd.to_timedelta(np.linspace(0.0, span, k), unit="h")
    elif scheme == "full-random":
        times = rise + pd.to_timedelta(np.sort(rng.uniform(0.0, span, k)), unit="h")
    elif scheme == "hourly":
        hours = pd.date_range(rise.ceil("h"), set_.floor("h"), freq="h")
        if len(hours) < tcfg["frames"][0]:
            return None
        k = min(k, len(hours))
        start = int(rng.integers(0, len(hours) - k + 1))
        times = hours[start : start + k]
    elif scheme == "window-random":
        width = min(_uniform(rng, tcfg["window_hours"]), span)
        start = rise + pd.to_timedelta(rng.uniform(0.0, span - width), unit="h")
        times = start + pd.to_timedelta(np.sort(rng.uniform(0.0, width, k)), unit="h")
    else:
        raise ValueError(f"unknown time scheme {scheme!r}")
    times = pd.DatetimeIndex(times).round("min")
    if len(times.unique()) != len(times):
        return None
    if np.any(_sun_z(times, latitude, longitude) <= tcfg["min_sun_z"]):
        return None
    return times


def _site_and_times(rng, cfg: dict, north: bool, scheme: str) -> dict:
    """Site, date and civil frame times; redrawn until the day gives the frames."""
    scfg, tcfg = cfg["site"], cfg["times"]
    for _ in range(500):
        latitude = _uniform(rng, scfg["abs_latitude"]) * (1.0 if north else -1.0)
        longitude = _uniform(rng, scfg["longitude"])
        offset = _utc_offset_hours(rng, longitude, scfg["half_hour_offset_fraction"])
        tz = dt.timezone(dt.timedelta(hours=offset))
        date = dt.date(cfg["year"], 1, 1) + dt.timedelta(days=int(rng.integers(0, 365)))
        k = int(rng.integers(tcfg["frames"][0], tcfg["frames"][1] + 1))
        times = _frame_times(rng, tcfg, scheme, date, tz, latitude, longitude, k)
        if times is not None:
            return {
                "latitude": round(latitude, 4),
                "longitude": round(longitude, 4),
                "utc_offset_hours": offset,
                "date": date.isoformat(),
                "scheme": scheme,
                "times": [t.isoformat() for t in times],
            }
    raise RuntimeError(f"no site and date with enough sunny frames for {scheme!r} in 500 draws")


def _rounded(values, digits: int = 5) -> list[float]:
    return [round(float(v), digits) for v in np.atleast_1d(values)]


def draw_objects(cfg: dict) -> list[dict]:
    """The study's objects, drawn from ``default_rng(cfg["seed"])`` in one fixed order.

    Parameters
    ----------
    cfg : dict
        The config (``studies/configs/calibration_joint.json``).

    Returns
    -------
    list of dict
        ``cfg["n_objects"]`` object configs (JSON-ready), named
        ``cj<index>-<family>``: sky, site and times, object and camera,
        encoding, material, noise and every per-frame departure, each value
        rounded as it is used to simulate.
    """
    rng = np.random.default_rng(cfg["seed"])
    n = cfg["n_objects"]
    sk, dep = cfg["sky"], cfg["departures"]
    families = _labels(rng, sk["families"], n)
    cie_index = [i for i in range(n) if families[i] == "cie"]
    types: list[int] = []
    while len(types) < len(cie_index):  # balanced: every type once before any twice
        types += [int(t) for t in rng.permutation(sk["cie_types"])]
    cie_type = dict(zip(cie_index, types, strict=False))
    encodings = _labels(rng, cfg["encodings"], n)
    north = _chosen(rng, np.arange(n), cfg["site"]["north"], n)
    schemes = _labels(rng, cfg["times"]["schemes"], n)
    shapes = _labels(rng, cfg["objects"]["shapes"], n)
    sunny = np.flatnonzero([has_sun(families[i], cie_type.get(i)) for i in range(n)])
    broken = _chosen(rng, sunny, int(round(dep["broken_cloud_fraction_of_sunny"] * len(sunny))), n)
    linear = np.flatnonzero([e == "linear" for e in encodings])
    auto = _chosen(
        rng, linear, int(round(dep["auto_exposure_fraction_of_linear"] * len(linear))), n
    )

    out = []
    for i in range(n):
        family = families[i]
        obj: dict = {"index": i, "name": f"cj{i:03d}-{family}", "family": family}
        if family.startswith("gensky-"):
            obj["sky"] = family
            obj["sky_options"] = {"turbidity": round(_uniform(rng, sk["gensky_turbidity"]), 3)}
        else:
            obj["sky"] = f"cie-{cie_type[i]}" if family == "cie" else "perez"
            obj["sky_options"] = {"linke_turbidity": round(_uniform(rng, sk["linke_turbidity"]), 3)}
        obj["has_sun"] = has_sun(family, cie_type.get(i))
        obj.update(_site_and_times(rng, cfg, bool(north[i]), schemes[i]))
        t = len(obj["times"])

        o, cam = cfg["objects"], cfg["camera"]
        obj["shape"] = shapes[i]
        if shapes[i] == "hemisphere":
            obj["shape_options"] = {
                "n_rings": int(rng.integers(o["n_rings"][0], o["n_rings"][1] + 1)),
                "n_segments": int(rng.integers(o["n_segments"][0], o["n_segments"][1] + 1)),
            }
        elif shapes[i] == "box":
            obj["shape_options"] = {
                "box_size": _rounded(rng.uniform(*o["box_size"], 3), 3),
                "box_azimuth": round(_uniform(rng, o["box_azimuth"]), 2),
            }
        else:
            obj["shape_options"] = {
                "gem_stand": str(o["gem_stand"][int(rng.integers(len(o["gem_stand"])))]),
                "gem_azimuth": round(_uniform(rng, o["gem_azimuth"]), 2),
            }
        obj["camera"] = {
            "bearing": round(_uniform(rng, cam["bearing"]), 2),
            "height": round(_uniform(rng, cam["height"]), 3),
            "distance": round(_uniform(rng, cam["distance"]), 3),
        }

        obj["encoding"] = encodings[i]
        formats = cfg["frame_formats"][encodings[i]]
        obj["frame_format"] = str(formats[int(rng.integers(len(formats)))])
        obj["white_scale"] = round(_uniform(rng, cfg["white_scale"]), 4)

        m = cfg["material"]
        obj["gamma"] = round(_uniform(rng, m["gamma"]), 5)
        obj["log_n"] = round(_uniform(rng, lk.Priors().log_n), 5)
        obj["albedo"] = round(_uniform(rng, m["albedo"]), 4)
        obj["facet_scale_sd"] = m["facet_scale_sd"]
        obj["ground_reflectance"] = round(_uniform(rng, cfg["ground_reflectance"]), 4)
        obj["noise_sd"] = round(_uniform(rng, cfg["noise_sd"]), 5)

        haze = dep["haze_sd"] * rng.standard_normal(t)
        cloud_sun, cloud_sky = np.ones(t), np.ones(t)
        if broken[i]:
            n_cut = max(1, int(round(_uniform(rng, dep["broken_frame_fraction"]) * t)))
            cut = rng.choice(t, n_cut, replace=False)
            cloud_sun[cut] = rng.uniform(*dep["broken_sun_factor"], n_cut)
            cloud_sky[cut] = rng.uniform(*dep["broken_sky_factor"], n_cut)
        gain = np.ones(t)
        if auto[i]:
            gain = np.exp(dep["auto_exposure_sd"] * rng.standard_normal(t))
        obj["departures"] = {
            "broken_cloud": bool(broken[i]),
            "auto_exposure": bool(auto[i]),
            "haze_log_sun": _rounded(haze),
            "cloud_sun_factor": _rounded(cloud_sun),
            "cloud_sky_factor": _rounded(cloud_sky),
            "gain": _rounded(gain),
        }
        obj["simulation_seed"] = int(rng.integers(0, 2**31 - 1))
        obj["fit_seed"] = i
        out.append(obj)
    return out


def composition(objects: list[dict]) -> dict:
    """Counts by sky group, encoding, shape, scheme, hemisphere and departure;
    latitude and frame ranges."""

    def count(values):
        out: dict = {}
        for v in values:
            out[v] = out.get(v, 0) + 1
        return dict(sorted(out.items()))

    lat = np.array([o["latitude"] for o in objects])
    frames = [len(o["times"]) for o in objects]
    return {
        "objects": len(objects),
        "sky_group": count(sky_group(o) for o in objects),
        "sky": count(o["sky"] for o in objects),
        "has_sun": count(o["has_sun"] for o in objects),
        "encoding": count(f"{o['encoding']} {o['frame_format']}" for o in objects),
        "shape": count(o["shape"] for o in objects),
        "scheme": count(o["scheme"] for o in objects),
        "hemisphere": count("north" if o["latitude"] >= 0 else "south" for o in objects),
        "broken_cloud": sum(o["departures"]["broken_cloud"] for o in objects),
        "auto_exposure": sum(o["departures"]["auto_exposure"] for o in objects),
        "latitude_range": [float(lat.min()), float(lat.max())],
        "frames": [min(frames), max(frames)],
        "total_frames": int(sum(frames)),
    }


def configs_json(objects: list[dict]) -> str:
    """The drawn objects as JSON text, with their composition."""
    doc = {"composition": composition(objects), "objects": objects}
    return json.dumps(doc, indent=1) + "\n"


# ---------------------------------------------------------------------------
# simulating one object's bundle
# ---------------------------------------------------------------------------


def sequence_config(obj: dict, sim: dict) -> sequences.SequenceConfig:
    """The object's shape, camera and image as a :class:`~bayesgloss.sequences.SequenceConfig`
    (for its facets, camera position and label image; nothing is rendered)."""
    options = dict(obj["shape_options"])
    if "box_size" in options:
        options["box_size"] = tuple(options["box_size"])
    return sequences.SequenceConfig(
        name=obj["name"],
        shape=obj["shape"],
        view=float(obj["camera"]["bearing"]),
        camera_height=float(obj["camera"]["height"]),
        camera_distance=float(obj["camera"]["distance"]),
        image_size=int(sim["image_size"]),
        **options,
    )


def seen_facets(obj: dict, sim: dict, rng: np.random.Generator):
    """The facets written to the bundle and their label image.

    Facets with at least ``min_pixels`` labelled pixels (wholly inside the
    facet, :func:`bayesgloss.sequences.label_image`), at most ``max_facets``
    of them chosen with ``rng``; the others' pixels become background.

    Returns
    -------
    facets : bayesgloss.geometry.Facets
    labels : ndarray (H, W) of int
    camera_position : ndarray (3,) [m]
    """
    config = sequence_config(obj, sim)
    facets = config.facets()
    labels = sequences.label_image(config, facets)
    counts = np.bincount(labels.ravel(), minlength=int(facets.ids.max()) + 1)
    seen = np.flatnonzero(counts[facets.ids] >= sim["min_pixels"])
    if len(seen) > sim["max_facets"]:
        seen = np.sort(rng.choice(seen, sim["max_facets"], replace=False))
    chosen = facets.subset(seen)
    labels = np.where(np.isin(labels, chosen.ids), labels, 0)
    return chosen, labels, config.camera_position()


def frame_sun_directions(times, latitude: float, longitude: float) -> np.ndarray:
    """Unit vectors toward the apparent sun, as :func:`bayesgloss.bundle.read_bundle`
    computes them from a bundle's site and times, (T, 3)."""
    index = pd.DatetimeIndex([pd.Timestamp(t) for t in times]).tz_convert("UTC")
    position = sun.solar_position(index, latitude, longitude, 0.0)
    return sun.sun_direction(position["solar_zenith"], position["solar_azimuth"])


def true_daylight(obj: dict, sun_direction: np.ndarray) -> sky.DaylightSky:
    """The object's true sky (before departures) from :func:`bayesgloss.sky.daylight`."""
    options = dict(obj["sky_options"], ground_reflectance=obj["ground_reflectance"])
    if obj["sky"] == "perez" or obj["sky"].startswith("cie-"):
        options["day_of_year"] = int(pd.Timestamp(obj["date"]).day_of_year)
    return sky.daylight(obj["sky"], sun_direction, **options)


def source_curves(geometry_, day, rho: float, gamma: float, log_n: float):
    """Each source's unit-scale facet curves (1 - gamma) D + gamma G(n) and its
    diffuse basis: the sun part and the sky part of ``day``.

    G is linear in log n between the nodes of :data:`bayesgloss.render.DEFAULT_EXPONENTS`
    (:func:`bayesgloss.likelihood.grid_position`, as the model interpolates).

    Returns
    -------
    dict
        ``"sun"`` and ``"sky"``: (curve (F, T), diffuse (F, T)) [W sr^-1 m^-2].
    """
    exps = render.DEFAULT_EXPONENTS
    j, w = lk.grid_position(np.asarray(log_n, float), np.log(exps))
    out = {}
    for source, part in zip(("sun", "sky"), il.split_sky(day), strict=True):
        b = render.facet_bases(geometry_, part, exps, ground="plane", ground_reflectance=rho)
        glossy = b.glossy[:, j] + w * (b.glossy[:, j + 1] - b.glossy[:, j])
        out[source] = ((1.0 - gamma) * b.diffuse + gamma * glossy, b.diffuse)
    return out


def simulate_object(obj: dict, sim: dict) -> dict:
    """The object's facet values in every frame, and what the bundle needs.

    Returns
    -------
    dict
        ``facets``, ``labels``, ``camera_position``, ``sun_direction`` (T, 3),
        ``mu`` (F, T, noiseless, after the camera's gains), ``y`` (F, T, with
        noise), ``scale`` (F,) and ``sunlit`` (F,) of bool.
    """
    rng = np.random.default_rng(obj["simulation_seed"])
    facets, labels, camera = seen_facets(obj, sim, rng)
    sun_dir = frame_sun_directions(obj["times"], obj["latitude"], obj["longitude"])
    day = true_daylight(obj, sun_dir)
    rho = obj["ground_reflectance"]
    parts = source_curves(
        render.view_geometry(facets, camera), day, rho, obj["gamma"], obj["log_n"]
    )
    d = obj["departures"]
    sun_factor = np.exp(np.asarray(d["haze_log_sun"])) * np.asarray(d["cloud_sun_factor"])
    sky_factor = np.asarray(d["cloud_sky_factor"])
    gain = np.asarray(d["gain"])
    scale = obj["albedo"] * np.exp(obj["facet_scale_sd"] * rng.standard_normal(len(facets)))
    mu = scale[:, None] * gain * (sun_factor * parts["sun"][0] + sky_factor * parts["sky"][0])
    # the likelihood's noise: sd = sigma (mu + c), c a fraction of the facet's largest value
    floor = sim["noise_floor_fraction"] * mu.max(axis=1, keepdims=True)
    y = mu + obj["noise_sd"] * (mu + floor) * rng.standard_normal(mu.shape)
    lit = (facets.normal @ day.sun_direction.T > SUNLIT_COS) & (
        day.solar_radiance * sun_factor > 0
    )[None, :]
    lit &= (np.asarray(d["cloud_sun_factor"]) >= 0.05)[None, :]
    return {
        "facets": facets,
        "labels": labels,
        "camera_position": camera,
        "sun_direction": sun_dir,
        "mu": mu,
        "y": np.maximum(y, 0.0),
        "scale": scale,
        "sunlit": lit.sum(axis=1) >= 2,
    }


def paint_frames(labels: np.ndarray, ids: np.ndarray, values: np.ndarray, background: float):
    """Grey RGB frames with every labelled pixel at its facet's value, (T, H, W, 3).

    ``values`` (F, T) per facet and frame; the background holds ``background``
    times the frame's median facet value.
    """
    n_t = values.shape[1]
    table = np.zeros((n_t, max(int(labels.max()), int(ids.max())) + 1))
    table[:] = (background * np.median(values, axis=0))[:, None]
    table[:, ids] = values.T
    grey = table[:, labels]  # (T, H, W)
    return np.repeat(grey[..., None], 3, axis=-1)


def write_object_bundle(obj: dict, sim: dict, path: Path) -> dict:
    """Simulate the object and write it as a sequence bundle at ``path``.

    ``linear-radiance``: radiance as float TIFF. ``linear``: values divided
    by a white ``white_scale`` times the largest, as 16-bit PNG codes or
    float TIFF. The manifest's ``truth`` holds the object's config (the
    estimator does not read it); no ``frames[].exposure`` is written.

    Returns
    -------
    dict
        The simulation (:func:`simulate_object`) and ``white``.
    """
    s = simulate_object(obj, sim)
    values = s["y"]
    white = None
    if obj["encoding"] == "linear":
        white = float(obj["white_scale"] * values.max())
        values = values / white
    frames = paint_frames(s["labels"], s["facets"].ids, values, sim["background_fraction"])
    if obj["frame_format"] == "tiff":
        frames = frames.astype(np.float32)
    bundle_io.write_bundle(
        path,
        site={"latitude": obj["latitude"], "longitude": obj["longitude"], "elevation": 0.0},
        camera_position=s["camera_position"],
        pixel_encoding=obj["encoding"],
        frames=list(frames),
        times=obj["times"],
        facets=s["facets"],
        labels=s["labels"].astype(np.uint16),
        ground_reflectance=obj["ground_reflectance"],
        truth={**obj, "gloss": obj["gamma"], "renderer": "bayesgloss.render (forward model)"},
        frame_format=obj["frame_format"],
        overwrite=True,
    )
    return {**s, "white": white}


# ---------------------------------------------------------------------------
# fitting and recording one object
# ---------------------------------------------------------------------------


def object_posterior(result, seed: int) -> tuple[np.ndarray, bool]:
    """Draws of the object's gamma and whether they give the summary's quantiles.

    With per-frame illumination the estimator's object is the one-material
    model's gamma (``gamma_object`` in the InferenceData); with fixed
    brightness the population mean, recomputed here from the facet draws as
    the estimator computes it (:func:`bayesgloss.pooling.population_gloss`
    on the converged facets, or all of them when fewer than two converged,
    with their bulk ESS and the fit's seed). ``False``: the estimator
    computes them otherwise now, and the draws must not be used.
    """
    idata = result.idata
    # the model's own interval (the reported one adds the model's error,
    # bayesgloss.model_error): this study checks the model on its own data
    obj = result.summary["object"]
    summary = obj.get("gamma_within_model", obj["gamma"])
    if "gamma_object" in idata.posterior:
        mu = idata.posterior["gamma_object"].values.ravel()
    else:
        diag = diagnostics.gamma_convergence(idata)
        conv = np.asarray(diag["converged"], bool)
        gam = idata.posterior["gamma"].values  # (E, S, F)
        per_facet = gam.transpose(2, 0, 1).reshape(gam.shape[-1], -1)
        use = conv if conv.sum() >= 2 else np.ones(len(conv), dtype=bool)
        mu = pooling.population_gloss(per_facet[use], ess=diag["ess_bulk"][use], seed=seed)["mu"]
    q = np.quantile(mu, [0.05, 0.5, 0.95])
    want = [summary["q05"], summary["median"], summary["q95"]]
    return mu, bool(np.allclose(q, want, rtol=0, atol=1e-12))


def facet_records(result, sim_out: dict, truth: float) -> list[dict]:
    """Each written facet's interval, the truth's place in its draws, and
    whether the sun lights it; facets the estimator left out have no interval."""
    summary = {f["id"]: f for f in result.summary["facets"]}
    post = result.idata.posterior["gamma"]
    fitted = [int(v) for v in post.coords["facet"].values]
    out = []
    for k, fid in enumerate(sim_out["facets"].ids):
        entry = summary.get(int(fid), {})
        rec = {"id": int(fid), "sunlit": bool(sim_out["sunlit"][k])}
        if entry.get("gamma") is not None and int(fid) in fitted:
            g = entry.get("gamma_within_model", entry["gamma"])  # the model's own
            draws = post.values[..., fitted.index(int(fid))].ravel()
            rec.update(
                median=g["median"],
                q05=g["q05"],
                q95=g["q95"],
                hdi90=g["hdi90"],
                pit=float(np.mean(draws < truth)),
                converged=bool(entry["converged"]),
            )
        rec["flags"] = entry.get("flags", ["not-in-summary"])
        out.append(rec)
    return out


def sampler_diagnostics(samples, n_facets: int) -> dict | None:
    """The joint sampler's worst R-hat and smallest bulk ESS, of the facets'
    gamma and of the frames' sun and sky latents (None for another sampler)."""
    rhat, ess = getattr(samples, "rhat", None), getattr(samples, "ess_bulk", None)
    if rhat is None or ess is None or len(rhat) <= n_facets:
        return None
    rhat, ess = np.asarray(rhat, float), np.asarray(ess, float)
    return {
        "rhat_max_gamma": float(np.nanmax(rhat[:n_facets])),
        "rhat_max_frames": float(np.nanmax(rhat[n_facets:])),
        "ess_bulk_min_gamma": float(np.nanmin(ess[:n_facets])),
        "ess_bulk_min_frames": float(np.nanmin(ess[n_facets:])),
    }


def object_record(obj: dict, result, sim_out: dict, levels, seconds: float, caught) -> dict:
    """Everything the study's tables need of one fitted object."""
    truth = obj["gamma"]
    s = result.summary
    o = s["object"]
    record = {
        "index": obj["index"],
        "name": obj["name"],
        "family": obj["family"],
        "sky": obj["sky"],
        "sky_group": sky_group(obj),
        "has_sun": obj["has_sun"],
        "shape": obj["shape"],
        "encoding": obj["encoding"],
        "frame_format": obj["frame_format"],
        "scheme": obj["scheme"],
        "broken_cloud": obj["departures"]["broken_cloud"],
        "auto_exposure": obj["departures"]["auto_exposure"],
        "latitude": obj["latitude"],
        "frames": len(obj["times"]),
        "facets_written": len(sim_out["facets"]),
        "facets_sunlit": int(np.sum(sim_out["sunlit"])),
        "noise_sd": obj["noise_sd"],
        "truth": {"gamma": truth, "n": float(np.exp(obj["log_n"]))},
        "object": {
            k: o.get("gamma_within_model", o["gamma"])[k] for k in ("median", "q05", "q95", "hdi90")
        },
        "object_reported": {k: o["gamma"][k] for k in ("median", "q05", "q95", "hdi90")},
        "shared_material_gamma": o["shared_material_gamma"],
        "mean_of_facet_medians": o["mean_of_facet_medians"],
        "flags": o["flags"],
        "converged": o["converged"],
        "facets_fitted": o["facets"],
        "facets_converged": o["facets_converged"],
        "illumination": s["illumination"],
        "sky_models": s.get("sky_models"),
        # how much the sky families' weights rest on unreliable PSIS-LOO, and
        # whether they were made equal for it (sky_families.equal_when_unreliable)
        "sky_families": {
            k: s["sky_families"].get(k) for k in ("most_weight", "high_k_share", "equal_weights")
        }
        if "sky_families" in s
        else None,
        "model": s["sampler"]["model"],
        "sweeps": s["sampler"].get("sweeps"),
        "sampler_seconds": s["sampler"]["seconds"],
        "seconds": seconds,
        "facets": facet_records(result, sim_out, truth),
        "warnings": sorted({str(w.message)[:200] for w in caught}),
        "sampler_diagnostics": sampler_diagnostics(result.samples, o["facets"]),
    }
    mu, match = object_posterior(result, obj["fit_seed"])
    record["object"]["draws_match_summary"] = match
    if match:
        record["object"]["pit"] = float(np.mean(mu < truth))
        record["object"]["quantiles"] = [float(v) for v in np.quantile(mu, levels)]
    return record


def unit_options(obj: dict, cfg: dict, sampler_options: dict, code: str) -> dict:
    """A unit's options (hashed into its cache key): the object, the
    simulation and fit settings, the quantile levels and the code's hash."""
    return {
        "obj": obj,
        "sim": cfg["simulation"],
        "fit": {"per_frame": cfg["fit"]["per_frame"], "sampler_options": sampler_options},
        "levels": cfg["quantile_levels"],
        "code": code,
    }


def unit(obj: dict, sim: dict, fit: dict, levels, code: str, bundles: str) -> dict[str, bytes]:
    """Simulate, write and fit one object: its record as ``record.json``.

    The bundle is written to ``bundles/<unit key>/`` (kept for inspection).
    """
    key = runner.unit_key(obj["name"], dict(obj=obj, sim=sim, fit=fit, levels=levels, code=code))
    path = Path(bundles) / key
    sim_out = write_object_bundle(obj, sim, path)
    t0 = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            result = estimate.estimate_bundle(
                path,
                per_frame=fit["per_frame"],
                seed=obj["fit_seed"],
                sampler_options=fit["sampler_options"] or None,
            )
        except (bundle_io.NoUsableData, bundle_io.BundleError) as err:
            record = {"index": obj["index"], "name": obj["name"], "error": str(err)}
            return {"record.json": json.dumps(record).encode()}
    seconds = time.perf_counter() - t0
    record = object_record(obj, result, sim_out, levels, seconds, caught)
    record["bundle"] = str(path)
    return {"record.json": json.dumps(record).encode()}


#: The functions whose source, with bayesgloss's, keys the cache.
UNIT_FUNCTIONS = (
    seen_facets,
    sequence_config,
    frame_sun_directions,
    true_daylight,
    source_curves,
    simulate_object,
    paint_frames,
    write_object_bundle,
    object_posterior,
    facet_records,
    sampler_diagnostics,
    object_record,
    unit,
)


def code_hash() -> str:
    """SHA-256 (16 hex digits) of bayesgloss's source and of the functions
    that simulate, fit and record an object: a change to either computes
    every object again."""
    import bayesgloss

    h = hashlib.sha256()
    root = Path(bayesgloss.__file__).resolve().parent
    for path in sorted(root.rglob("*.py")):
        h.update(str(path.relative_to(root)).encode())
        h.update(path.read_bytes())
    for func in UNIT_FUNCTIONS:
        h.update(inspect.getsource(func).encode())
    return h.hexdigest()[:16]


def run_objects(objects, cfg, sampler_options, cache: Path, jobs: int) -> list[dict]:
    """Every object's record, computed where not cached (:func:`bayesgloss.runner.run_units`)."""
    code = code_hash()
    units = [(o["name"], unit_options(o, cfg, sampler_options, code)) for o in objects]
    func = functools.partial(
        runner.script_unit, str(Path(__file__).resolve()), "unit", bundles=str(cache / "bundles")
    )

    def progress(done: int, total: int) -> None:
        print(f"\r{NAME}: {done}/{total} objects", end="", file=sys.stderr, flush=True)

    folders = runner.run_units(func, units, cache / "objects", jobs=jobs, progress=progress)
    print(file=sys.stderr)
    return [json.loads((f / "record.json").read_text()) for f in folders]


# ---------------------------------------------------------------------------
# the tables
# ---------------------------------------------------------------------------


def binomial_interval(k: int, n: int, level: float = 0.9) -> list[float]:
    """Clopper-Pearson interval of a proportion k / n at ``level`` [-]."""
    from scipy import stats

    if n == 0:
        return [float("nan"), float("nan")]
    a = 0.5 * (1.0 - level)
    lo = 0.0 if k == 0 else float(stats.beta.ppf(a, k, n - k + 1))
    hi = 1.0 if k == n else float(stats.beta.ppf(1.0 - a, k + 1, n - k))
    return [lo, hi]


def _covers(interval, truth: float) -> bool:
    return interval[0] <= truth <= interval[1]


def coverage_of(records: list[dict]) -> dict:
    """Coverage of the 90 % intervals (equal-tailed, HDI, shared material),
    each with its binomial 90 % interval, MAE and the interval widths of a
    set of object records."""
    n = len(records)
    out: dict = {"objects": n}
    if not n:
        return out
    truth = [r["truth"]["gamma"] for r in records]
    kinds = {
        "q05_q95": [(r["object"]["q05"], r["object"]["q95"]) for r in records],
        "hdi90": [tuple(r["object"]["hdi90"]) for r in records],
        "shared_q05_q95": [
            (r["shared_material_gamma"]["q05"], r["shared_material_gamma"]["q95"]) for r in records
        ],
    }
    for kind, intervals in kinds.items():
        k = sum(_covers(i, t) for i, t in zip(intervals, truth, strict=True))
        out[kind] = {"covered": int(k), "coverage": k / n, "interval90": binomial_interval(k, n)}
    err = np.abs([r["object"]["median"] - t for r, t in zip(records, truth, strict=True)])
    width = np.array([r["object"]["q95"] - r["object"]["q05"] for r in records])
    out["mae"] = float(np.mean(err))
    out["median_abs_error"] = float(np.median(err))
    out["max_abs_error"] = float(np.max(err))
    out["median_width"] = float(np.median(width))
    out["not_converged"] = sum("not-converged" in r["flags"] for r in records)
    out["not_identifiable"] = sum("gloss-not-identifiable" in r["flags"] for r in records)
    return out


def coverage_curve(records: list[dict], levels, key: str = "object") -> dict:
    """Observed coverage of central intervals at each nominal level, from the
    truth's place (PIT) in the object's draws (``key="object"``), or in each
    sunlit facet's draws (``key="facets"``, facets of one object pooled)."""
    if key == "object":
        pit = [r["object"]["pit"] for r in records if "pit" in r["object"]]
    else:
        pit = [f["pit"] for r in records for f in r["facets"] if f["sunlit"] and "pit" in f]
    pit = np.asarray(pit, float)
    rows = []
    for level in levels:
        k = int(np.sum(np.abs(pit - 0.5) <= 0.5 * level))
        rows.append(
            {
                "level": level,
                "covered": k,
                "n": len(pit),
                "coverage": k / len(pit) if len(pit) else float("nan"),
                "interval90": binomial_interval(k, len(pit)),
            }
        )
    return {"n": int(len(pit)), "levels": rows}


def facet_coverage(records: list[dict]) -> dict:
    """Coverage of the sunlit facets' 90 % intervals (facets of one object
    share their illumination, so they are not independent)."""
    pairs = [
        (f, r["truth"]["gamma"]) for r in records for f in r["facets"] if f["sunlit"] and "q05" in f
    ]
    facets = [f for f, _ in pairs]
    k = sum(_covers((f["q05"], f["q95"]), t) for f, t in pairs)
    n = len(pairs)
    return {
        "facets": n,
        "covered": int(k),
        "coverage": k / n if n else float("nan"),
        "interval90_if_independent": binomial_interval(k, n),
        "not_converged": sum(not f["converged"] for f in facets),
    }


def summarise(records: list[dict], cfg: dict) -> dict:
    """Coverage overall, per sky group, departure, encoding, sun and shape;
    coverage curves; facet coverage; times; the issue's goal."""
    ok = [r for r in records if "error" not in r]
    groups: dict[str, list[dict]] = {"all": ok}
    for g in SKY_GROUPS:
        groups[f"sky:{g}"] = [r for r in ok if r["sky_group"] == g]
    groups["departure:haze-only"] = [r for r in ok if not (r["broken_cloud"] or r["auto_exposure"])]
    groups["departure:broken-cloud"] = [r for r in ok if r["broken_cloud"]]
    groups["departure:auto-exposure"] = [r for r in ok if r["auto_exposure"]]
    for e in cfg["encodings"]:
        groups[f"encoding:{e}"] = [r for r in ok if r["encoding"] == e]
    groups["sun:direct"] = [r for r in ok if r["has_sun"]]
    groups["sun:none"] = [r for r in ok if not r["has_sun"]]
    for s in cfg["objects"]["shapes"]:
        groups[f"shape:{s}"] = [r for r in ok if r["shape"] == s]
    groups["converged"] = [r for r in ok if r["converged"]]
    table = {name: coverage_of(rows) for name, rows in groups.items() if rows}
    seconds = np.array([r["seconds"] for r in ok]) if ok else np.array([np.nan])
    goal = cfg["goal"]
    overall = table.get("all", {}).get("q05_q95", {}).get("coverage", float("nan"))
    return {
        "objects": len(records),
        "errors": [r for r in records if "error" in r],
        "draws_match_summary": sum(r["object"].get("draws_match_summary", False) for r in ok),
        "coverage": table,
        "curve_object": coverage_curve(ok, cfg["coverage_levels"], "object"),
        "curve_object_direct_sun": coverage_curve(groups["sun:direct"], cfg["coverage_levels"]),
        "curve_facets_sunlit": coverage_curve(ok, cfg["coverage_levels"], "facets"),
        "facets_sunlit_q05_q95": facet_coverage(ok),
        "seconds": {
            "median": float(np.median(seconds)),
            "max": float(np.max(seconds)),
            "total": float(np.sum(seconds)),
        },
        "goal": {
            **goal,
            "objects": len(ok),
            "observed": overall,
            "met": bool(
                len(ok) >= goal["min_objects"]
                and goal["coverage"][0] <= overall <= goal["coverage"][1]
            ),
        },
    }


# ---------------------------------------------------------------------------
# the figure
# ---------------------------------------------------------------------------


def plot(results: dict, path: Path) -> None:
    """Nominal against observed coverage (objects, direct-sun objects, sunlit
    facets), the 90 % coverage of each group, and truth against estimate."""
    plt = _common.plt()
    s = results["summary"]
    fig, axes = plt.subplots(1, 3, figsize=(15, 5))

    ax = axes[0]
    for key, label, colour, style in (
        ("curve_object", "objects", "C0", "o-"),
        ("curve_object_direct_sun", "objects with direct sun", "C1", "s--"),
        ("curve_facets_sunlit", "sunlit facets (pooled)", "C2", "^-"),
    ):
        rows = s[key]["levels"]
        if not s[key]["n"]:
            continue
        x = [r["level"] for r in rows]
        y = [r["coverage"] for r in rows]
        lo = [r["interval90"][0] for r in rows]
        hi = [r["interval90"][1] for r in rows]
        ax.plot(x, y, style, color=colour, ms=4, label=f"{label} (n={s[key]['n']})")
        if key != "curve_facets_sunlit":
            ax.fill_between(x, lo, hi, color=colour, alpha=0.15, lw=0)
    ax.plot([0.45, 1.0], [0.45, 1.0], "k:", lw=0.8)
    g = s["goal"]
    mid = float(np.mean(g["coverage"]))
    ax.errorbar(
        [g["level"]],
        [mid],
        yerr=[[mid - g["coverage"][0]], [g["coverage"][1] - mid]],
        color="k",
        capsize=4,
        lw=1.5,
        label="goal at 90 %",
    )
    ax.set_xlabel("nominal coverage of the central interval")
    ax.set_ylabel("observed coverage (binomial 90 % band)")
    ax.set_xlim(0.45, 1.0)
    ax.set_ylim(0.0, 1.02)
    ax.legend(fontsize=8, loc="upper left")
    ax.set_title("calibration of the object's gamma")

    ax = axes[1]
    names = [k for k in s["coverage"] if k != "converged"]
    ys = np.arange(len(names))[::-1]
    for y, name in zip(ys, names, strict=True):
        c = s["coverage"][name]["q05_q95"]
        ax.errorbar(
            c["coverage"],
            y,
            xerr=[[c["coverage"] - c["interval90"][0]], [c["interval90"][1] - c["coverage"]]],
            fmt="o",
            color="C0",
            ms=4,
            capsize=2,
        )
        text = f"{c['covered']}/{s['coverage'][name]['objects']}"
        ax.text(1.01, y, text, va="center", fontsize=7)
    ax.axvspan(*g["coverage"], color="0.9", zorder=0)
    ax.axvline(g["level"], color="k", ls=":", lw=0.8)
    ax.set_yticks(ys)
    ax.set_yticklabels(names, fontsize=8)
    ax.set_xlim(0.0, 1.12)
    ax.set_xlabel("coverage of the 90 % interval (q05-q95)")
    ax.set_title("by group (grey: the goal)")

    ax = axes[2]
    objects = [r for r in results["objects"] if "error" not in r]
    colours = dict(zip(SKY_GROUPS, plt.cm.tab10(np.arange(len(SKY_GROUPS))), strict=True))
    for r in objects:
        o, t = r["object"], r["truth"]["gamma"]
        miss = not (o["q05"] <= t <= o["q95"])
        ax.errorbar(
            t,
            o["median"],
            yerr=[[o["median"] - o["q05"]], [o["q95"] - o["median"]]],
            fmt="x" if miss else "o",
            color=colours[r["sky_group"]],
            ms=4 if miss else 2.5,
            lw=0.6,
        )
    ax.plot([0, 1], [0, 1], "k:", lw=0.8)
    handles = [plt.Line2D([], [], color=colours[c], marker="o", ls="") for c in SKY_GROUPS]
    ax.legend(handles, SKY_GROUPS, fontsize=7, loc="upper left")
    ax.set_xlabel("true gamma")
    ax.set_ylabel("object gamma: median, 90 % interval (x: misses)")
    ax.set_xlim(-0.03, 1.03)
    ax.set_ylim(-0.03, 1.03)
    ax.set_title("truth and estimate")
    run = results["run"]
    fig.suptitle(
        f"joint model, forward-model objects: {len(objects)} objects, "
        f"sampler options {run['sampler_options'] or 'default'}",
        fontsize=10,
    )
    fig.tight_layout()
    _common.save_figure(fig, path, dpi=110)


# ---------------------------------------------------------------------------
# main
# ---------------------------------------------------------------------------


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default=str(CONFIG))
    ap.add_argument("--n", type=int, default=None, help="the first N objects (default: all)")
    ap.add_argument(
        "--shape",
        nargs="*",
        choices=("hemisphere", "box", "gem"),
        default=None,
        help="fit only the objects of these shapes (a subset's check; default: all)",
    )
    ap.add_argument("--jobs", type=int, default=2, help="worker processes (default 2)")
    ap.add_argument("--out", default=str(RESULTS), help="results folder (default %(default)s)")
    ap.add_argument("--cache", default=str(CACHE), help="object cache (default %(default)s)")
    ap.add_argument(
        "--max-sweeps",
        type=int,
        default=None,
        help="cap the joint sampler's sweeps (quick checks only; default: the library's)",
    )
    ap.add_argument("--draw-only", action="store_true", help="write the drawn configs, fit nothing")
    ap.add_argument(
        "--plot-only", action="store_true", help="redraw the figure from the saved results"
    )
    args = ap.parse_args(argv)
    check_code("calibration_joint")  # a candidate's worktree on PYTHONPATH is the code run
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    results_path, figure_path = out / f"{NAME}.json", out / f"{NAME}.png"
    if args.plot_only:
        results = json.loads(results_path.read_text())
        plot(results, figure_path)
        return results

    cfg = json.loads(Path(args.config).read_text())
    objects = draw_objects(cfg)
    (out / f"{NAME}_configs.json").write_text(configs_json(objects))
    print(json.dumps(composition(objects), indent=1))
    if args.draw_only:
        return {"objects": objects}

    chosen = objects if args.n is None else objects[: args.n]
    if args.shape:
        chosen = [o for o in chosen if o["shape"] in args.shape]
    sampler_options = dict(cfg["fit"]["sampler_options"])
    if args.max_sweeps is not None:
        sampler_options["max_sweeps"] = args.max_sweeps
    start = time.perf_counter()
    records = run_objects(chosen, cfg, sampler_options, Path(args.cache), args.jobs)
    results = {
        "config": cfg,
        "run": {
            "objects": len(chosen),
            "complete": len(chosen) == cfg["n_objects"] and not sampler_options,
            "shapes": args.shape or "all",
            "sampler_options": sampler_options,
            "code": code_hash(),
            "auto_skies": list(getattr(estimate, "AUTO_SKIES", [])),
            "jobs": args.jobs,
            "wall_seconds": time.perf_counter() - start,
            "finished": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
        },
        "summary": summarise(records, cfg),
        "objects": records,
    }
    results_path.write_text(json.dumps(results, indent=1) + "\n")
    plot(results, figure_path)
    s = results["summary"]
    for name, row in s["coverage"].items():
        c = row["q05_q95"]
        lo, hi = c["interval90"]
        print(
            f"{name:28s} {c['covered']:4d}/{row['objects']:<4d} {c['coverage']:.3f} "
            f"[{lo:.3f}, {hi:.3f}]  MAE {row['mae']:.3f}"
        )
    print(f"goal: {json.dumps(s['goal'])}")
    print(f"seconds per object: median {s['seconds']['median']:.1f}, max {s['seconds']['max']:.1f}")
    return results


if __name__ == "__main__":
    main()

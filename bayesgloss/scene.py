"""The paper's scene and other configured scenes: site, day, object, camera, sky.

Love & Efford (sec. 4): a tessellated hemisphere on a ground plane at
latitude 40 N, longitude 0; cameras west, south-west, south, south-east and
east; 19 frames hourly from 04:00 to 22:00 local solar time; Radiance plastic
and metal of specularity 0, 0.5, 1.0 and roughness 0 under CIE clear and
intermediate skies with sun. The paper gives no date, object size, camera
distance or material colour; bayesgloss documents its choices here:
21 June 1996 (a summer solstice, so the sun's path is longest), a hemisphere
of radius 1 m in 6 rings of 16 facets, cameras 10 m away at 2 m height, grey
material colour 0.5, ground reflectance 0.2 (gensky's default).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from . import geometry, render, sky, sun

__all__ = ["PAPER", "Sequence", "paper_sequence", "plastic_radiance", "seen_geometry"]

#: The paper's scene, with bayesgloss's documented choices where it is silent.
PAPER = {
    "latitude": 40.0,
    "longitude": 0.0,
    "date": "1996-06-21",
    "solar_hours": np.arange(4.0, 23.0),
    "radius": 1.0,
    "n_rings": 6,
    "n_segments": 16,
    "camera_distance": 10.0,
    "camera_height": 2.0,
    "colour": 0.5,
    "ground_reflectance": 0.2,
}


@dataclass(frozen=True)
class Sequence:
    """A configured scene over a day: what the forward model needs.

    Attributes
    ----------
    facets : geometry.Facets
    camera_position : ndarray (3,) [m]
    geometry : render.ViewGeometry
    times : pandas.DatetimeIndex (UTC)
    solar_hours : ndarray (T,) local apparent solar time [h]
    sky : bayesgloss.sky.DaylightSky
    """

    facets: geometry.Facets
    camera_position: np.ndarray
    geometry: render.ViewGeometry
    times: pd.DatetimeIndex
    solar_hours: np.ndarray
    sky: object


def paper_sequence(view: str = "W", sky_model: str = "gensky-clear", **overrides) -> Sequence:
    """The paper's hemisphere seen from one of its five views.

    Parameters
    ----------
    view : {"W", "SW", "S", "SE", "E"}
    sky_model : str
        A :func:`bayesgloss.sky.daylight` model name.
    **overrides
        Any key of :data:`PAPER`.
    """
    cfg = {**PAPER, **overrides}
    facets = geometry.tessellated_hemisphere(cfg["radius"], cfg["n_rings"], cfg["n_segments"])
    cam = geometry.camera_position(view, cfg["camera_distance"], cfg["camera_height"])
    times = sun.times_at_local_solar_time(cfg["date"], cfg["solar_hours"], cfg["longitude"])
    sun_dir = sun.sun_direction_at(times, cfg["latitude"], cfg["longitude"], refraction=False)
    day = sky.daylight(sky_model, sun_dir, ground_reflectance=cfg["ground_reflectance"])
    return Sequence(
        facets,
        cam,
        render.view_geometry(facets, cam),
        times,
        np.asarray(cfg["solar_hours"], float),
        day,
    )


def plastic_radiance(
    seq: Sequence,
    specularity: float,
    colour: float = PAPER["colour"],
    kind: str = "plastic",
    **kwargs,
) -> np.ndarray:
    """Radiance toward the camera of the sequence's facets made of a Radiance
    material of roughness 0, (F, T) [W sr^-1 m^-2]."""
    return render.radiance_material_prediction(
        seq.geometry, seq.sky, kind, colour, specularity, 0.0, **kwargs
    )


def seen_geometry(seq: Sequence, min_cos_view: float = 0.1) -> render.ViewGeometry:
    """The view geometry of the facets the camera sees at more than a grazing
    angle (cos of the view angle above ``min_cos_view``) [-]."""
    g = seq.geometry
    seen = g.cos_view > min_cos_view
    return render.ViewGeometry(g.normal[seen], g.view_direction[seen], g.center[seen], g.occluder)

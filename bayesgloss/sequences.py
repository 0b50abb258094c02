"""Test sequences rendered with the real Radiance, written as sequence bundles.

A :class:`SequenceConfig` says everything about one sequence: site, day and
frame times, object, camera, material, sky, ground, image size and Radiance's
ambient settings. :func:`render_bundles` renders any number of them:

- configurations that differ only in the camera share one scene per frame,
  and one ``rtrace`` process traces all their cameras' pixels, so Radiance's
  irradiance cache is shared between views;
- frames render in parallel (``jobs`` processes of ``rtrace``);
- each bundle is written atomically into ``cache_dir/<name>-<hash>/``, the
  hash being that of its configuration, so a finished bundle is never
  rendered again and an interrupted run resumes where it stopped.

Images are traced with ``rtrace`` on bayesgloss's own pinhole camera rays
(through OpenCV's lens distortion where the config gives one:
:func:`opencv_camera`, each pixel's points undistorted by
:func:`bayesgloss.camera_model.camera_rays`), so the image and the facet
label pass use exactly the same rays. A pixel is
labelled with a facet only when its centre and its four corners all hit that
facet (wholly inside); the other pixels are background (0).

The sun of every frame is bayesgloss's SPA position (apparent, as the bundle
reader computes it), handed to ``gensky -ang`` or ``gendaylit -ang``.

Skies
-----
``gensky-*``: the real ``gensky -ang`` (clear and intermediate with sun,
overcast, uniform). ``perez``: the real ``gendaylit -ang ... -W DNI DHI``
with each frame's irradiances (``dni``, ``dhi``; pvlib's Ineichen-Perez
clear sky at ``linke_turbidity`` where not given). ``cie-1`` ... ``cie-15``:
the pyradiance build of gensky makes only the clear, intermediate,
overcast and uniform skies (no CIE general skies, no ``-r``), so the 15 CIE
standard general skies (ISO 15469:2004) are written as a Radiance
``brightfunc`` of :data:`CIE_CAL` (the formula of
:func:`bayesgloss.sky.cie_general`, evaluated by Radiance per ray) scaled
exactly as ``bayesgloss.sky.daylight("cie-N")`` scales it (the sky's
horizontal irradiance equals the diffuse horizontal illuminance / 179 from
``dni``, ``dhi`` through gendaylit's efficacy models), plus a solar
``source`` of 0.533 deg with that model's beam radiance (types 6-15; types
1-5 have no sun) and its ground radiance below the horizon.

Camera
------
After rendering, each frame is multiplied by its ``exposure`` gain (given,
or "auto": inverse to the frame's mean luminance, times a log-normal
jitter), given relative Gaussian ``sensor_noise`` (a generator seeded by the
configuration's hash), and, for every ``pixel_encoding`` but
``linear-radiance``, divided by the encoding's white, clipped to [0, 1]
(highlights at the top code: saturated) and encoded (``linear``, ``srgb``,
``gamma:G``) as 8- or 16-bit PNG. The white is ``white_scale`` times the
99th percentile of the exposed, noise-free channel values of the frames
with the sun up, one white for the whole sequence (a sensor's full well
after its gain). The gains are written as ``frames[].exposure`` only for
``linear-radiance``, where pixel = exposure x radiance; with any other
encoding they are left out, so an estimator must treat exposure as unknown
(the bundle spec). ``truth`` holds everything: sky, irradiances, gains,
white, encoding, colour luminance and the true gloss.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import re
import shutil
import sys
import tempfile
import time
import warnings
from concurrent.futures import ThreadPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from . import geometry, images, radiance, reflectance, sky, sun

__all__ = [
    "SequenceConfig",
    "SKIES",
    "SHAPES",
    "CIE_CAL",
    "paper_configs",
    "render_bundles",
    "RenderWarning",
    "warn_lambertian_indirect_gloss",
    "RTRACE_SPECULAR_THRESHOLD",
    "camera_rays",
    "opencv_camera",
    "label_image",
    "camera_response",
    "auto_exposure",
    "DEFAULT_AMBIENT",
    "TRACED_SPECULAR_AMBIENT",
]

#: A sequence's name: it names the bundle's folder under ``--out``.
NAME_PATTERN = r"[A-Za-z0-9_-][A-Za-z0-9._-]{0,127}"
#: rtrace's ambient and sampling options a config may set (each with a
#: number), and its switches; nothing else reaches rtrace's command line
#: (``-e FILE`` once made rtrace write a file anywhere).
AMBIENT_OPTIONS = (
    "-ab", "-aa", "-ar", "-ad", "-as", "-lr", "-lw", "-dj", "-ds", "-dt", "-dc", "-st", "-ss"
)  # fmt: skip
AMBIENT_SWITCHES = ("-u-", "-u+", "-u")

#: rtrace settings for the test sequences: two bounces (facet -> ground ->
#: sky), irradiance cache at 10 % accuracy with a resolution fine for the
#: 40 m scene (-ar 512: 8 cm), 512 stratified samples, repeatable sampling.
#: rtrace's specular threshold stays at its default, ``-st 0.15``: Radiance's
#: ``normal.c`` then sets SP_RBLT on a rough (roughness > 0) material of
#: specularity <= 0.15, skips its specular sampling (``gaussamp``) and
#: reflects all indirect light (sky, ground) through the diffuse ambient with
#: the full material colour: the sky's glossy reflection becomes Lambertian
#: and only the sun keeps its lobe. Real surfaces do not do that; see
#: :data:`TRACED_SPECULAR_AMBIENT`. (Kept as the default so far because the
#: settings are part of every config's hash, which seeds its noise.)
DEFAULT_AMBIENT = (
    "-ab",
    "2",
    "-aa",
    "0.1",
    "-ar",
    "512",
    "-ad",
    "512",
    "-as",
    "256",
    "-lr",
    "6",
    "-lw",
    "1e-4",
    "-u-",
)

#: :data:`DEFAULT_AMBIENT` with ``-st 0``: every rough specular reflection
#: traced, so the sky's and ground's glossy reflections keep their lobe at
#: any specularity (measured in ``tests/test_reflectance.py``). For new
#: validation sets.
TRACED_SPECULAR_AMBIENT = (*DEFAULT_AMBIENT, "-st", "0")

#: rtrace's specular sampling threshold where ``-st`` is not given [-].
RTRACE_SPECULAR_THRESHOLD = 0.15

#: Sky names of :class:`SequenceConfig` (``cie-N``: the CIE standard general skies).
SKIES = (
    "gensky-clear",
    "gensky-intermediate",
    "gensky-overcast",
    "gensky-uniform",
    "perez",
    *(f"cie-{t}" for t in range(1, 16)),
)
SHAPES = ("hemisphere", "box", "gem", "mesh")
#: Integer pixel encodings and their default bit depth.
_ENCODING_BITS = {"linear": 16, "srgb": 8, "gamma": 16}
#: "auto" exposure: the gain is at most this many times the reference gain [-].
AUTO_EXPOSURE_RANGE = 100.0

#: Radiance function file of the CIE standard general sky (ISO 15469:2004 /
#: CIE S 011/E:2003 eq. 3, 5 and 7), the formula of :func:`bayesgloss.sky.cie_general`.
#: Arguments: A1 zenith radiance, A2 ground radiance [W sr^-1 m^-2], A3-A5 sun
#: direction, A6-A10 the standard's a, b, c, d, e.
CIE_CAL = """{ CIE standard general sky, ISO 15469:2004 eq. 7, from bayesgloss.sequences }
{ A1 zenith radiance, A2 ground radiance, A3 A4 A5 sun direction, A6..A10 a b c d e }
cosgamma = Dx*A3 + Dy*A4 + Dz*A5;
chi = Acos(cosgamma);
zsun = Acos(A5);
gradation(cz) = 1 + if(cz, A6*Exp(A7/if(cz - 1e-9, cz, 1e-9)), 0);
indicatrix(x) = 1 + A8*(Exp(A9*x) - Exp(A9*PI/2)) + A10*cos(x)*cos(x);
ciesky = A1*indicatrix(chi)*gradation(Dz) / (indicatrix(zsun)*(1 + A6*Exp(A7)));
skybright = if(Dz, ciesky, A2);
"""

#: Fields added after the first bundles were cached, with their defaults: a
#: field at its default is left out of :meth:`SequenceConfig.key`, so the
#: hashes (and cached bundles) of older configurations stay the same.
_LATER_DEFAULTS = {
    "gem_stand": "culet",
    "gem_azimuth": 0.0,
    "dni": None,
    "dhi": None,
    "exposure": None,
    "exposure_jitter": 0.0,
    "pixel_encoding": "linear-radiance",
    "bit_depth": None,
    "sensor_noise": 0.0,
    "white_scale": 1.0,
    "mesh_file": None,
    "mesh_facet_angle": 10.0,
    "distortion": None,
}
#: Later fields that :meth:`SequenceConfig.to_dict` leaves out at their default,
#: so that the configs (and bundle truths) written before they existed compare equal.
_OMITTED_AT_DEFAULT = ("mesh_file", "mesh_facet_angle", "distortion")
#: Fields that change only what is done to the rendered frames, not the scene.
_CAMERA_FIELDS = (
    "view",
    "camera_distance",
    "camera_height",
    "image_size",
    "exposure",
    "exposure_jitter",
    "pixel_encoding",
    "bit_depth",
    "sensor_noise",
    "white_scale",
    "distortion",
)


@dataclass(frozen=True)
class SequenceConfig:
    """One test sequence. Every field has a documented default (the paper's scene).

    Site and time: ``latitude``, ``longitude`` (deg, east positive),
    ``elevation`` (m); frames at ``solar_hours`` (local apparent solar time,
    h) on ``date``, or at ``times`` (ISO 8601 with UTC offsets) when given.
    Object: ``shape`` ("hemisphere": ``radius``, ``n_rings``, ``n_segments``;
    "box": ``box_size`` (x, y, z) m, standing on the ground, turned by
    ``box_azimuth`` deg; "gem": :func:`bayesgloss.geometry.gem` of girdle
    radius ``radius`` m standing on ``gem_stand`` ("culet" or "table"),
    turned by ``gem_azimuth`` deg; "mesh": the triangle mesh of the OBJ or PLY
    ``mesh_file`` in the world frame, e.g. a non-convex
    :func:`bayesgloss.geometry.l_building` written by
    :func:`bayesgloss.geometry.write_obj`, its facets the near-planar regions
    within ``mesh_facet_angle`` deg (:func:`bayesgloss.capture.mesh_facets`),
    the file copied into the bundle as its ``object_mesh``; hashed by content).
    Camera: ``view`` (a paper view name or
    bearing in degrees), ``camera_distance`` and ``camera_height`` (m),
    square image of ``image_size`` pixels framing the object, through a lens
    of OpenCV ``distortion`` (k1, k2, p1, p2[, k3]) where given
    (:func:`opencv_camera`). Material:
    Radiance ``material`` ("plastic" or "metal"), ``colour`` (grey float or
    RGB triple, each in [0, 1]), ``specularity``, ``roughness``.
    Sky: ``sky`` (one of :data:`SKIES`), gensky's ``turbidity``, the clear
    sky's ``linke_turbidity``; for "perez" and "cie-N", per-frame ``dni`` and
    ``dhi`` (W m^-2, one per frame; None: pvlib's clear sky). Ground:
    ``ground_reflectance`` and a disc of ``ground_radius`` m (beyond it, the
    sky description's ground glow). ``ambient``: rtrace options.

    Camera response (applied to the rendered frames, module docstring):
    ``exposure`` (per-frame gains [-], or "auto" with log-normal
    ``exposure_jitter`` sd [-]), ``pixel_encoding`` ("linear-radiance",
    "linear", "srgb" or "gamma:G"), ``bit_depth`` (8 or 16; None: 8 for
    srgb, 16 for linear and gamma), ``sensor_noise`` (relative Gaussian sd on
    linear values [-]), ``white_scale`` (the white, the linear value of the top
    code, as a multiple of the sequence's 99th percentile [-]).
    ``category``: a label for scoring sets by kind (e.g. "broken-cloud"),
    written to ``truth``; like ``name`` it is not hashed.
    """

    name: str = "sequence"
    latitude: float = 40.0
    longitude: float = 0.0
    elevation: float = 0.0
    date: str = "1996-06-21"
    solar_hours: tuple = tuple(float(h) for h in range(4, 23))
    times: tuple | None = None
    shape: str = "hemisphere"
    radius: float = 1.0
    n_rings: int = 6
    n_segments: int = 16
    box_size: tuple = (1.0, 1.0, 1.0)
    box_azimuth: float = 0.0
    view: str | float = "W"
    camera_distance: float = 10.0
    camera_height: float = 2.0
    image_size: int = 128
    material: str = "plastic"
    colour: float = 0.5
    specularity: float = 0.0
    roughness: float = 0.0
    sky: str = "gensky-clear"
    turbidity: float = 2.45
    linke_turbidity: float = 3.0
    ground_reflectance: float = 0.2
    ground_radius: float = 20.0
    ambient: tuple = field(default=DEFAULT_AMBIENT)
    gem_stand: str = "culet"
    gem_azimuth: float = 0.0
    dni: tuple | None = None
    dhi: tuple | None = None
    exposure: tuple | str | None = None
    exposure_jitter: float = 0.0
    pixel_encoding: str = "linear-radiance"
    bit_depth: int | None = None
    sensor_noise: float = 0.0
    white_scale: float = 1.0
    category: str | None = None
    mesh_file: str | None = None
    mesh_facet_angle: float = 10.0
    distortion: tuple | None = None

    def __post_init__(self):
        problems = self._input_problems()
        if problems:  # the checks below need the right types
            raise ValueError(f"sequence config {str(self.name)[:80]!r}: " + "; ".join(problems))
        if not -90 <= self.latitude <= 90:
            problems.append(f"latitude {self.latitude} outside [-90, 90]")
        if not -180 <= self.longitude <= 180:
            problems.append(f"longitude {self.longitude} outside [-180, 180]")
        if self.shape not in SHAPES:
            problems.append(f"shape {self.shape!r} not one of {', '.join(SHAPES)}")
        if self.sky not in SKIES:
            problems.append(f"sky {self.sky!r} not one of {', '.join(SKIES)}")
        if self.material not in reflectance.MATERIAL_KINDS:
            problems.append(f"material {self.material!r} not one of plastic, metal")
        if not 0 <= self.specularity <= 1:
            problems.append(f"specularity {self.specularity} outside [0, 1]")
        colour = np.asarray(self.colour, dtype=float)
        if colour.shape not in ((), (3,)) or not np.all((colour >= 0) & (colour <= 1)):
            problems.append(f"colour {self.colour} not a float or RGB triple in [0, 1]")
        if not 8 <= self.image_size <= 4096:
            problems.append(f"image_size {self.image_size} outside [8, 4096]")
        problems += self._mesh_problems()
        if self.gem_stand not in ("culet", "table"):
            problems.append(f"gem_stand {self.gem_stand!r} not one of culet, table")
        problems += self._frame_problems() + self._camera_problems()
        if problems:
            raise ValueError(f"sequence config {self.name!r}: " + "; ".join(problems))

    def _input_problems(self) -> list[str]:
        """Types and forms a hand-written config may get wrong: the name a
        plain file name (it names the bundle's folder), the frame times a
        list, each time with its UTC offset, ambient settings from
        :data:`AMBIENT_OPTIONS` with numeric values, the image size an
        integer."""
        problems = []
        if not isinstance(self.name, str) or not re.fullmatch(NAME_PATTERN, self.name):
            problems.append(
                f"name {str(self.name)[:80]!r} is not a plain name (letters, digits, '.', '_', "
                "'-', not starting with '.'; it names the bundle's folder)"
            )
        if isinstance(self.image_size, bool) or not isinstance(self.image_size, int):
            problems.append(f"image_size {self.image_size!r} is not an integer")
        if self.times is not None:
            if not isinstance(self.times, tuple) or not self.times:
                problems.append(f"times {self.times!r} is not a non-empty list of times")
            else:
                for t in self.times:
                    try:
                        naive = pd.Timestamp(t).tzinfo is None
                    except (ValueError, TypeError):
                        problems.append(f"times: {t!r} is not an ISO 8601 time")
                        break
                    if naive:
                        problems.append(f"times: {t!r} has no UTC offset")
                        break
        else:
            hours = self.solar_hours
            if not isinstance(hours, tuple) or not hours:
                problems.append(f"solar_hours {hours!r} is not a non-empty list of hours")
            elif not all(
                isinstance(h, int | float) and not isinstance(h, bool) and 0 <= h <= 24
                for h in hours
            ):
                problems.append(f"solar_hours {hours!r} are not all numbers in [0, 24]")
        options = self.ambient
        if not isinstance(options, tuple) or len(options) % 2 and "-u-" not in options:
            problems.append(f"ambient {options!r} is not a list of rtrace options")
        else:
            items = [o for o in options if o not in AMBIENT_SWITCHES]
            for opt, value in zip(items[::2], items[1::2], strict=False):
                if opt not in AMBIENT_OPTIONS:
                    problems.append(
                        f"ambient option {str(opt)[:40]!r} is not one of "
                        f"{', '.join(AMBIENT_OPTIONS + AMBIENT_SWITCHES)}"
                    )
                    break
                try:
                    float(value)
                except (TypeError, ValueError):
                    problems.append(f"ambient option {opt} needs a number, got {value!r}")
                    break
            if len(items) % 2:
                problems.append(f"ambient option {items[-1]!r} has no value")
        return problems

    def _mesh_problems(self) -> list[str]:
        """Shape "mesh" needs a mesh file that exists; a distortion is 4 or 5 numbers."""
        problems = []
        if (self.shape == "mesh") != (self.mesh_file is not None):
            problems.append(f"mesh_file goes with shape 'mesh' (shape {self.shape!r}, "
                            f"mesh_file {self.mesh_file!r})")  # fmt: skip
        elif self.mesh_file is not None and Path(self.mesh_file).suffix.lower() not in (
            ".obj",
            ".ply",
        ):
            problems.append(f"mesh_file {self.mesh_file!r} is not an OBJ or PLY file")
        elif self.mesh_file is not None and not Path(self.mesh_file).is_file():
            problems.append(f"mesh_file {self.mesh_file!r}: no such file")
        if not 0 < self.mesh_facet_angle < 90:
            problems.append(f"mesh_facet_angle {self.mesh_facet_angle} outside (0, 90) deg")
        if self.distortion is not None:
            d = np.asarray(self.distortion, dtype=float)
            if d.shape not in ((4,), (5,)) or not np.all(np.isfinite(d)):
                problems.append(f"distortion {self.distortion} is not k1, k2, p1, p2[, k3]")
        return problems

    def _frame_problems(self) -> list[str]:
        n = self.n_frames
        problems = []
        for name in ("dni", "dhi"):
            values = getattr(self, name)
            if values is None:
                continue
            if not (self.sky == "perez" or self.sky.startswith("cie-")):
                problems.append(f"{name} given for sky {self.sky!r} (only perez and cie-N)")
            arr = np.asarray(values, dtype=float)
            if arr.shape != (n,) or not np.all(np.isfinite(arr) & (arr >= 0)):
                problems.append(f"{name} needs {n} finite values >= 0 (one a frame), got {values}")
        if isinstance(self.exposure, str):
            if self.exposure != "auto":
                problems.append(f"exposure {self.exposure!r} not 'auto' or per-frame gains")
        elif self.exposure is not None:
            arr = np.asarray(self.exposure, dtype=float)
            if arr.shape != (n,) or not np.all(np.isfinite(arr) & (arr > 0)):
                problems.append(f"exposure needs {n} gains > 0 (one a frame), got {self.exposure}")
        return problems

    def _camera_problems(self) -> list[str]:
        problems = []
        try:
            name, _ = images.parse_pixel_encoding(self.pixel_encoding)
        except ValueError as err:
            return [str(err)]
        if name == "unknown":
            problems.append("pixel_encoding 'unknown' cannot be rendered")
        elif name == "linear-radiance" and self.bit_depth is not None:
            problems.append("bit_depth must be None for linear-radiance (float Radiance pictures)")
        if self.bit_depth not in (None, 8, 16):
            problems.append(f"bit_depth {self.bit_depth} not 8 or 16")
        if not (np.isfinite(self.sensor_noise) and self.sensor_noise >= 0):
            problems.append(f"sensor_noise {self.sensor_noise} not >= 0")
        if not (np.isfinite(self.exposure_jitter) and self.exposure_jitter >= 0):
            problems.append(f"exposure_jitter {self.exposure_jitter} not >= 0")
        if not (np.isfinite(self.white_scale) and self.white_scale > 0):
            problems.append(f"white_scale {self.white_scale} not > 0")
        return problems

    @property
    def n_frames(self) -> int:
        """Number of frames [-]."""
        return len(self.times) if self.times is not None else len(self.solar_hours)

    @classmethod
    def from_dict(cls, values: dict) -> SequenceConfig:
        """A configuration from a JSON-like dict; unknown keys are an error."""
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise ValueError(
                f"unknown sequence config field(s): {', '.join(unknown)}; "
                f"valid: {', '.join(sorted(known))}"
            )
        tuples = {"solar_hours", "times", "box_size", "ambient", "dni", "dhi", "colour", "exposure"}
        tuples.add("distortion")
        clean = {
            k: (tuple(v) if k in tuples and isinstance(v, list | tuple) else v)
            for k, v in values.items()
        }
        return cls(**clean)

    def to_dict(self) -> dict:
        """The fields as a JSON-like dict; :data:`_OMITTED_AT_DEFAULT` only where set."""
        d = dataclasses.asdict(self)
        for k in _OMITTED_AT_DEFAULT:
            if d[k] == _LATER_DEFAULTS[k]:
                d.pop(k)
        return d

    def _hashed(self) -> dict:
        """The fields without the name, the category and later fields at their default."""
        d = dataclasses.asdict(self)
        d.pop("name")
        d.pop("category")
        for k, default in _LATER_DEFAULTS.items():
            if d[k] == default:
                d.pop(k)
        if "mesh_file" in d:  # the mesh's content, wherever the file lies
            d["mesh_file"] = hashlib.sha256(Path(self.mesh_file).read_bytes()).hexdigest()
        return d

    def key(self) -> str:
        """Hash of everything that changes the rendered bundle (not the name)."""
        d = self._hashed()
        d["renderer"] = _renderer_version()
        return hashlib.sha256(json.dumps(d, sort_keys=True).encode()).hexdigest()[:12]

    def scene_key(self) -> str:
        """Hash of the scene only: configs sharing it differ only in the camera."""
        d = self._hashed()
        for k in _CAMERA_FIELDS:
            d.pop(k, None)
        return hashlib.sha256(json.dumps(d, sort_keys=True).encode()).hexdigest()[:12]

    # -- derived scene quantities ------------------------------------------

    def facets(self) -> geometry.Facets:
        """The object's facets; for shape "mesh" the near-planar regions of
        ``mesh_file`` within ``mesh_facet_angle`` (:func:`bayesgloss.capture.mesh_facets`,
        ids = region + 1), without polygons (its triangles: :meth:`object_triangles`)."""
        if self.shape == "mesh":
            region, normal, center, _ = self._mesh_regions()
            return geometry.Facets(np.arange(1, len(normal) + 1), normal, center)
        if self.shape == "hemisphere":
            return geometry.tessellated_hemisphere(self.radius, self.n_rings, self.n_segments)
        if self.shape == "gem":
            return geometry.gem(self.radius, stand=self.gem_stand, azimuth=self.gem_azimuth)
        return geometry.box(self.box_size, self.box_azimuth)

    def _mesh_regions(self):
        from .capture import load_mesh, mesh_facets

        mesh, group = load_mesh(self.mesh_file)
        region, normal, center, area = mesh_facets(mesh, group, self.mesh_facet_angle)
        return region, normal, center, np.asarray(mesh.triangles, dtype=float)

    def object_triangles(self, facets: geometry.Facets | None = None):
        """The object's surface as polygons and the facet id of each.

        Parameters
        ----------
        facets : Facets, optional
            :meth:`facets`, when already made.

        Returns
        -------
        polygons : list of ndarray (V, 3)
            The facets' polygons, or for shape "mesh" the mesh's triangles [m].
        ids : ndarray of int
            The facet of each polygon [-].
        """
        if self.shape == "mesh":
            region, _, _, tris = self._mesh_regions()
            return list(tris), region + 1
        facets = self.facets() if facets is None else facets
        return list(facets.polygons), np.asarray(facets.ids)

    def camera_position(self) -> np.ndarray:
        return geometry.camera_position(self.view, self.camera_distance, self.camera_height)

    def frame_times(self) -> pd.DatetimeIndex:
        if self.times is not None:
            return pd.DatetimeIndex([pd.Timestamp(t) for t in self.times]).tz_convert("UTC")
        return sun.times_at_local_solar_time(
            self.date, np.asarray(self.solar_hours), self.longitude, self.latitude
        )

    def sun_directions(self) -> np.ndarray:
        return sun.sun_direction_at(
            self.frame_times(), self.latitude, self.longitude, self.elevation
        )

    def colour_luminance(self) -> float:
        """Luminance of the colour, 0.265 R + 0.670 G + 0.065 B (a grey is itself) [-]."""
        if np.ndim(self.colour) == 0:
            return float(self.colour)
        return float(reflectance.luminance_rgb(np.asarray(self.colour, dtype=float)))

    def irradiances(self) -> tuple[np.ndarray, np.ndarray] | None:
        """Per-frame DNI and DHI handed to the sky (perez, cie-N), else None [W m^-2].

        Values not given in ``dni``/``dhi`` are pvlib's Ineichen-Perez clear
        sky at ``linke_turbidity`` (0 with the sun down), for the day of the
        first frame.
        """
        if not (self.sky == "perez" or self.sky.startswith("cie-")):
            return None
        day = int(self.frame_times()[0].day_of_year)
        clear_dni, clear_dhi = sky.clear_sky_irradiance(
            self.sun_directions(), day, self.linke_turbidity
        )
        dni = clear_dni if self.dni is None else np.asarray(self.dni, dtype=float)
        dhi = clear_dhi if self.dhi is None else np.asarray(self.dhi, dtype=float)
        return dni, dhi

    def truth(self) -> dict:
        """What made the scene: material, colour, sky, the true gloss and the config.

        The keys are those of the first bundles (saved results compare them);
        :meth:`bundle_truth` adds the rest.
        """
        return {
            "material": self.material,
            "colour": self.colour,
            "specularity": self.specularity,
            "roughness": self.roughness,
            "sky": self.sky,
            "renderer": "radiance",
            "gloss": float(
                reflectance.gloss_of_radiance_material(
                    self.material, self.specularity, self.colour_luminance()
                )
            ),
            "config": self.to_dict(),
        }

    def bundle_truth(self) -> dict:
        """:meth:`truth` and everything else written to a bundle's ``truth``:
        category, shape, colour luminance, per-frame DNI and DHI (perez and
        cie-N), pixel encoding, bit depth and sensor noise (the exposure gains
        and the white are added when the frames are written)."""
        irr = self.irradiances()
        name, _ = images.parse_pixel_encoding(self.pixel_encoding)
        return {
            **self.truth(),
            "category": self.category if self.category is not None else self.sky,
            "shape": self.shape,
            "colour_luminance": self.colour_luminance(),
            "dni": None if irr is None else [float(v) for v in irr[0]],
            "dhi": None if irr is None else [float(v) for v in irr[1]],
            "pixel_encoding": self.pixel_encoding,
            "bit_depth": None if name == "linear-radiance" else self._bit_depth(),
            "sensor_noise": self.sensor_noise,
            "lambertian_indirect_gloss": self.lambertian_indirect_gloss(),
        }

    def specular_threshold(self) -> float:
        """rtrace's ``-st`` in :attr:`ambient` (the last one given), else
        :data:`RTRACE_SPECULAR_THRESHOLD`."""
        options = list(self.ambient)
        values = [options[i + 1] for i, o in enumerate(options[:-1]) if o == "-st"]
        return float(values[-1]) if values else RTRACE_SPECULAR_THRESHOLD

    def lambertian_indirect_gloss(self) -> bool:
        """Whether Radiance renders this material's reflection of the sky,
        the ground and the object itself as Lambertian.

        Radiance's ``normal.c`` sets SP_RBLT on a rough material (roughness
        > 0) whose specularity is at most the specular threshold
        (``specthresh >= rspec - FTINY``): it then skips the specular
        sampling of indirect light and reflects all of it through the
        diffuse ambient with the full material colour. Only light sources
        (the sun) keep the glossy lobe, so the images show less gloss than
        the material's true gamma says.
        """
        rough = self.roughness > 0 and self.specularity > 0
        return bool(rough and self.specular_threshold() >= self.specularity - 1e-9)

    def _bit_depth(self) -> int:
        name, _ = images.parse_pixel_encoding(self.pixel_encoding)
        return self.bit_depth if self.bit_depth is not None else _ENCODING_BITS[name]


def _renderer_version() -> str:
    from . import __version__

    return f"bayesgloss-{__version__}"


def paper_configs(image_size: int = 128, **overrides) -> list[SequenceConfig]:
    """The paper's 60 sequences: 5 views x plastic/metal x specularity 0, 0.5, 1
    x CIE clear and intermediate skies with sun (Love & Efford, sec. 4)."""
    out = []
    for sky_name in ("gensky-clear", "gensky-intermediate"):
        for kind in ("plastic", "metal"):
            for spec in (0.0, 0.5, 1.0):
                for view in geometry.CAMERA_AZIMUTHS:
                    name = f"paper-{view}-{kind}-{spec:g}-{sky_name.split('-')[1]}"
                    out.append(
                        SequenceConfig(
                            name=name,
                            view=view,
                            material=kind,
                            specularity=spec,
                            sky=sky_name,
                            image_size=image_size,
                            **overrides,
                        )
                    )
    return out


# -- camera and labels ---------------------------------------------------------


def _camera_frame(config: SequenceConfig, facets: geometry.Facets):
    """Camera position, look direction, right and up vectors, tan of half the FOV."""
    verts = np.concatenate(config.object_triangles(facets)[0])
    lo, hi = verts.min(0), verts.max(0)
    target = 0.5 * (lo + hi)
    bound = 0.5 * np.linalg.norm(hi - lo)  # bounding-sphere radius about the centre
    cam = config.camera_position()
    fwd = target - cam
    dist = np.linalg.norm(fwd)
    fwd /= dist
    right = np.cross(fwd, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    tan_half = 1.08 * bound / np.sqrt(max(dist**2 - bound**2, 1e-9))  # 8 % margin
    return cam, fwd, right, up, tan_half


def opencv_camera(config: SequenceConfig, facets: geometry.Facets | None = None):
    """The configured camera as OpenCV's model (:class:`bayesgloss.camera_model.Camera`).

    The renderer's pinhole framing the object (square, ``image_size``
    pixels): f = n / (2 tan(half field of view)), the principal point at the
    image's centre ((n - 1) / 2 in OpenCV's pixel coordinates), R's rows the
    image's right, down and forward axes; with ``distortion`` (k1, k2, p1,
    p2[, k3]) as its lens distortion. What ``bundle make``'s camera file
    holds for frames rendered with this configuration.
    """
    from .camera_model import Camera

    facets = config.facets() if facets is None else facets
    cam, fwd, right, up, tan_half = _camera_frame(config, facets)
    n = config.image_size
    f = n / (2 * tan_half)
    distortion = np.zeros(5)
    if config.distortion is not None:
        distortion[: len(config.distortion)] = config.distortion
    rotation = np.stack([right, -up, fwd])
    c = (n - 1) / 2
    return Camera(n, n, f, f, c, c, distortion, rotation, np.asarray(cam, dtype=float))


def camera_rays(config: SequenceConfig, facets: geometry.Facets, corners: bool = False):
    """Pinhole rays through pixel centres (or the pixel grid's corners).

    Returns origins and unit directions, shape (H*W, 3) with rows top to
    bottom, or ((H+1)*(W+1), 3) for corners. With ``distortion`` the rays
    are those of :func:`opencv_camera` through its lens
    (:func:`bayesgloss.camera_model.camera_rays`: each pixel point
    undistorted), so the frames are what that distorted camera sees.

    Raises
    ------
    ValueError
        A distortion that cannot be inverted at some pixel of the image.
    """
    if config.distortion is not None:
        from . import camera_model

        camera = opencv_camera(config, facets)
        n = config.image_size
        grid = np.arange(n + 1) - 0.5 if corners else np.arange(n, dtype=float)
        u, v = np.meshgrid(grid, grid)
        d = camera_model.camera_rays(camera, u, v).reshape(-1, 3)
        if not np.all(np.isfinite(d)):
            raise ValueError(
                f"sequence config {config.name!r}: distortion {config.distortion} cannot be "
                "inverted at some pixels of the image (too strong for the field of view)"
            )
        return np.broadcast_to(camera.position, d.shape), d
    cam, fwd, right, up, tan_half = _camera_frame(config, facets)
    n = config.image_size
    grid = np.arange(n + 1) if corners else np.arange(n) + 0.5
    x = (grid / n * 2 - 1) * tan_half
    y = (1 - grid / n * 2) * tan_half
    d = fwd + x[None, :, None] * right + y[:, None, None] * up
    d = (d / np.linalg.norm(d, axis=-1, keepdims=True)).reshape(-1, 3)
    return np.broadcast_to(cam, d.shape), d


def label_image(config: SequenceConfig, facets: geometry.Facets) -> np.ndarray:
    """Facet label image (H, W): facet id where the pixel lies wholly inside it, else 0."""
    scene = "".join(radiance.material(f"f{i}", "plastic", 0.5, 0.0, 0.0) for i in facets.ids)
    polygons, owner = config.object_triangles(facets)
    if config.shape == "mesh":  # a facet of many triangles: one name a triangle
        scene += radiance.polygons(polygons, [f"f{i}" for i in owner], prefix="tri")
    else:
        scene += "".join(
            radiance.polygons([p], f"f{i}", prefix=f"poly{i}_")
            for i, p in zip(owner, polygons, strict=True)
        )
    n = config.image_size
    oc, dc = camera_rays(config, facets, corners=False)
    ok, dk = camera_rays(config, facets, corners=True)
    rays = np.concatenate([np.concatenate([oc, dc], 1), np.concatenate([ok, dk], 1)])
    with radiance.scratch_folder("label") as tmp:
        octree = radiance.oconv(scene, Path(tmp) / "labels.oct")
        out = radiance.run(
            ["rtrace", "-h-", "-ff", "-om", "-ab", "0", str(octree)],
            input=rays.astype(np.float32).tobytes(),
        )
    names = out.decode().split()
    ids = np.array([int(s[1:]) if s.startswith("f") else 0 for s in names])
    centre = ids[: n * n].reshape(n, n)
    corner = ids[n * n :].reshape(n + 1, n + 1)
    whole = (
        (corner[:-1, :-1] == centre)
        & (corner[:-1, 1:] == centre)
        & (corner[1:, :-1] == centre)
        & (corner[1:, 1:] == centre)
    )
    return np.where(whole, centre, 0)


# -- scene text ----------------------------------------------------------------


def _sky_text(config: SequenceConfig, frame: int, sun_direction: np.ndarray, day: int) -> str:
    """Radiance description of frame ``frame``'s sky (and sun)."""
    if config.sky.startswith("gensky-"):
        return radiance.gensky_ang(
            sun_direction,
            config.sky.split("-", 1)[1],
            ground_reflectance=config.ground_reflectance,
            turbidity=config.turbidity,
        )
    dni, dhi = (float(v[frame]) for v in config.irradiances())
    if config.sky == "perez":
        return radiance.gendaylit_ang(
            sun_direction, dni, dhi, ground_reflectance=config.ground_reflectance
        )
    return _cie_sky_text(config.sky, sun_direction, dni, dhi, day, config.ground_reflectance)


def _cie_sky_text(
    model: str, sun_direction, dni: float, dhi: float, day: int, ground_reflectance: float
) -> str:
    """A CIE general sky as :func:`bayesgloss.sky.daylight` defines it, in Radiance text.

    Parameters
    ----------
    model : str
        "cie-1" ... "cie-15".
    sun_direction : array_like (3,)
        Unit vector toward the sun, world frame [-].
    dni, dhi : float
        Direct normal and diffuse horizontal irradiance [W m^-2].
    day : int
        Day of the year [-].
    ground_reflectance : float
        [-]
    """
    s = np.asarray(sun_direction, dtype=float)
    day_sky = sky.daylight(
        model,
        s[None, :],
        direct_normal_irradiance=dni,
        diffuse_horizontal_irradiance=dhi,
        day_of_year=day,
        ground_reflectance=ground_reflectance,
    )
    sky_type = int(model.split("-")[1])
    gradation, indicatrix, _ = sky.CIE_SKY_TYPES[sky_type]
    a, b = sky._CIE_GRADATION[gradation]  # the standard's Table 1, as sky.cie_general reads it
    c, d, e = sky._CIE_INDICATRIX[indicatrix]
    zenith = float(day_sky.parameters.zenith_radiance[0])
    ground = float(day_sky.ground_radiance[0])
    solar = float(day_sky.solar_radiance[0])
    diameter = np.degrees(2 * np.arccos(1 - day_sky.sun_solid_angle / (2 * np.pi)))
    sun = " ".join(f"{v:.9g}" for v in s)
    args = [zenith, ground, *s, a, b, c, d, e]
    return (
        f"# {model}: bayesgloss.sky.daylight scale, DNI {dni:.6g} DHI {dhi:.6g} W m^-2\n"
        f"void light solar\n0\n0\n3 {solar:.6g} {solar:.6g} {solar:.6g}\n\n"
        f"solar source sun\n0\n0\n4 {sun} {diameter:.6g}\n\n"
        f"void brightfunc skyfunc\n2 skybright {_cie_cal_file()}\n0\n"
        f"{len(args)} " + " ".join(f"{v:.9g}" for v in args) + "\n\n"
    )


def _cie_cal_file() -> str:
    """Path of :data:`CIE_CAL` written once in the system's temporary folder."""
    digest = hashlib.sha256(CIE_CAL.encode()).hexdigest()[:12]
    path = Path(tempfile.gettempdir()) / f"bayesgloss-cie-general-{digest}.cal"
    if not path.exists() or path.read_text() != CIE_CAL:
        tmp = path.with_suffix(f".{os.getpid()}.tmp")
        tmp.write_text(CIE_CAL)
        os.replace(tmp, path)
    return str(path)


def _object_text(config: SequenceConfig, facets: geometry.Facets) -> str:
    mat = radiance.material(
        "object_material", config.material, config.colour, config.specularity, config.roughness
    )
    r = config.ground_radius
    a = np.linspace(0, 2 * np.pi, 64, endpoint=False)
    disc = np.column_stack([r * np.cos(a), r * np.sin(a), np.zeros_like(a)])
    return (
        mat
        + radiance.polygons(config.object_triangles(facets)[0], "object_material")
        + radiance.material("ground_material", "plastic", config.ground_reflectance, 0, 0)
        + radiance.polygons([disc], "ground_material", prefix="ground")
    )


# -- rendering -----------------------------------------------------------------


def _bundle_dir(cache_dir: Path, config: SequenceConfig) -> Path:
    return cache_dir / f"{config.name}-{config.key()}"


def _render_frame(scene_text: str, sky_text: str, rays: np.ndarray, ambient) -> np.ndarray:
    with radiance.scratch_folder("frame") as tmp:
        octree = radiance.oconv(
            sky_text + radiance.sky_glow(ground=True) + scene_text, Path(tmp) / "frame.oct"
        )
        return radiance.rtrace(octree, rays[:, :3], rays[:, 3:], ambient)


class RenderWarning(UserWarning):
    """A render that will not show what its config's truth says."""


def warn_lambertian_indirect_gloss(configs) -> None:
    """One :class:`RenderWarning` naming the configs whose material Radiance
    will render with Lambertian indirect gloss
    (:meth:`SequenceConfig.lambertian_indirect_gloss`)."""
    names = [
        f"{c.name} (specularity {c.specularity:g}, -st {c.specular_threshold():g})"
        for c in configs
        if c.lambertian_indirect_gloss()
    ]
    if names:
        warnings.warn(
            f"{len(names)} sequence(s) of a rough material no more specular than rtrace's "
            f"specular threshold: {', '.join(names)}. Radiance renders their sky's and "
            "ground's reflection as Lambertian (normal.c's SP_RBLT), so the images show "
            "less gloss than their truth; render with '-st 0' "
            "(sequences.TRACED_SPECULAR_AMBIENT). Recorded as the bundle truth's "
            "'lambertian_indirect_gloss'.",
            RenderWarning,
            stacklevel=3,
        )


def render_bundles(configs, cache_dir, *, jobs: int = 2, progress: bool = True) -> list[Path]:
    """Render sequences into bundles (cached by configuration hash).

    Parameters
    ----------
    configs : iterable of SequenceConfig
    cache_dir : path
        Bundles are written to ``cache_dir/<name>-<hash>/``.
    jobs : int
        Radiance processes running at once.
    progress : bool
        Print a progress line to stderr.

    Returns
    -------
    list of Path
        The bundle folders, in the order of ``configs``.
    """
    from . import bundle as bundle_io

    configs = list(configs)
    cache_dir = Path(cache_dir)
    cache_dir.mkdir(parents=True, exist_ok=True)
    paths = [_bundle_dir(cache_dir, c) for c in configs]
    todo = [c for c, p in zip(configs, paths, strict=True) if not (p / "sequence.json").exists()]
    warn_lambertian_indirect_gloss(todo)
    groups: dict[str, list[SequenceConfig]] = {}
    for c in todo:
        groups.setdefault(c.scene_key(), []).append(c)

    tasks, plans = [], {}
    for key, members in groups.items():
        first = members[0]
        facets = first.facets()
        suns = first.sun_directions()
        day = int(first.frame_times()[0].day_of_year)
        rays = [np.concatenate(camera_rays(m, facets), axis=1) for m in members]
        plans[key] = dict(
            members=members,
            facets=facets,
            suns=suns,
            rays=rays,
            frames=[None] * len(suns),
            scene=_object_text(first, facets),
        )
        for t, s in enumerate(suns):
            tasks.append((key, t, _sky_text(first, t, s, day)))

    done, start = 0, time.perf_counter()
    with ThreadPoolExecutor(max_workers=max(1, jobs)) as pool:
        futures = {
            pool.submit(
                _render_frame,
                plans[k]["scene"],
                sky_text,
                np.concatenate(plans[k]["rays"]),
                plans[k]["members"][0].ambient,
            ): (k, t)
            for k, t, sky_text in tasks
        }
        for fut in as_completed(futures):
            k, t = futures[fut]
            plans[k]["frames"][t] = fut.result()
            done += 1
            if progress:
                el = time.perf_counter() - start
                print(
                    f"\rbayesgloss render: {done}/{len(tasks)} frames, {el:.0f} s",
                    end="",
                    file=sys.stderr,
                    flush=True,
                )
            plan = plans[k]
            if all(f is not None for f in plan["frames"]):
                _write_group(plan, cache_dir, bundle_io)
                plan["frames"] = []  # free memory
    if progress and tasks:
        print(file=sys.stderr)
    return paths


def _write_group(plan, cache_dir: Path, bundle_io) -> None:
    facets = plan["facets"]
    n_pix = [len(r) for r in plan["rays"]]
    offsets = np.cumsum([0, *n_pix])
    sun_up = plan["suns"][:, 2] > 0.0
    for i, config in enumerate(plan["members"]):
        n = config.image_size
        labels = label_image(config, facets)
        frames = np.stack([f[offsets[i] : offsets[i + 1]].reshape(n, n, 3) for f in plan["frames"]])
        write_rendered_bundle(
            _bundle_dir(cache_dir, config), config, facets, labels, frames, sun_up, bundle_io
        )


def write_rendered_bundle(
    final: Path, config: SequenceConfig, facets, labels, frames, sun_up, bundle_io, truth=None
) -> Path:
    """Rendered radiance frames (T, n, n, 3) as a bundle at ``final``: the
    camera response of ``config`` (:func:`camera_response`), the facets its
    ``labels`` hold, ``truth`` (default :meth:`SequenceConfig.bundle_truth`)
    with the exposure gains and white level added, ``frames[].exposure``
    written for ``linear-radiance`` only; staged and renamed into place. The
    writer of the Radiance renderer and of :mod:`bayesgloss.mitsuba_render`."""
    present = np.isin(facets.ids, np.unique(labels[labels > 0]))
    coded, gains, white = camera_response(config, frames, sun_up)
    name, _ = images.parse_pixel_encoding(config.pixel_encoding)
    if name == "linear-radiance":
        frame_format = "hdr"
    else:
        frame_format = "png8" if config._bit_depth() == 8 else "png16"
    truth = config.bundle_truth() if truth is None else truth
    truth["exposure"] = None if gains is None else [float(g) for g in gains]
    truth["exposure_written"] = gains is not None and name == "linear-radiance"
    truth["white"] = white
    final = Path(final)
    staging = final.with_name(f".{final.name}.staging")
    bundle_io.write_bundle(
        staging,
        site={
            "latitude": config.latitude,
            "longitude": config.longitude,
            "elevation": config.elevation,
        },
        camera_position=config.camera_position(),
        pixel_encoding=config.pixel_encoding,
        frames=list(coded),
        times=[t.isoformat() for t in config.frame_times()],
        facets=facets.subset(np.flatnonzero(present)),
        labels=labels,
        ground_reflectance=config.ground_reflectance,
        truth=truth,
        frame_format=frame_format,
        object_mesh=config.mesh_file,  # None but for shape "mesh"
        overwrite=True,
        # pixel = exposure x radiance (the spec's frames[].exposure)
        exposure=truth["exposure"] if truth["exposure_written"] else None,
    )
    if final.exists():  # a bundle left without its manifest by an old interrupted run
        shutil.rmtree(final)
    os.replace(staging, final)
    return final


# -- camera response -----------------------------------------------------------


def _noise_generator(config: SequenceConfig) -> np.random.Generator:
    """The configuration's own generator, seeded by its hash."""
    return np.random.default_rng(int(config.key(), 16))


def auto_exposure(
    frames: np.ndarray, sun_up: np.ndarray, jitter: float, rng: np.random.Generator
) -> np.ndarray:
    """Per-frame gains of a camera that meters each frame's mean luminance.

    ``gain_t = m_ref / max(m_t, m_ref / R) x exp(jitter z_t)``, with ``m_t``
    the frame's mean luminance, ``m_ref`` the median of ``m_t`` over the
    frames with the sun up (all frames if none), ``R`` =
    :data:`AUTO_EXPOSURE_RANGE` the camera's gain range and ``z_t`` standard
    normal draws from ``rng``.

    Parameters
    ----------
    frames : ndarray (T, H, W, 3)
        Linear RGB radiance [W sr^-1 m^-2].
    sun_up : ndarray of bool (T,)
        Frames with the sun above the horizon [-].
    jitter : float
        Standard deviation of the log gain about the metered one [-].
    rng : numpy.random.Generator
        Source of the jitter.

    Returns
    -------
    ndarray (T,)
        Gains [-], near 1 for a frame of median brightness.
    """
    mean = np.mean(frames @ np.asarray(reflectance.LUMINANCE_WEIGHTS), axis=(1, 2))
    ref = np.median(mean[sun_up]) if np.any(sun_up) else np.median(mean)
    if not ref > 0:
        ref = 1.0
    z = rng.standard_normal(len(mean))
    return ref / np.maximum(mean, ref / AUTO_EXPOSURE_RANGE) * np.exp(jitter * z)


def camera_response(
    config: SequenceConfig, frames: np.ndarray, sun_up: np.ndarray
) -> tuple[np.ndarray, np.ndarray | None, float | None]:
    """What the configured camera stores of rendered frames.

    Gains (``exposure``), then relative Gaussian ``sensor_noise`` (values
    clipped at 0), then for an integer encoding division by the white, clipping
    to [0, 1] and the encoding's transfer curve (see the module docstring).

    Parameters
    ----------
    config : SequenceConfig
    frames : ndarray (T, H, W, 3)
        Rendered RGB radiance [W sr^-1 m^-2].
    sun_up : ndarray of bool (T,)
        Frames with the sun above the horizon (where the white is measured) [-].

    Returns
    -------
    coded : ndarray (T, H, W, 3)
        Radiance times gain (float32) for ``linear-radiance``, else normalised
        code values in [0, 1] for :func:`bayesgloss.bundle.write_bundle` [-].
    gains : ndarray (T,) or None
        The exposure gains applied [-].
    white : float or None
        Exposed linear value of the top code; None for ``linear-radiance``
        [W sr^-1 m^-2].
    """
    rng = _noise_generator(config)
    linear = np.asarray(frames, dtype=float)
    if config.exposure is None:
        gains = None
    elif isinstance(config.exposure, str):  # "auto"; the jitter is the generator's first draw
        gains = auto_exposure(linear, sun_up, config.exposure_jitter, rng)
    else:
        gains = np.asarray(config.exposure, dtype=float)
    exposed = linear if gains is None else linear * gains[:, None, None, None]
    noisy = exposed
    if config.sensor_noise > 0:
        noisy = np.maximum(
            exposed * (1 + config.sensor_noise * rng.standard_normal(exposed.shape)), 0
        )
    name, gamma = images.parse_pixel_encoding(config.pixel_encoding)
    if name == "linear-radiance":
        return noisy.astype(np.float32), gains, None
    metered = exposed[sun_up] if np.any(sun_up) else exposed
    white = float(config.white_scale * np.percentile(metered, 99))
    if not white > 0:
        white = 1.0
    v = np.clip(noisy / white, 0.0, 1.0)
    if name == "srgb":
        v = images.linear_to_srgb(v)
    elif name == "gamma":
        v = v ** (1.0 / gamma)
    return v, gains, white

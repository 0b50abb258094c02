"""Sequence bundles: image codecs, reading and writing ``bayesgloss-sequence/1``.

A sequence bundle (``shared/spec/sequence-bundle.md``) is one folder holding
what a static camera saw of one object over a day::

    my-bundle/
      sequence.json   manifest: site, camera, frames (file, time), facets, ...
      frames/...      one image a frame
      facets.png      facet label image: pixel value k > 0 is facet k

This module reads and writes bundles and reduces them to facet curves, the
observations of the likelihood: for each facet and frame a robust summary
(mean or median) of the luminance of the facet's pixels.

Images
------
Radiance RGBE pictures (``.hdr``/``.pic``) are decoded by this module's own
codec (:func:`read_hdr`, :func:`write_hdr`); PNG (8 or 16 bit, all 16 bits
kept) through ``pypng``; TIFF (8/16-bit integer, float) through ``tifffile``;
OpenEXR through the optional ``openexr`` package. The format is recognised by
the file's magic bytes, not its suffix.

Pixel encodings (``camera.pixel_encoding``)
-------------------------------------------
Integer images are first normalised by their top code (255, 65535, ...);
a pixel with any channel at the top code is *saturated*. Then

``linear-radiance``
    RGB radiance, W sr^-1 m^-2; the luminance is 179 (0.265 R + 0.670 G +
    0.065 B) cd m^-2. Needs a floating-point image (Radiance, float TIFF,
    EXR): a bundle that pairs it with integer frames is rejected.
``linear``
    linear in radiance with an unknown scale; luminance in relative units.
``srgb``
    the sRGB transfer curve (IEC 61966-2-1), inverted.
``gamma:G``
    value = linear^(1/G), inverted as linear = value^G.
``unknown``
    a monotone response that is not known: the normalised code values pass
    through unchanged and :attr:`FacetCurves.response_known` is False, so
    the likelihood can model the response.

Bad bundles
-----------
Following the spec, a reader *rejects* with :class:`BundleError` (which
names the bundle, the field and the problem): a missing or unreadable
manifest, frame or label image; frames of different sizes or a label image
of another size; a time with no UTC offset; a normal that is not of unit
length within 1e-3; a latitude outside [-90, 90] or a longitude outside
[-180, 180]; a facet id that ``facets.png`` never holds; a wrong ``format``
literal, a missing or ill-typed required field, an empty frame or facet
list, a duplicate facet id; a ``camera.position`` that sees no facet: at a
facet centre (within 1e-3 times the object's size, the diagonal of the box
around the facet centres, or within 1 mm when the centres coincide), where
the viewing direction is undefined, or behind every facet, (position -
center) . normal <= 0 for all of them (as for a camera inside a convex
object); a PNG frame of fewer than 8 bits per sample. Every listed facet
counts, since a listed facet that ``facets.png`` never holds is rejected
first. It *reports* in the facet curves' ``valid`` mask and ``flags``, and
does not reject: frames with the sun below the horizon, NaN or infinite
pixels, saturated pixels, a negative luminance (float images: a facet whose
mean or median is below 0 cannot be a radiance; single negative pixels, as
noise about a black level, are kept), facets seen from behind ((position -
center) . normal <= 0 for some but not all facets), and facets with fewer
than ``min_pixels`` (default :data:`MIN_PIXELS` = 4) labelled pixels. It
*warns* (:class:`BundleWarning`) of labels that no facet lists (their pixels
are ignored), of frames that share a time (those are kept, each frame an
independent observation of the same sun and sky), and of a camera below
``z = 0`` and below every facet centre (under the ground of bundles that put
it at ``z = 0``, as bayesgloss's own do; the spec fixes no origin, so this
is a warning).

Frames keep the manifest's order, which need not be the order of their
times: the reader does not sort them, and neither warns of nor rejects
frames out of time order.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
import math
import os
import shutil
import tempfile
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import pandas as pd

from . import sun as _sun
from .geometry import Facets
from .images import (  # noqa: F401 - re-exported: the bundle API includes the codecs
    PIXEL_ENCODINGS,
    ImageInfo,
    decode_pixels,
    float_to_rgbe,
    image_info,
    image_kind,
    linear_to_srgb,
    parse_pixel_encoding,
    read_exr,
    read_hdr,
    read_image,
    read_labels,
    read_png,
    read_tiff,
    rgbe_to_float,
    srgb_to_linear,
    write_exr,
    write_hdr,
    write_png,
    write_tiff,
)
from .reflectance import LUMINANCE_WEIGHTS
from .sky import WHITE_EFFICACY  # Radiance's 179 lm/W: cd m^-2 per W sr^-1 m^-2

__all__ = [
    "NoUsableData",
    "usable_facets",
    "facing_camera",
    "bundle_digest",
    "FLAG_REASONS",
    "FORMAT",
    "FRAME_FORMATS",
    "MANIFEST",
    "LABELS",
    "MIN_PIXELS",
    "PIXEL_ENCODINGS",
    "STATISTICS",
    "Bundle",
    "BundleError",
    "BundleWarning",
    "FacetCurves",
    "ImageInfo",
    "Site",
    "decode_pixels",
    "facet_curves",
    "image_info",
    "linear_to_srgb",
    "parse_pixel_encoding",
    "read_bundle",
    "read_exr",
    "read_hdr",
    "read_image",
    "read_labels",
    "read_png",
    "read_tiff",
    "srgb_to_linear",
    "write_bundle",
    "write_exr",
    "write_hdr",
    "write_png",
    "write_tiff",
]

#: The ``format`` literal of the manifest this module reads and writes.
FORMAT = "bayesgloss-sequence/1"
#: File names inside a bundle.
MANIFEST = "sequence.json"
LABELS = "facets.png"
#: The largest label image (and so frame) read, in pixels: a header declaring
#: more is rejected before any pixel is decoded (a 389 KB PNG declaring 20000 x
#: 20000 pixels took 4 GB).
MAX_IMAGE_PIXELS = 100_000_000
#: Site elevations read, metres: the Dead Sea's shore to above Everest (the
#: sun's position model's pressure has no meaning far outside).
SITE_ELEVATION = (-500.0, 9000.0)
#: File name endings of ``object_mesh``.
MESH_SUFFIXES = (".obj", ".ply")
#: Facets with fewer labelled pixels are reported as ``too-few-pixels``.
MIN_PIXELS = 4
#: Reasons an observation is left out, in the order of :attr:`FacetCurves.flag_bits`.
#: ``partly-shadowed`` and ``shadowed-by-object`` come from a bundle's
#: ``object_mesh`` and are set by :func:`bayesgloss.visibility.shadow_flags`,
#: not by :func:`facet_curves`.
FLAG_REASONS = (
    "sun-below-horizon",
    "nan-pixels",
    "saturated",
    "too-few-pixels",
    "negative-luminance",
    "seen-from-behind",
    "partly-shadowed",
    "shadowed-by-object",
)
#: Robust summaries of a facet's pixel luminances.
STATISTICS = ("mean", "median")
#: ``frame_format`` of :func:`write_bundle`: file suffix of each.
FRAME_FORMATS = {
    "hdr": ".hdr",
    "png16": ".png",
    "png8": ".png",
    "tiff": ".tif",
    "tiff16": ".tif",
    "exr": ".exr",
}

_NORMAL_TOLERANCE = 1e-3
#: A camera nearer a facet centre than this fraction of the object's size (the
#: diagonal of the box around the facet centres; 1 m when they coincide) is
#: at that centre.
_CAMERA_AT_CENTER = 1e-3
_WEIGHTS = np.asarray(LUMINANCE_WEIGHTS, dtype=float)


# ---------------------------------------------------------------------------
# errors
# ---------------------------------------------------------------------------


class BundleError(ValueError):
    """A bundle that breaks the spec: names the bundle, the field and the problem.

    Attributes
    ----------
    bundle : str
        The bundle's folder as given.
    field : str
        The manifest field (``"frames[3].time"``) or file (``"facets.png"``).
    problem : str
        What is wrong, with the bad value.
    """

    def __init__(self, bundle: Any, field: str, problem: str):
        self.bundle = str(bundle)
        self.field = field
        self.problem = problem
        super().__init__(f"bundle '{self.bundle}': field '{field}': {problem}")

    def __reduce__(self):
        return (type(self), (self.bundle, self.field, self.problem))


class BundleWarning(UserWarning):
    """Something odd in a bundle that the spec does not make an error."""


class NoUsableData(ValueError):
    """No facet of a bundle has enough usable frames for an estimate."""


def usable_facets(bundle, usable, min_frames: int, censored=None, min_measured: int = 2):
    """Facets with at least ``min_frames`` usable frames, ``min_measured`` of
    them measured rather than censored, (F,) of bool.

    A censored entry (every saturated pixel at the top code) is only a lower
    bound: a facet seen saturated in every frame says nothing of its curve's
    shape under a free scale, however many frames it has.

    Parameters
    ----------
    bundle : Bundle
    usable : ndarray (F, T) of bool
        Usable entries of the bundle's facet curves.
    min_frames : int
        Usable frames an estimator needs per facet [-].
    censored : ndarray (F, T) of bool, optional
        Usable entries that are lower bounds only (saturated). -
    min_measured : int, default 2
        Usable entries that are not censored a facet needs [-]. -

    Raises
    ------
    NoUsableData
        Where no facet has them (every frame at night, a single frame, every
        pixel saturated...), naming the bundle and saying how many frames
        have the sun up and how many entries are saturated.
    """
    usable = np.asarray(usable, dtype=bool)
    censored = np.zeros_like(usable) if censored is None else np.asarray(censored, dtype=bool)
    measured = (usable & ~censored).sum(axis=1)
    keep = (usable.sum(axis=1) >= min_frames) & (measured >= min_measured)
    if not np.any(keep):
        n_up, n_t = int(np.sum(bundle.sun_up)), len(bundle.sun_up)
        best = int(usable.sum(axis=1).max()) if usable.size else 0
        if best >= min_frames:  # frames enough, but lower bounds only
            raise NoUsableData(
                f"bundle '{bundle.path}': no facet has enough measured frames: "
                f"{int(censored.sum())} of {int(usable.sum())} usable entries are saturated "
                f"(lower bounds only), the best facet has {int(measured.max())} measured, "
                f"{min_measured} needed: lower the exposure"
            )
        raise NoUsableData(
            f"bundle '{bundle.path}': no facet has enough usable frames: {n_up} of {n_t} "
            f"frames have the sun up, the best facet has {best} usable, {min_frames} needed"
        )
    return keep


# ---------------------------------------------------------------------------
# the manifest
# ---------------------------------------------------------------------------


class Site(NamedTuple):
    """Where the camera stood: deg north, deg east (positive), m above sea level."""

    latitude: float
    longitude: float
    elevation: float = 0.0


class _Manifest(NamedTuple):
    site: Site
    camera_position: np.ndarray
    pixel_encoding: str
    encoding_gamma: float | None
    ground_reflectance: float | None
    frame_files: tuple[str, ...]
    times: pd.DatetimeIndex
    facets: Facets
    truth: dict | None
    exposure: np.ndarray | None
    irradiance: np.ndarray
    object_mesh: str | None = None


def _short(value: Any, limit: int = 60) -> str:
    """repr of a manifest value for an error line, cut at ``limit`` characters."""
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _is_number(value: Any) -> bool:
    """A finite JSON number (an integer too large for a float, as ``1e400``
    written without its point, is not one)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return False
    try:
        return math.isfinite(value)
    except OverflowError:
        return False


class _Checker:
    """Field access with errors that name the bundle and the field."""

    def __init__(self, bundle: Any):
        self.bundle = bundle

    def fail(self, field: str, problem: str) -> BundleError:
        return BundleError(self.bundle, field, problem)

    def get(self, obj: Mapping, key: str, where: str, kind: type, required: bool = True):
        name = f"{where}.{key}" if where else key
        if key not in obj or (obj[key] is None and not required):
            if required:
                raise self.fail(name, "missing required field")
            return None
        value = obj[key]
        if kind is float:
            if not _is_number(value):
                raise self.fail(name, f"must be a finite number, got {_short(value)}")
            return float(value)
        if kind is int:
            if isinstance(value, bool) or not (
                isinstance(value, int) or (isinstance(value, float) and value.is_integer())
            ):
                raise self.fail(name, f"must be an integer, got {_short(value)}")
            return int(value)
        names = {dict: "an object", list: "a list", str: "a string"}
        if not isinstance(value, kind):
            raise self.fail(name, f"must be {names[kind]}, got {_short(value)}")
        return value

    def vector(self, obj: Mapping, key: str, where: str) -> np.ndarray:
        value = self.get(obj, key, where, list)
        if len(value) != 3 or not all(_is_number(v) for v in value):
            raise self.fail(f"{where}.{key}", f"must be 3 finite numbers, got {value!r}")
        return np.array(value, dtype=float)


#: Keys of ``frames[].irradiance``, in the order of :attr:`Bundle.irradiance`'s columns.
IRRADIANCE_KEYS = ("ghi", "dni", "dhi")


def _parse_irradiance(check: _Checker, frame: Mapping, where: str) -> list[float]:
    """(GHI, DNI, DHI) of ``frames[i].irradiance``, NaN where absent [W m^-2]."""
    value = check.get(frame, "irradiance", where, dict, required=False)
    out = [math.nan] * 3
    if value is None:
        return out
    for k, key in enumerate(IRRADIANCE_KEYS):
        x = check.get(value, key, f"{where}.irradiance", float, required=False)
        if x is not None and x < 0:
            raise check.fail(f"{where}.irradiance.{key}", f"must be >= 0 W m^-2, got {x!r}")
        out[k] = math.nan if x is None else x
    if all(math.isnan(x) for x in out):
        raise check.fail(
            f"{where}.irradiance", f"holds none of {', '.join(IRRADIANCE_KEYS)}: {value!r}"
        )
    return out


def _parse_time(check: _Checker, value: Any, name: str) -> pd.Timestamp:
    if not isinstance(value, str):
        raise check.fail(name, f"must be an ISO 8601 string, got {value!r}")
    try:
        stamp = _dt.datetime.fromisoformat(value)
    except ValueError:
        raise check.fail(name, f"time {value!r} is not an ISO 8601 time") from None
    if stamp.tzinfo is None or stamp.utcoffset() is None:
        raise check.fail(name, f"time {value!r} has no UTC offset")
    return pd.Timestamp(stamp).tz_convert("UTC")


def _parse_manifest(manifest: Any, bundle: Any) -> _Manifest:
    """Validate a manifest dict; every error names its field."""
    check = _Checker(bundle)
    if not isinstance(manifest, dict):
        raise check.fail(MANIFEST, f"must hold a JSON object, got {type(manifest).__name__}")
    fmt = check.get(manifest, "format", "", str)
    if fmt != FORMAT:
        raise check.fail("format", f"expected {FORMAT!r}, got {fmt!r}")

    site = check.get(manifest, "site", "", dict)
    latitude = check.get(site, "latitude", "site", float)
    if not -90.0 <= latitude <= 90.0:
        raise check.fail("site.latitude", f"latitude {latitude} lies outside [-90, 90]")
    longitude = check.get(site, "longitude", "site", float)
    if not -180.0 <= longitude <= 180.0:
        raise check.fail("site.longitude", f"longitude {longitude} lies outside [-180, 180]")
    elevation = check.get(site, "elevation", "site", float, required=False)
    low, high = SITE_ELEVATION
    if elevation is not None and not low <= elevation <= high:
        raise check.fail(
            "site.elevation",
            f"{elevation:g} m lies outside [{low:g}, {high:g}] m (metres above sea level)",
        )
    site = Site(latitude, longitude, 0.0 if elevation is None else elevation)

    camera = check.get(manifest, "camera", "", dict)
    position = check.vector(camera, "position", "camera")
    encoding = check.get(camera, "pixel_encoding", "camera", str)
    try:
        name, gamma = parse_pixel_encoding(encoding)
    except ValueError as err:
        raise check.fail("camera.pixel_encoding", str(err)) from None

    ground = check.get(manifest, "ground_reflectance", "", float, required=False)
    if ground is not None and not 0.0 <= ground <= 1.0:
        raise check.fail("ground_reflectance", f"must lie in [0, 1], got {ground}")

    frames = check.get(manifest, "frames", "", list)
    if not frames:
        raise check.fail("frames", "the frame list is empty")
    files, times, exposures, irradiance = [], [], [], []
    for i, frame in enumerate(frames):
        where = f"frames[{i}]"
        if not isinstance(frame, dict):
            raise check.fail(where, f"must be an object, got {frame!r}")
        file = _relative_path(check, check.get(frame, "file", where, str), f"{where}.file")
        files.append(file)
        times.append(_parse_time(check, check.get(frame, "time", where, str), f"{where}.time"))
        exposure = check.get(frame, "exposure", where, float, required=False)
        if exposure is not None and not exposure > 0:
            raise check.fail(f"{where}.exposure", f"must be a positive number, got {exposure!r}")
        exposures.append(exposure)
        irradiance.append(_parse_irradiance(check, frame, where))
    given = [e is not None for e in exposures]
    if any(given) and not all(given):
        i = given.index(False)
        raise check.fail(
            f"frames[{i}].exposure",
            f"missing here but given for frames[{given.index(True)}]: give every frame's "
            "exposure or none",
        )

    facet_list = check.get(manifest, "facets", "", list)
    if not facet_list:
        raise check.fail("facets", "the facet list is empty")
    ids, normals, centers, seen = [], [], [], {}
    for i, facet in enumerate(facet_list):
        where = f"facets[{i}]"
        if not isinstance(facet, dict):
            raise check.fail(where, f"must be an object, got {facet!r}")
        fid = check.get(facet, "id", where, int)
        if not 1 <= fid <= 65535:
            raise check.fail(f"{where}.id", f"facet id {fid} must lie in 1-65535")
        if fid in seen:
            raise check.fail(f"{where}.id", f"facet id {fid} repeats facets[{seen[fid]}]")
        seen[fid] = i
        normal = check.vector(facet, "normal", where)
        norm = float(np.linalg.norm(normal))
        if abs(norm - 1.0) > _NORMAL_TOLERANCE:
            raise check.fail(
                f"{where}.normal",
                f"normal {normal.tolist()} has length {norm:.6g}, not 1 within {_NORMAL_TOLERANCE}",
            )
        ids.append(fid)
        normals.append(normal)
        centers.append(check.vector(facet, "center", where))
    facets = Facets(np.array(ids, dtype=int), np.array(normals), np.array(centers))

    truth = check.get(manifest, "truth", "", dict, required=False)
    mesh = check.get(manifest, "object_mesh", "", str, required=False)
    if mesh is not None:
        _relative_path(check, mesh, "object_mesh")
        if Path(mesh).suffix.lower() not in MESH_SUFFIXES:
            raise check.fail(
                "object_mesh", f"must name an OBJ or PLY file (.obj, .ply), got {mesh!r}"
            )
    return _Manifest(
        site,
        position,
        encoding,
        gamma,
        ground,
        tuple(files),
        pd.DatetimeIndex(times),
        facets,
        truth,
        np.array(exposures, dtype=float) if all(given) else None,
        np.array(irradiance, dtype=float).reshape(-1, 3),
        mesh,
    )


def _relative_path(check: _Checker, name: str, field: str) -> str:
    """``name`` if it is a non-empty relative path, else a BundleError naming ``field``."""
    if not name or Path(name).is_absolute():
        raise check.fail(field, f"must be a path relative to the bundle, got {_short(name)}")
    return name


def _inside_bundle(check: _Checker, root: Path, name: str, field: str) -> Path:
    """``root / name``, or a BundleError naming ``field`` if it lies outside
    the bundle folder once resolved (a ``..`` or a symbolic link out of it):
    no file outside the bundle is opened, nor its bytes echoed."""
    path = root / name
    try:
        inside = path.resolve().is_relative_to(root.resolve())
    except (OSError, RuntimeError) as err:  # a link loop, say
        raise check.fail(field, f"cannot resolve '{name}': {err}") from None
    if not inside:
        raise check.fail(
            field, f"'{name}' lies outside the bundle folder (a '..' or a link out of it)"
        )
    return path


def _check_camera(check: _Checker, position: np.ndarray, facets: Facets) -> None:
    """Reject a camera at a facet centre or behind every facet (``camera.position``).

    At a facet centre the viewing direction is undefined (0 / 0 in
    :func:`bayesgloss.geometry.view_directions`); behind every facet, (camera -
    center) . normal <= 0 for all of them, no facet faces the camera, as for a
    camera inside a convex object. "At" means within :data:`_CAMERA_AT_CENTER`
    times the object's size, the diagonal of the box around the facet centres
    (taken as 1 m when the centres coincide, as for a single facet).
    """
    center = np.asarray(facets.center, dtype=float)
    offset = position - center  # (F, 3): from each facet centre to the camera, m
    distance = np.linalg.norm(offset, axis=-1)
    size = float(np.linalg.norm(np.ptp(center, axis=0)))
    tolerance = _CAMERA_AT_CENTER * (size if size > 0.0 else 1.0)
    nearest = int(np.argmin(distance))
    if distance[nearest] <= tolerance:
        raise check.fail(
            "camera.position",
            f"camera position {position.tolist()} is at the centre of facets[{nearest}] "
            f"(id {int(facets.ids[nearest])}): {distance[nearest]:.3g} m from it, within "
            f"{_CAMERA_AT_CENTER:g} x the object's size ({size:.3g} m), so that facet has "
            "no viewing direction",
        )
    facing = facing_camera(position, facets)
    if np.all(facing <= 0.0):
        best = int(np.argmax(facing))
        raise check.fail(
            "camera.position",
            f"camera position {position.tolist()} is behind every facet: "
            f"(position - center) . normal <= 0 for all {len(facing)} facets (largest "
            f"{facing[best]:.3g} m, facets[{best}]), so no facet faces the camera (is it "
            "inside the object, or on a side of it that no listed facet faces?)",
        )


def facing_camera(position, facets: Facets) -> np.ndarray:
    """(position - center) . normal of each facet, m: positive where the facet
    faces the camera, zero or negative where it is seen edge-on or from behind."""
    offset = np.asarray(position, dtype=float) - np.asarray(facets.center, dtype=float)
    return np.sum(offset * np.asarray(facets.normal, dtype=float), axis=-1)


def _below_ground_warning(bundle: Any, position: np.ndarray, facets: Facets) -> str | None:
    """The warning text for a camera below ``z = 0`` and every facet centre, or None."""
    lowest = float(np.min(np.asarray(facets.center, dtype=float)[:, 2]))
    if position[2] >= 0.0 or position[2] >= lowest:
        return None
    return (
        f"bundle '{bundle}': camera.position {position.tolist()} is below z = 0 and below "
        f"every facet centre (the lowest at z = {lowest:.3g} m): if z = 0 is the ground, as "
        "in the bundles bayesgloss renders, the camera is under it"
    )


def bundle_digest(bundle: Bundle) -> str:
    """SHA-256 (hex) of what a bundle's estimate depends on: the manifest's and
    the label image's bytes, and each frame's (and the mesh's) name, size and
    modification time (ns).

    Stat rather than read the frames: a bundle's frames may be gigabytes, and
    a frame replaced or rewritten changes its time or size. The key of a
    finished result (:func:`bayesgloss.cli` over several bundles) and the
    check that ``report`` draws the bundle a result was computed from.
    """
    digest = hashlib.sha256()
    root = Path(bundle.path).resolve()
    for name in (MANIFEST, LABELS):
        data = (root / name).read_bytes()
        digest.update(f"{name}\0{len(data)}\0".encode())
        digest.update(data)
    mesh = bundle.manifest.get("object_mesh")  # a dict: the reader rejects any other
    for file in (*bundle.frame_files, *([root / mesh] if mesh else [])):
        st = Path(file).stat()
        name = os.path.relpath(Path(file).resolve(), root)
        digest.update(f"{name}\0{st.st_size}\0{st.st_mtime_ns}\0".encode())
    return digest.hexdigest()


def _same_time_warning(bundle: Any, times: pd.DatetimeIndex) -> str | None:
    """The warning text for frames that share a time, or None when no two do."""
    codes, instants = pd.factorize(times)
    counts = np.bincount(codes, minlength=len(instants))
    shared = np.flatnonzero(counts > 1)
    if not len(shared):
        return None
    groups = []
    for k in shared[:5]:  # a handful of groups is enough to find them
        index = [f"frames[{i}]" for i in np.flatnonzero(codes == k)]
        names = ", ".join(index[:-1]) + f" and {index[-1]}"
        groups.append(f"{names} have the same time {instants[k].isoformat()}")
    more = f" (and {len(shared) - 5} more times)" if len(shared) > 5 else ""
    return (
        f"bundle '{bundle}': " + "; ".join(groups) + more + "; frames with the same time are "
        "kept, each an independent observation of the same sun and sky"
    )


# ---------------------------------------------------------------------------
# bundles
# ---------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class Bundle:
    """A sequence bundle read and checked by :func:`read_bundle`; frames stay on disk.

    Attributes
    ----------
    path : Path
        The bundle folder.
    manifest : dict
        ``sequence.json`` as parsed (unknown fields included).
    site : Site
        Latitude (deg, north positive), longitude (deg, east positive),
        elevation (m).
    camera_position : ndarray (3,)
        Camera's centre of projection, world frame, m.
    pixel_encoding : str
        ``camera.pixel_encoding`` as written, e.g. ``"gamma:2.2"``.
    encoding_gamma : float or None
        G of a ``gamma:G`` encoding.
    ground_reflectance : float or None
        Albedo of the surrounding ground, -.
    times : pandas.DatetimeIndex
        Frame times, tz-aware, UTC.
    frame_files : tuple of Path
        Frame image files.
    facets : Facets
        Ids, unit normals and centres (m) of the facets; no polygons.
    labels : ndarray (H, W) of int
        ``facets.png``: facet id per pixel, 0 background.
    solar_zenith, solar_azimuth : ndarray (T,)
        Apparent sun position (SPA, refraction corrected) at the site and
        frame times, deg (azimuth clockwise from north).
    sun_direction : ndarray (T, 3)
        Unit vectors toward the apparent sun, world frame.
    truth : dict or None
        What made the bundle. Estimators must not read it.
    exposure : ndarray (T,) or None
        ``frames[].exposure``: each frame's relative exposure (a linear
        factor, any common scale), or None where the manifest gives none.
    irradiance : ndarray (T, 3)
        ``frames[].irradiance``: measured GHI, DNI and DHI of each frame,
        W m^-2; NaN where not given.
    """

    path: Path
    manifest: dict = field(repr=False)
    site: Site
    camera_position: np.ndarray
    pixel_encoding: str
    encoding_gamma: float | None
    ground_reflectance: float | None
    times: pd.DatetimeIndex = field(repr=False)
    frame_files: tuple = field(repr=False)
    facets: Facets = field(repr=False)
    labels: np.ndarray = field(repr=False)
    solar_zenith: np.ndarray = field(repr=False)
    solar_azimuth: np.ndarray = field(repr=False)
    sun_direction: np.ndarray = field(repr=False)
    truth: dict | None = field(repr=False, default=None)
    exposure: np.ndarray | None = field(repr=False, default=None)
    irradiance: np.ndarray | None = field(repr=False, default=None)

    def __len__(self) -> int:
        return len(self.times)

    @property
    def shape(self) -> tuple[int, int]:
        """Frame size (H, W) in pixels."""
        return tuple(self.labels.shape)

    @property
    def sun_up(self) -> np.ndarray:
        """Frames with the apparent sun's centre above the horizon, (T,) bool."""
        return self.solar_zenith < 90.0

    @property
    def ground_albedo(self) -> float:
        """``ground_reflectance``, or 0.2 (gensky's default) where the bundle gives none."""
        return 0.2 if self.ground_reflectance is None else float(self.ground_reflectance)

    @property
    def has_mesh(self) -> bool:
        """Whether the bundle gives an ``object_mesh`` (its shadows and
        occlusion then enter the forward model, :mod:`bayesgloss.visibility`)."""
        return bool(self.manifest.get("object_mesh"))

    @property
    def exposure_known(self) -> bool:
        """Whether frames share a known exposure: ``frames[].exposure`` given,
        or radiance itself (``linear-radiance``). Otherwise the spec lets the
        camera have changed it from frame to frame."""
        return self.exposure is not None or self.pixel_encoding == "linear-radiance"

    @property
    def response_known(self) -> bool:
        """False for ``pixel_encoding`` ``unknown``."""
        return self.pixel_encoding != "unknown"

    def view_geometry(self, occluder=None):
        """Facet normals and view directions (:func:`bayesgloss.render.view_geometry`)."""
        from .render import view_geometry

        return view_geometry(self.facets, self.camera_position, occluder)

    def read_frame(self, index: int) -> tuple[np.ndarray, int | None]:
        """Frame ``index`` as stored: (pixels, max_code) of :func:`read_image`.

        Raises BundleError for an unreadable frame or one of the wrong size.
        """
        name = f"frames[{index}].file"
        path = self.frame_files[index]
        try:
            pixels, max_code = read_image(path)
        except Exception as err:
            raise BundleError(self.path, name, f"cannot read '{path}': {err}") from err
        if pixels.shape[:2] != self.shape:
            raise BundleError(
                self.path,
                name,
                f"frame is {_size(pixels.shape)}, the labels are {_size(self.shape)}",
            )
        return pixels, max_code

    def linear_frame(self, index: int) -> tuple[np.ndarray, np.ndarray]:
        """Frame ``index`` decoded by the bundle's pixel encoding.

        Returns
        -------
        rgb : ndarray of float32 (H, W, 3)
            Linear RGB (radiance, W sr^-1 m^-2, for ``linear-radiance``).
        saturated : ndarray of bool (H, W)
        """
        pixels, max_code = self.read_frame(index)
        if pixels.ndim == 2:
            pixels = pixels[..., None]
        return decode_pixels(pixels, self.pixel_encoding, max_code)


def _size(shape) -> str:
    if len(shape) < 2:  # a damaged file decoded to no image
        return f"an array of shape {tuple(shape)}, not an image"
    return f"{shape[1]}x{shape[0]} pixels"


def read_bundle(path: str | os.PathLike) -> Bundle:
    """Read and check a sequence bundle (``bayesgloss-sequence/1``).

    Reads the manifest and the label image and every frame's header (size,
    sample type) but no frame pixels; :func:`facet_curves` reads those one
    frame at a time.

    Frames keep the manifest's order, sorted by time or not. Two or more
    frames with the same time (the same instant in UTC, whatever their
    offsets) are legal: they are all kept, each frame an independent
    observation of the same sun and sky, and a :class:`BundleWarning` names
    them and their time.

    Parameters
    ----------
    path : str or path-like
        The bundle folder. -

    Returns
    -------
    Bundle

    Raises
    ------
    BundleError
        For every case the spec rejects (see the module docstring), naming
        the bundle, the field and the problem; also for a ``camera.position``
        at a facet centre or behind every facet.

    Warns
    -----
    BundleWarning
        For labels that no facet lists, and for frames with the same time.
    """
    root = Path(path)
    if root.name == MANIFEST and root.is_file():  # the manifest's path names its bundle
        root = root.parent
    check = _Checker(path)
    manifest_path = root / MANIFEST
    if not root.is_dir():
        raise check.fail(MANIFEST, f"no bundle folder '{root}'")
    try:
        text = manifest_path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise check.fail(MANIFEST, f"missing manifest '{manifest_path}'") from None
    except (OSError, UnicodeDecodeError) as err:
        raise check.fail(MANIFEST, f"cannot read the manifest: {err}") from None
    try:
        manifest = json.loads(text)
    except json.JSONDecodeError as err:
        raise check.fail(MANIFEST, f"not valid JSON: {err}") from None
    parsed = _parse_manifest(manifest, path)

    # label image
    labels_path = _inside_bundle(check, root, LABELS, LABELS)
    if not labels_path.is_file():
        raise check.fail(LABELS, f"missing label image '{labels_path}'")
    try:
        if image_kind(labels_path) != "png":
            raise ValueError("not a PNG file")
        info = image_info(labels_path)
    except Exception as err:
        raise check.fail(LABELS, f"cannot read the label image: {err}") from None
    if info.height * info.width > MAX_IMAGE_PIXELS:
        raise check.fail(
            LABELS,
            f"declares {info.width} x {info.height} pixels, more than the "
            f"{MAX_IMAGE_PIXELS} this reader decodes",
        )
    try:
        labels = read_labels(labels_path)
    except Exception as err:
        raise check.fail(LABELS, f"cannot read the label image: {err}") from None
    counts = np.bincount(labels.ravel())
    ids = parsed.facets.ids
    held = counts[np.minimum(ids, len(counts) - 1)] * (ids < len(counts))
    missing = ids[held == 0]
    if len(missing):
        index = int(np.flatnonzero(held == 0)[0])
        raise check.fail(
            f"facets[{index}].id",
            f"facet id {int(missing[0])} never occurs in {LABELS}"
            + (f" (nor do {len(missing) - 1} more ids)" if len(missing) > 1 else ""),
        )
    _check_camera(check, parsed.camera_position, parsed.facets)  # every facet is labelled
    present = np.flatnonzero(counts[1:]) + 1
    unlisted = np.setdiff1d(present, ids)
    if len(unlisted):
        warnings.warn(
            f"bundle '{path}': {LABELS} holds {len(unlisted)} labels that no facet lists "
            f"(e.g. {unlisted[:5].tolist()}); their pixels are ignored",
            BundleWarning,
            stacklevel=2,
        )

    # frames: presence, size and sample type from the headers
    files = []
    for i, name in enumerate(parsed.frame_files):
        where = f"frames[{i}].file"
        file = _inside_bundle(check, root, name, where)
        if not file.is_file():
            raise check.fail(where, f"missing frame '{name}'")
        try:
            info = image_info(file)
        except Exception as err:
            raise check.fail(where, f"cannot read frame '{name}': {err}") from None
        if (info.height, info.width) != labels.shape:
            raise check.fail(
                where,
                f"frame '{name}' is {_size((info.height, info.width))}, but "
                + (
                    f"frames[0] is {_size(labels.shape)}"
                    if i
                    else f"{LABELS} is {_size(labels.shape)}"
                ),
            )
        if info.bits is not None and info.bits < 8:
            raise check.fail(
                where,
                f"frame '{name}' is a {info.bits}-bit PNG; frames need 8 or 16 bits per sample "
                "(a 1-, 2- or 4-bit image holds too few levels to measure a brightness)",
            )
        if info.channels not in (1, 2, 3, 4):
            raise check.fail(where, f"frame '{name}' has {info.channels} channels, not 1-4")
        if info.dtype not in (np.uint8, np.uint16) and info.dtype.kind != "f":
            raise check.fail(
                where,
                f"frame '{name}' has samples of type {info.dtype}; "
                "need 8/16-bit unsigned integers or floats",
            )
        if info.dtype.kind == "u" and parsed.pixel_encoding == "linear-radiance":
            raise check.fail(
                where,
                f"frame '{name}' holds {8 * info.dtype.itemsize}-bit integer codes, which "
                "cannot be pixel_encoding 'linear-radiance' (radiance needs a float image: "
                "Radiance, float TIFF or EXR; use 'linear' for integer linear images)",
            )
        files.append(file)
    if parsed.object_mesh is not None:
        mesh = _inside_bundle(check, root, parsed.object_mesh, "object_mesh")
        if not mesh.is_file():
            raise check.fail("object_mesh", f"missing mesh '{parsed.object_mesh}'")
        warnings.warn(
            f"bundle '{path}': object_mesh '{parsed.object_mesh}' enters the forward model "
            "(bayesgloss.visibility): the sun, sky and ground it hides from each facet; the "
            "light its faces reflect is modelled as from Lambertian faces of one albedo "
            "(0.5, or stacked with estimate --occluder-albedo stacked), and frames where it "
            "shadows part of a facet are left out",
            BundleWarning,
            stacklevel=2,
        )
    below = _below_ground_warning(path, parsed.camera_position, parsed.facets)
    if below:
        warnings.warn(below, BundleWarning, stacklevel=2)
    same_time = _same_time_warning(path, parsed.times)
    if same_time:
        warnings.warn(same_time, BundleWarning, stacklevel=2)

    position = _sun.solar_position(
        parsed.times, parsed.site.latitude, parsed.site.longitude, parsed.site.elevation
    )
    zenith = position["solar_zenith"]
    azimuth = position["solar_azimuth"]
    return Bundle(
        path=root,
        manifest=manifest,
        site=parsed.site,
        camera_position=parsed.camera_position,
        pixel_encoding=parsed.pixel_encoding,
        encoding_gamma=parsed.encoding_gamma,
        ground_reflectance=parsed.ground_reflectance,
        times=parsed.times,
        frame_files=tuple(files),
        facets=parsed.facets,
        labels=labels,
        solar_zenith=zenith,
        solar_azimuth=azimuth,
        sun_direction=_sun.sun_direction(zenith, azimuth),
        truth=parsed.truth,
        exposure=parsed.exposure,
        irradiance=parsed.irradiance,
    )


# ---------------------------------------------------------------------------
# facet curves
# ---------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class FacetCurves:
    """Per facet and frame luminance observations of a bundle.

    Attributes
    ----------
    ids : ndarray (F,)
        Facet ids, in manifest order.
    times : pandas.DatetimeIndex (T,)
        Frame times, UTC.
    luminance : ndarray (F, T)
        Mean or median pixel luminance of each facet in each frame, over its
        finite, unsaturated pixels (NaN if none), in :attr:`unit`. Also given
        for invalid entries: use :attr:`valid` to leave those out.
    lower_bound : ndarray (F, T)
        The same statistic over the facet's finite pixels with saturated
        pixels at their stored (top-code) value, in :attr:`unit`: a lower bound
        of the facet's true luminance where pixels saturate, defined even when
        every pixel does (NaN only without finite pixels); equal to
        ``luminance`` where no pixel saturates.
    unit : str
        ``"cd m-2"`` for ``linear-radiance`` (179 x Radiance's luminance
        weighting of the radiance); ``"relative"`` for ``linear``, ``srgb``
        and ``gamma:G`` (linear, unknown scale); ``"code value"`` for
        ``unknown`` (normalised code values, 0-1 for integer images).
    n_pixels : ndarray (F,) of int
        Labelled pixels of each facet.
    n_nonfinite, n_saturated : ndarray (F, T) of int
        Pixels left out of each observation: NaN/inf, or at the top code.
    flag_bits : ndarray (F, T) of uint8
        Bit k set when reason ``FLAG_REASONS[k]`` applies.
    valid : ndarray (F, T) of bool
        Entries free of every flag: the observations for a likelihood.
    statistic : str
        ``"mean"`` or ``"median"``.
    min_pixels : int
        Facets with fewer pixels are flagged ``too-few-pixels``.
    pixel_encoding : str
    response_known : bool
        False for ``unknown``: the likelihood must model the camera response.
    solar_zenith, solar_azimuth : ndarray (T,)
        Apparent sun position, deg.
    sun_direction : ndarray (T, 3)
        Unit vectors toward the sun, world frame.
    """

    ids: np.ndarray
    times: pd.DatetimeIndex
    luminance: np.ndarray
    lower_bound: np.ndarray
    unit: str
    n_pixels: np.ndarray
    n_nonfinite: np.ndarray
    n_saturated: np.ndarray
    flag_bits: np.ndarray
    statistic: str
    min_pixels: int
    pixel_encoding: str
    response_known: bool
    solar_zenith: np.ndarray
    solar_azimuth: np.ndarray
    sun_direction: np.ndarray

    @property
    def valid(self) -> np.ndarray:
        """Entries with no flag, (F, T) bool."""
        return self.flag_bits == 0

    def flagged(self, reason: str) -> np.ndarray:
        """Where one reason of :data:`FLAG_REASONS` applies, (F, T) bool."""
        if reason not in FLAG_REASONS:
            raise ValueError(f"unknown flag {reason!r}; valid: {', '.join(FLAG_REASONS)}")
        return (self.flag_bits >> FLAG_REASONS.index(reason)) & 1 == 1

    @property
    def flags(self) -> np.ndarray:
        """Reasons each entry is left out, ``;``-joined (``""`` when valid), (F, T) str."""
        out = np.full(self.flag_bits.shape, "", dtype=object)
        for reason in FLAG_REASONS:
            hit = self.flagged(reason)
            out[hit] = np.where(out[hit] == "", reason, out[hit] + ";" + reason)
        return out.astype(str)

    def to_frame(self) -> pd.DataFrame:
        """Long table, one row per facet and frame: id, frame, time, luminance, valid, flag."""
        n_facets, n_frames = self.luminance.shape
        return pd.DataFrame(
            {
                "id": np.repeat(self.ids, n_frames),
                "frame": np.tile(np.arange(n_frames), n_facets),
                "time": np.tile(self.times.strftime("%Y-%m-%dT%H:%M:%S+00:00"), n_facets),
                "luminance": self.luminance.ravel(),
                "valid": self.valid.ravel(),
                "flag": self.flags.ravel(),
            }
        )

    def to_csv(self, path_or_buffer) -> None:
        """Write :meth:`to_frame` as CSV (luminance in :attr:`unit`)."""
        self.to_frame().to_csv(path_or_buffer, index=False)


def facet_curves(
    bundle: Bundle | str | os.PathLike,
    *,
    statistic: str = "mean",
    min_pixels: int = MIN_PIXELS,
) -> FacetCurves:
    """Luminance of each facet in each frame, with the entries to leave out.

    Frames are read one at a time; per-facet sums come from ``np.bincount``
    over the label image, medians from one sort of each frame's labelled
    pixels by (facet, luminance).

    Parameters
    ----------
    bundle : Bundle or path
        A bundle or its folder. -
    statistic : {"mean", "median"}
        Summary of a facet's pixel luminances. -
    min_pixels : int, default 4
        Facets with fewer labelled pixels are flagged ``too-few-pixels``. -

    Returns
    -------
    FacetCurves
        Luminance in cd m^-2 for ``linear-radiance``; see
        :attr:`FacetCurves.unit` for the others. An entry is invalid (and
        flagged) when the sun is below the horizon, when any of the facet's
        pixels is NaN/infinite or saturated, when its statistic is negative,
        when the camera sees the facet from behind or edge-on, or when the
        facet has fewer than ``min_pixels`` pixels; its luminance is still
        computed from the remaining good pixels.

    Raises
    ------
    BundleError
        For an unreadable frame, or one of another size.
    """
    if statistic not in STATISTICS:
        raise ValueError(f"unknown statistic {statistic!r}; valid: {', '.join(STATISTICS)}")
    if isinstance(min_pixels, bool) or not isinstance(min_pixels, int | np.integer):
        raise ValueError(f"min_pixels must be an integer, got {min_pixels!r}")
    if not isinstance(bundle, Bundle):
        bundle = read_bundle(bundle)
    ids = bundle.facets.ids
    n_facets, n_frames = len(ids), len(bundle)
    # facet index of each labelled pixel (F for background and unlisted labels)
    lookup = np.full(max(int(bundle.labels.max()), int(ids.max())) + 1, n_facets, np.intp)
    lookup[ids] = np.arange(n_facets)
    facet_of_pixel = lookup[bundle.labels.ravel()]
    pixels = np.flatnonzero(facet_of_pixel < n_facets)
    facet = facet_of_pixel[pixels]
    n_pixels = np.bincount(facet, minlength=n_facets)
    if statistic == "median":  # group pixels by facet once
        order = np.argsort(facet, kind="stable")
        facet, pixels = facet[order], pixels[order]
        group_start = np.concatenate([[0], np.cumsum(n_pixels)[:-1]])
    scale = WHITE_EFFICACY if bundle.pixel_encoding == "linear-radiance" else 1.0

    def summary(y, bad):
        """The statistic of each facet's pixels that are not ``bad`` (NaN if none)."""
        good = n_pixels - np.bincount(facet, weights=bad, minlength=n_facets).astype(np.int64)
        if statistic == "mean":
            total = np.bincount(facet, weights=np.where(bad, 0.0, y), minlength=n_facets)
            with np.errstate(invalid="ignore", divide="ignore"):
                return np.where(good > 0, total / np.maximum(good, 1), np.nan)
        # sort within facets, bad pixels (NaN) last; median of the first `good`
        key = np.where(bad, np.nan, y)
        sorted_y = key[np.lexsort((key, facet))]
        low = group_start + np.maximum(good - 1, 0) // 2
        high = group_start + np.maximum(good, 0) // 2
        safe = good > 0
        med = 0.5 * (sorted_y[np.where(safe, low, 0)] + sorted_y[np.where(safe, high, 0)])
        return np.where(safe, med, np.nan)

    luminance = np.full((n_facets, n_frames), np.nan)
    lower_bound = np.full((n_facets, n_frames), np.nan)
    n_nonfinite = np.zeros((n_facets, n_frames), np.int64)
    n_saturated = np.zeros((n_facets, n_frames), np.int64)
    for t in range(n_frames):
        stored, max_code = bundle.read_frame(t)
        stored = stored.reshape(bundle.labels.size, -1)[pixels]
        rgb, saturated = decode_pixels(stored, bundle.pixel_encoding, max_code)
        y = rgb.astype(np.float64) @ _WEIGHTS * scale  # Radiance luminance weighting
        nonfinite = ~np.isfinite(y)
        bad = nonfinite | saturated
        n_nonfinite[:, t] = np.bincount(facet, weights=nonfinite, minlength=n_facets)
        n_saturated[:, t] = np.bincount(facet, weights=saturated, minlength=n_facets)
        luminance[:, t] = summary(y, bad)
        # saturated pixels at their stored code: the true value is at least that
        lower_bound[:, t] = summary(y, nonfinite) if saturated.any() else luminance[:, t]

    reasons = {
        "sun-below-horizon": ~bundle.sun_up[None, :],
        "nan-pixels": n_nonfinite > 0,
        "saturated": n_saturated > 0,
        "too-few-pixels": (n_pixels < min_pixels)[:, None],
        "negative-luminance": luminance < 0.0,
        "seen-from-behind": (facing_camera(bundle.camera_position, bundle.facets) <= 0.0)[:, None],
        # set from the bundle's object_mesh by bayesgloss.visibility.shadow_flags
        "partly-shadowed": False,
        "shadowed-by-object": False,
    }
    bits = np.zeros((n_facets, n_frames), np.uint8)
    for k, reason in enumerate(FLAG_REASONS):  # bit k: FLAG_REASONS[k]
        bits |= np.broadcast_to(reasons[reason], bits.shape).astype(np.uint8) << k
    if bundle.pixel_encoding == "linear-radiance":
        unit = "cd m-2"
    elif bundle.pixel_encoding == "unknown":
        unit = "code value"
    else:
        unit = "relative"
    return FacetCurves(
        ids=ids.copy(),
        times=bundle.times,
        luminance=luminance,
        lower_bound=lower_bound,
        unit=unit,
        n_pixels=n_pixels,
        n_nonfinite=n_nonfinite,
        n_saturated=n_saturated,
        flag_bits=bits,
        statistic=statistic,
        min_pixels=int(min_pixels),
        pixel_encoding=bundle.pixel_encoding,
        response_known=bundle.response_known,
        solar_zenith=bundle.solar_zenith,
        solar_azimuth=bundle.solar_azimuth,
        sun_direction=bundle.sun_direction,
    )


# ---------------------------------------------------------------------------
# writing bundles
# ---------------------------------------------------------------------------


def _iso_time(value: Any, index: int) -> str:
    try:
        stamp = pd.Timestamp(value)
    except (ValueError, TypeError):
        raise ValueError(f"times[{index}]: not a time: {value!r}") from None
    if stamp is pd.NaT or stamp.tzinfo is None:
        raise ValueError(f"times[{index}]: time {value!r} has no UTC offset")
    return stamp.isoformat()


def _site_dict(site: Any) -> dict:
    if isinstance(site, Mapping):
        return {k: float(v) for k, v in site.items()}
    values = [float(v) for v in site]
    if len(values) not in (2, 3):
        raise ValueError(f"site must be (latitude, longitude[, elevation]), got {site!r}")
    return dict(zip(("latitude", "longitude", "elevation"), values, strict=False))


def _frame_file(frame: Any, path: Path, frame_format: str) -> None:
    """Write one frame array (or copy a frame file) to ``path``."""
    if isinstance(frame, str | os.PathLike):
        shutil.copyfile(frame, path)
        return
    arr = np.asarray(frame)
    if frame_format == "hdr":
        write_hdr(path, arr)
    elif frame_format == "exr":
        write_exr(path, arr.astype(np.float32))
    elif frame_format == "tiff":
        write_tiff(path, arr.astype(np.float32))
    else:
        dtype = np.uint8 if frame_format == "png8" else np.uint16
        if arr.dtype.kind == "f":  # normalised code values in [0, 1]
            if not np.all(np.isfinite(arr)):
                raise ValueError(f"{frame_format} frames cannot hold NaN or infinite values")
            arr = np.rint(np.clip(arr, 0.0, 1.0) * np.iinfo(dtype).max)
        elif arr.dtype.kind in "ui" and (arr.min() < 0 or arr.max() > np.iinfo(dtype).max):
            raise ValueError(f"{frame_format} frame codes must lie in 0-{np.iinfo(dtype).max}")
        arr = arr.astype(dtype)
        if frame_format == "tiff16":
            write_tiff(path, arr)
        else:
            write_png(path, arr)


def write_bundle(
    path: str | os.PathLike,
    *,
    site: Mapping | Sequence[float],
    camera_position: Sequence[float],
    pixel_encoding: str,
    frames: Sequence[np.ndarray | str | os.PathLike],
    times: Sequence[Any],
    facets: Facets,
    labels: np.ndarray,
    ground_reflectance: float | None = None,
    truth: Mapping | None = None,
    frame_format: str = "hdr",
    extra: Mapping | None = None,
    overwrite: bool = False,
    exposure: Sequence[float] | None = None,
    object_mesh: str | os.PathLike | None = None,
) -> Path:
    """Write a sequence bundle folder (``bayesgloss-sequence/1``).

    Everything is written to a hidden temporary folder beside ``path`` and
    renamed into place at the end, so an interrupted write never leaves a
    folder at ``path`` that looks like a complete bundle.

    Parameters
    ----------
    path : str or path-like
        The bundle folder to create. -
    site : mapping or sequence
        ``{"latitude", "longitude", "elevation"}`` or (latitude, longitude[,
        elevation]): deg north, deg EAST, m.
    camera_position : sequence of 3 float
        World position of the camera, m.
    pixel_encoding : str
        ``camera.pixel_encoding`` of the frames as given (see
        :data:`PIXEL_ENCODINGS`); frames are written as given, no curve is
        applied. -
    frames : sequence of arrays (H, W, 3) or of image paths
        Arrays are written in ``frame_format``; paths are copied as they are.
        For ``png8``/``png16``/``tiff16`` a float array holds normalised code
        values in [0, 1] (rounded to the nearest code) and an integer array
        the codes themselves. -
    times : sequence of tz-aware times
        One per frame: pandas Timestamps, datetimes or ISO strings with a UTC
        offset; written in ISO 8601 with their offset. -
    facets : Facets
        Ids (1-65535), unit normals and centres (m) of the facets.
    labels : ndarray (H, W) of int
        Facet id of each pixel, 0 for background; written as ``facets.png``,
        8-bit when every id is below 256, else 16-bit. -
    ground_reflectance : float, optional
        Albedo of the ground, -.
    truth : mapping, optional
        What made the bundle (material, specularity, ...). -
    frame_format : {"hdr", "png16", "png8", "tiff", "tiff16", "exr"}
        File format of array frames: Radiance RGBE, PNG, float32 or 16-bit
        TIFF, OpenEXR (float32). -
    extra : mapping, optional
        More top-level manifest fields (readers ignore what they do not know). -
    overwrite : bool, default False
        Replace an existing folder at ``path``. -
    exposure : sequence of float, optional
        ``frames[].exposure``: each frame's relative exposure, > 0, one per
        frame (a linear factor between radiance and pixel value, any common
        scale) [-].
    object_mesh : str or path-like, optional
        A triangle mesh file (OBJ or PLY, world frame, metres) copied into the
        bundle as ``object_mesh.obj`` or ``object_mesh.ply`` and named by the
        manifest's ``object_mesh``. -

    Returns
    -------
    Path
        The bundle folder.

    Raises
    ------
    ValueError
        For inputs that would make a bad bundle (the message names the
        manifest field; a :class:`BundleError` for what :func:`read_bundle`
        rejects, such as a camera position behind every facet), or an
        unknown ``frame_format``.
    FileExistsError
        When ``path`` exists and ``overwrite`` is False.
    """
    root = Path(path)
    if frame_format not in FRAME_FORMATS:
        raise ValueError(
            f"unknown frame_format {frame_format!r}; valid: {', '.join(FRAME_FORMATS)}"
        )
    if root.exists() and not overwrite:
        raise FileExistsError(f"bundle folder '{root}' exists (pass overwrite=True)")
    frames = list(frames)
    times = list(times)
    if len(frames) != len(times):
        raise ValueError(f"got {len(frames)} frames but {len(times)} times")
    label_arr = np.asarray(labels)
    if label_arr.ndim != 2 or label_arr.dtype.kind not in "ui":
        raise ValueError(
            f"labels must be a 2-D integer array, got {label_arr.dtype} {label_arr.shape}"
        )
    if label_arr.size and (label_arr.min() < 0 or label_arr.max() > 65535):
        raise ValueError("labels must lie in 0-65535")
    ids = np.asarray(facets.ids)
    unknown = np.setdiff1d(np.unique(label_arr), np.concatenate([[0], ids]))
    if len(unknown):
        raise ValueError(f"labels hold ids that no facet has: {unknown[:5].tolist()}")

    names = []
    for i, frame in enumerate(frames):
        if isinstance(frame, str | os.PathLike):
            names.append(f"frames/f{i:03d}{Path(frame).suffix.lower()}")
        else:
            shape = np.shape(frame)
            if shape[:2] != label_arr.shape:
                raise ValueError(f"frames[{i}] has shape {shape}, the labels {label_arr.shape}")
            names.append(f"frames/f{i:03d}{FRAME_FORMATS[frame_format]}")
    manifest = {
        "format": FORMAT,
        "site": _site_dict(site),
        "camera": {
            "position": [float(v) for v in camera_position],
            "pixel_encoding": pixel_encoding,
        },
    }
    if ground_reflectance is not None:
        manifest["ground_reflectance"] = float(ground_reflectance)
    manifest["frames"] = [
        {"file": name, "time": _iso_time(t, i)}
        for i, (name, t) in enumerate(zip(names, times, strict=True))
    ]
    if exposure is not None:
        exposure = [float(e) for e in exposure]
        if len(exposure) != len(frames):
            raise ValueError(f"got {len(frames)} frames but {len(exposure)} exposures")
        for frame, value in zip(manifest["frames"], exposure, strict=True):
            frame["exposure"] = value
    mesh_name = None
    if object_mesh is not None:
        mesh_name = f"object_mesh{Path(object_mesh).suffix.lower()}"
        if not Path(object_mesh).is_file():
            raise ValueError(f"object_mesh: no mesh file '{object_mesh}'")
    manifest["facets"] = [
        {
            "id": int(fid),
            "normal": np.asarray(n, float).tolist(),
            "center": np.asarray(c, float).tolist(),
        }
        for fid, n, c in zip(ids, facets.normal, facets.center, strict=True)
    ]
    if mesh_name is not None:
        manifest["object_mesh"] = mesh_name
    if truth is not None:
        manifest["truth"] = dict(truth)
    for key, value in (extra or {}).items():
        manifest.setdefault(key, value)
    parsed = _parse_manifest(json.loads(json.dumps(manifest)), root)  # the reader's checks
    held = np.isin(ids, label_arr)
    if not np.all(held):
        raise BundleError(
            root,
            f"facets[{int(np.argmin(held))}].id",
            f"facet id {ids[~held][0]} has no pixel in labels",
        )
    _check_camera(_Checker(root), parsed.camera_position, parsed.facets)

    root.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{root.name}.partial-", dir=root.parent))
    umask = os.umask(0o022)
    os.umask(umask)
    os.chmod(tmp, 0o777 & ~umask)  # mkdtemp makes it private
    try:
        (tmp / "frames").mkdir()
        for frame, name in zip(frames, names, strict=True):
            _frame_file(frame, tmp / name, frame_format)
        write_png(tmp / LABELS, label_arr.astype(np.uint8 if ids.max() < 256 else np.uint16))
        if mesh_name is not None:
            shutil.copyfile(object_mesh, tmp / mesh_name)
        text = json.dumps(manifest, indent=2, allow_nan=False)
        (tmp / MANIFEST).write_text(text + "\n", encoding="utf-8")
        if root.exists():  # overwrite: move the old bundle aside, then swap
            old = Path(tempfile.mkdtemp(prefix=f".{root.name}.old-", dir=root.parent))
            os.replace(root, old / root.name)
            os.replace(tmp, root)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(tmp, root)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return root

"""Sequence bundles from a real camera: photos, a calibrated camera and a mesh.

:func:`make_bundle` (``bayesgloss bundle make``) writes a ``bayesgloss-sequence/1``
bundle from what a user of a tripod camera has:

- a triangle **mesh** of the object (OBJ, PLY or STL, read by ``trimesh``) in
  the world frame (x east, y north, z up, metres), or with a 4 x 4 transform
  into it (:func:`load_mesh`);
- a **camera** file (JSON, :func:`read_camera`): OpenCV's pinhole model with
  its distortion, and the pose;
- the **photos** (JPEG, PNG, TIFF) with their times, exposures and, perhaps,
  the site in EXIF (:func:`photo_time`, :func:`photo_exposure`,
  :func:`photo_site`).

The camera file
---------------
One JSON object, OpenCV's conventions throughout::

    {"width": 4000, "height": 3000,
     "fx": 3200.0, "fy": 3200.0, "cx": 1999.5, "cy": 1499.5,
     "distortion": [k1, k2, p1, p2, k3],
     "rotation": [[r11, r12, r13], [r21, r22, r23], [r31, r32, r33]],
     "position": [x, y, z]}

``width``, ``height``: the photos' size in pixels, as stored (EXIF
orientation is not applied). ``fx``, ``fy``, ``cx``, ``cy``: focal lengths and
principal point in pixels, in OpenCV's pixel coordinates: u to the right, v
down, the *centre* of the top-left pixel at (0, 0) (so the image's centre is
((width - 1) / 2, (height - 1) / 2)). ``distortion``: OpenCV's
``distCoeffs`` (k1, k2, p1, p2[, k3]), optional, default none; a point of
normalised coordinates (x, y) = (X_c / Z_c, Y_c / Z_c) is imaged at
u = fx x'' + cx, v = fy y'' + cy with (:func:`distort`)
x'' = x (1 + k1 r^2 + k2 r^4 + k3 r^6) + 2 p1 x y + p2 (r^2 + 2 x^2),
y'' = y (1 + k1 r^2 + k2 r^4 + k3 r^6) + p1 (r^2 + 2 y^2) + 2 p2 x y.
``rotation``: OpenCV's R, world to camera, as a 3 x 3 matrix or a
Rodrigues vector (``rvec``); its rows are the camera's axes in the world
frame: x to the right of the image, y down it, z along the optical axis.
``position``: the camera's centre C in the world frame [m]; or, instead,
``translation``: OpenCV's ``tvec`` t, with C = -R^T t. A world point X is then
at X_c = R (X - C) in the camera.

The label image is made in the *distorted* camera: frames are written as
stored (no resampling), and each pixel's rays are the undistorted
directions of its points (:func:`undistort`).

Facets and labels
-----------------
Facets are the mesh's near-planar regions (:func:`planar_regions`): faces
joined across shared edges while their normals lie within ``facet_angle``
of the region's seed face, never across the mesh's own groups (an OBJ's
``usemtl`` materials, a scene's separate geometries). Each facet's normal
and centre are the area-weighted means of its faces' normals and centroids
(the normal turned toward the camera where the mesh's winding made it face
away, with a warning). The label image (:func:`label_image`) casts a ray
through each pixel's centre and its four corners (``trimesh``'s ray
casting); a pixel is labelled with a facet only when all five rays first
hit that facet: wholly inside it and not occluded, edge and mixed pixels
left out, as the labels of :mod:`bayesgloss.sequences` are. Facets with
fewer than ``min_facet_pixels`` labelled pixels are dropped.

Times, exposures, site
----------------------
A frame's time is EXIF ``DateTimeOriginal`` (with ``SubSecTimeOriginal``)
at ``OffsetTimeOriginal``, or at a stated UTC offset for photos whose
camera wrote none. Its exposure is EXIF ``ExposureTime`` x ISO /
``FNumber``^2 (s); written as ``frames[].exposure`` when every photo has it.
The site is EXIF GPS (the first photo that has it) unless given.

JPEG frames are decoded and written as 8-bit PNG (the same codes), ``srgb``;
PNG and TIFF frames are copied as they are, with the pixel encoding given.
The mesh, in the world frame, is the bundle's ``object_mesh``.

Bad input raises :class:`CaptureError`, which names the file, the field and
the problem.
"""

from __future__ import annotations

import datetime as _dt
import math
import os
import re
import tempfile
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from . import bundle as _bundle
from .geometry import Facets

__all__ = [
    "Camera",
    "CaptureError",
    "CaptureWarning",
    "PHOTO_SUFFIXES",
    "distort",
    "undistort",
    "read_camera",
    "camera_rays",
    "project",
    "load_mesh",
    "planar_regions",
    "mesh_facets",
    "label_image",
    "photo_time",
    "photo_exposure",
    "photo_site",
    "find_photos",
    "make_bundle",
]

#: File name endings of photos read from a folder.
PHOTO_SUFFIXES = (".jpg", ".jpeg", ".png", ".tif", ".tiff")
#: File name endings of meshes.
MESH_SUFFIXES = (".obj", ".ply", ".stl")
#: Default largest angle between a facet's faces and its seed face [deg].
FACET_ANGLE = 10.0
#: Default fewest labelled pixels a facet keeps.
MIN_FACET_PIXELS = 10

# EXIF tags (CIPA DC-008-2019, Exif 2.32)
_EXIF_IFD, _GPS_IFD = 0x8769, 0x8825
_DATETIME_ORIGINAL, _OFFSET_TIME_ORIGINAL, _SUBSEC_ORIGINAL = 0x9003, 0x9011, 0x9291
_EXPOSURE_TIME, _F_NUMBER, _ISO = 0x829A, 0x829D, 0x8827
_GPS_LAT_REF, _GPS_LAT, _GPS_LON_REF, _GPS_LON, _GPS_ALT_REF, _GPS_ALT = 1, 2, 3, 4, 5, 6
_OFFSET = re.compile(r"^([+-])(\d{2}):?(\d{2})$")


class CaptureError(ValueError):
    """Bad input of :func:`make_bundle`: names the file, the field and the problem.

    Attributes
    ----------
    kind : str
        What the file is: "mesh", "camera", "photo", "photos".
    file : str
    field : str
        The file's field (``"fx"``, ``"DateTimeOriginal"``) or part.
    problem : str
    """

    def __init__(self, kind: str, file: Any, field: str, problem: str):
        self.kind, self.file, self.field, self.problem = kind, str(file), field, problem
        super().__init__(f"{kind} '{self.file}': field '{field}': {problem}")

    def __reduce__(self):
        return (type(self), (self.kind, self.file, self.field, self.problem))


class CaptureWarning(UserWarning):
    """Something odd in a capture that still makes a bundle."""


# ---------------------------------------------------------------------------
# the camera
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class Camera:
    """OpenCV's pinhole camera with distortion (see the module docstring).

    Attributes
    ----------
    width, height : int
        Image size [pixels].
    fx, fy, cx, cy : float
        Focal lengths and principal point, OpenCV pixel coordinates [pixels].
    distortion : ndarray (5,)
        k1, k2, p1, p2, k3 [-].
    rotation : ndarray (3, 3)
        World to camera (OpenCV's R) [-].
    position : ndarray (3,)
        Centre of projection, world frame [m].
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    distortion: np.ndarray
    rotation: np.ndarray
    position: np.ndarray


def distort(xy: np.ndarray, distortion: Sequence[float]) -> np.ndarray:
    """OpenCV's lens distortion of normalised image coordinates.

    Brown-Conrady radial (k1, k2, k3) and tangential (p1, p2) terms, as
    ``cv::projectPoints`` applies them (module docstring).

    Parameters
    ----------
    xy : ndarray (..., 2)
        Undistorted normalised coordinates (X_c / Z_c, Y_c / Z_c) [-].
    distortion : sequence of 4 or 5 float
        k1, k2, p1, p2[, k3] [-].

    Returns
    -------
    ndarray (..., 2)
        Distorted normalised coordinates [-].
    """
    k1, k2, p1, p2, k3 = _coefficients(distortion)
    x, y = np.asarray(xy, dtype=float)[..., 0], np.asarray(xy, dtype=float)[..., 1]
    r2 = x * x + y * y
    radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return np.stack([xd, yd], axis=-1)


def undistort(
    xy: np.ndarray, distortion: Sequence[float], tol: float = 1e-12, max_iter: int = 50
) -> np.ndarray:
    """Invert :func:`distort` by Newton's method, point by point (vectorised).

    Parameters
    ----------
    xy : ndarray (..., 2)
        Distorted normalised coordinates [-].
    distortion : sequence of 4 or 5 float
        k1, k2, p1, p2[, k3] [-].
    tol : float
        Largest residual |distort(x) - xy| accepted [-].
    max_iter : int
        Newton steps at most [-].

    Returns
    -------
    ndarray (..., 2)
        Undistorted normalised coordinates; NaN where Newton's method did not
        reach ``tol`` (points beyond where the model is invertible) [-].
    """
    target = np.asarray(xy, dtype=float)
    k1, k2, p1, p2, k3 = _coefficients(distortion)
    if not any((k1, k2, p1, p2, k3)):
        return target.copy()
    x, y = target[..., 0].copy(), target[..., 1].copy()
    for _ in range(max_iter):
        r2 = x * x + y * y
        radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
        slope = k1 + r2 * (2 * k2 + 3 * k3 * r2)  # d radial / d r^2
        ex = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x) - target[..., 0]
        ey = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y - target[..., 1]
        if np.nanmax(np.abs(np.concatenate([np.ravel(ex), np.ravel(ey)])), initial=0) < tol:
            break
        a = radial + 2 * x * x * slope + 2 * p1 * y + 6 * p2 * x  # d xd / dx
        b = 2 * x * y * slope + 2 * p1 * x + 2 * p2 * y  # d xd / dy = d yd / dx
        d = radial + 2 * y * y * slope + 6 * p1 * y + 2 * p2 * x  # d yd / dy
        det = a * d - b * b
        with np.errstate(divide="ignore", invalid="ignore"):
            x, y = x - (d * ex - b * ey) / det, y - (a * ey - b * ex) / det
    residual = np.hypot(*np.moveaxis(distort(np.stack([x, y], -1), distortion) - target, -1, 0))
    bad = ~(residual < max(tol, 1e-9))
    x, y = np.where(bad, np.nan, x), np.where(bad, np.nan, y)
    return np.stack([x, y], axis=-1)


def _coefficients(distortion) -> tuple[float, ...]:
    d = [float(v) for v in distortion]
    if len(d) not in (4, 5):
        raise ValueError(f"distortion needs k1, k2, p1, p2[, k3], got {len(d)} values")
    return (*d, 0.0) if len(d) == 4 else tuple(d)


def _rodrigues(rvec: np.ndarray) -> np.ndarray:
    """Rotation matrix of a rotation vector (axis x angle, rad), as cv::Rodrigues."""
    theta = float(np.linalg.norm(rvec))
    if theta < 1e-15:
        return np.eye(3)
    k = rvec / theta
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(theta) * kx + (1 - math.cos(theta)) * (kx @ kx)


def read_camera(path: str | os.PathLike) -> Camera:
    """Read a camera file (JSON; the module docstring gives its fields).

    Raises
    ------
    CaptureError
        For a file that is not a JSON object, a missing field, a value of the
        wrong form (a rotation that is not a proper rotation within 1e-6,
        focal lengths or an image size that are not positive).
    """

    def fail(field: str, problem: str) -> CaptureError:
        return CaptureError("camera", path, field, problem)

    import json

    try:
        data = json.loads(Path(path).read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise fail("file", "no such file") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise fail("file", f"not a readable JSON file: {err}") from None
    if not isinstance(data, dict):
        raise fail("file", f"must be a JSON object, got {type(data).__name__}")

    def number(key: str, positive: bool = False) -> float:
        if key not in data:
            raise fail(key, "missing required field")
        value = data[key]
        if (
            isinstance(value, bool)
            or not isinstance(value, int | float)
            or not math.isfinite(value)
        ):
            raise fail(key, f"must be a finite number, got {value!r}")
        if positive and not value > 0:
            raise fail(key, f"must be > 0, got {value!r}")
        return float(value)

    def array(key: str, shapes: tuple) -> np.ndarray:
        try:
            value = np.asarray(data[key], dtype=float)
        except (TypeError, ValueError):
            raise fail(key, f"must be numbers, got {data[key]!r}") from None
        if value.shape not in shapes or not np.all(np.isfinite(value)):
            raise fail(key, f"must be {' or '.join(_shape(s) for s in shapes)}, got {data[key]!r}")
        return value

    size = {}
    for key in ("width", "height"):
        value = number(key, positive=True)
        if not value.is_integer():
            raise fail(key, f"must be a whole number of pixels, got {data[key]!r}")
        size[key] = int(value)
    intrinsics = {k: number(k, positive=k in ("fx", "fy")) for k in ("fx", "fy", "cx", "cy")}
    distortion = np.zeros(5)
    if data.get("distortion") is not None:
        given = array("distortion", ((4,), (5,)))
        distortion[: len(given)] = given
    if "rotation" not in data:
        raise fail("rotation", "missing required field")
    rotation = array("rotation", ((3, 3), (3,)))
    if rotation.shape == (3,):
        rotation = _rodrigues(rotation)
    if not (
        np.allclose(rotation @ rotation.T, np.eye(3), atol=1e-6) and np.linalg.det(rotation) > 0
    ):
        raise fail("rotation", "is not a rotation (R R^T = I and det R = +1 within 1e-6)")
    if ("position" in data) == ("translation" in data):
        raise fail("position", "give exactly one of position (C) or translation (t = -R C)")
    if "position" in data:
        position = array("position", ((3,),))
    else:
        position = -rotation.T @ array("translation", ((3,),))
    return Camera(
        size["width"], size["height"], **intrinsics, distortion=distortion,
        rotation=rotation, position=position,
    )  # fmt: skip


def _shape(shape: tuple) -> str:
    return {(3, 3): "a 3 x 3 matrix", (3,): "3 numbers"}.get(shape, f"{shape[0]} numbers")


def camera_rays(camera: Camera, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Unit world directions of the rays that image at pixel coordinates (u, v).

    Parameters
    ----------
    camera : Camera
    u, v : ndarray
        OpenCV pixel coordinates, broadcast together [pixels].

    Returns
    -------
    ndarray (..., 3)
        Unit vectors from the camera's centre, world frame; NaN where the
        distortion cannot be inverted [-].
    """
    xd = (np.asarray(u, dtype=float) - camera.cx) / camera.fx
    yd = (np.asarray(v, dtype=float) - camera.cy) / camera.fy
    xy = undistort(np.stack(np.broadcast_arrays(xd, yd), axis=-1), camera.distortion)
    d_cam = np.concatenate([xy, np.ones(xy.shape[:-1] + (1,))], axis=-1)
    d = d_cam @ camera.rotation  # R^T d_cam, on the last axis
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def project(camera: Camera, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixel coordinates (u, v) of world points, and whether each is in front.

    Parameters
    ----------
    camera : Camera
    points : ndarray (..., 3)
        World points [m].

    Returns
    -------
    uv : ndarray (..., 2)
        OpenCV pixel coordinates [pixels].
    in_front : ndarray (...) of bool
        Z_c > 0.
    """
    pc = (np.asarray(points, dtype=float) - camera.position) @ camera.rotation.T
    z = pc[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        xy = pc[..., :2] / z[..., None]
    xyd = distort(xy, camera.distortion)
    uv = np.stack([camera.fx * xyd[..., 0] + camera.cx, camera.fy * xyd[..., 1] + camera.cy], -1)
    return uv, z > 0


# ---------------------------------------------------------------------------
# the mesh and its facets
# ---------------------------------------------------------------------------


def load_mesh(path: str | os.PathLike, transform: np.ndarray | None = None):
    """A triangle mesh file in the world frame, and each face's group.

    Parameters
    ----------
    path : str or path-like
        OBJ, PLY or STL, read by ``trimesh``. An OBJ's ``usemtl`` materials
        (and a file's separate geometries) are its groups. -
    transform : ndarray (4, 4), optional
        Homogeneous transform from the file's coordinates into the world
        frame (x east, y north, z up) [m].

    Returns
    -------
    mesh : trimesh.Trimesh
        All groups in one mesh (vertices not merged across groups), world frame.
    group : ndarray (F,) of int
        Each face's group [-].

    Raises
    ------
    CaptureError
        For a file that is not a mesh of these formats, does not load, or
        holds no triangles; for a transform that is not affine and invertible.
    """
    import trimesh

    def fail(field: str, problem: str) -> CaptureError:
        return CaptureError("mesh", path, field, problem)

    path = Path(path)
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise fail("format", f"must be an OBJ, PLY or STL file ({', '.join(MESH_SUFFIXES)})")
    if not path.is_file():
        raise fail("file", "no such file")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # trimesh's notes on what it skipped
            scene = trimesh.load_scene(path)
            parts = [g for g in scene.dump() if isinstance(g, trimesh.Trimesh)]
    except Exception as err:  # trimesh raises many kinds on a damaged file
        raise fail("file", f"cannot load the mesh: {type(err).__name__}: {err}") from None
    parts = [g for g in parts if len(g.faces)]
    if not parts:
        raise fail("faces", "the file holds no triangles")
    vertices, faces, group, offset = [], [], [], 0
    for k, part in enumerate(parts):
        vertices.append(np.asarray(part.vertices, dtype=float))
        faces.append(np.asarray(part.faces) + offset)
        group.append(np.full(len(part.faces), k))
        offset += len(part.vertices)
    vertices, faces = np.concatenate(vertices), np.concatenate(faces)
    if not np.all(np.isfinite(vertices)):
        raise fail("vertices", "holds NaN or infinite coordinates")
    if transform is not None:
        m = np.asarray(transform, dtype=float)
        if m.shape != (4, 4) or not np.allclose(m[3], [0, 0, 0, 1]) or not np.all(np.isfinite(m)):
            raise fail("transform", f"must be a finite 4 x 4 affine matrix, got {m.tolist()}")
        det = np.linalg.det(m[:3, :3])
        if not abs(det) > 1e-12:
            raise fail("transform", "is not invertible")
        vertices = vertices @ m[:3, :3].T + m[:3, 3]
        if det < 0:  # a mirror turns the winding, and so the normals, inside out
            faces = faces[:, ::-1]
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    return mesh, np.concatenate(group)


def planar_regions(
    normal: np.ndarray,
    area: np.ndarray,
    adjacency: np.ndarray,
    max_angle: float = FACET_ANGLE,
    group: np.ndarray | None = None,
) -> np.ndarray:
    """Near-planar regions of a mesh by region growing over shared edges.

    Seeds are taken largest face first; a region grows across shared edges
    to faces of the same group whose normal lies within ``max_angle`` of the
    seed's normal (so any two of its faces are within twice that), until no
    neighbour qualifies. A cube's six sides are six regions at any angle
    below 90 deg; a finely tessellated sphere becomes caps of half-angle
    about ``max_angle``.

    Parameters
    ----------
    normal : ndarray (F, 3)
        Unit face normals (a zero normal, a degenerate face, is a region of
        its own) [-].
    area : ndarray (F,)
        Face areas (seed order) [m^2].
    adjacency : ndarray (E, 2) of int
        Pairs of faces that share an edge [-].
    max_angle : float
        Largest angle between a face's normal and its region's seed's [deg].
    group : ndarray (F,) of int, optional
        Faces of different groups never share a region [-].

    Returns
    -------
    ndarray (F,) of int
        Region of each face, 0, 1, ... in the order their seeds were taken [-].
    """
    from scipy import sparse

    normal = np.asarray(normal, dtype=float)
    n_faces = len(normal)
    pairs = np.asarray(adjacency, dtype=np.int64).reshape(-1, 2)
    if group is not None:
        group = np.asarray(group)
        pairs = pairs[group[pairs[:, 0]] == group[pairs[:, 1]]]
    both = np.concatenate([pairs, pairs[:, ::-1]])
    graph = sparse.csr_array(
        (np.ones(len(both), dtype=bool), (both[:, 0], both[:, 1])), shape=(n_faces, n_faces)
    )
    cos_max = math.cos(math.radians(max_angle))
    region = np.full(n_faces, -1, dtype=np.int64)
    order = np.argsort(-np.asarray(area, dtype=float), kind="stable")
    count = 0
    for seed in order:  # one pass per region; each region grows a whole ring at a time
        if region[seed] >= 0:
            continue
        seed_normal = normal[seed]
        region[seed] = count
        frontier = np.array([seed])
        while len(frontier):
            rows = graph[frontier]
            near = np.unique(rows.indices) if hasattr(rows, "indices") else np.array([], int)
            near = near[region[near] < 0]
            near = near[normal[near] @ seed_normal >= cos_max]
            region[near] = count
            frontier = near
        count += 1
    return region


def mesh_facets(
    mesh, group: np.ndarray | None = None, max_angle: float = FACET_ANGLE
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A mesh's near-planar regions (:func:`planar_regions`) and their geometry.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        World frame [m].
    group : ndarray (F,) of int, optional
        Face groups regions do not cross [-].
    max_angle : float
        [deg]

    Returns
    -------
    region : ndarray (F,) of int
        Each face's region [-].
    normal : ndarray (R, 3)
        Area-weighted mean face normal of each region, unit [-].
    center : ndarray (R, 3)
        Area-weighted mean face centroid of each region (a planar region's
        centroid) [m].
    area : ndarray (R,)
        [m^2]
    """
    face_normal = np.asarray(mesh.face_normals, dtype=float)
    face_area = np.asarray(mesh.area_faces, dtype=float)
    region = planar_regions(face_normal, face_area, mesh.face_adjacency, max_angle, group)
    n = region.max() + 1
    area = np.bincount(region, face_area, minlength=n)
    weighted = face_area[:, None] * face_normal
    normal = np.stack([np.bincount(region, weighted[:, k], minlength=n) for k in range(3)], -1)
    length = np.linalg.norm(normal, axis=-1, keepdims=True)
    normal = np.divide(normal, length, out=np.zeros_like(normal), where=length > 0)
    centroid = face_area[:, None] * np.asarray(mesh.triangles_center, dtype=float)
    center = np.stack([np.bincount(region, centroid[:, k], minlength=n) for k in range(3)], -1)
    center = np.divide(center, area[:, None], out=np.zeros_like(center), where=area[:, None] > 0)
    return region, normal, center, area


#: Rays cast at once with Embree (``embreex``; trimesh picks it where installed).
_RAY_CHUNK = 250_000


def _first_hits(mesh, origin: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Index of the first face each ray hits, -1 for none (NaN rays miss)."""
    directions = directions.reshape(-1, 3)
    hit = np.full(len(directions), -1, dtype=np.int64)
    ok = np.flatnonzero(np.all(np.isfinite(directions), axis=-1))
    chunk = _RAY_CHUNK
    if not type(mesh.ray).__module__.endswith("ray_pyembree"):
        # trimesh's own ray-triangle tests (no embreex) hold every triangle whose box
        # meets a ray's: bound the pairs held at once (a 82k-face mesh took 24 GB)
        chunk = max(64, 20_000_000 // max(len(mesh.faces), 1))
    for start in range(0, len(ok), chunk):
        index = ok[start : start + chunk]
        origins = np.broadcast_to(origin, (len(index), 3))
        hit[index] = mesh.ray.intersects_first(origins, directions[index])
    return hit


def label_image(mesh, face_region: np.ndarray, camera: Camera) -> np.ndarray:
    """Region of each pixel wholly inside one region and not occluded, -1 elsewhere.

    A ray through the pixel's centre and one through each of its four
    corners (the distorted camera: each point undistorted, module docstring)
    must all first hit faces of the same region.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        World frame [m].
    face_region : ndarray (F,) of int
        Region of each face (:func:`planar_regions`) [-].
    camera : Camera

    Returns
    -------
    ndarray (height, width) of int
        Region per pixel, -1 for background, edge and mixed pixels [-].
    """
    return _cast(mesh, face_region, camera)[0]


def _cast(mesh, face_region, camera: Camera) -> tuple[np.ndarray, np.ndarray]:
    """:func:`label_image`, and whether each pixel's centre ray met its face's front."""
    w, h = camera.width, camera.height
    lookup = np.append(np.asarray(face_region, dtype=np.int64), -1)  # -1: no hit
    u, v = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    rays = camera_rays(camera, u, v)
    face = _first_hits(mesh, camera.position, rays)
    normal = np.append(np.asarray(mesh.face_normals, dtype=float), np.zeros((1, 3)), axis=0)
    front = (np.einsum("pk,pk->p", normal[face], rays.reshape(-1, 3)) < 0).reshape(h, w)
    centre = lookup[face].reshape(h, w)
    u, v = np.meshgrid(np.arange(w + 1) - 0.5, np.arange(h + 1) - 0.5)
    corner = lookup[_first_hits(mesh, camera.position, camera_rays(camera, u, v))]
    corner = corner.reshape(h + 1, w + 1)
    whole = (
        (corner[:-1, :-1] == centre)
        & (corner[:-1, 1:] == centre)
        & (corner[1:, :-1] == centre)
        & (corner[1:, 1:] == centre)
    )
    return np.where(whole, centre, -1), front


# ---------------------------------------------------------------------------
# photos: EXIF times, exposures, site
# ---------------------------------------------------------------------------


def _exif(path: Path) -> tuple[dict, dict, dict]:
    """A photo's EXIF: the main IFD, the Exif IFD and the GPS IFD (tag -> value)."""
    from PIL import Image

    try:
        with Image.open(path) as img:
            exif = img.getexif()
            return dict(exif), dict(exif.get_ifd(_EXIF_IFD)), dict(exif.get_ifd(_GPS_IFD))
    except Exception as err:  # Pillow raises many kinds on a damaged file
        raise CaptureError("photo", path, "file", f"cannot read the photo: {err}") from None


def _utc_offset(text: str, path, field: str) -> _dt.timezone:
    match = _OFFSET.match(str(text).strip())
    if not match:
        raise CaptureError("photo", path, field, f"not a UTC offset (+HH:MM): {text!r}")
    sign, hours, minutes = match.groups()
    delta = _dt.timedelta(hours=int(hours), minutes=int(minutes))
    if delta > _dt.timedelta(hours=14) or int(minutes) >= 60:
        raise CaptureError("photo", path, field, f"UTC offset {text!r} out of range")
    return _dt.timezone(-delta if sign == "-" else delta)


def photo_time(path: str | os.PathLike, utc_offset: str | None = None) -> pd.Timestamp:
    """When a photo was taken: EXIF ``DateTimeOriginal`` at its UTC offset.

    Parameters
    ----------
    path : str or path-like
        JPEG, PNG or TIFF with EXIF. -
    utc_offset : str, optional
        ``+HH:MM``: the offset of the camera's clock, used where EXIF has no
        ``OffsetTimeOriginal``. -

    Returns
    -------
    pandas.Timestamp
        Tz-aware, at the photo's offset (``SubSecTimeOriginal`` included).

    Raises
    ------
    CaptureError
        No ``DateTimeOriginal``, an unreadable one, or no offset in EXIF and
        none given.
    """
    path = Path(path)
    _, exif, _ = _exif(path)
    stamp = exif.get(_DATETIME_ORIGINAL)
    if not stamp:
        raise CaptureError(
            "photo", path, "DateTimeOriginal", "EXIF holds no time the photo was taken"
        )
    try:
        when = _dt.datetime.strptime(str(stamp).strip().rstrip("\x00"), "%Y:%m:%d %H:%M:%S")
    except ValueError:
        raise CaptureError(
            "photo", path, "DateTimeOriginal", f"not a time 'YYYY:MM:DD HH:MM:SS': {stamp!r}"
        ) from None
    subsec = str(exif.get(_SUBSEC_ORIGINAL, "")).strip().rstrip("\x00")
    if subsec.isdigit():
        when += _dt.timedelta(seconds=float(f"0.{subsec}"))
    offset = exif.get(_OFFSET_TIME_ORIGINAL)
    if offset:
        zone = _utc_offset(str(offset).rstrip("\x00"), path, "OffsetTimeOriginal")
    elif utc_offset is not None:
        zone = _utc_offset(utc_offset, "--utc-offset", "--utc-offset")
    else:
        raise CaptureError(
            "photo",
            path,
            "OffsetTimeOriginal",
            f"EXIF gives the time {stamp} but no UTC offset; give the camera clock's "
            "offset with --utc-offset +HH:MM",
        )
    return pd.Timestamp(when.replace(tzinfo=zone))


def photo_exposure(path: str | os.PathLike) -> float | None:
    """A photo's relative exposure from EXIF: ExposureTime x ISO / FNumber^2.

    The factor between scene radiance and the sensor's linear signal, up to
    one scale for a camera and lens (the spec's ``frames[].exposure``).

    Returns
    -------
    float or None
        [s] (ISO and f-number are unitless); None where EXIF lacks any of
        the three or holds a non-positive one.
    """
    _, exif, _ = _exif(Path(path))
    values = []
    for tag in (_EXPOSURE_TIME, _F_NUMBER, _ISO):
        value = exif.get(tag)
        if isinstance(value, tuple | list):  # ISO may be a list of speeds
            value = value[0] if value else None
        try:
            value = float(value)
        except (TypeError, ValueError, ZeroDivisionError):
            return None
        if not (math.isfinite(value) and value > 0):
            return None
        values.append(value)
    time, f_number, iso = values
    return time * iso / f_number**2  # exposure ~ t S / N^2 (ISO 12232 exposure index)


def _degrees(value) -> float:
    d, m, s = (float(v) for v in value)
    return d + m / 60 + s / 3600


def photo_site(path: str | os.PathLike) -> tuple[float, float, float | None] | None:
    """Latitude and longitude (deg, north and east positive) and altitude (m)
    from EXIF GPS; None where the photo has no GPS position."""
    _, _, gps = _exif(Path(path))
    if _GPS_LAT not in gps or _GPS_LON not in gps:
        return None
    try:
        lat = _degrees(gps[_GPS_LAT]) * (-1 if str(gps.get(_GPS_LAT_REF, "N"))[:1] == "S" else 1)
        lon = _degrees(gps[_GPS_LON]) * (-1 if str(gps.get(_GPS_LON_REF, "E"))[:1] == "W" else 1)
    except (TypeError, ValueError, ZeroDivisionError):
        raise CaptureError("photo", path, "GPSLatitude", "unreadable GPS position") from None
    alt = None
    if _GPS_ALT in gps:
        try:
            below = gps.get(_GPS_ALT_REF, 0) in (1, b"\x01")
            alt = float(gps[_GPS_ALT]) * (-1 if below else 1)
        except (TypeError, ValueError, ZeroDivisionError):
            alt = None
    return lat, lon, alt


def find_photos(items: Sequence[str | os.PathLike]) -> list[Path]:
    """Photo files of folders (their JPEG, PNG and TIFF files, by name) and files.

    Raises
    ------
    CaptureError
        A path that does not exist, or no photo at all.
    """
    found = []
    for item in items:
        path = Path(item)
        if path.is_dir():
            found += sorted(p for p in path.iterdir() if p.suffix.lower() in PHOTO_SUFFIXES)
        elif path.is_file():
            found.append(path)
        else:
            raise CaptureError("photos", path, "file", "no such file or folder")
    if not found:
        raise CaptureError(
            "photos", ", ".join(map(str, items)), "file", "holds no JPEG, PNG or TIFF photo"
        )
    return found


def _photo_pixels(path: Path, camera: Camera, camera_file) -> tuple[Any, str]:
    """What the bundle gets of a photo: a uint8 array (JPEG) or the file, and its kind."""
    from PIL import Image

    from .images import image_info, image_kind

    try:
        kind = image_kind(path)
    except OSError as err:
        raise CaptureError("photo", path, "file", f"cannot read the photo: {err}") from None
    except ValueError:
        kind = "jpeg"
    if kind in ("png", "tiff"):
        try:
            info = image_info(path)
        except Exception as err:
            raise CaptureError("photo", path, "file", f"cannot read the photo: {err}") from None
        size, frame = (info.width, info.height), path
    elif kind == "jpeg":
        try:
            with Image.open(path) as img:
                frame = np.asarray(img.convert("RGB"))
        except Exception as err:
            raise CaptureError("photo", path, "file", f"cannot read the photo: {err}") from None
        size = (frame.shape[1], frame.shape[0])
    else:
        raise CaptureError("photo", path, "file", f"a {kind} file; photos are JPEG, PNG or TIFF")
    if size != (camera.width, camera.height):
        raise CaptureError(
            "photo",
            path,
            "size",
            f"is {size[0]} x {size[1]} pixels, camera '{camera_file}' says "
            f"{camera.width} x {camera.height}",
        )
    return frame, kind


# ---------------------------------------------------------------------------
# the bundle
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class MadeBundle:
    """What :func:`make_bundle` wrote: the folder, its facets and frames.

    Attributes
    ----------
    path : Path
    facets : Facets
        Ids, unit normals and centres [m] written.
    labels : ndarray (H, W) of int
    times : pandas.DatetimeIndex
    exposure : ndarray (T,) or None
        [s]
    regions : int
        Near-planar regions found in the mesh, seen or not [-].
    """

    path: Path
    facets: Facets
    labels: np.ndarray
    times: pd.DatetimeIndex
    exposure: np.ndarray | None
    regions: int


def make_bundle(
    mesh: str | os.PathLike,
    camera: str | os.PathLike,
    photos: Sequence[str | os.PathLike],
    out: str | os.PathLike,
    *,
    utc_offset: str | None = None,
    latitude: float | None = None,
    longitude: float | None = None,
    elevation: float | None = None,
    facet_angle: float = FACET_ANGLE,
    min_facet_pixels: int = MIN_FACET_PIXELS,
    transform: np.ndarray | None = None,
    pixel_encoding: str = "srgb",
    overwrite: bool = False,
) -> MadeBundle:
    """Write a sequence bundle from a mesh, a camera file and photos (module docstring).

    Parameters
    ----------
    mesh : str or path-like
        OBJ, PLY or STL of the object (:func:`load_mesh`). -
    camera : str or path-like
        Camera JSON file (:func:`read_camera`). -
    photos : sequence of str or path-like
        Photo files and folders of photos (:func:`find_photos`); frames are
        written in time order. -
    out : str or path-like
        The bundle folder to write. -
    utc_offset : str, optional
        ``+HH:MM`` of the camera's clock for photos whose EXIF has no offset. -
    latitude, longitude : float, optional
        The site [deg, north and east positive]; default EXIF GPS.
    elevation : float, optional
        [m above sea level]; default EXIF GPS altitude, else 0.
    facet_angle : float
        Largest angle between a facet's faces and its seed face [deg].
    min_facet_pixels : int
        Facets with fewer whole, unoccluded pixels are dropped [-].
    transform : ndarray (4, 4), optional
        Mesh file coordinates to the world frame [m].
    pixel_encoding : str
        ``camera.pixel_encoding`` of PNG and TIFF photos; JPEGs are ``srgb``. -
    overwrite : bool
        Replace an existing bundle at ``out``. -

    Returns
    -------
    MadeBundle

    Raises
    ------
    CaptureError
        Bad input (a mesh that does not load, a camera file missing a field,
        photos without times, EXIF without an offset and none given, a camera
        that sees no facet of the mesh), naming the file, field and problem.
    """
    cam = read_camera(camera)
    world, group = load_mesh(mesh, transform)
    files = find_photos(photos)
    if not 0 < facet_angle < 90:
        raise ValueError(f"facet_angle must lie in (0, 90) deg, got {facet_angle}")
    times = [photo_time(p, utc_offset) for p in files]
    order = np.argsort(pd.DatetimeIndex([t.tz_convert("UTC") for t in times]), kind="stable")
    files, times = [files[i] for i in order], [times[i] for i in order]
    frames, kinds = zip(*(_photo_pixels(p, cam, camera) for p in files), strict=True)

    exposures = [photo_exposure(p) for p in files]
    if all(e is not None for e in exposures):
        exposure = np.array(exposures, dtype=float)
    else:
        exposure = None
        missing = [p.name for p, e in zip(files, exposures, strict=True) if e is None]
        warnings.warn(
            f"photos: {len(missing)} of {len(files)} photos (e.g. '{missing[0]}') lack EXIF "
            "ExposureTime, FNumber or ISO: no frames[].exposure written (the estimator "
            "infers each frame's exposure)",
            CaptureWarning,
            stacklevel=2,
        )
    site = _site(files, latitude, longitude, elevation)

    region, normal, center, _ = mesh_facets(world, group, facet_angle)
    seen, front = _cast(world, region, cam)
    counts = np.bincount(seen[seen >= 0], minlength=len(normal))
    # a region whose seen faces the rays meet from behind is wound inside out: turn it
    backs = np.bincount(seen[(seen >= 0) & ~front], minlength=len(normal))
    inverted = (counts > 0) & (backs > counts / 2)
    normal = np.where(inverted[:, None], -normal, normal)
    # a curved region at the silhouette may be seen while its mean normal faces away
    facing = np.einsum("fk,fk->f", cam.position - center, normal) > 0
    keep = np.flatnonzero((counts >= min_facet_pixels) & facing)
    if not len(keep):
        raise CaptureError(
            "camera",
            camera,
            "rotation/position",
            f"the camera sees no facet of mesh '{mesh}' with {min_facet_pixels} or more whole "
            f"pixels (the most: {int(counts.max(initial=0))}); check the pose and the "
            "mesh's transform into the world frame",
        )
    if len(keep) > 65535:
        raise ValueError(f"{len(keep)} facets seen, more than a label image holds (65535)")
    if np.any(inverted[keep]):
        warnings.warn(
            f"mesh '{mesh}': the camera sees {int(inverted[keep].sum())} of {len(keep)} facets "
            "from behind by the mesh's winding (faces wound inside out); their normals are "
            "turned toward it",
            CaptureWarning,
            stacklevel=2,
        )
    ids = np.zeros(len(normal) + 1, dtype=np.int64)  # region -> id; index -1 is background
    ids[keep] = np.arange(1, len(keep) + 1)
    labels = ids[seen]
    facet_normal, facet_center = normal[keep], center[keep]
    facets = Facets(np.arange(1, len(keep) + 1), facet_normal, facet_center)

    encoding = "srgb" if all(k == "jpeg" for k in kinds) else pixel_encoding
    if "jpeg" in kinds and encoding != "srgb":
        raise CaptureError(
            "photos", files[kinds.index("jpeg")], "pixel_encoding",
            f"JPEG photos are srgb; cannot mix them with {pixel_encoding} PNG or TIFF photos",
        )  # fmt: skip
    with tempfile.TemporaryDirectory(prefix="bayesgloss-capture-") as tmp:
        mesh_file = Path(mesh)
        if transform is not None or mesh_file.suffix.lower() not in _bundle.MESH_SUFFIXES:
            mesh_file = Path(tmp) / "object_mesh.ply"  # the world-frame mesh
            world.export(mesh_file)
        path = _bundle.write_bundle(
            out,
            site=site,
            camera_position=cam.position,
            pixel_encoding=encoding,
            frames=list(frames),
            times=[t.isoformat() for t in times],
            facets=facets,
            labels=labels,
            frame_format="png8",
            exposure=exposure,
            object_mesh=mesh_file,
            extra={"capture": _provenance(mesh, camera, cam, facet_angle, min_facet_pixels)},
            overwrite=overwrite,
        )
    return MadeBundle(
        path, facets, labels, pd.DatetimeIndex(times).tz_convert("UTC"), exposure, len(normal)
    )


def _site(files: list[Path], latitude, longitude, elevation) -> dict:
    """The site from the flags, else the first photo with an EXIF GPS position."""
    if (latitude is None) != (longitude is None):
        given, other = ("--latitude", "--longitude")[:: 1 if latitude is not None else -1]
        raise CaptureError("site", given, other, f"{given} needs {other} too")
    if latitude is None:
        for path in files:
            found = photo_site(path)
            if found is not None:
                latitude, longitude, altitude = found
                if elevation is None and altitude is not None:
                    elevation = altitude
                break
        else:
            raise CaptureError(
                "photos",
                files[0].parent if len({p.parent for p in files}) == 1 else files[0],
                "GPSLatitude",
                "no photo has an EXIF GPS position; give --latitude and --longitude",
            )
    return {
        "latitude": float(latitude),
        "longitude": float(longitude),
        "elevation": 0.0 if elevation is None else float(elevation),
    }


def _provenance(mesh, camera_file, cam: Camera, facet_angle, min_facet_pixels) -> dict:
    """The manifest's ``capture`` field: how the bundle was made (readers ignore it)."""
    return {
        "made_by": "bayesgloss.capture",
        "mesh": str(mesh),
        "camera_file": str(camera_file),
        "camera": {
            "width": cam.width,
            "height": cam.height,
            "fx": cam.fx,
            "fy": cam.fy,
            "cx": cam.cx,
            "cy": cam.cy,
            "distortion": cam.distortion.tolist(),
            "rotation": cam.rotation.tolist(),
            "position": cam.position.tolist(),
        },  # fmt: skip
        "labels": "distorted camera, frames as stored; pixel centre and 4 corners on one facet",
        "facet_angle": float(facet_angle),
        "min_facet_pixels": int(min_facet_pixels),
    }

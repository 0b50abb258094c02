"""Sequence bundles from a real camera: photos, a calibrated camera and a mesh.

:func:`make_bundle` (``bayesgloss bundle make``) writes a ``bayesgloss-sequence/1``
bundle from what a user of a tripod camera has:

- a triangle **mesh** of the object (OBJ, PLY or STL, read by ``trimesh``) in
  the world frame (x east, y north, z up, metres), or with a 4 x 4 transform
  into it (:func:`load_mesh`);
- a **camera** file (JSON, :func:`bayesgloss.camera_model.read_camera`, whose
  docstring gives the fields): OpenCV's pinhole model with its distortion,
  and the pose; or a COLMAP sparse model of the photos
  (:func:`bayesgloss.camera_model.read_colmap`), in the mesh's frame;
- the **photos** (JPEG, PNG, TIFF, or camera RAW through ``rawpy``) with
  their times, exposures and, perhaps, the site in EXIF (:mod:`bayesgloss.exif`).

The label image is made in the *distorted* camera: frames are written as
stored (no resampling), and each pixel's rays are the undistorted
directions of its points (:func:`bayesgloss.camera_model.undistort`).

Facets and labels
-----------------
Facets are the mesh's near-planar regions (:func:`planar_regions`): faces
joined across shared edges while their normals lie within ``facet_angle``
of the region's seed face, never across the mesh's own groups (an OBJ's
``usemtl`` materials, a scene's separate geometries). Each facet's normal
and centre are the area-weighted means of its faces' normals and centroids.
The label image (:func:`label_image`) casts a ray through each pixel's
centre and its four corners (``trimesh``'s ray casting, with Embree through
``embreex``); a pixel is labelled with a facet only when all five rays
first hit that facet: wholly inside it and not occluded, edge and mixed
pixels left out, as the labels of :mod:`bayesgloss.sequences` are. Dropped:
facets with fewer than ``min_facet_pixels`` labelled pixels, and curved
regions at the silhouette whose mean normal faces away from the camera.
Where the rays meet most of a facet's seen faces from behind (a mesh
wound inside out), its normal is turned, with a :class:`CaptureWarning`.

Times, exposures, site
----------------------
A frame's time is EXIF ``DateTimeOriginal`` at ``OffsetTimeOriginal``, or
at a stated UTC offset for photos whose camera wrote none; frames are
written in time order. Its exposure is EXIF ``ExposureTime`` x ISO /
``FNumber``^2 (s); written as ``frames[].exposure`` when every photo has it.
The site is EXIF GPS (the first photo that has it) unless given.

JPEG frames are decoded and written as 8-bit PNG (the same codes), ``srgb``;
camera RAW frames are decoded linearly by LibRaw
(:func:`bayesgloss.images.read_raw`: black level off, the camera's white
balance, demosaiced, linear sRGB primaries, no transfer curve) and written
as 16-bit PNG, ``linear``; PNG and TIFF frames are copied as they are, with
the pixel encoding given. One bundle's photos share one encoding.
The mesh, in the world frame, is the bundle's ``object_mesh``.

Bad input raises :class:`CaptureError`, which names the file, the field and
the problem.
"""

from __future__ import annotations

import os
import tempfile
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from . import bundle as _bundle
from .camera_model import (
    Camera,
    CaptureError,
    camera_rays,
    read_camera,
    read_colmap,
    transform_camera,
)
from .exif import photo_exposure, photo_orientation, photo_site, photo_time
from .geometry import Facets
from .images import RAW_SUFFIXES

__all__ = [
    "CaptureError",
    "CaptureWarning",
    "MadeBundle",
    "PHOTO_SUFFIXES",
    "load_mesh",
    "site_frame",
    "planar_regions",
    "mesh_facets",
    "label_image",
    "find_photos",
    "make_bundle",
    "label_overlay",
]

#: File name endings of photos read from a folder (camera RAW: :data:`RAW_SUFFIXES`).
PHOTO_SUFFIXES = (".jpg", ".jpeg", ".png", ".tif", ".tiff", *RAW_SUFFIXES)
#: File name endings of meshes.
MESH_SUFFIXES = (".obj", ".ply", ".stl")
#: Default largest angle between a facet's faces and its seed face [deg].
FACET_ANGLE = 10.0
#: Default fewest labelled pixels a facet keeps.
MIN_FACET_PIXELS = 10


class CaptureWarning(UserWarning):
    """Something odd in a capture that still makes a bundle."""


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


def site_frame(north: float, origin: Sequence[float] = (0.0, 0.0, 0.0)) -> np.ndarray:
    """Transform from a site-local frame (z up, metres) into the world frame.

    A model made on site, or by CAD, often has z up but +y along a building's
    axis rather than north. Its +y points toward the bearing ``north``; its
    +x, 90 deg clockwise from that; its origin is at ``origin`` in the world.

    Parameters
    ----------
    north : float
        Bearing of the local +y axis, clockwise from true north [deg].
    origin : sequence of 3 float
        The local origin in the world frame [m].

    Returns
    -------
    ndarray (4, 4)
        World = M @ local (homogeneous column vectors) [-].
    """
    b = np.radians(north)
    m = np.eye(4)
    # local +y -> (sin b, cos b, 0) (bearing b), local +x -> (cos b, -sin b, 0) (b + 90 deg)
    m[:2, :2] = [[np.cos(b), np.sin(b)], [-np.sin(b), np.cos(b)]]
    m[:3, 3] = np.asarray(origin, dtype=float)
    return m


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
    cos_max = np.cos(np.radians(max_angle))
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
            near = np.unique(rows.indices)
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
# photos
# ---------------------------------------------------------------------------


def find_photos(items: Sequence[str | os.PathLike]) -> list[Path]:
    """Photo files of folders (their JPEG, PNG, TIFF and RAW files, by name) and files.

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
            "photos", ", ".join(map(str, items)), "file",
            "holds no photo (JPEG, PNG, TIFF or camera RAW)",
        )  # fmt: skip
    return found


def _photo_pixels(path: Path, camera: Camera, camera_file) -> tuple[Any, str]:
    """What the bundle gets of a photo: a uint8 (JPEG) or uint16 (RAW) array or the
    file, and its kind ("jpeg", "raw", "png", "tiff")."""
    from PIL import Image

    from .images import image_info, image_kind, read_raw

    try:
        if path.suffix.lower() in RAW_SUFFIXES:  # before the magic bytes: a DNG is a TIFF
            kind = "raw"
        else:
            kind = image_kind(path)
    except OSError as err:
        raise CaptureError("photo", path, "file", f"cannot read the photo: {err}") from None
    except ValueError:
        kind = "jpeg"
    if kind == "raw":
        try:
            frame = read_raw(path)
        except ImportError as err:
            raise CaptureError("photo", path, "file", str(err)) from None
        except ValueError as err:
            raise CaptureError("photo", path, "file", str(err)) from None
        size = (frame.shape[1], frame.shape[0])
    elif kind in ("png", "tiff"):
        try:
            info = image_info(path)
        except Exception as err:
            raise CaptureError("photo", path, "file", f"cannot read the photo: {err}") from None
        size, frame = (info.width, info.height), path
    elif kind == "jpeg":
        try:
            with Image.open(path) as img:
                kind = str(img.format).lower()
                frame = np.asarray(img.convert("RGB")) if kind == "jpeg" else None
        except Exception as err:
            raise CaptureError("photo", path, "file", f"cannot read the photo: {err}") from None
        if frame is None:
            raise CaptureError(
                "photo", path, "file", f"a {kind} file; photos are JPEG, PNG, TIFF or camera RAW"
            )
        size = (frame.shape[1], frame.shape[0])
    else:
        raise CaptureError(
            "photo", path, "file", f"a {kind} file; photos are JPEG, PNG, TIFF or camera RAW"
        )
    if size != (camera.width, camera.height):
        turned = ""
        if size == (camera.height, camera.width) and photo_orientation(path) >= 5:
            turned = (
                " (its EXIF Orientation turns it by 90 deg: the camera file must be of the "
                "pixels as stored)"
            )
        raise CaptureError(
            "photo",
            path,
            "size",
            f"is {size[0]} x {size[1]} pixels, camera '{camera_file}' says "
            f"{camera.width} x {camera.height}" + turned,
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
        Camera JSON file (:func:`bayesgloss.camera_model.read_camera`), or the
        folder of a COLMAP sparse model of the photos
        (:func:`bayesgloss.camera_model.read_colmap`), which is in the mesh's
        frame: ``transform`` then moves the camera too. -
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
        ``camera.pixel_encoding`` of PNG and TIFF photos; JPEGs are ``srgb``,
        camera RAW files ``linear``. -
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
    if Path(out).exists() and not overwrite:
        raise CaptureError("bundle", out, "--out", "exists; give --overwrite to replace it")
    files = find_photos(photos)
    if Path(camera).is_dir():  # a COLMAP model, in the mesh's (the reconstruction's) frame
        cam = read_colmap(camera, [p.name for p in files])
        if transform is not None:
            try:
                cam = transform_camera(cam, transform)
            except ValueError as err:
                raise CaptureError("camera", camera, "transform", str(err)) from None
    else:
        cam = read_camera(camera)
    world, group = load_mesh(mesh, transform)
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

    # JPEG is srgb and RAW linear; PNG and TIFF are as stated
    encodings = [{"jpeg": "srgb", "raw": "linear"}.get(k, pixel_encoding) for k in kinds]
    encoding = encodings[0]
    if any(e != encoding for e in encodings):
        odd = next(i for i, e in enumerate(encodings) if e != encoding)
        raise CaptureError(
            "photos", files[odd], "pixel_encoding",
            f"a {kinds[odd]} photo is {encodings[odd]}, '{files[0].name}' ({kinds[0]}) "
            f"{encoding}: one bundle's photos share one encoding (JPEG srgb, RAW linear, "
            f"PNG and TIFF {pixel_encoding})",
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
            frame_format="png16" if "raw" in kinds else "png8",
            exposure=exposure,
            object_mesh=mesh_file,
            extra={"capture": _provenance(mesh, camera, cam, facet_angle, min_facet_pixels)},
            overwrite=overwrite,
        )
    return MadeBundle(
        path, facets, labels, pd.DatetimeIndex(times).tz_convert("UTC"), exposure, len(normal)
    )


def label_overlay(frame: np.ndarray, labels: np.ndarray, alpha: float = 0.5) -> np.ndarray:
    """A frame with its label image laid over it, to check the mesh's registration.

    Each facet gets its own colour (hues by the golden angle), blended with the
    frame's pixels at ``alpha``; background and left-out pixels keep the frame.

    Parameters
    ----------
    frame : ndarray (H, W, 3) or (H, W)
        8-bit or 16-bit codes, or floats in [0, 1] [-].
    labels : ndarray (H, W) of int
        Facet id per pixel, 0 for none [-].
    alpha : float
        Weight of the facet colours [-].

    Returns
    -------
    ndarray (H, W, 3) of uint8
    """
    rgb = np.asarray(frame)
    if rgb.dtype.kind in "ui":
        rgb = rgb / float(np.iinfo(rgb.dtype).max)
    rgb = np.clip(np.nan_to_num(np.asarray(rgb, dtype=float)), 0.0, 1.0)
    if rgb.ndim == 2:
        rgb = np.repeat(rgb[..., None], 3, axis=-1)
    rgb = rgb[..., :3]
    hue = (np.arange(int(labels.max()) + 1) * 0.381966) % 1.0  # golden-angle hues
    phase = hue[:, None] + np.array([0.0, 1 / 3, 2 / 3])
    colour = 0.5 + 0.5 * np.cos(2 * np.pi * phase)  # a bright colour per hue
    mask = labels > 0
    out = rgb.copy()
    out[mask] = (1 - alpha) * rgb[mask] + alpha * colour[labels[mask]]
    return np.rint(out * 255).astype(np.uint8)


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

"""What an object's own mesh hides from its facets: the sun and the sky.

A bundle's optional ``object_mesh`` (``shared/spec/sequence-bundle.md``) is a
triangle mesh, world frame and metres, of the object and of whatever near it
shadows it or hides part of its sky. This module casts rays against it
(``trimesh`` with Embree through ``embreex``, as :mod:`bayesgloss.capture`)
and gives, for a bundle's F facets and T frames (:func:`bundle_visibility`):

``sunlit_fraction`` (F, T)
    The fraction of a fixed set of points on the facet from which a ray
    toward the centre of the sun meets no face of the mesh. 0 where the sun
    is below the horizon or behind the facet (sun_direction . normal <= 0).
``sky_view_factor`` (F,)
    The cosine-weighted fraction of the facet's hemisphere (about its
    normal) that is open sky: directions above the horizon (z > 0) whose
    rays meet no face, weighted by their cosine to the normal, over pi. 1 for
    an unoccluded horizontal facet, 1/2 for an unoccluded vertical one.
``sky_visible_fraction`` (F,)
    ``sky_view_factor`` over what the convex model gives the facet, the
    cosine-weighted part of its hemisphere above the horizon ((1 + n_z) / 2):
    1 for any facet the mesh does not hide sky from, vertical or not.
    ``sky_occluded_fraction`` = 1 - ``sky_visible_fraction`` is the part of
    the facet's upper-hemisphere sky that the mesh hides. Where the facet's
    hemisphere holds no sky (a facet facing straight down) nothing is hidden:
    visible 1, occluded 0.
``ground_visible_fraction`` (F,)
    The same for the directions below the horizon (the ground plane the
    forward model assumes): the cosine-weighted fraction whose rays meet no
    face (a face beyond the ground plane also counts as hiding it).

The facet's region of the mesh
------------------------------
Bundles give a facet as a normal and a centre only. Its faces are found by
this rule (:func:`facet_faces`): the mesh faces whose normal lies within
``angle_tolerance`` (default 10 deg, ``bundle make``'s ``--facet-angle``)
of the facet's normal and whose centroid lies within ``plane_tolerance``
(default 1 % of the mesh's size, the diagonal of its bounding box) of the
facet's plane; of those, joined into pieces across shared edges within the
mesh's groups (an OBJ's materials, as ``bundle make`` joins them), the one
piece whose area-weighted centroid is nearest the facet's centre. For a
bundle made by ``bundle make`` that piece is the facet's own region (its
centre is that region's area-weighted centroid), and coplanar facets apart
on the mesh (windows of one facade) each keep their own; two coplanar
regions that only a group boundary split are told apart, two that touch
within a group are taken as one. A facet with no such face is
a :class:`~bayesgloss.bundle.BundleError` naming ``object_mesh``.

Points and directions
---------------------
Each facet's points are :data:`N_POINTS` (64) points of a fixed stratified
set over its region: the first coordinate of an unscrambled Halton sequence
picks a face in proportion to its area, the other two a point in it
(uniform over the triangle); each point is lifted by :data:`RAY_OFFSET`
(1e-4) times the mesh's size along its face's normal before rays leave it.
The sky's directions are :data:`N_DIRECTIONS` (1024) per facet, a fixed
cosine-weighted Halton set about the facet's normal (Malley's method), each
leaving one of the facet's points in turn. Nothing is random: the same
bundle gives the same numbers. The sunlit fraction is so a multiple of 1/64
(``sunlit`` below takes 63 lit points of 64, ``shadowed`` 1 of 64); across a
shadow edge it is the lit area's fraction to within about 0.05 (a 64-point
quasi-random set on a straight edge, ~64^-3/4; against Radiance's rtrace on
a fine grid it was within 0.016, ``tests/test_visibility.py``), the sky
fractions to within about 0.01.

Classification (:func:`classify`): an entry is ``sunlit`` at a sunlit
fraction of at least :data:`SUNLIT_MIN` (0.98), ``shadowed`` at most
:data:`SHADOWED_MAX` (0.02), ``partly-shadowed`` in between.

The forward model's map
-----------------------
:func:`occlusion` (cached per bundle content by :func:`bundle_occlusion`,
in memory only: a cache inside the bundle folder is not allowed, bundles are
inputs) gives :class:`bayesgloss.render.Occlusion`, which the forward model
takes as ``occlusion=`` (:mod:`bayesgloss.render`, "Self-occlusion"): for
each facet and each cell of ``render.sphere_quadrature`` in front of it (or
within 3.4 deg behind its plane, where lobe nodes still reach) :data:`N_SUB`
(8) rays, from 8 of the facet's 64 points in turn, each through its own
stratified point of the cell; the share that meets no face is the cell's open
fraction. A blocked ray's face (turned toward the facet) and whether the
point it meets sees the sun in each frame give the mesh's own light there;
a downward open ray's ground point, whether it sees the sun (on a 256 x 256
grid over the shadow the mesh's bounding box casts, :data:`GROUND_GRID`);
from each of those points :data:`N_VIEW` (2) cosine-weighted rays find how
much of its own sky and ground the mesh hides. The sunlit fraction is
:func:`sunlit_fraction`'s. Cost: for 20,492 faces, 100 facets and 20 frames
about 8 s once (``studies/bench_occlusion.py``, 2 shared cores), then
``facet_bases`` 0.8 s instead of 0.35 s.

Which entries the estimator keeps (:func:`shadow_flags`): where the bundle
has a mesh, ``estimate`` and ``compare`` use the map, so entries wholly in
sun and entries wholly in the mesh's shadow are modelled (their sun is the
sunlit fraction, 1 or 0 to within 0.02) and kept. ``partly-shadowed``
entries are flagged and left out: the model gives them the sun times the
lit share of the facet's area, but their pixel summary weighs lit and
shadowed pixels by what the camera labels of each, and a median follows
whichever is the majority rather than the mean. (``shadowed-by-object``,
which earlier versions set to leave out wholly shadowed entries, is no
longer set.)

Limitations: the mesh's faces reflect as Lambertian surfaces of one albedo
(``occluder_reflectance``, 0.5 unless given, and stacked over 0.2, 0.5 and
0.8 by ``estimate``, :mod:`bayesgloss.occluder_albedo`: 0.2 for a building of 0.5
misplaced sun-lit courtyard walls by 10 % against rtrace, and made
``estimate`` too glossy on two renders of the L building, 0.373 for 0.270
and 0.733 for 0.667, where 0.5 held both truths:
``studies/occlusion_estimate.py``), one bounce
and a closure for the rest; the sky that the mesh hides from the ground
plane is scaled by the share of radiance the ground points' rays see (2 of
them a point); the map is on 3 deg cells, so a mirror-like lobe sees the
mesh's edges blurred by a cell. Without a mesh nothing of this runs and the
bases are the convex model's, bit for bit. :func:`facet_visibility` itself:
100 facets x 20 frames x 64 points and 1024 sky directions a facet on a
20,480-face mesh took 0.1-0.4 s on a 2-core machine, loading the mesh 0.03 s.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import bundle as bundle_io
from .bundle import BundleError
from .render import OCCLUDER_REFLECTANCE

__all__ = [
    "CLASSES",
    "N_DIRECTIONS",
    "N_POINTS",
    "RAY_OFFSET",
    "SHADOWED_MAX",
    "SUNLIT_MIN",
    "Visibility",
    "N_SUB",
    "N_VIEW",
    "GROUND_GRID",
    "bundle_occlusion",
    "bundle_visibility",
    "classify",
    "facet_faces",
    "facet_points",
    "facet_visibility",
    "load_object_mesh",
    "occlusion",
    "partly_shadowed",
    "shadow_flags",
    "sky_view",
    "sunlit_fraction",
]

#: A facet is sunlit at a sunlit fraction of at least this [-].
SUNLIT_MIN = 0.98
#: A facet is shadowed at a sunlit fraction of at most this [-].
SHADOWED_MAX = 0.02
#: Classes of :func:`classify`, by code 0, 1, 2.
CLASSES = ("sunlit", "partly-shadowed", "shadowed")
#: Points per facet the sun's rays leave from.
N_POINTS = 64
#: Sky and ground directions per facet.
N_DIRECTIONS = 1024
#: Rays leave a point lifted this much (times the mesh's size) along its face's normal.
RAY_OFFSET = 1e-4
#: Default tolerances of :func:`facet_faces`: normal angle [deg], plane distance [mesh size].
ANGLE_TOLERANCE = 10.0
PLANE_TOLERANCE = 0.01
#: Rays cast at once.
_RAY_CHUNK = 500_000


@dataclass(frozen=True, eq=False)
class Visibility:
    """What a mesh hides from F facets in T frames (module docstring).

    Attributes
    ----------
    sunlit_fraction : ndarray (F, T)
        Fraction of the facet's points that see the sun's centre [-].
    sky_view_factor, sky_visible_fraction, sky_occluded_fraction : ndarray (F,)
        Cosine-weighted open sky of the facet's hemisphere; its share of the
        convex model's; the share hidden [-].
    ground_visible_fraction : ndarray (F,)
        Cosine-weighted share of the facet's below-horizon directions not
        hidden by the mesh [-].
    n_faces : ndarray (F,) of int
        Mesh faces found for each facet.
    area : ndarray (F,)
        Their area [m^2].
    sun_in_front : ndarray (F, T) of bool
        Sun above the horizon and in front of the facet: where the convex
        model gives the facet direct sun.
    """

    sunlit_fraction: np.ndarray
    sky_view_factor: np.ndarray
    sky_visible_fraction: np.ndarray
    sky_occluded_fraction: np.ndarray
    ground_visible_fraction: np.ndarray
    n_faces: np.ndarray
    area: np.ndarray
    sun_in_front: np.ndarray

    @property
    def classes(self) -> np.ndarray:
        """:func:`classify` of the sunlit fraction, (F, T) codes into :data:`CLASSES`."""
        return classify(self.sunlit_fraction)

    @property
    def partly_shadowed(self) -> np.ndarray:
        """Entries partly in shadow, (F, T) bool: the estimator leaves them out."""
        return partly_shadowed(self.sunlit_fraction)

    @property
    def shadowed_by_object(self) -> np.ndarray:
        """Entries in shadow where the convex model gives direct sun, (F, T) bool."""
        return (classify(self.sunlit_fraction) == 2) & self.sun_in_front


def classify(sunlit_fraction) -> np.ndarray:
    """Sunlit (0), partly shadowed (1) or shadowed (2), by the sunlit fraction.

    Parameters
    ----------
    sunlit_fraction : array_like
        Fractions [-]; NaN gives -1.

    Returns
    -------
    ndarray of int8, the shape of ``sunlit_fraction``
        Codes into :data:`CLASSES`: 0 at >= :data:`SUNLIT_MIN`, 2 at <=
        :data:`SHADOWED_MAX`, 1 in between.
    """
    x = np.asarray(sunlit_fraction, dtype=float)
    out = np.where(x >= SUNLIT_MIN, 0, np.where(x <= SHADOWED_MAX, 2, 1)).astype(np.int8)
    out[np.isnan(x)] = -1
    return out


def partly_shadowed(sunlit_fraction) -> np.ndarray:
    """Entries partly in shadow (class ``partly-shadowed``), bool of the input's shape."""
    return classify(sunlit_fraction) == 1


# ---------------------------------------------------------------------------
# the mesh and the facets' regions of it
# ---------------------------------------------------------------------------


def load_object_mesh(bundle):
    """The bundle's ``object_mesh`` as (trimesh.Trimesh, group of each face), or None.

    Raises
    ------
    BundleError
        Naming the bundle and ``object_mesh``, where the mesh is missing or
        does not load (one line).
    """
    from .capture import CaptureError, load_mesh

    name = bundle.manifest.get("object_mesh")
    if not name:
        return None
    path = Path(bundle.path) / name
    if not path.is_file():
        raise BundleError(bundle.path, "object_mesh", f"missing mesh '{name}'")
    try:
        return load_mesh(path)
    except CaptureError as err:
        raise BundleError(bundle.path, "object_mesh", f"mesh '{name}': {err.problem}") from None


def _size(mesh) -> float:
    """Diagonal of the mesh's bounding box [m] (1 for a degenerate box)."""
    lo, hi = np.asarray(mesh.bounds, dtype=float)
    size = float(np.linalg.norm(hi - lo))
    return size if size > 0 else 1.0


def facet_faces(
    mesh,
    normal,
    center,
    group=None,
    *,
    angle_tolerance: float = ANGLE_TOLERANCE,
    plane_tolerance: float | None = None,
) -> np.ndarray:
    """Facet of each mesh face by the rule of the module docstring, -1 for none.

    Parameters
    ----------
    mesh : trimesh.Trimesh
    normal, center : array_like (F, 3)
        Facets' unit normals and centres [-], [m].
    group : array_like (M,) of int, optional
        Each face's group; pieces do not cross groups.
    angle_tolerance : float
        Largest angle between a face's normal and the facet's [deg].
    plane_tolerance : float, optional
        Largest distance of a face's centroid from the facet's plane [m];
        default 1 % of the mesh's size.

    Returns
    -------
    ndarray (M,) of int
        Index of the facet each face belongs to; -1 for faces of none. Pieces
        join faces across shared edges where one facet accepts both, so
        coplanar facets apart on the mesh (windows of one facade) each get
        their own; a face in the pieces of two facets goes to the one whose
        centre is nearer its centroid.
    """
    from scipy.sparse import coo_matrix, csr_matrix
    from scipy.sparse.csgraph import connected_components

    normal = np.atleast_2d(np.asarray(normal, dtype=float))
    center = np.atleast_2d(np.asarray(center, dtype=float))
    tol = PLANE_TOLERANCE * _size(mesh) if plane_tolerance is None else float(plane_tolerance)
    n_faces, n_facets = len(mesh.faces), len(normal)
    group = np.zeros(n_faces, int) if group is None else np.asarray(group)
    face_normal = np.asarray(mesh.face_normals, dtype=float)
    centroid = np.asarray(mesh.triangles_center, dtype=float)
    area = np.asarray(mesh.area_faces, dtype=float)
    cos_tol = np.cos(np.radians(angle_tolerance))
    offset = np.sum(normal * center, -1)  # the facets' planes: x . normal = offset
    # (face, facet) pairs the rule accepts, a (faces, facets) block at a time
    rows, cols = [], []
    chunk = max(1, 4_000_000 // max(n_facets, 1))
    for s in range(0, n_faces, chunk):
        cos = face_normal[s : s + chunk] @ normal.T
        dist = np.abs(centroid[s : s + chunk] @ normal.T - offset)
        r, c = np.nonzero((cos >= cos_tol) & (dist <= tol))
        rows.append(r + s)
        cols.append(c)
    rows, cols = np.concatenate(rows), np.concatenate(cols)
    accept = csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(n_faces, n_facets))
    # pieces: faces joined across shared edges within a group where one facet accepts both
    adj = np.asarray(mesh.face_adjacency).reshape(-1, 2)
    a, b = adj[:, 0], adj[:, 1]
    common = np.asarray(accept[a].multiply(accept[b]).sum(axis=1)).ravel() > 0
    join = common & (group[a] == group[b])
    graph = coo_matrix((np.ones(join.sum()), (a[join], b[join])), shape=(n_faces, n_faces))
    _, piece = connected_components(graph, directed=False)
    # each (piece, facet) pair's accepted faces: area-weighted centroid, gap to the centre
    pair_key = piece[rows].astype(np.int64) * n_facets + cols
    pairs, pair = np.unique(pair_key, return_inverse=True)
    pair_facet = pairs % n_facets
    w = np.bincount(pair, area[rows], len(pairs))
    c = (
        np.stack(
            [np.bincount(pair, area[rows] * centroid[rows, k], len(pairs)) for k in range(3)], -1
        )
        / np.maximum(w, 1e-300)[:, None]
    )
    gap = np.linalg.norm(c - center[pair_facet], axis=-1)
    # one piece per facet: the centroid nearest its centre
    order = np.lexsort((gap, pair_facet))
    chosen = np.zeros(len(pairs), bool)
    chosen[order[np.diff(pair_facet[order], prepend=-1) != 0]] = True
    keep = chosen[pair]
    r, f = rows[keep], cols[keep]
    # a face in two facets' pieces: the facet whose centre is nearer
    near = np.linalg.norm(centroid[r] - center[f], axis=-1)
    order = np.lexsort((near, r))
    first = order[np.diff(r[order], prepend=-1) != 0]
    out = np.full(n_faces, -1)
    out[r[first]] = f[first]
    return out


def _halton(n: int, dims: int) -> np.ndarray:
    """The first ``n`` points of the unscrambled Halton sequence after its origin, (n, dims)."""
    from scipy.stats import qmc

    return qmc.Halton(d=dims, scramble=False).random(n + 1)[1:]


def facet_points(mesh, face_facet, n_facets: int, n_points: int = N_POINTS):
    """A fixed stratified set of points on each facet's faces (module docstring).

    Parameters
    ----------
    mesh : trimesh.Trimesh
    face_facet : ndarray (M,) of int
        Facet of each face, -1 for none (:func:`facet_faces`).
    n_facets : int
        F; every facet needs at least one face.
    n_points : int
        Points per facet.

    Returns
    -------
    points : ndarray (F, P, 3)
        On the faces [m].
    normals : ndarray (F, P, 3)
        Their faces' unit normals.
    """
    face_facet = np.asarray(face_facet)
    area = np.where(face_facet >= 0, np.asarray(mesh.area_faces, dtype=float), 0.0)
    order = np.argsort(face_facet, kind="stable")
    order = order[face_facet[order] >= 0]
    cum = np.cumsum(area[order])
    facet_area = np.bincount(face_facet[order], area[order], minlength=n_facets)
    start = np.concatenate([[0.0], np.cumsum(facet_area)[:-1]])
    u = _halton(n_points, 3)  # (P, 3)
    # the face: the first coordinate through each facet's cumulative area
    target = start[:, None] + u[None, :, 0] * facet_area[:, None]  # (F, P)
    k = np.minimum(np.searchsorted(cum, target, side="right"), len(order) - 1)
    face = order[k]
    # uniform in the triangle: sqrt(u1) along the median, u2 across
    tri = np.asarray(mesh.triangles, dtype=float)[face]  # (F, P, 3, 3)
    r = np.sqrt(u[:, 1])[None, :, None]
    s = u[None, :, 2, None]
    points = (1 - r) * tri[..., 0, :] + r * (1 - s) * tri[..., 1, :] + r * s * tri[..., 2, :]
    return points, np.asarray(mesh.face_normals, dtype=float)[face]


def _occluded(mesh, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Whether each ray meets a face of the mesh, (N,) bool."""
    origins = origins.reshape(-1, 3)
    directions = directions.reshape(-1, 3)
    out = np.zeros(len(origins), bool)
    for s in range(0, len(origins), _RAY_CHUNK):
        out[s : s + _RAY_CHUNK] = mesh.ray.intersects_any(
            origins[s : s + _RAY_CHUNK], directions[s : s + _RAY_CHUNK]
        )
    return out


def _lift(mesh, points, normals) -> np.ndarray:
    return points + RAY_OFFSET * _size(mesh) * normals


def sunlit_fraction(mesh, points, point_normals, normal, sun_direction) -> np.ndarray:
    """Fraction of each facet's points that see the sun's centre, (F, T).

    Parameters
    ----------
    mesh : trimesh.Trimesh
    points, point_normals : ndarray (F, P, 3)
        Points on the facets [m] and their faces' normals (:func:`facet_points`).
    normal : array_like (F, 3)
        Facets' unit normals.
    sun_direction : array_like (T, 3)
        Unit vectors toward the sun.

    Returns
    -------
    ndarray (F, T)
        0 where the sun is below the horizon (z <= 0) or behind the facet
        (sun_direction . normal <= 0); otherwise the fraction of points whose
        ray toward the sun meets no face [-].
    """
    normal = np.atleast_2d(np.asarray(normal, dtype=float))
    sun = np.atleast_2d(np.asarray(sun_direction, dtype=float))
    n_f, n_p = points.shape[:2]
    front = (sun[None, :, 2] > 0) & (normal @ sun.T > 0)  # (F, T)
    out = np.zeros(front.shape)
    f_idx, t_idx = np.nonzero(front)
    if not len(f_idx):
        return out
    origins = np.broadcast_to(_lift(mesh, points, point_normals)[f_idx], (len(f_idx), n_p, 3))
    dirs = np.broadcast_to(sun[t_idx][:, None, :], (len(f_idx), n_p, 3))
    blocked = _occluded(mesh, np.ascontiguousarray(origins), np.ascontiguousarray(dirs))
    out[f_idx, t_idx] = 1.0 - blocked.reshape(len(f_idx), n_p).mean(1)
    return out


def _cosine_directions(normal: np.ndarray, n: int) -> np.ndarray:
    """A fixed cosine-weighted set of n directions about each normal, (F, n, 3)."""
    u = _halton(n, 2)
    r, phi = np.sqrt(u[:, 0]), 2 * np.pi * u[:, 1]  # Malley: uniform disc, lifted
    local = np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(1 - u[:, 0])], -1)
    # an orthonormal frame (e1, e2, normal) of each facet
    helper = np.where(np.abs(normal[:, 2:3]) < 0.9, [0.0, 0.0, 1.0], [1.0, 0.0, 0.0])
    e1 = np.cross(helper, normal)
    e1 /= np.linalg.norm(e1, axis=-1, keepdims=True)
    e2 = np.cross(normal, e1)
    return (
        local[None, :, 0:1] * e1[:, None]
        + local[None, :, 1:2] * e2[:, None]
        + local[None, :, 2:3] * normal[:, None]
    )


def sky_view(mesh, points, point_normals, normal, n_directions: int = N_DIRECTIONS):
    """Sky view factor, visible and occluded fractions of the sky, visible ground, (F,) each.

    Parameters
    ----------
    mesh : trimesh.Trimesh
    points, point_normals : ndarray (F, P, 3)
        Points on the facets [m] and their faces' normals.
    normal : array_like (F, 3)
        Facets' unit normals.
    n_directions : int
        Cosine-weighted directions per facet, each leaving one point in turn.

    Returns
    -------
    sky_view_factor, sky_visible_fraction, sky_occluded_fraction, ground_visible_fraction
        Module docstring [-].
    """
    normal = np.atleast_2d(np.asarray(normal, dtype=float))
    n_f, n_p = points.shape[:2]
    dirs = _cosine_directions(normal, n_directions)  # (F, D, 3)
    which = np.arange(n_directions) % n_p
    origins = _lift(mesh, points, point_normals)[:, which]  # (F, D, 3)
    blocked = _occluded(mesh, origins, dirs).reshape(n_f, n_directions)
    up = dirs[..., 2] > 0
    n_up, n_down = up.sum(1), (~up).sum(1)
    open_sky = (up & ~blocked).sum(1)
    open_ground = (~up & ~blocked).sum(1)
    view_factor = open_sky / n_directions
    visible = np.where(n_up > 0, open_sky / np.maximum(n_up, 1), 1.0)
    ground = np.where(n_down > 0, open_ground / np.maximum(n_down, 1), 1.0)
    return view_factor, visible, 1.0 - visible, ground


def facet_visibility(
    mesh,
    normal,
    center,
    sun_direction,
    group=None,
    *,
    n_points: int = N_POINTS,
    n_directions: int = N_DIRECTIONS,
    angle_tolerance: float = ANGLE_TOLERANCE,
    plane_tolerance: float | None = None,
    ids=None,
) -> Visibility:
    """Sun and sky visibility of facets (normal, centre) of a mesh.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        World frame [m].
    normal, center : array_like (F, 3)
        Facets' unit normals and centres [-], [m].
    sun_direction : array_like (T, 3)
        Unit vectors toward the sun.
    group : array_like (M,), optional
        Each face's group (:func:`bayesgloss.capture.load_mesh`).
    n_points, n_directions : int
        Points per facet, sky directions per facet.
    angle_tolerance, plane_tolerance
        :func:`facet_faces` [deg], [m].
    ids : array_like (F,), optional
        Facet ids, to name a facet in an error (default: its index).

    Returns
    -------
    Visibility

    Raises
    ------
    ValueError
        For a facet that no face of the mesh belongs to (naming its index).
    """
    normal = np.atleast_2d(np.asarray(normal, dtype=float))
    center = np.atleast_2d(np.asarray(center, dtype=float))
    sun = np.atleast_2d(np.asarray(sun_direction, dtype=float))
    face_facet = facet_faces(
        mesh,
        normal,
        center,
        group,
        angle_tolerance=angle_tolerance,
        plane_tolerance=plane_tolerance,
    )
    n_f = len(normal)
    n_faces = np.bincount(face_facet[face_facet >= 0], minlength=n_f)
    if np.any(n_faces == 0):
        f = int(np.flatnonzero(n_faces == 0)[0])
        name = f"facet {f}" if ids is None else f"facet id {int(np.asarray(ids)[f])}"
        raise ValueError(
            f"no face of the mesh lies on {name}'s plane (normal {normal[f].round(4).tolist()}, "
            f"centre {center[f].round(4).tolist()}) within {angle_tolerance:g} deg"
            + (
                f" ({int(np.sum(n_faces == 0)) - 1} more facets)"
                if np.sum(n_faces == 0) > 1
                else ""
            )
        )
    area = np.bincount(face_facet[face_facet >= 0], mesh.area_faces[face_facet >= 0], n_f)
    points, point_normals = facet_points(mesh, face_facet, n_f, n_points)
    fraction = sunlit_fraction(mesh, points, point_normals, normal, sun)
    view, visible, occluded, ground = sky_view(mesh, points, point_normals, normal, n_directions)
    return Visibility(
        sunlit_fraction=fraction,
        sky_view_factor=view,
        sky_visible_fraction=visible,
        sky_occluded_fraction=occluded,
        ground_visible_fraction=ground,
        n_faces=n_faces,
        area=area,
        sun_in_front=(sun[None, :, 2] > 0) & (normal @ sun.T > 0),
    )


def bundle_visibility(bundle, **kwargs) -> Visibility | None:
    """:func:`facet_visibility` of a bundle's facets and frames, or None without a mesh.

    Parameters
    ----------
    bundle : bayesgloss.bundle.Bundle
    **kwargs
        For :func:`facet_visibility`.

    Raises
    ------
    BundleError
        Naming the bundle and ``object_mesh``: a mesh missing, not loading, or
        without faces on a facet's plane.
    """
    loaded = load_object_mesh(bundle)
    if loaded is None:
        return None
    mesh, group = loaded
    facets = bundle.facets
    try:
        return facet_visibility(
            mesh,
            facets.normal,
            facets.center,
            bundle.sun_direction,
            group,
            ids=facets.ids,
            **kwargs,
        )
    except ValueError as err:
        raise BundleError(bundle.path, "object_mesh", str(err)) from None


# ---------------------------------------------------------------------------
# the forward model's view: a visibility map over its quadrature
# ---------------------------------------------------------------------------

#: Points of a facet each quadrature direction's rays leave from.
N_SUB = 8
#: Rays from each point a facet's ray meets (mesh or ground) to find how much
#: of that point's own sky and ground the mesh hides.
N_VIEW = 2
#: Cells cast: those whose centre lies above the facet's plane or within this
#: (sine of 3.4 deg, more than half a 3 deg cell) below it, where a lobe's or
#: the cosine's directions still reach [-].
_BELOW_PLANE = 0.06
#: Rays along a cell centre less than this above the facet's plane are tilted
#: up to it, so they do not meet the facet's own faces [-].
_MIN_ELEVATION = 0.02


def _cell_points(resolution: float, cells, n: int) -> np.ndarray:
    """``n`` directions spread over each quadrature cell, (C, n, 3).

    A fixed 2-D Halton set of ``n`` points, turned by a different amount in
    each cell (Kronecker step by the cell's index), maps to the cell's height
    range (uniform in z: equal solid angle) and azimuth range.
    """
    from .render import _rings

    n_rings, n_phi, start = _rings(resolution)
    cells = np.asarray(cells)
    ring = np.searchsorted(start, cells, side="right") - 1
    j = cells - start[ring]
    edges = np.cos(np.linspace(0.0, np.pi, n_rings + 1))
    z_hi, z_lo = edges[ring], edges[ring + 1]
    width = 2 * np.pi / n_phi[ring]
    phi_c = (j + 0.5 * (1 + ring % 2)) * width
    shift = (cells[:, None] * np.array([0.7548776662, 0.5698402910])) % 1.0  # (C, 2)
    u = (_halton(n, 2)[None] + shift[:, None]) % 1.0  # (C, n, 2)
    z = z_lo[:, None] + u[..., 0] * (z_hi - z_lo)[:, None]
    phi = phi_c[:, None] + (u[..., 1] - 0.5) * width[:, None]
    r = np.sqrt(np.maximum(1.0 - z**2, 0.0))
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], -1)


def _first_hits(mesh, origins, directions):
    """First face each ray meets: (hit (N,) bool, location (N, 3), face (N,) int)."""
    origins = np.ascontiguousarray(origins.reshape(-1, 3))
    directions = np.ascontiguousarray(directions.reshape(-1, 3))
    hit = np.zeros(len(origins), bool)
    loc = np.zeros((len(origins), 3))
    face = np.full(len(origins), -1)
    for s in range(0, len(origins), _RAY_CHUNK):
        o, d = origins[s : s + _RAY_CHUNK], directions[s : s + _RAY_CHUNK]
        where, ray, tri = mesh.ray.intersects_location(o, d, multiple_hits=False)
        hit[s + ray] = True
        loc[s + ray] = where
        face[s + ray] = tri
    return hit, loc, face


def _sees_sun(mesh, points, normals, sun, wanted) -> np.ndarray:
    """Whether points (M, 3), lifted along normals (M, 3), see the sun (T, 3), (M, T) bool.

    Only entries ``wanted`` (M, T) are cast, a frame at a time; the others
    are False.
    """
    out = np.zeros(wanted.shape, bool)
    lifted = _lift(mesh, points, normals)
    for t, s in enumerate(sun):
        m = np.flatnonzero(wanted[:, t])
        if len(m):
            out[m, t] = ~_occluded(mesh, lifted[m], np.broadcast_to(s, (len(m), 3)))
    return out


#: Ground cells a side of the grid on which :func:`_ground_sees_sun` finds the
#: mesh's shadow in each frame.
GROUND_GRID = 256


def _ground_sees_sun(mesh, points, sun, n_grid: int = GROUND_GRID) -> np.ndarray:
    """Whether ground points (M, 3) (z = 0) see the sun (T, 3), (M, T) bool.

    In each frame with the sun up, rays leave the centres of an ``n_grid`` x
    ``n_grid`` grid over the box that the mesh's bounding box casts on the
    ground; a point takes its grid cell's answer, and outside the box it is
    lit. The shadow's edge is so placed to within a cell (the box's side /
    ``n_grid``). False with the sun down.
    """
    corners = np.array(list(np.ndindex(2, 2, 2)), float)
    lo, hi = np.asarray(mesh.bounds, dtype=float)
    box = lo + corners * (hi - lo)  # (8, 3)
    out = np.zeros((len(points), len(sun)), bool)
    for t, s in enumerate(sun):
        if s[2] <= 0:
            continue
        cast = box[:, :2] - (box[:, 2:3] / s[2]) * s[:2]  # the corners cast on z = 0
        glo = np.minimum(cast.min(0), box[:, :2].min(0))
        ghi = np.maximum(cast.max(0), box[:, :2].max(0))
        step = (ghi - glo) / n_grid
        ij = np.floor((points[:, :2] - glo) / np.where(step > 0, step, 1.0)).astype(np.int64)
        inside = np.all((ij >= 0) & (ij < n_grid), axis=1)
        out[~inside, t] = True
        if not np.any(inside):
            continue
        x = glo[0] + (np.arange(n_grid) + 0.5) * step[0]
        y = glo[1] + (np.arange(n_grid) + 0.5) * step[1]
        gx, gy = np.meshgrid(x, y, indexing="ij")
        cells = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], -1)
        up = np.broadcast_to([0.0, 0.0, 1.0], cells.shape)
        lit = ~_occluded(mesh, _lift(mesh, cells, up), np.broadcast_to(s, cells.shape))
        k = ij[inside]
        out[inside, t] = lit.reshape(n_grid, n_grid)[k[:, 0], k[:, 1]]
    return out


def _open_view(mesh, points, normals, n_rays: int, n_set: int = 64):
    """Cosine-weighted rays from points (M, 3), lifted along their normals (M, 3):
    whether each meets no face (M, R) and its direction (M, R, 3). Point i takes
    directions i R ... i R + R - 1 (mod ``n_set``) of one fixed set."""
    u = _halton(n_set, 2)
    r, phi = np.sqrt(u[:, 0]), 2 * np.pi * u[:, 1]  # Malley: uniform disc, lifted
    local = np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(1 - u[:, 0])], -1)
    pick = (np.arange(len(points))[:, None] * n_rays + np.arange(n_rays)) % n_set  # (M, R)
    helper = np.where(np.abs(normals[:, 2:3]) < 0.9, [0.0, 0.0, 1.0], [1.0, 0.0, 0.0])
    e1 = np.cross(helper, normals)
    e1 /= np.maximum(np.linalg.norm(e1, axis=-1, keepdims=True), 1e-300)
    e2 = np.cross(normals, e1)
    lp = local[pick]  # (M, R, 3)
    dirs = lp[..., 0:1] * e1[:, None] + lp[..., 1:2] * e2[:, None] + lp[..., 2:3] * normals[:, None]
    origins = np.broadcast_to(_lift(mesh, points, normals)[:, None], dirs.shape)
    if not len(points):
        return np.zeros((0, n_rays), bool), dirs
    blocked = _occluded(mesh, origins, dirs).reshape(len(points), n_rays)
    return ~blocked, dirs


def _view_rays(rows, n_rows, open_, dirs, resolution):
    """Secondary rays binned by pair and quadrature cell: (open (P, K), all (P, K)) CSR counts."""
    from scipy.sparse import csr_matrix

    from .render import quadrature_cell, sphere_quadrature

    n_k = len(sphere_quadrature(resolution)[0])
    r = np.repeat(rows, open_.shape[1])
    cell = quadrature_cell(dirs.reshape(-1, 3), resolution)
    every = csr_matrix((np.ones(len(r)), (r, cell)), shape=(n_rows, n_k))
    seen = csr_matrix((open_.ravel().astype(float), (r, cell)), shape=(n_rows, n_k))
    every.sum_duplicates()
    seen.sum_duplicates()
    return seen, every


def occlusion(
    mesh,
    normal,
    center,
    sun_direction,
    group=None,
    *,
    resolution: float = 3.0,
    n_points: int = N_POINTS,
    n_sub: int = N_SUB,
    n_view: int = N_VIEW,
    interreflection: str = "lambert",
    occluder_reflectance: float = OCCLUDER_REFLECTANCE,
    angle_tolerance: float = ANGLE_TOLERANCE,
    plane_tolerance: float | None = None,
    ids=None,
):
    """What the mesh hides from each facet, on the forward model's quadrature.

    For :class:`bayesgloss.render.Occlusion` (the forward model's
    ``occlusion=``): from each of ``n_sub`` of the facet's :data:`N_POINTS`
    points (a different set for each direction, in turn through all of them)
    a ray along each direction of ``render.sphere_quadrature(resolution)``
    that lies above the facet's plane (or within 3.4 deg below it); the open
    fraction is the share of them that meets no face. Per cell, the first of
    those rays that meets a face is its representative: the face's normal and
    whether the point met sees the sun in each frame (one more ray a frame);
    per downward cell, the first ray that meets none gives the ground point
    (where it reaches z = 0) whose view of the sun is tested the same way.
    The sunlit fraction is :func:`sunlit_fraction`'s.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        World frame [m].
    normal, center : array_like (F, 3)
        Facets' unit normals and centres [-], [m].
    sun_direction : array_like (T, 3)
        Unit vectors toward the sun.
    group : array_like (M,), optional
        Each face's group.
    resolution : float
        Ring width of the quadrature [deg]; the bases must use the same.
    n_points, n_sub : int
        Points per facet; rays per facet and direction.
    interreflection : {"lambert", "none"}
        Radiance of blocked directions (:class:`bayesgloss.render.Occlusion`).
    occluder_reflectance : float
        Albedo of the mesh's faces for ``"lambert"`` [-]
        (:data:`bayesgloss.render.OCCLUDER_REFLECTANCE`, on which see
        :mod:`bayesgloss.render`).
    angle_tolerance, plane_tolerance, ids
        As :func:`facet_visibility`.

    Returns
    -------
    bayesgloss.render.Occlusion
    """
    from . import render

    normal = np.atleast_2d(np.asarray(normal, dtype=float))
    center = np.atleast_2d(np.asarray(center, dtype=float))
    sun = np.atleast_2d(np.asarray(sun_direction, dtype=float))
    face_facet = facet_faces(
        mesh,
        normal,
        center,
        group,
        angle_tolerance=angle_tolerance,
        plane_tolerance=plane_tolerance,
    )
    n_f = len(normal)
    missing = np.bincount(face_facet[face_facet >= 0], minlength=n_f) == 0
    if np.any(missing):
        f = int(np.flatnonzero(missing)[0])
        name = f"facet {f}" if ids is None else f"facet id {int(np.asarray(ids)[f])}"
        raise ValueError(
            f"no face of the mesh lies on {name}'s plane within {angle_tolerance:g} deg"
        )
    points, point_normals = facet_points(mesh, face_facet, n_f, n_points)
    lifted = _lift(mesh, points, point_normals)  # (F, P, 3)
    dirs, _ = render.sphere_quadrature(resolution)
    n_k, n_p = len(dirs), points.shape[1]
    cos = normal @ dirs.T  # (F, K)
    f_idx, k_idx = np.nonzero(cos > -_BELOW_PLANE)
    # each ray along its own stratified point of the cell; those at or below the
    # facet's plane tilted up to a small elevation above it
    d = _cell_points(resolution, k_idx, n_sub)  # (C, S, 3)
    up_n = normal[f_idx][:, None, :]
    d = d + np.maximum(_MIN_ELEVATION - np.sum(d * up_n, -1), 0.0)[..., None] * up_n
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    which = (k_idx[:, None] * n_sub + np.arange(n_sub)) % n_p  # (C, S)
    origins = lifted[f_idx[:, None], which]  # (C, S, 3)
    hit, loc, face = _first_hits(mesh, origins, d)
    hit, loc, face = hit.reshape(-1, n_sub), loc.reshape(-1, n_sub, 3), face.reshape(-1, n_sub)
    open_fraction = np.ones((n_f, n_k))
    open_fraction[f_idx, k_idx] = 1.0 - hit.mean(1)
    sun_up = sun[:, 2] > 0
    # cells with a blocked part: each blocked ray's face, turned toward the
    # facet, and whether the point it meets sees the sun
    h = np.flatnonzero(hit.any(1))
    hc, hs = np.nonzero(hit[h])  # (blocked ray) -> (cell among h, sub-ray)
    h_normal = np.asarray(mesh.face_normals, dtype=float)[face[h][hc, hs]]
    h_normal *= np.where(np.sum(h_normal * d[h][hc, hs], -1) > 0, -1.0, 1.0)[:, None]
    cos_sun = np.maximum(h_normal @ sun.T, 0.0) * sun_up  # (R, T)
    lit = _sees_sun(mesh, loc[h][hc, hs], h_normal, sun, cos_sun > 0)
    n_blocked = hit[h].sum(1)
    h_sun = np.zeros((len(h), len(sun)))
    np.add.at(h_sun, hc, cos_sun * lit)
    h_sun /= n_blocked[:, None]
    h_open, h_dirs = _open_view(mesh, loc[h][hc, hs], h_normal, n_view)
    h_rays = _view_rays(hc, len(h), h_open, h_dirs, resolution)
    h_view = np.zeros(len(h))
    np.add.at(h_view, hc, h_open.mean(1))
    h_view /= n_blocked
    mean_normal = np.zeros((len(h), 3))
    np.add.at(mean_normal, hc, h_normal)
    mean_normal /= np.maximum(np.linalg.norm(mean_normal, axis=-1, keepdims=True), 1e-12)
    # downward cells with an open part: the ground points its open rays reach
    g = np.flatnonzero((dirs[k_idx, 2] < 0) & ~hit.all(1))
    gc, gs = np.nonzero(~hit[g])
    start, ray = origins[g][gc, gs], d[g][gc, gs]
    g_loc = start - (start[:, 2:3] / np.minimum(ray[:, 2:3], -1e-12)) * ray
    g_loc[:, 2] = 0.0
    up = np.broadcast_to([0.0, 0.0, 1.0], g_loc.shape)
    g_lit = _ground_sees_sun(mesh, g_loc, sun)
    g_sun = np.zeros((len(g), len(sun)))
    np.add.at(g_sun, gc, g_lit.astype(float))
    g_open, g_dirs = _open_view(mesh, g_loc, np.ascontiguousarray(up), n_view)
    g_rays = _view_rays(gc, len(g), g_open, g_dirs, resolution)
    g_view = np.zeros(len(g))
    np.add.at(g_view, gc, g_open.mean(1))
    g_sun /= (~hit[g]).sum(1)[:, None]
    g_view /= (~hit[g]).sum(1)
    return render.Occlusion(
        open_fraction=open_fraction,
        sunlit_fraction=sunlit_fraction(mesh, points, point_normals, normal, sun),
        resolution=float(resolution),
        ground_facet=f_idx[g],
        ground_cell=k_idx[g],
        ground_lit=g_sun,
        ground_view=g_view,
        ground_rays=g_rays,
        hit_facet=f_idx[h],
        hit_cell=k_idx[h],
        hit_normal=mean_normal,
        hit_sun=h_sun,
        hit_view=h_view,
        hit_rays=h_rays,
        interreflection=interreflection,
        occluder_reflectance=occluder_reflectance,
    )


#: :func:`bundle_occlusion`'s results, by the mesh file's digest, the facets,
#: the suns and the options; the oldest go first beyond :data:`_CACHE_SIZE`.
_CACHE: dict = {}
_CACHE_SIZE = 4


def bundle_occlusion(bundle, **kwargs):
    """:func:`occlusion` of a bundle's facets and frames, or None without a mesh.

    Computed once per bundle content and kept in memory (by a digest of the
    mesh file, the facets' normals and centres, the sun directions and the
    options); never written to disk. Raises :class:`BundleError` naming
    ``object_mesh`` as :func:`bundle_visibility` does.
    """
    import hashlib

    name = bundle.manifest.get("object_mesh")
    if not name:
        return None
    path = Path(bundle.path) / name
    facets = bundle.facets
    digest = hashlib.sha256()
    try:
        digest.update(path.read_bytes())
    except OSError:
        load_object_mesh(bundle)  # the one-line error for a missing mesh
        raise
    for a in (facets.normal, facets.center, bundle.sun_direction):
        digest.update(np.ascontiguousarray(a, dtype=float).tobytes())
    digest.update(repr(sorted(kwargs.items())).encode())
    key = digest.hexdigest()
    if key in _CACHE:
        return _CACHE[key]
    mesh, group = load_object_mesh(bundle)
    try:
        out = occlusion(
            mesh,
            facets.normal,
            facets.center,
            bundle.sun_direction,
            group,
            ids=facets.ids,
            **kwargs,
        )
    except ValueError as err:
        raise BundleError(bundle.path, "object_mesh", str(err)) from None
    _CACHE[key] = out
    while len(_CACHE) > _CACHE_SIZE:
        _CACHE.pop(next(iter(_CACHE)))
    return out


def shadow_flags(bundle, curves, visibility: Visibility | None = None):
    """The facet curves with the mesh's partial shadows flagged (bundles with ``object_mesh``).

    Sets ``partly-shadowed`` where the mesh shadows part of a facet (a
    sunlit fraction between :data:`SHADOWED_MAX` and :data:`SUNLIT_MIN`),
    which leaves the entry out. Entries wholly in the mesh's shadow are not
    flagged: the forward model takes the mesh's :func:`occlusion`
    (:func:`bundle_occlusion`) and gives them no sun. (``shadowed-by-object``
    stays a flag name of :data:`bayesgloss.bundle.FLAG_REASONS` for results of
    earlier versions, which left those entries out; it is no longer set.) A
    bundle without a mesh gets ``curves`` back, the same object.

    Parameters
    ----------
    bundle : bayesgloss.bundle.Bundle
    curves : bayesgloss.bundle.FacetCurves
        Of that bundle.
    visibility : Visibility, optional
        :func:`bundle_visibility` of it, when already computed.
    """
    if visibility is None:
        if not bundle.has_mesh:
            return curves
        visibility = bundle_visibility(bundle)
    reasons = bundle_io.FLAG_REASONS
    bits = curves.flag_bits.copy()
    bits |= visibility.partly_shadowed.astype(np.uint8) << reasons.index("partly-shadowed")
    return dataclasses.replace(curves, flag_bits=bits)

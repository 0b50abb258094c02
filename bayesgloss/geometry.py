"""Object geometry: faceted shapes and the facet-camera geometry the forward model needs.

The paper's test object (Love & Efford, sec. 4) is a tessellated hemisphere of
flat facets standing on a ground plane at the origin of the world frame
(x east, y north, z up, metres). The paper does not give its tessellation;
:func:`tessellated_hemisphere` builds rings of planar quadrilaterals (each an
isosceles trapezoid, hence exactly planar) capped by a fan of triangles.
Other shapes: a :func:`box` and a brilliant-cut-like convex :func:`gem`, and
one that is not convex, an L-shaped building of two wings
(:func:`l_building`), whose wings shadow each other and hide part of each
other's sky. :func:`triangles` and :func:`write_obj` turn any of them into a
triangle mesh (the ``object_mesh`` of a bundle, ``bundle make``'s input).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = [
    "Facets",
    "tessellated_hemisphere",
    "box",
    "gem",
    "l_building",
    "triangles",
    "write_obj",
    "view_directions",
    "CAMERA_AZIMUTHS",
    "camera_position",
]

#: Camera bearings of the paper's five views, degrees clockwise from north
#: (the camera stands this way from the object and looks back at it).
CAMERA_AZIMUTHS = {"W": 270.0, "SW": 225.0, "S": 180.0, "SE": 135.0, "E": 90.0}


@dataclass(frozen=True)
class Facets:
    """Planar facets of an object.

    Attributes
    ----------
    ids : ndarray of int, shape (F,)
        Facet labels (k > 0, the value in a bundle's ``facets.png``).
    normal : ndarray, shape (F, 3)
        Outward unit normals, world frame.
    center : ndarray, shape (F, 3)
        Facet centroids, world frame [m].
    polygons : list of ndarray (V_f, 3)
        Vertices of each facet, counter-clockwise seen from outside [m].
    """

    ids: np.ndarray
    normal: np.ndarray
    center: np.ndarray
    polygons: list = field(default_factory=list, repr=False)

    def __len__(self) -> int:
        return len(self.ids)

    def subset(self, index) -> Facets:
        """The facets selected by an integer or boolean index."""
        idx = np.arange(len(self))[index]
        polys = [self.polygons[i] for i in idx] if self.polygons else []
        return Facets(self.ids[idx], self.normal[idx], self.center[idx], polys)


def _polygon_normal_centroid(vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit normal (Newell's method) and area centroid of a planar polygon."""
    v = np.asarray(vertices, dtype=float)
    nxt = np.roll(v, -1, axis=0)
    newell = np.sum(np.cross(v, nxt), axis=0)  # = 2 x area vector
    area2 = np.linalg.norm(newell)
    normal = newell / area2
    # area-weighted centroid of the fan triangles from vertex 0
    a, b, c = v[0], v[1:-1], v[2:]
    tri_area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=-1)
    tri_centroid = (a + b + c) / 3.0
    centroid = np.sum(tri_area[:, None] * tri_centroid, axis=0) / np.sum(tri_area)
    return normal, centroid


def tessellated_hemisphere(
    radius: float = 1.0, n_rings: int = 6, n_segments: int = 16, center=(0.0, 0.0, 0.0)
) -> Facets:
    """A hemisphere of flat facets resting on the plane z = center[2].

    Parameters
    ----------
    radius : float
        Radius of the circumscribed sphere [m].
    n_rings : int
        Rings of facets from the equator to the pole (the top ring is a fan
        of triangles).
    n_segments : int
        Facets around each ring.
    center : sequence of 3 float
        Centre of the equator circle, world frame [m].

    Returns
    -------
    Facets
        ``n_rings * n_segments`` facets numbered from 1, ring by ring from
        the equator, anticlockwise from east seen from above.
    """
    if n_rings < 1 or n_segments < 3:
        raise ValueError(f"need n_rings >= 1 and n_segments >= 3, got {n_rings}, {n_segments}")
    if not radius > 0:
        raise ValueError(f"radius must be positive, got {radius}")
    c = np.asarray(center, dtype=float)
    elev = np.linspace(0.0, np.pi / 2, n_rings + 1)  # ring boundaries, elevation [rad]
    azim = np.linspace(0.0, 2 * np.pi, n_segments + 1)

    def point(e, a):
        return c + radius * np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])

    polygons = []
    for i in range(n_rings):
        for j in range(n_segments):
            e0, e1, a0, a1 = elev[i], elev[i + 1], azim[j], azim[j + 1]
            if i == n_rings - 1:
                poly = [point(e0, a0), point(e0, a1), point(e1, a0)]  # apex
            else:
                poly = [point(e0, a0), point(e0, a1), point(e1, a1), point(e1, a0)]
            polygons.append(np.array(poly))
    normals, centers = zip(*(_polygon_normal_centroid(p) for p in polygons), strict=True)
    ids = np.arange(1, len(polygons) + 1)
    return Facets(ids, np.array(normals), np.array(centers), polygons)


def box(size=(1.0, 1.0, 1.0), azimuth: float = 0.0, center=(0.0, 0.0, 0.0)) -> Facets:
    """A box of five faces (no bottom) standing on the plane z = center[2].

    Parameters
    ----------
    size : sequence of 3 float
        Extent along its own x, y and z axes [m].
    azimuth : float
        Rotation about the vertical, degrees clockwise seen from above.
    center : sequence of 3 float
        Centre of its base [m].

    Returns
    -------
    Facets
        Faces 1-4 are the sides (facing +x, +y, -x, -y before rotation), 5 the top.
    """
    sx, sy, sz = (0.5 * float(size[0]), 0.5 * float(size[1]), float(size[2]))
    if min(sx, sy, sz) <= 0:
        raise ValueError(f"box size must be positive, got {tuple(size)}")
    corners = {
        (i, j, k): np.array([i * sx, j * sy, k * sz])
        for i in (-1, 1)
        for j in (-1, 1)
        for k in (0, 1)
    }
    faces = [
        [(1, -1, 0), (1, 1, 0), (1, 1, 1), (1, -1, 1)],
        [(1, 1, 0), (-1, 1, 0), (-1, 1, 1), (1, 1, 1)],
        [(-1, 1, 0), (-1, -1, 0), (-1, -1, 1), (-1, 1, 1)],
        [(-1, -1, 0), (1, -1, 0), (1, -1, 1), (-1, -1, 1)],
        [(-1, -1, 1), (1, -1, 1), (1, 1, 1), (-1, 1, 1)],
    ]
    a = -np.radians(azimuth)  # clockwise seen from above
    rot = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    c = np.asarray(center, dtype=float)
    polygons = [np.array([rot @ corners[v] for v in f]) + c for f in faces]
    normals, centers = zip(*(_polygon_normal_centroid(p) for p in polygons), strict=True)
    return Facets(np.arange(1, 6), np.array(normals), np.array(centers), polygons)


def _ring(radius: float, z: float, n_sides: int, offset_rad: float) -> np.ndarray:
    """Vertices (n_sides, 3) of a regular polygon at height z, the first at offset_rad."""
    a = offset_rad + np.arange(n_sides) * (2 * np.pi / n_sides)
    return np.column_stack([radius * np.cos(a), radius * np.sin(a), np.full(n_sides, z)])


def _band(ring: np.ndarray, turned: np.ndarray) -> list[np.ndarray]:
    """Triangles of the convex hull between two parallel rings turned half a step.

    ``turned[k]`` lies half a step after ``ring[k]`` in angle: each edge of
    ``ring`` with the vertex of ``turned`` over its middle, and each edge of
    ``turned`` with the vertex of ``ring`` over its middle (the sides of an
    antiprism frustum).
    """
    n = len(ring)
    tris = []
    for k in range(n):
        tris.append(np.array([ring[k], ring[(k + 1) % n], turned[k]]))
        tris.append(np.array([turned[k], ring[(k + 1) % n], turned[(k + 1) % n]]))
    return tris


def _outward(polygons: list[np.ndarray]) -> Facets:
    """Facets of a convex solid, each polygon ordered so its normal points outward."""
    inside = np.mean(np.concatenate(polygons), axis=0)  # inside a convex solid
    out = []
    for p in polygons:
        normal, centroid = _polygon_normal_centroid(p)
        out.append(p if np.dot(centroid - inside, normal) > 0 else p[::-1].copy())
    normals, centers = zip(*(_polygon_normal_centroid(p) for p in out), strict=True)
    return Facets(np.arange(1, len(out) + 1), np.array(normals), np.array(centers), out)


def gem(
    radius: float = 1.0,
    n_sides: int = 8,
    stand: str = "culet",
    azimuth: float = 0.0,
    center=(0.0, 0.0, 0.0),
) -> Facets:
    """A brilliant-cut-like convex polyhedron of planar facets standing on the ground.

    Proportions of a round brilliant (Tolkowsky, *Diamond Design*, 1919) on an
    ``n_sides``-gon: girdle of circumradius ``radius`` and height 0.06
    ``radius`` (3 % of the diameter), crown 0.32 ``radius`` high (16 %) up to
    a table of circumradius 0.55 ``radius`` (55 %), pavilion 0.86 ``radius``
    deep (43 %) down to a flat culet of circumradius 0.25 ``radius`` (large
    enough to stand on). Table and culet are turned half a step against the
    girdle, so crown and pavilion are bands of ``2 n_sides`` triangles each
    (the convex hull of the two rings): every facet is planar and the solid
    is convex.

    Parameters
    ----------
    radius : float
        Circumradius of the girdle [m].
    n_sides : int
        Sides of the girdle polygon (8: octagonal) [-].
    stand : {"culet", "table"}
        The face it stands on, left out like a box's bottom: ``"culet"``
        (table up, as a gem is shown) or ``"table"`` (upside down) [-].
    azimuth : float
        Rotation about the vertical, clockwise seen from above [deg].
    center : sequence of 3 float
        Centre of the face it stands on, world frame [m].

    Returns
    -------
    Facets
        ``5 n_sides + 1`` facets (41 for an octagon) numbered from 1: the
        pavilion band, the girdle, the crown band, then the top face (table,
        or culet when standing on the table); outward normals, vertices
        counter-clockwise seen from outside.
    """
    if n_sides < 3:
        raise ValueError(f"need n_sides >= 3, got {n_sides}")
    if not radius > 0:
        raise ValueError(f"radius must be positive, got {radius}")
    if stand not in ("culet", "table"):
        raise ValueError(f"unknown stand {stand!r}; valid: culet, table")
    r, half = float(radius), np.pi / n_sides
    depth, girdle, crown = 0.86 * r, 0.06 * r, 0.32 * r
    height = depth + girdle + crown
    culet = _ring(0.25 * r, 0.0, n_sides, half)
    low = _ring(r, depth, n_sides, 0.0)
    high = _ring(r, depth + girdle, n_sides, 0.0)
    table = _ring(0.55 * r, height, n_sides, half)
    sides = [
        np.array([low[k], low[(k + 1) % n_sides], high[(k + 1) % n_sides], high[k]])
        for k in range(n_sides)
    ]
    polys = [*_band(low, culet), *sides, *_band(high, table), table]
    if stand == "table":  # upside down, standing on the table; the culet on top
        polys = [*polys[:-1], culet]
        polys = [np.column_stack([p[:, :2], height - p[:, 2]]) for p in polys]
    a = -np.radians(azimuth)  # clockwise seen from above
    rot = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    c = np.asarray(center, dtype=float)
    return _outward([p @ rot.T + c for p in polys])


def l_building(
    wing_length: float = 3.0,
    wing_width: float = 1.0,
    heights=(1.0, 1.5),
    azimuth: float = 0.0,
    center=(0.0, 0.0, 0.0),
) -> Facets:
    """An L-shaped building of two wings on the ground: a non-convex object.

    Before turning, a north wing along x and an east wing along y meet in the
    north-east corner of a ``wing_length`` square footprint, each
    ``wing_width`` wide; the L's inner corner opens toward the south-west.
    The east wing is the taller (``heights`` = north wing's, east wing's):
    its west wall rises above the north wing's roof, and it shadows that roof
    and the north wing's inner, south-facing wall in the morning; the north
    wing shadows the east wing's inner, west-facing wall in the evening (June,
    northern mid-latitudes). No bottom faces (it stands on the ground).

    Parameters
    ----------
    wing_length : float
        Side of the square footprint, each wing's length [m].
    wing_width : float
        Width of each wing, less than ``wing_length`` [m].
    heights : sequence of 2 float
        Heights of the north and the east wing; the east wing's must be at
        least the north wing's [m].
    azimuth : float
        Rotation about the vertical, clockwise seen from above [deg].
    center : sequence of 3 float
        Centre of the footprint's bounding square on the ground [m].

    Returns
    -------
    Facets
        8 planar facets, numbered from 1: the east wing's roof, the north
        wing's roof, the east wing's east, south and west walls (the west
        wall L-shaped where it rises above the north roof; equal heights
        make it a rectangle), the north wing's inner (south) and west walls,
        and the north wall (L-shaped). Outward normals; each polygon's
        vertices counter-clockwise seen from outside, starting at a vertex
        from which the polygon is star-shaped, so the fan of triangles from
        its first vertex (:func:`triangles`) tiles it.
    """
    w, d = float(wing_length), float(wing_width)
    hn, he = (float(h) for h in heights)
    if not (0 < d < w and 0 < hn <= he):
        raise ValueError(
            f"need 0 < wing_width < wing_length and 0 < heights[0] <= heights[1], got "
            f"{wing_length}, {wing_width}, {tuple(heights)}"
        )
    x0 = w - d  # the east wing's west wall, and the north wing's inner wall at y = x0
    raw = [
        ([[x0, 0, he], [w, 0, he], [w, w, he], [x0, w, he]], (0, 0, 1)),  # east roof
        ([[0, x0, hn], [x0, x0, hn], [x0, w, hn], [0, w, hn]], (0, 0, 1)),  # north roof
        ([[w, 0, 0], [w, w, 0], [w, w, he], [w, 0, he]], (1, 0, 0)),  # east wall
        ([[x0, 0, 0], [w, 0, 0], [w, 0, he], [x0, 0, he]], (0, -1, 0)),  # east wing's south
        (  # east wing's west wall, from its reflex corner (x0, x0, hn)
            [[x0, x0, hn], [x0, w, hn], [x0, w, he], [x0, 0, he], [x0, 0, 0], [x0, x0, 0]]
            if he > hn
            else [[x0, 0, 0], [x0, x0, 0], [x0, x0, he], [x0, 0, he]],
            (-1, 0, 0),
        ),
        ([[0, x0, 0], [x0, x0, 0], [x0, x0, hn], [0, x0, hn]], (0, -1, 0)),  # north's inner
        ([[0, x0, 0], [0, w, 0], [0, w, hn], [0, x0, hn]], (-1, 0, 0)),  # north's west
        (  # north wall, from its reflex corner (x0, w, hn)
            [[x0, w, hn], [0, w, hn], [0, w, 0], [w, w, 0], [w, w, he], [x0, w, he]]
            if he > hn
            else [[0, w, 0], [w, w, 0], [w, w, he], [0, w, he]],
            (0, 1, 0),
        ),
    ]
    a = -np.radians(azimuth)  # clockwise seen from above
    rot = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    shift = np.asarray(center, dtype=float) - [w / 2, w / 2, 0.0]
    polygons = []
    for vertices, outward in raw:
        p = np.array(vertices, dtype=float)
        normal, _ = _polygon_normal_centroid(p)
        if normal @ outward < 0:  # counter-clockwise seen from outside, same first vertex
            p = np.concatenate([p[:1], p[:0:-1]])
        polygons.append((p + shift) @ rot.T)
    normals, centers = zip(*(_polygon_normal_centroid(p) for p in polygons), strict=True)
    return Facets(np.arange(1, len(polygons) + 1), np.array(normals), np.array(centers), polygons)


def triangles(facets: Facets) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A triangle mesh of facets: each polygon a fan from its first vertex.

    The fan tiles a polygon that is convex or star-shaped from its first
    vertex (every shape of this module). Vertices are not shared between
    facets, so a mesh's region growing (:func:`bayesgloss.capture.planar_regions`)
    finds each facet as one region whatever the angle between neighbours.

    Parameters
    ----------
    facets : Facets
        With polygons [m].

    Returns
    -------
    vertices : ndarray (V, 3)
        [m]
    faces : ndarray (T, 3) of int
        Vertex indices, counter-clockwise seen from outside [-].
    face_facet : ndarray (T,) of int
        The facet id of each triangle [-].
    """
    vertices, faces, owner, first = [], [], [], 0
    for fid, poly in zip(facets.ids, facets.polygons, strict=True):
        p = np.asarray(poly, dtype=float)
        k = np.arange(1, len(p) - 1)
        vertices.append(p)
        faces.append(np.column_stack([np.zeros_like(k), k, k + 1]) + first)
        owner.append(np.full(len(k), fid))
        first += len(p)
    return np.concatenate(vertices), np.concatenate(faces), np.concatenate(owner)


def write_obj(facets: Facets, path) -> None:
    """Write facets as a Wavefront OBJ triangle mesh (:func:`triangles`), 17 digits.

    Parameters
    ----------
    facets : Facets
        World frame [m].
    path : str or path-like
        The file to write. -
    """
    from pathlib import Path

    vertices, faces, _ = triangles(facets)
    lines = ["# bayesgloss.geometry.write_obj"]
    lines += ["v {:.17g} {:.17g} {:.17g}".format(*v) for v in vertices]
    lines += ["f {} {} {}".format(*(f + 1)) for f in faces]
    Path(path).write_text("\n".join(lines) + "\n")


def camera_position(
    bearing: float | str, distance: float = 10.0, height: float = 2.0
) -> np.ndarray:
    """World position of a camera standing at a bearing from the origin.

    Parameters
    ----------
    bearing : float or str
        Degrees clockwise from north, or one of the paper's views
        ``"W", "SW", "S", "SE", "E"``.
    distance : float
        Horizontal distance from the origin [m].
    height : float
        Height above the ground plane [m].
    """
    if isinstance(bearing, str):
        try:
            bearing = CAMERA_AZIMUTHS[bearing.upper()]
        except KeyError:
            raise ValueError(
                f"unknown view {bearing!r}; valid: {', '.join(CAMERA_AZIMUTHS)}"
            ) from None
    b = np.radians(bearing)
    return np.array([distance * np.sin(b), distance * np.cos(b), height])


def view_directions(center: np.ndarray, camera_position: np.ndarray) -> np.ndarray:
    """Unit vectors from facet points toward the camera, shape (..., 3)."""
    d = np.asarray(camera_position, dtype=float) - np.asarray(center, dtype=float)
    return d / np.linalg.norm(d, axis=-1, keepdims=True)

"""A convex object's shape from its seen facets, for the shadow it casts on the ground.

A bundle without ``object_mesh`` holds a convex object standing alone on
the ground (the spec), and gives only the facets the camera sees: each
one's outward normal n_f and a point c_f on it. The object's shadow on the
ground is still in the frames: a glossy facet whose mirror direction
points down (every wall, seen from a camera above it) reflects the ground
at its foot, which is in the object's shadow when the sun is behind that
facet. A forward model whose ground is sunlit everywhere then reads that
facet's dark frames as a dim sun or a matt material (holdout 3's vs20, a
box of gamma 0.985 read 0.29; holdout 6's vs01, 0.820 read 0.71; stop 35's
diagnosis in studies/README.md).

:func:`convex_object` builds the object as the intersection of half-spaces
n . x <= n . c:

- each seen facet's;
- each seen facet's mirror image through the object's vertical axis, (-n_x,
  -n_y, n_z) at (2 o - c_xy, c_z), for the side the camera does not see
  (exact for objects symmetric under a half turn about that axis: boxes,
  bodies of revolution with an even number of segments, cut gems);
- the ground, z >= 0, and, only so that the intersection is bounded, a
  16-sided prism about the axis wider than any box through the facets'
  points and a lid at twice their height (neither touches an object whose
  facets and their images enclose it).

The axis o is the point nearest, in least squares, to the lines c_f,xy + s
n_f,xy of the facets' normals seen from above (weights |n_f,xy|^2: through
the axis for a box's walls and for any body of revolution), with a weak pull
(1e-3 of the total weight) toward the centroid of the highest facets'
points, which fixes it where the walls' lines are parallel or absent.

Each seen facet's polygon is the intersection's face in its plane;
:func:`facet_points` spreads points over it so that the forward model's
bases can be averaged over the facet (:mod:`bayesgloss.object_shadow`): a
wall's mirror footprint on the ground crosses the shadow's edge during the
day, which its centre alone does not see.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

__all__ = ["ConvexObject", "convex_object", "object_axis", "facet_points"]

#: Sides of the bounding prism about the axis.
BOUND_SIDES = 16
#: Weight of the pull toward the highest facets' centroid, relative to the lines'.
AXIS_PULL = 1e-3
#: Facets within this fraction of the height range of the highest are "highest".
TOP_FRACTION = 0.05


@dataclass(frozen=True)
class ConvexObject:
    """A convex object estimated from its seen facets.

    Attributes
    ----------
    vertices : ndarray (V, 3)
        Vertices of the object [m].
    polygons : list of ndarray (k, 3)
        Each seen facet's polygon (its face of the object), in order around
        the facet [m]; an empty array where the facet's plane meets the
        object in fewer than 3 points.
    axis : ndarray (2,)
        (x, y) of the vertical axis the unseen side was mirrored through [m].
    """

    vertices: np.ndarray
    polygons: list
    axis: np.ndarray


def object_axis(normal, center) -> np.ndarray:
    """(x, y) of a convex object's vertical axis from its facets (module docstring) [m].

    Parameters
    ----------
    normal : array_like (F, 3)
        Outward unit normals.
    center : array_like (F, 3)
        A point on each facet [m].
    """
    n = np.asarray(normal, dtype=float)
    c = np.asarray(center, dtype=float)
    z = c[:, 2]
    top = z >= z.max() - TOP_FRACTION * max(np.ptp(z), 1e-9)
    anchor = c[top, :2].mean(axis=0)
    nxy = n[:, :2]
    w = np.sum(nxy**2, axis=1)  # |n_xy|^2: 0 for a horizontal facet
    # distance of o from the line c + s u (u = n_xy / |n_xy|): |(I - u u^T)(o - c)|
    a = np.zeros((2, 2))
    rhs = np.zeros(2)
    for f in np.nonzero(w > 1e-12)[0]:
        u = nxy[f] / np.sqrt(w[f])
        p = np.eye(2) - np.outer(u, u)
        a += w[f] * p
        rhs += w[f] * p @ c[f, :2]
    pull = AXIS_PULL * max(w.sum(), 1.0)
    a += pull * np.eye(2)
    rhs += pull * anchor
    return np.linalg.solve(a, rhs)


def _interior_point(halfspaces) -> np.ndarray:
    """The centre of the largest ball inside {x: A x + b <= 0} (Chebyshev centre)."""
    from scipy.optimize import linprog

    a, b = halfspaces[:, :-1], halfspaces[:, -1]
    norm = np.linalg.norm(a, axis=1)
    cost = np.zeros(a.shape[1] + 1)
    cost[-1] = -1.0  # maximise the radius
    res = linprog(
        cost,
        A_ub=np.hstack([a, norm[:, None]]),
        b_ub=-b,
        bounds=[(None, None)] * a.shape[1] + [(0, None)],
        method="highs",
    )
    if not res.success or res.x[-1] <= 0:
        raise ValueError("the facets' planes enclose no volume above the ground")
    return res.x[:-1]


def convex_object(normal, center) -> ConvexObject:
    """The convex object bounded by its seen facets and their mirror images
    through its axis (module docstring).

    Parameters
    ----------
    normal : array_like (F, 3)
        Outward unit normals of the seen facets.
    center : array_like (F, 3)
        A point on each facet [m], above the ground.

    Returns
    -------
    ConvexObject

    Raises
    ------
    ValueError
        Where the planes enclose no volume above the ground.

    Notes
    -----
    The last few objects are kept (one fit asks for its object two or
    three times: whether the facets bound one, then its shadow's points),
    so their arrays are read-only.
    """
    n = np.ascontiguousarray(normal, dtype=float)
    c = np.ascontiguousarray(center, dtype=float)
    return _convex_object(n.tobytes(), c.tobytes(), n.shape, c.shape)


@functools.lru_cache(maxsize=16)
def _convex_object(normal: bytes, center: bytes, n_shape, c_shape) -> ConvexObject:
    """:func:`convex_object` of the normals and centres held as bytes."""
    from scipy.spatial import HalfspaceIntersection

    n = np.frombuffer(normal, dtype=float).reshape(n_shape)
    c = np.frombuffer(center, dtype=float).reshape(c_shape)
    o = object_axis(n, c)
    mirrored_n = n * np.array([-1.0, -1.0, 1.0])
    mirrored_c = np.column_stack([2 * o - c[:, :2], c[:, 2]])
    reach = np.sqrt(2.0) * max(np.max(np.linalg.norm(c[:, :2] - o, axis=1)), 1e-3)
    reach /= np.cos(np.pi / BOUND_SIDES)  # the prism's sides clear any box through the points
    phi = 2 * np.pi * np.arange(BOUND_SIDES) / BOUND_SIDES
    side_n = np.column_stack([np.cos(phi), np.sin(phi), np.zeros(BOUND_SIDES)])
    side_c = np.column_stack([o + reach * side_n[:, :2], np.zeros(BOUND_SIDES)])
    lid = 2.0 * max(c[:, 2].max(), 1e-3)
    normals = np.vstack([n, mirrored_n, side_n, [[0, 0, -1.0], [0, 0, 1.0]]])
    points = np.vstack([c, mirrored_c, side_c, [[0, 0, 0.0], [0, 0, lid]]])
    halfspaces = np.column_stack([normals, -np.sum(normals * points, axis=1)])  # A x + b <= 0
    hull = HalfspaceIntersection(halfspaces, _interior_point(halfspaces))
    vertices = hull.intersections
    scale = max(np.ptp(vertices, axis=0).max(), 1e-6)
    polygons = []
    for f in range(len(n)):
        on = np.abs(vertices @ n[f] - n[f] @ c[f]) <= 1e-6 * scale
        polygons.append(_ordered(vertices[on], n[f]) if on.sum() >= 3 else np.zeros((0, 3)))
    for array in (vertices, o, *polygons):
        array.setflags(write=False)
    return ConvexObject(vertices, polygons, o)


def _plane_basis(normal) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors spanning the plane normal to ``normal``."""
    helper = np.array([0.0, 0.0, 1.0]) if abs(normal[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    u = np.cross(normal, helper)
    u /= np.linalg.norm(u)
    return u, np.cross(normal, u)


def _ordered(points, normal) -> np.ndarray:
    """Distinct coplanar points in order around their centroid."""
    pts = np.unique(np.round(points, 12), axis=0)
    u, v = _plane_basis(normal)
    d = pts - pts.mean(axis=0)
    return pts[np.argsort(np.arctan2(d @ v, d @ u))]


def facet_points(polygon, normal, per_side: int = 4) -> np.ndarray:
    """Points spread evenly over a convex polygon, (M, 3) [m].

    The centres of a ``per_side`` x ``per_side`` grid of cells over the
    polygon's bounding rectangle in its plane, aligned with its longest
    edge, those inside it; the polygon's centroid where none is. Each point
    stands for the same area.

    Parameters
    ----------
    polygon : array_like (k, 3)
        Vertices in order around the polygon [m].
    normal : array_like (3,)
    per_side : int
    """
    poly = np.asarray(polygon, dtype=float)
    nrm = np.asarray(normal, dtype=float)
    edges = np.roll(poly, -1, axis=0) - poly
    u = edges[np.argmax(np.linalg.norm(edges, axis=1))]
    u = u - (u @ nrm) * nrm
    u /= np.linalg.norm(u)
    v = np.cross(nrm, u)  # (u, v, n) right-handed, as _ordered's order assumes
    origin = poly.mean(axis=0)
    p2 = np.column_stack([(poly - origin) @ u, (poly - origin) @ v])
    lo, hi = p2.min(axis=0), p2.max(axis=0)
    g = (np.arange(per_side) + 0.5) / per_side
    gu, gv = np.meshgrid(lo[0] + g * (hi[0] - lo[0]), lo[1] + g * (hi[1] - lo[1]))
    q = np.column_stack([gu.ravel(), gv.ravel()])
    # inside a convex polygon ordered counter-clockwise in (u, v): left of every edge
    edge = np.roll(p2, -1, axis=0) - p2
    cross = edge[None, :, 0] * (q[:, None, 1] - p2[None, :, 1]) - edge[None, :, 1] * (
        q[:, None, 0] - p2[None, :, 0]
    )
    inside = np.all(cross >= -1e-12 * max(np.ptp(p2), 1e-12), axis=1)
    if not inside.any():
        return origin[None, :]
    q = q[inside]
    return origin + q[:, :1] * u + q[:, 1:] * v

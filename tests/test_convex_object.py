"""A convex object's shape from its seen facets (bayesgloss.convex_object)."""

import numpy as np
import pytest
from scipy.spatial import ConvexHull

from bayesgloss import geometry
from bayesgloss.convex_object import convex_object, facet_points, object_axis


def _seen(facets, camera):
    """The facets whose front a camera at ``camera`` sees."""
    view = camera - facets.center
    return facets.subset(np.einsum("ij,ij->i", facets.normal, view) > 0)


def _sorted_rows(x):
    return x[np.lexsort(np.round(x, 9).T[::-1])]


@pytest.mark.parametrize("azimuth", [0.0, 27.0, 85.4])
def test_a_box_is_recovered_from_two_walls_and_its_top(azimuth):
    # the camera sees two walls and the top; the other two walls are the seen
    # ones mirrored through the axis, so the box comes back exactly (a model
    # without the mirror images is bounded by the 16-sided prism instead)
    box = geometry.box(size=(0.646, 1.3, 1.226), azimuth=azimuth, center=(2.0, -1.0, 0.0))
    seen = _seen(box, np.array([9.0, 6.0, 4.0]))
    assert len(seen) == 3
    obj = convex_object(seen.normal, seen.center)
    corners = np.unique(np.round(np.concatenate(box.polygons), 12), axis=0)
    np.testing.assert_allclose(_sorted_rows(obj.vertices), _sorted_rows(corners), atol=1e-9)
    np.testing.assert_allclose(obj.axis, [2.0, -1.0], atol=1e-12)
    # each seen facet's polygon is its face of the box
    for poly, true in zip(obj.polygons, seen.polygons, strict=True):
        np.testing.assert_allclose(_sorted_rows(poly), _sorted_rows(np.asarray(true)), atol=1e-9)


def test_a_hemisphere_of_even_segments_is_recovered_from_its_seen_half():
    dome = geometry.tessellated_hemisphere(n_rings=5, n_segments=12)
    seen = _seen(dome, np.array([-8.0, 3.0, 3.0]))
    assert len(seen) < len(dome)
    obj = convex_object(seen.normal, seen.center)
    true = ConvexHull(np.concatenate(dome.polygons))
    est = ConvexHull(obj.vertices)
    # the same polyhedron: same volume, and every true vertex on the estimate
    assert est.volume == pytest.approx(true.volume, rel=1e-9)
    np.testing.assert_allclose(obj.axis, [0.0, 0.0], atol=1e-9)


def test_the_axis_of_one_wall_and_a_top_is_the_top_centre():
    # one wall's normal line passes through the axis but does not fix it
    # along itself: the highest facet's point does
    box = geometry.box(size=(1.0, 2.0, 0.5), azimuth=0.0, center=(0.3, 0.4, 0.0))
    seen = box.subset([0, 4])  # the +x wall and the top
    np.testing.assert_allclose(object_axis(seen.normal, seen.center), [0.3, 0.4], atol=1e-9)


def test_planes_that_enclose_nothing_above_the_ground_are_an_error():
    normal = np.array([[0.0, 0.0, 1.0]])
    with pytest.raises(ValueError, match="enclose no volume above the ground"):
        convex_object(normal, np.array([[0.0, 0.0, -1.0]]))  # a top below the ground


def test_facet_points_cover_a_polygon_evenly():
    square = np.array([[0, 0, 0], [2, 0, 0], [2, 2, 0], [0, 2, 0.0]])
    pts = facet_points(square, np.array([0, 0, 1.0]), per_side=4)
    assert len(pts) == 16
    np.testing.assert_allclose(pts.mean(axis=0), [1.0, 1.0, 0.0], atol=1e-12)
    assert np.all((pts[:, :2] > 0) & (pts[:, :2] < 2))
    # a right triangle, the grid along its hypotenuse: the cells whose centres
    # fall inside it, 4 + 2 + 2 + 0 by rows up from the hypotenuse, on its plane
    tri = np.array([[0, 0, 1.0], [2, 0, 1.0], [0, 2, 1.0]])
    inside = facet_points(tri, np.array([0, 0, 1.0]), per_side=4)
    assert len(inside) == 8
    assert np.all(inside[:, 0] + inside[:, 1] <= 2) and np.allclose(inside[:, 2], 1.0)


def test_convex_object_is_built_once_for_the_same_facets():
    # a fit asks for its object two or three times: the same facets (even
    # as other arrays of the same values) give the very same object, whose
    # arrays cannot be changed under another caller; other facets another
    f = geometry.box()
    first = convex_object(f.normal, f.center)
    assert convex_object(np.array(f.normal), np.array(f.center)) is first
    with pytest.raises(ValueError):
        first.vertices[0, 0] = 1.0
    moved = np.asarray(f.center) + np.array([0.5, 0.0, 0.0])
    other = convex_object(f.normal, moved)
    assert other is not first
    assert np.allclose(other.vertices.mean(axis=0)[:2], first.vertices.mean(axis=0)[:2] + [0.5, 0])

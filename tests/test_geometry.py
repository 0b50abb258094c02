import numpy as np
import pytest

from bayesgloss import geometry


def test_hemisphere_facets_are_planar_unit_outward():
    f = geometry.tessellated_hemisphere(radius=2.0, n_rings=5, n_segments=12)
    assert len(f) == 60
    np.testing.assert_allclose(np.linalg.norm(f.normal, axis=1), 1.0, atol=1e-12)
    # outward: the normal points away from the sphere centre
    assert np.all(np.einsum("ij,ij->i", f.normal, f.center) > 0)
    for poly, n, c in zip(f.polygons, f.normal, f.center, strict=True):
        # every vertex lies in the facet plane through the centroid
        np.testing.assert_allclose((poly - c) @ n, 0.0, atol=1e-12)
        # vertices lie on the circumscribed sphere
        np.testing.assert_allclose(np.linalg.norm(poly, axis=1), 2.0, atol=1e-12)
    # nothing below the ground plane, apex ring is triangles
    assert np.all(np.array([p[:, 2].min() for p in f.polygons]) >= -1e-12)
    assert {len(p) for p in f.polygons[-12:]} == {3}


def test_hemisphere_normals_tend_to_radial_with_refinement():
    # finer tessellation -> facet normal closer to the radial direction of its centroid
    errs = []
    for rings, segs in [(4, 8), (16, 32)]:
        f = geometry.tessellated_hemisphere(1.0, rings, segs)
        radial = f.center / np.linalg.norm(f.center, axis=1, keepdims=True)
        errs.append(np.max(np.arccos(np.clip(np.sum(radial * f.normal, 1), -1, 1))))
    assert errs[1] < errs[0] / 3


def test_camera_positions_and_bad_view():
    np.testing.assert_allclose(geometry.camera_position("W", 10, 2), [-10, 0, 2], atol=1e-12)
    np.testing.assert_allclose(geometry.camera_position("S", 5, 1), [0, -5, 1], atol=1e-12)
    np.testing.assert_allclose(geometry.camera_position(90.0, 3, 0), [3, 0, 0], atol=1e-12)
    with pytest.raises(ValueError, match="NNE"):
        geometry.camera_position("NNE")


def test_view_directions_broadcast():
    c = np.zeros((4, 2, 3))
    v = geometry.view_directions(c, [0, 0, 5])
    assert v.shape == (4, 2, 3)
    np.testing.assert_allclose(v, np.broadcast_to([0, 0, 1.0], v.shape))


def test_bad_tessellation():
    with pytest.raises(ValueError, match="n_segments"):
        geometry.tessellated_hemisphere(1.0, 3, 2)
    with pytest.raises(ValueError, match="-1"):
        geometry.tessellated_hemisphere(-1.0)


def test_l_building_is_a_closed_non_convex_solid_with_the_stated_areas(tmp_path):
    import trimesh

    b = geometry.l_building(3.0, 1.0, (1.0, 1.5))
    assert len(b) == 8
    np.testing.assert_allclose(np.linalg.norm(b.normal, axis=1), 1.0, atol=1e-12)
    vertices, faces, owner = geometry.triangles(b)
    tri = vertices[faces]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    # every fan triangle faces its facet's way: the fans tile the L-shaped walls
    np.testing.assert_allclose(
        cross / np.linalg.norm(cross, axis=1, keepdims=True), b.normal[owner - 1], atol=1e-12
    )
    # areas by hand: roofs 3 x 1 and 2 x 1; east wall 3 x 1.5, its south 1 x 1.5; its
    # west wall 2 x 1.5 + 1 x 0.5; the inner wall 2 x 1, the north's west 1 x 1; the
    # north wall 2 x 1 + 1 x 1.5
    area = np.bincount(owner, 0.5 * np.linalg.norm(cross, axis=1))[1:]
    np.testing.assert_allclose(area, [3, 2, 4.5, 1.5, 3.5, 2, 1, 3.5], rtol=1e-12)
    # with the ground (the footprint) it closes: the divergence theorem gives the
    # volume 3 x 1 x 1.5 + 2 x 1 x 1 = 6.5 m^3 (the footprint adds nothing: z = 0)
    volume = np.sum(np.einsum("tk,tk->t", tri[:, 0], cross)) / 6
    assert volume == pytest.approx(6.5, rel=1e-12)
    # not convex: the inner corner's walls face the L's other wing
    inner = b.center[5]  # the north wing's south-facing inner wall
    assert np.any((vertices - inner) @ b.normal[5] > 0.5)
    geometry.write_obj(b, tmp_path / "l.obj")
    mesh = trimesh.load_mesh(tmp_path / "l.obj", process=False)
    assert mesh.area == pytest.approx(21.0, rel=1e-12) and len(mesh.faces) == len(faces)
    # turned and moved: the same solid
    t = geometry.l_building(azimuth=90.0, center=(1.0, 2.0, 0.0))
    np.testing.assert_allclose(t.normal[2], [0, -1, 0], atol=1e-12)  # east wall faces south
    with pytest.raises(ValueError, match="wing_width < wing_length"):
        geometry.l_building(1.0, 2.0)

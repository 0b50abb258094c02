"""Self-shadowing and sky occlusion from a bundle's object_mesh (bayesgloss.visibility)."""

import time
import warnings

import numpy as np
import pandas as pd
import pytest

from bayesgloss import radiance
from bayesgloss import visibility as vis

trimesh = pytest.importorskip("trimesh")


def box(lo, hi):
    """An axis-aligned box from corner ``lo`` to corner ``hi`` [m], outward normals."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    mesh = trimesh.creation.box(extents=hi - lo)
    mesh.apply_translation((lo + hi) / 2)
    return mesh


def quad(center, normal, size):
    """A square of two triangles, side ``size`` [m], about ``center`` facing ``normal``."""
    n = np.asarray(normal, float)
    e1 = np.cross([0.0, 0.0, 1.0] if abs(n[2]) < 0.9 else [1.0, 0.0, 0.0], n)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n, e1)
    h = size / 2
    v = np.asarray(center) + np.array(
        [-h * e1 - h * e2, h * e1 - h * e2, h * e1 + h * e2, -h * e1 + h * e2]
    )
    return trimesh.Trimesh(v, [[0, 1, 2], [0, 2, 3]], process=False)


def tall_and_low():
    """A tall box (1 x 1 x 3 m) beside a low one (2 x 0.8 x 1 m) 0.1 m east of it."""
    return trimesh.util.concatenate(
        [box([-0.5, -0.5, 0], [0.5, 0.5, 3]), box([0.6, -0.4, 0], [2.6, 0.4, 1])]
    )


#: The low box's top: normal, centre [m].
LOW_TOP = (np.array([[0.0, 0.0, 1.0]]), np.array([[1.6, 0.0, 1.0]]))


def sun(elevation, azimuth):
    """Unit vector toward a sun at ``elevation`` [deg], ``azimuth`` [deg east of north]."""
    e, a = np.radians(elevation), np.radians(azimuth)
    return np.array([np.sin(a) * np.cos(e), np.cos(a) * np.cos(e), np.sin(e)])


# -- against Radiance ----------------------------------------------------------


def radiance_lit(mesh, points, sun_direction):
    """Whether rtrace sees the sun from each point (direct irradiance only, -ab 0).

    The mesh's triangles are written as Radiance polygons of a grey plastic; the
    sun is a ``source`` of 0.533 deg. ``rtrace -I`` gives the irradiance on an
    upward surface at each point (lifted 1e-4 m): the sun's alone, as there is
    no sky and no ambient bounce, so it is lit where it is above zero.
    """
    scene = radiance.material("grey", "plastic", 0.5, 0.0, 0.0)
    scene += "void light solar\n0\n0\n3 1e6 1e6 1e6\n"
    d = np.asarray(sun_direction, float)
    scene += f"solar source sun\n0\n0\n4 {d[0]:.9g} {d[1]:.9g} {d[2]:.9g} 0.533\n"
    scene += radiance.polygons(list(mesh.triangles), "grey")
    origins = np.asarray(points, float) + [0.0, 0.0, 1e-4]
    normals = np.broadcast_to([0.0, 0.0, 1.0], origins.shape)
    irradiance = radiance.rtrace_scene(
        scene, origins, normals, ("-I", "-ab", "0", "-av", "0", "0", "0", "-dj", "0", "-u-")
    )
    return irradiance.mean(axis=1) > 1.0


#: (elevation, azimuth) of suns: the tall box's shadow over part of the low top,
#: over none of it, over all of it, and an oblique edge.
SUNS = [(60.0, 270.0), (60.0, 90.0), (25.0, 270.0), (40.0, 240.0), (55.0, 300.0)]


@pytest.mark.radiance
def test_sunlit_fraction_matches_rtrace():
    # The low box's top, partly in the tall box's shadow. Reference: Radiance's
    # rtrace on a 60 x 40 grid of cell centres over the top (its lit fraction is
    # the area fraction to within about 1/40 on a straight shadow edge).
    # visibility's 64 stratified points discretise the edge: tolerance 0.06
    # (a 64-point quasi-random set's error on a straight edge, ~64^-3/4 = 0.044,
    # plus the grid's). On visibility's own points rtrace must agree point by point.
    mesh = tall_and_low()
    normal, center = LOW_TOP
    suns = np.array([sun(*s) for s in SUNS])
    v = vis.facet_visibility(mesh, normal, center, suns)
    assert v.n_faces.tolist() == [2]
    x, y = np.meshgrid(
        np.linspace(0.6, 2.6, 61)[:-1] + 1 / 60, np.linspace(-0.4, 0.4, 41)[:-1] + 0.01
    )
    grid = np.stack([x.ravel(), y.ravel(), np.full(x.size, 1.0)], -1)
    face = vis.facet_faces(mesh, normal, center)
    points, up = vis.facet_points(mesh, face, 1)  # (1, 64, 3)
    fractions, agree = [], []
    for t, d in enumerate(suns):
        lit = radiance_lit(mesh, grid, d)
        fractions.append((lit.mean(), v.sunlit_fraction[0, t]))
        assert v.sunlit_fraction[0, t] == pytest.approx(lit.mean(), abs=0.06), SUNS[t]
        # point by point: each point a facet of its own
        each = vis.sunlit_fraction(mesh, points[0][:, None], up[0][:, None], up[0], d[None])[:, 0]
        agree.append(float(np.mean(radiance_lit(mesh, points[0], d) == (each > 0))))
        assert each.mean() == v.sunlit_fraction[0, t]
    assert min(agree) >= 63 / 64, agree
    print("points agreeing with rtrace:", agree)
    f = np.array(fractions)
    # the cases: partly lit, wholly lit, wholly shadowed
    assert f[1, 0] == 1.0 and v.sunlit_fraction[0, 1] == 1.0
    assert f[2, 0] == 0.0 and v.sunlit_fraction[0, 2] == 0.0
    assert 0.1 < f[0, 0] < 0.9 and 0.1 < f[3, 0] < 0.9
    print("rtrace vs visibility:", f.round(3).tolist())


# -- the sky ---------------------------------------------------------------------


def wall_view(d, h):
    """Cosine-weighted sky view factor of a horizontal point at distance ``d`` [m] from
    an infinitely long vertical wall of height ``h`` [m] standing on its plane.

    In the section across the wall (the wall infinitely long, so the 2-D view
    factor of a strip, Hottel's crossed strings; Modest, Radiative Heat Transfer,
    3rd ed., sec. 4.4), the wall spans the angles from the normal between
    90 deg - atan(h / d) and 90 deg: it takes (sin 90 - sin(90 - atan(h/d))) / 2 =
    (1 - d / sqrt(d^2 + h^2)) / 2 of the view, the sky the rest.
    """
    return 1.0 - (1.0 - d / np.hypot(d, h)) / 2.0


def test_sky_view_open_wall_and_courtyard():
    # 1024 cosine-weighted Halton directions: sampling tolerance 0.01 on a view
    # factor (a quasi-random estimate of a smooth fraction; ~0.5/sqrt(1024) even
    # for a random one). Walls of 400 m make the finite wall's missing view
    # factor below 1e-5.
    flat = quad([0, 0, 0], [0, 0, 1], 0.1)
    upright = quad([0, 0, 0.5], [1, 0, 0], 0.1)
    wall = box([-200, 1.0, 0], [200, 1.2, 1.0])  # its face at y = 1, 1 m high
    wall2 = box([-200, -1.2, 0], [200, -1.0, 1.0])
    up, east = [[0.0, 0, 1]], [[1.0, 0, 0]]
    sun_none = np.zeros((0, 3))
    open_flat = vis.facet_visibility(flat, up, [[0, 0, 0]], sun_none)
    assert open_flat.sky_view_factor[0] == 1.0 and open_flat.sky_visible_fraction[0] == 1.0
    open_up = vis.facet_visibility(upright, east, [[0, 0, 0.5]], sun_none)
    # a vertical facet on open ground: half its hemisphere is sky, all of it visible
    assert open_up.sky_view_factor[0] == pytest.approx(0.5, abs=0.01)
    assert open_up.sky_visible_fraction[0] == 1.0 and open_up.sky_occluded_fraction[0] == 0.0
    assert open_up.ground_visible_fraction[0] == 1.0
    one = vis.facet_visibility(trimesh.util.concatenate([flat, wall]), up, [[0, 0, 0]], sun_none)
    assert one.sky_view_factor[0] == pytest.approx(wall_view(1.0, 1.0), abs=0.01)  # 0.854
    court = trimesh.util.concatenate([flat, wall, wall2])
    two = vis.facet_visibility(court, up, [[0, 0, 0]], sun_none)
    # between two walls each takes (1 - d / sqrt(d^2 + h^2)) / 2: sky 0.707
    assert two.sky_view_factor[0] == pytest.approx(2 * wall_view(1.0, 1.0) - 1, abs=0.01)
    assert two.sky_view_factor[0] < one.sky_view_factor[0] < 1.0
    assert two.sky_occluded_fraction[0] == pytest.approx(1 - two.sky_visible_fraction[0])
    # the vertical facet facing a wall 1 m away loses sky and ground
    facing = vis.facet_visibility(
        trimesh.util.concatenate([upright, box([1.0, -200, 0], [1.2, 200, 2.0])]),
        east,
        [[0, 0, 0.5]],
        sun_none,
    )
    assert facing.sky_visible_fraction[0] < 0.6 and facing.ground_visible_fraction[0] < 0.6


def test_classes_and_partly_shadowed_mask():
    f = np.array([[1.0, 0.99, 0.98, 0.5, 0.02, 0.0, np.nan]])
    assert vis.classify(f).tolist() == [[0, 0, 0, 1, 2, 2, -1]]
    assert vis.partly_shadowed(f).tolist() == [[False, False, False, True, False, False, False]]
    assert vis.classify(0.5).shape == ()  # broadcasting: any shape in, the same out
    assert [vis.CLASSES[c] for c in vis.classify([1.0, 0.3, 0.0])] == [
        "sunlit",
        "partly-shadowed",
        "shadowed",
    ]


def test_sun_below_horizon_or_behind_is_zero_and_mesh_faces_found():
    mesh = tall_and_low()
    normal, center = LOW_TOP
    suns = np.array([[0.0, 0.0, -1.0], sun(-5.0, 90.0), sun(80.0, 90.0)])
    v = vis.facet_visibility(
        mesh, np.r_[normal, [[0, 0, -1.0]]], np.r_[center, [[1.6, 0, 0]]], suns
    )
    assert v.sunlit_fraction[0].tolist() == [0.0, 0.0, 1.0]
    assert v.sunlit_fraction[1].tolist() == [0.0, 0.0, 0.0]  # a bottom face: sun behind
    assert v.sun_in_front.tolist() == [[False, False, True], [False, False, False]]
    assert not v.shadowed_by_object.any()
    assert v.area.tolist() == pytest.approx([1.6, 1.6])
    # the bottom facet's hemisphere holds no sky: nothing hidden
    assert v.sky_visible_fraction[1] == 1.0 and v.sky_view_factor[1] == 0.0
    with pytest.raises(ValueError, match="no face of the mesh lies on facet 0's plane"):
        vis.facet_visibility(mesh, [[0, 0, 1.0]], [[1.6, 0, 1.5]], suns)


def test_fast_on_100_facets_20_frames_10k_faces():
    # 100 facets x 20 frames x 64 points, and 100 x 1024 sky rays, on a 20,480-face
    # sphere beside a box: measured 0.1-0.4 s on this 2-core machine; 5 s allowed.
    sphere = trimesh.creation.icosphere(subdivisions=5)
    mesh = trimesh.util.concatenate([sphere, box([1.2, -1, -1], [1.6, 1, 2])])
    pick = np.random.default_rng(1).choice(len(sphere.faces), 100, replace=False)
    normal, center = sphere.face_normals[pick], sphere.triangles_center[pick]
    az = np.radians(np.linspace(60, 300, 20))
    suns = np.stack([np.sin(az) * 0.6, np.cos(az) * 0.6, np.full(20, 0.8)], -1)
    t0 = time.perf_counter()
    v = vis.facet_visibility(mesh, normal, center, suns, angle_tolerance=1.0)
    seconds = time.perf_counter() - t0
    print(f"visibility of 100 facets x 20 frames, {len(mesh.faces)} faces: {seconds:.2f} s")
    assert seconds < 5.0
    assert v.sunlit_fraction.shape == (100, 20) and (v.n_faces >= 1).all()
    assert v.partly_shadowed.any() or v.shadowed_by_object.any()  # the box shadows some


# -- bundles: the flags and estimate's usable mask --------------------------------

#: Facets of the tall-and-low mesh: the low top, the tall top, their east faces.
FACET_NORMALS = np.array([[0, 0, 1.0], [0, 0, 1.0], [1.0, 0, 0], [1.0, 0, 0]])
FACET_CENTERS = np.array([[1.6, 0, 1.0], [0, 0, 3.0], [0.5, 0, 1.5], [2.6, 0, 0.5]])
#: Every half hour of 21 June 1996 from 05:00 to 19:00 UTC at 40 N, 0 E.
TIMES = pd.date_range("1996-06-21T05:00:00+00:00", "1996-06-21T19:00:00+00:00", freq="30min")


def write_mesh_bundle(tmp_path, name, with_mesh=True, mesh=None):
    """A bundle of the tall-and-low boxes' four facets (``write_bundle``), with the
    mesh as its object_mesh or without; frames of constant facet radiances."""
    from bayesgloss import bundle as bd
    from bayesgloss.geometry import Facets

    obj = tmp_path / f"{name}.obj"
    (tall_and_low() if mesh is None else mesh).export(obj)
    labels = np.zeros((16, 16), int)
    for k in range(4):
        labels[4 * k : 4 * k + 4, 2:14] = k + 1
    rng = np.random.default_rng(3)
    radiance = rng.uniform(0.5, 2.0, (len(TIMES), 5, 1))
    frames = [np.broadcast_to(r[labels], (16, 16, 3)).astype(np.float32) for r in radiance]
    facets = Facets(np.arange(1, 5), FACET_NORMALS, FACET_CENTERS)
    return bd.write_bundle(
        tmp_path / name,
        site={"latitude": 40.0, "longitude": 0.0, "elevation": 0.0},
        camera_position=[12.0, -4.0, 9.0],
        pixel_encoding="linear-radiance",
        frames=frames,
        times=TIMES,
        facets=facets,
        labels=labels,
        frame_format="tiff",
        object_mesh=obj if with_mesh else None,
    )


def read(path):
    from bayesgloss import bundle as bd

    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", "bundle .*object_mesh", bd.BundleWarning)
        return bd.read_bundle(path)


def test_bundle_with_mesh_flags_partly_shadowed_entries_and_estimate_leaves_them_out(
    tmp_path, monkeypatch
):
    # partly shadowed entries are flagged and left out; wholly shadowed ones
    # are kept (the forward model takes the mesh's occlusion)
    from bayesgloss import bundle as bd
    from bayesgloss import estimate

    with_mesh = read(write_mesh_bundle(tmp_path, "mesh"))
    without = read(write_mesh_bundle(tmp_path, "plain", with_mesh=False))
    v = vis.bundle_visibility(with_mesh)
    assert vis.bundle_visibility(without) is None
    # the low top is partly in the tall box's shadow in the afternoon, and the
    # tall box's east face in the low box's (low sun); the tall top never
    assert v.partly_shadowed[0].sum() >= 2 and v.partly_shadowed[2].sum() >= 1
    assert not v.partly_shadowed[1].any() and not v.shadowed_by_object[1].any()
    curves = estimate.bundle_curves(with_mesh)
    np.testing.assert_array_equal(curves.flagged("partly-shadowed"), v.partly_shadowed)
    assert v.shadowed_by_object.any()  # kept now: the forward model gives them no sun
    assert not curves.flagged("shadowed-by-object").any()
    plain = bd.facet_curves(with_mesh)
    _, usable, _ = estimate.observations(curves)
    _, usable_convex, _ = estimate.observations(plain)
    left_out = v.partly_shadowed
    assert left_out.any()
    np.testing.assert_array_equal(usable, usable_convex & ~left_out)
    # a bundle without a mesh: the curves of facet_curves, bit for bit
    same = estimate.bundle_curves(without)
    reference = bd.facet_curves(without)
    np.testing.assert_array_equal(same.flag_bits, reference.flag_bits)
    np.testing.assert_array_equal(same.luminance, reference.luminance)
    assert not same.flagged("partly-shadowed").any()

    # estimate_bundle's usable mask is this one: caught where it picks facets
    seen = []

    def catch(b, usable, *args, **kwargs):
        seen.append(np.array(usable))
        raise KeyboardInterrupt  # stop before sampling

    monkeypatch.setattr(bd, "usable_facets", catch)
    for b in (with_mesh, without):
        with pytest.raises(KeyboardInterrupt):
            estimate.estimate_bundle(b)
    np.testing.assert_array_equal(seen[0], usable)
    np.testing.assert_array_equal(seen[1], estimate.observations(reference)[1])
    assert seen[0].sum() == seen[1].sum() - left_out.sum()


def test_bundle_mesh_errors_name_bundle_field_and_problem(tmp_path):
    from bayesgloss import bundle as bd

    path = write_mesh_bundle(tmp_path, "broken")
    b = read(path)
    (path / "object_mesh.obj").write_text("v 0 0 0\nf 1 2 3\nthis is no mesh\n")
    with pytest.raises(bd.BundleError, match=r"bundle '.*broken'.*field 'object_mesh'.*mesh"):
        vis.bundle_visibility(b)
    (path / "object_mesh.obj").unlink()
    with pytest.raises(bd.BundleError, match="field 'object_mesh': missing mesh"):
        vis.bundle_visibility(b)
    # a mesh with nothing on the facets' planes
    other = read(write_mesh_bundle(tmp_path, "other", mesh=box([5, 5, 0], [6, 6, 0.5])))
    with pytest.raises(bd.BundleError, match="object_mesh.*no face of the mesh lies on facet id 1"):
        vis.bundle_visibility(other)


def test_curves_command_shows_the_shadow_flags(tmp_path, capsys):
    from bayesgloss import cli

    b = read(write_mesh_bundle(tmp_path, "cli"))
    v = vis.bundle_visibility(b)
    assert cli.main(["curves", str(b.path)]) == 0
    out = capsys.readouterr().out
    assert f"partly-shadowed {int(v.partly_shadowed.sum())}" in out
    assert "shadowed-by-object 0" in out  # no longer set: modelled


def test_facet_faces_takes_the_piece_nearest_the_centre():
    # two boxes' tops on one plane, apart: a facet centred on one gets only its faces
    a, b = box([0, 0, 0], [1, 1, 1]), box([3, 0, 0], [4, 2, 1])
    mesh = trimesh.util.concatenate([a, b])
    up = [[0, 0, 1.0], [0, 0, 1.0]]
    face = vis.facet_faces(mesh, up, [[0.5, 0.5, 1.0], [3.5, 1.0, 1.0]])
    assert face[:12].tolist() == [0 if n[2] > 0.5 else -1 for n in a.face_normals]
    assert face[12:].tolist() == [1 if n[2] > 0.5 else -1 for n in b.face_normals]
    # a face 0.2 m under the plane (beyond 1 % of the 4.6 m size) is not on it
    sunk = trimesh.util.concatenate([a, box([3, 0, 0], [4, 2, 0.8])])
    face = vis.facet_faces(sunk, up[:1], [[0.5, 0.5, 1.0]])
    assert (face[12:] == -1).all() and (face[:12] == 0).sum() == 2


# -- the forward model's map (visibility.occlusion) --------------------------------


def _view_factor(occ, normal, upward=True):
    """Cosine-weighted share of a facet's hemisphere the map leaves open (sky only or all)."""
    from bayesgloss import render

    dirs, omega = render.sphere_quadrature(occ.resolution)
    w = np.maximum(dirs @ np.asarray(normal, float), 0.0) * omega / np.pi
    if upward:
        w = w * (dirs[:, 2] > 0)
    return occ.open_fraction @ w


def test_occlusion_map_gives_a_wall_and_a_courtyard_their_sky_view():
    # The map on the sphere quadrature (8 rays a direction from the facet's
    # points), weighted by cosine: the closed-form view factors of the sky test
    # above (Hottel's crossed strings) to within 0.01 (the 3 deg cells and 8 of
    # 64 points), and 1 where nothing hides anything.
    flat = quad([0, 0, 0], [0, 0, 1], 0.1)
    wall = box([-200, 1.0, 0], [200, 1.2, 1.0])
    wall2 = box([-200, -1.2, 0], [200, -1.0, 1.0])
    up, none = [[0.0, 0, 1]], np.zeros((0, 3))
    open_ = vis.occlusion(flat, up, [[0, 0, 0]], none)
    assert open_.open_fraction.min() == 1.0 and len(open_.hit_facet) == 0
    one = vis.occlusion(trimesh.util.concatenate([flat, wall]), up, [[0, 0, 0]], none)
    two = vis.occlusion(trimesh.util.concatenate([flat, wall, wall2]), up, [[0, 0, 0]], none)
    # rays leave 1e-4 of the mesh's size (0.04 m on walls 400 m long) above the
    # facet: the walls stand that much lower for it
    h = 1.0 - vis.RAY_OFFSET * np.linalg.norm([400.0, 2.4, 1.0])
    assert _view_factor(one, up[0])[0] == pytest.approx(wall_view(1.0, h), abs=0.005)
    assert _view_factor(two, up[0])[0] == pytest.approx(2 * wall_view(1.0, h) - 1, abs=0.005)
    # the blocked cells' faces are the walls' long sides (a few cells along the
    # walls meet their far ends), turned toward the facet
    n = two.hit_normal
    assert np.mean(np.abs(n[:, 1]) > 0.99) > 0.95
    from bayesgloss import render

    d = render.sphere_quadrature(3.0)[0][two.hit_cell]
    above = d[:, 2] > 0.06  # cells below the plane are cast tilted up into it
    assert np.all(np.sum(n * d, -1)[above] < 0)
    # the points met on a wall see the opposite wall, 2 m away and 1 m high: at
    # half height, (sin atan(0.5 / 2) + sin atan(0.5 / 2)) / 2 = 0.243 of their
    # view (crossed strings), so 0.757 open; 2 rays a point: a median near it
    assert np.median(two.hit_view) == pytest.approx(0.757, abs=0.05)


def test_mesh_shadow_on_the_ground_matches_a_box_shadow():
    # visibility._ground_sees_sun rasterises the mesh's shadow on a 256 x 256
    # grid over the box its bounding box casts; for a lone box the shadow is the
    # convex hull of its corners cast along the sun (render.ground_shadow).
    # Points farther than a grid cell from the shadow's edge must agree.
    from bayesgloss import render

    mesh = box([-0.5, -0.5, 0], [0.5, 0.5, 2.0])
    suns = np.array([sun(60.0, 180.0), sun(30.0, 250.0), sun(15.0, 90.0), [0, 0, -1.0]])
    rng = np.random.default_rng(5)
    points = np.c_[rng.uniform(-8, 8, (20000, 2)), np.zeros(20000)]
    lit = vis._ground_sees_sun(mesh, points, suns)
    shadow = render.ground_shadow(points[:, :2], suns, mesh.vertices)
    assert not lit[:, 3].any()  # the sun down: nothing lit
    # the shadow's length is 2 m / tan(elevation), at most 7.5 m: the grid's cell
    # is at most (7.5 + 1) / 256 = 0.033 m; points within 0.05 m of the edge may differ
    disagree = lit[:, :3] == shadow[:, :3]  # lit where the hull shadows, or the reverse
    assert disagree.mean() < 0.002
    inside = (np.abs(points[:, 0]) < 0.45) & (np.abs(points[:, 1]) < 0.45)
    assert not lit[inside, :3].any()  # under the box: no sun


def test_occlusion_sees_the_low_top_in_the_tall_box_shadow():
    # the tall-and-low boxes: the low top is open to the sky but for the tall
    # box's side; its sunlit fraction is facet_visibility's; its blocked
    # directions meet the tall box's east face (at x = 0.5, facing +x, toward
    # the low top east of it)
    mesh = tall_and_low()
    normal, center = LOW_TOP
    suns = np.array([sun(*s) for s in SUNS])
    occ = vis.occlusion(mesh, normal, center, suns)
    v = vis.facet_visibility(mesh, normal, center, suns)
    np.testing.assert_array_equal(occ.sunlit_fraction, v.sunlit_fraction)
    assert 0.8 < _view_factor(occ, normal[0])[0] < 1.0
    assert _view_factor(occ, normal[0])[0] == pytest.approx(v.sky_view_factor[0], abs=0.02)
    blocked = occ.open_fraction[0] < 1
    assert blocked.any() and np.allclose(occ.hit_normal, [1.0, 0, 0], atol=0.05)
    # the tall box's east face is lit by an eastern sun and in shade under a western one
    east, west = SUNS.index((60.0, 90.0)), SUNS.index((60.0, 270.0))
    assert occ.hit_sun[:, east].mean() > 0.5 and occ.hit_sun[:, west].max() == 0.0
    # the low top points up: its only downward cells are the ring just below
    # the horizon (cast, tilted up, as a lobe's nodes may reach them)
    from bayesgloss import render

    dz = render.sphere_quadrature(3.0)[0][occ.ground_cell, 2]
    assert np.all((dz < 0) & (dz > -0.06))


def test_bundle_occlusion_is_cached_and_none_without_a_mesh(tmp_path):
    from bayesgloss import bundle as bd

    with_mesh = read(write_mesh_bundle(tmp_path, "mesh"))
    without = read(write_mesh_bundle(tmp_path, "plain", with_mesh=False))
    assert vis.bundle_occlusion(without) is None
    vis._CACHE.clear()  # other tests' bundles of these boxes (same content) are cached
    t0 = time.perf_counter()
    first = vis.bundle_occlusion(with_mesh)
    t1 = time.perf_counter()
    again = vis.bundle_occlusion(read(with_mesh.path))  # the same content, read anew
    t2 = time.perf_counter()
    assert again is first and t2 - t1 < (t1 - t0)
    assert first.sunlit_fraction.shape == (4, len(TIMES))
    np.testing.assert_array_equal(
        first.sunlit_fraction, vis.bundle_visibility(with_mesh).sunlit_fraction
    )
    other = vis.bundle_occlusion(with_mesh, interreflection="none")
    assert other is not first and other.interreflection == "none"
    # a mesh changed on disk is a new map; a missing one a one-line error
    (with_mesh.path / "object_mesh.obj").write_text(
        (with_mesh.path / "object_mesh.obj").read_text() + "\n# changed\n"
    )
    assert vis.bundle_occlusion(with_mesh) is not first
    (with_mesh.path / "object_mesh.obj").unlink()
    with pytest.raises(bd.BundleError, match="field 'object_mesh': missing mesh"):
        vis.bundle_occlusion(with_mesh)


def test_joint_inputs_and_bundle_bases_use_the_mesh(tmp_path):
    # estimate's forward model on a bundle with object_mesh is the mesh's: the
    # joint model's sun basis loses the sun where the tall box shadows a facet
    # the sun faces, and keeps it on the tall top that nothing shades; the
    # fixed-brightness bases are render's with bundle_occlusion; without a mesh
    # both are the convex model's
    from bayesgloss import estimate, facets_estimate, joint_estimate, render, sky

    b = read(write_mesh_bundle(tmp_path, "mesh"))
    plain = read(write_mesh_bundle(tmp_path, "plain", with_mesh=False))
    occ = vis.bundle_occlusion(b)
    y, usable, censored = estimate.observations(estimate.bundle_curves(b))
    every, keep = np.ones_like(usable), np.arange(4)  # all entries: the bases whole
    none = np.zeros_like(censored)
    data, used, _ = joint_estimate.joint_inputs(b, y, every, none, keep, "gensky-clear")
    data0, used0, _ = joint_estimate.joint_inputs(plain, y, every, none, keep, "gensky-clear")
    assert used.tolist() == used0.tolist()
    sun = b.sun_direction[used]
    shadowed = (occ.sunlit_fraction[:, used] == 0) & (b.facets.normal @ sun.T > 0.1)
    assert shadowed.any()
    assert np.all(data.diffuse[0][shadowed] < 0.2 * data0.diffuse[0][shadowed])
    np.testing.assert_allclose(data.diffuse[0][1], data0.diffuse[0][1], rtol=1e-6)  # tall top
    # the fixed-brightness path
    day = sky.daylight("gensky-clear", b.sun_direction, ground_reflectance=b.ground_albedo)
    rho = b.ground_albedo
    np.testing.assert_array_equal(
        facets_estimate.bundle_bases(b, "gensky-clear").diffuse,
        render.facet_bases(b.view_geometry(), day, ground_reflectance=rho, occlusion=occ).diffuse,
    )
    np.testing.assert_array_equal(
        facets_estimate.bundle_bases(plain, "gensky-clear").diffuse,
        render.facet_bases(plain.view_geometry(), day, ground_reflectance=rho).diffuse,
    )

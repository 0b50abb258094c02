"""Bundles from photos, a camera file and a mesh (bayesgloss.capture, `bundle make`)."""

import json
import time
from fractions import Fraction

import numpy as np
import pandas as pd
import pytest

from bayesgloss import bundle as bd
from bayesgloss import camera_model, capture, cli, exif, geometry

# -- helpers: files a user would have ------------------------------------------


def write_obj(path, polygons, materials=False):
    """An OBJ of planar polygons, each a fan of triangles (``usemtl`` per polygon
    when ``materials``); vertices written once per polygon, to 17 digits."""
    lines, first = [], 1
    for k, poly in enumerate(polygons):
        if materials:
            lines.append(f"usemtl part{k}")
        lines += ["v {:.17g} {:.17g} {:.17g}".format(*v) for v in poly]
        lines += [f"f {first} {first + j} {first + j + 1}" for j in range(1, len(poly) - 1)]
        first += len(poly)
    path.write_text("\n".join(lines) + "\n")
    return path


def write_photo(
    path, pixels, when=None, offset=None, exposure=None, gps=None, subsec=None, quality=95
):
    """A JPEG (or PNG by suffix) with EXIF DateTimeOriginal ('YYYY:MM:DD HH:MM:SS'),
    SubSecTimeOriginal (digits), OffsetTimeOriginal, (ExposureTime [s], FNumber, ISO)
    and GPS (lat, lon)."""
    from PIL import Image, TiffImagePlugin

    exif = Image.Exif()
    sub = exif.get_ifd(0x8769)
    if when is not None:
        sub[0x9003] = when
    if offset is not None:
        sub[0x9011] = offset
    if subsec is not None:
        sub[0x9291] = subsec
    if exposure is not None:
        t, n, iso = exposure
        frac = Fraction(t).limit_denominator(2**31 - 1)
        sub[0x829A] = TiffImagePlugin.IFDRational(frac.numerator, frac.denominator)
        sub[0x829D] = TiffImagePlugin.IFDRational(int(round(n * 10)), 10)
        sub[0x8827] = int(iso)
    if gps is not None:
        g = exif.get_ifd(0x8825)
        for ref, tag, value, signs in ((1, 2, gps[0], "NS"), (3, 4, gps[1], "EW")):
            g[ref] = signs[value < 0]
            deg = abs(value)
            g[tag] = (
                TiffImagePlugin.IFDRational(int(deg), 1),
                TiffImagePlugin.IFDRational(int(deg * 60) % 60, 1),
                TiffImagePlugin.IFDRational(int(round(deg * 3600 * 1000)) % 60000, 1000),
            )
    img = Image.fromarray(np.asarray(pixels, dtype=np.uint8))
    if path.suffix.lower() in (".jpg", ".jpeg"):
        img.save(path, exif=exif.tobytes(), quality=quality, subsampling=0)
    else:
        img.save(path, exif=exif.tobytes())
    return path


def srgb_grey(code):
    """Linear value of an 8-bit sRGB grey code (IEC 61966-2-1)."""
    v = code / 255
    return v / 12.92 if v <= 0.04045 else ((v + 0.055) / 1.055) ** 2.4


def camera_dict(position, forward, up, f, width, height, distortion=None):
    """OpenCV camera file fields: R's rows are right, down, forward."""
    fwd = np.asarray(forward, float) / np.linalg.norm(forward)
    right = np.cross(fwd, up)
    right /= np.linalg.norm(right)
    down = np.cross(fwd, right)
    d = {
        "width": width,
        "height": height,
        "fx": f,
        "fy": f,
        "cx": (width - 1) / 2,
        "cy": (height - 1) / 2,
        "rotation": np.stack([right, down, fwd]).tolist(),
        "position": np.asarray(position, float).tolist(),
    }
    if distortion is not None:
        d["distortion"] = list(distortion)
    return d


# -- the key test: Radiance's frames, remade from mesh, camera file and JPEGs --------


#: Objects rendered, and the facet angle that finds their facets: the hemisphere's
#: top-ring neighbours are 2.9 deg apart, so 1 deg; the box and the gem: the default.
RENDERED = {
    "hemisphere": ({"shape": "hemisphere"}, 1.0),
    "box": ({"shape": "box", "box_size": (1.2, 0.8, 1.0), "box_azimuth": 20.0}, 10.0),
    "gem": ({"shape": "gem", "gem_azimuth": 10.0}, 10.0),
}


@pytest.fixture(scope="module", params=sorted(RENDERED))
def rendered(tmp_path_factory, request):
    """A small Radiance sequence of the paper's hemisphere (or a turned box) as 8-bit
    sRGB frames with per-frame auto-exposure, and the user's files made from it."""
    from bayesgloss import sequences

    shape, angle = RENDERED[request.param]
    root = tmp_path_factory.mktemp("capture")
    cfg = sequences.SequenceConfig(
        **shape,
        name="capture",
        view="SW",
        image_size=80,
        solar_hours=(7.0, 10.0, 12.0, 14.5, 17.0),
        specularity=0.5,
        pixel_encoding="srgb",
        exposure="auto",
        exposure_jitter=0.3,
    )
    (path,) = sequences.render_bundles([cfg], root / "cache", jobs=2, progress=False)
    truth = bd.read_bundle(path)
    facets = cfg.facets()
    write_obj(root / "object.obj", facets.polygons)
    cam, fwd, right, up, tan_half = sequences._camera_frame(cfg, facets)
    n = cfg.image_size
    # the renderer's pinhole: pixel column j's centre at x = ((j + 0.5) / n * 2 - 1) tan_half,
    # i.e. f = n / (2 tan_half) and the centre at (n - 1) / 2 in OpenCV's pixel coordinates
    camera = camera_dict(cam, fwd, [0, 0, 1], n / (2 * tan_half), n, n)
    assert np.allclose(camera["rotation"][1], -up)
    (root / "camera.json").write_text(json.dumps(camera))
    photos = root / "photos"
    photos.mkdir()
    gains = np.asarray(truth.truth["exposure"])
    local = truth.times.tz_convert("+02:00")
    for t in range(len(truth)):
        pixels, _ = truth.read_frame(t)
        write_photo(
            photos / f"IMG_{t:04d}.JPG",
            pixels,
            when=local[t].strftime("%Y:%m:%d %H:%M:%S"),
            offset="+02:00",
            subsec=f"{local[t].microsecond:06d}",
            exposure=(gains[t] / 250, 8.0, 200),
        )
    return cfg, truth, root, angle


@pytest.mark.radiance
def test_bundle_make_remakes_the_renderers_bundle(rendered, capsys):
    cfg, truth, root, angle = rendered
    out = root / "made"
    start = time.perf_counter()
    code = cli.main(
        [
            "bundle", "make", "--mesh", str(root / "object.obj"),
            "--camera", str(root / "camera.json"), "--photos", str(root / "photos"),
            "--out", str(out), "--latitude", "40", "--longitude", "0", "--facet-angle",
            str(angle),
        ]
    )  # fmt: skip
    seconds = time.perf_counter() - start
    assert code == 0, capsys.readouterr().err
    with pytest.warns(
        bd.BundleWarning, match="object_mesh 'object_mesh.obj' enters the forward model"
    ):
        made = bd.read_bundle(out)
    overlay = root / "overlay.png"
    labels_over = capture.label_overlay(made.read_frame(2)[0], made.labels)
    assert _make(root / "object.obj", root / "camera.json", root / "photos", root / "again",
                 "--latitude", "40", "--longitude", "0", "--facet-angle", str(angle),
                 "--overlay", str(overlay)) == 0  # fmt: skip
    from PIL import Image

    with Image.open(overlay) as img:
        np.testing.assert_array_equal(np.asarray(img), labels_over)
    print(f"{cfg.shape}: bundle make {seconds:.2f} s for {len(made)} frames of {made.shape}")

    # facets: each made facet is one of the object's (normal and centre)
    rendered_facets = cfg.facets()
    dist = np.linalg.norm(made.facets.center[:, None] - rendered_facets.center[None], axis=-1)
    match = rendered_facets.ids[np.argmin(dist, axis=1)]
    assert np.all(dist.min(axis=1) < 1e-9)
    assert len(np.unique(match)) == len(match)
    k = np.argmin(dist, axis=1)
    np.testing.assert_allclose(made.facets.normal, rendered_facets.normal[k], atol=1e-9)

    # labels: the renderer's own (centre and corner rays in rtrace) against ray casting
    lookup = np.zeros(made.facets.ids.max() + 1, dtype=int)
    lookup[made.facets.ids] = match
    ours = lookup[made.labels]
    theirs = truth.labels
    both = (ours > 0) & (theirs > 0)
    agree = np.mean(ours[both] == theirs[both])
    # facets under --min-facet-pixels (10) are dropped by design: coverage of the others
    # (measured 98.4 %: the rest are pixels with a corner exactly on a facet's edge, the
    # camera's vertical plane holding the hemisphere's edges at azimuth 225 deg)
    kept = np.isin(theirs, match)
    covered = np.sum(both) / np.sum(kept)
    print(f"labels agree on {100 * agree:.3f} % of {both.sum()} pixels labelled in both; "
          f"{100 * covered:.2f} % of the renderer's labelled pixels of kept facets labelled, "
          f"{100 * np.sum(both) / np.sum(theirs > 0):.2f} % of all")  # fmt: skip
    assert agree >= 0.98
    assert covered >= 0.95
    sizes = np.bincount(theirs.ravel())
    assert set(np.flatnonzero(sizes[1:] >= 20) + 1) <= set(match)

    # times and exposures round-trip (exposure: ExposureTime x ISO / FNumber^2)
    assert made.times.equals(truth.times)
    assert made.manifest["frames"][0]["time"].endswith("+02:00")
    gains = np.asarray(truth.truth["exposure"])
    np.testing.assert_allclose(made.exposure, gains / 250 * 200 / 64, rtol=1e-6)

    # curves: the JPEG's facets against the renderer's PNG's, on sun-lit facets
    mine = bd.facet_curves(made)
    ref = bd.facet_curves(truth)
    row = {fid: i for i, fid in enumerate(ref.ids)}
    mine_lum = mine.luminance
    ref_lum = ref.luminance[[row[m] for m in match]]
    lit = (made.sun_direction @ made.facets.normal.T).T > 0.2  # (F, T)
    ok = lit & mine.valid & ref.valid[[row[m] for m in match]] & (mine.n_pixels[:, None] >= 10)
    rel = np.abs(mine_lum[ok] / ref_lum[ok] - 1)
    print(f"curves: {ok.sum()} sun-lit entries, |rel. diff| median {np.median(rel):.4f}, "
          f"95 % {np.percentile(rel, 95):.4f}, max {rel.max():.4f}")  # fmt: skip
    assert ok.sum() >= 0.3 * ok.size  # hemisphere 65 of 110, box 7 of 15
    # 8-bit JPEG at quality 95 (4:4:4) against the renderer's 8-bit PNG: a code or two
    # per pixel, less in a facet's mean (measured: median 0.15 %, largest 1.0 %); the
    # issue's bar is 2 %
    assert rel.max() < 0.02


# -- EXIF: times, exposures, site -------------------------------------------------


def test_photo_time_with_offset_subseconds_and_stated_offset(tmp_path):
    pixels = np.zeros((4, 6, 3), np.uint8)
    p = write_photo(tmp_path / "a.jpg", pixels, "2024:06:21 14:30:05", "+02:00", subsec="25")
    t = exif.photo_time(p)
    assert t == pd.Timestamp("2024-06-21T12:30:05.25Z")
    assert t.isoformat() == "2024-06-21T14:30:05.250000+02:00"  # the camera's civil time kept
    # the photo's own offset wins over a stated one; a stated one serves where EXIF has none
    assert exif.photo_time(p, utc_offset="-05:00") == t
    q = write_photo(tmp_path / "b.png", pixels, "2024:12:01 08:00:00")
    assert exif.photo_time(q, utc_offset="-03:30") == pd.Timestamp("2024-12-01T11:30:00Z")
    with pytest.raises(capture.CaptureError, match=r"b\.png'.*'OffsetTimeOriginal'.*--utc-offset"):
        exif.photo_time(q)
    with pytest.raises(capture.CaptureError, match="'--utc-offset'.*not a UTC offset"):
        exif.photo_time(q, utc_offset="2h")
    r = write_photo(tmp_path / "c.jpg", pixels)
    with pytest.raises(capture.CaptureError, match=r"c\.jpg'.*'DateTimeOriginal'"):
        exif.photo_time(r, utc_offset="+00:00")


def test_photo_exposure_and_site_from_exif(tmp_path):
    pixels = np.zeros((4, 6, 3), np.uint8)
    p = write_photo(
        tmp_path / "a.jpg", pixels, exposure=(1 / 250, 5.6, 400), gps=(-33.8568, 151.2153)
    )
    # t ISO / N^2 = (1/250) 400 / 5.6^2 (FNumber stored as 56/10)
    assert exif.photo_exposure(p) == pytest.approx(400 / 250 / 5.6**2, rel=1e-12)
    lat, lon, alt = exif.photo_site(p)
    assert lat == pytest.approx(-33.8568, abs=1e-6) and lon == pytest.approx(151.2153, abs=1e-6)
    assert alt is None
    q = write_photo(tmp_path / "b.jpg", pixels)
    assert exif.photo_exposure(q) is None and exif.photo_site(q) is None


# -- the camera model ----------------------------------------------------------------


def test_distortion_round_trip_and_opencv_values():
    k = [-0.28, 0.09, 0.0012, -0.0008, -0.015]  # a wide-angle lens's sort of values
    x, y = np.meshgrid(np.linspace(-0.6, 0.6, 41), np.linspace(-0.45, 0.45, 31))
    xy = np.stack([x, y], -1)
    back = camera_model.undistort(camera_model.distort(xy, k), k)
    np.testing.assert_allclose(back, xy, atol=1e-10)
    # one point by hand from OpenCV's formula (cv::projectPoints' documentation)
    px, py = 0.3, -0.2
    r2 = px * px + py * py
    radial = 1 + k[0] * r2 + k[1] * r2**2 + k[4] * r2**3
    want = [
        px * radial + 2 * k[2] * px * py + k[3] * (r2 + 2 * px * px),
        py * radial + k[2] * (r2 + 2 * py * py) + 2 * k[3] * px * py,
    ]
    np.testing.assert_allclose(camera_model.distort([px, py], k), want, rtol=1e-14)
    # no distortion: the identity; four coefficients mean k3 = 0
    np.testing.assert_array_equal(camera_model.undistort(xy, [0] * 5), xy)
    # beyond the model's reach (k1 = -0.6: r (1 - 0.6 r^2) is at most 0.497) and for
    # NaN input, no undistorted point: NaN, not a wrong ray
    far = camera_model.undistort([[0.6, 0.0], [np.nan, 0.1], [0.3, 0.1]], [-0.6, 0, 0, 0, 0])
    assert np.all(np.isnan(far[:2])) and np.all(np.isfinite(far[2]))
    four = camera_model.distort(xy, k[:4])
    np.testing.assert_allclose(four, camera_model.distort(xy, [*k[:4], 0]))


def test_camera_file_conventions(tmp_path):
    d = camera_dict([1.0, 2.0, 3.0], [0, 1, 0], [0, 0, 1], 100.0, 64, 48)
    (tmp_path / "c.json").write_text(json.dumps(d))
    cam = camera_model.read_camera(tmp_path / "c.json")
    # looking north: a point ahead images at the principal point, one to the east
    # to the right, one above upward (smaller v)
    uv, front = camera_model.project(cam, [[1, 12, 3], [2, 12, 3], [1, 12, 4], [1, -8, 3]])
    np.testing.assert_allclose(uv[0], [31.5, 23.5])
    assert uv[1, 0] > 31.5 and uv[2, 1] < 23.5 and list(front) == [True, True, True, False]
    # the ray of a pixel goes back through the point that projects onto it
    ray = camera_model.camera_rays(cam, uv[1, 0], uv[1, 1])
    np.testing.assert_allclose(ray, np.array([1, 10, 0]) / np.sqrt(101), atol=1e-12)
    # OpenCV's rvec and tvec give the same camera
    rvec = _rotation_vector(np.array(d["rotation"]))
    tvec = -np.array(d["rotation"]) @ d["position"]
    d2 = {k: v for k, v in d.items() if k not in ("rotation", "position")}
    (tmp_path / "c2.json").write_text(
        json.dumps({**d2, "rotation": rvec, "translation": tvec.tolist()})
    )
    cam2 = camera_model.read_camera(tmp_path / "c2.json")
    np.testing.assert_allclose(cam2.rotation, cam.rotation, atol=1e-12)
    np.testing.assert_allclose(cam2.position, cam.position, atol=1e-12)


def _rotation_vector(r):
    """Axis x angle of a rotation matrix (angle below pi)."""
    angle = np.arccos((np.trace(r) - 1) / 2)
    axis = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    return (axis / (2 * np.sin(angle)) * angle).tolist()


# -- facets of a mesh ------------------------------------------------------------------


def test_region_growing_splits_a_cube_into_its_six_sides():
    import trimesh

    cube = trimesh.creation.box(extents=(2.0, 1.0, 0.5))  # 12 triangles about the origin
    for angle in (1.0, 10.0, 89.0):
        region, normal, center, area = capture.mesh_facets(cube, None, angle)
        assert len(normal) == 6 and np.all(np.bincount(region) == 2)
        # sides x: 1 x 0.5 m^2 at 1 m from the centre; y: 2 x 0.5 at 0.5 m; z: 2 x 1 at 0.25 m
        side = np.argmax(np.abs(normal), axis=1)
        np.testing.assert_allclose(area, np.array([0.5, 1.0, 2.0])[side], rtol=1e-12)
        np.testing.assert_allclose(np.abs(normal).max(axis=1), 1.0, atol=1e-12)
        np.testing.assert_allclose(
            np.einsum("fk,fk->f", center, normal), np.array([1.0, 0.5, 0.25])[side], atol=1e-12
        )


def test_region_growing_on_a_sphere_cap_makes_caps_of_the_stated_angle():
    import trimesh

    sphere = trimesh.creation.icosphere(subdivisions=4)  # 5120 faces, ~3.5 deg apart
    cap = sphere.submesh([np.flatnonzero(sphere.triangles_center[:, 2] > 0.5)], append=True)
    face_normal = cap.face_normals
    counts = {}
    for angle in (1.0, 10.0, 20.0):
        region, normal, _, area = capture.mesh_facets(cap, None, angle)
        counts[angle] = len(normal)
        # any two faces of a region are within twice the angle (each within it of the seed)
        for r in range(len(normal)):
            n = face_normal[region == r]
            cos = np.clip(n @ n.T, -1, 1)
            assert np.degrees(np.arccos(cos.min())) <= 2 * angle + 1e-9
        np.testing.assert_allclose(area.sum(), cap.area, rtol=1e-12)
        # most of the cap lies in regions of at least a quarter of a whole cap of
        # half-angle `angle` (the rest: leftovers between caps; measured 93-97 %)
        whole = 2 * np.pi * (1 - np.cos(np.radians(angle))) / (cap.area / len(cap.faces))
        big = np.bincount(region) >= whole / 4
        assert area[big].sum() >= 0.9 * cap.area
    assert counts[1.0] == len(cap.faces)  # neighbours differ by more than 1 deg
    assert counts[1.0] > 4 * counts[10.0] > 4 * counts[20.0]
    print(f"sphere cap of {len(cap.faces)} faces: regions by angle {counts}")


def test_regions_never_cross_the_meshs_groups(tmp_path):
    # one plane split into two materials: two facets; without materials, one
    square = [np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)]
    halves = [
        np.array([[0, 0, 0], [1, 0, 0], [1, 0.5, 0], [0, 0.5, 0]], float),
        np.array([[0, 0.5, 0], [1, 0.5, 0], [1, 1, 0], [0, 1, 0]], float),
    ]
    mesh, group = capture.load_mesh(write_obj(tmp_path / "two.obj", halves, materials=True))
    assert len(np.unique(group)) == 2
    assert len(capture.mesh_facets(mesh, group, 10.0)[1]) == 2
    mesh, group = capture.load_mesh(write_obj(tmp_path / "one.obj", halves))
    assert len(capture.mesh_facets(mesh, group, 10.0)[1]) == 1
    mesh, group = capture.load_mesh(write_obj(tmp_path / "sq.obj", square))
    assert len(capture.mesh_facets(mesh, group, 10.0)[1]) == 1


# -- a small scene without Radiance: a box, a camera file and two photos --------------


def _box_scene(tmp_path, distortion=None, size=(48, 36), aim=(0.0, 0.0, 0.5), dated=True, **photo):
    """A 1 m box on the ground, a camera file looking at it from the south-west, and
    two grey JPEG photos with EXIF (``photo`` overrides write_photo's fields)."""
    import trimesh

    box = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    box.apply_translation([0, 0, 0.5])
    mesh = tmp_path / "box.ply"
    box.export(mesh)
    width, height = size
    position = np.array([-3.0, -2.5, 1.8])
    cam = camera_dict(position, aim - position, [0, 0, 1], 1.6 * width, width, height,
                      distortion)  # fmt: skip
    camera = tmp_path / "camera.json"
    camera.write_text(json.dumps(cam))
    photos = tmp_path / "photos"
    photos.mkdir(exist_ok=True)
    fields = dict(offset="+01:00", exposure=(1 / 125, 8.0, 100), gps=(51.5, -0.1))
    fields.update(photo)
    pixels = np.full((height, width, 3), 128, np.uint8)
    for k, hour in enumerate((10, 14)):
        when = f"2024:06:21 {hour}:00:00" if dated else None
        write_photo(photos / f"p{k}.jpg", pixels, when=when, **fields)
    return mesh, camera, photos


def _make(mesh, camera, photos, out, *more):
    return cli.main(
        ["bundle", "make", "--mesh", str(mesh), "--camera", str(camera), "--photos",
         str(photos), "--out", str(out), *more]
    )  # fmt: skip


def test_bundle_make_on_a_box_uses_exif_site_and_exposure(tmp_path, capsys):
    mesh, camera, photos = _box_scene(tmp_path)
    assert _make(mesh, camera, photos, tmp_path / "out") == 0
    out = capsys.readouterr().out
    assert _make(mesh, camera, photos, tmp_path / "out") == 2  # an existing bundle stays
    assert "bundle '" in capsys.readouterr().err
    assert _make(mesh, camera, photos, tmp_path / "out", "--overwrite") == 0
    capsys.readouterr()
    assert "2 frames" in out and "3 facets seen of 6" in out, out
    with pytest.warns(bd.BundleWarning, match="object_mesh 'object_mesh.ply'"):
        b = bd.read_bundle(tmp_path / "out")
    assert b.site.latitude == pytest.approx(51.5, abs=1e-6)
    assert b.site.longitude == pytest.approx(-0.1, abs=1e-6)
    np.testing.assert_allclose(b.exposure, 100 / 125 / 64)
    assert list(b.times.hour) == [9, 13] and b.pixel_encoding == "srgb"
    # the camera at (-3, -2.5, 1.8) sees the west, south and top sides
    np.testing.assert_allclose(
        sorted(map(tuple, b.facets.normal)), [(-1, 0, 0), (0, -1, 0), (0, 0, 1)], atol=1e-12
    )


def _projection_check(made, cam, rng):
    """Points on each seen side of the box projected by OpenCV's forward model: how
    many land in a pixel of their own facet, and how many in another facet's."""
    own = other = 0
    for fid, normal, center in zip(made.facets.ids, made.facets.normal, made.facets.center,
                                   strict=True):  # fmt: skip
        axes = np.eye(3)[np.abs(normal) < 0.5]  # the side's two in-plane axes
        points = center + rng.uniform(-0.5, 0.5, (4000, 2)) @ axes
        uv, front = camera_model.project(cam, points)
        assert np.all(front)
        col, row = np.rint(uv).astype(int).T
        inside = (col >= 0) & (col < cam.width) & (row >= 0) & (row < cam.height)
        found = made.labels[row[inside], col[inside]]
        own += np.sum(found == fid)
        other += np.sum((found != fid) & (found > 0))
    return own, other


def test_labels_in_a_distorted_camera_match_the_forward_projection(tmp_path):
    # points on the box's sides, projected through OpenCV's forward model (distort),
    # land in pixels labelled with their side, or in unlabelled (edge) pixels
    k = [-0.6, 0.2, 0.002, -0.001, 0.0]  # a wide-angle lens's barrel distortion
    # aimed beside the box, so that it images off-centre where the distortion is strong
    mesh, camera, photos = _box_scene(tmp_path, k, (96, 72), aim=(-0.2, 0.9, 0.2))
    made = capture.make_bundle(mesh, camera, [photos], tmp_path / "out")
    cam = camera_model.read_camera(camera)
    own, other = _projection_check(made, cam, np.random.default_rng(1))
    assert other == 0 and own > 4000
    # the check can fail: labels made without the distortion put points in other sides
    plain = json.loads(camera.read_text())
    plain.pop("distortion")
    (tmp_path / "plain.json").write_text(json.dumps(plain))
    wrong = capture.make_bundle(mesh, tmp_path / "plain.json", [photos], tmp_path / "plain")
    own, other = _projection_check(wrong, cam, np.random.default_rng(1))
    print(f"without its distortion: {other} of {own + other} points in another facet")
    assert other > 30, (own, other)  # measured 68


# -- bad input: one line naming the file, the field and the problem; exit 2 -------------


def _bad_mesh(tmp_path):
    mesh, camera, photos = _box_scene(tmp_path)
    mesh.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nend_header\n")
    return (mesh, camera, photos), (), ("mesh", mesh, "field '")


def _camera_without_fx(tmp_path):
    mesh, camera, photos = _box_scene(tmp_path)
    fields = json.loads(camera.read_text())
    del fields["fx"]
    camera.write_text(json.dumps(fields))
    return (mesh, camera, photos), (), ("camera", camera, "field 'fx': missing required field")


def _photos_without_times(tmp_path):
    files = _box_scene(tmp_path, dated=False)
    return files, (), ("photo", files[2] / "p0.jpg", "field 'DateTimeOriginal'")


def _no_offset(tmp_path):
    files = _box_scene(tmp_path, offset=None)
    return files, (), ("photo", files[2] / "p0.jpg", "field 'OffsetTimeOriginal'", "--utc-offset")


def _unseen_mesh(tmp_path):
    files = _box_scene(tmp_path, aim=(-6.0, -5.0, 3.1))  # looking away from the box
    return files, (), ("camera", files[1], "field 'rotation/position'", "sees no facet", "box.ply")


def _no_site(tmp_path):
    files = _box_scene(tmp_path, gps=None)
    return files, (), ("photos", files[2], "field 'GPSLatitude'", "--latitude")


def _photo_of_another_size(tmp_path):
    mesh, camera, photos = _box_scene(tmp_path)
    write_photo(
        photos / "p1.jpg", np.zeros((10, 10, 3)), "2024:06:21 12:00:00", "+01:00",
        exposure=(1 / 125, 8.0, 100),
    )  # fmt: skip
    return (mesh, camera, photos), (), ("photo", photos / "p1.jpg", "field 'size'", "10 x 10")


@pytest.mark.parametrize(
    "case",
    [_bad_mesh, _camera_without_fx, _photos_without_times, _no_offset, _unseen_mesh, _no_site,
     _photo_of_another_size],
)  # fmt: skip
def test_bad_input_is_one_line_naming_file_and_field(tmp_path, capsys, case):
    (mesh, camera, photos), more, expected = case(tmp_path)
    capsys.readouterr()
    assert _make(mesh, camera, photos, tmp_path / "out", *more) == 2
    captured = capsys.readouterr()
    err = captured.err
    assert err.count("\n") == 1 and err.startswith("bayesgloss bundle: error: "), err
    kind, file, *words = expected
    assert f"{kind} '{file}'" in err, err
    for word in words:
        assert word in err, err
    assert "Traceback" not in err and not (tmp_path / "out").exists()


def test_a_stated_offset_serves_photos_without_one(tmp_path, capsys):
    files = _box_scene(tmp_path, offset=None)
    assert _make(*files, tmp_path / "out", "--utc-offset=-04:00") == 0
    manifest = json.loads((tmp_path / "out" / bd.MANIFEST).read_text())
    assert [f["time"] for f in manifest["frames"]] == [
        "2024-06-21T10:00:00-04:00",
        "2024-06-21T14:00:00-04:00",
    ]


def test_a_mesh_wound_inside_out_gets_outward_normals_and_a_warning(tmp_path):
    import trimesh

    mesh, camera, photos = _box_scene(tmp_path)
    box = trimesh.load_mesh(mesh)
    inside_out = trimesh.Trimesh(box.vertices, box.faces[:, ::-1], process=False)
    inside_out.export(tmp_path / "inside_out.ply")
    with pytest.warns(capture.CaptureWarning, match="sees 3 of 3 facets from behind"):
        made = capture.make_bundle(tmp_path / "inside_out.ply", camera, [photos], tmp_path / "o")
    normal = made.facets.normal
    np.testing.assert_allclose(
        sorted(map(tuple, normal)), [(-1, 0, 0), (0, -1, 0), (0, 0, 1)], atol=1e-12
    )


def _assert_same_facets(made, reference):
    """The same facets (normals, centres) and labels, whatever their numbering."""
    dot = made.facets.normal @ reference.facets.normal.T
    match = np.argmax(dot, axis=1)
    assert np.all(dot.max(axis=1) > 1 - 1e-9) and len(set(match)) == len(match)
    np.testing.assert_allclose(made.facets.center, reference.facets.center[match], atol=1e-6)
    lookup = np.zeros(made.facets.ids.max() + 1, dtype=int)
    lookup[made.facets.ids] = reference.facets.ids[match]
    np.testing.assert_array_equal(lookup[made.labels], reference.labels)


def test_png_photos_are_copied_and_a_transformed_stl_is_written_in_the_world_frame(tmp_path):
    import trimesh

    mesh, camera, photos = _box_scene(tmp_path)
    reference = capture.make_bundle(mesh, camera, [photos], tmp_path / "ref")
    # the same box in a y-up frame (x east, y up, z south), as STL, with its transform
    box = trimesh.load_mesh(mesh)
    to_world = np.array([[1, 0, 0, 0], [0, 0, -1, 0], [0, 1, 0, 0], [0, 0, 0, 1]], float)
    y_up = box.copy()
    y_up.apply_transform(np.linalg.inv(to_world))
    y_up.export(tmp_path / "box_y_up.stl")
    # PNG photos of the same codes, with EXIF in eXIf chunks
    pngs = tmp_path / "pngs"
    pngs.mkdir()
    for k, hour in enumerate((10, 14)):
        write_photo(pngs / f"p{k}.png", np.full((36, 48, 3), 128, np.uint8),
                    f"2024:06:21 {hour}:00:00", "+01:00", exposure=(1 / 125, 8.0, 100),
                    gps=(51.5, -0.1))  # fmt: skip
    transform = ",".join(f"{v:g}" for v in to_world.ravel())
    out = tmp_path / "out"
    assert _make(tmp_path / "box_y_up.stl", camera, pngs, out, "--mesh-transform", transform) == 0
    with pytest.warns(bd.BundleWarning, match="object_mesh 'object_mesh.ply'"):
        made = bd.read_bundle(out)
    _assert_same_facets(made, reference)
    assert [f.suffix for f in made.frame_files] == [".png", ".png"]
    assert made.frame_files[0].read_bytes() == (pngs / "p0.png").read_bytes()
    curves = bd.facet_curves(made)  # the reader decodes PNGs that carry an eXIf chunk
    np.testing.assert_allclose(curves.luminance, srgb_grey(128), rtol=1e-6)
    world = trimesh.load_mesh(out / "object_mesh.ply")
    np.testing.assert_allclose(world.bounds, [[-0.5, -0.5, 0], [0.5, 0.5, 1]], atol=1e-12)


def test_label_overlay_keeps_the_frame_outside_the_labels():
    frame = np.full((4, 5, 3), 200, np.uint8)
    labels = np.zeros((4, 5), int)
    labels[1:3, 1:3] = 1
    labels[0, 4] = 7
    out = capture.label_overlay(frame, labels, alpha=0.5)
    assert out.dtype == np.uint8 and out.shape == (4, 5, 3)
    np.testing.assert_array_equal(out[labels == 0], frame[labels == 0])
    assert np.all(out[1, 1] == out[2, 2]) and not np.all(out[1, 1] == out[0, 4])
    assert not np.all(out[1, 1] == frame[1, 1])
    grey16 = capture.label_overlay(np.full((4, 5), 65535, np.uint16), labels)
    np.testing.assert_array_equal(grey16[labels == 0], 255)


def test_site_frame_turns_a_local_model_to_north():
    m = capture.site_frame(90.0, origin=(5.0, 0.0, 0.0))
    # local +y toward the east (bearing 90), local +x toward the south; origin moved
    np.testing.assert_allclose(m @ [0, 1, 0, 0], [1, 0, 0, 0], atol=1e-15)
    np.testing.assert_allclose(m @ [1, 0, 0, 0], [0, -1, 0, 0], atol=1e-15)
    np.testing.assert_allclose(m @ [0, 0, 0, 1], [5, 0, 0, 1], atol=1e-15)
    np.testing.assert_allclose(capture.site_frame(0.0), np.eye(4))


def test_mesh_north_gives_the_same_bundle_as_a_world_mesh(tmp_path):
    import trimesh

    mesh, camera, photos = _box_scene(tmp_path)
    reference = capture.make_bundle(mesh, camera, [photos], tmp_path / "ref")
    local = trimesh.load_mesh(mesh)
    local.apply_transform(np.linalg.inv(capture.site_frame(30.0)))  # its +y at bearing 30
    local.export(tmp_path / "local.ply")
    assert _make(tmp_path / "local.ply", camera, photos, tmp_path / "out", "--mesh-north",
                 "30") == 0  # fmt: skip
    with pytest.warns(bd.BundleWarning):
        made = bd.read_bundle(tmp_path / "out")
    _assert_same_facets(made, reference)


# -- COLMAP models ------------------------------------------------------------------


def _colmap_model(folder, cam, name="p0.jpg", binary=False, model="OPENCV"):
    """A COLMAP sparse model of one image seen by an OpenCV camera: the pose as
    qvec (w, x, y, z) and t = -R C, the principal point at COLMAP's +0.5."""
    import struct

    from scipy.spatial.transform import Rotation

    x, y, z, w = (float(v) for v in Rotation.from_matrix(cam.rotation).as_quat())
    t = [float(v) for v in -cam.rotation @ cam.position]
    k1, k2, p1, p2, _ = cam.distortion
    params = {
        "OPENCV": (4, [cam.fx, cam.fy, cam.cx + 0.5, cam.cy + 0.5, k1, k2, p1, p2]),
        "PINHOLE": (1, [cam.fx, cam.fy, cam.cx + 0.5, cam.cy + 0.5]),
    }
    model_id, values = params[model]
    folder.mkdir(parents=True)
    if binary:
        head = struct.pack("<QiiQQ", 1, 1, model_id, cam.width, cam.height)
        (folder / "cameras.bin").write_bytes(head + struct.pack(f"<{len(values)}d", *values))
        image = struct.pack("<Qi7di", 1, 1, w, x, y, z, *t, 1) + name.encode() + b"\0"
        image += struct.pack("<Q2dq", 1, 10.0, 12.0, -1)  # one 2-D point
        (folder / "images.bin").write_bytes(image)
    else:
        (folder / "cameras.txt").write_text(
            "# Camera list\n" + f"1 {model} {cam.width} {cam.height} "
            + " ".join(repr(float(v)) for v in values) + "\n"
        )  # fmt: skip
        (folder / "images.txt").write_text(
            "# Image list\n"
            + f"1 {w!r} {x!r} {y!r} {z!r} {t[0]!r} {t[1]!r} {t[2]!r} 1 images/{name}\n\n"
        )


@pytest.mark.parametrize("binary", [False, True])
def test_a_colmap_model_gives_the_camera_files_camera(tmp_path, binary):
    mesh, camera, photos = _box_scene(tmp_path, distortion=[-0.2, 0.05, 0.001, 0.0, 0.0])
    cam = camera_model.read_camera(camera)
    _colmap_model(tmp_path / "sparse", cam, binary=binary)
    got = camera_model.read_colmap(tmp_path / "sparse", ["other.jpg", "p0.jpg"])
    for field in ("fx", "fy", "cx", "cy", "width", "height"):
        assert getattr(got, field) == pytest.approx(getattr(cam, field), rel=1e-12)
    np.testing.assert_allclose(got.rotation, cam.rotation, atol=1e-12)
    np.testing.assert_allclose(got.position, cam.position, atol=1e-12)
    np.testing.assert_allclose(got.distortion, cam.distortion, atol=1e-15)
    with pytest.raises(capture.CaptureError, match="field 'images': holds none of the photos"):
        camera_model.read_colmap(tmp_path / "sparse", ["x.jpg"])


def test_bundle_make_from_a_colmap_model_in_the_reconstructions_frame(tmp_path):
    import trimesh

    mesh, camera, photos = _box_scene(tmp_path)
    reference = capture.make_bundle(mesh, camera, [photos], tmp_path / "ref")
    # a reconstruction in its own frame: scaled by 2.5, turned, shifted from the world
    to_world = capture.site_frame(40.0, origin=(3.0, -1.0, 0.2)) @ np.diag([0.4, 0.4, 0.4, 1])
    to_recon = np.linalg.inv(to_world)
    box = trimesh.load_mesh(mesh)
    box.apply_transform(to_recon)
    box.export(tmp_path / "recon.ply")
    cam = camera_model.transform_camera(camera_model.read_camera(camera), to_recon)
    _colmap_model(tmp_path / "sparse", cam, model="PINHOLE")
    transform = ",".join(repr(float(v)) for v in to_world.ravel())
    code = _make(tmp_path / "recon.ply", tmp_path / "sparse", photos, tmp_path / "out",
                 "--mesh-transform", transform)  # fmt: skip
    assert code == 0
    with pytest.warns(bd.BundleWarning):
        made = bd.read_bundle(tmp_path / "out")
    _assert_same_facets(made, reference)
    np.testing.assert_allclose(made.camera_position, camera_model.read_camera(camera).position)


def test_embree_and_trimeshs_own_ray_casting_label_alike(tmp_path):
    # Embree (embreex) traces in single precision; trimesh's own ray-triangle tests in
    # double: the labels differ at most in a few pixels with a corner on an edge
    import trimesh

    pytest.importorskip("embreex")
    polygons = geometry.tessellated_hemisphere(n_rings=4, n_segments=8).polygons
    world, group = capture.load_mesh(write_obj(tmp_path / "h.obj", polygons))
    region = capture.mesh_facets(world, group, 1.0)[0]
    cam = camera_model.Camera(
        64, 48, 110.0, 110.0, 31.5, 23.5, np.array([-0.3, 0.1, 0.001, 0.0, 0.0]),
        np.array(camera_dict([-4, -3, 1.5], [4, 3, -1.2], [0, 0, 1], 1, 1, 1)["rotation"]),
        np.array([-4.0, -3.0, 1.5]),
    )  # fmt: skip
    assert type(world.ray).__module__.endswith("ray_pyembree")
    fast = capture.label_image(world, region, cam)
    world.ray = trimesh.ray.ray_triangle.RayMeshIntersector(world)
    exact = capture.label_image(world, region, cam)
    assert np.sum(exact >= 0) > 500  # measured 651 labelled, 0 different
    assert np.sum(fast != exact) <= 0.005 * np.sum(exact >= 0), np.sum(fast != exact)


def test_photos_as_files_and_a_turned_photo(tmp_path, capsys):
    from PIL import Image

    mesh, camera, photos = _box_scene(tmp_path)
    files = [str(photos / "p1.jpg"), str(photos / "p0.jpg")]  # written in time order
    code = cli.main(["bundle", "make", "--mesh", str(mesh), "--camera", str(camera),
                     "--photos", *files, "--out", str(tmp_path / "out")])  # fmt: skip
    assert code == 0
    manifest = json.loads((tmp_path / "out" / bd.MANIFEST).read_text())
    assert [f["time"][11:13] for f in manifest["frames"]] == ["10", "14"]
    # a photo stored turned (portrait pixels, EXIF Orientation 6) is named as such
    with Image.open(photos / "p0.jpg") as img:
        exif = img.getexif()
        exif[0x0112] = 6
        img.transpose(Image.Transpose.ROTATE_90).save(photos / "p0.jpg", exif=exif.tobytes())
    assert _make(mesh, camera, photos, tmp_path / "turned") == 2
    assert "EXIF Orientation turns it by 90 deg" in capsys.readouterr().err
    (tmp_path / "empty").mkdir()
    assert _make(mesh, camera, tmp_path / "empty", tmp_path / "none") == 2
    err = capsys.readouterr().err
    assert (
        f"photos '{tmp_path / 'empty'}'" in err
        and "holds no photo (JPEG, PNG, TIFF or camera RAW)" in err
    )


def test_undistort_refuses_a_root_past_the_lens_models_fold():
    # k1 = -3: r (1 - 3 r^2) rises to 0.192 at r = 1/3, then falls through 0 at
    # r = 0.577 to -0.35 at r = 0.75: a distorted radius of 0.3 has no physical
    # undistorted point, but (-x, -y) at r ~ 0.72 solves the equations (the point
    # mapped through the centre); it must be NaN, not that backward ray
    k = [-3.0, 0.0, 0.0, 0.0, 0.0]
    far = camera_model.undistort([[0.3, 0.0], [0.0, -0.35], [0.1, 0.05]], k)
    assert np.all(np.isnan(far[:2]))
    np.testing.assert_allclose(camera_model.distort(far[2], k), [0.1, 0.05], atol=1e-12)
    x = np.array([-0.72, 0.0])  # the spurious root exists
    assert np.linalg.norm(camera_model.distort(x, k) - [0.72 * (3 * 0.72**2 - 1), 0]) < 1e-12


# -- camera RAW (rawpy, decoded linearly) ---------------------------------------------


def write_dng(path, cfa, when=None, offset=None, exposure=None, black=256, white=16383,
              neutral=(0.5, 1.0, 0.625)):  # fmt: skip
    """A minimal uncompressed Bayer (RGGB) DNG 1.4, little-endian, written byte by
    byte from the TIFF 6.0 and DNG 1.4 specifications: IFD0 with the DNG tags (black
    and white levels, an identity ColorMatrix1, AsShotNeutral ``neutral``, the
    camera's response to a grey) and an Exif IFD with DateTimeOriginal,
    OffsetTimeOriginal, ExposureTime [s], FNumber and ISO (``exposure``)."""
    import struct

    cfa = np.ascontiguousarray(cfa, dtype="<u2")
    h, w = cfa.shape
    byte, ascii_, short, long_, rational, srational = 1, 2, 3, 4, 5, 10

    def ratio(v):
        f = Fraction(v).limit_denominator(1_000_000)
        return (f.numerator, f.denominator)

    exif = []
    if when is not None:
        exif.append((36867, ascii_, when.encode() + b"\0"))
    if offset is not None:
        exif.append((36881, ascii_, offset.encode() + b"\0"))
    if exposure is not None:
        t, n, iso = exposure
        exif += [(33434, rational, [ratio(t)]), (33437, rational, [ratio(n)]),
                 (34855, short, [int(iso)])]  # fmt: skip
    identity = [(1, 1), (0, 1), (0, 1), (0, 1), (1, 1), (0, 1), (0, 1), (0, 1), (1, 1)]

    def ifd0(pixels_at, exif_at):
        tags = [
            (254, long_, [0]), (256, long_, [w]), (257, long_, [h]), (258, short, [16]),
            (259, short, [1]), (262, short, [32803]), (271, ascii_, b"bayesgloss\0"),
            (272, ascii_, b"test DNG\0"), (273, long_, [pixels_at]), (274, short, [1]),
            (277, short, [1]), (278, long_, [h]), (279, long_, [cfa.nbytes]),
            (284, short, [1]), (33421, short, [2, 2]), (33422, byte, bytes([0, 1, 1, 2])),
            (50706, byte, bytes([1, 4, 0, 0])), (50708, ascii_, b"bayesgloss test DNG\0"),
            (50714, long_, [black]), (50717, long_, [white]), (50721, srational, identity),
            (50728, rational, [ratio(v) for v in neutral]), (50778, short, [21]),
        ]  # fmt: skip
        return tags + ([(34665, long_, [exif_at])] if exif else [])

    def packed(typ, value):
        if typ in (byte, ascii_):
            return bytes(value)
        if typ in (short, long_):
            return struct.pack(f"<{len(value)}{'H' if typ == short else 'I'}", *value)
        return b"".join(struct.pack("<ii" if typ == srational else "<II", *r) for r in value)

    def block(entries, start):
        """An IFD at file offset ``start``, then its values longer than 4 bytes."""
        head, data = struct.pack("<H", len(entries)), b""
        data_at = start + 2 + 12 * len(entries) + 4
        for tag, typ, value in sorted(entries, key=lambda e: e[0]):
            raw = packed(typ, value)
            field = raw.ljust(4, b"\0") if len(raw) <= 4 else struct.pack("<I", data_at + len(data))
            if len(raw) > 4:
                data += raw + b"\0" * (len(raw) % 2)
            head += struct.pack("<HHI", tag, typ, len(value)) + field
        return head + struct.pack("<I", 0) + data

    exif_at = 8 + len(block(ifd0(0, 0), 8))  # the sizes do not depend on the offsets
    exif_block = block(exif, exif_at) if exif else b""
    pixels_at = exif_at + len(exif_block) + (exif_at + len(exif_block)) % 2
    out = b"II*\0" + struct.pack("<I", 8) + block(ifd0(pixels_at, exif_at), 8) + exif_block
    path.write_bytes(out.ljust(pixels_at, b"\0") + cfa.tobytes())
    return path


def bayer(scene, gain, black=256, white=16383, neutral=(0.5, 1.0, 0.625)):
    """RGGB raw codes of a grey scene (H, W) of relative radiance, times ``gain``."""
    h, w = scene.shape
    channel = np.array([[0, 1], [1, 2]])[np.arange(h)[:, None] % 2, np.arange(w)[None, :] % 2]
    codes = black + gain * scene * np.asarray(neutral)[channel] * (white - black)
    return np.clip(np.rint(codes), 0, white).astype(np.uint16)


def test_raw_is_decoded_linearly(tmp_path):
    pytest.importorskip("rawpy")
    from bayesgloss import images

    h, w = 36, 48
    scene = np.broadcast_to(0.05 + 0.4 * np.linspace(0, 1, w), (h, w))  # a grey ramp
    one = write_dng(tmp_path / "one.dng", bayer(scene, 1.0))
    half = write_dng(tmp_path / "half.dng", bayer(scene, 0.5))
    a, b = images.read_raw(one), images.read_raw(half)
    assert a.shape == (h, w, 3) and a.dtype == np.uint16
    inner = (slice(2, -2), slice(2, -2))  # the demosaic's border pixels aside
    ratio = a[inner] / b[inner].astype(float)
    print(f"pixel ratio of exposures 1 and 1/2: {ratio.min():.4f} - {ratio.max():.4f}")
    np.testing.assert_allclose(ratio, 2.0, rtol=0.01)  # measured 1.993 - 2.008 (rounding)
    # linear in the scene: codes = 65535 x (raw - black) / (white - black) after the white
    # balance (AsShotNeutral) makes the grey grey; no transfer curve, no brightening
    want = np.broadcast_to(65535 * scene[inner][..., None], a[inner].shape)
    fit = np.polyfit(want.ravel(), a[inner].astype(float).ravel(), 1)
    deviation = np.max(np.abs(a[inner] - np.polyval(fit, want))) / 65535
    print(f"codes against the scene: slope {fit[0]:.5f}, intercept {fit[1]:.2f}, largest "
          f"deviation from the line {deviation:.2e} of full scale")  # fmt: skip
    np.testing.assert_allclose(a[inner], want, rtol=0.005, atol=3)  # the demosaic's few codes
    assert deviation < 1e-3
    (tmp_path / "bad.nef").write_bytes(b"not a raw file " * 64)
    with pytest.raises(ValueError, match=r"bad\.nef: rawpy \(LibRaw\) cannot decode it"):
        images.read_raw(tmp_path / "bad.nef")


def test_raw_frames_near_white_keep_their_ratio(tmp_path):
    # Two frames of one scene whose brightest photosites sit at 95 % and 81 % of the white
    # level. LibRaw's default (adjust_maximum_thr 0.75) scales each frame to its own
    # maximum, which would decode both as equally bright (ratio ~1.0); a linear decode
    # keeps the exposure ratio 1 / 0.85 = 1.176 and the absolute codes of the scene.
    pytest.importorskip("rawpy")
    from bayesgloss import images

    h, w = 36, 48
    scene = np.broadcast_to(0.05 + 0.9 * np.linspace(0, 1, w), (h, w))  # up to 0.95 of white
    # a neutral of 1 in every channel, so that the white-balanced grey stays below white
    one = write_dng(tmp_path / "one.dng", bayer(scene, 1.0, neutral=(1, 1, 1)), neutral=(1, 1, 1))
    dim = write_dng(tmp_path / "dim.dng", bayer(scene, 0.85, neutral=(1, 1, 1)), neutral=(1, 1, 1))
    a, b = images.read_raw(one).astype(float), images.read_raw(dim).astype(float)
    inner = (slice(2, -2), slice(2, -2))
    ratio = a[inner] / b[inner]
    print(f"pixel ratio of exposures 1 and 0.85: {ratio.min():.4f} - {ratio.max():.4f}")
    np.testing.assert_allclose(ratio, 1 / 0.85, rtol=0.01)  # rounding of 14-bit codes
    want = np.broadcast_to(65535 * scene[inner][..., None], a[inner].shape)
    np.testing.assert_allclose(a[inner], want, rtol=0.005, atol=3)


def test_raw_exif_from_its_tiff_tags_and_from_libraw(tmp_path):
    pytest.importorskip("rawpy")
    p = write_dng(tmp_path / "a.dng", bayer(np.full((32, 32), 0.3), 1.0),
                  when="2024:06:21 14:30:05", offset="+02:00",
                  exposure=(1 / 250, 5.6, 400))  # fmt: skip
    assert exif.photo_time(p) == pd.Timestamp("2024-06-21T12:30:05Z")
    assert exif.photo_exposure(p) == pytest.approx(400 / 250 / 5.6**2, rel=1e-9)
    assert exif.photo_site(p) is None and exif.photo_orientation(p) == 1
    # LibRaw's own reading, for RAW formats that are not TIFF: the time without offset
    _, tags, _ = exif._libraw_exif(p)
    assert tags[0x9003] == "2024:06:21 14:30:05" and 0x9011 not in tags
    t, n, iso = tags[0x829A], tags[0x829D], tags[0x8827]
    assert t * iso / n**2 == pytest.approx(400 / 250 / 5.6**2, rel=1e-6)


def test_bundle_make_from_raw_photos_is_linear(tmp_path, capsys):
    pytest.importorskip("rawpy")
    mesh, camera, photos = _box_scene(tmp_path)
    raws = tmp_path / "raws"
    raws.mkdir()
    for k, (hour, gain) in enumerate(((10, 0.8), (14, 0.4))):
        write_dng(raws / f"IMG_{k}.DNG", bayer(np.full((36, 48), 0.5), gain),
                  when=f"2024:06:21 {hour}:00:00", offset="+01:00",
                  exposure=(gain / 100, 8.0, 100))  # fmt: skip
    out = tmp_path / "out"
    overlay = tmp_path / "overlay.png"
    assert _make(mesh, camera, raws, out, "--latitude", "51.5", "--longitude", "-0.1",
                 "--overlay", str(overlay)) == 0  # fmt: skip
    with pytest.warns(bd.BundleWarning, match="object_mesh"):
        made = bd.read_bundle(out)
    assert made.pixel_encoding == "linear" and list(made.times.hour) == [9, 13]
    np.testing.assert_allclose(made.exposure, np.array([0.8, 0.4]) / 100 * 100 / 64)
    pixels, top = made.read_frame(0)
    assert pixels.dtype == np.uint16 and top == 65535
    # the facets' values: 0.5 x gain of the white level (linear), the ratio the exposures'
    curves = bd.facet_curves(made)
    np.testing.assert_allclose(curves.luminance, [[0.4, 0.2]] * 3, rtol=0.003)
    # the overlay shows the linear frame through sRGB's curve: 0.2 of white (frame 1 of 2,
    # the middle) is code 124 where no facet's colour lies over it
    from PIL import Image

    with Image.open(overlay) as img:
        shown = np.asarray(img)
    assert np.all(np.abs(shown[made.labels == 0].astype(int) - 124) <= 1)
    # a RAW file rawpy cannot decode, and RAW mixed with JPEG: one line each, exit 2
    (raws / "IMG_2.NEF").write_bytes(b"\0" * 2048)
    capsys.readouterr()
    assert _make(mesh, camera, raws, tmp_path / "bad", "--utc-offset", "+00:00") == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"photo '{raws / 'IMG_2.NEF'}': field 'file'" in err, err
    assert "rawpy (LibRaw) cannot decode it" in err
    (raws / "IMG_2.NEF").unlink()
    write_photo(raws / "p.jpg", np.zeros((36, 48, 3)), "2024:06:21 12:00:00", "+01:00",
                exposure=(1 / 125, 8.0, 100))  # fmt: skip
    assert _make(mesh, camera, raws, tmp_path / "mixed", "--latitude", "51.5", "--longitude",
                 "-0.1") == 2  # fmt: skip
    err = capsys.readouterr().err
    assert "field 'pixel_encoding'" in err and "share one encoding" in err, err

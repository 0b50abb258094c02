"""Bundles from photos, a camera file and a mesh (bayesgloss.capture, `bundle make`)."""

import json
import time
from fractions import Fraction

import numpy as np
import pytest

from bayesgloss import bundle as bd
from bayesgloss import cli

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
        img.save(path, exif=exif, quality=quality, subsampling=0)
    else:
        img.save(path, exif=exif)
    return path


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


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    """A small Radiance sequence of the paper's hemisphere as 8-bit sRGB frames
    with per-frame auto-exposure, and the user's files made from it."""
    from bayesgloss import sequences

    root = tmp_path_factory.mktemp("capture")
    cfg = sequences.SequenceConfig(
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
    return cfg, truth, root


@pytest.mark.radiance
def test_bundle_make_remakes_the_renderers_bundle(rendered, capsys):
    cfg, truth, root = rendered
    out = root / "made"
    start = time.perf_counter()
    code = cli.main(
        [
            "bundle", "make", "--mesh", str(root / "object.obj"),
            "--camera", str(root / "camera.json"), "--photos", str(root / "photos"),
            "--out", str(out), "--latitude", "40", "--longitude", "0", "--facet-angle", "1",
        ]
    )  # fmt: skip
    seconds = time.perf_counter() - start
    assert code == 0, capsys.readouterr().err
    with pytest.warns(bd.BundleWarning, match="object_mesh 'object_mesh.obj' is not used yet"):
        made = bd.read_bundle(out)
    print(f"bundle make: {seconds:.2f} s for {len(made)} frames of {made.shape}")

    # facets: each made facet is one of the hemisphere's (normal and centre)
    hemisphere = cfg.facets()
    dist = np.linalg.norm(made.facets.center[:, None] - hemisphere.center[None], axis=-1)
    match = hemisphere.ids[np.argmin(dist, axis=1)]
    assert np.all(dist.min(axis=1) < 1e-9)
    assert len(np.unique(match)) == len(match)
    k = np.argmin(dist, axis=1)
    np.testing.assert_allclose(made.facets.normal, hemisphere.normal[k], atol=1e-9)

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
    assert ok.sum() >= 50
    # 8-bit JPEG at quality 95 (4:4:4) against the renderer's 8-bit PNG: a code or two
    # per pixel, less in a facet's mean (measured: median 0.15 %, largest 1.0 %); the
    # issue's bar is 2 %
    assert rel.max() < 0.02

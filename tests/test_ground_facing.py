"""Facets facing the ground are left out where the bundle has no object_mesh."""

import json

import numpy as np
import pytest

from bayesgloss import estimate, ground_facing


def test_which_facets_face_the_ground():
    normals = np.array(
        [[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 0.995, -0.0998], [0.0, 0.78, -0.62]]
    )
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    # a roof and a wall stay, a wall tilted 5.7 deg down stays (z -0.0998 > -0.1),
    # a gem's lower facet (z -0.62) faces the ground
    assert ground_facing.facets_facing_ground(normals, has_mesh=False).tolist() == [
        False, False, False, True,
    ]  # fmt: skip
    # with a mesh the object's shadow on the ground is cast from it: none left out
    assert not ground_facing.facets_facing_ground(normals, has_mesh=True).any()
    with pytest.raises(ValueError, match="unknown ground-facing mode 'drop'"):
        ground_facing.check_ground_facing_mode("drop")


def _tilt_down(path, ids):
    """Rewrite the manifest so that facets ``ids`` face the ground (z -0.6)."""
    manifest = path / "sequence.json"
    m = json.loads(manifest.read_text())
    for f in m["facets"]:
        if f["id"] in ids:
            n = np.array(f["normal"], float)
            h = n[:2] / np.linalg.norm(n[:2])
            f["normal"] = [0.8 * h[0], 0.8 * h[1], -0.6]
    manifest.write_text(json.dumps(m))


def test_estimate_leaves_ground_facing_facets_out_and_flags_them(tmp_path):
    from conftest import make_synthetic_bundle

    path = make_synthetic_bundle(tmp_path / "b", specularity=0.5, noise=0.01, seed=3)
    ids = [f["id"] for f in json.loads((path / "sequence.json").read_text())["facets"]]
    down = ids[:2]
    _tilt_down(path, down)
    opts = dict(per_frame=False, illumination="gensky-clear", sampler_options={"max_steps": 300})
    res = estimate.estimate_bundle(path, **opts)
    facets = {f["id"]: f for f in res.summary["facets"]}
    for k in down:
        assert facets[k]["gamma"] is None and facets[k]["flags"] == ["faces-ground"]
    fitted = list(res.idata.posterior["facet"].values)
    assert sorted(fitted) == sorted(set(ids) - set(down))
    # kept on request: every facet fitted, none flagged faces-ground
    kept = estimate.estimate_bundle(path, ground_facing="keep", **opts)
    assert sorted(kept.idata.posterior["facet"].values) == sorted(ids)
    assert not any("faces-ground" in f["flags"] for f in kept.summary["facets"])
    # where every usable facet faces the ground, they are all kept (nothing else to fit)
    _tilt_down(path, ids)
    every = estimate.estimate_bundle(path, **opts)
    assert sorted(every.idata.posterior["facet"].values) == sorted(ids)


def test_cli_takes_ground_facing(tmp_path, capsys):
    from conftest import make_synthetic_bundle

    from bayesgloss import cli

    path = make_synthetic_bundle(tmp_path / "b", specularity=0.5, noise=0.01, seed=3)
    ids = [f["id"] for f in json.loads((path / "sequence.json").read_text())["facets"]]
    _tilt_down(path, ids[:1])
    args = ["estimate", str(path), "--fixed-brightness", "--sky", "gensky-clear"]
    args += ["--max-steps", "300", "--json", "--quiet"]
    assert cli.main(args) == 0
    out = json.loads(capsys.readouterr().out)
    assert [f["flags"] for f in out["facets"] if f["id"] == ids[0]] == [["faces-ground"]]
    assert cli.main([*args, "--ground-facing", "keep"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert [f["gamma"] is not None for f in out["facets"] if f["id"] == ids[0]] == [True]


def test_several_bundles_carry_ground_facing_into_their_units(tmp_path, monkeypatch):
    # over several bundles each is a unit of work: --ground-facing must reach each
    # unit's options (absent where not given: earlier runs keep their keys) and,
    # through estimate_unit, estimate_bundle
    from conftest import estimate_option_route

    route = estimate_option_route(
        monkeypatch, tmp_path, ["--ground-facing", "keep"], "ground_facing"
    )
    assert route["units"] == ["keep", "keep"]
    assert not route["plain_units_have_key"]
    assert route["estimate_bundle"] == ["keep", None, "keep"]  # None: the library's default

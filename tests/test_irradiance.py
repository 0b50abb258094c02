"""Measured irradiance (bayesgloss.irradiance) and the bundle's frames[].irradiance."""

import json
import warnings

import numpy as np
import pvlib
import pytest
from conftest import make_synthetic_bundle

from bayesgloss import bundle as bundle_io
from bayesgloss import estimate, irradiance, render, sky


def test_closure_and_erbs_split():
    nan = np.nan
    z = np.array([30.0, 30.0, 30.0, 40.0, 95.0])
    dni, dhi = irradiance.complete_irradiance(
        [800, 800, nan, 500, 10], [nan, 700, 700, nan, nan], [100, nan, 100, nan, nan], z, 172
    )
    cz = np.cos(np.deg2rad(z))
    # two of three: GHI = DNI cos z + DHI
    np.testing.assert_allclose(dni[0], 700 / cz[0])
    np.testing.assert_allclose(dhi[1], 800 - 700 * cz[1])
    np.testing.assert_allclose([dni[2], dhi[2]], [700, 100])
    # GHI alone: pvlib's Erbs decomposition, the reference
    ref = pvlib.irradiance.erbs(np.array([500.0]), np.array([40.0]), np.array([172.0]))
    np.testing.assert_allclose([dni[3], dhi[3]], [ref["dni"][0], ref["dhi"][0]])
    # the sun down: no sky
    assert dni[4] == 0 and dhi[4] == 0


def _with_irradiance(path, values):
    manifest = json.loads((path / "sequence.json").read_text())
    for frame, v in zip(manifest["frames"], values, strict=True):
        if v is not None:
            frame["irradiance"] = v
    (path / "sequence.json").write_text(json.dumps(manifest))


def test_measured_irradiance_makes_the_sky(tmp_path):
    path = make_synthetic_bundle(tmp_path / "b", specularity=0.5, seed=2)
    b = bundle_io.read_bundle(path)
    rng = np.random.default_rng(0)
    dni = np.where(b.sun_up, rng.uniform(0, 800, len(b)), 0.0)
    dhi = np.where(b.sun_up, rng.uniform(50, 300, len(b)), 0.0)
    _with_irradiance(path, [{"dni": a, "dhi": c} for a, c in zip(dni, dhi, strict=True)])
    b = bundle_io.read_bundle(path)
    np.testing.assert_allclose(b.irradiance[:, 1:], np.column_stack([dni, dhi]))
    # the bases under "measured" are those of gendaylit's Perez with these values
    got = estimate.bundle_bases(b, "measured")
    day = sky.daylight(
        "perez",
        b.sun_direction,
        direct_normal_irradiance=dni,
        diffuse_horizontal_irradiance=dhi,
        day_of_year=b.times.day_of_year.values,
        ground_reflectance=b.ground_reflectance,
    )
    want = render.facet_bases(b.view_geometry(), day, ground_reflectance=b.ground_reflectance)
    np.testing.assert_allclose(got.diffuse, want.diffuse, rtol=1e-12)
    # and the estimate uses them by default
    res = estimate.estimate_bundle(b, sampler_options={"max_steps": 300})
    assert res.summary["illumination"] == "measured"


def test_bad_or_partial_irradiance(tmp_path):
    path = make_synthetic_bundle(tmp_path / "b", seed=3)
    n = len(bundle_io.read_bundle(path))
    _with_irradiance(path, [{"ghi": -5.0}] + [None] * (n - 1))
    with pytest.raises(bundle_io.BundleError, match=r"frames\[0\]\.irradiance\.ghi.*>= 0"):
        bundle_io.read_bundle(path)
    _with_irradiance(path, [{"poa": 3.0}] + [None] * (n - 1))
    with pytest.raises(bundle_io.BundleError, match=r"frames\[0\]\.irradiance.*none of"):
        bundle_io.read_bundle(path)
    # DNI alone for every frame: not enough to know the sky; said, and not used
    _with_irradiance(path, [{"dni": 500.0}] * n)
    b = bundle_io.read_bundle(path)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert irradiance.measured_sky(b) is None
    assert any("not used" in str(w.message) for w in caught)


def test_irradiance_csv_on_the_command_line(tmp_path):
    # a CSV for the bundle's frames becomes the sky; bad files are one line each
    import subprocess
    import sys

    path = make_synthetic_bundle(tmp_path / "b", seed=5)
    b = bundle_io.read_bundle(path)
    local = b.times.tz_convert("Etc/GMT-2")  # the file may use any offset
    rows = ["time,ghi,dhi"] + [
        f"{t.isoformat()},{600 if up else 0},{120 if up else 0}"
        for t, up in zip(local, b.sun_up, strict=True)
    ]
    good = tmp_path / "irr.csv"
    good.write_text("\n".join(rows) + "\n")
    got = irradiance.read_irradiance_csv(good, b.times)
    np.testing.assert_allclose(got[:, 0], np.where(b.sun_up, 600, 0))
    assert np.all(np.isnan(got[:, 1]))
    cmd = [sys.executable, "-m", "bayesgloss.cli", "estimate", str(path), "--json", "--quiet"]
    run = subprocess.run(
        [*cmd, "--irradiance", str(good), "--max-steps", "300"], capture_output=True, text=True
    )
    assert run.returncode == 0, run.stderr
    assert json.loads(run.stdout)["illumination"] == "measured"
    for text, message in [
        ("\n".join(rows[:-1]) + "\n", "holds no row for frame"),
        ("\n".join(rows).replace(",600,", ",-3,", 1) + "\n", ", ghi: must be a number"),
        ("when,ghi\n", "no 'time' column"),
    ]:
        bad = tmp_path / "bad.csv"
        bad.write_text(text)
        run = subprocess.run([*cmd, "--irradiance", str(bad)], capture_output=True, text=True)
        assert run.returncode == 2 and message in run.stderr, run.stderr
        assert "Traceback" not in run.stderr and len(run.stderr.strip().splitlines()) == 1

"""Shared fixtures: simple skies with known integrals."""

from dataclasses import dataclass

import numpy as np
import pytest


@dataclass(frozen=True)
class UniformSky:
    """Radiance ``level`` from every direction (sky and ground), optional sun.

    Duck-types :class:`bayesgloss.sky.DaylightSky` for forward-model tests
    whose integrals are known in closed form.
    """

    level: np.ndarray  # (T,)
    sun_direction: np.ndarray  # (T, 3)
    solar_radiance: np.ndarray  # (T,)
    sun_solid_angle: float = 6.8e-5
    model: str = "uniform-test"

    @property
    def ground_radiance(self):
        return self.level

    def radiance(self, directions):
        d = np.asarray(directions, dtype=float)
        return np.broadcast_to(self.level, d.shape[:-1] + self.level.shape).copy()


@pytest.fixture
def uniform_sky():
    def make(levels=(1.0,), sun=None, solar_radiance=0.0):
        levels = np.atleast_1d(np.asarray(levels, dtype=float))
        t = len(levels)
        sun = np.tile([0.0, 0.0, 1.0], (t, 1)) if sun is None else np.atleast_2d(sun)
        return UniformSky(levels, sun, np.broadcast_to(solar_radiance, (t,)).astype(float))

    return make


@dataclass(frozen=True)
class FunctionSky:
    """Radiance given by a smooth function of direction, times a level per frame."""

    func: object  # (..., 3) -> (...)
    level: np.ndarray  # (T,)
    sun_direction: np.ndarray  # (T, 3)
    solar_radiance: np.ndarray  # (T,)
    sun_solid_angle: float = 6.8e-5
    model: str = "function-test"

    @property
    def ground_radiance(self):
        return self.level

    def radiance(self, directions):
        d = np.asarray(directions, dtype=float)
        return self.func(d)[..., None] * self.level


@pytest.fixture
def smooth_sky():
    def func(d):
        return 1.0 + 0.8 * d[..., 2] + 0.5 * d[..., 0] ** 2 + 0.3 * d[..., 1]

    t = 3
    return FunctionSky(
        func, np.array([1.0, 2.0, 0.5]), np.tile([0.0, 0.0, 1.0], (t, 1)), np.zeros(t)
    )


def make_synthetic_bundle(
    path,
    *,
    specularity=0.5,
    view="SW",
    noise=0.01,
    seed=0,
    n_rings=2,
    n_segments=8,
    block=3,
    encoding=None,
    response_gamma=2.2,
    bits=16,
    exposure=None,
    sky_model="gensky-clear",
    radiance=None,
):
    """A small sequence bundle made by the forward model, no Radiance needed.

    Every facet facing the camera gets a block x block patch of the label image;
    its frames hold the facet's predicted radiance (grey plastic of the given
    specularity under gensky's clear sky) with relative noise.

    Parameters
    ----------
    encoding : None or {"unknown", "linear", "srgb", "gamma:G"}
        None (default): float32 TIFF frames of radiance, ``linear-radiance``.
        Otherwise integer PNG frames of ``bits`` bits whose codes are the noisy
        radiance divided by ``exposure`` and passed through the camera
        response (the sRGB curve, value^(1/G), or value^(1/response_gamma)
        for ``unknown``), rounded to the nearest code; values at or above
        ``exposure`` clip to the top code (saturated pixels).
    response_gamma : float
        True response exponent g of an ``unknown`` encoding [-].
    bits : {8, 16}
        Bit depth of integer frames [-].
    exposure : float, optional
        Radiance that maps to the top code [W sr^-1 m^-2]; default 1.25 x the
        brightest noisy facet radiance (nothing clips).
    sky_model : str
        The day's sky (:func:`bayesgloss.sky.daylight` name), gensky's clear
        sky by default.
    radiance : callable, optional
        (ViewGeometry, DaylightSky) -> noiseless facet radiance (F, T), in
        place of the plastic's (e.g. another lobe family's forward model).
    """
    from bayesgloss import bundle, geometry, render, scene

    seq = scene.paper_sequence(
        view=view, sky_model=sky_model, n_rings=n_rings, n_segments=n_segments
    )
    facing = np.flatnonzero(seq.geometry.cos_view > 0.2)
    facets = seq.facets.subset(facing)
    geom = render.view_geometry(facets, seq.camera_position, occluder=seq.facets)
    if radiance is None:
        radiance = render.radiance_material_prediction(geom, seq.sky, "plastic", 0.5, specularity)
    else:
        radiance = radiance(geom, seq.sky)
    rng = np.random.default_rng(seed)
    radiance = radiance * (1 + noise * rng.standard_normal(radiance.shape))
    side = int(np.ceil(np.sqrt(len(facets))))
    size = side * (block + 1) + 1
    labels = np.zeros((size, size), dtype=np.uint16)
    frames = [np.zeros((size, size, 3), np.float32) for _ in seq.times]
    for k, fid in enumerate(facets.ids):
        r, c = divmod(k, side)
        sl = (
            slice(1 + r * (block + 1), 1 + r * (block + 1) + block),
            slice(1 + c * (block + 1), 1 + c * (block + 1) + block),
        )
        labels[sl] = fid
        for t, fr in enumerate(frames):
            fr[sl] = radiance[k, t]
    pixel_encoding, frame_format = "linear-radiance", "tiff"
    if encoding is not None:
        if bits not in (8, 16):
            raise ValueError(f"bits must be 8 or 16, got {bits!r}")
        top = 1.25 * float(radiance.max()) if exposure is None else float(exposure)
        frames = [_encode_codes(fr / top, encoding, response_gamma) for fr in frames]
        pixel_encoding, frame_format = encoding, f"png{bits}"
    bundle.write_bundle(
        path,
        site={"latitude": 40.0, "longitude": 0.0, "elevation": 0.0},
        camera_position=seq.camera_position,
        pixel_encoding=pixel_encoding,
        frames=frames,
        times=[t.isoformat() for t in seq.times],
        facets=geometry.Facets(facets.ids, facets.normal, facets.center),
        labels=labels,
        ground_reflectance=0.2,
        truth={"specularity": specularity, "material": "plastic"},
        frame_format=frame_format,
    )
    return path


def _encode_codes(value, encoding, response_gamma):
    """Normalised code values in [0, 1] of linear values (1 = top code) under a
    camera response; write_bundle rounds them to the nearest integer code."""
    from bayesgloss import images

    name, gamma = images.parse_pixel_encoding(encoding)
    v = np.clip(np.asarray(value, dtype=float), 0.0, 1.0)
    if name == "srgb":
        v = images.linear_to_srgb(v)
    elif name == "gamma":
        v = v ** (1.0 / gamma)
    elif name == "unknown":
        v = v ** (1.0 / response_gamma)
    elif name != "linear":
        raise ValueError(f"integer frames cannot have pixel encoding {encoding!r}")
    return v


def study_script(name: str):
    """``studies/NAME.py`` loaded as a module (the studies are scripts, not a
    package), and its path: (module, path as str)."""
    import importlib.util
    from pathlib import Path

    path = str(Path(__file__).resolve().parents[1] / "studies" / f"{name}.py")
    spec = importlib.util.spec_from_file_location(f"{name}_study", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module, path


def paper_three_skies_bases(**kwargs):
    """Split bases of the paper scene (SW) under gensky's clear, intermediate and
    overcast skies (the ``auto`` mixture), sun-up frames, and the seen
    geometry: (bases, up, geometry); ``kwargs`` for
    :func:`bayesgloss.illumination.illumination_bases`."""
    from bayesgloss import illumination as il
    from bayesgloss import scene, sky

    seq = scene.paper_sequence(view="SW")
    g = scene.seen_geometry(seq)
    up = seq.sky.sun_direction[:, 2] > 0.02
    others = [
        sky.daylight(name, seq.sky.sun_direction, ground_reflectance=0.2)
        for name in ("gensky-intermediate", "gensky-overcast")
    ]
    return il.illumination_bases(g, seq.sky, others=others, **kwargs), up, g


@pytest.fixture(scope="session")
def paper_three_skies():
    """:func:`paper_three_skies_bases`' bases and sun-up frames."""
    return paper_three_skies_bases()[:2]


def planned_unit_options(monkeypatch, paths, out, *extra) -> list[dict]:
    """The options of each unit that ``bayesgloss estimate`` over several
    bundles ``paths`` (with the CLI arguments ``extra``) plans, caught before
    any unit runs (``runner.run_units`` replaced)."""
    from bayesgloss import cli, runner

    class Planned(Exception):
        pass

    seen = []

    def plan(func, units, out, **kwargs):
        seen.extend(options for _, options in units)
        raise Planned

    monkeypatch.setattr(runner, "run_units", plan)
    with pytest.raises(Planned):
        cli.main(["estimate", *map(str, paths), "--out", str(out), "--quiet", *extra])
    return seen


def estimate_bundle_options(monkeypatch, call) -> dict:
    """The keyword arguments with which ``call()`` (``estimate.estimate_unit``
    or ``cli.main`` of one bundle) reaches ``estimate.estimate_bundle``,
    caught before any fit (``estimate_bundle`` replaced)."""
    from bayesgloss import estimate

    class Reached(Exception):
        pass

    seen = {}

    def reach(b, **kwargs):
        seen.update(kwargs)
        raise Reached

    monkeypatch.setattr(estimate, "estimate_bundle", reach)
    with pytest.raises(Reached):
        call()
    return seen


def estimate_option_route(monkeypatch, tmp_path, flag: list, key: str) -> dict:
    """Where ``bayesgloss estimate``'s CLI arguments ``flag`` take the option
    ``key`` of :func:`bayesgloss.estimate.estimate_bundle`, caught before any
    fit.

    Returns
    -------
    dict
        ``units``: its value in each unit planned over two bundles with
        ``flag``; ``plain_units_have_key``: whether any unit planned without
        ``flag`` holds the key (none must: earlier runs keep their units'
        keys); ``estimate_bundle``: the value ``estimate_bundle`` gets through
        ``estimate_unit`` of the first unit, a one-bundle run without
        ``flag`` and one with it.
    """
    from bayesgloss import cli, estimate

    paths = [make_synthetic_bundle(tmp_path / f"b{i}", seed=i) for i in range(2)]
    units = planned_unit_options(monkeypatch, paths, tmp_path / "out", *flag)
    plain = planned_unit_options(monkeypatch, paths, tmp_path / "out")
    one = ["estimate", str(paths[0]), "--quiet"]
    calls = (
        lambda: estimate.estimate_unit(**units[0]),
        lambda: cli.main(one),
        lambda: cli.main([*one, *flag]),
    )
    return {
        "units": [u[key] for u in units],
        "plain_units_have_key": any(key in u for u in plain),
        "estimate_bundle": [estimate_bundle_options(monkeypatch, c)[key] for c in calls],
    }

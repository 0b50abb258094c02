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
    path, *, specularity=0.5, view="SW", noise=0.01, seed=0, n_rings=2, n_segments=8, block=3
):
    """A small sequence bundle made by the forward model, no Radiance needed.

    Every facet facing the camera gets a block x block patch of the label image;
    its frames hold the facet's predicted radiance (grey plastic of the given
    specularity under gensky's clear sky) with relative noise.
    """
    from bayesgloss import bundle, geometry, render, scene

    seq = scene.paper_sequence(view=view, n_rings=n_rings, n_segments=n_segments)
    facing = np.flatnonzero(seq.geometry.cos_view > 0.2)
    facets = seq.facets.subset(facing)
    geom = render.view_geometry(facets, seq.camera_position, occluder=seq.facets)
    radiance = render.radiance_material_prediction(geom, seq.sky, "plastic", 0.5, specularity)
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
    bundle.write_bundle(
        path,
        site={"latitude": 40.0, "longitude": 0.0, "elevation": 0.0},
        camera_position=seq.camera_position,
        pixel_encoding="linear-radiance",
        frames=frames,
        times=[t.isoformat() for t in seq.times],
        facets=geometry.Facets(facets.ids, facets.normal, facets.center),
        labels=labels,
        ground_reflectance=0.2,
        truth={"specularity": specularity, "material": "plastic"},
        frame_format="tiff",
    )
    return path

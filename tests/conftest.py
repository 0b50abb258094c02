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

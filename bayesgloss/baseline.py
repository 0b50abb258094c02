"""The paper's peak-frame gloss estimator (Love & Efford, secs. 3 and 5): the baseline.

For each facet, gloss factors gamma are hypothesised on a grid; for each, the
radiance toward the camera is predicted with the sun as a point source of
unit radiance and no sky (eq. 2 with eqs. 4-6, the unnormalised Phong of
exponent n, :func:`bayesgloss.render.paper_point_sun`); the estimate is the
gamma whose predicted peak frame equals the frame of peak observed luminance.
The object's gloss is the mean over facets that receive direct sun.

Rules the paper leaves open, fixed here
---------------------------------------
- Grid: gamma = 0, 0.01, ..., 1 (101 values). The predicted peak frame is a
  step function of gamma, so a finer grid cannot tell more apart.
- Plateaus and ties: several gammas usually predict the observed peak frame;
  the estimate is the middle of that set (the median of the matching gammas).
- No match: when no gamma predicts the observed peak frame, the gammas whose
  predicted peak lies nearest in time to the observed one are taken (middle
  of that set) and the facet is flagged ``"no-exact-match"``.
- Frames: only frames valid in the observations (sun up, no saturation...)
  compete for the peak, in both the observed and the predicted curves.
- Equal peak values: the earliest frame wins (``numpy.argmax``). Radiance
  pictures store 8-bit mantissas, so flat-topped matt curves can hold two
  exactly equal frames (6-14 % of the paper's clear-sky matt facets); a
  tolerance-based tie rule is a known improvement not yet made.
- Exponent: n = 2 by default, overridable. The paper does not state its
  value (it calls 1-200 typical), but its Fig. 3 shows the six gloss
  factors 0, 0.2, ..., 1 peaking in distinct frames, which needs a broad
  lobe: with the narrow lobes of large n the Lambert term decides the peak for
  every gamma below ~0.9. Over the facets the paper's W, SW and S cameras see,
  the mean number of distinct peak frames among those six gammas is 3.08,
  2.98, 2.60 at n = 2 against 2.04, 2.08, 2.00 at n = 20; n = 2 tells them
  apart best (n = 1, 3, 5, 10 and 50 do no better).
- Direct sun: a facet receives direct sun when the sun is above the horizon
  and in front of it in at least one valid frame.

Flags per facet
---------------
``"mirror-degenerate"``: the Lambert (gamma 0) and Phong (gamma 1)
predictions peak in the same frame, so the peak cannot tell gloss (paper,
sec. 3: the sun's path passes the camera's mirror direction).
``"no-direct-sun"``: the facet never receives direct sun; excluded from the
object mean. ``"no-valid-frames"``: nothing observed; gamma is NaN.
``"no-exact-match"``: see above.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .render import ViewGeometry, paper_point_sun

__all__ = [
    "BaselineResult",
    "peak_frame_gloss",
    "bundle_peak_frame_gloss",
    "DEFAULT_GLOSS_GRID",
    "DEFAULT_EXPONENT",
]

DEFAULT_GLOSS_GRID = np.linspace(0.0, 1.0, 101)
DEFAULT_EXPONENT = 2.0
#: Valid frames a facet needs for its peak frame to be compared with others.
MIN_FRAMES = 2


@dataclass(frozen=True)
class BaselineResult:
    """Peak-frame estimates.

    Attributes
    ----------
    ids : ndarray (F,)
    gloss : ndarray (F,)
        Estimated gamma per facet (NaN where nothing was observed).
    interval : ndarray (F, 2)
        Smallest and largest gamma of the matching set (the plateau).
    flags : list of list of str
        Per facet (module docstring).
    object_gloss : float
        Mean over facets that receive direct sun (NaN if none).
    observed_peak : ndarray (F,) of int
        Frame of peak observed luminance (-1 where none).
    predicted_peak : ndarray (G, F) of int
        Predicted peak frame for each hypothesised gamma (-1: no light).
    gloss_grid : ndarray (G,)
    exponent : float
    """

    ids: np.ndarray
    gloss: np.ndarray
    interval: np.ndarray
    flags: list
    object_gloss: float
    observed_peak: np.ndarray
    predicted_peak: np.ndarray
    gloss_grid: np.ndarray
    exponent: float
    direct_sun: np.ndarray = field(repr=False, default=None)

    def to_json(self) -> dict:
        """``{"object": {"gamma": ...}, "facets": [{"id", "gamma", "flags"}]}``."""

        def num(x):
            return None if not np.isfinite(x) else float(x)

        return {
            "object": {
                "gamma": num(self.object_gloss),
                "exponent": self.exponent,
                "facets_used": int(np.sum(self.direct_sun & np.isfinite(self.gloss))),
            },
            "facets": [
                {"id": int(i), "gamma": num(g), "interval": [num(lo), num(hi)], "flags": list(f)}
                for i, g, (lo, hi), f in zip(
                    self.ids, self.gloss, self.interval, self.flags, strict=True
                )
            ],
        }


def _peak_frame(curves: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Index of the largest valid value along the last axis; -1 if none is positive."""
    masked = np.where(valid, curves, -np.inf)
    peak = np.argmax(masked, axis=-1)
    best = np.take_along_axis(masked, peak[..., None], axis=-1)[..., 0]
    return np.where(best > 0, peak, -1)


def peak_frame_gloss(
    luminance,
    valid,
    geometry: ViewGeometry,
    sun_direction,
    *,
    ids=None,
    gloss_grid=DEFAULT_GLOSS_GRID,
    exponent: float = DEFAULT_EXPONENT,
    frame_hours=None,
) -> BaselineResult:
    """The paper's peak-frame estimate of gamma per facet and for the object.

    Parameters
    ----------
    luminance : array_like (F, T)
        Observed facet luminance (any linear or monotone scale: only the
        frame of the peak is used).
    valid : array_like of bool (F, T)
        Frames that may be used.
    geometry : ViewGeometry
        The F facets' normals and view directions.
    sun_direction : array_like (T, 3)
    ids : array_like (F,), optional
        Facet ids (default 1..F).
    gloss_grid : array_like (G,)
        Hypothesised gammas, within [0, 1].
    exponent : float
        Phong exponent n of eq. 6.
    frame_hours : array_like (T,), optional
        Frame times [h]; nearest-in-time matching uses them (default: frame
        index).

    Returns
    -------
    BaselineResult
    """
    lum = np.asarray(luminance, dtype=float)
    ok = np.asarray(valid, dtype=bool) & np.isfinite(lum)
    sun = np.asarray(sun_direction, dtype=float)
    grid = np.asarray(gloss_grid, dtype=float)
    if lum.ndim != 2 or lum.shape != ok.shape or lum.shape[1] != len(sun):
        raise ValueError(
            f"luminance {lum.shape}, valid {ok.shape} and sun_direction {sun.shape} "
            "must be (F, T), (F, T) and (T, 3)"
        )
    if np.any((grid < 0) | (grid > 1)) or grid.ndim != 1 or len(grid) < 2:
        raise ValueError(f"gloss_grid must be a 1-d grid within [0, 1], got {gloss_grid}")
    if not exponent > 0:
        raise ValueError(f"exponent must be positive, got {exponent}")
    n_f, n_t = lum.shape
    ids = np.arange(1, n_f + 1) if ids is None else np.asarray(ids)
    hours = np.arange(n_t, dtype=float) if frame_hours is None else np.asarray(frame_hours)

    observed = _peak_frame(lum, ok)  # (F,)
    pred = paper_point_sun(geometry, sun, grid[:, None, None], exponent)  # (G, F, T)
    predicted = _peak_frame(pred, ok[None])  # (G, F)
    sun_up = sun[:, 2] > 0
    direct = np.any((geometry.normal @ sun.T > 0) & sun_up & ok, axis=1)

    gloss = np.full(n_f, np.nan)
    interval = np.full((n_f, 2), np.nan)
    flags: list[list[str]] = [[] for _ in range(n_f)]
    lam, pho = predicted[0], predicted[-1]
    for f in range(n_f):  # F is small (tens to hundreds); each step is vectorised over G
        if observed[f] < 0:
            flags[f].append("no-valid-frames")
            continue
        if lam[f] >= 0 and lam[f] == pho[f]:
            flags[f].append("mirror-degenerate")
        if not direct[f]:
            flags[f].append("no-direct-sun")
        match = predicted[:, f] == observed[f]
        if not np.any(match):
            lit = predicted[:, f] >= 0
            if not np.any(lit):
                flags[f].append("no-exact-match")
                continue
            dist = np.where(
                lit, np.abs(hours[np.maximum(predicted[:, f], 0)] - hours[observed[f]]), np.inf
            )
            match = dist == dist.min()
            flags[f].append("no-exact-match")
        gloss[f] = np.median(grid[match])
        interval[f] = grid[match].min(), grid[match].max()

    used = direct & np.isfinite(gloss)
    object_gloss = float(np.mean(gloss[used])) if np.any(used) else float("nan")
    return BaselineResult(
        ids,
        gloss,
        interval,
        flags,
        object_gloss,
        observed,
        predicted,
        grid,
        float(exponent),
        direct,
    )


def bundle_peak_frame_gloss(bundle, **options) -> BaselineResult:
    """The peak-frame estimate of a sequence bundle.

    Parameters
    ----------
    bundle : path or bayesgloss.bundle.Bundle
    **options
        Passed to :func:`peak_frame_gloss` (``gloss_grid``, ``exponent``).

    Returns
    -------
    BaselineResult
        From the bundle's facet curves and validity, its sun and geometry, with
        frames timed in local apparent solar time.

    Raises
    ------
    bayesgloss.bundle.NoUsableData
        Where no facet has :data:`MIN_FRAMES` valid frames: a peak among
        fewer frames says nothing of gloss.
    """
    from . import bundle as bundle_io
    from . import sun

    b = bundle if isinstance(bundle, bundle_io.Bundle) else bundle_io.read_bundle(bundle)
    curves = bundle_io.facet_curves(b)
    bundle_io.usable_facets(b, curves.valid, MIN_FRAMES)
    hours = np.unwrap(sun.local_solar_time(b.times, b.site.longitude), period=24)
    return peak_frame_gloss(
        curves.luminance,
        curves.valid,
        b.view_geometry(),
        b.sun_direction,
        ids=curves.ids,
        frame_hours=hours,
        **options,
    )

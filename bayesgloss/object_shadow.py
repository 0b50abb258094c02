"""The object's own shadow on the ground, in the bases of a bundle without a mesh.

``estimate --ground-shadow convex``, the joint model's default since stop 49
(:func:`default_ground_shadow`; holdout 16's rule, studies/README.md). A
convex object standing alone (a bundle without ``object_mesh``) shadows the
ground at its foot, and a glossy facet whose mirror direction points down
sees that shadow when the sun is behind it
(:mod:`bayesgloss.convex_object`). The forward model has the shadow
(:func:`bayesgloss.render.ground_shadow`, a convex occluder's) but a bundle
gives no occluder; here it is the object that the seen facets and their
mirror images bound (:func:`bayesgloss.convex_object.convex_object`).

A facet's footprint on the ground crosses the shadow's edge during the day,
so its centre alone is not enough: the bases are computed at points spread
over each facet's polygon (:func:`bayesgloss.convex_object.facet_points`,
:data:`POINTS_PER_SIDE` a side) and averaged, as a facet's observation
averages its pixels. The Fresnel terms are averaged the same way.

What is still missing: the sky the object hides from the ground near it,
and the light the object sends onto that ground (about 1 % of a
near-mirror wall's signal on holdout 3's vs20, stop 35's diagnosis).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from . import render
from .convex_object import convex_object, facet_points

__all__ = [
    "GROUND_SHADOWS",
    "DEFAULT_GROUND_SHADOW",
    "default_ground_shadow",
    "bounds_a_volume",
    "convex_shadow_state",
    "shadow_points",
    "facet_mean",
    "averaged_bases",
]

#: ``estimate --ground-shadow``: ``"none"`` (the ground sunlit everywhere, as
#: before), ``"convex"`` (this module).
GROUND_SHADOWS = ("none", "convex")
#: The default where per-frame illumination is inferred (the joint model):
#: the convex object's shadow, since holdout 16 (studies/README.md, "Holdout
#: 16 and Mitsuba holdout 6"). A model with the sky's brightness fixed has none.
DEFAULT_GROUND_SHADOW = "convex"
#: Grid cells a side of each facet's bounding rectangle (:func:`facet_points`).
POINTS_PER_SIDE = 4


def default_ground_shadow(joint: bool) -> str:
    """The ground shadow ``estimate`` fits without ``--ground-shadow``:
    :data:`DEFAULT_GROUND_SHADOW` for the joint model (per-frame
    illumination), ``"none"`` otherwise (the only one that model has). A
    bundle with an ``object_mesh`` casts its shadow from the mesh whatever
    this says (:mod:`bayesgloss.visibility`)."""
    return DEFAULT_GROUND_SHADOW if joint else "none"


def check_ground_shadow(mode: str) -> str:
    """``mode`` if it is one of :data:`GROUND_SHADOWS`, else ValueError."""
    if mode not in GROUND_SHADOWS:
        raise ValueError(f"unknown ground shadow {mode!r}; valid: {', '.join(GROUND_SHADOWS)}")
    return mode


def bounds_a_volume(facets) -> bool:
    """Whether the seen facets and their mirror images bound an object
    (:func:`bayesgloss.convex_object.convex_object` builds one).

    Not where one wall is seen alone, or only walls whose planes are
    parallel (a box seen square-on from below its top): the axis then
    falls on the walls' plane, each wall's image is the wall itself turned
    round, and nothing tells how deep the object is (Mitsuba holdout 10's
    ms16 crashed the default there until stop 60). Such an object casts
    no modelled shadow: the ground is taken sunlit, as before stop 49, and
    the estimate is flagged ``ground-shadow-not-built``.
    """
    try:
        convex_object(facets.normal, facets.center)
    except ValueError:
        return False
    return True


def convex_shadow_state(facets, mode: str, has_mesh: bool, ground: str) -> str:
    """Whether the object's shadow on the ground is modelled from its facets.

    ``"built"`` where ``mode`` is ``"convex"``, the bundle has no
    ``object_mesh`` (its own occlusion map then hides the ground), the
    illumination has a ground plane (``ground="plane"``; a point sun has
    none) and the facets bound a volume (:func:`bounds_a_volume`);
    ``"not-built"`` where all hold but the last (the estimate is flagged
    ``ground-shadow-not-built``); ``"not-modelled"`` otherwise. The one
    decision both the joint model's data and the estimate's flags read.
    """
    if mode != "convex" or has_mesh or ground != "plane":
        return "not-modelled"
    return "built" if bounds_a_volume(facets) else "not-built"


def shadow_points(facets, camera_position, per_side: int = POINTS_PER_SIDE, which=None):
    """Points over facets, as a geometry that casts the object's shadow.

    Parameters
    ----------
    facets : bayesgloss.geometry.Facets
        Every facet the bundle gives (all bound the object).
    camera_position : array_like (3,)
        [m]
    per_side : int
        :func:`bayesgloss.convex_object.facet_points`' grid.
    which : array_like of bool (F,), optional
        The facets to spread points over (default all): the object is
        bounded by every facet whether or not its bases are wanted.

    Returns
    -------
    geometry : bayesgloss.render.ViewGeometry
        M points: each its facet's normal, its own view direction, the
        object's vertices as the occluder.
    owner : ndarray of int (M,)
        The facet of each point, counted among ``which``'s.
    """
    normal = np.asarray(facets.normal, dtype=float)
    center = np.asarray(facets.center, dtype=float)
    obj = convex_object(normal, center)
    chosen = np.flatnonzero(np.ones(len(normal), bool) if which is None else which)
    points, owner = [], []
    for k, f in enumerate(chosen):
        poly, n = obj.polygons[f], normal[f]
        pts = facet_points(poly, n, per_side) if len(poly) else center[f][None, :]
        points.append(pts)
        owner.append(np.full(len(pts), k))
    points = np.concatenate(points)
    owner = np.concatenate(owner)
    view = render.view_directions(points, camera_position)
    geometry = render.ViewGeometry(normal[chosen][owner], view, points, obj.vertices)
    return geometry, owner


def facet_mean(x, owner, n_facets: int, axis: int = 0) -> np.ndarray:
    """The mean over each facet's points (``owner``, from
    :func:`shadow_points`) of ``x`` along ``axis`` (M points there, F after)."""
    counts = np.bincount(owner, minlength=n_facets).astype(float)
    if np.any(counts == 0):
        raise ValueError("every facet needs at least one point")
    moved = np.moveaxis(np.asarray(x), axis, 0)
    total = np.zeros((n_facets,) + moved.shape[1:])
    np.add.at(total, owner, moved)
    total /= counts.reshape((-1,) + (1,) * (moved.ndim - 1))
    return np.moveaxis(total, 0, axis)


def averaged_bases(bases, owner, n_facets: int):
    """:class:`~bayesgloss.illumination.IlluminationBases` of points averaged
    over each facet's points (``owner``): (P, F, ...) from (P, M, ...)."""

    def mean(x, axis):
        return facet_mean(x, owner, n_facets, axis)

    fresnel = bases.fresnel
    if fresnel is not None:
        rise = fresnel.glossy_rise
        fresnel = dataclasses.replace(
            fresnel,
            view=mean(fresnel.view, 0),
            sun_direct=mean(fresnel.sun_direct, 0),
            glossy_rise=None if rise is None else mean(rise, 1),
        )
    return dataclasses.replace(
        bases, diffuse=mean(bases.diffuse, 1), glossy=mean(bases.glossy, 1), fresnel=fresnel
    )

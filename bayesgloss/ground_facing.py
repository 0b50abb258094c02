"""Facets that face the ground, left out where the object's shape is not given.

The forward model lights the ground around the object as an open plane:
the sun's and the sky's light on it, times its reflectance
(:func:`bayesgloss.render.facet_bases`, ``ground="plane"``). Where a bundle
has an ``object_mesh``, the object's own shadow on that ground is cast from
the mesh (:mod:`bayesgloss.visibility`). A bundle without one says only that
the object is convex and stands alone on the ground (the bundle spec), and
lists the facets the camera sees, not the object's whole shape: the shadow
it casts on the ground cannot be known.

For most facets that matters little: a facet that faces the sky sees
ground only beyond its own plane, and the sun lights the facet directly.
A facet whose normal points below the horizon sees more ground than sky,
and the ground it sees lies under and beside the object, in the object's
shadow for much of the day; it gets no direct sun for most of the day. Its
light is mostly what the model cannot predict. On holdout 2's vs12 (a
gem, rough plastic of gamma 0.459), the five downward facets (normal z
-0.62 to -0.67) missed the model's best fit by 30-60 % under every gamma
and pulled the object's answer to 0.115; without them the best fit's
gamma was 0.5 (``studies/README.md``, "Holdout 3").

So, without a mesh, :func:`estimate <bayesgloss.estimate.estimate_bundle>`
leaves out facets whose normal's z is below :data:`GROUND_FACING_NZ`
(``"leave-out"``, the default; ``"keep"`` keeps them), flagged
``faces-ground`` in the summary, unless no other facet is left to fit.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "GROUND_FACING_NZ",
    "GROUND_FACING_MODES",
    "DEFAULT_GROUND_FACING",
    "check_ground_facing_mode",
    "facets_facing_ground",
    "leave_out_ground_facing",
]

#: A facet faces the ground where its unit normal's z (up) is below this [-]:
#: tilted more than about 6 degrees below the horizon. Walls (z = 0) stay.
GROUND_FACING_NZ = -0.1
#: What :func:`bayesgloss.estimate.estimate_bundle` does with such facets.
GROUND_FACING_MODES = ("leave-out", "keep")
#: Its default.
DEFAULT_GROUND_FACING = "leave-out"


def check_ground_facing_mode(mode: str) -> str:
    """``mode`` if it is one of :data:`GROUND_FACING_MODES`; else ``ValueError``."""
    if mode not in GROUND_FACING_MODES:
        raise ValueError(
            f"unknown ground-facing mode {mode!r}; valid: {', '.join(GROUND_FACING_MODES)}"
        )
    return mode


def facets_facing_ground(normals, has_mesh: bool) -> np.ndarray:
    """Facets that face the ground and whose ground the bundle does not describe.

    Parameters
    ----------
    normals : array_like (F, 3)
        Outward unit normals in the world frame (z up) [-].
    has_mesh : bool
        Whether the bundle has an ``object_mesh`` (then its shadow on the
        ground is modelled and no facet is returned).

    Returns
    -------
    ndarray (F,) of bool
        Normal's z below :data:`GROUND_FACING_NZ`, and no mesh.
    """
    nz = np.asarray(normals, dtype=float)[..., 2]
    if has_mesh:
        return np.zeros(nz.shape, dtype=bool)
    return nz < GROUND_FACING_NZ


def leave_out_ground_facing(bundle, keep, mode: str = DEFAULT_GROUND_FACING):
    """The usable facets ``keep`` without those facing the ground (``mode``
    ``"leave-out"``), unless no other usable facet is left.

    Parameters
    ----------
    bundle : bayesgloss.bundle.Bundle
    keep : ndarray (F,) of bool
        Usable facets (:func:`bayesgloss.bundle.usable_facets`). -
    mode : {"leave-out", "keep"}
        :data:`GROUND_FACING_MODES`. -

    Returns
    -------
    keep : ndarray (F,) of bool
        The facets to fit.
    left_out : ndarray (F,) of bool
        The usable facets left out as facing the ground.
    """
    keep = np.asarray(keep, dtype=bool)
    left_out = np.zeros_like(keep)
    if check_ground_facing_mode(mode) == "leave-out":
        left_out = keep & facets_facing_ground(bundle.facets.normal, bundle.has_mesh)
        if not (keep & ~left_out).any():  # nothing else to fit: keep them
            left_out[:] = False
    return keep & ~left_out, left_out

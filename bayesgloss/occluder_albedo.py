"""The albedo of a non-convex object's own faces, an unknown averaged by predictive performance.

Where a bundle has an ``object_mesh``, the forward model gives the
directions a facet sees of the object's other faces the radiance of
Lambertian faces of one albedo, lit by the sky, the ground and the sun they
see (:mod:`bayesgloss.render`, "Self-occlusion"). Those faces are the object
itself, whose reflectance nobody gives: a courtyard wall lit by a white
wing is brighter than one lit by a dark one, and a wrong albedo puts the
difference into the material. The camera's unknown exposure takes the
object's absolute reflectance with it, so the faces' albedo cannot be read
off the facets' brightness; what tells it is how much brighter the facets
that face the object are than the model's sky and sun alone make them.

``estimate --occluder-albedo stacked`` (:func:`fit_occluder_albedos`): the
one-material joint model is fitted with the faces at each albedo of
:data:`OCCLUDER_ALBEDOS` under the day's sky
(:func:`bayesgloss.stacking.fit_stacked`: with stacked sky families, the
families at :data:`~bayesgloss.render.OCCLUDER_REFLECTANCE` and the other
albedos under the most-weighted family, two fits more), and the object's
gloss is the mixture of the fits with the stacking weights of their PSIS-LOO
predictive densities (Yao, Vehtari, Simpson & Gelman 2018). The three
albedos span the painted, plastic and stone surfaces' 0.2-0.8 with 0.3
between neighbours; where the data cannot tell them apart the mixture
carries them all.

What the weights find is the faces' diffuse albedo, (1 - s) colour for
Radiance's plastic, not their total reflectance: a Lambertian stand-in
sends the diffuse part everywhere, the specular part goes toward the
mirror direction. On six L buildings nobody tuned to
(``studies/occluder_set.py``, rule written before the run) the
most-weighted albedo was the one nearest the diffuse albedo in 6 of 6, and
the object's gamma was off by 0.138 on average against 0.148 with 0.5
fixed, its own 90 % interval holding the truth as often (2 of 6: three dark
rough plastics read matt under every albedo, ``studies/README.md``).
Default of ``estimate`` since: :data:`DEFAULT_OCCLUDER_ALBEDO`.

A bundle without a mesh has no faces to see: the option changes nothing.
"""

from __future__ import annotations

from .render import OCCLUDER_REFLECTANCE
from .stacking import fit_stacked

__all__ = [
    "OCCLUDER_ALBEDOS",
    "OCCLUDER_ALBEDO_MODES",
    "DEFAULT_OCCLUDER_ALBEDO",
    "check_occluder_albedo_mode",
    "fit_occluder_albedos",
]

#: The faces' albedos fitted and stacked [-].
OCCLUDER_ALBEDOS = (0.2, OCCLUDER_REFLECTANCE, 0.8)
#: ``estimate --occluder-albedo``: the faces at :data:`~bayesgloss.render.OCCLUDER_REFLECTANCE`,
#: or each of :data:`OCCLUDER_ALBEDOS` stacked.
OCCLUDER_ALBEDO_MODES = ("fixed", "stacked")
#: The mode ``estimate`` uses unless told (``studies/README.md``, "Occluder albedo").
DEFAULT_OCCLUDER_ALBEDO = "stacked"


def _label(albedo: float) -> str:
    return f"{albedo:g}"


def check_occluder_albedo_mode(mode: str) -> str:
    """``mode``, or a ValueError naming the valid ones."""
    if mode not in OCCLUDER_ALBEDO_MODES:
        raise ValueError(
            f"unknown occluder albedo {mode!r}; valid: {', '.join(OCCLUDER_ALBEDO_MODES)}"
        )
    return mode


def fit_occluder_albedos(
    b,
    curves,
    y,
    usable,
    censored,
    keep,
    illumination,
    seed,
    options,
    progress=None,
    jobs=1,
    **sky_options,
):
    """The joint model with the mesh's faces at each of :data:`OCCLUDER_ALBEDOS`, stacked.

    Parameters
    ----------
    b, curves, y, usable, censored, keep
        As :func:`bayesgloss.joint_estimate.joint_fit`'s; ``b`` has an ``object_mesh``.
    illumination : str
        A sky model, ``"auto"`` or ``"families"``.
    seed : int
    options : dict
        Sampler options (``occluder_albedo`` is set per fit).
    progress : callable, optional
        Called with (fits done, fits).
    jobs : int
        Fits at once in worker processes.
    **sky_options
        ``overcast_variants`` and ``unreliable_loo`` of
        :func:`bayesgloss.stacking.fit_stacked`.

    Returns
    -------
    idata : arviz.InferenceData
        The most-weighted albedo's fit (with its facets' posteriors), its
        object's gloss and lobe replaced by the stacked mixture's draws;
        posterior attributes ``occluder_albedo_weights`` (JSON, albedo to
        weight) and ``occluder_albedo_most_weight``.
    samples : bayesgloss.sampling.JointSamples
        The most-weighted albedo's run.
    used : ndarray of bool
    info : dict
        ``occluder_albedos`` (per albedo: stacking weight, elpd_loo, se,
        p_loo, high_k and its own gamma quantiles), ``occluder_albedo``
        (the most-weighted), ``sky_families`` (where stacked), ``seconds``.
    """
    choices = {_label(a): a for a in OCCLUDER_ALBEDOS}
    stack = fit_stacked(
        b,
        curves,
        y,
        usable,
        censored,
        keep,
        illumination,
        seed,
        options,
        option="occluder_albedo",
        choices=choices,
        default=_label(OCCLUDER_REFLECTANCE),
        attribute="occluder_albedo",
        progress=progress,
        jobs=jobs,
        **sky_options,
    )
    info = stack.record("occluder_albedos", stack.entries(), "occluder_albedo", choices[stack.best])
    return stack.idata, stack.samples, stack.used, info

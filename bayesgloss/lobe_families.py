"""The glossy lobe's family averaged by predictive performance: one fit per family, stacked.

``estimate --lobe families`` (:func:`fit_lobe_families`): the one-material
joint model (:func:`bayesgloss.joint_estimate.joint_fit`) is fitted with the
glossy lobe of each family of :data:`bayesgloss.lobes.LOBE_FAMILIES`
(Phong, Radiance's Ward, GGX with Smith shadowing; :mod:`bayesgloss.lobes`),
and the object's gloss is the mixture of the fits' posteriors with the
stacking weights of their PSIS-LOO predictive densities (Yao, Vehtari,
Simpson & Gelman 2018; the weights of
:func:`bayesgloss.sky_families.loo_stacking_weights`). A lobe shape the
data cannot tell apart from another then widens the object's interval
instead of biasing it. Families tied with the best (PSIS-LOO elpd within
:data:`bayesgloss.stacking.TIED_ELPD`) share their weight evenly
(:func:`bayesgloss.stacking.spread_tied_weights`): on an overcast day the
lobe's family and the gloss trade off, and stacking alone once gave one of
four equally predictive fits all the weight (stop 40, Mitsuba holdout 1).
Where the day's sky is an overcast one the lobe families are not stacked
at all: Phong alone answers, flagged ``lobe-family-not-stacked`` (stop 41:
with its fits tied and spread, ``materials`` still failed holdout 8's
overcast rule by one sunless day; ``sunless_default`` of
:func:`bayesgloss.stacking.fit_stacked`). Since stop 70 the other families
are fitted beside it under the day's sky all the same (:data:`SUNLESS_SPREAD`):
their stack-weighted spread joins the model error
(:func:`bayesgloss.model_error.choice_spread`) and the object is flagged
``gloss-not-identifiable`` where their mixture's 90 % interval is wider than
0.6 (:func:`sunless_spread_of`), so the answer's median is Phong's and its
interval carries the lobe's shape. By the rule of holdout 29 and Mitsuba
holdout 15 (24 unseen sunless days, studies/README.md): the overcast rule
passed on 18 against 14, the interval held the truth on 22 both, MAE 0.130
against 0.131, 1.27 times the time.

The sky is chosen first (:func:`bayesgloss.stacking.fit_stacked`): with
``illumination="families"`` the sky families are stacked with the Phong
lobe and the other lobes are fitted under the most-weighted sky family, so
the families cost two fits more than the sky alone (not three times as
many); with a named sky (or ``"auto"``) every lobe is fitted under it.
Where the sky families tie (``sky-family-not-identifiable``, most objects
of 1-3 facets), every lobe is fitted under each sky family sharing the
weight and the answer mixes them with weight w_sky w_lobe|sky (since stop
61, by the rule of holdout 24 and Mitsuba holdout 11: on their 26 sun-lit
boxes the reported interval held the truth in 22 against Phong alone's 19,
confident misses 3 against 7, MAE 0.130 against 0.146).

``estimate --lobe materials`` (:data:`MATERIAL_FAMILIES`) stacks one fit
more: GGX with Schlick's Fresnel (:mod:`bayesgloss.fresnel`), a dielectric
coating over a diffuse base (plastics, paints, varnish: Walter et al. 2007's
microfacet lobe, whose specular part rises toward grazing incidence while
the diffuse part passes the coating twice), beside the three lobes without a
Fresnel term (Phong and Radiance's Ward, the rough Radiance materials'; GGX
alone, near a metal's, whose Fresnel changes little below grazing). On two
seen Mitsuba renders of dark rough plastic (stop 39, studies/README.md) the
coating's PSIS-LOO was 225-260 above Phong's; fitted with their own sky,
a rough gold read 0.47 with GGX for a true 0.51 where Phong read 0.22.
Since stop 55 the coating's rise is taken inside the lobe, at each light's
own half vector (``"schlick-lobe"``, :func:`bayesgloss.fresnel.fresnel_parts_in_lobe`),
not at the view: on holdout 18 and Mitsuba holdout 8 (rule written before
they were drawn) the sun-lit MAE fell from 0.057 to 0.055, the Mitsuba
plastics where the fit ran from 0.088 to 0.083 (rough, 3) and 0.034 to
0.019 (smooth, 3), the reported interval holding the truth as often.

gamma means the same under every family (README, "The estimand"), so the
mixture of the families' gamma is a mixture of one quantity; ``n_object``
is each family's Phong-equivalent exponent (:func:`bayesgloss.lobes.roughness_of_exponent`).
"""

from __future__ import annotations

import json

import numpy as np

from .fresnel import IN_LOBE
from .intervals import GAMMA_BOUNDS
from .intervals import posterior_quantiles as _quantiles
from .joint_estimate import DEFAULT_FRESNEL, DEFAULT_LOBE_FAMILY
from .lobes import LOBE_FAMILIES, check_lobe_family, roughness_of_exponent
from .model_error import choice_spread
from .stacking import fit_stacked

__all__ = [
    "MATERIAL_FAMILIES",
    "DEFAULT_LOBE",
    "SUNLESS_SPREAD",
    "SPREAD_STREAM",
    "default_lobe",
    "check_lobe",
    "fit_lobe_families",
    "sunless_spread_of",
]

#: ``estimate``'s lobe where none is named and the joint model runs with no
#: Fresnel model named (:func:`default_lobe`), since stop 42: on the two
#: unseen holdouts whose rule was written before they were drawn (Radiance
#: holdout 9, Mitsuba holdout 3; ``studies/README.md``) it was as good as
#: Phong alone or better on every count (Mitsuba: sun-lit MAE 0.087 against
#: 0.178, the reported interval holding the truth in 17 of 19 against 13,
#: 1 confident miss against 4; Radiance: 0.065 against 0.063, 18 of 19 both).
DEFAULT_LOBE = "materials"

#: On a sunless day, fit the other families beside Phong, which answers alone,
#: and add their spread to the model error (:func:`bayesgloss.model_error.choice_spread`;
#: ``sunless_spread`` of :func:`bayesgloss.stacking.fit_stacked`). The object
#: is flagged ``gloss-not-identifiable`` where their stack-weighted mixture's
#: own 90 % interval is wider than :data:`bayesgloss.estimate.NOT_IDENTIFIABLE_WIDTH`:
#: the data do not tell the lobe's shape, and gloss moves with it.
SUNLESS_SPREAD = True
#: The random stream (with the seed) of the families' mixture's draws.
SPREAD_STREAM = 7

#: ``--lobe materials``: label to (lobe family, Fresnel model) of each fit.
MATERIAL_FAMILIES = {
    "phong": ("phong", "none"),
    "ward": ("ward", "none"),
    "ggx": ("ggx", "none"),
    "ggx-schlick": ("ggx", "schlick-lobe"),
}


def default_lobe(
    joint: bool, fresnel: str, has_mesh: bool = False, illumination: str = "families"
) -> str:
    """The lobe ``estimate`` fits where none is named: :data:`DEFAULT_LOBE`
    where the estimate is the one the deciding holdouts scored, the joint
    model under the stacked sky families (``illumination="families"``, the
    default sky) with no Fresnel model named (``materials`` chooses each
    fit's own) and no ``object_mesh``; otherwise Phong, as each of those
    was checked: the fixed-brightness estimator's only lobe, the lobe of a
    named sky or Fresnel model and of ``--sky auto`` (whose speed goal, 30 s
    on the benchmark bundle, the stack's four fits would break: 61-134 s
    against 15-28), and of a mesh bundle, whose faces' albedo is stacked
    instead (:mod:`bayesgloss.occluder_albedo`; one stack at a time). A
    Fresnel model whose rise is inside a lobe (:data:`bayesgloss.fresnel.IN_LOBE`)
    takes that lobe."""
    if fresnel in IN_LOBE:
        return IN_LOBE[fresnel]
    if joint and illumination == "families" and fresnel == DEFAULT_FRESNEL and not has_mesh:
        return DEFAULT_LOBE
    return DEFAULT_LOBE_FAMILY


def check_lobe(lobe: str, fresnel: str, joint: bool) -> tuple[str, bool]:
    """``estimate``'s ``lobe`` checked against its other options: (lobe,
    whether it is a stack, ``"families"`` or ``"materials"``). A ValueError
    for an unknown family, a Fresnel model named with ``"materials"`` (which
    chooses each fit's own), a lobe other than the one a Fresnel model's rise
    is inside (:data:`bayesgloss.fresnel.IN_LOBE`), or any lobe but the
    default without the joint model."""
    stacked = lobe in ("families", "materials")
    if not stacked:
        check_lobe_family(lobe)
    if lobe == "materials" and fresnel != DEFAULT_FRESNEL:
        raise ValueError(
            f"lobe 'materials' chooses each fit's Fresnel model itself; fresnel "
            f"'{fresnel}' cannot be given with it"
        )
    if fresnel in IN_LOBE and lobe != IN_LOBE[fresnel]:
        raise ValueError(
            f"fresnel '{fresnel}' takes its rise inside the '{IN_LOBE[fresnel]}' lobe; "
            f"lobe '{lobe}' cannot be given with it"
        )
    if lobe != DEFAULT_LOBE_FAMILY and not joint:
        raise ValueError(
            f"lobe '{lobe}' needs per-frame illumination (relative noise and a known "
            "pixel response); the fixed-brightness estimator has the Phong lobe only"
        )
    return lobe, stacked


def fit_lobe_families(
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
    materials=False,
    **sky_options,
):
    """The joint model under each lobe family, stacked (module docstring).

    Parameters
    ----------
    b, curves, y, usable, censored, keep
        As :func:`bayesgloss.joint_estimate.joint_fit`'s.
    illumination : str
        A sky model, ``"auto"`` or ``"families"``.
    seed : int
    options : dict
        Sampler options (``lobe_family`` is set per fit).
    progress : callable, optional
        Called with (fits done, fits).
    jobs : int
        Fits at once in worker processes.
    materials : bool
        Stack :data:`MATERIAL_FAMILIES` (the lobes and the dielectric
        coating, each with its Fresnel model) instead of the lobes alone.
    **sky_options
        ``overcast_variants`` and ``unreliable_loo`` of
        :func:`bayesgloss.stacking.fit_stacked`.

    Returns
    -------
    idata : arviz.InferenceData
        The most-weighted family's fit (with its facets' posteriors), its
        ``gamma_object`` and ``n_object`` replaced by the stacked mixture's
        draws; posterior attributes ``lobe_family_weights`` (JSON) and
        ``lobe_family_most_weight`` (and the sky families' attributes
        where the sky was stacked).
    samples : bayesgloss.sampling.JointSamples
        The most-weighted family's run.
    used : ndarray of bool
    info : dict
        ``lobe_families`` (per family: stacking weight, elpd_loo, se,
        p_loo, high_k, its own gamma and roughness quantiles, and, for a
        fit with a Fresnel model, its strength k and normal-incidence albedo
        A, ``fresnel_strength`` and ``normal_albedo``),
        ``lobe_family`` (the most-weighted), ``sky_families`` and ``sky``
        (where stacked), ``seconds``.
    """
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
        option=("lobe_family", "fresnel") if materials else "lobe_family",
        choices=MATERIAL_FAMILIES if materials else {name: name for name in LOBE_FAMILIES},
        default="phong",
        attribute="lobe_family",
        ties="spread",
        sunless_default=True,
        sunless_spread=SUNLESS_SPREAD,
        progress=progress,
        jobs=jobs,
        **sky_options,
    )
    beside = stack.beside()
    if beside is not None:  # the families beside Phong on a sunless day
        own = {k: post["gamma_object"].values for k, post in beside["own"].items()}
        rng = np.random.default_rng([seed, SPREAD_STREAM])
        spread = choice_spread(own, beside["weights"], rng)
        stack.idata.posterior.attrs["lobe_family_spread"] = json.dumps(
            {"sd": spread["sd"], "mixture": _quantiles(spread["mixture"], GAMMA_BOUNDS)}
        )
    # the families' microfacet roughness differ in meaning; the mixture keeps none
    stack.idata.posterior = stack.idata.posterior.drop_vars("roughness_object", errors="ignore")
    families = stack.entries()
    for label, own in stack.own.items():
        lobe = MATERIAL_FAMILIES[label][0] if materials else label
        if lobe != "phong":  # the microfacet ones
            families[label]["roughness"] = _quantiles(roughness_of_exponent(own["n_object"].values))
        if materials:
            families[label]["lobe_family"], families[label]["fresnel"] = MATERIAL_FAMILIES[label]
        for name in ("fresnel_strength", "normal_albedo"):  # a Fresnel model's unknowns
            if name in own:
                families[label][name] = _quantiles(own[name].values)
    return (
        stack.idata,
        stack.samples,
        stack.used,
        stack.record("lobe_families", families, "lobe_family", stack.best),
    )


def sunless_spread_of(posterior) -> dict | None:
    """The other lobe families' spread where Phong answered a sunless day
    alone (:data:`SUNLESS_SPREAD`), as :func:`fit_lobe_families` recorded it
    in ``posterior.attrs``: ``{"sd"`` (tau_choices of
    :func:`bayesgloss.model_error.choice_spread`), ``"mixture"`` (the
    quantiles of their stack-weighted mixture)``}``; None elsewhere."""
    return json.loads(posterior.attrs.get("lobe_family_spread", "null"))

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
instead of biasing it.

The sky is chosen first (:func:`bayesgloss.stacking.fit_stacked`): with
``illumination="families"`` the sky families are stacked with the Phong
lobe and the other lobes are fitted under the most-weighted sky family, so
the families cost two fits more than the sky alone (not three times as
many); with a named sky (or ``"auto"``) every lobe is fitted under it.

gamma means the same under every family (README, "The estimand"), so the
mixture of the families' gamma is a mixture of one quantity; ``n_object``
is each family's Phong-equivalent exponent (:func:`bayesgloss.lobes.roughness_of_exponent`).
"""

from __future__ import annotations

from .intervals import posterior_quantiles as _quantiles
from .lobes import LOBE_FAMILIES, roughness_of_exponent
from .stacking import fit_stacked

__all__ = ["fit_lobe_families"]


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
        p_loo, high_k, its own gamma and roughness quantiles),
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
        option="lobe_family",
        choices={name: name for name in LOBE_FAMILIES},
        default="phong",
        attribute="lobe_family",
        progress=progress,
        jobs=jobs,
        **sky_options,
    )
    # the families' microfacet roughness differ in meaning; the mixture keeps none
    stack.idata.posterior = stack.idata.posterior.drop_vars("roughness_object", errors="ignore")
    families = stack.entries()
    for n in (n for n in LOBE_FAMILIES if n != "phong" and n in stack.own):  # microfacet ones
        families[n]["roughness"] = _quantiles(
            roughness_of_exponent(stack.own[n]["n_object"].values)
        )
    return (
        stack.idata,
        stack.samples,
        stack.used,
        stack.record("lobe_families", families, "lobe_family", stack.best),
    )

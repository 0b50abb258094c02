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

The sky is chosen first: with ``illumination="families"`` the sky families
are stacked with the Phong lobe (:func:`bayesgloss.sky_families.fit_families`)
and the other lobes are fitted under the most-weighted sky family, so the
families cost two fits more than the sky alone (not three times as many);
with a named sky (or ``"auto"``) every lobe is fitted under it. The Phong
component of the mixture keeps the sky mixture's draws.

gamma means the same under every family (README, "The estimand"), so the
mixture of the families' gamma is a mixture of one quantity; ``n_object``
is each family's Phong-equivalent exponent (:func:`bayesgloss.lobes.roughness_of_exponent`).
"""

from __future__ import annotations

import json
from concurrent.futures import as_completed

import numpy as np

from . import sky_families
from .intervals import GAMMA_BOUNDS
from .intervals import posterior_quantiles as _quantiles
from .joint_estimate import add_facet_posteriors, joint_fit
from .lobes import LOBE_FAMILIES, roughness_of_exponent
from .pool import process_pool

__all__ = ["fit_lobe_families"]


def _fit_each(args, illumination, seed, options, names, progress, jobs):
    """joint_fit of each lobe family in ``names`` under one sky: {name: (idata, samples, used)}."""
    fits = {}

    def opts(name):
        return {**options, "lobe_family": name}

    if jobs > 1 and len(names) > 1:
        with process_pool(min(jobs, len(names))) as pool:
            futures = {
                pool.submit(joint_fit, *args, illumination, seed, opts(n), facets=False): n
                for n in names
            }
            for done, future in enumerate(as_completed(futures), 1):
                fits[futures[future]] = future.result()
                if progress is not None:
                    progress(done, len(names))
    else:
        for name in names:
            fits[name] = joint_fit(*args, illumination, seed, opts(name), facets=False)
            if progress is not None:
                progress(len(fits), len(names))
    return fits


def fit_lobe_families(
    b, curves, y, usable, censored, keep, illumination, seed, options, progress=None, jobs=1
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
    args = (b, curves, y, usable, censored, keep)
    options = {k: v for k, v in options.items() if k != "lobe_family"}
    info, seconds = {}, 0.0
    others = [n for n in LOBE_FAMILIES if n != "phong"]
    if illumination == "families":
        phong = sky_families.fit_families(
            *args, seed, {**options, "lobe_family": "phong"}, None, jobs
        )
        sky_info = phong[3]
        seconds += sky_info.pop("seconds")
        info["sky_families"] = sky_info  # families and most_weight
        sky = sky_info["most_weight"]
        fits = {"phong": phong[:3]}
        fits.update(_fit_each(args, sky, seed, options, others, progress, jobs))
    else:
        sky = illumination
        fits = _fit_each(args, sky, seed, options, list(LOBE_FAMILIES), progress, jobs)
    scores = sky_families.loo_stacking_weights({n: fits[n][0] for n in LOBE_FAMILIES})
    weights = np.array([scores[n]["weight"] for n in LOBE_FAMILIES])
    best = LOBE_FAMILIES[int(np.argmax(weights))]
    idata, samples, used = fits[best]
    if "gamma" not in idata.posterior:  # facets' own posteriors of the chosen fit only
        add_facet_posteriors(idata, samples, seed)
    for name, fit in fits.items():
        if name != "phong" or illumination != "families":
            seconds += fit[1].seconds
    seconds += samples.facets.seconds
    own = {n: fits[n][0].posterior["gamma_object"].values.copy() for n in LOBE_FAMILIES}
    rng = np.random.default_rng(seed)
    for var in ("gamma_object", "n_object"):
        draws = [fits[n][0].posterior[var].values for n in LOBE_FAMILIES]
        mixed = sky_families.mixture_draws(draws, weights, rng)
        idata.posterior[var] = (idata.posterior[var].dims, mixed)
    idata.posterior = idata.posterior.drop_vars("roughness_object", errors="ignore")
    if illumination == "families" and best != "phong":  # keep the sky's record
        for key in ("sky_family_weights", "sky_family_most_weight"):
            idata.posterior.attrs[key] = fits["phong"][0].posterior.attrs[key]
    idata.posterior.attrs["lobe_family_weights"] = json.dumps(
        {n: float(w) for n, w in zip(LOBE_FAMILIES, weights, strict=True)}
    )
    idata.posterior.attrs["lobe_family_most_weight"] = best
    families = {}
    for n in LOBE_FAMILIES:
        entry = {**scores[n], "gamma": _quantiles(own[n], GAMMA_BOUNDS)}
        if n != "phong":
            alpha = roughness_of_exponent(fits[n][0].posterior["n_object"].values)
            entry["roughness"] = _quantiles(alpha)
        families[n] = entry
    info.update({"lobe_families": families, "lobe_family": best, "seconds": seconds})
    return idata, samples, used, info

"""The summary of an estimate: the reported gloss of each facet and of the
object, with the model's error, and its flags.

:func:`summarise_estimate` turns a fit of :mod:`bayesgloss.estimate` into
the summary a user reads. The reported gamma of the object and of each
facet carries the model's error of the material's gloss
(:mod:`bayesgloss.model_error`: the facets' disagreement, a floor measured
on renders and, where Phong answered a sunless day alone, the other lobe
families' spread); the model's own posterior is beside it as
``gamma_within_model`` (the one SBC checks), and the object's draws with
the error are ``gamma_material`` in the InferenceData.

Flags: a facet ``not-converged``, ``gloss-not-identifiable`` (the model's
own 90 % interval wider than :data:`NOT_IDENTIFIABLE_WIDTH`: what the data
tell, the model's error aside; for the object also where Phong answered a
sunless day alone and the lobe families' mixture is that wide:
``lobe_mixture_gamma``, :func:`bayesgloss.lobe_families.sunless_spread_of`),
``mostly-saturated`` (more than half its usable entries are lower bounds),
or, left out, ``too-few-frames``, ``saturated`` (too few measured entries)
or ``faces-ground``; the object the same, ``mostly-saturated`` over the
facets used.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from . import bundle as bundle_io
from . import diagnostics, lobe_families
from . import likelihood as lk
from .intervals import GAMMA_BOUNDS, reported_width
from .intervals import posterior_quantiles as _quantiles
from .joint_estimate import frame_summary, object_convergence, sky_model_summary, sun_flags
from .model_error import model_error_sd, with_model_error
from .pooling import population_gloss, shared_gloss
from .render import OCCLUDER_REFLECTANCE
from .results import EstimateResult

__all__ = ["summarise_estimate", "NOT_IDENTIFIABLE_WIDTH", "MODEL_ERROR_STREAM"]

#: The posterior of gamma of a facet or object is "not identifiable" when its
#: 90 % interval is wider than this (the prior's is 0.9).
NOT_IDENTIFIABLE_WIDTH = 0.6

#: The random stream of the model error's draws (with the run's seed:
#: ``default_rng([seed, MODEL_ERROR_STREAM])``), apart from the samplers'.
MODEL_ERROR_STREAM = 7


def summarise_estimate(
    b,
    curves,
    keep,
    idata,
    samples,
    illumination,
    noise,
    camera,
    seed,
    used,
    run,
    facing=None,
    *,
    usable,
    censored,
    min_frames: int,
) -> EstimateResult:
    """The summary of an estimate, and its result (module docstring).

    Parameters
    ----------
    b : bundle.Bundle
        The bundle estimated.
    curves : bundle.FacetCurves
        Its facet curves; ``keep`` (F,) the facets fitted.
    idata : arviz.InferenceData
        The fit's posterior (``gamma`` (chain, draw, facet), ``n``, and the
        one-material model's ``gamma_object`` where it answered).
    samples : object
        The sampler's run (``facets``, ``converged``).
    illumination, noise, camera : str
        The models used, as the summary records them.
    seed : int
        The run's seed; the model error's draws use ``[seed,
        MODEL_ERROR_STREAM]``.
    used : object or None
        The per-frame illumination's inputs where it answered, else None.
    run : dict
        The sampler's timing, steps and model, recorded as ``sampler``.
    facing : ndarray of bool or None
        The facets left out as facing the ground (:mod:`bayesgloss.ground_facing`).
    usable, censored : ndarray of bool, (F, T)
        Each facet and frame's entry usable, and a lower bound only
        (:func:`bayesgloss.estimate.observations`).
    min_frames : int
        Usable frames a facet needs (:data:`bayesgloss.estimate.MIN_FRAMES`):
        a facet left out with fewer is ``too-few-frames``, else ``saturated``.

    Returns
    -------
    EstimateResult
        ``idata`` (with ``gamma_material`` added where the one-material model
        answered), the JSON-ready summary and ``samples``.
    """
    ids = curves.ids[keep]
    diag = diagnostics.gamma_convergence(idata, getattr(samples, "facets", None))
    data_priors = lk.Priors()

    gam = idata.posterior["gamma"].values  # (E, S, F)
    per_facet = gam.transpose(2, 0, 1).reshape(len(ids), -1)
    # kept facets whose usable entries are mostly lower bounds
    mostly_saturated = censored[keep].sum(1) > 0.5 * usable[keep].sum(1)
    # the model's error of the material's gloss (bayesgloss.model_error): the facets'
    # disagreement, the floor no disagreement shows and, where Phong answered a
    # sunless day alone, the other lobe families' spread
    lobes = lobe_families.sunless_spread_of(idata.posterior) or {"sd": 0.0, "mixture": None}
    error = model_error_sd(per_facet.mean(axis=1), per_facet.std(axis=1), choices_sd=lobes["sd"])
    rng = np.random.default_rng([seed, MODEL_ERROR_STREAM])
    facets = []
    for k, fid in enumerate(ids):
        flags = [] if diag["converged"][k] else ["not-converged"]
        within = _quantiles(per_facet[k], GAMMA_BOUNDS)
        gq = _quantiles(with_model_error(per_facet[k], error["sd"], rng), GAMMA_BOUNDS)
        if reported_width(within) > NOT_IDENTIFIABLE_WIDTH:  # the data, not the model error
            flags.append("gloss-not-identifiable")
        if mostly_saturated[k]:
            flags.append("mostly-saturated")
        facets.append(
            {
                "id": int(fid),
                "gamma": gq,
                "gamma_within_model": within,
                "n": _quantiles(idata.posterior["n"].values[..., k]),
                "converged": bool(diag["converged"][k]),
                "rhat": float(diag["rhat"][k]),
                "ess_bulk": float(diag["ess_bulk"][k]),
                "ess_tail": float(diag["ess_tail"][k]),
                "flags": flags,
            }
        )
    for k in np.flatnonzero(~keep):
        short = usable[k].sum() < min_frames  # else too few measured: saturated
        reason = "too-few-frames" if short else "saturated"
        if facing is not None and facing[k]:
            reason = "faces-ground"
        facets.append(
            {"id": int(curves.ids[k]), "gamma": None, "converged": False, "flags": [reason]}
        )
    conv = diag["converged"]
    use = conv if conv.sum() >= 2 else np.ones(len(conv), dtype=bool)
    pop = population_gloss(per_facet[use], ess=diag["ess_bulk"][use], seed=seed)
    logn = np.log(idata.posterior["n"].values).transpose(2, 0, 1).reshape(len(ids), -1)
    shared = shared_gloss(
        np.stack([per_facet, logn], axis=-1)[conv if conv.sum() else slice(None)], data_priors
    )
    if "gamma_object" in idata.posterior:  # the one-material model's own answer
        object_draws = idata.posterior["gamma_object"].values
        obj_converged = bool(samples.converged) and len(ids) > 0
        model = "one material (shared gamma and n, hierarchical albedo, per-frame light)"
    else:
        object_draws = np.asarray(pop["mu"])
        obj_converged = bool(np.all(conv)) and len(ids) > 0
        model = "population (hierarchical Beta)"
    obj_within = _quantiles(object_draws, GAMMA_BOUNDS)
    material = with_model_error(object_draws, error["sd"], rng)
    obj_q = _quantiles(material, GAMMA_BOUNDS)
    if "gamma_object" in idata.posterior:
        idata.posterior["gamma_material"] = (("chain", "draw"), material)
    obj_flags = [] if obj_converged else ["not-converged"]
    if censored[keep].sum() > 0.5 * usable[keep].sum():  # mostly lower bounds
        obj_flags.append("mostly-saturated")
    # what the data tell; where Phong answered alone, with the lobe's family unknown
    widths = [reported_width(q) for q in (obj_within, lobes["mixture"]) if q is not None]
    if max(widths) > NOT_IDENTIFIABLE_WIDTH:
        obj_flags.append("gloss-not-identifiable")
    summary = {
        "object": {
            "gamma": obj_q,
            "gamma_within_model": obj_within,
            "model_error": error,
            "flags": obj_flags,
            "n": {"median": shared["n_median"]},
            "converged": obj_converged,
            "model": model,
            "facet_population_gamma": _quantiles(pop["mu"], GAMMA_BOUNDS),
            "shared_material_gamma": {k: shared[k] for k in ("median", "q05", "q95")},
            "lobe_mixture_gamma": lobes["mixture"],
            "mean_of_facet_medians": float(np.mean(np.median(per_facet, axis=1))),
            "facets_converged": int(conv.sum()),
            "facets": int(len(ids)),
        },
        "facets": facets,
        "illumination": illumination,
        "noise": noise,
        "camera": camera,
        "unit": curves.unit,
        "bundle": str(Path(b.path).resolve()),
        "bundle_content": bundle_io.bundle_digest(b),
        "sampler": run,
        "per_frame_illumination": used is not None,
    }
    if used is not None:
        summary["frames"] = frame_summary(idata, b, used, samples)
        summary["object"]["sun_unidentified_share"], flags = sun_flags(idata)
        summary["object"]["flags"] += flags
        summary["object"]["convergence"] = object_convergence(samples, used)
        summary["sky_models"] = sky_model_summary(idata)
        post = idata.posterior
        summary["object"]["n"] = _quantiles(post["n_object"].values)
        # the day-level spreads, the Fresnel raise's unknowns, the family's roughness
        for name in ("albedo_spread", "exposure_spread", "fresnel_strength", "normal_albedo"):
            if name in post:
                summary["object"][name] = _quantiles(post[name].values)
        summary["fresnel"] = post.attrs.get("fresnel", "none")
        summary["lobe_family"] = post.attrs.get(
            "lobe_family_most_weight", post.attrs.get("lobe_family", "phong")
        )
        if b.has_mesh:  # its faces' albedo: the most-weighted, or fixed
            summary["occluder_albedo"] = float(
                post.attrs.get(
                    "occluder_albedo_most_weight",
                    post.attrs.get("occluder_albedo", OCCLUDER_REFLECTANCE),
                )
            )
        if "roughness_object" in post:
            summary["object"]["roughness"] = _quantiles(post["roughness_object"].values)
        states = post["sun_state_weight"].values.mean(axis=(0, 1)).tolist()
        summary["sun_state"] = dict(zip(post["sun_state"].values.tolist(), states, strict=True))
    return EstimateResult(idata, summary, samples)

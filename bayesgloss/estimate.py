"""Posterior gloss of a sequence bundle: per facet, and for the object.

:func:`estimate_bundle` reads a bundle's facet curves, computes the
forward-model bases for the chosen illumination model, samples every
facet's posterior (:func:`bayesgloss.sampling.sample_posterior`), checks
convergence with ArviZ (R-hat < 1.01, bulk and tail ESS >= 400 for gamma;
otherwise the facet is flagged ``"not-converged"``, never silently
reported), and returns an :class:`arviz.InferenceData` with groups
``posterior``, ``log_likelihood`` (per facet and frame), ``observed_data``,
``posterior_predictive`` and ``sample_stats``, plus a JSON-ready summary.

Object-level gloss, beside the paper's average of facets:

- ``population``: a hierarchical model, facet gammas drawn from a Beta
  population of mean mu and concentration kappa, fitted by reweighting the
  facet posteriors, which were sampled under a uniform prior on gamma (Hogg,
  Myers & Bovy 2010, eq. 11): p(mu, kappa | data) is proportional to
  p(mu, kappa) prod_f int Beta(g; mu kappa, (1 - mu) kappa) p_f(g) dg, p_f a
  kernel density of facet f's draws with a bandwidth set by their effective
  sample size (:func:`bayesgloss.pooling.population_gloss`), a two-parameter density
  integrated on a grid. The object's gloss is mu. Priors: mu uniform on
  [0, 1], log kappa uniform on [log 0.5, log 1e4].
- ``shared``: one material, all facets with the same gamma and n (and their
  own scale and noise): the product of the facets' marginal posteriors of
  (gamma, log n) divided by the prior F - 1 times, evaluated on a grid with a
  kernel density estimate of each facet's draws.
- ``mean``: the mean over facets of their posterior medians (the paper's
  average, for comparison).

Illumination models (``illumination=``, :data:`ILLUMINATION_MODELS`): the
sky models of :func:`bayesgloss.sky.sky_models` (``"point-sun"``, the
paper's sun with no sky; gensky's clear, intermediate, overcast and uniform
skies; the 15 CIE general skies; Perez).

A facet needs at least :data:`MIN_FRAMES` usable frames; a bundle in which
no facet has them (every frame at night, a single frame) is rejected with
:class:`bayesgloss.bundle.NoUsableData`, which says how many frames have
the sun up.

:func:`estimate_unit` is one bundle's estimate as files
(:func:`result_files`), the unit of work that
:func:`bayesgloss.runner.run_units` fans out over many bundles;
:func:`~bayesgloss.results.write_result` and :func:`~bayesgloss.results.read_result`
(:mod:`bayesgloss.results`, re-exported here) write and read a result folder.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from . import bundle as bundle_io
from . import diagnostics, render, sampling, sky
from . import illumination as il
from . import likelihood as lk
from ._thirdparty import arviz
from .irradiance import measured_sky
from .pool import process_pool
from .pooling import population_gloss, shared_gloss
from .results import (
    RESULT_FILES,
    EstimateResult,
    check_result_folder,
    read_result,
    result_files,
    write_result,
)

__all__ = [
    "RESULT_FILES",
    "check_result_folder",
    "result_files",
    "write_result",
    "read_result",
    "ILLUMINATION_MODELS",
    "MIN_FRAMES",
    "estimate_unit",
    "default_illumination",
    "bundle_bases",
    "bundle_sky",
    "observations",
    "EstimateResult",
    "estimate_bundle",
    "to_inference_data",
    "convergence",
]

#: Illumination models: every sky model of :func:`bayesgloss.sky.sky_models`.
ILLUMINATION_MODELS = sky.sky_models()
#: Usable frames a facet's curve needs at least.
MIN_FRAMES = 4


def bundle_sky(b, illumination: str, ground_reflectance: float):
    """The sky of a bundle's frames: a sky model by name, or ``"measured"``,
    the Perez sky of its ``frames[].irradiance`` (:func:`bayesgloss.irradiance.measured_sky`)."""
    if illumination == "measured":
        day = measured_sky(b, ground_reflectance)
        if day is None:
            raise ValueError(
                f"bundle '{b.path}': illumination 'measured' needs frames[].irradiance "
                "(DNI and DHI, or GHI) for every frame with the sun up"
            )
        return day
    return sky.daylight(illumination, b.sun_direction, ground_reflectance=ground_reflectance)


def bundle_bases(
    b, illumination: str = "gensky-clear", *, exponents=render.DEFAULT_EXPONENTS, occluder=None
) -> render.FacetBases:
    """Forward-model bases of a bundle's facets under an illumination model.

    The sky model sees the bundle's ground reflectance (0.2 if absent) and a
    ground plane (``"point-sun"``: nothing but the sun).
    """
    if illumination not in (*ILLUMINATION_MODELS, "measured"):
        raise ValueError(
            f"unknown illumination {illumination!r}; valid: {', '.join(ILLUMINATION_MODELS)}, "
            "measured"
        )
    rho = b.ground_albedo
    day = bundle_sky(b, illumination, rho)
    ground = "sky" if illumination == "point-sun" else "plane"
    return render.facet_bases(
        b.view_geometry(occluder), day, exponents, ground=ground, ground_reflectance=rho
    )


def observations(curves) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(y, usable, censored) from a bundle's facet curves.

    Entries flagged only ``saturated`` enter as censored, at the facet's
    statistic with its saturated pixels at the top code
    (:attr:`bayesgloss.bundle.FacetCurves.lower_bound`), a lower bound of
    its true value, also where every pixel of the facet saturates. Every
    other flag leaves the entry out.
    """
    sat_bit = 1 << bundle_io.FLAG_REASONS.index("saturated")
    only_saturated = curves.flag_bits == sat_bit
    censored = only_saturated & np.isfinite(curves.lower_bound)
    usable = curves.valid | censored
    y = np.where(censored, curves.lower_bound, curves.luminance)
    return np.where(usable, y, 0.0), usable, censored


def convergence(idata) -> dict:
    """R-hat and bulk/tail ESS of gamma per facet, and whether each converged
    (the rule of :mod:`bayesgloss.diagnostics`)."""
    gamma = np.moveaxis(idata.posterior["gamma"].values, -1, 0)  # (F, E, S)
    rhat, ess_bulk, ess_tail, ok = diagnostics.diagnose(gamma)
    return {"rhat": rhat, "ess_bulk": ess_bulk, "ess_tail": ess_tail, "converged": ok}


def to_inference_data(
    samples: sampling.PosteriorSamples, data: lk.CurveData, ids, *, times=None, rng=None
):
    """ArviZ InferenceData of facet posteriors (chains are independent ensembles)."""
    az = arviz()

    rng = np.random.default_rng(rng)
    draws = samples.draws  # (F, E, S, P)
    f, e, s_, p = draws.shape
    th = draws.transpose(0, 1, 2, 3).reshape(f, e * s_, p)
    pointwise = lk.log_likelihood(th, data, pointwise=True)  # (F, E*S, T)
    pred = lk.simulate(th, data, rng)  # (F, E*S, T)
    t = data.y.shape[1]

    def chains(x):  # (F, E*S, ...) -> (E, S, F, ...)
        x = x.reshape(f, e, s_, *x.shape[2:])
        return np.moveaxis(x, 0, 2)

    post = {
        "gamma": chains(th[..., 0]),
        "n": chains(np.exp(th[..., 1])),
        "s": chains(np.exp(th[..., 2])),
        "sigma": chains(np.exp(th[..., 3])),
    }
    if p == 5:
        post["g"] = chains(np.exp(th[..., 4]))
    ll = np.where(data.valid[:, None, :], pointwise, np.nan)
    coords = {"facet": np.asarray(ids), "frame": np.arange(t)}
    idata = az.from_dict(
        posterior=post,
        log_likelihood={"y": chains(ll)},
        posterior_predictive={"y": chains(pred)},
        observed_data={"y": np.where(data.valid, data.y, np.nan)},
        sample_stats={
            "tau_gamma": np.broadcast_to(samples.tau[..., 0].T[:, None, :], (e, s_, f)),
        },
        coords={"facet": coords["facet"], "frame": coords["frame"]},
        dims={
            "gamma": ["facet"],
            "n": ["facet"],
            "s": ["facet"],
            "sigma": ["facet"],
            "g": ["facet"],
            "y": ["facet", "frame"],
            "tau_gamma": ["facet"],
        },
    )
    idata.observed_data["valid"] = (("facet", "frame"), data.valid)
    idata.observed_data["censored"] = (("facet", "frame"), data.censored)
    if times is not None:  # UTC, stored without a zone
        idata.observed_data["time"] = (("frame",), times.tz_convert("UTC").tz_localize(None))
    return idata


def _quantiles(x) -> dict:
    """Median, 5 and 95 % quantiles, and the 90 % highest-density interval.

    For a gamma at the edge of [0, 1] the equal-tailed interval cannot hold
    the edge; the highest-density interval can.
    """
    az = arviz()

    x = np.asarray(x, float).ravel()
    q = np.quantile(x, [0.05, 0.5, 0.95])
    hdi = az.hdi(x, hdi_prob=0.9)
    return {
        "median": float(q[1]),
        "q05": float(q[0]),
        "q95": float(q[2]),
        "hdi90": [float(hdi[0]), float(hdi[1])],
    }


def _joint_fit(b, curves, y, usable, censored, keep, illumination, seed, options, progress=None):
    """The joint model of facets and per-frame illumination
    (:mod:`bayesgloss.illumination`) on the usable facets and the frames
    any of them sees: (idata, samples, frames used)."""
    az = arviz()
    rho = b.ground_albedo
    names = AUTO_SKIES if illumination == "auto" else (illumination,)
    day, *others = (bundle_sky(b, name, rho) for name in names)
    ground = "sky" if illumination == "point-sun" else "plane"
    ok = usable[keep] & ~censored[keep]  # censored entries are left out of the joint model
    used = ok.any(axis=0) & b.sun_up
    geometry = b.view_geometry()
    bases = il.illumination_bases(
        geometry, day, others=others, ground=ground, ground_reflectance=rho
    ).take(keep, used)
    exposure = None
    if b.exposure is not None:
        exposure = b.exposure[used]
    elif b.pixel_encoding == "linear-radiance":
        exposure = np.ones(int(used.sum()))
    data = il.joint_data(y[keep][:, used], ok[:, used], bases, exposure=exposure)
    options = dict(options or {})
    if "max_steps" in options:  # a sweep of the joint sampler is its step
        options.setdefault("max_sweeps", options.pop("max_steps"))
    options.setdefault("max_sweeps", JOINT_MAX_SWEEPS)
    allowed = {"max_sweeps", "min_sweeps", "n_walkers", "n_ensembles", "draws_per_ensemble"}
    samples = sampling.sample_joint(
        data,
        seed=seed,
        progress=progress,
        **{k: v for k, v in options.items() if k in allowed},
    )
    rng = np.random.default_rng(seed)
    th = samples.draws.transpose(1, 0, 2, 3)  # (E, F, S, 4)
    frames = samples.frames  # (E, S, T, L)
    ll = il.pointwise_log_likelihood(th, frames, data).transpose(0, 2, 1, 3)  # (E, S, F, T)
    pred = il.simulate(th, frames, data, rng).transpose(0, 2, 1, 3)
    post = {
        "gamma": th[..., 0].transpose(0, 2, 1),
        "n": np.exp(th[..., 1]).transpose(0, 2, 1),
        "s": np.exp(th[..., 2]).transpose(0, 2, 1),
        "sigma": np.exp(th[..., 3]).transpose(0, 2, 1),
        "sun": np.exp(frames[..., 1]),
        "sky": np.exp(frames[..., 2]),
    }
    if exposure is None:
        post["exposure"] = np.exp(frames[..., 0])
    dims = {
        **{v: ["facet"] for v in ("gamma", "n", "s", "sigma")},
        **{v: ["frame"] for v in ("sun", "sky", "exposure")},
        "y": ["facet", "frame"],
    }
    coords = {"facet": curves.ids[keep], "frame": np.flatnonzero(used)}
    if data.shapes >= 2:  # each frame's weights of the sky models
        post["sky_weight"] = np.exp(il.log_shape_weights(frames))
        dims["sky_weight"] = ["frame", "sky_model"]
        coords["sky_model"] = list(names)
    # each draw's log posterior density (up to a constant), sigma at its draw
    lp = np.nansum(ll, axis=(2, 3)) + il.log_prior_frames(frames, data).sum(-1)
    lp += il.log_prior_facets(th, data).sum(1)
    idata = az.from_dict(
        posterior=post,
        log_likelihood={"y": ll},
        posterior_predictive={"y": pred},
        observed_data={"y": np.where(data.valid, data.y, np.nan)},
        sample_stats={"lp": lp},
        coords=coords,
        dims=dims,
    )
    idata.observed_data["valid"] = (("facet", "frame"), data.valid)
    idata.observed_data["censored"] = (("facet", "frame"), censored[keep][:, used])
    idata.observed_data["time"] = (
        ("frame",),
        b.times[used].tz_convert("UTC").tz_localize(None),
    )
    return idata, samples, used


def _frame_summary(idata, b, used) -> list:
    """Each frame's inferred sun, sky (relative to the sky model's) and exposure."""
    out = []
    for j, t in enumerate(np.flatnonzero(used)):
        entry = {"frame": int(t), "time": b.times[t].isoformat()}
        for v in ("sun", "sky", "exposure"):
            if v in idata.posterior:
                entry[v] = _quantiles(idata.posterior[v].values[..., j])
        if "sky_weight" in idata.posterior:
            weights = idata.posterior["sky_weight"]
            entry["sky_weight"] = {
                str(name): _quantiles(weights.values[..., j, k])
                for k, name in enumerate(weights["sky_model"].values)
            }
        out.append(entry)
    return out


def _sky_model_summary(idata) -> dict | None:
    """The posterior weight of each sky model, averaged over frames, and the
    one with the most (None with one sky model)."""
    if "sky_weight" not in idata.posterior:
        return None
    weights = idata.posterior["sky_weight"]
    mean = weights.values.mean(axis=(0, 1, 2))
    names = [str(x) for x in weights["sky_model"].values]
    return {
        "weights": {n: float(m) for n, m in zip(names, mean, strict=True)},
        "most_weight": names[int(np.argmax(mean))],
    }


#: ``illumination="auto"`` with per-frame illumination: each frame's sky a
#: mixture of these shapes, its weights inferred (:mod:`bayesgloss.illumination`):
#: a clear sky, the broad circumsolar brightening of an intermediate or hazy
#: one (without it a glossy lobe stands in for it), and an overcast one.
AUTO_SKIES = ("gensky-clear", "gensky-intermediate", "gensky-overcast")

#: Sweeps at most of the joint sampler where no ``max_steps`` is given (the
#: run stops earlier once converged; otherwise it is flagged ``not-converged``).
JOINT_MAX_SWEEPS = 2000

#: The posterior of gamma of a facet or object is "not identifiable" when its
#: 90 % interval is wider than this (the prior's is 0.9).
NOT_IDENTIFIABLE_WIDTH = 0.6


def _camera(b, camera: str) -> str:
    """``camera="auto"`` resolved: ``"power"`` for an ``unknown`` encoding, else ``"linear"``."""
    if camera != "auto":
        return camera
    return "linear" if b.response_known else "power"


def _joint_possible(per_frame: bool, noise: str, camera: str) -> bool:
    """Whether the joint model of per-frame illumination applies (a resolved camera)."""
    return per_frame and noise == "relative" and camera == "linear"


def default_illumination(
    b, *, per_frame: bool = True, noise: str = "relative", camera: str = "auto"
) -> str:
    """The sky :func:`estimate_bundle` uses where none is named: ``"measured"``
    where the bundle measures every frame with the sun up, else ``"auto"``
    where the joint model applies and ``"gensky-clear"`` where it does not."""
    if measured_sky(b, b.ground_albedo) is not None:
        return "measured"
    return "auto" if _joint_possible(per_frame, noise, _camera(b, camera)) else "gensky-clear"


def estimate_bundle(
    path,
    *,
    illumination: str | None = None,
    noise: str = "relative",
    camera: str = "auto",
    per_frame: bool = True,
    seed: int = 0,
    jobs: int = 1,
    progress=None,
    sampler_options: dict | None = None,
) -> EstimateResult:
    """Posterior gloss of every facet of a bundle, and of the object.

    Parameters
    ----------
    path : path or bundle.Bundle
    illumination : str, optional
        The sky's shape: one of :data:`ILLUMINATION_MODELS`; ``"measured"``,
        the Perez sky of the bundle's ``frames[].irradiance``; or ``"auto"``
        (with ``per_frame`` only: each frame's sky a mixture of
        :data:`AUTO_SKIES`, its weights inferred). Default: ``"measured"``
        where the bundle measures every frame with the sun up, else
        ``"auto"`` with ``per_frame`` and ``"gensky-clear"`` without.
    per_frame : bool
        Infer each frame's sun and sky brightness (and the exposure where
        the bundle does not fix it) jointly with the facets
        (:mod:`bayesgloss.illumination`, :func:`bayesgloss.sampling.sample_joint`),
        the default; False fixes them to the sky model's (the facets
        sampled independently: ``estimate --fixed-brightness``, the
        estimator before per-frame illumination). The joint model needs
        relative noise, a known pixel response and uncensored entries: for
        other noise models and ``unknown`` encodings the brightnesses are
        fixed (said in the summary), and saturated entries are left out of
        it.
    noise : {"relative", "gaussian", "student"}
    camera : {"auto", "linear", "power"}
        ``"auto"``: ``"power"`` for an ``unknown`` pixel encoding, else
        ``"linear"`` (the reader undoes known responses).
    seed : int
    progress : callable, optional
        Called with (done, total): facets of the fixed-brightness model, or
        sweeps of the joint sampler's cap.
    jobs : int
        Local worker processes for the sampler (:func:`bayesgloss.pool.process_pool`).
    sampler_options : dict, optional
        More keyword arguments for :func:`~bayesgloss.sampling.sample_posterior`
        (``max_steps``...); for the joint sampler ``max_steps`` caps its
        sweeps (default :data:`JOINT_MAX_SWEEPS`).

    Raises
    ------
    bayesgloss.bundle.NoUsableData
        Where no facet has :data:`MIN_FRAMES` usable frames.
    """
    b = path if isinstance(path, bundle_io.Bundle) else bundle_io.read_bundle(path)
    sampler_options = {k: v for k, v in (sampler_options or {}).items() if v is not None}
    curves = bundle_io.facet_curves(b)
    camera = _camera(b, camera)
    y, usable, censored = observations(curves)
    keep = bundle_io.usable_facets(b, usable, MIN_FRAMES)
    joint = _joint_possible(per_frame, noise, camera)
    if illumination is None:
        illumination = default_illumination(b, per_frame=per_frame, noise=noise, camera=camera)
    if illumination == "auto" and not joint:
        raise ValueError(
            "illumination 'auto' (a per-frame mixture of sky shapes) needs per-frame "
            "illumination (relative noise and a known pixel response); name a sky model"
        )
    if joint:
        idata, samples, used = _joint_fit(
            b, curves, y, usable, censored, keep, illumination, seed, sampler_options, progress
        )
        run = {"seconds": samples.seconds, "sweeps": samples.n_sweeps, "model": "joint"}
    else:
        idata, samples = _facets_fit(
            b,
            curves,
            y,
            usable,
            censored,
            keep,
            illumination,
            noise,
            camera,
            seed,
            jobs,
            progress,
            sampler_options,
        )
        used = None
        run = {
            "seconds": samples.seconds,
            "median_steps": float(np.median(samples.n_steps)),
            "model": "facets"
            if not per_frame
            else "facets (per-frame illumination needs relative noise and a known pixel response)",
        }
    return _summarise(b, curves, keep, idata, samples, illumination, noise, camera, seed, used, run)


def _facets_fit(
    b,
    curves,
    y,
    usable,
    censored,
    keep,
    illumination,
    noise,
    camera,
    seed,
    jobs,
    progress,
    options,
):
    """The facets sampled independently under the sky model's brightness: (idata, samples)."""
    if b.exposure is not None:  # frames[].exposure: pixel = exposure x radiance
        y = y / (b.exposure / np.exp(np.mean(np.log(b.exposure))))
    bases = bundle_bases(b, illumination)
    sub = render.FacetBases(bases.diffuse[keep], bases.glossy[keep], bases.exponents)
    data = lk.curve_data(
        y[keep], usable[keep], sub, censored=censored[keep], noise=noise, camera=camera
    )
    options = dict(seed=seed, progress=progress, **(options or {}))
    if jobs > 1:
        with process_pool(jobs) as pool:
            samples = sampling.sample_posterior(data, pool=pool, **options)
    else:
        samples = sampling.sample_posterior(data, **options)
    idata = to_inference_data(samples, data, curves.ids[keep], times=b.times, rng=seed)
    return idata, samples


def _summarise(b, curves, keep, idata, samples, illumination, noise, camera, seed, used, run):
    """The summary of an estimate and its result."""
    ids = curves.ids[keep]
    diag = convergence(idata)
    data_priors = lk.Priors()

    gam = idata.posterior["gamma"].values  # (E, S, F)
    per_facet = gam.transpose(2, 0, 1).reshape(len(ids), -1)
    facets = []
    for k, fid in enumerate(ids):
        flags = [] if diag["converged"][k] else ["not-converged"]
        gq = _quantiles(per_facet[k])
        if gq["q95"] - gq["q05"] > NOT_IDENTIFIABLE_WIDTH:
            flags.append("gloss-not-identifiable")
        facets.append(
            {
                "id": int(fid),
                "gamma": gq,
                "n": _quantiles(idata.posterior["n"].values[..., k]),
                "converged": bool(diag["converged"][k]),
                "rhat": float(diag["rhat"][k]),
                "ess_bulk": float(diag["ess_bulk"][k]),
                "ess_tail": float(diag["ess_tail"][k]),
                "flags": flags,
            }
        )
    for fid in curves.ids[~keep]:
        facets.append(
            {"id": int(fid), "gamma": None, "converged": False, "flags": ["too-few-frames"]}
        )
    conv = diag["converged"]
    use = conv if conv.sum() >= 2 else np.ones(len(conv), dtype=bool)
    pop = population_gloss(per_facet[use], ess=diag["ess_bulk"][use], seed=seed)
    logn = np.log(idata.posterior["n"].values).transpose(2, 0, 1).reshape(len(ids), -1)
    shared = shared_gloss(
        np.stack([per_facet, logn], axis=-1)[conv if conv.sum() else slice(None)], data_priors
    )
    obj_q = _quantiles(pop["mu"])
    # the joint sampler's rule covers every frame's latents too
    obj_converged = bool(np.all(conv)) and len(ids) > 0 and getattr(samples, "converged", True)
    obj_flags = [] if obj_converged else ["not-converged"]
    if obj_q["q95"] - obj_q["q05"] > NOT_IDENTIFIABLE_WIDTH:
        obj_flags.append("gloss-not-identifiable")
    summary = {
        "object": {
            "gamma": obj_q,
            "flags": obj_flags,
            "n": {"median": shared["n_median"]},
            "converged": obj_converged,
            "model": "population (hierarchical Beta)",
            "shared_material_gamma": {k: shared[k] for k in ("median", "q05", "q95")},
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
        "sampler": run,
        "per_frame_illumination": used is not None,
    }
    if used is not None:
        summary["frames"] = _frame_summary(idata, b, used)
        summary["sky_models"] = _sky_model_summary(idata)
    return EstimateResult(idata, summary, samples)


def estimate_unit(
    bundle: str,
    illumination: str | None = "gensky-clear",
    noise: str = "relative",
    camera: str = "auto",
    seed: int = 0,
    max_steps: int | None = 8000,
    per_frame: bool = False,
) -> dict[str, bytes]:
    """One bundle's estimate as files: ``summary.json`` and ``posterior.nc``.

    The unit of work of :func:`bayesgloss.runner.run_units` over many
    bundles; it runs in one process (parallelism is across units), so the
    result is the same whatever executor runs it.
    """
    res = estimate_bundle(
        bundle,
        illumination=illumination,
        noise=noise,
        camera=camera,
        per_frame=per_frame,
        seed=seed,
        jobs=1,
        sampler_options={"max_steps": max_steps},
    )
    return result_files(res)

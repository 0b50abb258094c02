"""The joint estimate of a bundle: one material and each frame's light.

The default of :func:`bayesgloss.estimate.estimate_bundle`: the bundle's
usable facets and sun-up frames (:func:`joint_inputs`) fitted by the
one-material model with per-frame illumination
(:func:`bayesgloss.sampling.sample_material`), each facet's own posterior
given the object's illumination
(:func:`bayesgloss.sampling.facets_given_frames`), gathered in an
:class:`arviz.InferenceData` (:func:`joint_fit`); :func:`frame_summary` and
:func:`sky_model_summary` are its parts of the summary.
"""

from __future__ import annotations

import contextlib

import numpy as np

from . import diagnostics, sampling, sky
from . import illumination as il
from ._thirdparty import arviz
from .fresnel import FRESNEL_COLUMNS
from .intervals import posterior_quantiles
from .irradiance import measured_sky
from .lobes import check_lobe_family, roughness_of_exponent
from .object_shadow import (
    DEFAULT_GROUND_SHADOW,
    averaged_bases,
    check_ground_shadow,
    convex_shadow_state,
    shadow_points,
)
from .pool import process_pool
from .visibility import bundle_occlusion

__all__ = [
    "AUTO_SKIES",
    "DEFAULT_FRESNEL",
    "DEFAULT_LOBE_FAMILY",
    "JOINT_MAX_SWEEPS",
    "FACETS_GIVEN_FRAMES_STEPS",
    "bundle_sky",
    "ground_of",
    "joint_inputs",
    "joint_fit",
    "add_facet_posteriors",
    "frame_summary",
    "sun_flags",
    "sun_not_identified",
    "frame_convergence",
    "object_convergence",
    "sky_model_summary",
    "posterior_quantiles",
]

#: ``illumination="auto"`` with per-frame illumination: each frame's sky a
#: mixture of these shapes, its weights inferred (:mod:`bayesgloss.illumination`):
#: a clear sky, the broad circumsolar brightening of an intermediate or hazy
#: one (without it a glossy lobe stands in for it), and an overcast one.
AUTO_SKIES = ("gensky-clear", "gensky-intermediate", "gensky-overcast")

#: The one-material model's Fresnel model where none is named
#: (:data:`bayesgloss.fresnel.FRESNEL_MODELS`).
DEFAULT_FRESNEL = "none"

#: The glossy lobe's family where none is named (:data:`bayesgloss.lobes.LOBE_FAMILIES`).
DEFAULT_LOBE_FAMILY = "phong"

#: How the joint model takes entries whose pixels clipped at the top code
#: (censored: only a lower bound known): ``"drop"`` leaves them out (the
#: model until stop 42: biased where the clipped entries are the glossy
#: peaks), ``"likelihood"`` keeps them with the noise's survival function at
#: the bound (:mod:`bayesgloss.sampling.censored`). ``"drop"`` stays the
#: default: on the unseen holdout 10 the two read alike (sun-lit MAE 0.072
#: and 0.073; 0.0381 and 0.0385 on the 11 sequences with clipped entries),
#: the likelihood at 1.4 times the time (studies/README.md).
CLIPPED = ("drop", "likelihood")
DEFAULT_CLIPPED = "drop"

#: Sweeps at most of the joint sampler where no ``max_steps`` is given (the
#: run stops earlier once converged; otherwise it is flagged ``not-converged``).
JOINT_MAX_SWEEPS = 2000

#: Step cap of each facet's own sampler given the object's illumination
#: (:func:`bayesgloss.sampling.facets_given_frames`).
FACETS_GIVEN_FRAMES_STEPS = 4000


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
    options = {"ground_reflectance": ground_reflectance}
    if sky.takes_day_of_year(illumination):  # a clear-sky irradiance: the date's sun distance
        options["day_of_year"] = np.asarray(b.times.day_of_year, dtype=float)
    return sky.daylight(illumination, b.sun_direction, **options)


def ground_of(illumination: str) -> str:
    """The ground the bases of ``illumination`` see: ``"sky"`` for the bare
    point sun (nothing but the sun), else ``"plane"`` (the bundle's ground
    at its reflectance; :func:`bayesgloss.render.facet_bases`)."""
    return "sky" if illumination == "point-sun" else "plane"


def joint_inputs(
    b,
    y,
    usable,
    censored,
    keep,
    illumination,
    fresnel="none",
    lobe_family=DEFAULT_LOBE_FAMILY,
    occluder_albedo=None,
    ground_shadow=DEFAULT_GROUND_SHADOW,
    clipped=DEFAULT_CLIPPED,
    jobs=1,
):
    """The joint model's data (:func:`bayesgloss.illumination.joint_data`) of
    the usable facets ``keep`` (a mask, or indices: taken in increasing
    order either way) and the frames any of them sees with the sun
    up, with the Fresnel model ``fresnel`` (:data:`bayesgloss.fresnel.FRESNEL_MODELS`),
    the glossy lobe's family ``lobe_family`` (:data:`bayesgloss.lobes.LOBE_FAMILIES`)
    and, for a bundle with an ``object_mesh``, its faces' albedo
    ``occluder_albedo`` (default :data:`bayesgloss.render.OCCLUDER_REFLECTANCE`;
    :mod:`bayesgloss.occluder_albedo`), and for one without, the object's
    shadow on the ground where ``ground_shadow`` is ``"convex"``
    (:mod:`bayesgloss.object_shadow`), and the clipped entries left out or
    kept as censored (``clipped``, :data:`CLIPPED`): (data, frames used (T,)
    of bool, sky model names). ``jobs``: worker processes for the bases
    (:func:`bayesgloss.illumination.illumination_bases`)."""
    clipped = check_clipped(clipped)
    which = np.zeros(len(b.facets), dtype=bool)
    which[keep] = True
    keep = np.flatnonzero(which)
    rho = b.ground_albedo
    names = AUTO_SKIES if illumination == "auto" else (illumination,)
    day, *others = (bundle_sky(b, name, rho) for name in names)
    ground = ground_of(illumination)
    measured = usable[keep] & ~censored[keep]
    used = measured.any(axis=0) & b.sun_up  # frames with a measured entry
    ok, clip = measured, None
    if clipped == "likelihood":  # the clipped entries too, as lower bounds
        ok, clip = usable[keep], censored[keep][:, used]
    geometry = b.view_geometry()
    # what a non-convex object's own mesh (object_mesh) hides from each facet
    mesh = {}
    if (occlusion := bundle_occlusion(b)) is not None:
        if occluder_albedo is not None:  # the map is the same: only its faces' albedo changes
            occlusion = occlusion.replace(occluder_reflectance=float(occluder_albedo))
        mesh["occlusion"] = occlusion
    owner = None
    mode = check_ground_shadow(ground_shadow)
    if convex_shadow_state(b.facets, mode, bool(mesh), ground) == "built":
        # points over the kept facets only; the object is bounded by all of them
        geometry, owner = shadow_points(b.facets, b.camera_position, which=which)
    bases = il.illumination_bases(
        geometry,
        day,
        others=others,
        lobe_family=lobe_family,
        fresnel="radiance" if fresnel == "none" else fresnel,
        ground=ground,
        ground_reflectance=rho,
        jobs=jobs,
        **mesh,
    )
    if owner is None:
        bases = bases.take(keep, used)
    else:  # points over each kept facet, averaged
        bases = averaged_bases(bases, owner, len(keep)).take(frames=used)
    exposure = None
    if b.exposure is not None:
        exposure = b.exposure[used]
    elif b.pixel_encoding == "linear-radiance":
        exposure = np.ones(int(used.sum()))
    data = il.joint_data(
        y[keep][:, used], ok[:, used], bases, exposure=exposure, fresnel=fresnel, censored=clip
    )
    return data, used, names


def check_clipped(clipped: str) -> str:
    """``clipped`` if it is one of :data:`CLIPPED`, else a ValueError naming them."""
    if clipped not in CLIPPED:
        raise ValueError(f"clipped entries: unknown treatment {clipped!r}; use one of {CLIPPED}")
    return clipped


def joint_max_sweeps(options: dict) -> int:
    """The joint sampler's cap of sweeps after burn-in for sampler options:
    ``max_sweeps``, else ``max_steps`` (a sweep of the joint sampler is its
    step), else :data:`JOINT_MAX_SWEEPS`."""
    return options.get("max_sweeps", options.get("max_steps", JOINT_MAX_SWEEPS))


def joint_fit(
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
    facets=True,
    resume=None,
    jobs=1,
):
    """The joint model of facets and per-frame illumination
    (:mod:`bayesgloss.illumination`) on the usable facets and the frames
    any of them sees: (idata, samples, frames used).

    ``facets=False`` leaves out each facet's own posterior given the
    object's illumination (:func:`add_facet_posteriors` adds it later: the
    stacked sky families need it of one fit only). ``resume``: the samples
    of a fit with the same arguments stopped at its cap unconverged, run on
    to ``options``' cap (:func:`bayesgloss.sampling.schedule.run_chain`).
    ``jobs``: worker processes for the bases (split by facets) and the
    sampler's groups of ensembles (the draws do not depend on it but for a
    matrix product's last bits: :func:`bayesgloss.illumination.illumination_bases`).
    """
    az = arviz()
    options = dict(options or {})
    fresnel = options.pop("fresnel", DEFAULT_FRESNEL)
    family = check_lobe_family(options.pop("lobe_family", DEFAULT_LOBE_FAMILY))
    albedo = options.pop("occluder_albedo", None)
    shadow = options.pop("ground_shadow", DEFAULT_GROUND_SHADOW)
    clipped = options.pop("clipped", DEFAULT_CLIPPED)
    data, used, names = joint_inputs(
        b, y, usable, censored, keep, illumination, fresnel, family, albedo, shadow, clipped, jobs
    )
    options["max_sweeps"] = joint_max_sweeps(options)
    options.pop("max_steps", None)
    allowed = {
        *("max_sweeps", "min_sweeps", "chunk", "burn_rounds"),
        *("n_walkers", "n_ensembles", "draws_per_ensemble"),
    }
    samples = sampling.sample_material(
        data,
        seed=seed,
        progress=progress,
        resume=None if resume is None else resume.run,
        jobs=jobs,
        **{k: v for k, v in options.items() if k in allowed},
    )
    rng = np.random.default_rng(seed)
    th = samples.draws.transpose(1, 0, 2, 3)  # (E, F, S, 4): gamma and n shared
    frames = samples.frames  # (E, S, T, L)
    ll = il.pointwise_log_likelihood(th, frames, data).transpose(0, 2, 1, 3)  # (E, S, F, T)
    pred = il.simulate(th, frames, data, rng).transpose(0, 2, 1, 3)
    hyper = samples.material  # (E, S, H): il.HYPER
    post = {
        "gamma_object": th[:, 0, :, 0],
        "n_object": np.exp(th[:, 0, :, 1]),
        "albedo_spread": np.exp(hyper[..., 1]),
        "sun_state_weight": np.exp(il.log_sun_weights(hyper)),
        "sun": np.exp(frames[..., 1]),
        "sky": np.exp(frames[..., 2]),
    }
    if data.log_exposure is None:
        post["exposure"] = np.exp(frames[..., 0])
    if hyper.shape[-1] > 4:  # the sd of the frames' log exposures about the day's
        post["exposure_spread"] = np.exp(hyper[..., 5])
    if family != "phong":  # the family's microfacet roughness (bayesgloss.lobes)
        post["roughness_object"] = roughness_of_exponent(post["n_object"])
    if data.fresnel is not None:  # the Fresnel raise's strength and normal-incidence albedo
        k_col, a_col = FRESNEL_COLUMNS
        post["fresnel_strength"] = th[:, 0, :, k_col]
        post["normal_albedo"] = np.exp(th[:, 0, :, a_col])
    dims = {
        **{v: ["frame"] for v in ("sun", "sky", "exposure")},
        "sun_state_weight": ["sun_state"],
        "y": ["facet", "frame"],
    }
    coords = {
        "facet": curves.ids[keep],
        "frame": np.flatnonzero(used),
        "sun_state": ["clear", "dimmed", "hidden"],
    }
    if data.shapes >= 2:  # each frame's weights of the sky models
        post["sky_weight"] = np.exp(il.log_shape_weights(frames))
        dims["sky_weight"] = ["frame", "sky_model"]
        coords["sky_model"] = list(names)
    # each draw's log posterior density (up to a constant), sigma at its draw
    lp = np.nansum(ll, axis=(2, 3)) + il.log_prior_material(th, hyper, data)
    lp += il.log_prior_frames(
        frames, data, il.log_sun_weights(hyper), exposure=il.exposure_day(hyper)
    ).sum(-1)
    samples.data = data
    samples.facets = None
    idata = az.from_dict(
        posterior=post,
        log_likelihood={"y": ll},
        posterior_predictive={"y": pred},
        observed_data={"y": np.where(data.valid, data.y, np.nan)},
        sample_stats={"lp": lp},
        coords=coords,
        dims=dims,
    )
    idata.posterior.attrs["fresnel"] = fresnel
    idata.posterior.attrs["lobe_family"] = family
    idata.posterior.attrs["ground_shadow"] = shadow
    idata.posterior.attrs["clipped"] = clipped
    if albedo is not None:
        idata.posterior.attrs["occluder_albedo"] = float(albedo)
    idata.observed_data["valid"] = (("facet", "frame"), data.valid)
    idata.observed_data["censored"] = (("facet", "frame"), censored[keep][:, used])
    idata.observed_data["time"] = (
        ("frame",),
        b.times[used].tz_convert("UTC").tz_localize(None),
    )
    if facets:
        add_facet_posteriors(idata, samples, seed, jobs)
    return idata, samples, used


def add_facet_posteriors(idata, samples, seed, jobs: int = 1) -> None:
    """Each facet's own posterior given the object's illumination draws
    (:func:`bayesgloss.sampling.facets_given_frames`) into ``idata``'s
    posterior (``gamma``, ``n``, ``s``, ``sigma`` per facet) and its run
    into ``samples.facets``; ``jobs`` worker processes share the facet
    sampler's streams (the draws do not depend on it)."""
    with process_pool(jobs) if jobs > 1 else contextlib.nullcontext() as pool:
        facet_draws, facet_run = sampling.facets_given_frames(
            samples.data, samples.frames, seed=seed, max_steps=FACETS_GIVEN_FRAMES_STEPS, pool=pool
        )
    fd = facet_draws.transpose(1, 2, 0, 3)  # (E, S', F, 4)
    values = {"gamma": fd[..., 0], "n": np.exp(fd[..., 1]), "s": np.exp(fd[..., 2])}
    values["sigma"] = np.exp(fd[..., 3])
    for name, v in values.items():
        idata.posterior[name] = (("chain", "draw", "facet"), v)
    # the facets' ids (the label image's values), as the observations have
    # them: the posterior had no facet variable to carry them before these
    idata.posterior = idata.posterior.assign_coords(facet=idata.observed_data["facet"].values)
    samples.facets = facet_run


def frame_convergence(samples, n_frames: int) -> np.ndarray:
    """Whether each frame's sun and sky latents met the stopping rule
    (:func:`bayesgloss.diagnostics.meets_rule`), (T,) of bool, from the
    run's own statistics (:class:`~bayesgloss.sampling.schedule.JointSamples`:
    ``rhat``, ``ess_bulk``, ``ess_tail`` end with each frame's log a, then
    each frame's log b)."""
    k = len(samples.rhat) - 2 * n_frames
    ok = diagnostics.meets_rule(samples.rhat[k:], samples.ess_bulk[k:], samples.ess_tail[k:])
    return ok[:n_frames] & ok[n_frames:]


def object_convergence(samples, used) -> dict:
    """What kept a joint run from converging: the object's gamma's R-hat
    and ESS (the first of the run's statistics) and whether they meet the
    rule, and the frames (indices in the bundle; ``used`` the run's frames)
    whose sun or sky did not. A run is flagged ``not-converged`` when
    either fails; most renders' runs that stop at the cap fail on frames the
    data barely inform, not on gloss (``studies/README.md``, stop 41)."""
    frames = np.flatnonzero(used)
    conv = frame_convergence(samples, len(frames))
    r, eb, et = (float(x[0]) for x in (samples.rhat, samples.ess_bulk, samples.ess_tail))
    return {
        "gamma": {
            "rhat": r,
            "ess_bulk": eb,
            "ess_tail": et,
            "meets_rule": bool(diagnostics.meets_rule(r, eb, et)),
        },
        "frames_not_converged": [int(t) for t in frames[~conv]],
    }


def frame_summary(idata, b, used, samples=None) -> list:
    """Each frame's inferred sun, sky (relative to the sky model's) and
    exposure; with the run's ``samples``, whether its sun and sky met the
    stopping rule (``converged``)."""
    conv = None if samples is None else frame_convergence(samples, int(np.sum(used)))
    out = []
    for j, t in enumerate(np.flatnonzero(used)):
        entry = {"frame": int(t), "time": b.times[t].isoformat()}
        if conv is not None:
            entry["converged"] = bool(conv[j])
        for v in ("sun", "sky", "exposure"):
            if v in idata.posterior:
                entry[v] = posterior_quantiles(idata.posterior[v].values[..., j])
        if "sky_weight" in idata.posterior:
            weights = idata.posterior["sky_weight"]
            entry["sky_weight"] = {
                str(name): posterior_quantiles(weights.values[..., j, k])
                for k, name in enumerate(weights["sky_model"].values)
            }
        out.append(entry)
    return out


#: A frame's sun is not identified where its 90 % interval (equal-tailed,
#: relative to the sky model's sun) runs from below ``SUN_HIDDEN`` (a sun
#: cut to a tenth, or hidden) to above ``SUN_SHOWN`` (half the model's or
#: more): the curves do not say whether it shone.
SUN_HIDDEN, SUN_SHOWN = 0.1, 0.5
#: More than this share of the frames' suns not identified flags the
#: object ``sun-not-identifiable``. On the seen holdouts' scores (23 sets,
#: 393 sun-lit objects, stop 63; ``studies/sun_flag_seen.py``) the flagged
#: sun-lit objects read MAE 0.183 and their intervals held 27 of 37, the
#: others 0.064 and 329 of 356; 109 of 125 sunless days are flagged
#: (studies/README, "Stop 63: a flag where the sun is not identified").
SUN_UNIDENTIFIED_SHARE = 0.5


def sun_not_identified(q05, q95) -> np.ndarray:
    """Whether each frame's sun is not identified, from its 5 and 95 %
    quantiles relative to the sky model's sun (:data:`SUN_HIDDEN`,
    :data:`SUN_SHOWN`)."""
    return (np.asarray(q05, float) < SUN_HIDDEN) & (np.asarray(q95, float) > SUN_SHOWN)


def sun_flags(idata) -> tuple[float | None, list[str]]:
    """The share of frames whose sun is not identified (:data:`SUN_HIDDEN`,
    :data:`SUN_SHOWN`) and the object's flag ``sun-not-identifiable`` where
    it exceeds :data:`SUN_UNIDENTIFIED_SHARE`; (None, []) without per-frame
    suns. Frames are those of the posterior's ``sun`` (the sun up, a
    measured entry)."""
    if "sun" not in idata.posterior or idata.posterior["sun"].shape[-1] == 0:
        return None, []
    sun = idata.posterior["sun"].values
    lo, hi = np.quantile(sun.reshape(-1, sun.shape[-1]), [0.05, 0.95], axis=0)
    share = float(np.mean(sun_not_identified(lo, hi)))
    return share, ["sun-not-identifiable"] if share > SUN_UNIDENTIFIED_SHARE else []


def sky_model_summary(idata) -> dict | None:
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

"""Posterior gloss of a sequence bundle: per facet, and for the object.

:func:`estimate_bundle` reads a bundle's facet curves, computes the
forward-model bases for the chosen illumination model, samples every
facet's posterior (:func:`bayesgloss.sampling.sample_posterior`), checks
convergence with ArviZ (R-hat < 1.01, bulk and tail ESS >= 400 for gamma;
otherwise the facet is flagged ``"not-converged"``, never silently
reported), and returns an :class:`arviz.InferenceData` with groups
``posterior``, ``log_likelihood`` (per facet and frame), ``observed_data``,
``posterior_predictive`` and ``sample_stats``, plus a JSON-ready summary.

With per-frame illumination (the default), the object's answer is the
one-material model's (:func:`bayesgloss.sampling.sample_material`): one
gamma and n for every facet, each facet's albedo from a log-normal
population of spread tau, every frame's sun, sky and sky shape (and
exposure) inferred with them; the posterior groups hold ``gamma_object``,
``n_object``, ``albedo_spread`` (tau), ``sun_state_weight`` (the day's
clear, dimmed and hidden sun) and ``exposure_spread`` (the frames' log
exposures' sd about the day's, where unknown). Each facet's own posterior
(``gamma``...) is its sampler's given the object's illumination, averaged
over it (:func:`bayesgloss.sampling.facets_given_frames`). Where no sky is named,
that model is fitted under each sky family of :mod:`bayesgloss.sky_families`
and the fits stacked by PSIS-LOO; the glossy lobe likewise under the
most-weighted family (``lobe="materials"``, :mod:`bayesgloss.lobe_families`).
Not a facet population's mu: on overcast days the facets' posteriors share
the frames, and their product read confident answers the data did not hold.

With fixed brightness (``per_frame=False``, :mod:`bayesgloss.facets_estimate`)
the facets are sampled on their own and pooled by :mod:`bayesgloss.pooling`
(``population``, ``shared``; ``mean``, the paper's average of facets).

Illumination models (``illumination=``, :data:`ILLUMINATION_MODELS`): the
sky models of :func:`bayesgloss.sky.sky_models` (``"point-sun"``, the
paper's sun with no sky; gensky's clear, intermediate, overcast and uniform
skies; the 15 CIE general skies; Perez).

A facet needs at least :data:`MIN_FRAMES` usable frames, two of them
measured (a saturated entry enters as a lower bound only); a bundle in which
no facet has them (every frame at night, a single frame, every pixel
saturated) is rejected with :class:`bayesgloss.bundle.NoUsableData`, which
says how many frames have the sun up and how many entries saturate.

The summary (:func:`bayesgloss.summary.summarise_estimate`) reports the
gamma of the object and of each facet with the model's error of the
material's gloss, the model's own posterior beside it as
``gamma_within_model``, and its flags (``not-converged``,
``gloss-not-identifiable``, ``mostly-saturated``; a facet left out
``too-few-frames``, ``saturated`` or ``faces-ground``).

:func:`estimate_unit` is one bundle's estimate as files
(:func:`result_files`), the unit of work that
:func:`bayesgloss.runner.run_units` fans out over many bundles;
:func:`~bayesgloss.results.write_result` and :func:`~bayesgloss.results.read_result`
(:mod:`bayesgloss.results`, re-exported here) write and read a result folder.
"""

from __future__ import annotations

import functools

import numpy as np

from . import bundle as bundle_io
from . import lobe_families, sky_families
from .facets_estimate import ILLUMINATION_MODELS, bundle_bases, facets_fit, to_inference_data
from .fresnel import check_fresnel_model
from .ground_facing import DEFAULT_GROUND_FACING, leave_out_ground_facing
from .irradiance import measured_sky
from .joint_estimate import (
    DEFAULT_CLIPPED,
    DEFAULT_FRESNEL,
    bundle_sky,
    check_clipped,
    ground_of,
    joint_fit,
)
from .object_shadow import check_ground_shadow, convex_shadow_state, default_ground_shadow
from .occluder_albedo import (
    DEFAULT_OCCLUDER_ALBEDO,
    check_occluder_albedo_mode,
    fit_occluder_albedos,
)
from .results import (
    RESULT_FILES,
    EstimateResult,
    check_result_folder,
    read_result,
    result_files,
    write_result,
)
from .summary import MODEL_ERROR_STREAM, NOT_IDENTIFIABLE_WIDTH, summarise_estimate
from .visibility import shadow_flags

__all__ = [
    "RESULT_FILES",
    "check_result_folder",
    "result_files",
    "write_result",
    "read_result",
    "ILLUMINATION_MODELS",
    "MIN_FRAMES",
    "NOT_IDENTIFIABLE_WIDTH",
    "MODEL_ERROR_STREAM",
    "estimate_unit",
    "default_illumination",
    "bundle_bases",
    "bundle_sky",
    "observations",
    "bundle_curves",
    "EstimateResult",
    "estimate_bundle",
    "to_inference_data",
]

#: Usable frames a facet's curve needs at least.
MIN_FRAMES = 4


def bundle_curves(b) -> bundle_io.FacetCurves:
    """A bundle's facet curves (:func:`bayesgloss.bundle.facet_curves`), with
    the shadows of its ``object_mesh`` flagged where it has one
    (:func:`bayesgloss.visibility.shadow_flags`).

    Entries partly in the mesh's shadow (``partly-shadowed``: their pixels
    mix lit and shadowed surface) are flagged and so left out of the
    likelihood. Entries wholly in sun or wholly in the mesh's shadow are kept: the forward model
    (:func:`bundle_bases`, :func:`bayesgloss.joint_estimate.joint_inputs`)
    takes the mesh's :func:`bayesgloss.visibility.bundle_occlusion`, so a
    kept entry's sun is its sunlit fraction (1 or 0 to within 0.02) and the
    sky and ground the mesh hides are replaced by the light of the mesh's
    faces. Partly shadowed entries stay out (:mod:`bayesgloss.visibility`:
    the pixel summary of a facet half in shadow follows its lit and shadowed
    pixels' shares as the labels and the statistic weigh them, not the
    facet's area). A bundle without ``object_mesh`` gets exactly
    :func:`facet_curves`'s result.
    """
    return shadow_flags(b, bundle_io.facet_curves(b))


def observations(curves) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(y, usable, censored) from a bundle's facet curves.

    Entries flagged only ``saturated`` enter as censored, at the facet's
    statistic with its saturated pixels at the top code
    (:attr:`bayesgloss.bundle.FacetCurves.lower_bound`), a lower bound of
    its true value, also where every pixel of the facet saturates. Every
    other flag leaves the entry out (also ``partly-shadowed``, set by
    :func:`bundle_curves` from an ``object_mesh``).
    """
    sat_bit = 1 << bundle_io.FLAG_REASONS.index("saturated")
    only_saturated = curves.flag_bits == sat_bit
    censored = only_saturated & np.isfinite(curves.lower_bound)
    usable = curves.valid | censored
    y = np.where(censored, curves.lower_bound, curves.luminance)
    return np.where(usable, y, 0.0), usable, censored


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
    where the bundle measures every frame with the sun up, else
    ``"families"`` (:mod:`bayesgloss.sky_families`) where the joint model
    applies and ``"gensky-clear"`` where it does not."""
    if measured_sky(b, b.ground_albedo) is not None:
        return "measured"
    return "families" if _joint_possible(per_frame, noise, _camera(b, camera)) else "gensky-clear"


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
    fresnel: str | None = None,
    lobe: str | None = None,
    occluder_albedo: str | None = None,
    ground_facing: str | None = None,
    overcast_variants: bool | None = None,
    perez_families: bool | None = None,
    unreliable_loo: str = "equal",
    ground_shadow: str | None = None,
    clipped: str | None = None,
) -> EstimateResult:
    """Posterior gloss of every facet of a bundle, and of the object.

    Parameters
    ----------
    path : path or bundle.Bundle
    illumination : str, optional
        The sky's shape: one of :data:`ILLUMINATION_MODELS`; ``"measured"``,
        the Perez sky of the bundle's ``frames[].irradiance``; or ``"auto"``
        (with ``per_frame`` only: each frame's sky a mixture of
        :data:`AUTO_SKIES`, its weights inferred); or ``"families"`` (with
        ``per_frame`` only: one fit per day-level family of
        :data:`bayesgloss.sky_families.FAMILIES`, stacked by PSIS-LOO,
        :mod:`bayesgloss.sky_families`). Default: ``"measured"``
        where the bundle measures every frame with the sun up, else
        ``"families"`` with ``per_frame`` and ``"gensky-clear"`` without.
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
    fresnel : {"none", "radiance", "schlick"}, optional
        The one-material model's Fresnel model (:mod:`bayesgloss.fresnel`;
        per-frame illumination only); default
        :data:`bayesgloss.joint_estimate.DEFAULT_FRESNEL`.
    lobe : {"phong", "ward", "ggx", "families", "materials"}, optional
        The glossy lobe's family (:mod:`bayesgloss.lobes`; per-frame
        illumination only), or ``"families"``: one fit per family, stacked
        by PSIS-LOO (:mod:`bayesgloss.lobe_families`), or ``"materials"``:
        those and GGX with Schlick's Fresnel
        (:data:`bayesgloss.lobe_families.MATERIAL_FAMILIES`; ``fresnel``
        must then be left at its default); default
        :func:`bayesgloss.lobe_families.default_lobe` (``"materials"``
        where it applies, else ``"phong"``).
    occluder_albedo : {"fixed", "stacked"}, optional
        For a bundle with an ``object_mesh`` (per-frame illumination only):
        its faces' albedo fixed at :data:`bayesgloss.render.OCCLUDER_REFLECTANCE`,
        or one fit per albedo of :data:`bayesgloss.occluder_albedo.OCCLUDER_ALBEDOS`
        stacked by PSIS-LOO (:mod:`bayesgloss.occluder_albedo`); default
        :data:`bayesgloss.occluder_albedo.DEFAULT_OCCLUDER_ALBEDO`, and
        ``"fixed"`` with ``lobe="families"`` or ``"materials"`` (one stack at a time; asking for
        both is an error). Without a mesh it changes nothing.
    ground_facing : {"leave-out", "keep"}, optional
        Facets facing the ground in a bundle without an ``object_mesh``
        (:mod:`bayesgloss.ground_facing`): left out, flagged
        ``faces-ground`` (unless no other facet is usable), or kept; default
        :data:`bayesgloss.ground_facing.DEFAULT_GROUND_FACING`.
    overcast_variants : bool, optional
        With the sky families: :data:`~.sky_families.OVERCAST_VARIANTS` too, types 2 and 4 in
        the first stack, the rest where an overcast shape wins (None: sky_families' default).
    perez_families : bool, optional
        With the sky families: also :data:`~bayesgloss.sky_families.PEREZ_FAMILIES`
        (:func:`~bayesgloss.sky_families.perez_families_for`; default: yes).
    unreliable_loo : {"equal", "stack"}
        With the sky families, where the stacking weights rest on unreliable
        PSIS-LOO: equal weights, the default (flagged
        ``sky-family-not-identifiable``;
        :func:`bayesgloss.sky_families.equal_when_unreliable`), or kept
        (flagged ``loo-unreliable``).
    ground_shadow : {"none", "convex"}, optional
        Without an ``object_mesh`` (per-frame illumination only): the
        ground sunlit everywhere, or the shadow of the convex object its
        facets bound (:mod:`bayesgloss.object_shadow`); default
        :func:`bayesgloss.object_shadow.default_ground_shadow` (``"convex"``
        with per-frame illumination, ``"none"`` without).
    clipped : {"drop", "likelihood"}, optional
        Entries clipped at the top code: left out of the joint model, or
        lower bounds (:mod:`bayesgloss.sampling.censored`); default
        :data:`bayesgloss.joint_estimate.DEFAULT_CLIPPED`.
    jobs : int
        Local worker processes for the sampler (:func:`bayesgloss.pool.process_pool`).
    sampler_options : dict, optional
        More keyword arguments for :func:`~bayesgloss.sampling.sample_posterior`
        (``max_steps``...); for the joint sampler ``max_steps`` caps its
        sweeps (default :data:`JOINT_MAX_SWEEPS`), ``burn_rounds``,
        ``chunk`` and ``min_sweeps`` set its schedule
        (:func:`~bayesgloss.sampling.sample_material`), and with the sky
        families ``screen_families=False`` runs every family in full
        (:func:`~bayesgloss.sky_families.fit_families`).

    Raises
    ------
    bayesgloss.bundle.NoUsableData
        Where no facet has :data:`MIN_FRAMES` usable frames.
    """
    b = path if isinstance(path, bundle_io.Bundle) else bundle_io.read_bundle(path)
    sampler_options = {k: v for k, v in (sampler_options or {}).items() if v is not None}
    fresnel = check_fresnel_model(fresnel or DEFAULT_FRESNEL)
    curves = bundle_curves(b)
    camera = _camera(b, camera)
    y, usable, censored = observations(curves)
    keep = bundle_io.usable_facets(b, usable, MIN_FRAMES, censored)
    keep, facing = leave_out_ground_facing(b, keep, ground_facing or DEFAULT_GROUND_FACING)
    joint = _joint_possible(per_frame, noise, camera)
    if illumination is None:
        illumination = default_illumination(b, per_frame=per_frame, noise=noise, camera=camera)
    if illumination in ("auto", "families") and not joint:
        raise ValueError(
            f"illumination '{illumination}' (sky shapes inferred) needs per-frame "
            "illumination (relative noise and a known pixel response); name a sky model"
        )
    perez_families = sky_families.perez_families_for(illumination, perez_families)
    lobe = lobe or lobe_families.default_lobe(joint, fresnel, b.has_mesh, illumination)
    lobe, lobe_stacked = lobe_families.check_lobe(lobe, fresnel, joint)
    shadow = check_ground_shadow(ground_shadow or default_ground_shadow(joint))
    if shadow != "none" and not joint:
        raise ValueError(f"ground shadow '{shadow}' needs per-frame illumination")
    shadow_state = convex_shadow_state(b.facets, shadow, b.has_mesh, ground_of(illumination))
    clipped = check_clipped(clipped or DEFAULT_CLIPPED)
    if joint:
        sampler_options["fresnel"] = fresnel
        sampler_options["ground_shadow"] = shadow
        sampler_options["clipped"] = clipped
        if not lobe_stacked:
            sampler_options["lobe_family"] = lobe
    if occluder_albedo is None:  # the lobe families' stack keeps the faces at one albedo
        occluder_albedo = "fixed" if lobe_stacked else DEFAULT_OCCLUDER_ALBEDO
    occluder = check_occluder_albedo_mode(occluder_albedo)
    stack_occluder = occluder == "stacked" and joint and b.has_mesh
    if stack_occluder and lobe_stacked:
        raise ValueError(
            f"occluder albedo 'stacked' and lobe '{lobe}' each fit and stack several "
            "models; name a lobe, or fix the occluder albedo"
        )
    # a part of the model fitted once per choice and stacked: (fitter, what, summary key)
    stacked = None
    if stack_occluder:
        stacked = fit_occluder_albedos, "occluder albedo", "occluder_albedos"
    elif lobe_stacked:
        fit = functools.partial(lobe_families.fit_lobe_families, materials=lobe == "materials")
        stacked = fit, "lobe family", "lobe_families"
    families = part = None
    if stacked is not None:
        fit, what, key = stacked
        data = (b, curves, y, usable, censored, keep, illumination, seed, sampler_options)
        idata, samples, used, info = fit(
            *data,
            progress,
            jobs,
            overcast_variants=overcast_variants,
            unreliable_loo=unreliable_loo,
            perez_families=perez_families,
        )
        families = info.pop("sky_families", None)
        part = key, info[key]
        run = {
            "seconds": info.pop("seconds"),
            "sweeps": samples.n_sweeps,
            "facet_seconds": samples.facets.seconds,
            "model": f"joint, one fit per {what} (and sky family), stacked",
        }
    elif illumination == "families":
        data = (b, curves, y, usable, censored, keep, seed, sampler_options, progress, jobs)
        idata, samples, used, families = sky_families.fit_families(
            *data,
            overcast_variants=overcast_variants,
            unreliable_loo=unreliable_loo,
            perez_families=perez_families,
        )
        run = {
            "seconds": families.pop("seconds"),
            "sweeps": samples.n_sweeps,
            "facet_seconds": samples.facets.seconds,
            "model": "joint, one fit per sky family, stacked",
        }
    elif joint:
        idata, samples, used = joint_fit(
            *(b, curves, y, usable, censored, keep, illumination, seed, sampler_options),
            progress,
            jobs=jobs,
        )
        run = {
            "seconds": samples.seconds + samples.facets.seconds,
            "sweeps": samples.n_sweeps,
            "facet_seconds": samples.facets.seconds,
            "model": "joint",
        }
    else:
        idata, samples = facets_fit(
            *(b, curves, y, usable, censored, keep, illumination, noise, camera, seed),
            *(jobs, progress, sampler_options),
        )
        used = None
        run = {
            "seconds": samples.seconds,
            "median_steps": float(np.median(samples.n_steps)),
            "model": "facets"
            if not per_frame
            else "facets (per-frame illumination needs relative noise and a known pixel response)",
        }
    out = summarise_estimate(
        *(b, curves, keep, idata, samples, illumination, noise, camera, seed, used, run, facing),
        usable=usable,
        censored=censored,
        min_frames=MIN_FRAMES,
    )
    if shadow_state == "not-built":  # one wall seen, or parallel walls only
        out.summary["object"]["flags"].append("ground-shadow-not-built")
    if families is not None:
        out.summary["sky_families"] = families
        out.summary["object"]["flags"] += sky_families.stack_flags(families)
    if part is not None:  # each choice's weight, LOO and own gloss
        out.summary[part[0]] = part[1]
        if not info["stacked"]:  # the default choice alone (fit_stacked: why)
            out.summary["object"]["flags"].append(f"{what.replace(' ', '-')}-not-stacked")
    return out


def estimate_unit(
    bundle: str,
    illumination: str | None = "gensky-clear",
    noise: str = "relative",
    camera: str = "auto",
    seed: int = 0,
    max_steps: int | None = 8000,
    per_frame: bool = False,
    bundle_content: str | None = None,
    fresnel: str | None = None,
    lobe: str | None = None,
    occluder_albedo: str | None = None,
    ground_facing: str | None = None,
    overcast_variants: bool | None = None,
    perez_families: bool | None = None,
    unreliable_loo: str = "equal",
    ground_shadow: str | None = None,
    clipped: str | None = None,
) -> dict[str, bytes]:
    """One bundle's estimate as files: ``summary.json`` and ``posterior.nc``.

    The unit of work of :func:`bayesgloss.runner.run_units` over many
    bundles; it runs in one process (parallelism is across units), so the
    result is the same whatever executor runs it. ``bundle_content``, the
    bundle's :func:`~bayesgloss.bundle.bundle_digest` when the run was
    planned, makes the unit's key follow the bundle's content (a bundle
    whose frames were replaced is a new unit, not a finished one); a bundle
    changed since is an error. ``fresnel``, ``lobe``, ``occluder_albedo``,
    ``ground_facing``, ``overcast_variants``, ``perez_families``, ``unreliable_loo`` and
    ``ground_shadow`` and ``clipped``: as :func:`estimate_bundle`'s
    (given in a unit's options only where set, so that other runs keep
    their units' keys).
    """
    b = bundle_io.read_bundle(bundle)
    if bundle_content is not None and bundle_io.bundle_digest(b) != bundle_content:
        raise ValueError(
            f"bundle '{bundle}' changed while the run was under way (its manifest, labels or "
            "frames differ from when the run started): run again"
        )
    res = estimate_bundle(
        b,
        illumination=illumination,
        noise=noise,
        camera=camera,
        per_frame=per_frame,
        seed=seed,
        jobs=1,
        sampler_options={"max_steps": max_steps},
        fresnel=fresnel,
        lobe=lobe,
        occluder_albedo=occluder_albedo,
        ground_facing=ground_facing,
        overcast_variants=overcast_variants,
        perez_families=perez_families,
        unreliable_loo=unreliable_loo,
        ground_shadow=ground_shadow,
        clipped=clipped,
    )
    return result_files(res)

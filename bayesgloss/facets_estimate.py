"""The fixed-brightness estimate: every facet sampled on its own under a sky model's light.

``estimate --fixed-brightness`` (:func:`bayesgloss.estimate.estimate_bundle`
with ``per_frame=False``, and wherever the joint model of per-frame
illumination does not apply: noise models other than relative, a power-law
camera response): each frame's sun and sky brightness are the sky model's
(:func:`bundle_bases`), every facet's posterior is sampled independently
(:func:`bayesgloss.sampling.sample_posterior`, :func:`facets_fit`) and
gathered in an :class:`arviz.InferenceData` (:func:`to_inference_data`).
"""

from __future__ import annotations

import numpy as np

from . import likelihood as lk
from . import render, sampling
from ._thirdparty import arviz
from .joint_estimate import bundle_sky, ground_of
from .pool import process_pool
from .sky import sky_models
from .visibility import bundle_occlusion

__all__ = ["ILLUMINATION_MODELS", "bundle_bases", "facets_fit", "to_inference_data"]

#: Illumination models: every sky model of :func:`bayesgloss.sky.sky_models`.
ILLUMINATION_MODELS = sky_models()


def bundle_bases(
    b, illumination: str = "gensky-clear", *, exponents=render.DEFAULT_EXPONENTS, occluder=None
) -> render.FacetBases:
    """Forward-model bases of a bundle's facets under an illumination model.

    The sky model sees the bundle's ground reflectance (0.2 if absent) and a
    ground plane (``"point-sun"``: nothing but the sun); where the bundle has
    ``object_mesh``, the bases take what it hides from each facet
    (:func:`bayesgloss.visibility.bundle_occlusion`).
    """
    if illumination not in (*ILLUMINATION_MODELS, "measured"):
        raise ValueError(
            f"unknown illumination {illumination!r}; valid: {', '.join(ILLUMINATION_MODELS)}, "
            "measured"
        )
    rho = b.ground_albedo
    day = bundle_sky(b, illumination, rho)
    ground = ground_of(illumination)
    return render.facet_bases(
        b.view_geometry(occluder),
        day,
        exponents,
        ground=ground,
        ground_reflectance=rho,
        occlusion=bundle_occlusion(b),  # None without object_mesh
    )


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


def facets_fit(
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

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
  sample size (:func:`population_gloss`), a two-parameter density
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
:class:`NoUsableData`, which says how many frames have the sun up.

:func:`estimate_unit` is one bundle's estimate as files, the unit of work
that :func:`bayesgloss.runner.run_units` fans out over many bundles.
"""

from __future__ import annotations

import functools
import json
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy import special

from . import bundle as bundle_io
from . import diagnostics, render, sampling, sky
from . import likelihood as lk
from ._thirdparty import arviz
from .pool import process_pool

__all__ = [
    "ILLUMINATION_MODELS",
    "MIN_FRAMES",
    "NoUsableData",
    "usable_facets",
    "estimate_unit",
    "bundle_bases",
    "observations",
    "EstimateResult",
    "estimate_bundle",
    "to_inference_data",
    "convergence",
    "population_gloss",
    "shared_gloss",
]

#: Illumination models: every sky model of :func:`bayesgloss.sky.sky_models`.
ILLUMINATION_MODELS = sky.sky_models()
#: Usable frames a facet's curve needs at least.
MIN_FRAMES = 4


NoUsableData = bundle_io.NoUsableData


def bundle_bases(
    b, illumination: str = "gensky-clear", *, exponents=render.DEFAULT_EXPONENTS, occluder=None
) -> render.FacetBases:
    """Forward-model bases of a bundle's facets under an illumination model.

    The sky model sees the bundle's ground reflectance (0.2 if absent) and a
    ground plane (``"point-sun"``: nothing but the sun).
    """
    if illumination not in ILLUMINATION_MODELS:
        raise ValueError(
            f"unknown illumination {illumination!r}; valid: {', '.join(ILLUMINATION_MODELS)}"
        )
    rho = 0.2 if b.ground_reflectance is None else float(b.ground_reflectance)
    day = sky.daylight(illumination, b.sun_direction, ground_reflectance=rho)
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


def usable_facets(b, usable, min_frames: int = MIN_FRAMES) -> np.ndarray:
    """Facets with at least ``min_frames`` usable frames
    (:func:`bayesgloss.bundle.usable_facets`)."""
    return bundle_io.usable_facets(b, usable, min_frames)


@dataclass
class EstimateResult:
    """What :func:`estimate_bundle` found."""

    idata: object
    summary: dict
    samples: sampling.PosteriorSamples = field(repr=False)


def convergence(idata) -> dict:
    """R-hat and bulk/tail ESS of gamma per facet, and whether each converged
    (the rule of :mod:`bayesgloss.diagnostics`)."""
    gamma = np.moveaxis(idata.posterior["gamma"].values, -1, 0)  # (F, E, S)
    rhat, ess_bulk, ess_tail = diagnostics.rank_diagnostics(gamma)
    ok = diagnostics.converged(gamma)
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


def population_gloss(
    gamma_draws,
    *,
    ess=None,
    seed=0,
    n_mu: int = 299,
    n_kappa: int = 80,
    n_bins: int = 400,
    max_draws: int = 1000,
    n_out: int = 4000,
):
    """Hierarchical Beta population of facet gammas (module docstring).

    Facet f's gammas are drawn from Beta(mu kappa, (1 - mu) kappa); its data
    enter through its posterior of gamma under the uniform prior it was
    sampled with, so that (Hogg, Myers & Bovy 2010, eq. 11)

        p(mu, kappa | data) ~ p(mu, kappa) prod_f int Beta(g; mu kappa, (1 - mu) kappa) p_f(g) dg.

    Each facet posterior p_f is a Gaussian kernel density of its draws,
    reflected at 0 and 1, whose bandwidth follows Scott's rule with the
    draws' *effective* sample size (h = 1.06 sd ESS^(-1/5)): a density of
    autocorrelated draws then has no more bumps than its information
    supports. (The earlier estimator, a mean of the Beta density over 200
    draws, read the clumps of autocorrelated draws from 24 flat posteriors
    as a population: intervals as narrow as 0.42 where the answer is the
    prior's.) The integral is a sum over ``n_bins`` bins of the kernel
    density's mass times the Beta distribution's mass in each bin, exact for
    a density constant on the bins; so flat facet posteriors give exactly
    the prior's likelihood, 1. The bins, and the cells of mu, are finer near
    0 and 1 (:func:`_cell_edges`: the 400 bins about 0.004 wide in the
    middle and 1.5e-5 at the ends, the 299 cells of mu 0.005 and 3e-5),
    where the posteriors of matt and mirror-like facets are sharpest. The two
    population parameters are integrated on a grid (mu in those cells,
    under a uniform prior; log kappa uniform over [log 0.5, log 1e4]); draws
    are taken from the grid posterior with jitter inside each cell.

    Parameters
    ----------
    gamma_draws : array_like (F, S)
        Posterior draws of each facet's gamma under a uniform prior (at most
        ``max_draws`` per facet are used, evenly spaced) [-].
    ess : array_like (F,), optional
        Effective sample size of each facet's draws (default S: independent
        draws) [-].
    seed : int or Generator
    n_mu, n_kappa : int
        Cells of mu (finer toward 0 and 1) and nodes of log kappa.
    n_bins : int
        Bins of gamma on which each facet's density is integrated.

    Returns
    -------
    dict
        ``mu`` and ``kappa`` draws.
    """
    rng = np.random.default_rng(seed)
    g = np.clip(np.asarray(gamma_draws, dtype=float), 0.0, 1.0)
    n_f, n_s = g.shape
    n_eff = np.full(n_f, float(n_s)) if ess is None else np.asarray(ess, dtype=float)
    n_eff = np.clip(np.nan_to_num(n_eff, nan=2.0), 2.0, n_s)
    h = np.maximum(1.06 * np.std(g, axis=1) * n_eff ** (-0.2), 1e-6)
    if n_s > max_draws:
        g = g[:, np.linspace(0, n_s - 1, max_draws).round().astype(int)]
    edges = _cell_edges(n_bins)
    mass = np.empty((n_f, n_bins))
    for f in range(n_f):  # one facet at a time bounds memory (draws x bins)
        x = g[f]
        cdf = sum(
            special.ndtr((edges[:, None] - r[None, :]) / h[f]) for r in (x, -x, 2.0 - x)
        ).mean(axis=1)  # reflected kernels: the mass below each edge
        mass[f] = np.maximum(np.diff(cdf), 0.0)  # rounding can make far tails negative
    mass /= mass.sum(axis=1, keepdims=True)
    lkap, beta_mass = _beta_bin_masses(n_mu, n_kappa, n_bins)  # (n_mu n_kappa, n_bins)
    density = mass.T / np.diff(edges)[:, None]  # (n_bins, F)
    with np.errstate(divide="ignore"):
        logp = np.log(beta_mass @ density).sum(axis=1).reshape(n_mu, n_kappa)
    mu_edges = _cell_edges(n_mu)
    logp += np.log(np.diff(mu_edges))[:, None]  # uniform prior: each mu cell's width
    w = np.exp(logp - logp.max()).ravel()
    w /= w.sum()
    pick = rng.choice(len(w), size=n_out, p=w)
    i, j = np.unravel_index(pick, (n_mu, n_kappa))
    dk = lkap[1] - lkap[0]
    mu_s = mu_edges[i] + np.diff(mu_edges)[i] * rng.random(n_out)
    k_s = np.exp(lkap[j] + dk * (rng.random(n_out) - 0.5))
    return {"mu": mu_s, "kappa": k_s}


def _cell_edges(n: int) -> np.ndarray:
    """Edges of n cells of [0, 1], equal in u for gamma = sin^2(pi u / 2): about
    pi / 2n wide in the middle and (pi / 2n)^2 at 0 and 1, where the posteriors
    of matt and mirror-like facets pile up (n + 1,)."""
    return np.sin(0.5 * np.pi * np.linspace(0.0, 1.0, n + 1)) ** 2


@functools.lru_cache(maxsize=4)
def _beta_bin_masses(n_mu: int, n_kappa: int, n_bins: int):
    """log kappa grid (n_kappa,) and the mass of Beta(mu kappa, (1 - mu) kappa)
    in each of the ``n_bins`` cells of :func:`_cell_edges`, (n_mu n_kappa,
    n_bins), mu at the centres (in u) of ``n_mu`` such cells (cached: the
    same for every object)."""
    mu = np.sin(0.5 * np.pi * (np.arange(n_mu) + 0.5) / n_mu) ** 2
    lkap = np.linspace(np.log(0.5), np.log(1e4), n_kappa)
    kap = np.exp(lkap)
    a = (mu[:, None] * kap[None, :]).ravel()
    b = ((1 - mu)[:, None] * kap[None, :]).ravel()
    edges = _cell_edges(n_bins)
    cdf = special.betainc(a[:, None], b[:, None], edges[None, :])
    # float32 halves the table (n_mu n_kappa x n_bins); the log likelihood it
    # gives errs by ~1e-7 relative, far below the grid's cell-to-cell range
    masses = np.maximum(np.diff(cdf, axis=1), 0.0).astype(np.float32)  # rounding: far tails < 0
    masses.flags.writeable = False
    lkap.flags.writeable = False
    return lkap, masses


def shared_gloss(
    draws, priors: lk.Priors, *, n_gamma: int = 201, n_logn: int = 93, max_draws: int = 500
):
    """One material for all facets: posterior of (gamma, log n) on a grid.

    Each facet's marginal posterior of (gamma, log n) is estimated by a
    Gaussian kernel density of its draws (Scott's bandwidth, reflected at
    the bounds); the shared posterior is their product divided by the prior
    F - 1 times (the prior is uniform, so it is the plain product).

    Parameters
    ----------
    draws : array_like (F, S, 2)
        Draws of (gamma, log n) per facet.

    Returns
    -------
    dict
        ``gamma`` grid and its marginal density, ``log_n`` grid and its
        marginal, and the median and 5/95 % quantiles of gamma.
    """
    d = np.asarray(draws, dtype=float)
    if d.shape[1] > max_draws:  # evenly spaced draws bound the kernel sums' cost
        d = d[:, np.linspace(0, d.shape[1] - 1, max_draws).round().astype(int)]
    gx = np.linspace(0, 1, n_gamma)
    nx = np.linspace(*priors.log_n, n_logn)
    log_post = np.zeros((n_gamma, n_logn))
    for f in range(len(d)):
        x, y = d[f, :, 0], d[f, :, 1]
        n = len(x)
        hx = max(1.06 * np.std(x) * n ** (-1 / 6), 0.5 * (gx[1] - gx[0]))
        hy = max(1.06 * np.std(y) * n ** (-1 / 6), 0.5 * (nx[1] - nx[0]))
        # product kernels reflected at the bounds of gamma and of log n: the
        # sum over the 3 x 3 reflections factorises, draw by draw
        kx = sum(np.exp(-0.5 * ((gx[:, None] - rx) / hx) ** 2) for rx in (x, -x, 2 - x))
        ky = sum(
            np.exp(-0.5 * ((nx[:, None] - ry) / hy) ** 2)
            for ry in (y, 2 * priors.log_n[0] - y, 2 * priors.log_n[1] - y)
        )
        dens = kx @ ky.T
        log_post += np.log(dens + 1e-300)
    post = np.exp(log_post - log_post.max())
    pg = post.sum(axis=1)
    pg /= pg.sum()
    cdf = np.cumsum(pg)
    q = [float(np.interp(v, cdf, gx)) for v in (0.05, 0.5, 0.95)]
    pn = post.sum(axis=0)
    pn /= pn.sum()
    return {
        "gamma": gx,
        "gamma_density": pg,
        "log_n": nx,
        "log_n_density": pn,
        "q05": q[0],
        "median": q[1],
        "q95": q[2],
        "n_median": float(np.exp(np.interp(0.5, np.cumsum(pn), nx))),
    }


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


def estimate_bundle(
    path,
    *,
    illumination: str = "gensky-clear",
    noise: str = "relative",
    camera: str = "auto",
    seed: int = 0,
    jobs: int = 1,
    progress=None,
    sampler_options: dict | None = None,
) -> EstimateResult:
    """Posterior gloss of every facet of a bundle, and of the object.

    Parameters
    ----------
    path : path or bundle.Bundle
    illumination : str
        One of :data:`ILLUMINATION_MODELS`.
    noise : {"relative", "gaussian", "student"}
    camera : {"auto", "linear", "power"}
        ``"auto"``: ``"power"`` for an ``unknown`` pixel encoding, else
        ``"linear"`` (the reader undoes known responses).
    seed, progress
        See :func:`bayesgloss.sampling.sample_posterior`.
    jobs : int
        Local worker processes for the sampler (:func:`bayesgloss.pool.process_pool`).
    sampler_options : dict, optional
        More keyword arguments for :func:`~bayesgloss.sampling.sample_posterior`
        (``max_steps``...).

    Raises
    ------
    NoUsableData
        Where no facet has :data:`MIN_FRAMES` usable frames.
    """
    b = path if isinstance(path, bundle_io.Bundle) else bundle_io.read_bundle(path)
    curves = bundle_io.facet_curves(b)
    if camera == "auto":
        camera = "linear" if b.response_known else "power"
    y, usable, censored = observations(curves)
    keep = usable_facets(b, usable)
    bases = bundle_bases(b, illumination)
    sub = render.FacetBases(bases.diffuse[keep], bases.glossy[keep], bases.exponents)
    data = lk.curve_data(
        y[keep], usable[keep], sub, censored=censored[keep], noise=noise, camera=camera
    )
    options = dict(seed=seed, progress=progress, **(sampler_options or {}))
    if jobs > 1:
        with process_pool(jobs) as pool:
            samples = sampling.sample_posterior(data, pool=pool, **options)
    else:
        samples = sampling.sample_posterior(data, **options)
    ids = curves.ids[keep]
    idata = to_inference_data(samples, data, ids, times=b.times, rng=seed)
    diag = convergence(idata)

    gam = idata.posterior["gamma"].values  # (E, S, F)
    per_facet = gam.transpose(2, 0, 1).reshape(len(ids), -1)
    facets = []
    for k, fid in enumerate(ids):
        flags = [] if diag["converged"][k] else ["not-converged"]
        facets.append(
            {
                "id": int(fid),
                "gamma": _quantiles(per_facet[k]),
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
        np.stack([per_facet, logn], axis=-1)[conv if conv.sum() else slice(None)], data.priors
    )
    summary = {
        "object": {
            "gamma": _quantiles(pop["mu"]),
            "n": {"median": shared["n_median"]},
            "converged": bool(np.all(conv)) and len(ids) > 0,
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
        "bundle": str(b.path),
        "sampler": {"seconds": samples.seconds, "median_steps": float(np.median(samples.n_steps))},
    }
    return EstimateResult(idata, summary, samples)


def estimate_unit(
    bundle: str,
    illumination: str = "gensky-clear",
    noise: str = "relative",
    camera: str = "auto",
    seed: int = 0,
    max_steps: int = 8000,
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
        seed=seed,
        jobs=1,
        sampler_options={"max_steps": max_steps},
    )
    with tempfile.TemporaryDirectory() as tmp:
        nc = Path(tmp) / "posterior.nc"
        res.idata.to_netcdf(str(nc))
        data = nc.read_bytes()
    summary = {**res.summary, "bundle": str(bundle)}
    return {"summary.json": json.dumps(summary, indent=2).encode(), "posterior.nc": data}

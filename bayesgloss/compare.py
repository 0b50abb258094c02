"""Bayesian model comparison: which reflectance model, which sky, and how sure.

Models
------
A model is a reflectance model crossed with an illumination model
(:data:`bayesgloss.estimate.ILLUMINATION_MODELS`), at one of two levels:

- ``level="facet"``: every facet has its own parameters; the facets are
  independent problems (evidence and predictive scores add over facets);
- ``level="object"``: one material for the whole object: one gamma, lobe
  width, scale s (albedo times exposure) and noise scale shared by every
  facet, so that one facet's curve can be predicted from the others'.
  Several objects of equal facet count (``object_size``, consecutive facets
  of the data) are independent problems of one batch.

Reflectance models (:data:`REFLECTANCE_MODELS`), on the bases of
:mod:`bayesgloss.render` and the likelihood of :mod:`bayesgloss.likelihood`:

- ``"lambert"``: mu = s D (gamma fixed at 0); parameters log s, log sigma;
- ``"phong"``: mu = s G(n) (gamma fixed at 1); log n, log s, log sigma;
- ``"lambert+phong"``: mu = s [(1 - gamma) D + gamma G(n)] (paper, eq. 4);
- ``"lambert+ward"``: the same with Ward's isotropic lobe of roughness alpha
  (:func:`bayesgloss.render.ward_glossy_basis`) in place of G(n); its second
  parameter is log alpha, uniform on the table's range
  (:data:`bayesgloss.render.WARD_ROUGHNESS`).

Priors are those of :class:`bayesgloss.likelihood.Priors`, normalised here
(evidence needs proper, normalised priors): gamma uniform on [0, 1], log n
(log alpha) uniform on the basis table's range, log s normal with sd 3, log
sigma uniform. The fixed gamma of ``lambert`` and ``phong`` lies on the
boundary of the uniform prior of ``lambert+phong``: both are nested in it.

Tools
-----
- :func:`fit_model`: posterior draws of a model from several independent
  batched ensembles (:class:`bayesgloss.sampling.BatchedEnsemble`), run
  until the rule of :mod:`bayesgloss.diagnostics` holds for every
  parameter, and the pointwise log likelihood, for PSIS-LOO
  (:func:`bayesgloss.loo.loo_compare`);
- :func:`model_evidence`: ln Z of every problem by thermodynamic
  integration (:func:`bayesgloss.evidence.thermodynamic_integration`);
- :func:`compare_bundle`: every (reflectance, sky) model of a bundle, with
  PSIS-LOO, evidence, Savage-Dickey Bayes factors of Lambert and the skies'
  posterior probabilities (:mod:`bayesgloss.evidence`).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from scipy import special

from . import bundle as bundle_io
from . import diagnostics, estimate, render, sampling, sky
from . import likelihood as lk
from .evidence import (
    EvidenceResult,
    marginal_gamma,
    power_ladder,
    savage_dickey,
    sky_posterior,
    thermodynamic_integration,
)
from .loo import loo_compare
from .sampling.ensemble import fold_copies, unfold_copies
from .visibility import bundle_occlusion

__all__ = [
    "REFLECTANCE_MODELS",
    "LEVELS",
    "ComparisonModel",
    "comparison_model",
    "bundle_models",
    "ModelFit",
    "fit_model",
    "model_evidence",
    "compare_bundle",
    "compare_bundle_quick",
]

REFLECTANCE_MODELS = ("lambert", "phong", "lambert+phong", "lambert+ward")
LEVELS = ("facet", "object")
# free parameters (indices into likelihood.PARAMETERS()) and fixed values
_FREE = {
    "lambert": (2, 3),
    "phong": (1, 2, 3),
    "lambert+phong": (0, 1, 2, 3),
    "lambert+ward": (0, 1, 2, 3),
}
_NAMES = ("gamma", "log_n", "log_s", "log_sigma")


def _check(name: str, value: str, valid) -> None:
    if value not in valid:
        raise ValueError(f"unknown {name} {value!r}; valid: {', '.join(valid)}")


@dataclass(frozen=True)
class ComparisonModel:
    """One reflectance model under one illumination model, over F facets.

    Attributes
    ----------
    reflectance : str
        One of :data:`REFLECTANCE_MODELS`.
    illumination : str
        One of :data:`bayesgloss.estimate.ILLUMINATION_MODELS` (or any label).
    level : {"facet", "object"}
    data : likelihood.CurveData
        F facets; for ``"ward"`` the table's ``log_n`` is log alpha.
    facet_ids : ndarray (F,), optional
    object_size : int, optional
        Object level: facets per object; the F facets are F / object_size
        objects of consecutive facets (default: all F facets one object).
    """

    reflectance: str
    illumination: str
    level: str
    data: lk.CurveData = field(repr=False)
    facet_ids: np.ndarray | None = field(default=None, repr=False)
    object_size: int | None = None

    def __post_init__(self):
        f = len(self.data.y)
        if self.object_size is not None and (self.object_size < 1 or f % self.object_size):
            raise ValueError(f"object_size {self.object_size} does not divide {f} facets")

    @property
    def name(self) -> str:
        return f"{self.reflectance}/{self.illumination}"

    @property
    def free(self) -> tuple[int, ...]:
        return _FREE[self.reflectance]

    @property
    def parameters(self) -> tuple[str, ...]:
        names = list(_NAMES)
        if self.reflectance == "lambert+ward":
            names[1] = "log_alpha"
        return tuple(names[i] for i in self.free)

    @property
    def n_params(self) -> int:
        return len(self.free)

    @property
    def facets_per_object(self) -> int:
        """Facets of one object (object level)."""
        return len(self.data.y) if self.object_size is None else int(self.object_size)

    @property
    def n_problems(self) -> int:
        """Independent problems: F facets, or the objects."""
        f = len(self.data.y)
        return f if self.level == "facet" else f // self.facets_per_object

    @property
    def log_prior_constant(self) -> float:
        """Normalising constant of the free parameters' prior (module docstring)."""
        p = self.data.priors
        c = -0.5 * np.log(2 * np.pi * p.log_s_sd**2) - np.log(p.log_sigma[1] - p.log_sigma[0])
        if 1 in self.free:
            c -= np.log(p.log_n[1] - p.log_n[0])
        return float(c)

    def full(self, theta) -> np.ndarray:
        """The likelihood's 4 parameters from the model's free ones, (..., 4)."""
        th = np.asarray(theta, dtype=float)
        out = np.empty(th.shape[:-1] + (4,))
        out[..., 0] = 1.0 if self.reflectance == "phong" else 0.0
        out[..., 1] = np.mean(self.data.priors.log_n)  # irrelevant where gamma = 0
        out[..., list(self.free)] = th
        return out

    def _facets(self, theta) -> np.ndarray:
        """theta (B, K, P) -> full parameters per facet (F, K, 4): an object's
        parameters repeated for each of its facets."""
        full = self.full(theta)
        if self.level == "facet":
            return full
        return np.repeat(full, self.facets_per_object, axis=0)

    def log_prior(self, theta) -> np.ndarray:
        """Normalised log prior density of the free parameters, (B, K)."""
        th = np.asarray(theta, dtype=float)
        full = self.full(th)
        if self.level == "facet":
            data = self.data
        else:  # one prior centre of log s per object (comparison_model)
            data = self.data.take(np.arange(0, len(self.data.y), self.facets_per_object))
        return lk.log_prior(full, data) + self.log_prior_constant

    def log_likelihood(self, theta, pointwise: bool = False) -> np.ndarray:
        """Log likelihood, (B, K); pointwise (F, K, T) per frame (facet level)
        or (B, K, m) per facet of each object of m facets (object level)."""
        th = np.asarray(theta, dtype=float)
        b, k = th.shape[:2]
        m = self.facets_per_object
        with np.errstate(all="ignore"):
            ll = lk.log_likelihood(self._facets(th), self.data, pointwise=pointwise)
            if self.level == "object":
                if pointwise:  # a facet's frames summed into one term
                    ll = ll.sum(-1).reshape(b, m, k).transpose(0, 2, 1)
                else:
                    ll = ll.reshape(b, m, k).sum(1)
            return np.nan_to_num(ll, nan=-np.inf)

    def log_posterior(self, theta, beta=1.0) -> np.ndarray:
        """log prior + beta x log likelihood, (B, K); -inf outside the prior."""
        lp = self.log_prior(theta)
        ok = np.isfinite(lp)
        if not np.any(ok):
            return lp
        ll = self.log_likelihood(theta)
        beta = np.asarray(beta, dtype=float)
        beta = beta[:, None] if beta.ndim else beta
        return np.where(ok, lp + np.where(ok, beta * ll, 0.0), -np.inf)

    def initial(self, n_walkers: int, rng: np.random.Generator) -> np.ndarray:
        """Starting walkers (B, W, P) near the optimum (least squares on the table)."""
        start = sampling.initial_ensemble(self.data, n_walkers, rng)  # (F, W, 4)
        if self.level == "object":
            pool = start.reshape(self.n_problems, -1, 4)  # every object's facets' walkers
            pick = np.stack([rng.choice(pool.shape[1], n_walkers, replace=False) for _ in pool])
            start = np.take_along_axis(pool, pick[..., None], axis=1)
            spread = np.log(np.exp(start[..., 3]) + np.std(pool[..., 3], axis=1, keepdims=True))
            start[..., 3] = np.clip(spread, *(np.array(self.data.priors.log_sigma) + [1e-6, -1e-6]))
        if self.reflectance == "phong":
            start[..., 0] = 1.0
        th = start[..., list(self.free)]
        th[..., self.parameters.index("log_s")] += 0.02 * rng.standard_normal(th.shape[:2])
        return th


def comparison_model(
    reflectance: str,
    illumination: str,
    y,
    valid,
    bases: render.FacetBases,
    *,
    level: str = "facet",
    censored=None,
    noise: str = "relative",
    priors: lk.Priors | None = None,
    object_size: int | None = None,
) -> ComparisonModel:
    """A model from observations and bases (Phong bases, or Ward bases for
    ``"lambert+ward"``, whose table's ``exponents`` hold alpha).

    For ``"lambert+ward"`` the prior of log alpha is set to the table's
    range; the object level uses one prior centre of log s per object, the
    median of its facets' data-based centres. ``object_size`` (object
    level): facets per object, consecutive in ``y`` (default: one object).
    """
    _check("reflectance model", reflectance, REFLECTANCE_MODELS)
    _check("level", level, LEVELS)
    priors = priors or lk.Priors()
    table = np.log(np.asarray(bases.exponents, dtype=float))
    priors = replace(priors, log_n=(float(table[0]), float(table[-1])))
    data = lk.curve_data(y, valid, bases, censored=censored, noise=noise, priors=priors)
    model = ComparisonModel(reflectance, illumination, level, data, object_size=object_size)
    if level == "object":
        m = model.facets_per_object
        center = np.median(data.log_s_center.reshape(-1, m), axis=1)
        data = replace(data, log_s_center=np.repeat(center, m))
        model = replace(model, data=data)
    return model


def _daylight(b, illumination: str):
    rho = b.ground_albedo
    if illumination == "point-sun":
        return sky.daylight(illumination, b.sun_direction), "sky", rho
    return sky.daylight(illumination, b.sun_direction, ground_reflectance=rho), "plane", rho


def bundle_models(
    b,
    *,
    reflectance=REFLECTANCE_MODELS,
    illumination=("gensky-clear",),
    level: str = "facet",
    noise: str = "relative",
    min_frames: int = 4,
) -> dict[tuple[str, str], ComparisonModel]:
    """Every (reflectance, illumination) model of a bundle's facet curves.

    Facets with fewer than ``min_frames`` usable frames are left out (the
    same facets for every model); a bundle in which no facet has them is
    rejected (:class:`bayesgloss.bundle.NoUsableData`).

    Parameters
    ----------
    b : path or bundle.Bundle
    reflectance, illumination : sequence of str
    level : {"facet", "object"}

    Returns
    -------
    dict
        ``(reflectance, illumination) -> ComparisonModel`` (with ``facet_ids``).
    """
    for r in reflectance:
        _check("reflectance model", r, REFLECTANCE_MODELS)
    for ill in illumination:
        _check("illumination", ill, estimate.ILLUMINATION_MODELS)
    b = b if isinstance(b, bundle_io.Bundle) else bundle_io.read_bundle(b)
    curves = estimate.bundle_curves(b)
    y, usable, censored = estimate.observations(curves)
    keep = bundle_io.usable_facets(b, usable, min_frames, censored)
    models = {}
    for ill in illumination:
        phong = estimate.bundle_bases(b, ill)
        phong = render.FacetBases(phong.diffuse[keep], phong.glossy[keep], phong.exponents)
        ward = None
        for r in reflectance:
            if r == "lambert+ward" and ward is None:
                day, ground, rho = _daylight(b, ill)
                geom = b.view_geometry()
                sub = render.ViewGeometry(geom.normal[keep], geom.view_direction[keep])
                occlusion = bundle_occlusion(b)  # None without object_mesh
                ward = render.ward_facet_bases(
                    sub,
                    day,
                    ground=ground,
                    ground_reflectance=rho,
                    diffuse=phong.diffuse,
                    occlusion=None if occlusion is None else occlusion.take(keep),
                )
            bases = ward if r == "lambert+ward" else phong
            models[(r, ill)] = comparison_model(
                r,
                ill,
                y[keep],
                usable[keep],
                bases,
                level=level,
                censored=censored[keep],
                noise=noise,
            )
    return {key: replace(m, facet_ids=curves.ids[keep]) for key, m in models.items()}


@dataclass
class ModelFit:
    """Posterior of a model: draws and pointwise log likelihood.

    Attributes
    ----------
    model : ComparisonModel
    draws : ndarray (B, E, S, P)
        B problems, E independent ensembles, S draws each.
    log_lik : ndarray (B, E, S, N)
        Pointwise log likelihood: N frames per facet (facet level, invalid
        frames 0) or N facets (object level).
    valid : ndarray (B, N) of bool
        Pointwise terms that are observations.
    rhat, tau : ndarray
        Rank-normalised split R-hat of every parameter (B, P) (ensembles as
        chains, :func:`bayesgloss.diagnostics.rank_diagnostics`) and
        integrated autocorrelation times (B, E, P) [steps].
    n_steps : int
        Production steps run.
    min_tau_multiple : float
        Production steps needed per integrated autocorrelation time.
    """

    model: ComparisonModel = field(repr=False)
    draws: np.ndarray
    log_lik: np.ndarray
    valid: np.ndarray
    rhat: np.ndarray
    tau: np.ndarray
    n_steps: int = 0
    min_tau_multiple: float = 50.0

    def converged(self) -> np.ndarray:
        """Per problem (B,): the rule of :mod:`bayesgloss.diagnostics` for
        every parameter (R-hat < 1.01, bulk and tail ESS >= 400, a production
        run of at least ``min_tau_multiple`` autocorrelation times in every
        ensemble), as :func:`bayesgloss.sampling.sample_posterior` applies it
        to gamma."""
        return _converged(self.draws, self.tau, self.n_steps, self.min_tau_multiple)


def _converged(draws, tau, n_steps, multiple) -> np.ndarray:
    """The rule of :mod:`bayesgloss.diagnostics` per problem, draws (B, E, S, P)."""
    return _diagnosed(draws, tau, n_steps, multiple)[1]


def _diagnosed(draws, tau, n_steps, multiple) -> tuple[np.ndarray, np.ndarray]:
    """R-hat of every parameter (B, P) and the rule per problem (B,), draws (B, E, S, P)."""
    b, e, s, p = draws.shape
    with np.errstate(invalid="ignore", divide="ignore"):
        rhat, _, _, met = diagnostics.diagnose(draws.transpose(0, 3, 1, 2).reshape(b * p, e, s))
    long = diagnostics.long_enough(n_steps, np.reshape(tau, (b, -1)), multiple)
    return rhat.reshape(b, p), long & np.all(met.reshape(b, p), axis=-1)


def fit_model(
    model: ComparisonModel,
    *,
    n_ensembles: int = 4,
    n_walkers: int = 16,
    burn: int = 500,
    steps: int = 1500,
    max_steps: int | None = None,
    min_tau_multiple: float = 50.0,
    draws_per_ensemble: int = 400,
    seed=0,
) -> ModelFit:
    """Posterior draws of a model from E independent batched ensembles.

    All problems and ensembles advance in one batch (emcee's stretch and
    differential-evolution moves, :class:`bayesgloss.sampling.BatchedEnsemble`);
    ``burn`` steps are discarded and at least ``steps`` kept; the run then
    goes on in chunks of ``steps`` while any problem is not converged
    (:meth:`ModelFit.converged`, the rule of :mod:`bayesgloss.diagnostics`
    for every parameter), up to ``max_steps``. The
    production run is thinned evenly to ``draws_per_ensemble`` draws
    (walkers one after the other). Problems still not converged at
    ``max_steps`` are flagged by :meth:`ModelFit.converged`.

    Parameters
    ----------
    model : ComparisonModel
    n_ensembles, n_walkers, burn, steps, draws_per_ensemble : int
    max_steps : int, optional
        Production steps at most (default ``steps``: a fixed-length run).
    min_tau_multiple : float
    seed : int or numpy.random.Generator
    """
    rng = np.random.default_rng(seed)
    e, w, p = n_ensembles, n_walkers, model.n_params
    b = model.n_problems
    max_steps = steps if max_steps is None else max(int(max_steps), steps)
    start = np.concatenate([model.initial(w, rng) for _ in range(e)])  # (E*B, W, P)

    def log_prob(th):
        return unfold_copies(model.log_posterior(fold_copies(th, e)), e)

    def thinned(chain):
        n = len(chain)
        per = max(1, draws_per_ensemble // w)
        idx = np.linspace(0, n - 1, per).round().astype(int)
        return chain[idx].reshape(per, e, b, w, p).transpose(2, 1, 3, 0, 4).reshape(b, e, -1, p)

    ens = sampling.BatchedEnsemble(log_prob, rng=rng)
    chain, lps, _ = ens.run(start, burn)
    chain, lps, _ = ens.run(chain[-1], steps, lps[-1])  # (N, E*B, W, P)
    while True:
        tau = diagnostics.integrated_time(chain).reshape(e, b, p).transpose(1, 0, 2)
        d = thinned(chain)
        rhat, done = _diagnosed(d, tau, len(chain), min_tau_multiple)
        if len(chain) >= max_steps or np.all(done):
            break
        more, lp_more, _ = ens.run(chain[-1], min(steps, max_steps - len(chain)), lps[-1])
        chain, lps = np.concatenate([chain, more]), np.concatenate([lps, lp_more])
    s = d.shape[2]
    ll = model.log_likelihood(d.reshape(b, e * s, p), pointwise=True)
    ll = ll.reshape(ll.shape[0], e, s, -1)
    if model.level == "object":
        valid = np.ones((b, ll.shape[-1]), dtype=bool)
    else:
        valid = model.data.valid
    return ModelFit(model, d, ll, valid, rhat, tau, len(chain), min_tau_multiple)


def model_evidence(
    model: ComparisonModel, *, n_walkers: int = 16, seed=0, **options
) -> EvidenceResult:
    """ln Z of every problem of a model (facets, or the object) by
    :func:`thermodynamic_integration`; options are passed on to it."""
    rng = np.random.default_rng(seed)
    start = model.initial(n_walkers, rng)
    return thermodynamic_integration(
        model.log_prior, model.log_likelihood, start, seed=rng, **options
    )


# --------------------------------------------------------------------------
# one bundle: the table of the command line


def compare_bundle(
    path,
    *,
    reflectance=REFLECTANCE_MODELS,
    illumination=("gensky-clear", "gensky-intermediate"),
    level: str = "object",
    seed: int = 0,
    fit_options: dict | None = None,
    evidence_options: dict | None = None,
) -> dict:
    """Compare every (reflectance, illumination) model on a bundle.

    Returns
    -------
    dict (JSON-ready)
        ``loo``: the PSIS-LOO table (leave-one-facet-out for the object
        level, pooled leave-one-frame-out for the facet level) with Pareto-k
        flags; ``evidence``: ln Z (summed over facets for the facet level)
        and its uncertainty per model, and ln BF against the best;
        ``savage_dickey``: ln BF01 of Lambert per facet or for the object,
        under each illumination's ``lambert+phong``; ``sky``: posterior
        probabilities of the skies (evidence summed over reflectance models,
        equal priors) and gamma with the sky marginalised.
    """
    models = bundle_models(path, reflectance=reflectance, illumination=illumination, level=level)
    rng = np.random.default_rng(seed)
    seeds = rng.integers(0, 2**32, size=(len(models), 2))
    fits, ev = {}, {}
    for (key, m), (s1, s2) in zip(models.items(), seeds, strict=True):
        fits[key] = fit_model(m, seed=int(s1), **(fit_options or {}))
        ev[key] = model_evidence(m, seed=int(s2), **(evidence_options or {}))
    names = {key: f"{key[0]}/{key[1]}" for key in models}
    loo = loo_compare({names[k]: f for k, f in fits.items()})
    log_z = {names[k]: float(e.log_z.sum()) for k, e in ev.items()}
    log_z_se = {names[k]: float(np.sqrt(np.sum(e.se**2))) for k, e in ev.items()}
    best = max(log_z, key=log_z.get)
    evidence = [
        {
            "model": n,
            "log_z": log_z[n],
            "se": log_z_se[n],
            "log_bf_vs_best": log_z[n] - log_z[best],
        }
        for n in sorted(log_z, key=log_z.get, reverse=True)
    ]
    sd = {}
    for ill in illumination:
        key = ("lambert+phong", ill)
        if key in fits:
            g = fits[key].draws[..., 0]  # (B, E, S)
            sd[ill] = [savage_dickey(g[i].ravel()) for i in range(len(g))]
    sky_z = {}
    for ill in illumination:
        zs = [log_z[names[k]] for k in models if k[1] == ill]
        sky_z[ill] = float(special.logsumexp(zs) - np.log(len(zs)))  # equal model priors
    if len(sky_z) > 1:
        skies = sky_posterior(sky_z)
    else:
        skies = {"prob": {illumination[0]: 1.0}, "best": illumination[0]}
    mix = None
    if all(("lambert+phong", s) in fits for s in illumination):
        draws = {}
        for s in illumination:
            g = fits[("lambert+phong", s)].draws[..., 0]
            draws[s] = g.reshape(len(g), -1)
        g = marginal_gamma(draws, skies["prob"], seed=seed)
        q = np.quantile(g, [0.05, 0.5, 0.95], axis=-1)
        mix = [{"median": float(b), "q05": float(a), "q95": float(c)} for a, b, c in q.T]
    return {
        "level": level,
        "facets": [int(i) for i in next(iter(models.values())).facet_ids],
        "loo": {k: v for k, v in loo.items() if k != "pareto_k"},
        "evidence": evidence,
        "savage_dickey": sd,
        "sky": skies,
        "gamma_sky_marginalised": mix,
        "converged": {names[k]: bool(np.all(f.converged())) for k, f in fits.items()},
    }


def compare_bundle_quick(
    path,
    *,
    reflectance=REFLECTANCE_MODELS,
    illumination=("gensky-clear", "gensky-intermediate"),
    level: str = "object",
    seed: int = 0,
    steps: int = 800,
    rungs: int = 40,
) -> dict:
    """:func:`compare_bundle` with the command line's run lengths: ``steps``
    kept per fit (a third more as burn-in, at least 100) and ``rungs``
    temperature rungs of 8 walkers for the evidence; each fit goes on to 50
    autocorrelation times and R-hat < 1.01, up to 4 x ``steps``."""
    opts = {"steps": steps, "burn": max(100, steps // 3)}
    ev_opts = {**opts, "n_walkers": 8, "betas": power_ladder(rungs)}
    opts["max_steps"] = 4 * steps  # fits go on to 50 tau (or are flagged)
    return compare_bundle(
        path,
        reflectance=reflectance,
        illumination=illumination,
        level=level,
        seed=seed,
        fit_options=opts,
        evidence_options=ev_opts,
    )

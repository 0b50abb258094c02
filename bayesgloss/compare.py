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
  batched ensembles (:class:`bayesgloss.sampling.BatchedEnsemble`) and the
  pointwise log likelihood; :func:`loo_compare`: PSIS-LOO through
  :func:`arviz.compare`, leave-one-frame-out per facet and leave-one-facet-out
  for the object model, Pareto k of every comparison reported and k > 0.7
  flagged (Vehtari, Gelman & Gabry 2017).
- :func:`savage_dickey`: the Bayes factor of the nested Lambert model from
  the posterior density of gamma at 0 (Dickey 1971; Wagenmakers et al. 2010),
  estimated at the prior's boundary by a local-linear (boundary-corrected)
  kernel density (Jones 1993).
- :func:`thermodynamic_integration`: ln Z = int_0^1 E_beta[ln L] d beta over
  power posteriors prior x L^beta (Lartillot & Philippe 2006; Friel & Pettitt
  2008), all rungs of all problems run as one batch with swaps between
  neighbouring rungs (parallel tempering), and the trapezoid rule corrected
  by the rung variances (Friel, Hurn & Wyse 2014, eq. 8); the uncertainty
  combines the Monte Carlo error and a quadrature error.
- :func:`sky_posterior`: posterior probabilities of candidate skies from
  their evidence (equal prior), and gamma with the sky marginalised.
"""

from __future__ import annotations

import logging
import warnings
from dataclasses import dataclass, field, replace

import numpy as np
from scipy import special

from . import bundle as bundle_io
from . import estimate, render, sampling, sky
from . import likelihood as lk

__all__ = [
    "REFLECTANCE_MODELS",
    "LEVELS",
    "PARETO_K_MAX",
    "ComparisonModel",
    "comparison_model",
    "bundle_models",
    "ModelFit",
    "fit_model",
    "loo_compare",
    "savage_dickey",
    "boundary_density",
    "power_ladder",
    "EvidenceResult",
    "thermodynamic_integration",
    "model_evidence",
    "sky_posterior",
    "compare_bundle",
]

log = logging.getLogger(__name__)

REFLECTANCE_MODELS = ("lambert", "phong", "lambert+phong", "lambert+ward")
LEVELS = ("facet", "object")
#: Pareto k above which a PSIS-LOO term is unreliable (Vehtari et al. 2024).
PARETO_K_MAX = 0.7
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
    rho = 0.2 if b.ground_reflectance is None else float(b.ground_reflectance)
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
    same facets for every model).

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
    curves = bundle_io.facet_curves(b)
    y, usable, censored = estimate.observations(curves)
    keep = usable.sum(axis=1) >= min_frames
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
                ward = render.ward_facet_bases(
                    sub, day, ground=ground, ground_reflectance=rho, diffuse=phong.diffuse
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


# --------------------------------------------------------------------------
# batched runs: C copies of a model's B problems folded into the walker axis


def _fold(theta, copies: int) -> np.ndarray:
    """(C*B, W, P) -> (B, C*W, P): copies of every problem side by side."""
    cb, w, p = theta.shape
    th = theta.reshape(copies, cb // copies, w, p).transpose(1, 0, 2, 3)
    return th.reshape(-1, copies * w, p)


def _unfold(values, copies: int) -> np.ndarray:
    """(B, C*W) -> (C*B, W)."""
    b, cw = values.shape
    return values.reshape(b, copies, cw // copies).transpose(1, 0, 2).reshape(copies * b, -1)


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
        Split R-hat of every parameter (B, P) (ArviZ, ensembles as chains)
        and integrated autocorrelation times (B, E, P) [steps].
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
        """Per problem (B,): R-hat < 1.01 for every parameter and a production
        run of at least ``min_tau_multiple`` autocorrelation times of every
        parameter in every ensemble (emcee's rule of thumb, as
        :func:`bayesgloss.sampling.sample_posterior`)."""
        return _converged(self.rhat, self.tau, self.n_steps, self.min_tau_multiple)


def _converged(rhat, tau, n_steps, multiple) -> np.ndarray:
    long = n_steps >= multiple * np.nan_to_num(np.max(tau, axis=1), nan=np.inf)  # (B, P)
    return np.all((rhat < estimate.RHAT_MAX) & long, axis=-1)


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
    (:meth:`ModelFit.converged`: R-hat < 1.01 and a run of at least
    ``min_tau_multiple`` integrated autocorrelation times, the rule of
    :func:`bayesgloss.sampling.sample_posterior`), up to ``max_steps``. The
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
    import arviz as az

    rng = np.random.default_rng(seed)
    e, w, p = n_ensembles, n_walkers, model.n_params
    b = model.n_problems
    max_steps = steps if max_steps is None else max(int(max_steps), steps)
    start = np.concatenate([model.initial(w, rng) for _ in range(e)])  # (E*B, W, P)

    def log_prob(th):
        return _unfold(model.log_posterior(_fold(th, e)), e)

    def rhat_of(d):  # d (B, E, S, P)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            ds = az.convert_to_dataset({"theta": d.transpose(1, 2, 0, 3)})  # (E, S, B, P)
            return np.asarray(az.rhat(ds)["theta"].values).reshape(b, p)

    def thinned(chain):
        n = len(chain)
        per = max(1, draws_per_ensemble // w)
        idx = np.linspace(0, n - 1, per).round().astype(int)
        return chain[idx].reshape(per, e, b, w, p).transpose(2, 1, 3, 0, 4).reshape(b, e, -1, p)

    ens = sampling.BatchedEnsemble(log_prob, rng=rng)
    chain, lps, _ = ens.run(start, burn)
    chain, lps, _ = ens.run(chain[-1], steps, lps[-1])  # (N, E*B, W, P)
    while True:
        tau = sampling.integrated_time(chain).reshape(e, b, p).transpose(1, 0, 2)
        d = thinned(chain)
        rhat = rhat_of(d)
        if len(chain) >= max_steps or np.all(_converged(rhat, tau, len(chain), min_tau_multiple)):
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


# --------------------------------------------------------------------------
# predictive comparison


def _idata(log_lik):
    """InferenceData with one log-likelihood variable ``y`` (E, S, N)."""
    import arviz as az

    return az.from_dict(
        posterior={"draw_index": np.zeros(log_lik.shape[:2])}, log_likelihood={"y": log_lik}
    )


def loo_compare(fits: dict, *, problem: int | None = None) -> dict:
    """PSIS-LOO comparison of fitted models (:func:`arviz.compare`).

    Parameters
    ----------
    fits : dict
        ``name -> ModelFit`` on the same data and level.
    problem : int, optional
        Facet level: compare on this facet alone (leave-one-frame-out);
        ``None`` pools every facet's frames (each facet with its own
        parameters, draws of different facets paired). Object level:
        leave-one-facet-out (a facet's frames summed into one term).

    Returns
    -------
    dict
        ``table``: rows per model (rank, elpd_loo, se, p_loo, elpd_diff, dse,
        weight, max Pareto k, count of k > 0.7, warning); ``pareto_k``:
        ``name -> ndarray`` of every term's k; ``flagged``: models with any
        k > 0.7. High k is reported, never dropped.
    """
    import arviz as az

    idatas, ks = {}, {}
    for name, fit in fits.items():
        ll = fit.log_lik
        valid = fit.valid
        if problem is not None:
            terms = ll[problem][..., valid[problem]]
        elif fit.model.level == "object":
            if fit.model.n_problems > 1:
                raise ValueError("several objects: compare one at a time (problem=...)")
            terms = ll[0]
        else:
            terms = np.moveaxis(ll, 0, 2)[..., valid]  # (E, S, valid (facet, frame))
        idatas[name] = _idata(terms)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        table = az.compare(idatas, ic="loo", method="stacking")
        for name, idata in idatas.items():
            ks[name] = np.asarray(az.loo(idata, pointwise=True).pareto_k)
    for w in caught:  # surfaced in the result as flags, and logged
        log.info("arviz: %s", w.message)
    rows = []
    for name in table.index:
        k = ks[name]
        n_high = int(np.sum(k > PARETO_K_MAX))
        r = table.loc[name]
        rows.append(
            {
                "model": name,
                "rank": int(r["rank"]),
                "elpd_loo": float(r["elpd_loo"]),
                "se": float(r["se"]),
                "p_loo": float(r["p_loo"]),
                "elpd_diff": float(r["elpd_diff"]),
                "dse": float(r["dse"]),
                "weight": float(r["weight"]),
                "pareto_k_max": float(np.max(k)),
                "pareto_k_high": n_high,
                "n_terms": int(k.size),
                "warning": bool(n_high > 0),
            }
        )
    return {
        "table": rows,
        "pareto_k": ks,
        "flagged": [r["model"] for r in rows if r["warning"]],
    }


def select_parsimonious(rows: list[dict], n_params: dict) -> str:
    """The simplest model whose elpd lies within one dse of the best.

    Nested models tie in elpd when the simpler one is true; this rule (the
    "one standard error" choice) then picks the simpler.
    """
    best = min(rows, key=lambda r: r["rank"])
    close = [r for r in rows if r["elpd_diff"] <= max(r["dse"], 1e-9) or r is best]
    return min(close, key=lambda r: (n_params[r["model"]], r["rank"]))["model"]


__all__ += ["select_parsimonious"]


# --------------------------------------------------------------------------
# Savage-Dickey at the prior's boundary


def boundary_density(x, *, bandwidth=None, ess=None) -> tuple[float, float, float]:
    """Density at 0 of draws supported on [0, inf): local-linear kernel estimate.

    A plain (or reflected) kernel estimate at a boundary is biased by
    O(h f'(0)); the local-linear estimator (Jones 1993, eq. 2.3, Gaussian
    kernel on the half line) removes that term:

        f(0) = 1/(n h) sum_i (a2 - a1 u_i) K(u_i) / (a0 a2 - a1^2),  u_i = x_i / h,

    a_j = int_0^inf u^j K(u) du (a0 = 1/2, a1 = 1/sqrt(2 pi), a2 = 1/2).

    Parameters
    ----------
    x : array_like (n,)
        Draws, >= 0 [-].
    bandwidth : float, optional
        Default: Silverman's rule for the draws reflected about 0,
        h = 0.9 sqrt(mean x^2) n^(-1/5).
    ess : float, optional
        Effective sample size for the standard error (default n).

    Returns
    -------
    density, se, bandwidth : float
        The estimate may be slightly negative when the true density at 0 is
        about zero; the standard error is that of the mean of the kernel
        terms with ``ess`` draws.
    """
    x = np.asarray(x, dtype=float).ravel()
    if x.size < 10 or np.any(x < 0) or not np.all(np.isfinite(x)):
        raise ValueError(f"need >= 10 finite draws >= 0, got {x.size} (min {np.min(x)})")
    n = x.size
    h = 0.9 * np.sqrt(np.mean(x**2)) * n ** (-0.2) if bandwidth is None else float(bandwidth)
    h = max(h, 1e-12)
    a0, a1, a2 = 0.5, 1.0 / np.sqrt(2 * np.pi), 0.5
    u = x / h
    terms = (a2 - a1 * u) * np.exp(-0.5 * u * u) / np.sqrt(2 * np.pi) / (a0 * a2 - a1**2) / h
    n_eff = n if ess is None else max(float(ess), 2.0)
    return float(terms.mean()), float(terms.std(ddof=1) / np.sqrt(n_eff)), float(h)


def savage_dickey(gamma_draws, *, prior_density: float = 1.0, ess=None) -> dict:
    """Bayes factor of gamma = 0 (Lambert) against the full model.

    BF01 = p(gamma = 0 | y) / p(gamma = 0) (Dickey 1971; Wagenmakers et al.
    2010, eq. 6), valid because the full model's likelihood at gamma = 0
    does not depend on the lobe width and the other priors are shared.

    Parameters
    ----------
    gamma_draws : array_like
        Posterior draws of gamma in [0, 1] under the full model.
    prior_density : float
        Prior density of gamma at 0 (uniform prior: 1) [-].
    ess : float, optional
        Effective sample size of the draws.

    Returns
    -------
    dict
        ``log_bf01`` (ln BF of Lambert over the full model), its ``se``
        (delta method), the ``density`` at 0, and ``bound``: True when the
        density estimate is indistinguishable from 0 (below 2 se); then
        ``log_bf01`` is an upper bound, ln(2 se / prior density), and
        ``se`` is None.
    """
    dens, se, h = boundary_density(gamma_draws, ess=ess)
    bound = dens < 2 * se
    value = 2 * se if bound else dens
    return {
        "log_bf01": float(np.log(value / prior_density)),
        "se": None if bound else float(se / dens),
        "density": dens,
        "bandwidth": h,
        "bound": bool(bound),
    }


# --------------------------------------------------------------------------
# thermodynamic integration


def power_ladder(n_rungs: int = 64, beta_min: float = 1e-24) -> np.ndarray:
    """Temperature ladder: 0, then ``n_rungs - 1`` rungs geometric from
    ``beta_min`` to 1.

    With the wide priors of the facet model, E_beta[ln L] at small beta is
    of order -1 / beta down to beta ~ 1e-20 (prior draws of a tiny noise
    scale give ln L ~ -1e20), so the ladder must be uniform in ln beta
    rather than the power ladder beta = (k / K)^5 of Friel & Pettitt (2008,
    sec. 2.2), which leaves most of that range in its first interval.
    """
    if n_rungs < 4 or n_rungs % 2:
        raise ValueError(f"need an even number of rungs >= 4, got {n_rungs}")
    if not 0 < beta_min < 1:
        raise ValueError(f"beta_min must lie in (0, 1), got {beta_min}")
    return np.concatenate([[0.0], np.geomspace(beta_min, 1.0, n_rungs - 1)])


@dataclass
class EvidenceResult:
    """ln Z per problem by thermodynamic integration.

    Attributes
    ----------
    log_z, se : ndarray (B,)
        Estimate and total standard uncertainty, sqrt(mc^2 + quadrature^2).
    mc_se, quadrature_error : ndarray (B,)
    betas : ndarray (K,)
    mean_log_lik, var_log_lik, ess : ndarray (K, B)
        E_beta[ln L], Var_beta[ln L] and effective sample size per rung.
    swap_rate : ndarray (K - 1,)
    """

    log_z: np.ndarray
    se: np.ndarray
    mc_se: np.ndarray
    quadrature_error: np.ndarray
    betas: np.ndarray
    mean_log_lik: np.ndarray
    var_log_lik: np.ndarray
    ess: np.ndarray
    swap_rate: np.ndarray


def _hermite_quadrature(betas, mean, var):
    """int_beta1^1 E_beta[ln L] d beta, (B,), and the weights of the rung means (K, 1).

    In u = ln beta the integral is int E(u) e^u du. On each interval E is
    the cubic Hermite interpolant of the rung means and their slopes
    dE/du = beta Var_beta[ln L] (as dE/d beta = Var_beta[ln L]; the
    derivative correction of Friel, Hurn & Wyse 2014, eq. 8, here in ln
    beta), integrated against e^u exactly (8-point Gauss-Legendre of a
    smooth integrand). Exact where E is a cubic in ln beta: constant near
    beta = 1, and close to it where E ~ -c / beta at small beta.
    """
    u = np.log(betas)
    h = np.diff(u)[:, None]  # (K-1, 1)
    x, wx = np.polynomial.legendre.leggauss(8)
    t, wt = 0.5 * (x + 1.0), 0.5 * wx
    basis = np.stack(
        [2 * t**3 - 3 * t**2 + 1, t**3 - 2 * t**2 + t, -2 * t**3 + 3 * t**2, t**3 - t**2]
    )  # h00, h10, h01, h11 at the nodes
    ints = (basis * wt * np.exp(h * t[None, :])[:, None, :]).sum(-1)  # (K-1, 4)
    scale = h[:, 0] * np.exp(u[:-1])  # d beta = e^u du, u = u0 + h t
    c00, c10, c01, c11 = (scale[:, None] * ints).T
    slope = betas[:, None] * var  # dE/du
    h1 = h[:, 0][:, None]
    total = (
        c00[:, None] * mean[:-1]
        + c10[:, None] * h1 * slope[:-1]
        + c01[:, None] * mean[1:]
        + c11[:, None] * h1 * slope[1:]
    ).sum(0)
    w = np.zeros((len(betas), 1))
    w[:-1, 0] += c00
    w[1:, 0] += c01
    return total, w


def thermodynamic_integration(
    log_prior,
    log_likelihood,
    start,
    *,
    betas=None,
    burn: int = 500,
    steps: int = 1500,
    thin: int = 5,
    swap_every: int = 1,
    n_blocks: int = 10,
    seed=0,
) -> EvidenceResult:
    """Marginal likelihood ln Z of B problems by thermodynamic integration.

    ln Z = int_0^1 E_beta[ln L] d beta, E_beta over the power posterior
    p_beta proportional to prior x L^beta (Friel & Pettitt 2008, eq. 6). All
    K rungs of all B problems are K x B problems of one
    :class:`bayesgloss.sampling.BatchedEnsemble`; every ``swap_every`` steps
    the walkers of neighbouring rungs (walker w of rung k with walker w of rung
    k+1, even and odd pairs in turn) swap with probability
    min(1, exp((beta_k+1 - beta_k)(ln L_k - ln L_k+1))) (parallel tempering;
    each rung keeps its distribution).

    Quadrature (:func:`power_ladder`): from beta_1 on, E_beta[ln L] as a
    cubic Hermite interpolant in ln beta of the rung means and their slopes
    (the variance correction of Friel, Hurn & Wyse 2014, eq. 8, in ln beta),
    integrated exactly; below beta_1, beta_1 E_beta1[ln L] (the rung at
    beta = 0, the prior, is sampled only to carry walkers between modes and
    its size counts as quadrature error). Uncertainty: the Monte Carlo
    standard error
    by batch means (the integral from each of ``n_blocks`` contiguous blocks
    of the production run; swaps correlate neighbouring rungs, so rung-wise
    errors cannot simply be added) combined with a quadrature error, the
    Richardson estimate |I_K - I_K/2| / 15 of the fourth-order rule from
    the ladder with every other rung.

    Parameters
    ----------
    log_prior, log_likelihood : callable
        theta (B, K', P) -> (B, K'); normalised prior; any K'.
    start : array_like (B, W, P)
        Starting walkers (copied to every rung).
    betas : array_like (K,), optional
        Increasing, from 0 to 1, even length (default :func:`power_ladder`).
    burn, steps, thin : int
        Steps discarded, steps kept, and the steps between stored ln L.
    swap_every : int
        Steps between swap attempts (1: the most mixing; each attempt costs
        one more likelihood evaluation of every walker).
    n_blocks : int
        Blocks of the batch-means error.
    seed : int or numpy.random.Generator
    """
    rng = np.random.default_rng(seed)
    betas = power_ladder() if betas is None else np.asarray(betas, dtype=float)
    if betas[0] != 0 or betas[-1] != 1 or np.any(np.diff(betas) <= 0) or len(betas) % 2:
        raise ValueError("betas must increase from 0 to 1 with an even number of rungs")
    start = np.asarray(start, dtype=float)
    b, w, p = start.shape
    k = len(betas)
    beta_col = np.repeat(betas, b)  # problem index = rung * B + b

    def prior_of(th):
        return _unfold(log_prior(_fold(th, k)), k)

    def loglik_of(th):
        return _unfold(log_likelihood(_fold(th, k)), k)

    def log_prob(th):
        lp = prior_of(th)
        ok = np.isfinite(lp)
        if not np.any(ok):
            return lp
        ll = loglik_of(th)
        with np.errstate(invalid="ignore"):
            out = np.where(ok, lp + np.where(ok, beta_col[:, None] * ll, 0.0), -np.inf)
        return np.where(np.isnan(out), -np.inf, out)

    ens = sampling.BatchedEnsemble(log_prob, rng=rng)
    coords = np.tile(start, (k, 1, 1))
    coords += 1e-3 * rng.standard_normal(coords.shape) * np.std(start, axis=1, keepdims=True).max()
    log_p = log_prob(coords)
    bad = ~np.isfinite(log_p)
    coords[bad] = np.tile(start, (k, 1, 1))[bad]
    log_p = log_prob(coords)
    n_keep = steps // thin
    lls = np.empty((n_keep, k * b, w))
    swaps = np.zeros(k - 1)
    tries = np.zeros(k - 1)
    for t in range(burn + steps):
        ens.step(coords, log_p)
        store = t >= burn and (t - burn) % thin == 0 and (t - burn) // thin < n_keep
        if not store and (t + 1) % swap_every:
            continue
        ll = loglik_of(coords)  # (K*B, W)
        if store:
            lls[(t - burn) // thin] = ll
        if (t + 1) % swap_every:
            continue
        # parallel-tempering swaps between neighbouring rungs
        lpr = prior_of(coords)
        lo = np.arange((t // swap_every) % 2, k - 1, 2)
        i = (lo[:, None] * b + np.arange(b)).ravel()
        j = i + b
        d_beta = (beta_col[j] - beta_col[i])[:, None]
        with np.errstate(invalid="ignore", over="ignore"):
            acc = np.log(rng.random((len(i), w))) < d_beta * (ll[i] - ll[j])
        acc &= np.isfinite(ll[i]) & np.isfinite(ll[j])
        for arr in (coords, ll, lpr):
            ai, aj = arr[i], arr[j]
            mask = acc[..., None] if arr.ndim == 3 else acc
            arr[i], arr[j] = np.where(mask, aj, ai), np.where(mask, ai, aj)
        with np.errstate(invalid="ignore"):
            log_p[:] = np.where(np.isfinite(lpr), lpr + beta_col[:, None] * ll, -np.inf)
        if t >= burn:
            swaps[lo] += acc.reshape(len(lo), b * w).mean(1)
            tries[lo] += 1
    lls = lls.reshape(n_keep, k, b, w)
    mean = lls.mean(axis=(0, 3))  # (K, B)
    var = lls.var(axis=(0, 3), ddof=1)
    tau = thin * sampling.integrated_time(lls.reshape(n_keep, k * b, w, 1))[..., 0]
    tau = np.nan_to_num(tau.reshape(k, b), nan=1.0)
    ess = np.clip(n_keep * thin * w / np.maximum(tau, 1.0), 2.0, n_keep * w)
    # rung 0 (the prior) carries the walkers between modes; the integral
    # starts at beta_1: int_0^beta1 E d beta lies in [beta_1 E_0, beta_1 E_1]
    # (E_beta increases with beta); beta_1 E_1 is taken and its size counted
    # as quadrature error
    lo, rest = betas[1], slice(1, None)
    full, weights = _hermite_quadrature(betas[rest], mean[rest], var[rest])
    half, _ = _hermite_quadrature(betas[rest][::2], mean[rest][::2], var[rest][::2])
    head = lo * mean[1]
    full = full + head
    # batch means in time: swaps correlate neighbouring rungs, so the
    # integral's Monte Carlo error is taken from its value over time blocks
    blocks = np.array_split(np.arange(n_keep), n_blocks)
    per_block = np.stack([(weights * lls[blk][:, rest].mean(axis=(0, 3))).sum(0) for blk in blocks])
    mc_se = per_block.std(axis=0, ddof=1) / np.sqrt(n_blocks)
    quad = np.abs(full - head - half) / 15.0 + np.abs(head)
    return EvidenceResult(
        full,
        np.sqrt(mc_se**2 + quad**2),
        mc_se,
        quad,
        betas,
        mean,
        var,
        ess,
        swaps / np.maximum(tries, 1),
    )


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
# sky type as an unknown


def sky_posterior(log_z: dict, *, log_z_se: dict | None = None) -> dict:
    """Posterior probabilities of candidate skies from their evidence.

    p(sky | y) = Z_sky / sum Z (equal prior over the candidates).

    Parameters
    ----------
    log_z : dict
        ``sky -> ln Z`` (scalar, or summed over independent facets).
    log_z_se : dict, optional
        Standard uncertainties of ln Z; the probabilities' spread under them
        is reported as ``prob_sd`` (delta method).

    Returns
    -------
    dict
        ``prob`` (sky -> probability), ``best``, ``log_bf_best_vs_next``.
    """
    skies = list(log_z)
    z = np.array([float(log_z[s]) for s in skies])
    prob = np.exp(z - special.logsumexp(z))
    out = {"prob": dict(zip(skies, prob.tolist(), strict=True))}
    order = np.argsort(-z)
    out["best"] = skies[order[0]]
    out["log_bf_best_vs_next"] = float(z[order[0]] - z[order[1]]) if len(z) > 1 else None
    if log_z_se is not None:
        se = np.array([float(log_z_se[s]) for s in skies])
        # d p_i / d lnZ_j = p_i (delta_ij - p_j)
        jac = np.diag(prob) - np.outer(prob, prob)
        out["prob_sd"] = dict(zip(skies, np.sqrt((jac**2) @ se**2).tolist(), strict=True))
    return out


def marginal_gamma(gamma_draws: dict, prob: dict, *, n: int = 4000, seed=0) -> np.ndarray:
    """Draws of gamma with the sky marginalised: the mixture of the per-sky
    posteriors weighted by the skies' posterior probabilities.

    Parameters
    ----------
    gamma_draws : dict
        ``sky -> draws`` (..., S): draws of gamma under each sky (the last
        axis the draws, leading axes e.g. facets).
    prob : dict
        ``sky -> probability``.
    """
    rng = np.random.default_rng(seed)
    skies = list(gamma_draws)
    p = np.array([prob[s] for s in skies], dtype=float)
    p /= p.sum()
    pick = rng.choice(len(skies), size=n, p=p)
    out = None
    for i, s in enumerate(skies):
        g = np.asarray(gamma_draws[s], dtype=float)
        if out is None:
            out = np.empty(g.shape[:-1] + (n,))
        sel = np.nonzero(pick == i)[0]
        if len(sel):
            out[..., sel] = g[..., rng.integers(0, g.shape[-1], len(sel))]
    return out


__all__ += ["marginal_gamma"]


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


def format_comparison(res: dict, name, level: str = "object") -> str:
    """The comparison table of :func:`compare_bundle` as text."""
    out = [
        f"{name}: model comparison, {level} level, {len(res['facets'])} facets (PSIS-LOO: "
        + ("leave-one-facet-out" if level == "object" else "leave-one-frame-out")
        + ")",
        f"{'model':36s} {'elpd_loo':>10} {'se':>7} {'d_elpd':>8} {'dse':>7} "
        f"{'weight':>6} {'k_max':>6} {'k>0.7':>6}  {'ln Z':>10} {'se':>6} {'ln BF':>8}",
    ]
    ev = {e["model"]: e for e in res["evidence"]}
    for r in res["loo"]["table"]:
        e = ev[r["model"]]
        flag = "  WARNING: Pareto k > 0.7" if r["warning"] else ""
        out.append(
            f"{r['model']:36s} {r['elpd_loo']:10.1f} {r['se']:7.1f} {r['elpd_diff']:8.1f} "
            f"{r['dse']:7.1f} {r['weight']:6.3f} {r['pareto_k_max']:6.2f} "
            f"{r['pareto_k_high']:>3}/{r['n_terms']:<3} {e['log_z']:10.1f} {e['se']:6.2f} "
            f"{e['log_bf_vs_best']:8.1f}{flag}"
        )
    out.append("ln BF: ln Z of the model minus ln Z of the best (thermodynamic integration)")
    for sky_name, rows in res["savage_dickey"].items():
        vals = ", ".join(("<= " if r["bound"] else "") + f"{r['log_bf01']:.2f}" for r in rows[:10])
        more = " ..." if len(rows) > 10 else ""
        out.append(f"Savage-Dickey ln BF(lambert : lambert+phong), {sky_name}: {vals}{more}")
    probs = ", ".join(f"{k} {v:.3f}" for k, v in res["sky"]["prob"].items())
    out.append(f"sky posterior (equal priors): {probs}")
    not_conv = [k for k, v in res["converged"].items() if not v]
    if not_conv:
        out.append(
            f"WARNING: not converged (R-hat >= 1.01 or run < 50 autocorrelation times): "
            f"{', '.join(not_conv)}"
        )
    return "\n".join(out)

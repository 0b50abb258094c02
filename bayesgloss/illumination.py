"""Per-frame illumination: each frame's sun and sky brightness, and exposure, as unknowns.

A bundle gives the sun's position in every frame, never how bright the sun
and the sky were, nor (for most cameras) the exposure (the bundle spec,
"What the estimator may not assume"). All facets of an object see the same
sun and sky in a frame, so the object itself is the light probe (Sunkavalli
et al. 2008 split time-lapses into per-frame sun and sky parts; Lalonde et
al. 2009 estimate per-frame sun and sky for webcams).

The forward model is linear in the incident radiance, so the bases of
:mod:`bayesgloss.render` split exactly into a sun part (the solar disc and
the ground it lights) and a sky part (the sky dome and the ground it
lights), :func:`illumination_bases`. For facet f in frame t

    mu_ft = s_f e_t [a_t S_ft + b_t sum_k w_tk K^k_ft],
    S = (1 - gamma_f) D^sun + gamma_f G^sun(n_f),  K^k = (1 - gamma_f) D^k + gamma_f G^k(n_f),

with a_t and b_t the sun's and the sky's brightness relative to the sky
model's prediction, e_t the frame's exposure relative to the others (1
where the bundle's encoding is ``linear-radiance`` or ``frames[].exposure``
gives it), s_f the facet's scale (albedo, units). The sky's shape is a
per-frame mixture of K sky models (by default gensky's clear, intermediate
and overcast skies; each scaled to the first one's diffuse horizontal
irradiance in each frame, so that b_t keeps its meaning), with weights w_t
on the simplex: the model is linear in its bases for any shape in between,
and each frame finds its own shape (a clear, hazy, intermediate or overcast
sky, the circumsolar brightening of a hazy or intermediate sky included)
instead of being told one. The mixture nests every one of its sky models,
so the posterior of the weights says which shape the object saw, and
gloss is averaged over the shapes the data allow (a continuous relaxation
of averaging over discrete sky families by evidence, at the cost of one
fit). The latent coordinates of a frame are ``(log e_t, log a_t, log b_t,
u_t1, ..., u_t(K-1))``, u_tk = log(w_tk / w_t0); with one sky model the
fourth coordinate is a fixed, unused slot (so there are always at least 4).

Noise: relative, sd = sigma_f (mu_ft + c_f), with the floor c_f =
``FLOOR_FRACTION`` x the facet's largest observation (fixed by the data, so
that the likelihood depends on s_f, e_t, a_t, b_t only through their
products, and frames are independent given sigma). sigma_f is integrated
out exactly under its log-uniform prior for the facet moves
(:func:`log_likelihood_sigma_marginal`, the formula of
:func:`bayesgloss.likelihood.log_likelihood_sigma_marginal`) and drawn from
its conditional for the frame moves. The one-material model has one sigma
for all facets (:func:`log_likelihood_shared_sigma`).

Priors (:class:`IlluminationPriors`): log a_t a two-part mixture, a clear
sun near the model's (weight 0.8, N(0, 0.35^2): haze and the model's
turbidity), and a sun dimmed or hidden by cloud (weight 0.2, N(-2.5,
1.5^2): down to a few per cent); log b_t ~ N(0, 0.7^2) (a sky half or
twice as bright at 1 sd: haze, broken cloud); w_t uniform on the simplex
(Dirichlet(1, ..., 1): in the u coordinates, log density sum_k log w_tk);
log e_t ~ N(0, 2^2) where the exposure is unknown. The one-material model
draws the unknown exposures about the day's instead (stop 46,
``IlluminationPriors.day_exposure``): log e_t ~ N(mu_e, sd_e^2), mu_e ~
N(0, 2^2), log sd_e uniform from log 0.01 to log 3, since the bundle
spec's camera keeps its exposure unless it is known to vary it; a camera
that kept it gives sd_e near 0.01 and frames tied to one exposure, an
automatic one a wider sd_e. The one-material model
(:func:`log_prior_material`) gives the sun a third, hidden component
(N(-9, 2^2): below the noise of any curve) and lets the day choose the
three components' weights (uniform on the simplex), so that a day whose
every frame is overcast is as plausible a priori as a clear one
(:func:`log_prior_frames` with ``log_sun_weights``). With ``point_mass``,
the hidden component is instead a point mass at a_t = 0 (log a_t = -inf: no
direct light at all), the model of the Hamiltonian sampler
(:mod:`bayesgloss.sampling.hamiltonian`): the normal one's posterior is
pressed against the wall where the sun begins to show in the most precise
facet's curve, whose curvature grows as a^2.
The facets' priors are those of :class:`bayesgloss.likelihood.Priors`.
"""

from __future__ import annotations

import dataclasses
import functools
from collections import namedtuple
from dataclasses import dataclass, field

import numpy as np
from scipy import special

from . import fresnel as fr
from . import likelihood as lk
from . import lobes, pool, render
from .gamma_interval import log_gamma_interval, tail_cuts

__all__ = [
    "IlluminationPriors",
    "IlluminationBases",
    "illumination_bases",
    "split_sky",
    "JointData",
    "joint_data",
    "log_prior_facets",
    "log_prior_frames",
    "log_prior_frames_along",
    "log_prior_material",
    "log_sun_weights",
    "material_m_center",
    "EXPOSURE_LOG_SPREAD",
    "HYPER",
    "hyper_size",
    "exposure_day",
    "log_prior_exposure_mean",
    "MATERIAL_M_SD",
    "MATERIAL_LOG_TAU",
    "unit_parts",
    "frame_weights",
    "predict",
    "log_likelihood_sigma_marginal",
    "log_likelihood_shared_sigma",
    "draw_shared_log_sigma",
    "frame_log_likelihood",
    "entry_log_likelihood",
    "pointwise_log_likelihood",
    "sample_prior",
    "sample_prior_material",
    "draw_log_sun",
    "simulate",
    "LATENTS",
    "latent_names",
    "log_shape_weights",
]

#: The latent coordinates of each frame, in order (then one log weight ratio
#: per further sky model: :func:`latent_names`).
LATENTS = ("log_exposure", "log_sun", "log_sky", "log_shape_ratio_1")
FLOOR_FRACTION = 0.01


@dataclass(frozen=True)
class IlluminationPriors:
    """Priors of the per-frame latents (module docstring). Natural logs.

    ``day_exposure``: where the exposure is unknown, the one-material model
    draws each frame's log e_t from the day's N(mu_e, sd_e^2), mu_e ~ N(0,
    ``exposure_sd``^2) and log sd_e uniform on :data:`EXPOSURE_LOG_SPREAD`
    (:func:`log_prior_material`), instead of N(0, ``exposure_sd``^2) for
    each frame alone: the bundle spec's camera keeps its exposure unless it
    is known to vary it, and the object then tells how much it varied.
    """

    sun_clear_sd: float = 0.35
    sun_cloud_weight: float = 0.2
    sun_cloud_mean: float = -2.5
    sun_cloud_sd: float = 1.5
    sun_hidden_mean: float = -9.0
    sun_hidden_sd: float = 2.0
    sky_sd: float = 0.7
    exposure_sd: float = 2.0
    day_exposure: bool = True


def split_sky(day):
    """The sun part and the sky part of a daylight sky.

    Parameters
    ----------
    day : bayesgloss.sky.DaylightSky

    Returns
    -------
    sun_only, sky_only : DaylightSky
        ``sun_only``: the solar disc, no sky dome (a ground plane in the
        forward model is then lit by the sun alone); ``sky_only``: the sky
        dome with the disc's radiance set to 0. The forward model's bases of
        the two sum to those of ``day`` (it is linear in the radiance).
    """
    sun_only = dataclasses.replace(
        day, ground_radiance=np.zeros_like(day.ground_radiance), parameters=None
    )
    sky_only = dataclasses.replace(day, solar_radiance=np.zeros_like(day.solar_radiance))
    return sun_only, sky_only


@dataclass(frozen=True)
class IlluminationBases:
    """Bases split by source: index 0 the sun, then one per sky model.

    Attributes
    ----------
    diffuse : ndarray (P, F, T)
        D^sun, then D^k of each sky model [W sr^-1 m^-2]; P = 1 + max(K, 2)
        sources (with one sky model, a copy of it as a second).
    glossy : ndarray (P, F, N, T)
        G^sun, then G^k of each sky model on the exponent table [W sr^-1 m^-2].
    exponents : ndarray (N,)
    shapes : int
        Sky models, K.
    log_sun_ratio : ndarray (K, T) or None
        log of each sky model's own solar radiance over the first's (where
        a model draws no sun, the cloud component's mean of the sun prior):
        where each model would put log a_t, for the starts of the sampler.
    fresnel : bayesgloss.fresnel.FresnelTerms or None
        The geometry's Fresnel estimates (:func:`bayesgloss.fresnel.fresnel_terms`).
    """

    diffuse: np.ndarray
    glossy: np.ndarray
    exponents: np.ndarray
    shapes: int = 1
    log_sun_ratio: np.ndarray | None = None
    fresnel: fr.FresnelTerms | None = None

    def total(self) -> render.FacetBases:
        """The bases at the model's brightness (a = b = e = 1, even weights)."""
        mix = _even_mix(len(self.diffuse))
        return render.FacetBases(
            np.tensordot(mix, self.diffuse, 1), np.tensordot(mix, self.glossy, 1), self.exponents
        )

    def take(self, facets=slice(None), frames=slice(None)) -> IlluminationBases:
        """The bases of a subset of facets and frames."""
        ratio = self.log_sun_ratio
        return IlluminationBases(
            self.diffuse[:, facets][..., frames],
            self.glossy[:, facets][..., frames],
            self.exponents,
            self.shapes,
            None if ratio is None else ratio[:, frames],
            None if self.fresnel is None else self.fresnel.take(facets, frames),
        )


def _node_rows(g, less=0.0) -> np.ndarray:
    """g - ``less`` at each node of the exponent table and g's step to the
    next node (0 at the last), (2, P, F N, T) for g (P, F, N, T): the rows
    :func:`unit_parts` gathers, each source's block contiguous."""
    nxt = np.concatenate([g[:, :, 1:], g[:, :, -1:]], axis=2)
    rows = np.stack([g - less, nxt - g])  # (2, P, F, N, T)
    return np.ascontiguousarray(rows.reshape(2, len(g), -1, g.shape[-1]))


def _even_mix(sources: int) -> np.ndarray:
    """Weights of the sources at the model's brightness: the sun 1, the sky
    models evenly."""
    return np.array([1.0] + [1.0 / (sources - 1)] * (sources - 1))


#: Fewest facets (points) a worker of :func:`illumination_bases` is given:
#: below about this many a worker's start costs more than its share saves.
MIN_FACETS_A_BLOCK = 8


def illumination_bases(
    geometry,
    day,
    exponents=render.DEFAULT_EXPONENTS,
    others=(),
    *,
    lobe_family="phong",
    fresnel="radiance",
    jobs=1,
    **kwargs,
) -> IlluminationBases:
    """Forward-model bases of the sun of ``day``, its sky, and other skies'.

    Parameters
    ----------
    geometry : bayesgloss.render.ViewGeometry
    day : bayesgloss.sky.DaylightSky
        The first sky model, and the sun.
    exponents : array_like
        Glossy exponent table.
    others : DaylightSky or sequence of them
        Further sky models (their suns ignored), each scaled in each frame
        to the first one's diffuse horizontal irradiance; none: one sky model.
    lobe_family : {"phong", "ward", "ggx"}
        The glossy lobe's family (:mod:`bayesgloss.lobes`), tabulated on the
        Phong-equivalent ``exponents``.
    fresnel : {"radiance", "schlick", "schlick-lobe"}
        Whose Fresnel rise the bases' Fresnel terms hold
        (:data:`bayesgloss.fresnel.FRESNEL_RISES`), for a one-material model
        with that Fresnel model; ``"schlick-lobe"`` (GGX only) adds G^S of
        each source (:attr:`bayesgloss.fresnel.FresnelTerms.glossy_rise`).
    jobs : int
        Worker processes (:func:`bayesgloss.pool.process_pool`): the facets
        are split into that many blocks, each block's bases of every source
        found in a worker of its own (blocks of at least
        :data:`MIN_FACETS_A_BLOCK`). The bases are the same whatever ``jobs``
        (each facet's quadrature is its own), but for the last bits of a
        matrix product (the workers' BLAS runs on one thread).
    **kwargs
        For :func:`bayesgloss.render.facet_bases` (``ground``,
        ``ground_reflectance``, ``lobe``...). ``occlusion`` (a
        :class:`bayesgloss.render.Occlusion`, what a non-convex object's mesh
        hides from each facet) also scales the sun's Fresnel term by each
        facet's sunlit fraction.
    """
    from .sky import horizontal_irradiance

    if not isinstance(others, (list, tuple)):
        others = (others,)
    if fresnel in fr.IN_LOBE and lobe_family != fr.IN_LOBE[fresnel]:
        raise ValueError(
            f"Fresnel model {fresnel!r} takes the rise inside the "
            f"{fr.IN_LOBE[fresnel]!r} lobe, not the {lobe_family!r} lobe"
        )
    args = (day, exponents, tuple(others), lobe_family, fresnel in fr.IN_LOBE)
    n_blocks = max(1, min(jobs, len(geometry) // MIN_FACETS_A_BLOCK))
    blocks = np.array_split(np.arange(len(geometry)), n_blocks)
    if len(blocks) == 1:
        d_parts, g_parts, r_parts = _source_bases(geometry, *args, kwargs)
    else:  # each block of facets in a worker of its own, joined along the facets
        occlusion = kwargs.get("occlusion")
        block_kw = [
            kwargs if occlusion is None else kwargs | {"occlusion": occlusion.take(rows)}
            for rows in blocks
        ]
        with pool.process_pool(len(blocks)) as workers:
            done = list(
                workers.map(
                    _source_bases,
                    [geometry.take(rows) for rows in blocks],
                    *([a] * len(blocks) for a in args),
                    block_kw,
                )
            )
        d_parts, g_parts, r_parts = (
            None if done[0][i] is None else np.concatenate([b[i] for b in done], axis=1)
            for i in range(3)
        )
    e_a = horizontal_irradiance(split_sky(day)[1], include_sun=False)
    sun_a = np.broadcast_to(day.solar_radiance, e_a.shape)
    ratios = [np.zeros(e_a.shape)]
    for second in others:
        with np.errstate(invalid="ignore", divide="ignore"):
            r = np.log(np.broadcast_to(second.solar_radiance, e_a.shape) / sun_a)
        ratios.append(np.where(np.isfinite(r), r, IlluminationPriors().sun_cloud_mean))
    sun_dir, e_sun = render._sun_terms(day)  # the disc's normal irradiance, 0 below the horizon
    terms = _sunlit(fr.fresnel_terms(geometry, sun_dir, e_sun, fresnel), kwargs.get("occlusion"))
    if r_parts is not None:
        terms = dataclasses.replace(terms, glossy_rise=r_parts)
    exps = np.sort(np.atleast_1d(np.asarray(exponents, dtype=float)))
    return IlluminationBases(d_parts, g_parts, exps, 1 + len(others), np.stack(ratios), terms)


def _source_bases(geometry, day, exponents, others, lobe_family, with_rise, kwargs):
    """The bases of :func:`illumination_bases` by source (the sun of ``day``,
    its sky, each of ``others``' skies scaled to its diffuse horizontal
    irradiance; with one sky model a copy of it second): diffuse (P, F, T),
    glossy (P, F, N, T), and with ``with_rise`` the GGX lobe's Schlick rise
    G^S (P, F, N, T), else None."""
    from .sky import horizontal_irradiance

    sun_only, sky_a = split_sky(day)

    def bases(d):
        return lobes.facet_bases(geometry, d, exponents, family=lobe_family, **kwargs)

    rise = None
    if with_rise:  # G^S of each source beside its glossy part
        kept = ("ground", "ground_reflectance", "occlusion")

        def rise(d):
            return lobes.ggx_schlick_rise_basis(
                geometry, d, exponents, **{k: v for k, v in kwargs.items() if k in kept}
            )

    parts = [bases(d) for d in (sun_only, sky_a)]
    d_parts, g_parts = [p.diffuse for p in parts], [p.glossy for p in parts]
    r_parts = [] if rise is None else [rise(d) for d in (sun_only, sky_a)]
    if not others:
        d_parts.append(d_parts[1])
        g_parts.append(g_parts[1])
        r_parts = r_parts + r_parts[1:2]
    e_a = horizontal_irradiance(sky_a, include_sun=False)
    for second in others:
        sky_b = split_sky(second)[1]
        other = bases(sky_b)
        e_b = horizontal_irradiance(sky_b, include_sun=False)
        with np.errstate(invalid="ignore", divide="ignore"):
            factor = np.where(e_b > 0, e_a / e_b, 0.0)  # (T,)
        d_parts.append(other.diffuse * factor)
        g_parts.append(other.glossy * factor)
        if rise is not None:
            r_parts.append(rise(sky_b) * factor)
    return np.stack(d_parts), np.stack(g_parts), np.stack(r_parts) if r_parts else None


def _sunlit(terms, occlusion):
    """Fresnel terms with the sun's part in the object's own shadow taken out."""
    if occlusion is None:
        return terms
    return dataclasses.replace(terms, sun_direct=terms.sun_direct * occlusion.sunlit_fraction)


@dataclass(frozen=True)
class JointData:
    """Observations and split bases of F facets over T frames.

    Attributes
    ----------
    y : ndarray (F, T)
        Linear observations, 0 where invalid.
    valid : ndarray (F, T) of bool
    floor : ndarray (F,)
        c_f on the observed scale.
    diffuse : ndarray (P, F, T)
    glossy : ndarray (P, F, N, T)
    log_n_grid : ndarray (N,)
    log_s_center : ndarray (F,)
        Prior centre of log s (the data's scale relative to the total bases).
    log_exposure : ndarray (T,) or None
        Known log exposure of each frame, or None where it is unknown.
    priors : bayesgloss.likelihood.Priors
    frame_priors : IlluminationPriors
    shapes : int
        Sky models, K (1: no weights).
    log_sun_ratio : ndarray (K, T) or None
        :attr:`IlluminationBases.log_sun_ratio` (starts only).
    fresnel : bayesgloss.fresnel.FresnelTerms or None
        Where set, the one-material model's glossy basis has Radiance's
        Fresnel raise with an unknown strength and albedo (theta's columns
        :data:`bayesgloss.fresnel.FRESNEL_COLUMNS`); None: no Fresnel term.
    censored : ndarray (F, T) of bool, or None
        Valid entries whose ``y`` is only a lower bound of the value (pixels
        clipped at the top code, :func:`bayesgloss.estimate.observations`):
        their likelihood is the noise's survival function at the bound
        (:func:`pointwise_log_likelihood`; the sampler's,
        :mod:`bayesgloss.sampling.censored`). None: no such entry.
    """

    y: np.ndarray
    valid: np.ndarray
    floor: np.ndarray
    diffuse: np.ndarray
    glossy: np.ndarray
    log_n_grid: np.ndarray
    log_s_center: np.ndarray
    log_exposure: np.ndarray | None
    priors: lk.Priors = field(default_factory=lk.Priors)
    frame_priors: IlluminationPriors = field(default_factory=IlluminationPriors)
    shapes: int = 1
    log_sun_ratio: np.ndarray | None = None
    fresnel: fr.FresnelTerms | None = None
    censored: np.ndarray | None = None

    @property
    def sources(self) -> int:
        """P: the sun and the sky models (at least 2 of them, module docstring)."""
        return len(self.diffuse)

    @property
    def n_latents(self) -> int:
        """Latent coordinates of each frame: 3 + the P - 2 weight ratios."""
        return self.sources + 1

    @property
    def exposure_direction(self) -> np.ndarray:
        """(L,): exposure up, sun and sky down, the direction of the frame
        latents along which the curves are unchanged (they depend on e_t a_t
        and e_t b_t only), as the exposure moves of :mod:`bayesgloss.sampling`
        take it."""
        out = np.zeros(self.n_latents)
        out[:3] = 1.0, -1.0, -1.0
        return out

    @property
    def free(self) -> np.ndarray:
        """Which of the frame latents (:func:`latent_names`) are unknowns, (L,) of bool."""
        ratios = [self.shapes >= 2] * (self.sources - 2)
        return np.array([not self.exposure_known, True, True, *ratios])

    @property
    def shape(self) -> tuple[int, int]:
        """(F, T)."""
        return self.y.shape

    @property
    def exposure_known(self) -> bool:
        return self.log_exposure is not None

    def curve_data(self) -> lk.CurveData:
        """The facets alone at the model's brightness (for starts and constants)."""
        mix = _even_mix(self.sources)
        return lk.CurveData(
            self.y,
            self.valid,
            np.zeros_like(self.valid),
            np.tensordot(mix, self.diffuse, 1),
            np.tensordot(mix, self.glossy, 1),
            self.log_n_grid,
            self.log_s_center,
            priors=self.priors,
        )

    @functools.cached_property
    def tables(self) -> np.ndarray:
        """G - D and its step to the next node, of each source that
        :func:`unit_parts` computes (P, or 2 with one sky model) at every
        (facet, node), (2, P, F N, T): one gather per walker gives every
        source's rows, each source's block contiguous."""
        p = self.sources if self.shapes >= 2 else 2
        return _node_rows(self.glossy[:p], self.diffuse[:p, :, None, :])

    @functools.cached_property
    def rise_tables(self) -> np.ndarray | None:
        """G^S of the Fresnel terms (:attr:`bayesgloss.fresnel.FresnelTerms.glossy_rise`)
        and its step to the next node, laid out as :attr:`tables`, (2, P, F N,
        T); None where the Fresnel model has no rise inside the lobe."""
        if self.fresnel is None or self.fresnel.glossy_rise is None:
            return None
        p = self.sources if self.shapes >= 2 else 2
        return _node_rows(self.fresnel.glossy_rise[:p])

    @functools.cached_property
    def relative_weights(self) -> np.ndarray:
        """Least-squares weights of relative noise at the data, 1 / (|y| + c)^2,
        0 where invalid, (F, T) (for starts and proposal scales)."""
        return np.where(self.valid, 1.0 / (np.abs(self.y) + self.floor[:, None]) ** 2, 0.0)

    @functools.cached_property
    def sigma_constants(self):
        """k = T_f / 2, the constant of the sigma-marginal likelihood, and the
        tail cuts of :func:`bayesgloss.gamma_interval.log_gamma_interval`, (F,) each."""
        return _sigma_constants(0.5 * self.valid.sum(axis=1).astype(float), self.priors)

    @functools.cached_property
    def shared_sigma_constants(self):
        """:attr:`sigma_constants` for one sigma of all facets, (1,) each
        (:func:`log_likelihood_shared_sigma`)."""
        return _sigma_constants(np.array([0.5 * float(self.valid.sum())]), self.priors)


def _sigma_constants(k, priors: lk.Priors):
    """(k, the constant of the sigma-marginal likelihood, the tail cuts of
    :func:`~bayesgloss.gamma_interval.log_gamma_interval`) for orders k."""
    la, lb = priors.log_sigma
    with np.errstate(divide="ignore", invalid="ignore"):
        const = -k * np.log(np.pi) + special.gammaln(k) - np.log(2.0 * (lb - la))
    return k, const, tail_cuts(k)


def joint_data(
    y,
    valid,
    bases: IlluminationBases,
    *,
    exposure=None,
    priors: lk.Priors | None = None,
    frame_priors: IlluminationPriors | None = None,
    fresnel: str = "none",
    censored=None,
) -> JointData:
    """Assemble the joint model's inputs.

    Parameters
    ----------
    y : array_like (F, T)
        Linear facet observations.
    valid : array_like (F, T) of bool
    bases : IlluminationBases
        Exponent table uniform in log n.
    exposure : array_like (T,) or None
        Known relative exposure of each frame (a linear factor, any common
        scale); None: unknown, inferred.
    priors, frame_priors
        Facet and frame priors (defaults: :class:`bayesgloss.likelihood.Priors`,
        :class:`IlluminationPriors`).
    fresnel : {"none", "radiance", "schlick"}
        The one-material model's Fresnel model (:data:`bayesgloss.fresnel.FRESNEL_MODELS`).
    censored : array_like (F, T) of bool, optional
        Entries of ``valid`` whose ``y`` is a lower bound (:attr:`JointData.censored`).
    """
    fr.check_fresnel_model(fresnel)
    if fresnel != "none" and bases.fresnel is None:
        raise ValueError("Fresnel model needs bases with Fresnel terms (illumination_bases)")
    if fresnel != "none" and bases.fresnel.model != fresnel:
        raise ValueError(
            f"Fresnel model {fresnel!r} needs bases with its terms; these hold "
            f"{bases.fresnel.model!r}'s (illumination_bases(..., fresnel={fresnel!r}))"
        )
    y = np.asarray(y, dtype=float)
    valid = np.asarray(valid, dtype=bool) & np.isfinite(y)
    total = bases.total()
    cd = lk.curve_data(y, valid, total, priors=priors)
    y0 = np.where(valid, y, 0.0)
    floor = FLOOR_FRACTION * np.max(np.where(valid, np.abs(y0), 0.0), axis=1)
    floor = np.maximum(floor, 1e-30)
    log_e = None
    if exposure is not None:
        e = np.asarray(exposure, dtype=float)
        if e.shape != (y.shape[1],) or not np.all(np.isfinite(e) & (e > 0)):
            raise ValueError(f"exposure must be T = {y.shape[1]} positive numbers, got {e}")
        log_e = np.log(e) - np.mean(np.log(e))
    cens = None if censored is None else np.asarray(censored, dtype=bool)
    if cens is not None and cens.shape != valid.shape:
        raise ValueError(f"censored must have the shape of y, {valid.shape}, got {cens.shape}")
    cens = None if cens is None else cens & valid
    return JointData(
        y0,
        valid,
        floor,
        np.asarray(bases.diffuse, float),
        np.asarray(bases.glossy, float),
        cd.log_n_grid,
        cd.log_s_center,
        log_e,
        cd.priors,
        frame_priors or IlluminationPriors(),
        bases.shapes,
        bases.log_sun_ratio,
        bases.fresnel if fresnel != "none" else None,
        cens if cens is not None and cens.any() else None,
    )


# --------------------------------------------------------------------------
# priors


def log_prior_facets(theta, data: JointData) -> np.ndarray:
    """Log prior of facet coordinates (gamma, log n, log s), (E, F, W) for theta
    (E, F, W, >= 3); -inf outside the support."""
    p = data.priors
    gamma, log_n, log_s = theta[..., 0], theta[..., 1], theta[..., 2]
    inside = (gamma >= 0) & (gamma <= 1) & (log_n >= p.log_n[0]) & (log_n <= p.log_n[1])
    lp = -0.5 * ((log_s - data.log_s_center[:, None]) / p.log_s_sd) ** 2
    return np.where(inside, lp, -np.inf)


#: The one-material model (:mod:`bayesgloss.sampling.material`): sd of the
#: prior of m, the facets' mean log scale, about the data's centre (natural log).
MATERIAL_M_SD = 3.0
#: Range of log tau, the sd of the facets' log scales about m, under its
#: log-uniform prior: from 1 % (one paint, the model's geometry right) to a
#: factor of 20 (facets whose albedos tell nothing of each other).
MATERIAL_LOG_TAU = (float(np.log(0.01)), float(np.log(3.0)))


#: Range of log sd_e, the spread of the frames' log exposures about the
#: day's mean under its log-uniform prior (``IlluminationPriors.day_exposure``):
#: from 1 % (a camera that kept its exposure) to a factor of 20 (an
#: automatic exposure through a day whose light changed that much).
EXPOSURE_LOG_SPREAD = (float(np.log(0.01)), float(np.log(3.0)))
#: The one-material model's day-level coordinates (its ``hyper``), in order;
#: the last two only where the exposure is day-level (:func:`hyper_size`).
HYPER = ("m", "log_tau", "sun_weight_ratio_1", "sun_weight_ratio_2", "exposure_mean",
         "log_exposure_spread")  # fmt: skip


def hyper_size(data: JointData) -> int:
    """Day-level coordinates of the one-material model (:data:`HYPER`): 6
    where each frame's unknown exposure is drawn about the day's
    (``IlluminationPriors.day_exposure``), else 4."""
    return 6 if data.frame_priors.day_exposure and not data.exposure_known else 4


def exposure_day(hyper):
    """(mu_e, log sd_e), (..., 2), of a hyper (..., 6); None for (..., 4)."""
    return hyper[..., 4:6] if hyper.shape[-1] > 4 else None


def log_prior_exposure_mean(hyper, data: JointData) -> np.ndarray:
    """Log prior of the day's mean log exposure mu_e, N(0, ``exposure_sd``^2)
    up to its constant, of a hyper (..., 6) (:data:`HYPER`): (...)."""
    return -0.5 * (hyper[..., 4] / data.frame_priors.exposure_sd) ** 2


def material_m_center(data: JointData) -> float:
    """The prior centre of m: the median over facets of the data's log scale."""
    return float(np.median(data.log_s_center))


def log_prior_material(theta, hyper, data: JointData) -> np.ndarray:
    """Log prior of the one-material model's facet and day parts, (E, W), for
    theta (E, F, W, >= 3) (gamma and log n the same for every facet; with
    Fresnel terms, k and log A of :func:`bayesgloss.fresnel.log_prior_fresnel`
    in its columns 4 and 5) and
    hyper (E, W, 4) = (m, log tau, v_1, v_2) or (E, W, 6) with (mu_e, log
    sd_e) (:data:`HYPER`, :func:`hyper_size`): uniform gamma and log n, log
    s_f ~ N(m, tau^2), m ~ N(:func:`material_m_center`, :data:`MATERIAL_M_SD`^2),
    log tau uniform on :data:`MATERIAL_LOG_TAU`, the day's sun weights
    (:func:`log_sun_weights`) uniform on the simplex (Dirichlet(1, 1, 1) in
    the log-ratio coordinates v), mu_e ~ N(0, ``exposure_sd``^2) and log
    sd_e uniform on :data:`EXPOSURE_LOG_SPREAD`; -inf outside the support.
    The frames' priors given these are :func:`log_prior_frames`'."""
    p = data.priors
    gamma, log_n, log_s = theta[:, 0, :, 0], theta[:, 0, :, 1], theta[..., 2]
    m, log_tau = hyper[..., 0], hyper[..., 1]
    lo, hi = MATERIAL_LOG_TAU
    inside = (gamma >= 0) & (gamma <= 1) & (log_n >= p.log_n[0]) & (log_n <= p.log_n[1])
    inside &= (log_tau >= lo) & (log_tau <= hi)
    tau = np.exp(log_tau)
    z = (log_s - m[:, None]) / tau[:, None]
    lp = np.sum(-0.5 * z * z, axis=1) - data.shape[0] * log_tau
    lp = lp - 0.5 * ((m - material_m_center(data)) / MATERIAL_M_SD) ** 2
    if hyper.shape[-1] > 2:  # the day's sun weights, uniform on the simplex
        lp = lp + np.sum(log_sun_weights(hyper), axis=-1)
    if hyper.shape[-1] > 4:  # the day's exposure: mu_e normal, log sd_e uniform
        lp = lp + log_prior_exposure_mean(hyper, data)
        inside &= (hyper[..., 5] >= EXPOSURE_LOG_SPREAD[0]) & (
            hyper[..., 5] <= EXPOSURE_LOG_SPREAD[1]
        )
    k_col, a_col = fr.FRESNEL_COLUMNS
    if data.fresnel is not None and theta.shape[-1] > a_col:  # k and log A, shared
        lp = lp + fr.log_prior_fresnel(theta[:, 0, :, k_col], theta[:, 0, :, a_col])
    return np.where(inside, lp, -np.inf)


def _logsumexp_last(x) -> np.ndarray:
    """log sum exp over the last axis, kept as a length-1 axis (scipy's
    ``logsumexp`` at a tenth of its overhead on the sampler's small arrays:
    it took 40 % of a sweep). The sampler's last axes are 2 to 4 long (sun
    states, sky shapes), where numpy's reductions along them cost more than
    the arithmetic: those are folded elementwise instead, in the order
    ``np.max`` and ``np.sum`` take (the same numbers, bit for bit)."""
    x = np.asarray(x)
    if x.shape[-1] > 4:
        top = np.max(x, axis=-1, keepdims=True)
        top = np.where(np.isfinite(top), top, 0.0)
        with np.errstate(divide="ignore"):
            return top + np.log(np.sum(np.exp(x - top), axis=-1, keepdims=True))
    parts = [x[..., k] for k in range(x.shape[-1])]
    top = parts[0]
    for p in parts[1:]:
        top = np.maximum(top, p)
    top = np.where(np.isfinite(top), top, 0.0)
    total = np.exp(parts[0] - top)
    for p in parts[1:]:
        total += np.exp(p - top)
    with np.errstate(divide="ignore"):
        return (top + np.log(total))[..., None]


def _logsumexp_finite(parts) -> np.ndarray:
    """log sum exp of a few arrays of finite numbers, elementwise: the
    arithmetic of :func:`_logsumexp_last` on its slices, bit for bit, without
    the stacking, the guard against an infinite maximum and the error state
    it needs (on the sampler's smallest objects, 6 facets over 6 frames, the
    frames' priors that call it took a quarter of a sweep)."""
    top = parts[0]
    for p in parts[1:]:
        top = np.maximum(top, p)
    total = np.exp(parts[0] - top)
    for p in parts[1:]:
        total += np.exp(p - top)
    return top + np.log(total)


def _log_softmax_norm(v) -> np.ndarray:
    """log(1 + sum_k e^(v_k)) over the last axis of v (..., K - 1), finite:
    the normaliser of the softmax of (0, v_1, ..., v_(K-1)), (...)."""
    # the first part a scalar 0, not an array of zeros (the same numbers: a
    # fifth of the time went to building the zeros)
    return _logsumexp_finite([0.0] + [v[..., k] for k in range(v.shape[-1])])


def _log_softmax_after_zero(v) -> np.ndarray:
    """The log softmax of (0, v_1, ..., v_(K-1)), (..., K), for v (..., K - 1) finite."""
    u = np.concatenate([np.zeros_like(v[..., :1]), v], axis=-1)
    return u - _log_softmax_norm(v)[..., None]


def log_sun_weights(hyper) -> np.ndarray:
    """log weights of the sun's clear, dimmed and hidden components for the
    day, (..., 3), from the one-material model's hyper (..., 4): the softmax
    of (0, v_1, v_2), its last two coordinates."""
    return _log_softmax_after_zero(hyper[..., 2:4])


def log_prior_frames(
    lam, data: JointData, log_sun_weights=None, point_mass=False, exposure=None
) -> np.ndarray:
    """Log prior of each frame's latents, (..., T) for lam (..., T, L) (module docstring).

    ``log_sun_weights`` (..., 3): the log weights of the sun's clear, dimmed
    and hidden components for the day (the one-material model's day-level
    sun state, :mod:`bayesgloss.sampling.material`); None: the fixed
    two-part mixture (clear 0.8, dimmed 0.2). ``point_mass``: the hidden
    component is a = 0, log a = -inf (its log prior its weight's).
    ``exposure`` (..., 2): the day's (mu_e, log sd_e) (:func:`exposure_day`),
    log e_t ~ N(mu_e, sd_e^2) where the exposure is unknown; None: N(0,
    ``exposure_sd``^2) (its constant left out).
    """
    return _frame_prior_terms(
        lam[..., 0],
        lam[..., 1],
        lam[..., 2],
        lam[..., 3:],
        data,
        log_sun_weights,
        point_mass,
        exposure,
    )


def log_prior_frames_along(
    lam, offsets, direction, data: JointData, log_sun_weights=None, exposure=None
) -> np.ndarray:
    """:func:`log_prior_frames` of the latents moved along a direction by each
    of many offsets, (K, ..., T): ``lam + offsets[..., None] * direction``
    for lam (..., T, L), offsets (K, ..., T) or broadcastable to it,
    direction (L,).

    The same numbers, bit for bit, as :func:`log_prior_frames` of the moved
    array, at a fraction of its cost: each term of the prior is computed on
    the moved latents only where ``direction`` moves them, and once, broadcast
    over the offsets, where it does not (the ridge moves of
    :mod:`bayesgloss.sampling.material` move the exposure, sun and sky along
    17 offsets and never the sky shapes: stop 77 found the shapes' and the
    sun's terms recomputed at every offset took an eighth of a sweep).
    ``exposure`` (..., 2) may carry the offsets' axis too."""
    offsets = np.asarray(offsets, dtype=float)

    def latent(i):
        return lam[..., i] + offsets * direction[i] if direction[i] != 0 else lam[..., i]

    if np.any(np.asarray(direction)[3:] != 0):
        shapes = lam[..., 3:] + offsets[..., None] * direction[3:]
    else:
        shapes = lam[..., 3:]
    out = _frame_prior_terms(
        latent(0), latent(1), latent(2), shapes, data, log_sun_weights, False, exposure
    )
    shape = np.broadcast_shapes(offsets.shape, lam.shape[:-1])
    # where no term the direction moves is in the prior (an exposure known)
    return out if out.shape == shape else np.broadcast_to(out, shape).copy()


def _frame_prior_terms(
    log_e, log_a, log_b, shape_ratios, data: JointData, log_sun_weights, point_mass, exposure
) -> np.ndarray:
    """The sum of :func:`log_prior_frames`'s terms from each latent's own
    array (each of (..., T), the shape ratios (..., T, L - 3)); arrays that
    differ in their leading axes broadcast."""
    q = data.frame_priors
    clear = -0.5 * (log_a / q.sun_clear_sd) ** 2 - np.log(q.sun_clear_sd)
    cloud = -0.5 * ((log_a - q.sun_cloud_mean) / q.sun_cloud_sd) ** 2 - np.log(q.sun_cloud_sd)
    if log_sun_weights is None:
        sun = np.logaddexp(
            clear + np.log1p(-q.sun_cloud_weight), cloud + np.log(q.sun_cloud_weight)
        )
    else:
        w = np.asarray(log_sun_weights)[..., None, :]
        if point_mass:
            seen = _logsumexp_last(np.stack([clear, cloud], -1) + w[..., :2])[..., 0]
            gone = np.isneginf(log_a)
            sun = np.where(gone, np.broadcast_to(w[..., 2], gone.shape), seen)
        else:
            hidden = -0.5 * ((log_a - q.sun_hidden_mean) / q.sun_hidden_sd) ** 2
            hidden -= np.log(q.sun_hidden_sd)
            sun = _logsumexp_finite([clear + w[..., 0], cloud + w[..., 1], hidden + w[..., 2]])
    lp = sun - 0.5 * (log_b / q.sky_sd) ** 2
    if data.shapes >= 2:  # w uniform on the simplex: sum_k log w_k in the u coordinates
        norm = _log_softmax_norm(shape_ratios)
        total = -norm  # log w_0, then each further model's, summed in order
        for k in range(shape_ratios.shape[-1]):
            total = total + (shape_ratios[..., k] - norm)
        lp = lp + total
    if data.exposure_known:
        return lp
    if exposure is None:
        return lp - 0.5 * (log_e / q.exposure_sd) ** 2
    mu, log_sd = exposure[..., 0][..., None], exposure[..., 1][..., None]
    return lp - 0.5 * ((log_e - mu) * np.exp(-log_sd)) ** 2 - log_sd


def log_shape_weights(lam) -> np.ndarray:
    """log w_tk of the sky models, (..., K) for lam (..., 3 + K - 1): the
    softmax of (0, u_1, ..., u_(K-1))."""
    return _log_softmax_after_zero(lam[..., 3:])


def latent_names(data: JointData) -> tuple[str, ...]:
    """Names of each frame's latent coordinates (:data:`LATENTS`, then one log
    weight ratio per further sky model)."""
    return LATENTS[:3] + tuple(f"log_shape_ratio_{k}" for k in range(1, data.sources - 1))


# --------------------------------------------------------------------------
# the likelihood


def unit_parts(theta, data: JointData, tables=None) -> tuple[np.ndarray, ...]:
    """S and each sky model's K^k of the module docstring at unit scale, P
    arrays (E, F, W, T), for theta (E, F, W, >= 2); G linear in log n between
    the table's nodes (with one sky model, its copy second). Where the data
    carry Fresnel terms and theta its columns (k, log A at
    :data:`bayesgloss.fresnel.FRESNEL_COLUMNS`), with the Fresnel raise of
    :func:`bayesgloss.fresnel.fresnel_parts`, or inside the lobe
    (:func:`bayesgloss.fresnel.fresnel_parts_in_lobe`) where the terms carry G^S."""
    rows = data.tables if tables is None else tables
    sources = rows.shape[1]
    n = len(data.log_n_grid)
    j, w = lk.grid_position(theta[..., 1], data.log_n_grid)  # (E, F, W)
    index = j + (np.arange(data.shape[0]) * n)[None, :, None]
    r = np.take(rows, index.ravel(), axis=2).reshape(2, sources, *j.shape, -1)
    gamma = theta[..., 0:1]
    glossy_minus_diffuse = w[..., None] * r[1]  # (P, E, F, W, T)
    glossy_minus_diffuse += r[0]
    diffuse = data.diffuse[:sources, None, :, None, :]
    k_col, a_col = fr.FRESNEL_COLUMNS
    if data.fresnel is None or theta.shape[-1] <= a_col:
        parts = gamma * glossy_minus_diffuse
        parts += diffuse
    elif data.fresnel.glossy_rise is not None:  # the rise inside the lobe
        k, log_a = theta[..., k_col : k_col + 1], theta[..., a_col : a_col + 1]
        s = np.take(data.rise_tables, index.ravel(), axis=2).reshape(2, sources, *j.shape, -1)
        rise = w[..., None] * s[1]
        rise += s[0]  # (P, E, F, W, T)
        parts = [
            fr.fresnel_parts_in_lobe(
                diffuse[p],
                diffuse[p] + glossy_minus_diffuse[p],
                rise[p],
                k,
                log_a,
                data.fresnel.view,
                gamma,
                data.fresnel.sun_direct if p == 0 else None,
            )
            for p in range(sources)
        ]
    else:  # the Fresnel raise at the view
        k, log_a = theta[..., k_col : k_col + 1], theta[..., a_col : a_col + 1]
        parts = [
            fr.fresnel_parts(
                diffuse[p] + gamma * glossy_minus_diffuse[p],
                diffuse[p] + glossy_minus_diffuse[p],
                k,
                log_a,
                data.fresnel.view,
                data.fresnel.sun_direct if p == 0 else None,
                gamma,
            )
            for p in range(sources)
        ]
    return (*parts, parts[1]) if data.shapes == 1 else tuple(parts)


def frame_weights(lam, data: JointData):
    """The weights of S and of each K^k: e a, then e b w_k, P arrays (E, 1, W,
    T), for lam (E, W, T, L) (one sky model: e b, then 0)."""
    log_e = lam[..., 0] if data.log_exposure is None else data.log_exposure
    ea = np.exp(log_e + lam[..., 1])[:, None]
    log_eb = log_e + lam[..., 2]
    if data.shapes == 1:
        eb = np.exp(log_eb)[:, None]
        return ea, eb, 0.0 * eb
    norm = _log_softmax_norm(lam[..., 3:])  # log w_k = u_k - norm, u_0 = 0
    log_w = [-norm] + [lam[..., 2 + k] - norm for k in range(1, data.shapes)]
    return (ea, *(np.exp(log_eb + x)[:, None] for x in log_w))


def predict(theta, lam, data: JointData, parts=None) -> np.ndarray:
    """mu_ft, (E, F, W, T), for theta (E, F, W, >= 3) and lam (E, W, T, L)."""
    parts = unit_parts(theta, data) if parts is None else parts
    weights = frame_weights(lam, data)
    mu = weights[0] * parts[0]
    for wk, pk in zip(weights[1:], parts[1:], strict=True):
        mu += wk * pk
    return np.exp(theta[..., 2:3]) * mu


def _residuals(mu, data: JointData, axis=None, y=None):
    """(z', log v): (y - mu) / (mu + c) and log(mu + c), 0 where invalid;
    with ``axis``, log v summed over it (the likelihoods need only sums).
    ``y``: each walker's own observations, (E, F, W, T) (censored entries
    completed, :mod:`bayesgloss.sampling.censored`); default the data's."""
    v = mu + data.floor[None, :, None, None]
    valid = data.valid[None, :, None, :]
    y = data.y[None, :, None, :] if y is None else y
    with np.errstate(invalid="ignore", divide="ignore"):
        z = np.where(valid, (y - mu) / v, 0.0)
        if axis is None:
            return z, np.where(valid, np.log(np.maximum(v, 1e-300)), 0.0)
        return z, _sum_log(np.where(valid, v, 1.0), axis)


def _sum_log(x, axis) -> np.ndarray:
    """sum log x over ``axis`` (x > 0; 1e-300 where not) as the log of the
    product: one logarithm per sum instead of one per entry (the entries'
    logarithms took half of :func:`_residuals`, a tenth of a sweep). Sums
    whose product leaves the range where it keeps full precision (outside
    1e-280 to 1e280, or not finite) are summed term by term instead."""
    with np.errstate(invalid="ignore", divide="ignore", over="ignore", under="ignore"):
        product = np.prod(x, axis=axis)
        out = np.log(product)
        bad = ~((product > 1e-280) & (product < 1e280))
    if bad.any():
        terms = np.sum(np.log(np.maximum(x, 1e-300)), axis=axis)
        out = np.where(bad, terms, out)
    return out


def log_likelihood_sigma_marginal(theta, lam, data: JointData, parts=None, with_q=False):
    """Each facet's log likelihood with sigma integrated out, (E, F, W).

    The closed form of :func:`bayesgloss.likelihood.log_likelihood_sigma_marginal`
    with Q = sum_t z'_t^2 and the sd per unit sigma v_t = mu_ft + c_f.
    """
    z, sum_log_v = _residuals(predict(theta, lam, data, parts), data, axis=-1)
    q = np.maximum(np.sum(z * z, axis=-1), 1e-300)
    k, const, cuts = data.sigma_constants
    k, const, *cuts = (x[None, :, None] for x in (k, const, *cuts))  # over (E, F, W)
    ll = _log_marginal_over_sigma(q, sum_log_v, k, const, cuts, data.priors)
    return (ll, q) if with_q else ll


def log_likelihood_shared_sigma(theta, lam, data: JointData, parts=None, with_q=False, y=None):
    """The one-material model's log likelihood with one sigma for all facets
    integrated out, (E, W).

    The closed form of :func:`log_likelihood_sigma_marginal` with Q and k
    summed over the facets. Why one sigma: with a sigma for each facet under
    its log-uniform prior, the marginal likelihood grows as Q_f^(-T/2) as a
    facet's residuals shrink, which the frames' four free latents can make
    them do for any one facet at a time (12 frames, 48 latents, 12 numbers to
    fit): the gain in density matches the loss of volume down to the prior's
    1e-4, so the posterior held ridges where one facet or another was fitted
    exactly, and the sampler's walkers each sat on their own (gamma's R-hat
    over walkers 2-10 on 24-facet, 12-frame prior draws; one sigma, no facet
    can be fitted alone). With ``with_q``, also each facet's Q (E, F, W).
    ``y``: each walker's completed observations (:func:`_residuals`).
    """
    z, sum_log_v = _residuals(predict(theta, lam, data, parts), data, axis=(1, -1), y=y)
    q_f = np.sum(z * z, axis=-1)
    q = np.maximum(q_f.sum(axis=1), 1e-300)
    k, const, cuts = data.shared_sigma_constants
    ll = _log_marginal_over_sigma(q, sum_log_v, k, const, cuts, data.priors)
    return (ll, q_f) if with_q else ll


def _log_marginal_over_sigma(q, sum_log_v, k, const, cuts, priors: lk.Priors):
    """The closed form of the sigma-marginal log likelihood, elementwise over
    q's shape (the other arrays broadcast to it): const - sum log v - k log Q
    + log of the incomplete gamma interval over the prior's sigma range; 0
    where k = 0 (no observation), -inf where NaN."""
    la, lb = priors.log_sigma
    k, lo_cut, hi_cut = (np.broadcast_to(x, q.shape) for x in (k, *cuts))
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        log_int = log_gamma_interval(
            k, q * (0.5 * np.exp(-2 * lb)), q * (0.5 * np.exp(-2 * la)), (lo_cut, hi_cut)
        )
        ll = const - sum_log_v - k * np.log(q) + log_int
    ll = np.where(k > 0, ll, 0.0)
    return np.where(np.isnan(ll), -np.inf, ll)


def draw_shared_log_sigma(q, data: JointData, rng: np.random.Generator) -> np.ndarray:
    """The one sigma of :func:`log_likelihood_shared_sigma` from its
    conditional given each facet's Q (E, F, W), the same for every facet, (E,
    F, W) (:func:`bayesgloss.likelihood.draw_log_sigma` with Q and the
    frames counted over all facets)."""
    e, f, w = q.shape
    total = np.maximum(q.sum(axis=1), 1e-300).reshape(1, -1)
    pooled = _PooledCurves(data.priors, data.valid.reshape(1, -1))
    ls = lk.draw_log_sigma(np.zeros((1, e * w, 3)), pooled, rng, q=total).reshape(e, 1, w)
    return np.broadcast_to(ls, q.shape).copy()


_PooledCurves = namedtuple("_PooledCurves", "priors valid")


def frame_log_likelihood(theta, lam, log_sigma, data: JointData, parts) -> np.ndarray:
    """Log likelihood of each frame given every facet's sigma, (E, W, T), up to
    a constant (sum over facets of -z^2 / 2 - log(mu + c))."""
    z, sum_log_v = _residuals(predict(theta, lam, data, parts), data, axis=1)
    inv_sigma = np.exp(-log_sigma)[..., None]  # (E, F, W, 1)
    zz = z * inv_sigma
    return np.sum(-0.5 * zz * zz, axis=1) - sum_log_v


def entry_log_likelihood(theta, lam, log_sigma, data: JointData, parts=None) -> np.ndarray:
    """Each entry's log likelihood given sigma (``log_sigma`` (E, F, W)),
    (E, F, W, T), 0 where invalid, -log sqrt(2 pi) left out: a measured
    entry's normal density, -z^2 / 2 - log(sigma v); a censored entry's
    survival at its bound, log Phi(-z) (the likelihood of what was
    observed: the pixel clipped); z = (y - mu) / (sigma v), v = mu + c_f."""
    z, log_v = _residuals(predict(theta, lam, data, parts), data)
    ls = log_sigma[..., None]
    z = z * np.exp(-ls)
    ll = -0.5 * z * z - log_v - ls
    if data.censored is not None:
        ll = np.where(data.censored[None, :, None, :], special.log_ndtr(-z), ll)
    return np.where(data.valid[None, :, None, :], ll, 0.0)


def pointwise_log_likelihood(theta, lam, data: JointData) -> np.ndarray:
    """Log likelihood of every (facet, frame), (E, F, W, T), theta with log
    sigma as its 4th coordinate; NaN where invalid
    (:func:`entry_log_likelihood` with the normal's constant on measured entries)."""
    ll = entry_log_likelihood(theta, lam, theta[..., 3], data)
    const = np.full(data.shape, 0.5 * np.log(2 * np.pi))
    if data.censored is not None:
        const[data.censored] = 0.0
    return np.where(data.valid[None, :, None, :], ll - const[None, :, None, :], np.nan)


def sample_prior(data: JointData, size: int, rng: np.random.Generator):
    """Draws from the joint prior: theta (F, size, 4) and lam (size, T, L)."""
    p, q = data.priors, data.frame_priors
    f, t = data.shape
    th = np.empty((f, size, 4))
    th[..., 0] = rng.uniform(0, 1, (f, size))
    th[..., 1] = rng.uniform(*p.log_n, (f, size))
    th[..., 2] = data.log_s_center[:, None] + p.log_s_sd * rng.standard_normal((f, size))
    th[..., 3] = rng.uniform(*p.log_sigma, (f, size))
    lam = np.zeros((size, t, data.n_latents))
    lam[..., 0] = 0.0 if data.exposure_known else q.exposure_sd * rng.standard_normal((size, t))
    cloud = rng.random((size, t)) < q.sun_cloud_weight
    lam[..., 1] = np.where(
        cloud,
        q.sun_cloud_mean + q.sun_cloud_sd * rng.standard_normal((size, t)),
        q.sun_clear_sd * rng.standard_normal((size, t)),
    )
    lam[..., 2] = q.sky_sd * rng.standard_normal((size, t))
    if data.shapes >= 2:  # uniform on the simplex, as log ratios to the first
        log_w = np.log(rng.dirichlet(np.ones(data.shapes), size=(size, t)))
        lam[..., 3:] = log_w[..., 1:] - log_w[..., :1]
    return th, lam


def sample_prior_material(
    data: JointData, size: int, rng: np.random.Generator, point_mass: bool = False
):
    """Draws from the one-material model's prior (:func:`log_prior_material`):
    theta (F, size, 4) (gamma, log n and log sigma shared, sigma log-uniform;
    (F, size, 6) with the shared Fresnel k and log A where the data carry
    Fresnel terms),
    hyper (size, :func:`hyper_size`) and lam (size, T, L), each frame's sun from the day's
    three-part mixture (``point_mass``: a hidden sun log a = -inf, as
    :func:`log_prior_frames`, and hyper (size, 4): the Hamiltonian sampler's
    model has no day-level exposure)."""
    p, q = data.priors, data.frame_priors
    f, t = data.shape
    th, lam = sample_prior(data, size, rng)
    th[..., 0] = rng.uniform(0, 1, size)[None, :]
    th[..., 1] = rng.uniform(*p.log_n, size)[None, :]
    # the Hamiltonian sampler's model (point_mass) keeps each frame's exposure on its own
    hyper = np.empty((size, 4 if point_mass else hyper_size(data)))
    hyper[:, 0] = material_m_center(data) + MATERIAL_M_SD * rng.standard_normal(size)
    hyper[:, 1] = rng.uniform(*MATERIAL_LOG_TAU, size)
    th[..., 2] = hyper[None, :, 0] + np.exp(hyper[None, :, 1]) * rng.standard_normal((f, size))
    th[..., 3] = rng.uniform(*p.log_sigma, size)[None, :]  # one sigma for all facets
    weights = rng.dirichlet(np.ones(3), size=size)  # clear, dimmed, hidden
    hyper[:, 2:4] = np.log(weights[:, 1:]) - np.log(weights[:, :1])
    lam[..., 1] = draw_log_sun(weights, t, q, rng, point_mass)
    if hyper.shape[1] > 4:  # each frame's exposure about the day's
        hyper[:, 4] = q.exposure_sd * rng.standard_normal(size)
        hyper[:, 5] = rng.uniform(*EXPOSURE_LOG_SPREAD, size)
        z = rng.standard_normal((size, t))
        lam[..., 0] = hyper[:, 4:5] + np.exp(hyper[:, 5:6]) * z
    if data.fresnel is not None:  # k and log A, shared by the facets
        fres = fr.sample_prior_fresnel(size, rng)
        th = np.concatenate([th, np.broadcast_to(fres[None], (f, size, 2))], axis=-1)
    return th, hyper, lam


def draw_log_sun(weights, frames: int, q: IlluminationPriors, rng, point_mass: bool = False):
    """Each frame's log sun drawn from the day's three-part mixture
    (:func:`log_prior_frames`), (..., frames), for the weights of its clear,
    dimmed and hidden components (..., 3) (``point_mass``: a hidden sun
    log a = -inf). The prior's draws (:func:`sample_prior_material`) and the
    one-material sampler's proposals (its sun's jumps) both."""
    u = rng.random((*weights.shape[:-1], frames))
    state = (u[..., None] > np.cumsum(weights, axis=-1)[..., None, :-1]).sum(-1)
    hidden_mean = -np.inf if point_mass else q.sun_hidden_mean
    means = np.array([0.0, q.sun_cloud_mean, hidden_mean])
    sds = np.array([q.sun_clear_sd, q.sun_cloud_sd, q.sun_hidden_sd])
    return means[state] + sds[state] * rng.standard_normal(state.shape)


def simulate(theta, lam, data: JointData, rng: np.random.Generator) -> np.ndarray:
    """Observations from the model, (E, F, W, T), theta (E, F, W, 4) with log
    sigma, lam (E, W, T, L)."""
    mu = predict(theta, lam, data)
    sd = np.exp(theta[..., 3:4]) * (mu + data.floor[None, :, None, None])
    y = mu + sd * rng.standard_normal(mu.shape)
    if data.censored is not None:  # clipped where the data were: at most the bound
        cut = data.censored[None, :, None, :]
        y = np.where(cut, np.minimum(y, data.y[None, :, None, :]), y)
    return y

"""Fresnel in the glossy basis: a smooth material's specular reflection rises toward grazing views.

Radiance's ``plastic`` and ``metal`` of roughness 0 raise their specular
reflectance by a Fresnel estimate F(c) = exp(-5.85 c) - c0 at the cosine c
of the view angle (``normal.c``; :func:`bayesgloss.reflectance.fresnel_radiance`,
:func:`bayesgloss.reflectance.radiance_material`), and so do real surfaces,
smooth or rough. Let the material reflect, at normal incidence, the albedo
A = g0 + d0, a glossy part g0 = A gamma and a diffuse part d0 = A (1 -
gamma): gamma is the fraction of the reflected energy in the glossy lobe at
normal incidence (the estimand; :func:`bayesgloss.reflectance.gloss_of_radiance_material`).
Seen at cosine c_f (facet f), Radiance's material reflects

    glossy  g_f = g0 + F_f (1 - g0),      diffuse  d_f = d0 (1 - F_f),

and the diffuse part lit by the sun at cosine c_i is further multiplied by
1 - F(c_i) (``dirnorm``). Divided by A (the facet's scale s_f carries the
material's albedo), the unit part of a source p of
:mod:`bayesgloss.illumination`, (1 - gamma) D^p + gamma G^p, becomes

    (1 - k F_f) [(1 - gamma) D^p + gamma G^p] + (k F_f / A) G^p
        - (1 - k F_f) (1 - gamma) k D^sun_F          (the sun's part only)

with D^sun_F = D^sun_direct F(c_i) the direct sun's diffuse basis weighted
by the Fresnel estimate at its incidence (:func:`fresnel_terms`). The
strength k in [0, 1] is 1 for Radiance's smooth materials and for real
surfaces, 0 for Radiance's rough ones (which have no Fresnel term); it and
the normal-incidence albedo A are unknowns of the one-material model
(uniform k, log A uniform on :data:`NORMAL_ALBEDO_RANGE`), shared by every
facet, so that the rise of the specular part across facets seen at
different angles tells them. A bright material (A near 1) barely shows the
raise; a dark one (A = 0.2: plastic of specularity 0.04 and colour 0.2) is
dominated by it at views beyond about 70 degrees.

``"schlick"`` is the same model with Schlick's rise F(c) = (1 - c)^5
(:func:`bayesgloss.reflectance.fresnel_schlick` with F0 = 0) in place of
Radiance's estimate: a dielectric coating over a diffuse base (Mitsuba's
``plastic``, a microfacet material's Fresnel factor at the half-vector's
angle, here at the mirror direction's) reflects F0 + (1 - F0) F(c) in its
specular part, so g_f = g0 + F_f (1 - g0) with g0 = F0, and passes (1 -
F(c)) of the light through its surface on the way in and out, the diffuse
part's (1 - F_f) and the sun's (1 - F(c_i)), as above. The two rises are
close (0.051 and 0.031 at 60 degrees, 0.31 and 0.33 at 78); Schlick's is
the microfacet literature's and the one issue 14 names.

``"schlick-lobe"`` takes Schlick's rise where a microfacet lobe has it:
inside the GGX lobe's integral, at the half vector of each light's
direction and the view, instead of at the view angle for the whole lobe
(:func:`fresnel_parts_in_lobe`, :func:`bayesgloss.lobes.ggx_schlick_rise_basis`).
The view's rise makes a rough coating's specular part up to 3 times too
bright at grazing views; against Mitsuba's ``roughplastic`` under a uniform
sky the rise inside reads 0.94-1.28 of Mitsuba's at views of 0-85 degrees
(studies/README.md, stop 51). The diffuse part keeps the view's rise.

Limits. Only the object's answer (the one-material model) has the raise;
each facet's own posterior given the object's light
(:func:`bayesgloss.sampling.facets_given_frames`) has none, so a facet's
gamma there is its view angle's apparent one. Radiance's rough materials
have no Fresnel term at all, real rough surfaces a softened one (Schlick's
inside a microfacet lobe: ``"schlick-lobe"``, GGX only). A is told only by how the raise
grows over the facets' view angles, so it is weakly identified, and a
misfit elsewhere (the sky's shape, a mirror's glint spread over a facet's
pixels) moves it, and gamma with it: on the holdout's vs23 (smooth plastic,
gamma 0.594, A 0.775, its own sky named) the model read A 0.52 and gamma
0.547 [0.479, 0.569] where the model without the raise read 0.594; fitted
to the forward model's own prediction of the same material it read 0.602
[0.585, 0.618] (A 0.93, broad). Opt-in (``estimate --fresnel radiance``)
until it does better on renders (studies/README.md, holdout run 4).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import reflectance

__all__ = [
    "FRESNEL_MODELS",
    "FRESNEL_COLUMNS",
    "FRESNEL_RISES",
    "NORMAL_ALBEDO_RANGE",
    "FresnelTerms",
    "fresnel_terms",
    "IN_LOBE",
    "fresnel_parts",
    "fresnel_parts_in_lobe",
    "check_fresnel_model",
    "log_prior_fresnel",
    "sample_prior_fresnel",
]

#: Fresnel models of the one-material fit: ``"none"`` (no Fresnel term, the
#: model of earlier versions and of Radiance's rough materials),
#: ``"radiance"`` (Radiance's estimate with an unknown strength k in [0, 1]
#: and normal-incidence albedo A; module docstring) and ``"schlick"`` (the
#: same with Schlick's rise (1 - c)^5 for F: a dielectric coating's, as
#: microfacet models and Mitsuba's plastics have it), and ``"schlick-lobe"``
#: (Schlick's rise inside the GGX lobe's integral, at each light's own half
#: vector: :func:`fresnel_parts_in_lobe`; the GGX lobe only).
FRESNEL_MODELS = ("none", "radiance", "schlick", "schlick-lobe")

#: The rise F(c) of each Fresnel model (c the view or incidence cosine):
#: 0 at normal incidence (Radiance's: 8.5e-4), 1 at grazing.
FRESNEL_RISES = {
    "radiance": reflectance.fresnel_radiance,
    "schlick": reflectance.fresnel_schlick,
    "schlick-lobe": reflectance.fresnel_schlick,
}

#: Fresnel models whose glossy part takes the rise inside the lobe (their
#: terms carry :attr:`FresnelTerms.glossy_rise`), and the lobe family each needs.
IN_LOBE = {"schlick-lobe": "ggx"}

#: Columns of theta (after gamma, log n, log s, log sigma) holding the
#: Fresnel strength k and log A, where the data carry Fresnel terms.
FRESNEL_COLUMNS = (4, 5)

#: Range of the normal-incidence albedo A under its log-uniform prior [-]:
#: from a near-black material to a white one.
NORMAL_ALBEDO_RANGE = (0.02, 1.0)


def check_fresnel_model(name: str) -> str:
    """``name`` if it is one of :data:`FRESNEL_MODELS`, else a ValueError listing them."""
    if name not in FRESNEL_MODELS:
        raise ValueError(f"unknown Fresnel model {name!r}; valid: {', '.join(FRESNEL_MODELS)}")
    return name


@dataclass(frozen=True)
class FresnelTerms:
    """The geometry's Fresnel estimates.

    Attributes
    ----------
    view : ndarray (F,)
        F(c_f) at each facet's view cosine [-].
    sun_direct : ndarray (F, T)
        D^sun_F: the direct sun's diffuse basis times F(c_i) at its
        incidence cosine [W sr^-1 m^-2].
    model : str
        The Fresnel model (:data:`FRESNEL_MODELS`).
    glossy_rise : ndarray (P, F, N, T) or None
        G^S of each source (the sun, then each sky model, as
        :attr:`bayesgloss.illumination.IlluminationBases.glossy`) on the
        exponent table, for the models of :data:`IN_LOBE`
        (:func:`bayesgloss.lobes.ggx_schlick_rise_basis`) [W sr^-1 m^-2].
    """

    view: np.ndarray
    sun_direct: np.ndarray
    model: str = "radiance"
    glossy_rise: np.ndarray | None = None

    def take(self, facets=slice(None), frames=slice(None)) -> FresnelTerms:
        """The terms of a subset of facets and frames."""
        rise = self.glossy_rise
        return FresnelTerms(
            self.view[facets],
            self.sun_direct[facets][:, frames],
            self.model,
            None if rise is None else rise[:, facets][..., frames],
        )


def fresnel_terms(geometry, sun_direction, solar_irradiance, model="radiance") -> FresnelTerms:
    """A Fresnel model's rise at each facet's view and at the sun on it.

    Parameters
    ----------
    geometry : bayesgloss.render.ViewGeometry
        F facets.
    sun_direction : array_like (T, 3)
        Unit vectors toward the sun.
    solar_irradiance : array_like (T,)
        Normal irradiance of the solar disc, 0 where the sun is down [W m^-2].
    model : {"radiance", "schlick"}
        Which rise F (:data:`FRESNEL_RISES`).

    Returns
    -------
    FresnelTerms
        F(max(c_f, 0.001)) (``pdot``'s floor in ``normal.c``), and
        c_i E_sun / pi F(c_i) (0 where c_i <= 0).
    """
    if model not in FRESNEL_RISES:
        raise ValueError(f"no Fresnel rise of model {model!r}; valid: {', '.join(FRESNEL_RISES)}")
    rise = FRESNEL_RISES[model]
    cos_view = np.maximum(geometry.cos_view, 0.001)
    view = rise(cos_view)
    sun = np.asarray(sun_direction, dtype=float)
    cos_i = np.maximum(geometry.normal @ sun.T, 0.0)  # (F, T)
    direct = cos_i * np.asarray(solar_irradiance, dtype=float)[None, :] / np.pi
    f_i = np.where(cos_i > 0, rise(np.maximum(cos_i, 1e-9)), 0.0)
    return FresnelTerms(view, direct * f_i, model)


def fresnel_parts(base, glossy, strength, log_albedo, view, sun_direct=None, gamma=None):
    """A source's unit part with the Fresnel raise (module docstring).

    Parameters
    ----------
    base : ndarray (..., F, W, T)
        (1 - gamma) D^p + gamma G^p without Fresnel.
    glossy : ndarray (..., F, W, T)
        G^p at the exponent.
    strength, log_albedo : ndarray (..., 1 or F, W, 1)
        k [-] and log A.
    view : ndarray (F,)
        F(c_f).
    sun_direct : ndarray (F, T), optional
        D^sun_F, for the sun's part (with ``gamma``).
    gamma : ndarray (..., F, W, 1), optional

    Returns
    -------
    ndarray (..., F, W, T)
    """
    c = strength * view[:, None, None]  # k F_f
    out = (1.0 - c) * base + c * np.exp(-log_albedo) * glossy
    if sun_direct is not None:
        out = out - (1.0 - c) * (1.0 - gamma) * strength * sun_direct[:, None, :]
    return out


def fresnel_parts_in_lobe(
    diffuse, glossy, rise, strength, log_albedo, view, gamma, sun_direct=None
):
    """A source's unit part with Schlick's rise inside the GGX lobe.

    The coating reflects, per unit of the normal-incidence albedo A, the
    glossy part gamma G + (1 - gamma A) (k / A) G^S: F0 = A gamma at each
    light's half vector, linear in it, so F0 G + (1 - F0) G^S of
    :func:`bayesgloss.lobes.ggx_schlick_rise_basis`, with strength k. That is
    gamma (G - k G^S) + (k / A) G^S. The diffuse part is the view's as in
    :func:`fresnel_parts`: (1 - k F_f) (1 - gamma) D, less the sun's
    (1 - k F_f) (1 - gamma) k D^sun_F. With G^S = F_f G it is
    :func:`fresnel_parts` exactly.

    Parameters
    ----------
    diffuse : ndarray (..., F, W, T) or broadcastable
        D^p.
    glossy, rise : ndarray (..., F, W, T)
        G^p and G^S_p at the exponent.
    strength, log_albedo : ndarray (..., 1 or F, W, 1)
        k [-] and log A.
    view : ndarray (F,)
        F(c_f), Schlick's at the view.
    gamma : ndarray (..., F, W, 1)
    sun_direct : ndarray (F, T), optional
        D^sun_F, for the sun's part.

    Returns
    -------
    ndarray (..., F, W, T)
    """
    c = strength * view[:, None, None]  # k F_f
    transmitted = (1.0 - c) * (1.0 - gamma)
    out = transmitted * diffuse + gamma * (glossy - strength * rise)
    out = out + strength * np.exp(-log_albedo) * rise
    if sun_direct is not None:
        out = out - transmitted * strength * sun_direct[:, None, :]
    return out


def log_prior_fresnel(strength, log_albedo) -> np.ndarray:
    """Log prior of (k, log A): uniform k on [0, 1], log A uniform on
    :data:`NORMAL_ALBEDO_RANGE`; -inf outside, 0 inside (a constant)."""
    lo, hi = np.log(NORMAL_ALBEDO_RANGE)
    inside = (strength >= 0) & (strength <= 1) & (log_albedo >= lo) & (log_albedo <= hi)
    return np.where(inside, 0.0, -np.inf)


def sample_prior_fresnel(size, rng: np.random.Generator) -> np.ndarray:
    """Draws of (k, log A) from their prior, (size, 2)."""
    lo, hi = np.log(NORMAL_ALBEDO_RANGE)
    return np.stack([rng.uniform(0.0, 1.0, size), rng.uniform(lo, hi, size)], axis=-1)

"""Test sequences rendered with Mitsuba 3, materials Radiance does not make.

A second renderer beside :mod:`bayesgloss.sequences` (Radiance): the same
:class:`~bayesgloss.sequences.SequenceConfig` (site, frame times, object,
camera, sky, ground, image size, camera response) with a Mitsuba material
(:class:`MitsubaMaterial`): smooth ``plastic``, GGX ``roughplastic``, and a
smooth ``conductor`` or GGX ``roughconductor`` blended with a Lambertian base
through ``blendbsdf``, so that a metal's gloss can be below 1 (but see
"Smooth metals" below). The config's
own Radiance material fields (``material``, ``colour``, ``specularity``,
``roughness``) and ``ambient`` are not used.

Scene of each frame (Mitsuba's ``scalar_rgb`` variant, path tracer):

- sky: an ``envmap`` emitter of :data:`ENVMAP_SIZE` pixels (latitude-longitude,
  Mitsuba's pixel centres) holding :meth:`bayesgloss.sky.DaylightSky.radiance`
  of the frame's sky, built by :func:`frame_skies` with the model and options
  the Radiance renderer's sky gets (gensky's turbidity; the Perez and CIE
  skies' DNI and DHI from :meth:`SequenceConfig.irradiances`), in Radiance's
  units (grey, W sr^-1 m^-2), the ground glow below the horizon included;
- sun: a disc (``disk`` with an ``area`` emitter) :data:`SUN_DISTANCE` m away
  along the sky's sun direction, of the sky model's angular size (0.5 deg for
  gensky, which writes that, 0.533 deg for Perez and CIE) and its solar
  radiance, so that smooth materials show the sun's mirror glint (a delta
  ``directional`` emitter is never seen in a mirror). The disc subtends the
  model's solid angle exactly from the origin; from a point 2 m away its
  direction moves by 2e-5 rad. Emitter sampling weights are the sun's normal
  irradiance and the sky's horizontal irradiance (Mitsuba picks an emitter
  at random; uniform picks doubled the noise of sunlit facets);
- ground: the Radiance scene's disc of ``ground_radius`` m (64-gon), Lambertian
  of ``ground_reflectance``; beyond it the sky's ground glow;
- object: the config's facets, one triangle mesh with face normals;
- camera: a pinhole with the field of view, position and orientation of
  :func:`bayesgloss.sequences.camera_rays`, box-filtered pixels. Its pixels
  line up with :func:`bayesgloss.sequences.label_image`'s (every labelled
  pixel of a hemisphere renders as its facet's id; ``tests/test_mitsuba_render.py``).

The frames then go through :func:`bayesgloss.sequences.camera_response` and
:func:`bayesgloss.bundle.write_bundle` exactly as the Radiance renderer's do
(labels from :func:`~bayesgloss.sequences.label_image`, exposure written for
``linear-radiance`` only), into ``cache_dir/<name>-<hash>/``.

Smooth metals
-------------
A smooth metal (kind ``conductor``) is rendered as a GGX ``roughconductor``
of roughness :data:`SMOOTH_CONDUCTOR_ALPHA` = 0.001, a lobe far narrower
than the sun's disc (0.27 degrees) and than a pixel of the sky's map, with
no delta lobe. Mitsuba 3.9.1's ``blendbsdf`` weights a sample of a delta
lobe by the blend's mixture density, (1 - w) p_diffuse + w, not by w (its
sampling fix of mitsuba3 PR #1681 is right for two non-delta lobes), so a
blend of the smooth ``conductor`` rendered far less gloss than its
components hold: at w = 0.054 the frames held 0.092 of gloss for a truth of
0.270 (Mitsuba holdout 7's ms10; studies/README.md, stop 52). With the
narrow lobe a blend of w = 0.1 renders 0.419 for a truth of 0.416 (the
delta lobe: 0.212; ``tests/test_mitsuba_render.py``, :func:`rendered_gloss`).
Sets drawn before stop 53 (Mitsuba holdouts 1-8) were rendered with the
delta lobe; their smooth metals' truths are the components', and
``studies/blend_truth.py`` reads what their frames hold.

True gloss
----------
gamma is the fraction of the reflected energy in the glossy (specular) part
at normal incidence, ``gamma = Y(R_s) / (Y(R_s) + Y(R_d))`` with ``R_s`` and
``R_d`` the directional-hemispherical albedos (RGB) of the specular and the
diffuse components for light arriving along the normal and ``Y`` the bundle's
luminance weights (0.265, 0.670, 0.065). :func:`mitsuba_albedos` integrates
Mitsuba's own BSDF (``eval`` of one component on a quadrature over outgoing
directions; ``sample`` for a delta component); :func:`model_albedos` computes
the same from the formulas of the models Mitsuba implements (below); on
seven materials of the four kinds they agree within 0.06 % in the albedos
and 2e-4 in gamma (``tests/test_mitsuba_render.py``, tolerances 0.3 % and
1e-3). With ``F(c; eta)`` the unpolarised Fresnel
reflectance at incidence cosine c, ``F0 = ((eta - 1) / (eta + 1))^2``,
``rho`` the diffuse reflectance, ``w`` the blend weight of the conductor:

- ``plastic`` (``plastic.cpp``): ``R_s = F0``;
  ``R_d = rho (1 - F0) eta^-2 (1 - Fbar_ext) / (1 - Fbar_int)``, with
  ``Fbar_ext = 2 int_0^1 F(mu; eta) mu dmu`` and Mitsuba's internal diffuse
  Fresnel reflectance ``Fbar_int = -1.4399 e^2 + 0.7099 e + 0.6681 + 0.0636 / e``,
  ``e = 1 / eta`` (the Egan-Hilgeman fit, Jensen et al. 2001 eq. 5). With the
  exact ``Fbar_int`` this would be ``rho (1 - F0)``; the fit moves it by < 1 %.
- ``roughplastic`` (``roughplastic.cpp``; GGX of Walter et al. 2007 eqs. 33-34
  with Smith's separable masking): ``R_s = 2 pi int_0^{pi/4} F(cos t; eta) D(t)
  G1(2 t) cos t sin t dt`` over the half-angle t (the reflected direction at
  2 t); ``R_d = rho T(1) eta^-2 (2 int_0^1 T(mu) mu dmu) / (1 - R_int)``, with
  ``T(mu)`` the rough interface's transmittance and ``R_int = 2 int_0^1
  R_i(mu) mu dmu`` its reflectance from inside (relative index 1 / eta),
  both integrals over microfacet normals of the visible-normal density;
  ``R_int`` summed as ``roughplastic.cpp`` sums it (the mean of ``R_i(mu) mu``
  over 64 equally spaced mu, doubled: 1-1.4 % below the integral, so its
  ``R_d`` is 1.3-2.7 % below that of an exact integral, and 2 % below smooth
  ``plastic``'s at alpha 0.002).
- ``conductor`` blended: the ``roughconductor``'s below at alpha
  :data:`SMOOTH_CONDUCTOR_ALPHA`, within 1e-5 of ``w F_c(1) = w ((n - 1)^2 +
  k^2) / ((n + 1)^2 + k^2)`` per channel (complex index n + ik), ``R_d = (1
  - w) rho``.
- ``roughconductor`` blended: ``R_s = w 2 pi int F_c(cos t) D(t) G1(2 t) cos t sin t dt``,
  ``R_d = (1 - w) rho``.

References
----------
.. [1] W. Jakob et al., Mitsuba 3 renderer, v3.9.1, https://mitsuba-renderer.org
   (``src/bsdfs/plastic.cpp``, ``roughplastic.cpp``, ``conductor.cpp``,
   ``roughconductor.cpp``, ``blendbsdf.cpp``, ``src/emitters/envmap.cpp``).
.. [2] B. Walter, S. Marschner, H. Li and K. Torrance, "Microfacet models for
   refraction through rough surfaces", EGSR 2007 (GGX D eq. 33, G1 eq. 34).
.. [3] H. W. Jensen, S. Marschner, M. Levoy and P. Hanrahan, "A practical model
   for subsurface light transport", SIGGRAPH 2001, eq. 5 (Egan and Hilgeman's
   fit of the diffuse Fresnel reflectance).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import bundle as bundle_io
from . import reflectance, sequences, sky

__all__ = [
    "MATERIAL_KINDS",
    "MATERIAL_CLASSES",
    "CONDUCTORS",
    "VARIANT",
    "ENVMAP_SIZE",
    "SUN_DISTANCE",
    "DEFAULT_SPP",
    "MitsubaMaterial",
    "MitsubaSequence",
    "bundle_path",
    "renderer_name",
    "write_sequence_bundle",
    "frame_skies",
    "envmap_directions",
    "render_frames",
    "rendered_horizontal_irradiance",
    "render_bundles",
    "mitsuba_albedos",
    "model_albedos",
    "true_gloss",
    "rendered_gloss",
    "gloss_of_albedos",
    "SMOOTH_CONDUCTOR_ALPHA",
]

#: Mitsuba's CPU variant used for rendering and for the BSDF integrals (the
#: LLVM variant needs libLLVM and failed in its code generator here).
VARIANT = "scalar_rgb"
#: Material kinds (Mitsuba plugin names; the conductors are blended with a
#: Lambertian base through ``blendbsdf``).
MATERIAL_KINDS = ("plastic", "roughplastic", "conductor", "roughconductor")
#: Scoring class of each kind.
MATERIAL_CLASSES = {
    "plastic": "smooth-plastic",
    "roughplastic": "rough-plastic",
    "conductor": "smooth-metal",
    "roughconductor": "rough-metal",
}
#: Mitsuba's named conductors a material may use (its ``material`` property).
CONDUCTORS = ("Au", "Cu", "Al", "Ag", "Cr", "W", "Hg")
#: Environment map (width, height): 0.35 deg pixels; rows are Mitsuba's
#: "align corners" latitudes (row 0 the zenith, the last row the nadir).
ENVMAP_SIZE = (1024, 513)
#: Distance of the sun disc from the origin [m].
SUN_DISTANCE = 1.0e5
#: Samples per pixel. At 128 px, one render's facet means (facets of 4 pixels
#: and more) are within 0.26 % (median) and 1 % (92 % of facets) of the
#: expectation, worst 1.9 % (``studies/README.md``, Mitsuba set).
DEFAULT_SPP = 256
#: Path length of the path tracer (camera -> object -> ground -> sky is 3).
MAX_DEPTH = 6
#: Alpha range of the rough kinds [-]; ior range of the plastics [-].
ALPHA_RANGE = (0.001, 1.0)
IOR_RANGE = (1.01, 3.0)
_WEIGHTS = np.asarray(reflectance.LUMINANCE_WEIGHTS, dtype=float)

#: GGX roughness of the lobe a smooth metal (kind ``conductor``) is rendered
#: with, instead of Mitsuba's delta lobe (module docstring, "Smooth metals") [-].
SMOOTH_CONDUCTOR_ALPHA = 0.001
#: Points of roughplastic.cpp's tables (MI_ROUGH_TRANSMITTANCE_RES).
_ROUGH_TABLE = 64


def _mitsuba(threads: int | None = None):
    """The ``mitsuba`` module with :data:`VARIANT` set (and drjit's thread count)."""
    import drjit as dr
    import mitsuba as mi

    if mi.variant() != VARIANT:
        mi.set_variant(VARIANT)
    if threads is not None:
        dr.set_thread_count(int(threads))
    return mi


def renderer_name() -> str:
    """The renderer written to a bundle's ``truth``: ``mitsuba-<version>-<variant>``."""
    import mitsuba

    return f"mitsuba-{mitsuba.__version__}-{VARIANT}"


def _rgb(value, name: str) -> np.ndarray:
    arr = np.broadcast_to(np.asarray(value, dtype=float), (3,))
    if not np.all(np.isfinite(arr) & (arr >= 0) & (arr <= 1)):
        raise ValueError(f"{name} {value} not a float or RGB triple in [0, 1]")
    return arr.copy()


# -- materials -------------------------------------------------------------------


@dataclass(frozen=True)
class MitsubaMaterial:
    """A Mitsuba material of one of :data:`MATERIAL_KINDS`.

    Attributes
    ----------
    kind : str
        "plastic", "roughplastic", "conductor" or "roughconductor".
    diffuse : float or tuple of 3 float
        Diffuse reflectance: the plastics' ``diffuse_reflectance`` (the base
        under the coating), the conductors' Lambertian blend partner [-].
    int_ior : float
        Index of refraction of the plastics' coating (air outside) [-].
    alpha : float
        GGX roughness of the rough kinds (0 for the smooth ones) [-].
    conductor : str or None
        A Mitsuba named conductor (:data:`CONDUCTORS`) of the metals; or give
        ``eta`` and ``k``.
    eta, k : tuple of 3 float or None
        Complex index of refraction (RGB) of the metals, instead of ``conductor``.
    weight : float
        ``blendbsdf`` weight of the conductor against the diffuse base (1: all
        metal) [-].
    """

    kind: str
    diffuse: float | tuple = 0.5
    int_ior: float = 1.5
    alpha: float = 0.0
    conductor: str | None = None
    eta: tuple | None = None
    k: tuple | None = None
    weight: float = 1.0

    def __post_init__(self):
        problems = []
        if self.kind not in MATERIAL_KINDS:
            raise ValueError(f"material kind {self.kind!r} not one of {', '.join(MATERIAL_KINDS)}")
        try:
            _rgb(self.diffuse, "diffuse")
        except ValueError as err:
            problems.append(str(err))
        rough = self.kind.startswith("rough")
        if rough and not ALPHA_RANGE[0] <= self.alpha <= ALPHA_RANGE[1]:
            problems.append(f"alpha {self.alpha} outside {ALPHA_RANGE} for {self.kind}")
        if not rough and self.alpha != 0:
            problems.append(f"alpha {self.alpha} given for smooth {self.kind}")
        if self.kind.endswith("plastic"):
            if not IOR_RANGE[0] <= self.int_ior <= IOR_RANGE[1]:
                problems.append(f"int_ior {self.int_ior} outside {IOR_RANGE}")
        else:
            named = self.conductor is not None
            if named == (self.eta is not None or self.k is not None):
                problems.append("a conductor needs either 'conductor' or both 'eta' and 'k'")
            elif named and self.conductor not in CONDUCTORS:
                problems.append(f"conductor {self.conductor!r} not one of {', '.join(CONDUCTORS)}")
            elif not named and (self.eta is None or self.k is None):
                problems.append("a conductor needs both 'eta' and 'k'")
            if not 0 <= self.weight <= 1:
                problems.append(f"weight {self.weight} outside [0, 1]")
        if problems:
            raise ValueError(f"mitsuba material {self.kind}: " + "; ".join(problems))

    @property
    def material_class(self) -> str:
        """Scoring class: smooth-plastic, rough-plastic, smooth-metal or rough-metal."""
        return MATERIAL_CLASSES[self.kind]

    def to_dict(self) -> dict:
        d = dataclasses.asdict(self)
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in d.items()}

    @classmethod
    def from_dict(cls, values: dict) -> MitsubaMaterial:
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise ValueError(f"unknown mitsuba material field(s): {', '.join(unknown)}")
        return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in values.items()})

    @property
    def lobe_alpha(self) -> float:
        """The GGX roughness the glossy lobe is rendered with: the material's
        ``alpha``, or :data:`SMOOTH_CONDUCTOR_ALPHA` for a smooth metal."""
        return float(SMOOTH_CONDUCTOR_ALPHA if self.kind == "conductor" else self.alpha)

    def bsdf(self) -> dict:
        """The material as a Mitsuba scene-dictionary BSDF (a smooth metal's
        lobe: module docstring, "Smooth metals")."""
        rgb = _rgb(self.diffuse, "diffuse")
        diffuse = {"type": "rgb", "value": [float(v) for v in rgb]}
        if self.kind == "plastic":
            return {
                "type": "plastic",
                "int_ior": float(self.int_ior),
                "ext_ior": 1.0,
                "diffuse_reflectance": diffuse,
            }
        if self.kind == "roughplastic":
            return {
                "type": "roughplastic",
                "distribution": "ggx",
                "alpha": float(self.alpha),
                "int_ior": float(self.int_ior),
                "ext_ior": 1.0,
                "diffuse_reflectance": diffuse,
            }
        metal: dict = {"type": "roughconductor", "distribution": "ggx", "alpha": self.lobe_alpha}
        if self.conductor is not None:
            metal["material"] = self.conductor
        else:
            metal["eta"] = {"type": "rgb", "value": [float(v) for v in self.eta]}
            metal["k"] = {"type": "rgb", "value": [float(v) for v in self.k]}
        return {
            "type": "blendbsdf",
            "weight": float(self.weight),
            "bsdf_0": {"type": "diffuse", "reflectance": diffuse},
            "bsdf_1": metal,
        }


# -- true gloss ------------------------------------------------------------------

#: Component indices (specular, diffuse) of each kind's BSDF in Mitsuba.
_COMPONENTS = {
    "plastic": (0, 1),
    "roughplastic": (0, 1),
    "conductor": (1, 0),
    "roughconductor": (1, 0),
}


def _gauss_legendre(n: int, a: float, b: float) -> tuple[np.ndarray, np.ndarray]:
    x, w = np.polynomial.legendre.leggauss(n)
    return a + (b - a) * (x + 1) / 2, w * (b - a) / 2


def _half_angle_nodes(alpha: float, n: int = 160) -> tuple[np.ndarray, np.ndarray]:
    """Half-angles t in [0, pi/4] and weights for integrals of a GGX lobe at
    normal incidence: tan t = alpha tan x, Gauss-Legendre in x, so the
    lobe's width alpha is resolved at any alpha [rad]."""
    x, w = _gauss_legendre(n, 0.0, np.arctan(1.0 / alpha))
    t = np.arctan(alpha * np.tan(x))
    dt_dx = alpha / np.cos(x) ** 2 / (1.0 + (alpha * np.tan(x)) ** 2)
    return t, w * dt_dx


def mitsuba_albedos(material: MitsubaMaterial) -> tuple[np.ndarray, np.ndarray]:
    """Specular and diffuse albedos at normal incidence by integrating Mitsuba's BSDF.

    The loaded BSDF's ``eval`` (which includes the outgoing cosine) of one
    component (``BSDFContext.component``) is integrated over outgoing
    directions: the diffuse component by Gauss-Legendre in cos(theta_o)
    (64 nodes) times 8 azimuths, a GGX lobe on :func:`_half_angle_nodes`
    (160 nodes) times 8 azimuths; a delta component (smooth plastic's
    specular, the smooth conductor) is the weight of ``sample`` restricted to
    it (its albedo in the mirror direction).

    Parameters
    ----------
    material : MitsubaMaterial

    Returns
    -------
    r_specular, r_diffuse : ndarray (3,)
        RGB directional-hemispherical albedos for light along the normal [-].
    """
    mi = _mitsuba()
    bsdf = mi.load_dict(material.bsdf())
    si = mi.SurfaceInteraction3f()
    si.wi = mi.Vector3f(0.0, 0.0, 1.0)
    spec_index, diff_index = _COMPONENTS[material.kind]
    phis = (np.arange(8) + 0.5) * (2 * np.pi / 8)

    def integrate(component: int, theta_o, weights) -> np.ndarray:
        ctx = mi.BSDFContext()
        ctx.component = component
        total = np.zeros(3)
        for th, w in zip(theta_o, weights, strict=True):
            ring = np.zeros(3)
            for ph in phis:
                wo = mi.Vector3f(np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th))
                ring += np.array(bsdf.eval(ctx, si, wo), dtype=float).reshape(3)
            total += w * np.sin(th) * ring / len(phis) * 2 * np.pi
        return total

    mu, wmu = _gauss_legendre(64, 0.0, 1.0)
    theta_d = np.arccos(mu)
    r_diff = integrate(diff_index, theta_d, wmu / np.sin(theta_d))  # dmu = sin dtheta
    if material.kind == "plastic":  # a delta component: sample() gives its albedo
        ctx = mi.BSDFContext()
        ctx.component = spec_index
        _, weight = bsdf.sample(ctx, si, 0.5, mi.Point2f(0.5, 0.5))
        r_spec = np.array(weight, dtype=float).reshape(3)
    else:
        t, wt = _half_angle_nodes(material.lobe_alpha)
        r_spec = integrate(spec_index, 2 * t, 2 * wt)  # theta_o = 2 t
    return r_spec, r_diff


def mitsuba_directional_albedo(
    material: MitsubaMaterial, view, part: str, rng: np.random.Generator, samples: int = 4000
) -> np.ndarray:
    """Directional albedo of one part of Mitsuba's BSDF toward a view, by its own sampling.

    The mean weight of the loaded BSDF's ``sample`` restricted to one
    component: the light a facet sends toward ``view`` under a uniform sky of
    radiance 1 (by reciprocity). Mitsuba's importance sampling puts its draws
    where a narrow lobe is, which a fixed quadrature misses at grazing views;
    its noise falls as ``samples ** -0.5`` (about 2 % at 4000 draws for a
    lobe of alpha 0.2).

    Parameters
    ----------
    material : MitsubaMaterial
    view : array_like (3,)
        Unit direction toward the camera, in the facet's frame (normal +z).
    part : {"specular", "diffuse"}
    rng : numpy.random.Generator
        Source of the sample's uniform numbers.
    samples : int

    Returns
    -------
    ndarray (3,)
        RGB directional albedo [-].
    """
    if part not in ("specular", "diffuse"):
        raise ValueError(f"part must be 'specular' or 'diffuse', got {part!r}")
    mi = _mitsuba()
    bsdf = mi.load_dict(material.bsdf())
    si = mi.SurfaceInteraction3f()
    si.wi = mi.Vector3f(*np.asarray(view, dtype=float))
    ctx = mi.BSDFContext()
    ctx.component = _COMPONENTS[material.kind][0 if part == "specular" else 1]
    total = np.zeros(3)
    for a, b, c in rng.random((samples, 3)):
        _, weight = bsdf.sample(ctx, si, float(a), mi.Point2f(float(b), float(c)))
        total += np.array(weight, dtype=float).reshape(3)
    return total / samples


def _fresnel(cos_i, eta, k=0.0) -> np.ndarray:
    """Unpolarised Fresnel reflectance of a boundary of complex relative index
    eta + i k (k = 0: a dielectric, total internal reflection where eta < 1)."""
    cos_i = np.clip(np.asarray(cos_i, dtype=float), 0.0, 1.0)
    n = np.asarray(eta, dtype=float) + 1j * np.asarray(k, dtype=float)
    cos_t = np.sqrt(1.0 - (1.0 - cos_i**2) / n**2 + 0j)
    r_s = (cos_i - n * cos_t) / (cos_i + n * cos_t)
    r_p = (n * cos_i - cos_t) / (n * cos_i + cos_t)
    return 0.5 * (np.abs(r_s) ** 2 + np.abs(r_p) ** 2)


def _ggx_d(cos_m, alpha):
    """GGX normal distribution D(m) (Walter et al. 2007 eq. 33) [sr^-1]."""
    c2 = cos_m**2
    return alpha**2 / (np.pi * (c2 * (alpha**2 - 1.0) + 1.0) ** 2)


def _ggx_g1(cos_v, v_dot_m, alpha):
    """Smith's GGX masking of direction v by microfacet m (Walter et al. 2007 eq. 34)."""
    cos_v = np.asarray(cos_v, dtype=float)
    tan2 = np.maximum(1.0 - cos_v**2, 0.0) / np.maximum(cos_v**2, 1e-300)
    g = 2.0 / (1.0 + np.sqrt(1.0 + alpha**2 * tan2))
    return np.where(v_dot_m * cos_v > 0, g, 0.0)


def _lobe_albedo(alpha: float, fresnel_of_cos) -> np.ndarray:
    """A GGX lobe's albedo at normal incidence, ``2 pi int F D G1(2 t) cos t sin t dt``."""
    t, w = _half_angle_nodes(alpha, 400)
    cos_t = np.cos(t)
    g1 = _ggx_g1(np.cos(2 * t), cos_t, alpha)
    f = fresnel_of_cos(cos_t)  # (N,) or (N, 3)
    kernel = 2 * np.pi * _ggx_d(cos_t, alpha) * g1 * cos_t * np.sin(t) * w
    return np.tensordot(kernel, f, axes=(0, 0))


def _interface_integrals(alpha: float, eta: float, mu: np.ndarray, inside: bool) -> np.ndarray:
    """Transmittance (outside, relative index eta) or reflectance (inside,
    relative index 1/eta) of a rough dielectric interface for incidence
    cosines mu: the visible-normal average of (1 - F) G1(t) or F G1(r)."""
    x, wx = _gauss_legendre(96, 0.0, np.pi / 2)
    theta_m = np.arctan(alpha * np.tan(x))
    w_theta = wx * alpha / np.cos(x) ** 2 / (1 + (alpha * np.tan(x)) ** 2)
    n_phi = 96
    phi = (np.arange(n_phi) + 0.5) * (np.pi / n_phi)  # symmetric about phi = 0: half, doubled
    tm, pm = np.meshgrid(theta_m, phi, indexing="ij")
    wm = (w_theta[:, None] * np.sin(theta_m)[:, None] * (2 * np.pi / n_phi)) * np.ones_like(pm)
    m = np.stack([np.sin(tm) * np.cos(pm), np.sin(tm) * np.sin(pm), np.cos(tm)], -1).reshape(-1, 3)
    wm = wm.reshape(-1)
    d = _ggx_d(m[:, 2], alpha)
    out = []
    rel = 1.0 / eta if inside else eta
    for c in mu:
        wi = np.array([np.sqrt(1 - c * c), 0.0, c])
        dot = m @ wi
        visible = _ggx_g1(c, dot, alpha) * np.maximum(dot, 0.0) / c * d  # VNDF
        f = _fresnel(dot, rel)
        if inside:
            wo = 2 * dot[:, None] * m - wi
            g = _ggx_g1(wo[:, 2], np.sum(wo * m, -1), alpha) * (wo[:, 2] > 0)
            out.append(np.sum(wm * visible * f * g))
        else:
            s2 = (1 - dot**2) / rel**2
            cos_t = np.sqrt(np.maximum(1 - s2, 0.0))
            wt = -wi / rel + ((dot / rel) - cos_t)[:, None] * m
            g = _ggx_g1(wt[:, 2], np.sum(wt * m, -1), alpha) * (wt[:, 2] < 0)
            out.append(np.sum(wm * visible * (1 - f) * g))
    return np.array(out)


def _conductor_ior(material: MitsubaMaterial) -> tuple[np.ndarray, np.ndarray]:
    """RGB eta and k of a metal as Mitsuba loads them (its named spectra in RGB)."""
    if material.conductor is None:
        return np.asarray(material.eta, float), np.asarray(material.k, float)
    mi = _mitsuba()
    params = mi.traverse(mi.load_dict(material.bsdf()))
    eta = np.array(params["bsdf_1.eta.value"], dtype=float).reshape(-1)
    k = np.array(params["bsdf_1.k.value"], dtype=float).reshape(-1)
    return np.broadcast_to(eta, (3,)).copy(), np.broadcast_to(k, (3,)).copy()


def model_albedos(material: MitsubaMaterial) -> tuple[np.ndarray, np.ndarray]:
    """Specular and diffuse albedos at normal incidence from the models' formulas.

    The formulas of the module docstring ("True gloss"), evaluated with
    numpy quadratures independent of Mitsuba (GGX lobes on 400 nodes in the
    mapped half-angle; the rough interface's transmittance and inner
    reflectance over 96 x 96 microfacet normals at 48 incidence cosines).
    Only a named conductor's RGB eta and k are read from Mitsuba.

    Parameters
    ----------
    material : MitsubaMaterial

    Returns
    -------
    r_specular, r_diffuse : ndarray (3,)
        RGB albedos for light along the normal [-].
    """
    rho = _rgb(material.diffuse, "diffuse")
    if material.kind.endswith("conductor"):
        eta, k = _conductor_ior(material)
        w = material.weight
        r_spec = _lobe_albedo(
            material.lobe_alpha, lambda c: _fresnel(c[:, None], eta[None, :], k[None, :])
        )
        return w * r_spec, (1 - w) * rho
    eta = material.int_ior
    f0 = ((eta - 1) / (eta + 1)) ** 2
    mu, wmu = _gauss_legendre(48, 0.0, 1.0)
    if material.kind == "plastic":
        fbar_ext = 2 * np.sum(wmu * mu * _fresnel(mu, eta))
        e = 1.0 / eta  # Egan-Hilgeman fit as Mitsuba evaluates it (Jensen et al. 2001 eq. 5)
        fbar_int = -1.4399 * e**2 + 0.7099 * e + 0.6681 + 0.0636 / e
        r_diff = rho * (1 - f0) * (1 - fbar_ext) / eta**2 / (1 - fbar_int)
        return np.full(3, f0), r_diff
    alpha = material.alpha
    r_spec = _lobe_albedo(alpha, lambda c: _fresnel(c, eta))
    t_mu = _interface_integrals(alpha, eta, mu, inside=False)
    t_1 = _interface_integrals(alpha, eta, np.array([1.0 - 1e-9]), inside=False)[0]
    # R_int as roughplastic.cpp sums it: 2 x the mean of R_i(mu) mu over 64
    # equally spaced mu in [1e-6, 1] (Gauss-Legendre instead: up to 1.4 % higher,
    # which raises R_d by up to 2.7 % at alpha 0.1)
    grid = np.maximum(np.linspace(0.0, 1.0, _ROUGH_TABLE), 1e-6)
    r_int = 2 * np.mean(grid * _interface_integrals(alpha, eta, grid, inside=True))
    r_diff = rho * t_1 / eta**2 * 2 * np.sum(wmu * mu * t_mu) / (1 - r_int)
    return np.full(3, float(r_spec)), r_diff


def gloss_of_albedos(r_specular, r_diffuse) -> float:
    """gamma = Y(R_s) / (Y(R_s) + Y(R_d)), Y the bundle's luminance weights [-]."""
    s = float(np.asarray(r_specular, float) @ _WEIGHTS)
    d = float(np.asarray(r_diffuse, float) @ _WEIGHTS)
    return s / (s + d) if s + d > 0 else 0.0


def true_gloss(material: MitsubaMaterial) -> float:
    """The material's true gamma, from :func:`mitsuba_albedos` (Mitsuba's own BSDF) [-]."""
    return gloss_of_albedos(*mitsuba_albedos(material))


def rendered_gloss(material: MitsubaMaterial, spp: int = 4096, bsdf: dict | None = None) -> float:
    """The gloss Mitsuba's path tracer renders at normal incidence [-].

    A square of the material seen straight down by a narrow camera under a
    uniform sky of radiance 1 (:func:`envmap_directions`' grid, 256 x 129):
    the pixels hold the specular and diffuse albedos together. Rendered again
    with the sky black within 6 degrees of the zenith, the mirror direction,
    they hold the diffuse albedo alone, less the cone's cosine-weighted share
    sin^2(6 deg) (divided back out). A check of :func:`true_gloss` by the
    renderer itself (module docstring, "Smooth metals"). ``bsdf``: a Mitsuba
    BSDF dictionary to render instead of ``material.bsdf()``.
    """
    mi = _mitsuba()
    directions = envmap_directions((256, 129))
    camera = mi.ScalarTransform4f().look_at(origin=[0, 0, 1], target=[0, 0, 0], up=[0, 1, 0])

    def render(hole: bool) -> float:
        radiance = np.ones(directions.shape[:2])
        if hole:
            radiance[directions[..., 2] > np.cos(np.radians(6.0))] = 0.0
        scene = {
            "type": "scene",
            "integrator": {"type": "path", "max_depth": 3},
            "sensor": {
                "type": "perspective",
                "fov": 2.0,
                "to_world": camera,
                "film": {"type": "hdrfilm", "width": 4, "height": 4, "rfilter": {"type": "box"}},
                "sampler": {"type": "independent", "sample_count": int(spp)},
            },
            "sky": _sky_emitter(radiance),
            "plane": {
                "type": "rectangle",
                "to_world": mi.ScalarTransform4f().scale([0.5, 0.5, 1.0]),
                "bsdf": material.bsdf() if bsdf is None else bsdf,
            },
        }
        image = np.array(mi.render(mi.load_dict(scene))).reshape(-1, 3)
        return float(image.mean(axis=0) @ _WEIGHTS)

    total = render(False)
    diffuse = render(True) / (1.0 - np.sin(np.radians(6.0)) ** 2)
    return (total - diffuse) / total


# -- scene -----------------------------------------------------------------------


def frame_skies(config: sequences.SequenceConfig) -> sky.DaylightSky:
    """The sky and sun of every frame of ``config``, as the Radiance renderer's scene has them.

    gensky skies with the config's turbidity; Perez and CIE skies with its
    per-frame DNI and DHI (:meth:`SequenceConfig.irradiances`) and the day
    of the first frame; the ground reflectance for the ground glow.
    """
    suns = config.sun_directions()
    if config.sky.startswith("gensky-"):
        return sky.daylight(
            config.sky,
            suns,
            turbidity=config.turbidity,
            ground_reflectance=config.ground_reflectance,
        )
    dni, dhi = config.irradiances()
    return sky.daylight(
        config.sky,
        suns,
        direct_normal_irradiance=dni,
        diffuse_horizontal_irradiance=dhi,
        day_of_year=int(config.frame_times()[0].day_of_year),
        ground_reflectance=config.ground_reflectance,
    )


def envmap_directions(size: tuple[int, int] = ENVMAP_SIZE) -> np.ndarray:
    """World directions of the envmap's pixel centres, (H, W, 3).

    Mitsuba's envmap (``envmap.cpp``) puts column i at u = (i + 0.5) / W and
    row j at v = j / (H - 1) ("align corners"); with the emitter's
    ``to_world`` of :data:`_ENVMAP_TO_WORLD` (local y up to world z), u is
    the bearing clockwise from north over 360 deg and v the zenith angle over
    180 deg.
    """
    width, height = size
    phi = 2 * np.pi * (np.arange(width) + 0.5) / width
    theta = np.pi * np.arange(height) / (height - 1)
    st = np.sin(theta)[:, None]
    return np.stack(
        [
            st * np.sin(phi)[None, :],
            st * np.cos(phi)[None, :],
            np.broadcast_to(np.cos(theta)[:, None], (height, width)),
        ],
        axis=-1,
    )


#: Envmap local frame (y up, Mitsuba's convention) to world (z up): local x
#: -> east, local y -> up, local z -> south.
_ENVMAP_TO_WORLD = [[1.0, 0, 0, 0], [0, 0, -1.0, 0], [0, 1.0, 0, 0], [0, 0, 0, 1.0]]


def _frame_to(axis: np.ndarray) -> np.ndarray:
    """A rotation (3, 3) whose third column is the unit vector ``axis``."""
    z = axis / np.linalg.norm(axis)
    helper = np.array([0.0, 0.0, 1.0]) if abs(z[2]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z])


def _sun_disc(sun_direction, solid_angle: float) -> tuple[np.ndarray, float]:
    """``to_world`` (4, 4) of a ``disk`` at :data:`SUN_DISTANCE` toward the sun,
    facing the origin and subtending ``solid_angle`` from it, and its radius [m]."""
    s = np.asarray(sun_direction, float)
    half = np.arccos(1.0 - solid_angle / (2 * np.pi))  # cone of the same solid angle
    radius = SUN_DISTANCE * np.tan(half)  # a disc at D of radius D tan(half) subtends it
    matrix = np.eye(4)
    matrix[:3, :3] = _frame_to(-s) * np.array([radius, radius, 1.0])
    matrix[:3, 3] = SUN_DISTANCE * s
    return matrix, radius


def _polygon_mesh(polygons, normals) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and fan triangles of polygons, each triangle wound to its normal."""
    verts, faces = [], []
    for poly, normal in zip(polygons, normals, strict=True):
        p = np.asarray(poly, float)
        base = len(verts)
        verts.extend(p)
        for k in range(1, len(p) - 1):
            tri = [base, base + k, base + k + 1]
            if np.cross(p[k] - p[0], p[k + 1] - p[0]) @ normal < 0:
                tri = [base, base + k + 1, base + k]
            faces.append(tri)
    return np.array(verts), np.array(faces)


def _write_meshes(config: sequences.SequenceConfig, facets, folder: Path) -> None:
    import trimesh

    v, f = _polygon_mesh(facets.polygons, facets.normal)
    trimesh.Trimesh(v, f, process=False).export(folder / "object.ply")
    a = np.linspace(0, 2 * np.pi, 64, endpoint=False)  # the Radiance scene's ground disc
    r = config.ground_radius
    disc = np.column_stack([r * np.cos(a), r * np.sin(a), np.zeros_like(a)])
    v, f = _polygon_mesh([disc], [np.array([0.0, 0.0, 1.0])])
    trimesh.Trimesh(v, f, process=False).export(folder / "ground.ply")


def _sensor(config: sequences.SequenceConfig, facets, spp: int) -> dict:
    """The pinhole camera of :func:`bayesgloss.sequences.camera_rays` as a Mitsuba sensor."""
    mi = _mitsuba()
    cam, fwd, _, up, tan_half = sequences._camera_frame(config, facets)
    n = config.image_size
    return {
        "type": "perspective",
        "fov": float(2 * np.degrees(np.arctan(tan_half))),
        "fov_axis": "x",
        "to_world": mi.ScalarTransform4f().look_at(
            origin=[float(v) for v in cam],
            target=[float(v) for v in cam + fwd],
            up=[float(v) for v in up],
        ),
        "film": {
            "type": "hdrfilm",
            "width": n,
            "height": n,
            "rfilter": {"type": "box"},
            "pixel_format": "rgb",
        },
        "sampler": {"type": "independent", "sample_count": int(spp)},
    }


def _sky_emitter(radiance: np.ndarray, weight: float = 1.0) -> dict:
    """An ``envmap`` of grey radiance (H, W) on :func:`envmap_directions`' grid."""
    mi = _mitsuba()
    image = np.repeat(np.asarray(radiance, np.float32)[:, :, None], 3, axis=2)
    return {
        "type": "envmap",
        "bitmap": mi.Bitmap(image),
        "to_world": mi.ScalarTransform4f(_ENVMAP_TO_WORLD),
        "sampling_weight": float(max(weight, 1e-9)),
    }


def _sun_emitter(sun_direction, solar_radiance: float, solid_angle: float, weight=1.0) -> dict:
    """The sun disc (:func:`_sun_disc`) as a Mitsuba shape with an area emitter."""
    mi = _mitsuba()
    matrix, _ = _sun_disc(sun_direction, solid_angle)
    return {
        "type": "disk",
        "to_world": mi.ScalarTransform4f(matrix.tolist()),
        "bsdf": {"type": "diffuse", "reflectance": 0.0},
        "emitter": {
            "type": "area",
            "radiance": {"type": "rgb", "value": float(solar_radiance)},
            "sampling_weight": float(weight),
        },
    }


def _scene_dict(
    config, facets, material: MitsubaMaterial, folder: Path, envmap, sun, spp: int
) -> dict:
    """Mitsuba scene dictionary of one frame; ``sun`` is (direction, radiance,
    solid angle, sampling weight) or None; ``envmap`` (H, W) radiance and its weight."""
    scene = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": MAX_DEPTH, "rr_depth": MAX_DEPTH + 1},
        "sensor": _sensor(config, facets, spp),
        "sky": _sky_emitter(*envmap),
        "ground": {
            "type": "ply",
            "filename": str(folder / "ground.ply"),
            "face_normals": True,
            "bsdf": {"type": "diffuse", "reflectance": float(config.ground_reflectance)},
        },
        "object": {
            "type": "ply",
            "filename": str(folder / "object.ply"),
            "face_normals": True,
            "bsdf": material.bsdf(),
        },
    }
    if sun is not None:
        scene["sun"] = _sun_emitter(*sun)
    return scene


def rendered_horizontal_irradiance(
    day: sky.DaylightSky, frame: int, *, sun: bool = True, sky_dome: bool = True, spp: int = 64
) -> float:
    """Irradiance on a horizontal plane as Mitsuba renders this module's sky and sun.

    A white Lambertian square (2 x 2 m at the origin) seen from above by a
    16 x 16 pixel camera, lit by the frame's sun disc (:func:`_sun_emitter`)
    and/or sky envmap (:func:`_sky_emitter`); irradiance = pi x its mean
    radiance. For the sun it should be ``solar_radiance x sun_solid_angle x
    cos(zenith)``, the sky model's direct normal irradiance (Radiance units)
    on the horizontal; for the sky :func:`bayesgloss.sky.horizontal_irradiance`
    without the sun.

    Parameters
    ----------
    day : DaylightSky
    frame : int
        Frame index [-].
    sun, sky_dome : bool
        Which emitters to include.
    spp : int
        Samples per pixel [-].

    Returns
    -------
    float
        Horizontal irradiance [W m^-2] (Radiance's units).
    """
    mi = _mitsuba()
    scene = {
        "type": "scene",
        "integrator": {"type": "direct", "emitter_samples": 4, "bsdf_samples": 4},
        "sensor": {
            "type": "perspective",
            "fov": 10.0,
            "to_world": mi.ScalarTransform4f().look_at(
                origin=[0.0, 0.0, 3.0], target=[0.0, 0.0, 0.0], up=[0.0, 1.0, 0.0]
            ),
            "film": {"type": "hdrfilm", "width": 16, "height": 16, "rfilter": {"type": "box"}},
            "sampler": {"type": "independent", "sample_count": int(spp)},
        },
        "plane": {
            "type": "rectangle",
            "to_world": mi.ScalarTransform4f().scale([2.0, 2.0, 1.0]),
            "bsdf": {"type": "diffuse", "reflectance": 1.0},
        },
    }
    if sun and day.solar_radiance[frame] > 0 and day.sun_direction[frame, 2] > 0:
        scene["sun"] = _sun_emitter(
            day.sun_direction[frame], float(day.solar_radiance[frame]), day.sun_solid_angle
        )
    if sky_dome:
        radiance = day.radiance(envmap_directions().reshape(-1, 3))[:, frame]
        scene["sky"] = _sky_emitter(radiance.reshape(ENVMAP_SIZE[1], ENVMAP_SIZE[0]))
    if "sun" not in scene and "sky" not in scene:
        return 0.0
    image = np.asarray(mi.render(mi.load_dict(scene)), dtype=float)
    return float(np.pi * np.mean(image[..., :3] @ _WEIGHTS))


def render_frames(
    config: sequences.SequenceConfig,
    material: MitsubaMaterial,
    *,
    spp: int = DEFAULT_SPP,
    seed: int = 0,
    frames=None,
    threads: int = 2,
) -> np.ndarray:
    """Render a sequence's frames with Mitsuba.

    Parameters
    ----------
    config : SequenceConfig
        Site, times, object, camera, sky and ground (its Radiance material
        fields are not used).
    material : MitsubaMaterial
        The object's material.
    spp : int
        Samples per pixel [-].
    seed : int
        Base seed of Mitsuba's sampler; frame t uses ``seed + t`` [-].
    frames : sequence of int, optional
        Frame indices to render (default all).
    threads : int
        Mitsuba's (drjit's) worker threads [-].

    Returns
    -------
    ndarray (T, H, W, 3)
        RGB radiance [W sr^-1 m^-2] (float32), rows top to bottom as
        :func:`bayesgloss.sequences.camera_rays`.
    """
    mi = _mitsuba(threads)
    facets = config.facets()
    day = frame_skies(config)
    index = range(config.n_frames) if frames is None else list(frames)
    directions = envmap_directions().reshape(-1, 3)
    sky_h = sky.horizontal_irradiance(day, include_sun=False)
    n = config.image_size
    out = np.zeros((len(index), n, n, 3), np.float32)
    with tempfile.TemporaryDirectory(prefix="bayesgloss-mitsuba-") as tmp:
        folder = Path(tmp)
        _write_meshes(config, facets, folder)
        for i, t in enumerate(index):
            radiance = day.radiance(directions)[:, t].reshape(ENVMAP_SIZE[1], ENVMAP_SIZE[0])
            solar = float(day.solar_radiance[t])
            sun = None
            if solar > 0 and day.sun_direction[t, 2] > 0:
                e_sun = solar * day.sun_solid_angle
                sun = (day.sun_direction[t], solar, day.sun_solid_angle, e_sun)
            if sun is None and not np.any(radiance > 0):
                continue  # nothing lights the scene: a black frame
            scene = mi.load_dict(
                _scene_dict(config, facets, material, folder, (radiance, sky_h[t]), sun, spp)
            )
            out[i] = finite_render(
                lambda s, scene=scene: mi.render(scene, spp=int(spp), seed=s), int(seed + t)
            )
    return out


#: Offset between the seeds of a frame's renders where one held a NaN sample.
RETRY_SEED_STEP = 1_000_003
#: Renders of a frame before a NaN sample is an error.
RENDER_TRIES = 3


def finite_render(render, seed: int, tries: int = RENDER_TRIES) -> np.ndarray:
    """``render(seed)`` as float32, rendered again with another seed
    (``seed + k`` :data:`RETRY_SEED_STEP`) where it holds a non-finite value.

    Mitsuba's sampler now and then returns a NaN sample (it warns "Invalid
    sample value"; seen on a perfectly smooth silver box of Mitsuba holdout
    11, one sample in about 10^8), which a bundle cannot hold. A frame
    whose render is finite keeps its seed, so sets rendered before are
    rendered the same. Raises ValueError after ``tries`` renders with one.
    """
    for k in range(tries):
        image = np.asarray(render(int(seed + k * RETRY_SEED_STEP)), np.float32)
        if np.all(np.isfinite(image)):
            return image
    raise ValueError(f"Mitsuba returned non-finite values in {tries} renders from seed {seed}")


# -- sequences and bundles ------------------------------------------------------


@dataclass(frozen=True)
class MitsubaSequence:
    """A sequence to render with Mitsuba: the scene's config, the material, spp, seed.

    Attributes
    ----------
    config : SequenceConfig
    material : MitsubaMaterial
    spp : int
        Samples per pixel [-].
    seed : int
        Base seed of Mitsuba's sampler [-].
    """

    config: sequences.SequenceConfig
    material: MitsubaMaterial
    spp: int = DEFAULT_SPP
    seed: int = 0

    def key(self) -> str:
        """Hash of everything that changes the rendered bundle (not the name)."""
        d = {
            "config": self.config.key(),
            "material": self.material.to_dict(),
            "spp": self.spp,
            "seed": self.seed,
            "renderer": renderer_name(),
            "scene": [ENVMAP_SIZE, SUN_DISTANCE, MAX_DEPTH],
        }
        if self.material.kind == "conductor":  # rendered with a narrow lobe since stop 53
            d["smooth_conductor_alpha"] = SMOOTH_CONDUCTOR_ALPHA
        return hashlib.sha256(json.dumps(d, sort_keys=True).encode()).hexdigest()[:12]

    def to_dict(self) -> dict:
        return {
            "config": self.config.to_dict(),
            "material": self.material.to_dict(),
            "spp": self.spp,
            "seed": self.seed,
        }

    @classmethod
    def from_dict(cls, values: dict) -> MitsubaSequence:
        return cls(
            sequences.SequenceConfig.from_dict(values["config"]),
            MitsubaMaterial.from_dict(values["material"]),
            int(values.get("spp", DEFAULT_SPP)),
            int(values.get("seed", 0)),
        )

    def truth(self, gloss: float | None = None) -> dict:
        """The bundle's ``truth``: the config's (:meth:`SequenceConfig.bundle_truth`)
        with the Radiance material fields replaced by the Mitsuba material, its
        class, albedos and true gloss (exposure gains and white added when written)."""
        r_spec, r_diff = mitsuba_albedos(self.material)
        truth = self.config.bundle_truth()
        truth.update(
            material=self.material.kind,
            material_class=self.material.material_class,
            mitsuba_material=self.material.to_dict(),
            colour=self.material.to_dict()["diffuse"],
            colour_luminance=float(_rgb(self.material.diffuse, "diffuse") @ _WEIGHTS),
            specularity=None,
            roughness=self.material.alpha,
            albedo_specular=[float(v) for v in r_spec],
            albedo_diffuse=[float(v) for v in r_diff],
            gloss=gloss_of_albedos(r_spec, r_diff) if gloss is None else float(gloss),
            renderer=renderer_name(),
            spp=self.spp,
            seed=self.seed,
        )
        return truth


def bundle_path(cache_dir, sequence: MitsubaSequence) -> Path:
    """``cache_dir/<name>-<hash>``, the bundle folder of ``sequence``."""
    return Path(cache_dir) / f"{sequence.config.name}-{sequence.key()}"


def write_sequence_bundle(path, sequence: MitsubaSequence, frames: np.ndarray) -> Path:
    """Write rendered frames as a bundle, as the Radiance renderer writes its own.

    Labels from :func:`bayesgloss.sequences.label_image`, the camera response
    of :func:`bayesgloss.sequences.camera_response` (gains, noise, white,
    encoding), facets that the labels hold, ``frames[].exposure`` written for
    ``linear-radiance`` only, staged and renamed into place.

    Parameters
    ----------
    path : path-like
        The bundle folder.
    sequence : MitsubaSequence
    frames : ndarray (T, H, W, 3)
        Rendered radiance [W sr^-1 m^-2].

    Returns
    -------
    Path
    """
    config = sequence.config
    facets = config.facets()
    labels = sequences.label_image(config, facets)
    sun_up = config.sun_directions()[:, 2] > 0.0
    return sequences.write_rendered_bundle(
        Path(path), config, facets, labels, frames, sun_up, bundle_io, sequence.truth()
    )


def render_bundles(items, cache_dir, *, threads: int = 2, progress: bool = True) -> list[Path]:
    """Render Mitsuba sequences into bundles (cached by :meth:`MitsubaSequence.key`).

    Parameters
    ----------
    items : iterable of MitsubaSequence
    cache_dir : path
        Bundles are written to ``cache_dir/<name>-<hash>/``; one already
        there (its manifest written) is not rendered again.
    threads : int
        Mitsuba's worker threads [-].
    progress : bool
        Print a progress line to stderr.

    Returns
    -------
    list of Path
        The bundle folders, in the order of ``items``.
    """
    items = list(items)
    cache_dir = Path(cache_dir)
    cache_dir.mkdir(parents=True, exist_ok=True)
    paths = [bundle_path(cache_dir, s) for s in items]
    start = time.perf_counter()
    for i, (seq, path) in enumerate(zip(items, paths, strict=True)):
        if (path / bundle_io.MANIFEST).exists():
            continue
        frames = render_frames(
            seq.config, seq.material, spp=seq.spp, seed=seq.seed, threads=threads
        )
        write_sequence_bundle(path, seq, frames)
        if progress:
            print(
                f"\rbayesgloss mitsuba: {i + 1}/{len(items)} sequences, "
                f"{time.perf_counter() - start:.0f} s",
                end="",
                file=sys.stderr,
                flush=True,
            )
    if progress and items:
        print(file=sys.stderr)
    return paths

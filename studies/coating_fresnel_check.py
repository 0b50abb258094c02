"""The one-material model's dielectric coating against Mitsuba's ``roughplastic`` BSDF (stop 51).

``ggx-schlick`` (GGX with Schlick's Fresnel raise, :mod:`bayesgloss.fresnel`)
at a material's true gamma, alpha, strength k = 1 and normal-incidence
albedo A, against Mitsuba's own BSDF (``eval``) of that material, for one
facet in the plane of incidence:

- the sun: the light a facet sends to each view for a sun at 20, 50 and
  70 degrees (specular and diffuse parts together), with Schlick's rise at
  the view angle (the model's) and at the sun's half vector;
- a uniform sky of radiance 1: each part's directional albedo at the view
  angle (by reciprocity, what the facet sends to that view), Mitsuba's by
  its own importance sampling (20000 draws, 5000 for the diffuse part,
  seed 0), the model's lobe by :func:`bayesgloss.lobes.ggx_glossy_basis`.

    python studies/coating_fresnel_check.py

Ratios are Mitsuba's over the model's. A development tool (studies/README.md,
"Stop 51"); it needs Mitsuba and runs in a few minutes.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from bayesgloss import fresnel as fr  # noqa: E402
from bayesgloss import lobes, reflectance, render  # noqa: E402
from bayesgloss import mitsuba_render as mr  # noqa: E402

#: The bundle's luminance weights of an RGB triple.
LUMINANCE = np.asarray(reflectance.LUMINANCE_WEIGHTS, dtype=float)
#: (alpha, index of refraction, diffuse reflectance) of the materials checked.
MATERIALS = ((0.05, 1.5, 0.05), (0.2, 1.5, 0.05), (0.2, 1.8, 0.3))
NORMAL = np.array([0.0, 0.0, 1.0])


def _in_plane(degrees) -> np.ndarray:
    t = np.radians(np.atleast_1d(degrees))
    return np.stack([np.sin(t), 0 * t, np.cos(t)], -1)


def _eval(mi, bsdf, view, light) -> float:
    """Mitsuba's f cos(light) toward ``view``, both parts, luminance."""
    si = mi.SurfaceInteraction3f()
    si.wi = mi.Vector3f(*view)
    return float(
        np.array(bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(*light))).reshape(3) @ LUMINANCE
    )


def sun_ratios(mi, bsdf, gamma, albedo, alpha, sun_degrees, view_degrees):
    """Mitsuba over the model for the direct sun: (view's rise, half vector's)."""
    s = _in_plane(sun_degrees)[0]
    o = _in_plane(view_degrees)
    mitsuba = np.array([_eval(mi, bsdf, v, s) for v in o])
    diffuse = s[2] / np.pi  # a white Lambertian facet's radiance per unit irradiance
    glossy = lobes.ggx_smith(s[None], o, NORMAL[None], alpha) / lobes.ggx_normal_albedo(alpha)
    glossy = glossy * s[2]
    rise_view = reflectance.fresnel_schlick(o[:, 2])  # F_f
    rise_sun = reflectance.fresnel_schlick(s[2])  # F(c_i), the light entering the coating
    rise_half = reflectance.fresnel_schlick(np.sqrt(np.clip(0.5 * (1 + o @ s), 0, 1)))
    # bayesgloss.fresnel's sun part at k = 1, per unit albedo: the diffuse part
    # through the coating twice, the glossy part raised by the rise given
    through = (1 - rise_view) * (1 - gamma) * diffuse * (1 - rise_sun)

    def model(rise):
        return albedo * (through + (gamma * (1 - rise) + rise / albedo) * glossy)

    # the first is bayesgloss.fresnel.fresnel_parts' own arithmetic, checked here
    parts = fr.fresnel_parts(
        ((1 - gamma) * diffuse + gamma * glossy)[:, None, None],
        glossy[:, None, None],
        np.ones((1, 1, 1)),
        np.full((1, 1, 1), np.log(albedo)),
        rise_view,
        np.full((len(o), 1), diffuse * rise_sun),
        np.full((len(o), 1, 1), gamma),
    )[:, 0, 0]
    np.testing.assert_allclose(albedo * parts, model(rise_view), rtol=1e-12)
    return mitsuba / model(rise_view), mitsuba / model(rise_half)


def sky_ratios(material, gamma, albedo, alpha, view_degrees, rng):
    """Mitsuba over the model under a uniform sky: (glossy part, diffuse part)."""
    views = _in_plane(view_degrees)
    geom = render.ViewGeometry(np.tile(NORMAL, (len(views), 1)), views)
    lobe = lobes.ggx_glossy_basis(geom, _Uniform(), [alpha], ground="sky")[:, 0, 0]
    rise = reflectance.fresnel_schlick(views[:, 2])
    out = []
    for deg, o, g, r in zip(np.atleast_1d(view_degrees), views, lobe, rise, strict=True):
        spec = mr.mitsuba_directional_albedo(material, o, "specular", rng, 20000) @ LUMINANCE
        diff = mr.mitsuba_directional_albedo(material, o, "diffuse", rng, 5000) @ LUMINANCE
        model_spec = albedo * (gamma * (1 - r) + r / albedo) * g
        model_diff = albedo * (1 - gamma) * (1 - r)
        out.append((deg, spec / model_spec, diff / model_diff))
    return out


class _Uniform:
    """A sky of radiance 1 everywhere, no sun."""

    sun_direction = np.array([[0.0, 0.0, 1.0]])
    solar_radiance = np.array([0.0])
    sun_solid_angle = 6.8e-5

    def radiance(self, d):
        return np.ones(np.shape(d)[:-1] + (1,))


def main() -> None:
    mi = mr._mitsuba()
    views = [-75, -60, -45, -30, -15, 0, 15, 30, 45, 60, 75]
    for alpha, eta, rho in MATERIALS:
        mat = mr.MitsubaMaterial(kind="roughplastic", diffuse=rho, int_ior=eta, alpha=alpha)
        r_s, r_d = mr.mitsuba_albedos(mat)
        albedo = float(r_s @ LUMINANCE + r_d @ LUMINANCE)
        gamma = float(r_s @ LUMINANCE) / albedo
        bsdf = mi.load_dict(mat.bsdf())
        print(f"alpha {alpha}, index {eta}, diffuse {rho}: gamma {gamma:.3f}, A {albedo:.3f}")
        for sun in (20, 50, 70):
            by_view, by_half = sun_ratios(mi, bsdf, gamma, albedo, alpha, sun, views)
            print(f"  sun at {sun} deg, views {views[0]}..{views[-1]}:")
            print("    view's rise   ", np.array2string(by_view, precision=2))
            print("    half vector's ", np.array2string(by_half, precision=2))
        print("  uniform sky, view angle: glossy part, diffuse part")
        rng = np.random.default_rng(0)
        for deg, spec, diff in sky_ratios(
            mat, gamma, albedo, alpha, [0, 30, 50, 60, 70, 75, 80, 85], rng
        ):
            print(f"    {deg:2d} deg  {spec:.2f}  {diff:.2f}")


if __name__ == "__main__":
    main()

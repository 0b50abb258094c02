"""Sky radiance distributions and the daylight holder the forward model consumes.

Three families of sky, each as a pure vectorised function plus a thin holder:

- Radiance's ``gensky`` skies (CIE clear, intermediate, overcast, uniform), as
  ``gensky.c`` computes their parameters and ``skybright.cal`` evaluates them:
  :func:`gensky_parameters`, :func:`skybright`.
- The CIE standard general sky, 15 types (ISO 15469:2004 / CIE S 011/E:2003):
  :func:`cie_general`.
- The Perez et al. (1993) all-weather sky as Radiance's ``gendaylit`` and
  ``perezlum.cal`` implement it: :func:`perez_coefficients`,
  :func:`perez_1993`, :func:`perez_parameters`, :func:`gendaylit_parameters`.

:func:`daylight` picks a sky by registry name and returns a
:class:`DaylightSky`, whose :meth:`DaylightSky.radiance` gives the radiance
seen in any direction for every frame; :func:`horizontal_irradiance`
integrates a sky by quadrature.

Units follow the project glossary (CONTRIBUTING.md): radiance in Radiance's
units, W sr^-1 m^-2 (luminance = 179 x radiance); world frame x east, y north,
z up; directions are unit vectors on the last axis; angles in degrees in the
public API.

References
----------
.. [1] G. Ward Larson and R. Shakespeare, *Rendering with Radiance*, 1998;
   Radiance source ``src/gen/gensky.c``, ``src/gen/skybright.cal``,
   ``src/gen/gendaylit.c``, ``src/gen/perezlum.cal``, ``src/common/color.h``
   (LBNL-ETA/Radiance, gensky.c v2.31).
.. [2] CIE (1973) standard clear sky; Kittler (1967); Moon & Spencer (1942)
   overcast sky, as used by gensky/skybright.cal.
.. [3] ISO 15469:2004(E) / CIE S 011/E:2003, *Spatial distribution of
   daylight - CIE standard general sky*, Table 1 and eqs. 1-7; S. Darula and
   R. Kittler, "CIE general sky standard defining luminance distributions",
   Proc. eSim 2002.
.. [4] R. Perez, R. Seals and J. Michalsky, "All-weather model for sky
   luminance distribution - preliminary configuration and validation",
   Solar Energy 50(3), 235-245, 1993 (eqs. 1-2, Table 1).
.. [5] R. Perez, P. Ineichen, R. Seals, J. Michalsky and R. Stewart,
   "Modeling daylight availability and irradiance components from direct and
   global irradiance", Solar Energy 44(5), 271-289, 1990 (eqs. 1-2 for
   clearness and brightness, Table 4 luminous efficacies).
"""

from __future__ import annotations

import dataclasses
import inspect
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np

__all__ = [
    "CIE_SKY_TYPES",
    "DaylightSky",
    "GendaylitParameters",
    "GenskyParameters",
    "PerezCoefficients",
    "SKY_EFFICACY",
    "SOLAR_CONSTANT",
    "SUN_EFFICACY",
    "TURBID_LINKE_TURBIDITY",
    "WHITE_EFFICACY",
    "cie_general",
    "daylight",
    "gendaylit_parameters",
    "gensky_parameters",
    "gensky_sun_solid_angle",
    "horizontal_irradiance",
    "perez_1993",
    "perez_coefficients",
    "perez_parameters",
    "skybright",
    "sky_models",
    "sun_disc",
    "sun_solid_angle",
    "takes_day_of_year",
]

# --- constants (Radiance src/common/color.h, gendaylit.c) -------------------

#: Luminous efficacy of Radiance's "white" radiance unit, lm/W (color.h WHTEFFICACY):
#: luminance [cd m^-2] = 179 x radiance [W sr^-1 m^-2]. The one definition of the
#: factor in bayesgloss (the bundle reader's ``linear-radiance`` frames use it too).
WHITE_EFFICACY = 179.0
#: Efficacy gensky uses for skylight, lm/W (color.h SKYEFFICACY = D65EFFICACY).
SKY_EFFICACY = 203.0
#: Efficacy gensky uses for direct sunlight, lm/W (color.h SUNEFFICACY).
SUN_EFFICACY = 208.0
#: Solar constant used by gendaylit, W m^-2.
SOLAR_CONSTANT = 1367.0
#: Solar illuminance constant used by gendaylit, lx.
_SOLAR_CONSTANT_LUX = 127500.0
#: Half the apparent solar diameter gendaylit uses, deg.
_GENDAYLIT_HALF_SUN_ANGLE = 0.2665
#: Radiance's horizon guard in skybright.cal and perezlum.cal (Dz threshold).
_HORIZON_GUARD = 0.01
#: Tolerance on the norm of direction vectors accepted at the public boundary.
_UNIT_TOLERANCE = 1e-4
#: gensky and gendaylit lower a sun above this altitude to it (deg).
_MAX_SUN_ALTITUDE = 87.0


def sun_solid_angle(diameter: float = 0.533) -> float:
    """Solid angle of the solar disc.

    A disc of angular diameter ``d`` subtends ``2 pi (1 - cos(d / 2))``.

    Parameters
    ----------
    diameter : float, optional
        Apparent angular diameter of the disc; 0.533 is gendaylit's
        (``2 x 0.2665``) and the sun's mean diameter. [deg]

    Returns
    -------
    float
        Solid angle. [sr]
    """
    diameter = float(diameter)
    if not (0.0 < diameter < 180.0):
        raise ValueError(f"diameter must lie in (0, 180) deg, got {diameter!r}")
    return float(2.0 * np.pi * (1.0 - np.cos(np.deg2rad(diameter) / 2.0)))


#: Solid angle of the sun gensky writes (``solar source sun ... 0.5``), sr.
gensky_sun_solid_angle: float = sun_solid_angle(0.5)


# --- validation helpers -----------------------------------------------------


def _unit_vectors(value: Any, name: str) -> np.ndarray:
    """Float array of unit vectors on the last axis; NaN passes through."""
    arr = np.asarray(value, dtype=float)
    if arr.ndim == 0 or arr.shape[-1] != 3:
        raise ValueError(f"{name} must have 3 components on the last axis, got shape {arr.shape}")
    norm = np.sqrt(np.sum(arr * arr, axis=-1))
    bad = np.abs(norm - 1.0) > _UNIT_TOLERANCE  # NaN compares False: propagates
    if np.any(bad):
        vec = arr.reshape(-1, 3)[int(np.argmax(np.ravel(bad)))]
        raise ValueError(
            f"{name} must be unit vectors; got {vec.tolist()} with norm "
            f"{float(np.linalg.norm(vec)):.6g}"
        )
    return arr


def _nonnegative(value: Any, name: str) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    bad = arr < 0  # NaN compares False: propagates
    if np.any(bad):
        raise ValueError(f"{name} must be >= 0, got {arr[bad].ravel()[0]!r}")
    return arr


def _altitude_rad(sun: np.ndarray) -> np.ndarray:
    return np.arcsin(np.clip(sun[..., 2], -1.0, 1.0))


def _clamp_sun(sun: np.ndarray, apply: np.ndarray | bool) -> tuple[np.ndarray, np.ndarray]:
    """gensky.c / gendaylit.c: a sun above 87 deg altitude is lowered to 87 deg.

    Both programs recompute the direction they write from the azimuth and the
    lowered altitude, so the returned direction is the one Radiance renders.
    Returns ``(altitude_rad, sun_direction)``.
    """
    altitude = _altitude_rad(sun)
    limit = np.deg2rad(_MAX_SUN_ALTITUDE)
    clamp = np.asarray(apply) & (altitude > limit)
    if not np.any(clamp):
        return altitude, sun
    # gensky's azimuth is measured from south, positive toward west:
    # sundir = (-sin(az) cos(alt), -cos(az) cos(alt), sin(alt)).
    azimuth = np.arctan2(-sun[..., 0], -sun[..., 1])
    lowered = np.stack(
        [
            -np.sin(azimuth) * np.cos(limit),
            -np.cos(azimuth) * np.cos(limit),
            np.full_like(azimuth, np.sin(limit)),
        ],
        axis=-1,
    )
    return np.where(clamp, limit, altitude), np.where(clamp[..., None], lowered, sun)


# --- gensky -----------------------------------------------------------------

_GENSKY_CODES = {"clear": 1, "overcast": 2, "uniform": 3, "intermediate": 4}
# gensky.c normsc(): polynomial in x = (altitude - pi/4)/(pi/4) approximating
# E0*F2/L0 (horizontal sky irradiance x F2 / zenith radiance); ascending powers.
_NORMSC_CLEAR = (2.766521, 0.547665, -0.369832, 0.009237, 0.059229)
_NORMSC_INTERMEDIATE = (3.5556, -2.7152, -1.3081, 1.0660, 0.60227)


def _normsc(altitude: np.ndarray, coefficients: tuple[float, ...]) -> np.ndarray:
    x = (altitude - np.pi / 4.0) / (np.pi / 4.0)
    return np.polynomial.polynomial.polyval(x, coefficients)


def _f2_clear(altitude: np.ndarray, sun_z: np.ndarray) -> np.ndarray:
    # gensky.c: F2 for the CIE clear sky, the indicatrix at the zenith x 0.274.
    return 0.274 * (0.91 + 10.0 * np.exp(-3.0 * (np.pi / 2.0 - altitude)) + 0.45 * sun_z * sun_z)


def _f2_intermediate(altitude: np.ndarray) -> np.ndarray:
    # gensky.c: F2 for the intermediate sky.
    return (2.739 + 0.9891 * np.sin(0.3119 + 2.6 * altitude)) * np.exp(
        -(np.pi / 2.0 - altitude) * (0.4441 + 1.48 * altitude)
    )


@dataclass(frozen=True, eq=False)
class GenskyParameters:
    """The numbers gensky writes for one or many skies.

    Every array has the broadcast shape of the inputs, ``sun_direction[..., 0]``
    and ``sky_type`` (``sun_direction`` has that shape plus (3,)).

    Attributes
    ----------
    sky_type : numpy.ndarray of str
        "clear", "intermediate", "overcast" or "uniform".
    zenith_radiance : numpy.ndarray
        gensky's ``zenithbr``, the skyfunc argument A2. [W sr^-1 m^-2]
    ground_radiance : numpy.ndarray
        gensky's ``groundbr``, argument A3. [W sr^-1 m^-2]
    normalisation : numpy.ndarray
        gensky's ``F2``, argument A4; NaN for overcast and uniform skies, for
        which gensky writes no A4. [-]
    solar_radiance : numpy.ndarray
        gensky's ``solarbr``: radiance of the 0.5 deg solar disc; 0 where gensky
        writes no sun (overcast, uniform, sun at or below the horizon).
        [W sr^-1 m^-2]
    sun_direction : numpy.ndarray
        Unit vector toward the sun, ``(..., 3)``, after gensky's 87 deg
        altitude limit for clear and intermediate skies (arguments A5-A7). [-]
    """

    sky_type: np.ndarray
    zenith_radiance: np.ndarray
    ground_radiance: np.ndarray
    normalisation: np.ndarray
    solar_radiance: np.ndarray
    sun_direction: np.ndarray

    @property
    def code(self) -> np.ndarray:
        """skybright.cal's A1: 1 clear, 2 overcast, 3 uniform, 4 intermediate."""
        return _gensky_codes(self.sky_type)


def _gensky_codes(sky_type: np.ndarray) -> np.ndarray:
    codes = np.zeros(np.shape(sky_type), dtype=int)
    for name, code in _GENSKY_CODES.items():
        codes[np.asarray(sky_type) == name] = code
    return codes


def gensky_parameters(
    sun_direction: Any,
    sky_type: Any,
    *,
    turbidity: Any = 2.45,
    ground_reflectance: Any = 0.2,
    zenith_radiance: Any = None,
    solar_radiance: Any = None,
) -> GenskyParameters:
    """Sky parameters exactly as Radiance's gensky computes them.

    Implements ``computesky()`` and ``normsc()`` of gensky.c [1]_: the 87 deg
    sun altitude limit for clear and intermediate skies, the normalisation F2
    and the polynomial ``normsc`` approximation of the horizontal sky
    irradiance, the zenith radiance formulas (CIE clear sky with turbidity,
    overcast ``8.6 sin(alt) + 0.123`` kcd/m^2, their mean for the intermediate
    sky; negative values clipped to 0; kcd/m^2 to radiance with
    ``1000 / SKY_EFFICACY``), the solar radiance
    ``1.5e9 / SUN_EFFICACY (1.147 - 0.147 / max(sin(alt), 0.16))`` (x 0.15 for
    the intermediate sky) and the ground radiance
    ``rho (zenithbr normfactor + 6e-5 / pi solarbr sin(alt))``.

    Parameters
    ----------
    sun_direction : array_like, shape (..., 3)
        Unit vector from the scene toward the sun, world frame (x east,
        y north, z up). [-]
    sky_type : str or array_like of str
        "clear" (gensky +s/-s), "intermediate" (+i/-i), "overcast" (-c) or
        "uniform" (-u); broadcast against ``sun_direction[..., 0]`` and the
        other arguments. [-]
    turbidity : float or array_like, optional
        gensky ``-t``, Linke turbidity used by the clear zenith formula. [-]
    ground_reflectance : float or array_like, optional
        gensky ``-g``, ground plane reflectance. [-]
    zenith_radiance : float or array_like, optional
        gensky ``-b``: zenith radiance given directly (not clipped). [W sr^-1 m^-2]
    solar_radiance : float or array_like, optional
        gensky ``-r``: solar radiance given directly; a value <= 0 gives no
        sun. [W sr^-1 m^-2]

    Returns
    -------
    GenskyParameters
        Arrays of the broadcast shape of ``sun_direction[..., 0]``,
        ``sky_type`` and the other arguments.

    Notes
    -----
    NaN in ``sun_direction`` propagates to the results. gensky's ``-s``/``-i``
    ("no sun") only stops it writing the sun: the ground still includes the
    sun's contribution, and ``solar_radiance`` here is what ``+s``/``+i`` would
    write; :func:`daylight` with ``sun=False`` reproduces ``-s``/``-i``.
    """
    sun = _unit_vectors(sun_direction, "sun_direction")
    kind = np.asarray(sky_type)
    if kind.dtype.kind not in "UO":
        raise ValueError(f"sky_type must be one of {sorted(_GENSKY_CODES)}, got {sky_type!r}")
    kind = kind.astype(str)
    unknown = ~np.isin(kind, list(_GENSKY_CODES))
    if np.any(unknown):
        raise ValueError(
            f"sky_type must be one of {sorted(_GENSKY_CODES)}, got {kind[unknown].ravel()[0]!r}"
        )
    turbidity = np.asarray(turbidity, dtype=float)
    rho = _nonnegative(ground_reflectance, "ground_reflectance")
    optional = [
        np.asarray(v, dtype=float) for v in (zenith_radiance, solar_radiance) if v is not None
    ]
    shape = np.broadcast_shapes(
        sun.shape[:-1], kind.shape, turbidity.shape, rho.shape, *(v.shape for v in optional)
    )
    sun = np.broadcast_to(sun, shape + (3,))
    kind, turbidity, rho = (np.broadcast_to(v, shape) for v in (kind, turbidity, rho))

    is_clear = kind == "clear"
    is_inter = kind == "intermediate"
    is_overcast = (kind == "overcast") | (kind == "uniform")
    altitude, sun = _clamp_sun(sun, ~is_overcast)
    sun_z = sun[..., 2]

    # gensky.c computesky(): normalisation factor, horizontal sky irradiance
    # over (pi x zenith radiance).
    f2 = np.where(
        is_clear, _f2_clear(altitude, sun_z), np.where(is_inter, _f2_intermediate(altitude), np.nan)
    )
    with np.errstate(invalid="ignore"):
        normfactor = np.select(
            [kind == "uniform", kind == "overcast", is_clear, is_inter],
            [
                1.0,
                0.777778,
                _normsc(altitude, _NORMSC_CLEAR) / f2 / np.pi,
                _normsc(altitude, _NORMSC_INTERMEDIATE) / f2 / np.pi,
            ],
            np.nan,
        )

    if zenith_radiance is None:
        overcast_zenith = 8.6 * sun_z + 0.123  # kcd/m^2, Moon-Spencer-type overcast
        clear_zenith = (1.376 * turbidity - 1.81) * np.tan(altitude) + 0.38  # kcd/m^2
        zenith = np.select(
            [is_overcast, is_clear],
            [overcast_zenith, clear_zenith],
            (clear_zenith + overcast_zenith) / 2.0,
        )
        zenith = np.where(zenith < 0.0, 0.0, zenith * (1000.0 / SKY_EFFICACY))
    else:
        zenith = np.broadcast_to(np.asarray(zenith_radiance, dtype=float), shape).copy()
    ground = zenith * normfactor

    if solar_radiance is None:
        solar = 1.5e9 / SUN_EFFICACY * (1.147 - 0.147 / np.maximum(sun_z, 0.16))
        solar = np.where(is_inter, 0.15 * solar, solar)  # gensky's "fudge factor"
        user_solar_ok = True
    else:
        solar = np.broadcast_to(np.asarray(solar_radiance, dtype=float), shape)
        user_solar_ok = solar > 0.0
    has_sun = ~is_overcast & (sun_z > 0.0) & user_solar_ok
    ground = np.where(has_sun, ground + 6e-5 / np.pi * solar * sun_z, ground)
    ground = ground * rho
    solar = np.where(has_sun, solar, 0.0)
    nan = np.isnan(sun_z)
    if np.any(nan):
        solar = np.where(nan, np.nan, solar)
        ground = np.where(nan, np.nan, ground)
    return GenskyParameters(
        sky_type=kind.copy(),
        zenith_radiance=np.asarray(zenith, dtype=float),
        ground_radiance=np.asarray(ground, dtype=float),
        normalisation=np.asarray(f2, dtype=float),
        solar_radiance=np.asarray(solar, dtype=float),
        sun_direction=np.array(sun, dtype=float),
    )


def _ground_blend(dz: np.ndarray, sky: np.ndarray, ground: np.ndarray) -> np.ndarray:
    """skybright.cal/perezlum.cal: wmean((Dz+1.01)^10, sky, (Dz+1.01)^-10, ground)."""
    w = (dz + 1.01) ** 20  # the ratio of the two weights
    out = sky * w
    out += ground
    out /= w + 1.0
    return out


def skybright(directions: Any, params: GenskyParameters) -> np.ndarray:
    """Sky radiance of a gensky sky, exactly as ``skybright.cal`` computes it.

    ``skybright.cal`` [1]_ evaluates, with ``g`` the angle to the sun, ``eta``
    the zenith angle of the direction and ``Zs`` that of the sun:

    - clear (CIE 1973): ``A2 (0.91 + 10 exp(-3 g) + 0.45 cos^2 g)
      (1 - exp(-0.32 / Dz)) / A4``, the last factor replaced by 1 where
      ``Dz <= 0.01``;
    - overcast (Moon & Spencer): ``A2 (1 + 2 Dz) / 3``;
    - uniform: ``A2``;
    - intermediate: ``A2 ((1.35 sin(5.631 - 3.59 eta) + 3.12) sin(4.396 - 2.6 Zs)
      + 6.37 - eta) / 2.326 exp(-0.563 g ((2.629 - eta)(1.562 - Zs) + 0.812)) / A4``;

    and blends every value with the ground radiance A3:
    ``wmean((Dz + 1.01)^10, sky, (Dz + 1.01)^-10, A3)``, so that directions
    below the horizon see the ground.

    Parameters
    ----------
    directions : array_like, shape (..., 3)
        Unit vectors toward the sky points, world frame; the leading axes
        broadcast against the shape of ``params`` (e.g. ``(K, 1, 3)`` with
        ``T`` skies gives ``(K, T)``). [-]
    params : GenskyParameters
        Output of :func:`gensky_parameters`.

    Returns
    -------
    numpy.ndarray
        Radiance. [W sr^-1 m^-2]

    Notes
    -----
    NaN directions give NaN.
    """
    if not isinstance(params, GenskyParameters):
        raise TypeError(f"params must be GenskyParameters, got {type(params).__name__}")
    d = _unit_vectors(directions, "directions")
    dx, dy, dz = d[..., 0], d[..., 1], d[..., 2]
    sx, sy, sz = (params.sun_direction[..., i] for i in range(3))
    code = params.code
    a2, a3, a4 = params.zenith_radiance, params.ground_radiance, params.normalisation

    cosgamma = np.clip(dx * sx + dy * sy + dz * sz, -1.0, 1.0)
    gamma = np.arccos(cosgamma)  # skybright.cal uses Acos (bounded)

    def sunny():
        above = dz - _HORIZON_GUARD > 0.0
        gradation = np.where(above, 1.0 - np.exp(-0.32 / np.where(above, dz, 1.0)), 1.0)
        # A2 (0.91 + 10 exp(-3 g) + 0.45 cos^2 g) gradation / A4, in place
        out = np.exp(-3.0 * gamma)
        out *= 10.0
        out += 0.91
        out += 0.45 * cosgamma * cosgamma
        out *= gradation
        out *= a2 / a4
        return out

    def cloudy():
        return a2 * (1.0 + 2.0 * dz) / 3.0

    def uniform():
        return a2 * np.ones_like(dz)

    def inter():
        zt = np.arccos(np.clip(sz, -1.0, 1.0))
        eta = np.arccos(np.clip(dz, -1.0, 1.0))
        return (
            a2
            * ((1.35 * np.sin(5.631 - 3.59 * eta) + 3.12) * np.sin(4.396 - 2.6 * zt) + 6.37 - eta)
            / 2.326
            * np.exp(gamma * -0.563 * ((2.629 - eta) * (1.562 - zt) + 0.812))
            / a4
        )

    # evaluate only the sky types present (usually one for a whole sequence)
    branches = {1: sunny, 2: cloudy, 3: uniform, 4: inter}
    present = [int(c) for c in np.unique(code) if int(c) in branches]
    if len(present) == 1 and np.all(code == present[0]):
        sky = branches[present[0]]()
    else:
        sky = np.full(np.broadcast_shapes(dz.shape, np.shape(code)), np.nan)
        for c in present:
            sky = np.where(code == c, branches[c](), sky)
    return _ground_blend(dz, sky, a3)


# --- CIE standard general sky ---------------------------------------------

# ISO 15469:2004 / CIE S 011/E:2003, Table 1 (also Darula & Kittler 2002,
# Table 1): gradation groups I-VI (a, b) and indicatrix groups 1-6 (c, d, e).
# The type -> (gradation, indicatrix) assignment below is the standard's
# Table 1 as reproduced by Darula & Kittler (2002) and in colour-science's
# colour.phenomena.sky.cie2003 (checked against each other; one third-party
# copy has e = 0.35 for type 7, a typo: the standard's indicatrix group 3 has
# e = 0.30).
_CIE_GRADATION = {
    "I": (4.0, -0.70),
    "II": (1.1, -0.80),
    "III": (0.0, -1.00),
    "IV": (-1.0, -0.55),
    "V": (-1.0, -0.32),
    "VI": (-1.0, -0.15),
}
_CIE_INDICATRIX = {
    1: (0.0, -1.0, 0.00),
    2: (2.0, -1.5, 0.15),
    3: (5.0, -2.5, 0.30),
    4: (10.0, -3.0, 0.45),
    5: (16.0, -3.0, 0.30),
    6: (24.0, -2.8, 0.15),
}
#: CIE standard general sky types: type -> (gradation group, indicatrix group, description).
CIE_SKY_TYPES: dict[int, tuple[str, int, str]] = {
    1: ("I", 1, "CIE standard overcast sky, steep gradation, azimuthal uniformity"),
    2: ("I", 2, "overcast, steep gradation, slight brightening toward the sun"),
    3: ("II", 1, "overcast, moderately graded, azimuthal uniformity"),
    4: ("II", 2, "overcast, moderately graded, slight brightening toward the sun"),
    5: ("III", 1, "sky of uniform luminance"),
    6: ("III", 2, "partly cloudy, no gradation toward zenith, slight brightening toward sun"),
    7: ("III", 3, "partly cloudy, no gradation toward zenith, brighter circumsolar region"),
    8: ("III", 4, "partly cloudy, no gradation toward zenith, distinct solar corona"),
    9: ("IV", 2, "partly cloudy, with the obscured sun"),
    10: ("IV", 3, "partly cloudy, with brighter circumsolar region"),
    11: ("IV", 4, "white-blue sky with distinct solar corona"),
    12: ("V", 4, "CIE standard clear sky, low luminance turbidity"),
    13: ("V", 5, "CIE standard clear sky, polluted atmosphere"),
    14: ("VI", 5, "cloudless turbid sky with broad solar corona"),
    15: ("VI", 6, "white-blue turbid sky with broad solar corona"),
}
# (15, 5) table of a, b, c, d, e indexed by type - 1.
_CIE_TABLE = np.array(
    [_CIE_GRADATION[g] + _CIE_INDICATRIX[i] for g, i, _ in (CIE_SKY_TYPES[t] for t in range(1, 16))]
)


def _cie_types(sky_type: Any) -> np.ndarray:
    arr = np.asarray(sky_type)
    if arr.dtype.kind not in "iuf":
        raise ValueError(f"sky_type must be an integer 1..15, got {sky_type!r}")
    ints = np.asarray(arr, dtype=float)
    bad = ~np.isin(ints, np.arange(1, 16))
    if np.any(bad):
        raise ValueError(f"sky_type must be an integer 1..15, got {ints[bad].ravel()[0]!r}")
    return ints.astype(int)


def _cie_gradation(cos_z: np.ndarray, a: Any, b: Any) -> np.ndarray:
    # ISO 15469 eq. 3: phi(Z) = 1 + a exp(b / cos Z); phi(pi/2) = 1 at the horizon.
    positive = cos_z > 0.0
    with np.errstate(over="ignore", divide="ignore"):
        term = a * np.exp(b / np.where(positive, cos_z, 1.0))
    return 1.0 + np.where(positive, term, 0.0)


def _cie_indicatrix(chi: np.ndarray, c: Any, d: Any, e: Any) -> np.ndarray:
    # ISO 15469 eq. 5: f(chi) = 1 + c (exp(d chi) - exp(d pi/2)) + e cos^2 chi.
    return 1.0 + c * (np.exp(d * chi) - np.exp(d * np.pi / 2.0)) + e * np.cos(chi) ** 2


def cie_general(directions: Any, sun_direction: Any, sky_type: Any) -> np.ndarray:
    """Relative luminance ``L / Lz`` of the CIE standard general sky.

    ISO 15469:2004 / CIE S 011/E:2003 [3]_, eq. 7::

        L / Lz = f(chi) phi(Z) / (f(Zs) phi(0))

    with ``phi(Z) = 1 + a exp(b / cos Z)`` (eq. 3; 1 at the horizon),
    ``f(chi) = 1 + c (exp(d chi) - exp(d pi / 2)) + e cos^2 chi`` (eq. 5),
    ``Z`` the zenith angle of the sky point, ``chi`` its angle to the sun
    (eq. 1) and ``Zs`` the solar zenith angle; ``(a, b, c, d, e)`` from the
    standard's Table 1 (see :data:`CIE_SKY_TYPES`).

    Parameters
    ----------
    directions : array_like, shape (..., 3)
        Unit vectors toward the sky points, world frame. [-]
    sun_direction : array_like, shape (..., 3)
        Unit vector toward the sun; broadcast against ``directions``. [-]
    sky_type : int or array_like of int
        Standard sky type 1..15; broadcast against the other inputs. [-]

    Returns
    -------
    numpy.ndarray
        Luminance relative to the zenith luminance; 1 at the zenith, 0 for
        directions below the horizon (``Dz < 0``: not sky). [-]

    Notes
    -----
    The standard defines the skies for the sun above the horizon; the formula
    is evaluated as it stands for any sun. NaN directions give NaN.
    """
    d = _unit_vectors(directions, "directions")
    sun = _unit_vectors(sun_direction, "sun_direction")
    types = _cie_types(sky_type)
    a, b, c, dd, e = np.moveaxis(_CIE_TABLE[types - 1], -1, 0)
    dz = d[..., 2]
    sun_z = sun[..., 2]
    chi = np.arccos(np.clip(np.sum(d * sun, axis=-1), -1.0, 1.0))  # eq. 1
    zenith_sun = np.arccos(np.clip(sun_z, -1.0, 1.0))
    relative = (
        _cie_indicatrix(chi, c, dd, e)
        * _cie_gradation(dz, a, b)
        / (_cie_indicatrix(zenith_sun, c, dd, e) * (1.0 + a * np.exp(b)))
    )
    return np.where(dz < 0.0, 0.0, relative)


# --- Perez 1993 all-weather sky, as gendaylit -------------------------------

# Perez, Seals & Michalsky (1993) Table 1, as gendaylit.c's coeff_perez[]:
# [clearness bin][parameter a..e][x0, x1, x2, x3], each parameter
# x0 + x1 Z + Delta (x2 + x3 Z) (Z the solar zenith angle in radians), except
# bin 1's c and d (see perez_coefficients). gendaylit stores the table as C
# float; the float32 rounding is kept so the coefficients match bit for bit.
_PEREZ_TABLE = np.array(
    [
        [
            [1.3525, -0.2576, -0.2690, -1.4366],
            [-0.7670, 0.0007, 1.2734, -0.1233],
            [2.8000, 0.6004, 1.2375, 1.0000],
            [1.8734, 0.6297, 0.9738, 0.2809],
            [0.0356, -0.1246, -0.5718, 0.9938],
        ],
        [
            [-1.2219, -0.7730, 1.4148, 1.1016],
            [-0.2054, 0.0367, -3.9128, 0.9156],
            [6.9750, 0.1774, 6.4477, -0.1239],
            [-1.5798, -0.5081, -1.7812, 0.1080],
            [0.2624, 0.0672, -0.2190, -0.4285],
        ],
        [
            [-1.1000, -0.2515, 0.8952, 0.0156],
            [0.2782, -0.1812, -4.5000, 1.1766],
            [24.7219, -13.0812, -37.7000, 34.8438],
            [-5.0000, 1.5218, 3.9229, -2.6204],
            [-0.0156, 0.1597, 0.4199, -0.5562],
        ],
        [
            [-0.5484, -0.6654, -0.2672, 0.7117],
            [0.7234, -0.6219, -5.6812, 2.6297],
            [33.3389, -18.3000, -62.2500, 52.0781],
            [-3.5000, 0.0016, 1.1477, 0.1062],
            [0.4659, -0.3296, -0.0876, -0.0329],
        ],
        [
            [-0.6000, -0.3566, -2.5000, 2.3250],
            [0.2937, 0.0496, -5.6812, 1.8415],
            [21.0000, -4.7656, -21.5906, 7.2492],
            [-3.5000, -0.1554, 1.4062, 0.3988],
            [0.0032, 0.0766, -0.0656, -0.1294],
        ],
        [
            [-1.0156, -0.3670, 1.0078, 1.4051],
            [0.2875, -0.5328, -3.8500, 3.3750],
            [14.0000, -0.9999, -7.1406, 7.5469],
            [-3.4000, -0.1078, -1.0750, 1.5702],
            [-0.0672, 0.4016, 0.3017, -0.4844],
        ],
        [
            [-1.0000, 0.0211, 0.5025, -0.5119],
            [-0.3000, 0.1922, 0.7023, -1.6317],
            [19.0000, -5.0000, 1.2438, -1.9094],
            [-4.0000, 0.0250, 0.3844, 0.2656],
            [1.0468, -0.3788, -2.4517, 1.4656],
        ],
        [
            [-1.0500, 0.0289, 0.4260, 0.3590],
            [-0.3250, 0.1156, 0.7781, 0.0025],
            [31.0625, -14.5000, -46.1148, 55.3750],
            [-7.2312, 0.4050, 13.3500, 0.6234],
            [1.5000, -0.6426, 1.8564, 0.5636],
        ],
    ],
    dtype=np.float32,
).astype(float)
# Upper clearness bounds of bins 1..7 (Perez et al. 1990, Table 1).
_PEREZ_BIN_EDGES = np.array([1.065, 1.230, 1.500, 1.950, 2.800, 4.500, 6.200])
# gendaylit check_parametrization(): the range epsilon and Delta are clipped to.
_EPSILON_RANGE = (1.0, 12.01)
_DELTA_RANGE = (0.01, 0.6)

# Perez et al. (1990) Table 4, as gendaylit.c: luminous efficacy [lm/W]
# = a + b W + c cos Z + d ln(Delta) (diffuse horizontal) and
# = a + b W + c exp(5.73 Z - 5) + d Delta (direct normal), per clearness bin,
# rows a, b, c, d.
_DIFFUSE_EFFICACY = np.array(
    [
        [97.24, 107.22, 104.97, 102.39, 100.71, 106.42, 141.88, 152.23],
        [-0.46, 1.15, 2.96, 5.59, 5.94, 3.83, 1.90, 0.35],
        [12.00, 0.59, -5.53, -13.95, -22.75, -36.15, -53.24, -45.27],
        [-8.91, -3.95, -8.77, -13.90, -23.74, -28.83, -14.03, -7.98],
    ]
)
_DIRECT_EFFICACY = np.array(
    [
        [57.20, 98.99, 109.83, 110.34, 106.36, 107.19, 105.75, 101.18],
        [-4.55, -3.46, -4.90, -5.84, -3.97, -1.25, 0.77, 1.58],
        [-2.98, -1.21, -1.71, -1.99, -1.75, -1.51, -1.26, -1.10],
        [117.12, 12.38, -8.81, -4.56, -6.16, -26.73, -34.44, -8.29],
    ]
)

# gendaylit's integration grid: the 145 Tregenza patch centres (zenith angle
# theta, azimuth phi from the sun's azimuth, deg), each weighted 2 pi / 145.
_TREGENZA_BANDS = ((84, 30), (72, 30), (60, 24), (48, 24), (36, 18), (24, 12), (12, 6), (0, 1))
_GRID_THETA = np.concatenate([np.full(n, t, dtype=float) for t, n in _TREGENZA_BANDS])
_GRID_PHI = np.concatenate([np.arange(n) * 360.0 / n for _, n in _TREGENZA_BANDS])


class PerezCoefficients(NamedTuple):
    """Perez (1993) coefficients a..e of eq. 1, arrays of a common shape."""

    a: np.ndarray
    b: np.ndarray
    c: np.ndarray
    d: np.ndarray
    e: np.ndarray


def perez_coefficients(epsilon: Any, delta: Any, solar_zenith: Any) -> PerezCoefficients:
    """Coefficients a..e of the Perez (1993) sky, as gendaylit computes them.

    Perez et al. (1993) [4]_, eq. 2 and Table 1: in each of 8 clearness bins,
    ``x = x0 + x1 Z + Delta (x2 + x3 Z)`` for each of a..e, ``Z`` the solar
    zenith angle in radians; in bin 1 (``epsilon < 1.065``)
    ``c = exp((Delta (c0 + c1 Z))^c2) - c3`` and
    ``d = -exp(Delta (d0 + d1 Z)) + d2 + Delta d3``. As gendaylit's
    ``coeff_lum_perez()``: Delta is raised to 0.2 where
    ``1.065 < epsilon < 2.8``, and the bin is chosen from epsilon rounded to
    single precision.

    Parameters
    ----------
    epsilon : array_like
        Perez sky clearness, in [1, 12.01). [-]
    delta : array_like
        Perez sky brightness. [-]
    solar_zenith : array_like
        Solar zenith angle. [deg]

    Returns
    -------
    PerezCoefficients
        ``a, b, c, d, e`` broadcast to a common shape. [-]

    Notes
    -----
    NaN in any input gives NaN coefficients.
    """
    eps = np.asarray(epsilon, dtype=float)
    bad = (eps < _EPSILON_RANGE[0]) | (eps >= _EPSILON_RANGE[1])
    if np.any(bad):
        raise ValueError(f"epsilon must lie in [1, 12.01), got {eps[bad].ravel()[0]!r}")
    eps, dlt, zen = np.broadcast_arrays(
        eps, np.asarray(delta, dtype=float), np.asarray(solar_zenith, dtype=float)
    )
    z = np.deg2rad(zen)
    dlt = np.where((eps > 1.065) & (eps < 2.8) & (dlt < 0.2), 0.2, dlt)
    # gendaylit's get_numlin(float epsilon): bin from epsilon as a C float.
    eps32 = eps.astype(np.float32).astype(float)
    index = np.searchsorted(_PEREZ_BIN_EDGES, np.where(np.isnan(eps32), 1.0, eps32), side="right")
    x = _PEREZ_TABLE[index]  # (..., 5, 4)
    linear = (
        x[..., 0]
        + x[..., 1] * z[..., None]
        + dlt[..., None] * (x[..., 2] + x[..., 3] * z[..., None])
    )
    a, b, c, d, e = np.moveaxis(linear, -1, 0)
    first = index == 0
    if np.any(first):
        base = np.maximum(dlt * (x[..., 2, 0] + x[..., 2, 1] * z), 0.0)
        # computed for every entry, kept for the first bin only (other bins'
        # coefficients may overflow here, harmlessly)
        with np.errstate(over="ignore"):
            c1 = np.exp(base ** x[..., 2, 2]) - x[..., 2, 3]
            d1 = (
                -np.exp(dlt * (x[..., 3, 0] + x[..., 3, 1] * z)) + x[..., 3, 2] + dlt * x[..., 3, 3]
            )
        c = np.where(first, c1, c)
        d = np.where(first, d1, d)
    nan = np.isnan(eps) | np.isnan(dlt) | np.isnan(z)
    coefficients = (np.where(nan, np.nan, v) for v in (a, b, c, d, e))
    return PerezCoefficients(*coefficients)


def _radiance_exp(x: np.ndarray) -> np.ndarray:
    """rayinit.cal's Exp(x): 0 below x = -100, else exp(x)."""
    with np.errstate(over="ignore"):
        return np.where(x < -100.0, 0.0, np.exp(np.maximum(x, -100.0)))


def _perez_relative(d: np.ndarray, sun: np.ndarray, co: PerezCoefficients) -> np.ndarray:
    """perezlum.cal's intersky / A1: eq. 1 with the Dz <= 0.01 guard."""
    dz = d[..., 2]
    cosgamma = np.sum(d * sun, axis=-1)
    gamma = np.arccos(np.clip(cosgamma, -1.0, 1.0))
    cos_zeta = np.where(dz - _HORIZON_GUARD > 0.0, dz, _HORIZON_GUARD)
    gradation = 1.0 + co.a * _radiance_exp(co.b / cos_zeta)
    indicatrix = 1.0 + co.c * _radiance_exp(co.d * gamma) + co.e * cosgamma * cosgamma
    return gradation * indicatrix


def perez_1993(directions: Any, sun_direction: Any, epsilon: Any, delta: Any) -> np.ndarray:
    """Relative luminance of the Perez et al. (1993) all-weather sky.

    Eq. 1 of Perez et al. (1993) [4]_::

        l = (1 + a exp(b / cos zeta)) (1 + c exp(d gamma) + e cos^2 gamma)

    with ``zeta`` the zenith angle of the sky point and ``gamma`` its angle to
    the sun, coefficients from :func:`perez_coefficients`. As in
    ``perezlum.cal``, ``cos zeta`` is replaced by 0.01 where it is <= 0.01
    (horizon guard) and ``exp`` of arguments below -100 is 0.

    Parameters
    ----------
    directions : array_like, shape (..., 3)
        Unit vectors toward the sky points, world frame. [-]
    sun_direction : array_like, shape (..., 3)
        Unit vector toward the sun (its altitude gives the solar zenith angle
        of the coefficients); broadcast against ``directions``. [-]
    epsilon : array_like
        Perez sky clearness, in [1, 12.01). [-]
    delta : array_like
        Perez sky brightness. [-]

    Returns
    -------
    numpy.ndarray
        Relative luminance, unnormalised (the scale of eq. 1). Directions
        below the horizon get the horizon-guarded value, as perezlum.cal's
        ``intersky``. [-]
    """
    d = _unit_vectors(directions, "directions")
    sun = _unit_vectors(sun_direction, "sun_direction")
    zenith = np.rad2deg(np.arccos(np.clip(sun[..., 2], -1.0, 1.0)))
    co = perez_coefficients(epsilon, delta, zenith)
    return _perez_relative(d, sun, co)


def _eccentricity(day_of_year: np.ndarray) -> np.ndarray:
    # gendaylit get_eccentricity(): Spencer (1971) series for (R0/R)^2.
    angle = 2.0 * np.pi * (day_of_year - 1.0) / 365.0
    return (
        1.00011
        + 0.034221 * np.cos(angle)
        + 0.00128 * np.sin(angle)
        + 0.000719 * np.cos(2 * angle)
        + 0.000077 * np.sin(2 * angle)
    )


def _gendaylit_air_mass(zenith_deg: np.ndarray) -> np.ndarray:
    # gendaylit air_mass(): Kasten (1966), zenith limited to 90 deg.
    z = np.minimum(zenith_deg, 90.0)
    return 1.0 / (np.cos(np.deg2rad(z)) + 0.15 * (93.885 - z) ** -1.253)


def _perez_epsilon_delta(zenith_deg, dni, dhi, day_of_year):
    """gendaylit -W: sky_brightness(), sky_clearness(), check_parametrization()."""
    z_deg = np.minimum(zenith_deg, 90.0)  # air_mass() overwrites sunzenith with 90
    delta = dhi * _gendaylit_air_mass(z_deg) / (SOLAR_CONSTANT * _eccentricity(day_of_year))
    z3 = 1.041 * np.deg2rad(z_deg) ** 3
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = (dhi + dni) / dhi
    ratio = np.where((dhi == 0) & (dni == 0), 1.0, ratio)  # no light: gendaylit's error sky
    epsilon = (ratio + z3) / (1.0 + z3)
    epsilon = np.where(epsilon < _EPSILON_RANGE[0], _EPSILON_RANGE[0], epsilon)
    epsilon = np.where(epsilon > _EPSILON_RANGE[1], _EPSILON_RANGE[1] - 0.001, epsilon)
    delta = np.clip(delta, *_DELTA_RANGE)
    return epsilon, delta, z_deg


def perez_parameters(
    sun_direction: Any,
    direct_normal_irradiance: Any,
    diffuse_horizontal_irradiance: Any,
    day_of_year: Any,
) -> tuple[np.ndarray, np.ndarray]:
    """Perez sky clearness and brightness, as gendaylit ``-W`` computes them.

    Perez et al. (1990) [5]_ eqs. 1-2::

        epsilon = ((Dh + I) / Dh + 1.041 Z^3) / (1 + 1.041 Z^3)
        Delta = Dh m / (I0 E0)

    with ``Z`` the solar zenith angle in radians, ``m`` gendaylit's air mass
    ``1 / (cos Z + 0.15 (93.885 - Z_deg)^-1.253)`` (Kasten 1966),
    ``I0 = 1367 W m^-2`` and ``E0`` the eccentricity correction (Spencer
    series). As gendaylit: the sun is first limited to 87 deg altitude (so
    ``Z >= 3 deg``), ``Z`` is limited to 90 deg, and the results are clipped to
    epsilon in [1, 12.009] and Delta in [0.01, 0.6].

    Parameters
    ----------
    sun_direction : array_like, shape (..., 3)
        Unit vector toward the sun. [-]
    direct_normal_irradiance : array_like
        Direct normal irradiance ``I``, broadband. [W m^-2]
    diffuse_horizontal_irradiance : array_like
        Diffuse horizontal irradiance ``Dh``, broadband. [W m^-2]
    day_of_year : array_like
        Day number for the eccentricity, 1..365; gendaylit uses
        ``jdate(month, day)``, and 0 with ``-ang``. [day]

    Returns
    -------
    epsilon, delta : numpy.ndarray
        Clearness and brightness, broadcast to a common shape. [-]

    Notes
    -----
    With both irradiances 0 (gendaylit writes an all-zero "error sky") the
    result is epsilon = 1. NaN inputs propagate.
    """
    sun = _unit_vectors(sun_direction, "sun_direction")
    dni = _nonnegative(direct_normal_irradiance, "direct_normal_irradiance")
    dhi = _nonnegative(diffuse_horizontal_irradiance, "diffuse_horizontal_irradiance")
    day = _day_of_year(day_of_year)
    altitude, _ = _clamp_sun(sun, True)
    zenith = 90.0 - np.rad2deg(altitude)
    epsilon, delta, _ = _perez_epsilon_delta(zenith, dni, dhi, day)
    return epsilon, delta


def _day_of_year(value: Any) -> np.ndarray:
    day = np.asarray(value, dtype=float)
    bad = (day < 0) | (day > 366)
    if np.any(bad):
        raise ValueError(f"day_of_year must lie in [0, 366], got {day[bad].ravel()[0]!r}")
    return day


def _efficacy_bin(epsilon: np.ndarray) -> np.ndarray:
    return np.searchsorted(
        _PEREZ_BIN_EDGES, np.where(np.isnan(epsilon), 1.0, epsilon), side="right"
    )


def _perez_illuminances(zenith_deg, dni, dhi, day, precipitable_water):
    """gendaylit -W: epsilon, Delta, diffuse and direct illuminance [lx]."""
    epsilon, delta, z_deg = _perez_epsilon_delta(zenith_deg, dni, dhi, day)
    k = _efficacy_bin(epsilon)
    z = np.deg2rad(z_deg)
    a, b, c, d = _DIFFUSE_EFFICACY[:, k]
    diffuse_efficacy = a + b * precipitable_water + c * np.cos(z) + d * np.log(delta)
    a, b, c, d = _DIRECT_EFFICACY[:, k]
    direct_efficacy = np.maximum(
        a + b * precipitable_water + c * np.exp(5.73 * z - 5.0) + d * delta, 0.0
    )
    diffuse = np.maximum(dhi * diffuse_efficacy, 0.0)
    direct = np.maximum(dni * direct_efficacy, 0.0)
    return epsilon, delta, z_deg, diffuse, direct


@dataclass(frozen=True, eq=False)
class GendaylitParameters:
    """The numbers gendaylit writes for one or many Perez skies.

    Arrays have the shape of ``sun_direction[..., 0]`` (the coefficients too).

    Attributes
    ----------
    sun_direction : numpy.ndarray
        Unit vector toward the sun after the 87 deg altitude limit
        (perezlum.cal A8-A10). [-]
    epsilon, delta : numpy.ndarray
        Perez clearness and brightness after gendaylit's clipping. [-]
    coefficients : PerezCoefficients
        a..e (perezlum.cal A3-A7). [-]
    diffuse_normalisation : numpy.ndarray
        perezlum.cal A1: radiance per unit relative luminance. [W sr^-1 m^-2]
    ground_radiance : numpy.ndarray
        perezlum.cal A2. [W sr^-1 m^-2]
    solar_radiance : numpy.ndarray
        Radiance of the 0.533 deg solar disc, 0 where gendaylit writes none.
        [W sr^-1 m^-2]
    diffuse_illuminance, direct_illuminance : numpy.ndarray
        Diffuse horizontal and direct normal illuminance from the Perez (1990)
        efficacy models. [lx]
    """

    sun_direction: np.ndarray
    epsilon: np.ndarray
    delta: np.ndarray
    coefficients: PerezCoefficients
    diffuse_normalisation: np.ndarray
    ground_radiance: np.ndarray
    solar_radiance: np.ndarray
    diffuse_illuminance: np.ndarray
    direct_illuminance: np.ndarray


def _gendaylit_grid_integral(co: PerezCoefficients, zenith_rad: np.ndarray) -> np.ndarray:
    """gendaylit integ_lv(): sum of l cos(theta) over the 145 grid points x 2 pi / 145."""
    theta = np.deg2rad(_GRID_THETA)
    phi = np.deg2rad(_GRID_PHI)
    z = zenith_rad[..., None]
    cosg = np.cos(z) * np.cos(theta) + np.sin(z) * np.sin(theta) * np.cos(phi)
    gamma = np.arccos(np.clip(cosg, -1.0, 1.0))  # theta_phi_to_dzeta_gamma()
    a, b, c, d, e = (v[..., None] for v in co)
    lum = (1.0 + a * np.exp(b / np.cos(theta))) * (
        1.0 + c * np.exp(d * gamma) + e * np.cos(gamma) ** 2
    )
    lum = lum.astype(np.float32).astype(float)  # gendaylit stores lv_mod as float
    return np.sum(lum * np.cos(theta), axis=-1) * (2.0 * np.pi / 145.0)


def gendaylit_parameters(
    sun_direction: Any,
    direct_normal_irradiance: Any,
    diffuse_horizontal_irradiance: Any,
    *,
    day_of_year: Any = 0,
    ground_reflectance: Any = 0.2,
    precipitable_water: float = 2.0,
    sun: bool = True,
) -> GendaylitParameters:
    """Perez sky parameters exactly as gendaylit ``-W`` (output ``-O0``) computes them.

    Steps of gendaylit.c's ``computesky()``: :func:`perez_parameters`; diffuse
    and direct illuminance from the Perez et al. (1990) [5]_ luminous efficacy
    models (Table 4) with precipitable water ``W``; coefficients from
    :func:`perez_coefficients`; the diffuse normalisation
    ``A1 = Ed / (179 S)``, where ``S`` is gendaylit's integral of
    ``l cos(theta)`` over its 145-point grid (patch centres of the Tregenza
    sky, each weighted ``2 pi / 145``); the solar radiance
    ``Eb / (179 x 2 pi (1 - cos 0.2665 deg))``; the ground radiance
    ``rho (Lz normfactor + 6.8e-5 / pi Ls sin(alt))`` with ``Lz = A1 l(zenith)``
    and gensky's ``normfactor`` (0.777778 for epsilon = 1, gensky's
    intermediate formula for 1 < epsilon < 6, its clear formula above).

    Parameters
    ----------
    sun_direction : array_like, shape (..., 3)
        Unit vector toward the sun. [-]
    direct_normal_irradiance : array_like
        Direct normal irradiance, broadband, at most 1367. [W m^-2]
    diffuse_horizontal_irradiance : array_like
        Diffuse horizontal irradiance, broadband. [W m^-2]
    day_of_year : array_like, optional
        Day number for the eccentricity; gendaylit uses ``jdate(month, day)``
        (1..365, no leap day) and 0 with ``-ang``. [day]
    ground_reflectance : array_like, optional
        gendaylit ``-g``. [-]
    precipitable_water : float, optional
        Atmospheric precipitable water of the efficacy models; gendaylit's
        default dew point gives 2.0. [cm]
    sun : bool, optional
        False as gendaylit ``-s``: no sun, and no sun term in the ground. [-]

    Returns
    -------
    GendaylitParameters

    Notes
    -----
    Where gendaylit writes its all-zero "error sky" the results are zero
    (documented zeros, not exceptions): sun at or below the horizon, both
    irradiances 0, a positive coefficient b, or a direct illuminance above
    127500 lx. NaN inputs propagate. For a sun below the horizon this follows
    gendaylit's date mode (error sky); with ``-ang`` gendaylit instead writes a
    glowing sky and a sun computed with the zenith angle limited to 90 deg.
    """
    sun_dir = _unit_vectors(sun_direction, "sun_direction")
    dni = _nonnegative(direct_normal_irradiance, "direct_normal_irradiance")
    too_bright = dni > SOLAR_CONSTANT
    if np.any(too_bright):
        raise ValueError(
            f"direct_normal_irradiance must not exceed the solar constant "
            f"{SOLAR_CONSTANT} W m-2, got {dni[too_bright].ravel()[0]!r}"
        )
    dhi = _nonnegative(diffuse_horizontal_irradiance, "diffuse_horizontal_irradiance")
    day = _day_of_year(day_of_year)
    rho = _nonnegative(ground_reflectance, "ground_reflectance")
    shape = np.broadcast_shapes(sun_dir.shape[:-1], dni.shape, dhi.shape, day.shape, rho.shape)
    sun_dir = np.broadcast_to(sun_dir, shape + (3,))
    dni, dhi, day, rho = (np.broadcast_to(v, shape) for v in (dni, dhi, day, rho))

    altitude, sun_dir = _clamp_sun(sun_dir, True)
    zenith = 90.0 - np.rad2deg(altitude)
    epsilon, delta, z_deg, diffuse, direct = _perez_illuminances(
        zenith, dni, dhi, day, float(precipitable_water)
    )
    zenith_rad = np.deg2rad(z_deg)
    co = perez_coefficients(epsilon, delta, z_deg)

    integral = _gendaylit_grid_integral(co, zenith_rad)
    normalisation = diffuse / integral / WHITE_EFFICACY
    solar = direct / sun_solid_angle(2 * _GENDAYLIT_HALF_SUN_ANGLE) / WHITE_EFFICACY

    # Ground: zenith radiance x gensky's normfactor for the matching sky.
    zenith_lum = _perez_relative(
        np.array([0.0, 0.0, 1.0]),
        np.stack([np.sin(zenith_rad), np.zeros_like(zenith_rad), np.cos(zenith_rad)], axis=-1),
        co,
    )
    sun_z = np.sin(altitude)
    with np.errstate(invalid="ignore", divide="ignore"):
        normfactor = np.select(
            [epsilon == 1.0, epsilon >= 6.0],
            [0.777778, _normsc(altitude, _NORMSC_CLEAR) / _f2_clear(altitude, sun_z) / np.pi],
            _normsc(altitude, _NORMSC_INTERMEDIATE) / _f2_intermediate(altitude) / np.pi,
        )
    ground = zenith_lum * normalisation * normfactor
    if sun:
        ground = np.where(epsilon > 1.0, ground + 6.8e-5 / np.pi * solar * sun_z, ground)
    else:
        solar = np.zeros_like(solar)
    ground = ground * rho
    solar = np.where(epsilon > 1.0, solar, 0.0)

    error_sky = (
        (sun_dir[..., 2] <= 0.0)
        | ((dni == 0) & (dhi == 0))
        | (co.b > 0.0)
        | (direct > _SOLAR_CONSTANT_LUX)
    )
    zero = np.zeros(shape)
    return GendaylitParameters(
        sun_direction=np.array(sun_dir, dtype=float),
        epsilon=np.asarray(epsilon, dtype=float),
        delta=np.asarray(delta, dtype=float),
        coefficients=co,
        diffuse_normalisation=np.where(error_sky, zero, normalisation),
        ground_radiance=np.where(error_sky, zero, ground),
        solar_radiance=np.where(error_sky, zero, solar),
        diffuse_illuminance=np.where(error_sky, zero, diffuse),
        direct_illuminance=np.where(error_sky, zero, direct),
    )


def _perezlum(directions: np.ndarray, params: GendaylitParameters) -> np.ndarray:
    """perezlum.cal's skybright: A1 x eq. 1, blended with the ground A2."""
    relative = _perez_relative(directions, params.sun_direction, params.coefficients)
    sky = params.diffuse_normalisation * relative
    return _ground_blend(directions[..., 2], sky, params.ground_radiance)


# --- the sun as a disc ------------------------------------------------------


def sun_disc(directions: Any, sun_direction: Any, diameter: float = 0.533) -> np.ndarray:
    """Mask of the directions that fall on the solar disc.

    Parameters
    ----------
    directions : array_like, shape (..., 3)
        Unit vectors, world frame. [-]
    sun_direction : array_like, shape (..., 3)
        Unit vector toward the sun's centre; broadcast against ``directions``. [-]
    diameter : float, optional
        Apparent diameter of the disc; gensky writes 0.5, gendaylit 0.533. [deg]

    Returns
    -------
    numpy.ndarray of bool
        True within half the diameter of the sun's centre (False for NaN). [-]
    """
    d = _unit_vectors(directions, "directions")
    sun = _unit_vectors(sun_direction, "sun_direction")
    sun_solid_angle(diameter)  # validates the diameter
    return np.sum(d * sun, axis=-1) >= np.cos(np.deg2rad(diameter) / 2.0)


# --- the holder and the dispatcher ------------------------------------------


@dataclass(frozen=True)
class _CieSky:
    """Parameters of a scaled CIE general sky: ``L = Lz x cie_general``."""

    sky_type: int
    zenith_radiance: np.ndarray


@dataclass(frozen=True, eq=False)
class DaylightSky:
    """A daylight sky for T frames: the input the forward model consumes.

    Attributes
    ----------
    model : str
        Registry name (see :func:`sky_models`).
    sun_direction : numpy.ndarray, shape (T, 3)
        Unit vector toward the sun (after Radiance's 87 deg limit where the
        model applies it). [-]
    solar_radiance : numpy.ndarray, shape (T,)
        Radiance of the solar disc; 0 where there is no sun or it is at or
        below the horizon. [W sr^-1 m^-2]
    sun_solid_angle : float
        Solid angle of the solar disc. [sr]
    ground_radiance : numpy.ndarray, shape (T,)
        Radiance of the ground seen below the horizon. [W sr^-1 m^-2]
    parameters : object
        The model's own parameters (:class:`GenskyParameters`,
        :class:`GendaylitParameters`, a CIE scale, or None for "point-sun").
    """

    model: str
    sun_direction: np.ndarray
    solar_radiance: np.ndarray
    sun_solid_angle: float
    ground_radiance: np.ndarray
    parameters: Any = field(default=None, repr=False)

    def radiance(self, directions: Any) -> np.ndarray:
        """Sky radiance seen in each direction for each frame.

        Parameters
        ----------
        directions : array_like, shape (..., 3)
            Unit vectors, world frame. [-]

        Returns
        -------
        numpy.ndarray, shape (..., T)
            Radiance of the sky (the sun's disc excluded). Below the horizon
            each model gives what it defines: gensky skies skybright.cal's
            ground blend, the Perez sky perezlum.cal's blend with A2, CIE skies
            ``ground_radiance``, "point-sun" 0. [W sr^-1 m^-2]
        """
        d = _unit_vectors(directions, "directions")[..., None, :]
        p = self.parameters
        if isinstance(p, GenskyParameters):
            return skybright(d, p)
        if isinstance(p, GendaylitParameters):
            return _perezlum(d, p)
        if isinstance(p, _CieSky):
            sky = p.zenith_radiance * cie_general(d, self.sun_direction, p.sky_type)
            return np.where(d[..., 2] < 0.0, self.ground_radiance, sky)
        shape = np.broadcast_shapes(d.shape[:-1], self.solar_radiance.shape)
        return np.broadcast_to(np.where(np.isnan(d[..., 2]), np.nan, 0.0), shape).copy()


def _sun_frames(sun_direction: Any) -> np.ndarray:
    sun = _unit_vectors(sun_direction, "sun_direction")
    if sun.ndim == 1:
        sun = sun[None, :]
    if sun.ndim != 2:
        raise ValueError(f"sun_direction must have shape (T, 3), got {sun.shape}")
    return sun


def _gensky_builder(kind: str) -> Callable[..., DaylightSky]:
    def build(
        sun_direction: Any,
        *,
        turbidity: float = 2.45,
        ground_reflectance: float = 0.2,
        sun: bool = True,
    ) -> DaylightSky:
        s = _sun_frames(sun_direction)
        p = gensky_parameters(s, kind, turbidity=turbidity, ground_reflectance=ground_reflectance)
        solar = p.solar_radiance if sun else np.zeros_like(p.solar_radiance)
        return DaylightSky(
            f"gensky-{kind}", p.sun_direction, solar, gensky_sun_solid_angle, p.ground_radiance, p
        )

    build.__doc__ = (
        f"gensky {kind} sky; options turbidity, ground_reflectance, sun (False as gensky -s/-i)."
    )
    return build


def clear_sky_irradiance(sun: np.ndarray, day: np.ndarray, linke_turbidity: float = 3.0):
    """Ineichen-Perez clear-sky DNI and DHI (pvlib), 0 with the sun down.

    Parameters
    ----------
    sun : ndarray (..., 3)
        Sun directions.
    day : int or ndarray
        Day of the year (Earth-sun distance) [-].
    linke_turbidity : float
        [-]

    Returns
    -------
    dni, dhi : ndarray
        Direct normal and diffuse horizontal irradiance [W m^-2].
    """
    import pvlib

    zenith = np.rad2deg(np.arccos(np.clip(sun[..., 2], -1.0, 1.0)))
    dni = np.zeros(zenith.shape)
    dhi = np.zeros(zenith.shape)
    up = zenith < 90.0
    if np.any(up):
        air_mass = pvlib.atmosphere.get_absolute_airmass(
            pvlib.atmosphere.get_relative_airmass(zenith[up], model="kastenyoung1989")
        )
        clear = pvlib.clearsky.ineichen(
            zenith[up],
            air_mass,
            linke_turbidity,
            dni_extra=SOLAR_CONSTANT * _eccentricity(np.broadcast_to(day, zenith.shape)[up]),
        )
        dni[up] = np.minimum(np.asarray(clear["dni"], dtype=float), SOLAR_CONSTANT)
        dhi[up] = np.asarray(clear["dhi"], dtype=float)
    return dni, dhi


def _irradiances(s, day, direct_normal_irradiance, diffuse_horizontal_irradiance, linke_turbidity):
    dni, dhi = direct_normal_irradiance, diffuse_horizontal_irradiance
    if dni is None or dhi is None:
        clear_dni, clear_dhi = clear_sky_irradiance(s, day, linke_turbidity)
        dni = clear_dni if dni is None else dni
        dhi = clear_dhi if dhi is None else dhi
    return dni, dhi


def _perez_builder(
    sun_direction: Any,
    *,
    direct_normal_irradiance: Any = None,
    diffuse_horizontal_irradiance: Any = None,
    day_of_year: Any = 0,
    ground_reflectance: float = 0.2,
    precipitable_water: float = 2.0,
    linke_turbidity: float = 3.0,
    sun: bool = True,
) -> DaylightSky:
    """Perez 1993 sky as gendaylit -W; irradiances default to Ineichen clear sky."""
    s = _sun_frames(sun_direction)
    day = _day_of_year(day_of_year)
    dni, dhi = _irradiances(
        s, day, direct_normal_irradiance, diffuse_horizontal_irradiance, linke_turbidity
    )
    p = gendaylit_parameters(
        s,
        dni,
        dhi,
        day_of_year=day,
        ground_reflectance=ground_reflectance,
        precipitable_water=precipitable_water,
        sun=sun,
    )
    return DaylightSky(
        "perez",
        p.sun_direction,
        p.solar_radiance,
        sun_solid_angle(2 * _GENDAYLIT_HALF_SUN_ANGLE),
        p.ground_radiance,
        p,
    )


#: Linke turbidity of the turbid clear-sky Perez model (``"perez-turbid"``): a
#: hazy or polluted day's, where a clean one's is 2-3 and ``"perez"``
#: defaults to 3 (Ineichen & Perez 2002; Remund et al. 2003's climatology
#: puts most sites' monthly values between 3 and 7).
TURBID_LINKE_TURBIDITY = 6.0


def _perez_turbid(
    sun_direction: Any,
    *,
    linke_turbidity: float = TURBID_LINKE_TURBIDITY,
    day_of_year: Any = 0,
    **options: Any,
) -> DaylightSky:
    """The Perez sky of pvlib's Ineichen clear-sky irradiance at Linke
    turbidity :data:`TURBID_LINKE_TURBIDITY`: a cloudless hazy day's shape
    (wider, brighter circumsolar region and horizon than a clean day's)."""
    day = _perez_builder(
        sun_direction, linke_turbidity=linke_turbidity, day_of_year=day_of_year, **options
    )
    return dataclasses.replace(day, model="perez-turbid")


def _cie_builder(sky_type: int) -> Callable[..., DaylightSky]:
    def build(
        sun_direction: Any,
        *,
        direct_normal_irradiance: Any = None,
        diffuse_horizontal_irradiance: Any = None,
        day_of_year: Any = 0,
        ground_reflectance: float = 0.2,
        precipitable_water: float = 2.0,
        linke_turbidity: float = 3.0,
        sun: bool | None = None,
    ) -> DaylightSky:
        s = _sun_frames(sun_direction)
        day = _day_of_year(day_of_year)
        show_sun = sky_type >= 6 if sun is None else bool(sun)
        dni, dhi = _irradiances(
            s, day, direct_normal_irradiance, diffuse_horizontal_irradiance, linke_turbidity
        )
        dni = _nonnegative(dni, "direct_normal_irradiance")
        dhi = _nonnegative(dhi, "diffuse_horizontal_irradiance")
        rho = _nonnegative(ground_reflectance, "ground_reflectance")
        zenith = np.rad2deg(np.arccos(np.clip(s[..., 2], -1.0, 1.0)))
        _, _, _, diffuse, direct = _perez_illuminances(
            zenith,
            np.broadcast_to(dni, zenith.shape),
            np.broadcast_to(dhi, zenith.shape),
            day,
            float(precipitable_water),
        )
        up = s[..., 2] > 0.0
        omega = sun_solid_angle()
        # Radiance units: illuminance / 179.
        sky_irradiance = np.where(up, diffuse / WHITE_EFFICACY, 0.0)
        beam = np.where(up & show_sun, direct / WHITE_EFFICACY, 0.0)
        directions, weights = _hemisphere_quadrature(_CIE_N_THETA, _CIE_N_PHI)
        shape = cie_general(directions[:, None, :], s, sky_type)  # (N, T)
        integral = np.sum(shape * (weights * directions[:, 2])[:, None], axis=0)
        zenith_radiance = sky_irradiance / integral
        ground = rho / np.pi * (sky_irradiance + beam * np.maximum(s[..., 2], 0.0))
        return DaylightSky(
            f"cie-{sky_type}", s, beam / omega, omega, ground, _CieSky(sky_type, zenith_radiance)
        )

    build.__doc__ = f"CIE standard general sky type {sky_type}: {CIE_SKY_TYPES[sky_type][2]}."
    return build


def _point_sun(sun_direction: Any, *, ground_reflectance: float = 0.2) -> DaylightSky:
    """No sky; a sun of unit normal irradiance where it is above the horizon.

    ``ground_reflectance`` is accepted like every model's, and unused: the
    paper's illumination has no sky, and its ground glow is zero (a ground
    plane lit by this sun is the forward model's business).
    """
    s = _sun_frames(sun_direction)
    omega = sun_solid_angle()
    solar = np.where(s[..., 2] > 0.0, 1.0 / omega, 0.0)
    solar = np.where(np.isnan(s[..., 2]), np.nan, solar)
    return DaylightSky("point-sun", s, solar, omega, np.zeros(s.shape[0]), None)


_CIE_N_THETA = 64
_CIE_N_PHI = 128

_REGISTRY: dict[str, Callable[..., DaylightSky]] = {
    **{f"gensky-{k}": _gensky_builder(k) for k in ("clear", "intermediate", "overcast", "uniform")},
    **{f"cie-{t}": _cie_builder(t) for t in range(1, 16)},
    "perez": _perez_builder,
    "perez-turbid": _perez_turbid,
    "point-sun": _point_sun,
}


def sky_models() -> tuple[str, ...]:
    """Names :func:`daylight` accepts."""
    return tuple(_REGISTRY)


def takes_day_of_year(model: str) -> bool:
    """Whether :func:`daylight`'s ``model`` takes the option ``day_of_year``
    (the Earth-sun distance of its clear-sky irradiance: the CIE general and
    Perez skies; gensky's skies and the point sun have no date). A builder
    takes it where its signature names it."""
    return "day_of_year" in inspect.signature(_REGISTRY[model]).parameters


def daylight(model: str, sun_direction: Any, **options: Any) -> DaylightSky:
    """Build a daylight sky by registry name.

    Models and options:

    - ``"gensky-clear"``, ``"gensky-intermediate"``, ``"gensky-overcast"``,
      ``"gensky-uniform"``: :func:`gensky_parameters`; options ``turbidity``
      (2.45), ``ground_reflectance`` (0.2), ``sun`` (True as ``+s``/``+i``;
      False as ``-s``/``-i``: no sun drawn, the ground still lit by it, as
      gensky). Sun disc 0.5 deg, as gensky writes.
    - ``"cie-1"`` ... ``"cie-15"``: :func:`cie_general` scaled so that the sky's
      horizontal irradiance (quadrature, 64 x 128 points) equals the diffuse
      horizontal illuminance / 179. Options ``direct_normal_irradiance``,
      ``diffuse_horizontal_irradiance`` [W m^-2, broadband, as gendaylit -W],
      converted to illuminance with gendaylit's Perez (1990) efficacy models;
      defaults: pvlib's Ineichen-Perez clear sky with ``linke_turbidity``
      (3.0), sea level, ``dni_extra`` 1367 x eccentricity of ``day_of_year``
      (0). ``sun`` defaults to False for the overcast/uniform types 1-5 and
      True for 6-15. Ground: ``ground_reflectance / pi`` x the horizontal
      (sky + sun) irradiance in Radiance units. Sun disc 0.533 deg.
    - ``"perez"``: :func:`gendaylit_parameters` (gendaylit -W, -O0); same
      irradiance options and defaults as the CIE skies, plus
      ``precipitable_water`` (2.0 cm) and ``sun`` (True).
    - ``"perez-turbid"``: ``"perez"`` with ``linke_turbidity``
      :data:`TURBID_LINKE_TURBIDITY` (6) by default: a hazy cloudless day.
    - ``"point-sun"``: no sky (radiance 0 everywhere, ground 0), solar
      radiance ``1 / sun_solid_angle`` so that the sun gives unit normal
      irradiance.

    A sun at or below the horizon gives solar radiance 0 (a documented zero).

    Parameters
    ----------
    model : str
        A name from :func:`sky_models`.
    sun_direction : array_like, shape (T, 3) or (3,)
        Unit vector toward the sun for each frame. [-]
    **options
        Model options listed above.

    Returns
    -------
    DaylightSky

    Raises
    ------
    ValueError
        For an unknown model name (the message lists the valid ones).
    """
    try:
        builder = _REGISTRY[model]
    except (KeyError, TypeError):
        raise ValueError(
            f"unknown sky model {model!r}; valid models: {', '.join(_REGISTRY)}"
        ) from None
    return builder(sun_direction, **options)


def _hemisphere_quadrature(n_theta: int, n_phi: int) -> tuple[np.ndarray, np.ndarray]:
    """Directions and solid-angle weights over the upper hemisphere.

    Gauss-Legendre in ``mu = cos(theta)`` on (0, 1) times the periodic
    midpoint rule in azimuth; weights sum to 2 pi.
    """
    if n_theta < 1 or n_phi < 1:
        raise ValueError(f"n_theta and n_phi must be >= 1, got {n_theta}, {n_phi}")
    x, w = np.polynomial.legendre.leggauss(int(n_theta))
    mu = (x + 1.0) / 2.0
    phi = (np.arange(n_phi) + 0.5) * (2.0 * np.pi / n_phi)
    mu, phi = np.meshgrid(mu, phi, indexing="ij")
    weights = np.broadcast_to((w / 2.0)[:, None] * (2.0 * np.pi / n_phi), mu.shape)
    sin_t = np.sqrt(1.0 - mu * mu)
    directions = np.stack([sin_t * np.cos(phi), sin_t * np.sin(phi), mu], axis=-1)
    return directions.reshape(-1, 3), weights.reshape(-1).copy()


def horizontal_irradiance(
    sky: DaylightSky, n_theta: int = 64, n_phi: int = 128, include_sun: bool = True
) -> np.ndarray:
    """Irradiance on a horizontal plane from the sky above the horizon and the sun.

    ``E = sum_k w_k L(d_k) cos(theta_k) + Ls omega_s max(sun_z, 0)``, with
    Gauss-Legendre nodes in ``cos(theta)`` and the midpoint rule in azimuth.
    The sun's disc is not in :meth:`DaylightSky.radiance`, so it is added
    once, as Radiance does for a source.

    Parameters
    ----------
    sky : DaylightSky
        The sky to integrate.
    n_theta, n_phi : int, optional
        Quadrature nodes in cos(theta) and in azimuth. [-]
    include_sun : bool, optional
        Add the solar disc's contribution. [-]

    Returns
    -------
    numpy.ndarray, shape (T,)
        Horizontal irradiance in Radiance's units. [W m^-2]
    """
    directions, weights = _hemisphere_quadrature(n_theta, n_phi)
    radiance = sky.radiance(directions)  # (N, T)
    total = np.sum(radiance * (weights * directions[:, 2])[:, None], axis=0)
    if include_sun:
        total = total + sky.solar_radiance * sky.sun_solid_angle * np.maximum(
            sky.sun_direction[..., 2], 0.0
        )
    return total

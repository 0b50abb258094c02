"""Measured irradiance: from a bundle's ``frames[].irradiance`` to the sky of each frame.

Where a bundle carries broadband irradiance measured at the site (the spec's
optional ``frames[].irradiance``: any of GHI, DNI, DHI [W m^-2]), the sky
of each frame follows from it with gendaylit's Perez conventions
(:func:`bayesgloss.sky.daylight` ``"perez"``, as ``gendaylit -W DNI DHI``)
instead of a clear-sky model. Any two of GHI, DNI and DHI give the third by
the closure GHI = DNI cos(z) + DHI; GHI alone is split with the Erbs et
al. (1982) decomposition (``pvlib.irradiance.erbs``).
"""

from __future__ import annotations

import warnings

import numpy as np

from . import sky

__all__ = ["complete_irradiance", "measured_sky", "read_irradiance_csv", "IrradianceFileError"]


def complete_irradiance(ghi, dni, dhi, solar_zenith, day_of_year):
    """DNI and DHI from whichever of GHI, DNI and DHI are known.

    Parameters
    ----------
    ghi, dni, dhi : array_like (T,)
        Global horizontal, direct normal and diffuse horizontal irradiance;
        NaN where not measured [W m^-2].
    solar_zenith : array_like (T,)
        [deg]
    day_of_year : array_like (T,)
        [-]

    Returns
    -------
    dni, dhi : ndarray (T,)
        [W m^-2]; 0 with the sun at or below the horizon; NaN where neither
        two values nor GHI were given (DNI alone or DHI alone). DNI is
        capped at the solar constant (closure at a low sun divides the
        sensors' GHI - DHI by a small cos z).
    """
    import pvlib

    ghi, dni, dhi = (np.asarray(x, dtype=float).copy() for x in (ghi, dni, dhi))
    zenith = np.asarray(solar_zenith, dtype=float)
    cos_z = np.cos(np.deg2rad(zenith))
    up = cos_z > 0
    day = np.broadcast_to(np.asarray(day_of_year, dtype=float), zenith.shape)
    # the closure GHI = DNI cos z + DHI, cos z floored at pvlib's 0.065 for DNI
    need_dni = np.isnan(dni) & ~np.isnan(ghi) & ~np.isnan(dhi)
    dni[need_dni] = np.maximum((ghi - dhi)[need_dni] / np.maximum(cos_z[need_dni], 0.065), 0.0)
    need_dhi = np.isnan(dhi) & ~np.isnan(ghi) & ~np.isnan(dni)
    beam_h = dni[need_dhi] * np.maximum(cos_z[need_dhi], 0.0)
    dhi[need_dhi] = np.maximum(ghi[need_dhi] - beam_h, 0.0)
    only_ghi = np.isnan(dni) & np.isnan(dhi) & ~np.isnan(ghi) & up
    if np.any(only_ghi):  # Erbs et al. (1982), through pvlib
        split = pvlib.irradiance.erbs(ghi[only_ghi], zenith[only_ghi], day[only_ghi])
        dni[only_ghi] = np.asarray(split["dni"], dtype=float)
        dhi[only_ghi] = np.asarray(split["dhi"], dtype=float)
    # closure at a low sun amplifies the GHI - DHI of real sensors: no DNI
    # above the solar constant (gendaylit rejects it)
    dni = np.where(up, np.minimum(dni, sky.SOLAR_CONSTANT), 0.0)
    dhi = np.where(up, dhi, 0.0)
    return dni, dhi


def measured_sky(bundle, ground_reflectance: float = 0.2):
    """The Perez sky of every frame from the bundle's measured irradiance, or None.

    None where the bundle measures no frame. Where it measures some frames
    with the sun up but not all, or a frame only by DNI or DHI alone, a
    :class:`bayesgloss.bundle.BundleWarning` says so and None is returned
    (the estimate then uses a sky model, as for a bundle without
    measurements).
    """
    from .bundle import BundleWarning

    irr = getattr(bundle, "irradiance", None)
    if irr is None or np.all(np.isnan(irr)):
        return None
    day = np.asarray(bundle.times.day_of_year, dtype=float)
    dni, dhi = complete_irradiance(irr[:, 0], irr[:, 1], irr[:, 2], bundle.solar_zenith, day)
    up = bundle.sun_up
    missing = up & (np.isnan(dni) | np.isnan(dhi))
    if np.any(missing):
        warnings.warn(
            f"bundle '{bundle.path}': frames[].irradiance gives {int(np.sum(up & ~missing))} of "
            f"{int(np.sum(up))} frames with the sun up enough to know DNI and DHI (e.g. "
            f"frames[{int(np.flatnonzero(missing)[0])}]); the measurements are not used",
            BundleWarning,
            stacklevel=2,
        )
        return None
    return sky.daylight(
        "perez",
        bundle.sun_direction,
        direct_normal_irradiance=np.nan_to_num(dni),
        diffuse_horizontal_irradiance=np.nan_to_num(dhi),
        day_of_year=day.astype(int),
        ground_reflectance=ground_reflectance,
    )


class IrradianceFileError(ValueError):
    """A bad irradiance file: names the file, the row or column, and the problem."""


def read_irradiance_csv(path, times) -> np.ndarray:
    """Measured irradiance of the frames from a time-indexed CSV file.

    The file has a ``time`` column (ISO 8601 with a UTC offset) and any of
    ``ghi``, ``dni``, ``dhi`` [W m^-2]; every frame's time must be in it
    (compared as instants). Empty cells are not measured.

    Parameters
    ----------
    path : path
    times : pandas.DatetimeIndex
        The frames' times, tz-aware.

    Returns
    -------
    ndarray (T, 3)
        GHI, DNI, DHI of each frame; NaN where not measured [W m^-2].

    Raises
    ------
    IrradianceFileError
        Unreadable file, no ``time`` column or none of the irradiance
        columns, a time without a UTC offset, a negative or non-numeric
        value, or a frame time the file does not hold.
    """
    import pandas as pd

    def fail(where, problem):
        return IrradianceFileError(f"irradiance file '{path}': {where}: {problem}")

    try:
        table = pd.read_csv(path, dtype=str, skipinitialspace=True)
    except Exception as err:
        raise fail("file", f"cannot read it as CSV: {err}") from None
    table.columns = [str(c).strip().lower() for c in table.columns]
    if "time" not in table.columns:
        raise fail("columns", f"no 'time' column (got {', '.join(table.columns)})")
    keys = [k for k in ("ghi", "dni", "dhi") if k in table.columns]
    if not keys:
        raise fail("columns", "none of ghi, dni, dhi")
    stamps = []
    for i, text in enumerate(table["time"]):
        try:
            t = pd.Timestamp(str(text).strip())
        except Exception:
            raise fail(f"row {i + 2}, time", f"not an ISO 8601 time: {text!r}") from None
        if t.tzinfo is None:
            raise fail(f"row {i + 2}, time", f"{text!r} has no UTC offset")
        stamps.append(t.tz_convert("UTC"))
    index = pd.DatetimeIndex(stamps)
    values = np.full((len(table), 3), np.nan)
    for k, key in enumerate(("ghi", "dni", "dhi")):
        if key not in keys:
            continue
        cells = table[key].fillna("").str.strip()
        num = pd.to_numeric(cells.where(cells != "", None), errors="coerce").to_numpy(float)
        bad = (cells != "") & ~np.isfinite(num) | (num < 0)
        if np.any(bad):
            i = int(np.flatnonzero(bad)[0])
            raise fail(f"row {i + 2}, {key}", f"must be a number >= 0 W m^-2, got {cells[i]!r}")
        values[:, k] = num
    out = np.full((len(times), 3), np.nan)
    position = {t: i for i, t in enumerate(index)}
    for j, t in enumerate(times.tz_convert("UTC")):
        if t not in position:
            raise fail("time", f"holds no row for frame {j} at {t.isoformat()}")
        out[j] = values[position[t]]
    return out

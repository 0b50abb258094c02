"""What a photo's EXIF says of when, how exposed and where it was taken.

For :mod:`bayesgloss.capture` (``bayesgloss bundle make``): a frame's time
is EXIF ``DateTimeOriginal`` (with ``SubSecTimeOriginal``) at
``OffsetTimeOriginal``, or at a stated UTC offset for photos whose camera
wrote none (:func:`photo_time`); its relative exposure is ``ExposureTime``
x ISO / ``FNumber``^2 (:func:`photo_exposure`); the site is the GPS
position (:func:`photo_site`). Tags as CIPA DC-008 (Exif 2.32) numbers
them; read with Pillow, from JPEG, PNG (``eXIf``) and TIFF. Camera RAW files
(:data:`bayesgloss.images.RAW_SUFFIXES`) are read with ``tifffile`` where
they are TIFF-based (DNG, NEF, CR2, ARW, PEF, ...): the Exif IFD, and the
same tags in IFD0 where TIFF/EP puts them; other RAW formats (CR3, RAF, ...)
give LibRaw's reading (``rawpy``'s ``other``: the time without its UTC
offset, shutter, aperture, ISO).
"""

from __future__ import annotations

import datetime as _dt
import math
import os
import re
from pathlib import Path

import pandas as pd

from .camera_model import CaptureError

__all__ = ["photo_time", "photo_exposure", "photo_site", "photo_orientation"]

# EXIF tags (CIPA DC-008-2019, Exif 2.32)
_EXIF_IFD, _GPS_IFD = 0x8769, 0x8825
_DATETIME_ORIGINAL, _OFFSET_TIME_ORIGINAL, _SUBSEC_ORIGINAL = 0x9003, 0x9011, 0x9291
_EXPOSURE_TIME, _F_NUMBER, _ISO = 0x829A, 0x829D, 0x8827
_ORIENTATION = 0x0112
_GPS_LAT_REF, _GPS_LAT, _GPS_LON_REF, _GPS_LON, _GPS_ALT_REF, _GPS_ALT = 1, 2, 3, 4, 5, 6
_OFFSET = re.compile(r"^([+-])(\d{2}):?(\d{2})$")


#: Tags whose values are RATIONALs (read as floats from RAW files).
_RATIONAL = {_EXPOSURE_TIME, _F_NUMBER, _GPS_ALT}
#: Exif tags TIFF/EP (ISO 12234-2) places in IFD0 of a RAW file.
_TIFF_EP = (_DATETIME_ORIGINAL, _OFFSET_TIME_ORIGINAL, _SUBSEC_ORIGINAL, _EXPOSURE_TIME,
            _F_NUMBER, _ISO)  # fmt: skip


def _number(value):
    """A tifffile value as Pillow gives it: a RATIONAL pair (num, den) as a float."""
    if isinstance(value, tuple) and len(value) == 2 and all(isinstance(v, int) for v in value):
        return value[0] / value[1] if value[1] else float("nan")
    return value


def _raw_exif(path: Path) -> tuple[dict, dict, dict]:
    """:func:`_exif` of a camera RAW file: tifffile's tags, else LibRaw's reading."""
    import tifffile
    from tifffile import TIFF

    from .images import _quiet_tifffile

    codes = {name: code for code, name in TIFF.TAGS.items()}
    try:
        with _quiet_tifffile(), tifffile.TiffFile(path) as tif:
            tags = {t.code: t.value for t in tif.pages[0].tags.values()}
    except Exception:  # not TIFF-based (CR3, RAF, ...), or not a RAW file at all
        return _libraw_exif(path)

    def by_code(named) -> dict:
        out = {}
        for name, value in (named or {}).items():
            code = codes.get(name)
            if code is None:
                continue
            if code == _GPS_LAT or code == _GPS_LON:  # 3 RATIONALs, flattened
                value = tuple(value[k] / value[k + 1] for k in (0, 2, 4))
            out[code] = _number(value) if code in _RATIONAL else value
        return out

    main = {code: v for code, v in tags.items() if not isinstance(v, dict)}
    exif = {code: _number(main[code]) for code in _TIFF_EP if code in main}
    exif.update(by_code(tags.get(_EXIF_IFD)))
    gps = tags.get(_GPS_IFD)
    gps = {**gps} if isinstance(gps, dict) else {}
    gps_codes = {"GPSLatitudeRef": _GPS_LAT_REF, "GPSLatitude": _GPS_LAT,
                 "GPSLongitudeRef": _GPS_LON_REF, "GPSLongitude": _GPS_LON,
                 "GPSAltitudeRef": _GPS_ALT_REF, "GPSAltitude": _GPS_ALT}  # fmt: skip
    gps = {gps_codes[k]: v for k, v in gps.items() if k in gps_codes}
    for code in (_GPS_LAT, _GPS_LON):
        if code in gps and len(gps[code]) == 6:
            v = gps[code]
            gps[code] = tuple(v[k] / v[k + 1] for k in (0, 2, 4))
    if _GPS_ALT in gps:
        gps[_GPS_ALT] = _number(gps[_GPS_ALT])
    if not exif.get(_DATETIME_ORIGINAL):  # a maker's format tifffile reads without Exif
        exif = {**_libraw_exif(path)[1], **exif}
    return main, exif, gps


def _libraw_exif(path: Path) -> tuple[dict, dict, dict]:
    """What LibRaw (``rawpy``) reads of a RAW file's time and exposure: no offset, no GPS."""
    from .images import read_raw

    try:
        import rawpy
    except ImportError:
        read_raw(path)  # raises the ImportError that names the extra
        raise
    try:
        with rawpy.imread(str(path)) as raw:
            other = raw.other
    except (rawpy.LibRawError, rawpy.NotSupportedError):
        try:
            read_raw(path)  # its one-line reason
        except ValueError as err:
            raise CaptureError("photo", path, "file", str(err)) from None
        raise
    exif = {}
    stamp = other.timestamp
    if isinstance(stamp, int | float) and stamp > 0:  # older rawpy: seconds
        stamp = _dt.datetime.fromtimestamp(stamp)
    if isinstance(stamp, _dt.datetime):  # the camera's clock, as LibRaw read it
        exif[_DATETIME_ORIGINAL] = stamp.strftime("%Y:%m:%d %H:%M:%S")
    for code, value in ((_EXPOSURE_TIME, other.shutter_speed), (_F_NUMBER, other.aperture),
                        (_ISO, other.iso_speed)):  # fmt: skip
        if value and value > 0:
            exif[code] = float(value)
    return {}, exif, {}


def _exif(path: Path) -> tuple[dict, dict, dict]:
    """A photo's EXIF: the main IFD, the Exif IFD and the GPS IFD (tag -> value)."""
    from PIL import Image

    from .images import RAW_SUFFIXES

    if path.suffix.lower() in RAW_SUFFIXES:
        return _raw_exif(path)
    try:
        with Image.open(path) as img:
            exif = img.getexif()
            return dict(exif), dict(exif.get_ifd(_EXIF_IFD)), dict(exif.get_ifd(_GPS_IFD))
    except Exception as err:  # Pillow raises many kinds on a damaged file
        raise CaptureError("photo", path, "file", f"cannot read the photo: {err}") from None


def _utc_offset(text: str, path, field: str) -> _dt.timezone:
    match = _OFFSET.match(str(text).strip())
    if not match:
        raise CaptureError("photo", path, field, f"not a UTC offset (+HH:MM): {text!r}")
    sign, hours, minutes = match.groups()
    delta = _dt.timedelta(hours=int(hours), minutes=int(minutes))
    if delta > _dt.timedelta(hours=14) or int(minutes) >= 60:
        raise CaptureError("photo", path, field, f"UTC offset {text!r} out of range")
    return _dt.timezone(-delta if sign == "-" else delta)


def photo_time(path: str | os.PathLike, utc_offset: str | None = None) -> pd.Timestamp:
    """When a photo was taken: EXIF ``DateTimeOriginal`` at its UTC offset.

    Parameters
    ----------
    path : str or path-like
        JPEG, PNG or TIFF with EXIF. -
    utc_offset : str, optional
        ``+HH:MM``: the offset of the camera's clock, used where EXIF has no
        ``OffsetTimeOriginal``. -

    Returns
    -------
    pandas.Timestamp
        Tz-aware, at the photo's offset (``SubSecTimeOriginal`` included).

    Raises
    ------
    CaptureError
        No ``DateTimeOriginal``, an unreadable one, or no offset in EXIF and
        none given.
    """
    path = Path(path)
    _, exif, _ = _exif(path)
    stamp = exif.get(_DATETIME_ORIGINAL)
    if not stamp:
        raise CaptureError(
            "photo", path, "DateTimeOriginal", "EXIF holds no time the photo was taken"
        )
    try:
        when = _dt.datetime.strptime(str(stamp).strip().rstrip("\x00"), "%Y:%m:%d %H:%M:%S")
    except ValueError:
        raise CaptureError(
            "photo", path, "DateTimeOriginal", f"not a time 'YYYY:MM:DD HH:MM:SS': {stamp!r}"
        ) from None
    subsec = str(exif.get(_SUBSEC_ORIGINAL, "")).strip().rstrip("\x00")
    if subsec.isdigit():
        when += _dt.timedelta(seconds=float(f"0.{subsec}"))
    offset = exif.get(_OFFSET_TIME_ORIGINAL)
    if offset:
        zone = _utc_offset(str(offset).rstrip("\x00"), path, "OffsetTimeOriginal")
    elif utc_offset is not None:
        zone = _utc_offset(utc_offset, "--utc-offset", "--utc-offset")
    else:
        raise CaptureError(
            "photo",
            path,
            "OffsetTimeOriginal",
            f"EXIF gives the time {stamp} but no UTC offset; give the camera clock's "
            "offset with --utc-offset +HH:MM",
        )
    return pd.Timestamp(when.replace(tzinfo=zone))


def photo_exposure(path: str | os.PathLike) -> float | None:
    """A photo's relative exposure from EXIF: ExposureTime x ISO / FNumber^2.

    The factor between scene radiance and the sensor's linear signal, up to
    one scale for a camera and lens (the spec's ``frames[].exposure``).

    Returns
    -------
    float or None
        [s] (ISO and f-number are unitless); None where EXIF lacks any of
        the three or holds a non-positive one.
    """
    _, exif, _ = _exif(Path(path))
    values = []
    for tag in (_EXPOSURE_TIME, _F_NUMBER, _ISO):
        value = exif.get(tag)
        if isinstance(value, tuple | list):  # ISO may be a list of speeds
            value = value[0] if value else None
        try:
            value = float(value)
        except (TypeError, ValueError, ZeroDivisionError):
            return None
        if not (math.isfinite(value) and value > 0):
            return None
        values.append(value)
    time, f_number, iso = values
    return time * iso / f_number**2  # exposure ~ t S / N^2 (ISO 12232 exposure index)


def _degrees(value) -> float:
    d, m, s = (float(v) for v in value)
    return d + m / 60 + s / 3600


def photo_site(path: str | os.PathLike) -> tuple[float, float, float | None] | None:
    """Latitude and longitude (deg, north and east positive) and altitude (m)
    from EXIF GPS; None where the photo has no GPS position."""
    _, _, gps = _exif(Path(path))
    if _GPS_LAT not in gps or _GPS_LON not in gps:
        return None
    try:
        lat = _degrees(gps[_GPS_LAT]) * (-1 if str(gps.get(_GPS_LAT_REF, "N"))[:1] == "S" else 1)
        lon = _degrees(gps[_GPS_LON]) * (-1 if str(gps.get(_GPS_LON_REF, "E"))[:1] == "W" else 1)
    except (TypeError, ValueError, ZeroDivisionError):
        raise CaptureError("photo", path, "GPSLatitude", "unreadable GPS position") from None
    alt = None
    if _GPS_ALT in gps:
        try:
            below = gps.get(_GPS_ALT_REF, 0) in (1, b"\x01")
            alt = float(gps[_GPS_ALT]) * (-1 if below else 1)
        except (TypeError, ValueError, ZeroDivisionError):
            alt = None
    return lat, lon, alt


def photo_orientation(path: str | os.PathLike) -> int:
    """EXIF ``Orientation`` (1-8; 5-8 turn the stored image by 90 deg), 1 where absent."""
    main, _, _ = _exif(Path(path))
    value = main.get(_ORIENTATION, 1)
    return int(value) if isinstance(value, int) and 1 <= value <= 8 else 1

"""Image codecs and pixel encodings for sequence bundles.

Radiance RGBE pictures (own reader and writer: flat and both run-length
styles, EXPOSURE and COLORCORR, every orientation of the resolution string),
8- and 16-bit PNG through pypng (keeping all 16 bits; Pillow drops the low
byte of 16-bit RGB), TIFF through tifffile, OpenEXR through the optional
``openexr`` package, camera RAW files decoded linearly through the optional
``rawpy`` (LibRaw; :func:`read_raw`, for ``bundle make``), and the pixel
encodings of the bundle spec (``linear-radiance``, ``linear``, ``srgb``,
``gamma:G``, ``unknown``).
:mod:`bayesgloss.bundle` re-exports the codecs of a bundle's own images (RAW
files are photos for ``bundle make``, never a bundle's frames).
"""

from __future__ import annotations

import contextlib
import logging
import math
import os
import struct
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

__all__ = [
    "PIXEL_ENCODINGS",
    "RAW_SUFFIXES",
    "ImageInfo",
    "decode_pixels",
    "decode_raw_linear",
    "float_to_rgbe",
    "image_info",
    "image_kind",
    "linear_to_srgb",
    "parse_pixel_encoding",
    "read_exr",
    "read_hdr",
    "read_image",
    "read_labels",
    "read_png",
    "read_raw",
    "read_tiff",
    "rgbe_to_float",
    "srgb_to_linear",
    "write_exr",
    "write_hdr",
    "write_png",
    "write_tiff",
]

#: Values of ``camera.pixel_encoding`` (``gamma:G`` with a number G > 0).
PIXEL_ENCODINGS = ("linear-radiance", "linear", "srgb", "gamma:G", "unknown")

#: File name endings of camera RAW files (:func:`read_raw`): Adobe DNG and the
#: makers' formats LibRaw reads.
RAW_SUFFIXES = (
    ".dng", ".nef", ".nrw", ".cr2", ".cr3", ".crw", ".arw", ".srf", ".sr2", ".raf", ".orf",
    ".rw2", ".pef", ".srw", ".3fr", ".iiq", ".erf", ".kdc", ".mef", ".mos", ".mrw", ".x3f",
    ".rwl",
)  # fmt: skip

# ---------------------------------------------------------------------------
# Radiance RGBE pictures
# ---------------------------------------------------------------------------

_HDR_FORMAT = "32-bit_rle_rgbe"
_RLE_MIN_LENGTH, _RLE_MAX_LENGTH = 8, 0x7FFF  # new-style run-length scanline lengths
_RLE_MIN_RUN = 4  # shortest run the writer encodes as a run (Radiance's MINRUN)


class _HdrHeader(NamedTuple):
    shape: tuple[int, int]  # stored (scanlines, scanline length)
    axes: tuple[str, str]  # e.g. ("-Y", "+X")
    exposure: float
    colorcorr: np.ndarray
    data_start: int


def _header_numbers(line: str, value: str, count: int) -> list[float]:
    try:
        numbers = [float(v) for v in value.split()[:count]]
    except ValueError:
        numbers = []
    if len(numbers) != count or not all(math.isfinite(v) and v > 0 for v in numbers):
        raise ValueError(f"bad header line {line!r}")
    return numbers


def _parse_hdr_header(data: bytes) -> _HdrHeader:
    """Header, resolution string and pixel-data offset of a Radiance picture."""
    if not data.startswith(b"#?"):
        raise ValueError("not a Radiance picture (no '#?' magic line)")
    end = data.find(b"\n\n")
    if end < 0:
        raise ValueError("Radiance header has no terminating blank line")
    exposure, colorcorr = 1.0, np.ones(3)
    for raw in data[:end].split(b"\n")[1:]:
        line = raw.decode("latin-1").strip()
        key, _, value = line.partition("=")
        key = key.strip()
        if key == "FORMAT" and value.strip() != _HDR_FORMAT:
            raise ValueError(f"unsupported FORMAT={value.strip()} (need {_HDR_FORMAT})")
        # EXPOSURE and COLORCORR are cumulative multipliers the pixels carry
        if key == "EXPOSURE":
            exposure *= _header_numbers(line, value, 1)[0]
        elif key == "COLORCORR":
            colorcorr = colorcorr * np.array(_header_numbers(line, value, 3))
    start = end + 2
    stop = data.find(b"\n", start)
    if stop < 0:
        raise ValueError("missing resolution string")
    tokens = data[start:stop].decode("latin-1").split()
    axes = tokens[0::2]
    if (
        len(tokens) != 4
        or sorted(a[1:] for a in axes) != ["X", "Y"]
        or any(a[:1] not in ("+", "-") for a in axes)
        or not all(t.isdigit() and int(t) > 0 for t in tokens[1::2])
    ):
        raise ValueError(f"bad resolution string {' '.join(tokens)!r}")
    shape = (int(tokens[1]), int(tokens[3]))
    return _HdrHeader(shape, (tokens[0], tokens[2]), exposure, colorcorr, stop + 1)


def _decode_old_scanline(data: bytes, pos: int, out: np.ndarray, y: int) -> int:
    """Flat pixels with old-style (1, 1, 1, n) repeat codes; returns the new offset."""
    length = len(out)
    chunk = np.frombuffer(data, np.uint8, min(4 * length, len(data) - pos) // 4 * 4, pos)
    chunk = chunk.reshape(-1, 4)
    if len(chunk) == length and not np.any(np.all(chunk[:, :3] == 1, axis=1)):
        out[:] = chunk  # flat scanline: no repeat codes
        return pos + 4 * length
    x, shift = 0, 0
    while x < length:
        if pos + 4 > len(data):
            raise ValueError(f"pixel data end early, in scanline {y}")
        pixel = data[pos : pos + 4]
        pos += 4
        if pixel[0] == 1 and pixel[1] == 1 and pixel[2] == 1:
            count = pixel[3] << shift
            if x == 0 or x + count > length:
                raise ValueError(f"bad old-style run in scanline {y}")
            out[x : x + count] = out[x - 1]
            x += count
            shift += 8
        else:
            out[x] = np.frombuffer(pixel, np.uint8)
            x += 1
            shift = 0
    return pos


def _decode_rle_scanline(data: bytes, pos: int, planes: bytearray, base: int, length: int, y: int):
    """One new-style run-length scanline into four component planes."""
    size = len(data)
    for component in range(4):
        x = base + component * length
        stop = x + length
        while x < stop:
            if pos >= size:
                raise ValueError(f"pixel data end early, in scanline {y}")
            count = data[pos]
            pos += 1
            if count > 128:  # a run of (count - 128) copies of the next byte
                count -= 128
                if pos >= size:
                    raise ValueError(f"pixel data end early, in scanline {y}")
                if x + count > stop:
                    raise ValueError(f"run overruns scanline {y}")
                planes[x : x + count] = data[pos : pos + 1] * count
                pos += 1
            else:  # count literal bytes
                if count == 0 or x + count > stop:
                    raise ValueError(f"bad literal count in scanline {y}")
                if pos + count > size:
                    raise ValueError(f"pixel data end early, in scanline {y}")
                planes[x : x + count] = data[pos : pos + count]
                pos += count
            x += count
    return pos


def _decode_rgbe(data: bytes, pos: int, n_lines: int, length: int) -> np.ndarray:
    """RGBE bytes of ``n_lines`` scanlines, shape (n_lines, length, 4)."""
    out = np.empty((n_lines, length, 4), np.uint8)
    new_style = _RLE_MIN_LENGTH <= length <= _RLE_MAX_LENGTH
    planes = bytearray(4 * length)
    for y in range(n_lines):
        if (
            new_style
            and pos + 4 <= len(data)
            and data[pos] == 2
            and data[pos + 1] == 2
            and not data[pos + 2] & 0x80
        ):
            if (data[pos + 2] << 8 | data[pos + 3]) != length:
                raise ValueError(f"scanline {y} has the wrong length")
            pos = _decode_rle_scanline(data, pos + 4, planes, 0, length, y)
            out[y] = np.frombuffer(planes, np.uint8).reshape(4, length).T
        else:
            pos = _decode_old_scanline(data, pos, out[y], y)
    return out


def rgbe_to_float(rgbe: np.ndarray) -> np.ndarray:
    """Decode RGBE bytes (..., 4) to float32 RGB (..., 3).

    Radiance's ``colr_color``: ``(mantissa + 0.5) 2^(exponent - 136)``, and 0
    for exponent byte 0.
    """
    rgbe = np.asarray(rgbe, dtype=np.uint8)
    exponent = rgbe[..., 3:].astype(np.int32)
    scale = np.where(exponent > 0, np.ldexp(np.float32(1.0), exponent - 136), np.float32(0.0))
    return (rgbe[..., :3].astype(np.float32) + np.float32(0.5)) * scale.astype(np.float32)


def float_to_rgbe(rgb: np.ndarray) -> np.ndarray:
    """Encode RGB (..., 3) >= 0 as RGBE bytes (..., 4), as Radiance's ``setcolr``."""
    rgb = np.asarray(rgb, dtype=np.float64)
    peak = np.max(rgb, axis=-1)
    mantissa, exponent = np.frexp(peak)  # peak = mantissa 2^exponent, mantissa in [0.5, 1)
    positive = peak > 1e-32
    scale = np.divide(mantissa * 256.0, peak, out=np.zeros_like(peak), where=positive)
    out = np.zeros(rgb.shape[:-1] + (4,), np.uint8)
    out[..., :3] = np.clip(np.floor(rgb * scale[..., None]), 0, 255)
    out[..., 3] = np.where(positive, exponent + 128, 0)
    return out


def read_hdr(path: str | os.PathLike) -> np.ndarray:
    """Read a Radiance RGBE picture.

    Reads flat, old-style and new-style run-length scanlines in any of the
    eight orientations of the resolution string, and divides by the
    cumulative ``EXPOSURE`` and ``COLORCORR`` of the header, so the values
    are the picture's original radiance.

    Parameters
    ----------
    path : str or path-like
        The picture file. -

    Returns
    -------
    ndarray of float32, shape (H, W, 3)
        RGB, top row first, in the picture's unit (W sr^-1 m^-2 for
        Radiance renderings). RGBE keeps an 8-bit mantissa shared by the three
        channels: each channel is within ``max(R, G, B) / 256`` of the value
        encoded.

    Raises
    ------
    ValueError
        For a file that is not a valid ``32-bit_rle_rgbe`` picture.
    """
    data = Path(path).read_bytes()
    header = _parse_hdr_header(data)
    n_lines, length = header.shape
    rgb = rgbe_to_float(_decode_rgbe(data, header.data_start, n_lines, length))
    if header.axes[0][1] == "X":  # scanlines are columns
        rgb = rgb.transpose(1, 0, 2)
        axis_y, axis_x = header.axes[1], header.axes[0]
    else:
        axis_y, axis_x = header.axes
    if axis_y[0] == "+":  # stored bottom to top
        rgb = rgb[::-1]
    if axis_x[0] == "-":  # stored right to left
        rgb = rgb[:, ::-1]
    correction = (header.exposure * header.colorcorr).astype(np.float32)
    if np.any(correction != 1):
        rgb = rgb / correction
    return np.ascontiguousarray(rgb, dtype=np.float32)


def _encode_rle_plane(plane: np.ndarray, out: bytearray) -> None:
    """Append one component of a scanline in new-style run-length code."""
    length = len(plane)
    starts = np.flatnonzero(np.diff(plane)) + 1
    starts = np.concatenate([[0], starts])
    counts = np.diff(np.concatenate([starts, [length]]))
    long_runs = counts >= _RLE_MIN_RUN
    literal_from = 0
    raw = plane.tobytes()
    for start, count in zip(starts[long_runs].tolist(), counts[long_runs].tolist(), strict=True):
        for chunk in range(literal_from, start, 128):
            n = min(128, start - chunk)
            out.append(n)
            out += raw[chunk : chunk + n]
        literal_from = start + count
        value = raw[start]
        while count > 0:
            n = min(127, count)
            out.append(128 + n)
            out.append(value)
            count -= n
    for chunk in range(literal_from, length, 128):
        n = min(128, length - chunk)
        out.append(n)
        out += raw[chunk : chunk + n]


def write_hdr(
    path: str | os.PathLike,
    rgb: np.ndarray,
    *,
    rle: bool = True,
    header: Sequence[str] = (),
) -> None:
    """Write a Radiance RGBE picture (``-Y H +X W``, top row first).

    Parameters
    ----------
    path : str or path-like
        Output file. -
    rgb : array_like, shape (H, W, 3) or (H, W)
        Non-negative finite values, e.g. radiance, W sr^-1 m^-2; a grey image
        is written with equal channels.
    rle : bool, default True
        New-style run-length scanlines (as Radiance writes them, for widths
        8-32767); False writes flat pixels. -
    header : sequence of str
        Extra header lines (no ``=`` line may be ``FORMAT``). -

    Raises
    ------
    ValueError
        For negative, NaN or infinite values, or values beyond RGBE's range
        (about 1.7e38).
    """
    arr = np.asarray(rgb, dtype=np.float64)
    if arr.ndim == 2:
        arr = np.repeat(arr[..., None], 3, axis=-1)
    if arr.ndim != 3 or arr.shape[-1] != 3 or min(arr.shape[:2]) < 1:
        raise ValueError(f"rgb must have shape (H, W, 3) or (H, W), got {np.shape(rgb)}")
    if not np.all(np.isfinite(arr)) or np.any(arr < 0) or np.any(arr >= 2.0**127):
        raise ValueError("a Radiance picture holds finite values in [0, 1.7e38) only")
    height, width = arr.shape[:2]
    lines = ["#?RADIANCE", "bayesgloss.bundle.write_hdr", *header, f"FORMAT={_HDR_FORMAT}"]
    out = bytearray(("\n".join(lines) + f"\n\n-Y {height} +X {width}\n").encode("ascii"))
    rgbe = float_to_rgbe(arr)
    if not rle or not _RLE_MIN_LENGTH <= width <= _RLE_MAX_LENGTH:
        out += rgbe.tobytes()
    else:
        mark = bytes([2, 2, width >> 8, width & 0xFF])
        planes = np.ascontiguousarray(rgbe.transpose(0, 2, 1))  # (H, 4, W)
        for row in planes:
            out += mark
            for plane in row:
                _encode_rle_plane(plane, out)
    Path(path).write_bytes(bytes(out))


# ---------------------------------------------------------------------------
# PNG, TIFF, EXR
# ---------------------------------------------------------------------------

_PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
_TIFF_MAGIC = (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+")
_EXR_MAGIC = b"\x76\x2f\x31\x01"


class ImageInfo(NamedTuple):
    """What an image file holds, from its header alone."""

    height: int
    width: int
    channels: int
    dtype: np.dtype  # sample type as read (uint8, uint16, float16/32/64)
    kind: str  # "hdr", "png", "tiff" or "exr"
    bits: int | None = None  # bits per stored sample where the header says (PNG), else None


def image_kind(path: Path) -> str:
    """The file format by its magic bytes: "hdr", "png", "tiff" or "exr"."""
    with open(path, "rb") as f:
        magic = f.read(8)
    if magic.startswith(b"#?"):
        return "hdr"
    if magic == _PNG_MAGIC:
        return "png"
    if magic[:4] in _TIFF_MAGIC:
        return "tiff"
    if magic[:4] == _EXR_MAGIC:
        return "exr"
    raise ValueError(
        f"{path.name}: not a Radiance picture, PNG, TIFF or OpenEXR file (magic bytes {magic!r})"
    )


def _read_png(path, direct: bool) -> tuple[np.ndarray, int, dict]:
    import png

    with open(path, "rb") as f:
        reader = png.Reader(file=f)
        width, height, rows, info = reader.asDirect() if direct else reader.read()
        depth = info["bitdepth"]
        planes = info["planes"]
        pixels = np.empty((height, width * planes), np.uint16 if depth > 8 else np.uint8)
        for y, row in enumerate(rows):
            pixels[y] = row
    pixels = pixels.reshape(height, width, planes)
    return (pixels[..., 0] if planes == 1 else pixels), (1 << depth) - 1, info


def read_png(path: str | os.PathLike) -> tuple[np.ndarray, int]:
    """Read a PNG keeping every bit (pypng; 16-bit RGB keeps its low byte).

    Parameters
    ----------
    path : str or path-like
        The PNG file. -

    Returns
    -------
    pixels : ndarray of uint8 or uint16, shape (H, W) or (H, W, C)
        Code values as stored, palette expanded; C is 2 (grey, alpha), 3
        (RGB) or 4 (RGBA).
    max_code : int
        The top code, ``2**bitdepth - 1`` (255, 65535, or 1-15 for low
        bit depths).
    """
    pixels, max_code, _ = _read_png(path, direct=True)
    return pixels, max_code


def read_labels(path: str | os.PathLike) -> np.ndarray:
    """A facet label image: a grey PNG's values exactly as stored (no sBIT scaling).

    Parameters
    ----------
    path : str or path-like
        The PNG file (``facets.png``). -

    Returns
    -------
    ndarray of uint8 or uint16, shape (H, W)
        Facet id per pixel, 0 for background.

    Raises
    ------
    ValueError
        For a PNG that is not grey without alpha (palette, RGB, grey + alpha).
    """
    pixels, _, info = _read_png(path, direct=False)
    if not info["greyscale"] or info["alpha"] or info.get("palette"):
        kind = "palette" if info.get("palette") else "colour" if not info["greyscale"] else "alpha"
        raise ValueError(f"a label image must be a grey PNG without alpha, got a {kind} PNG")
    return pixels


def write_png(path: str | os.PathLike, pixels: np.ndarray) -> None:
    """Write a grey (H, W) or RGB (H, W, 3) uint8 or uint16 array as PNG."""
    import png

    arr = np.asarray(pixels)
    if arr.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"write_png needs uint8 or uint16 pixels, got {arr.dtype}")
    if arr.ndim == 3 and arr.shape[-1] == 1:
        arr = arr[..., 0]
    if not (arr.ndim == 2 or (arr.ndim == 3 and arr.shape[-1] == 3)):
        raise ValueError(f"write_png needs shape (H, W) or (H, W, 3), got {arr.shape}")
    height, width = arr.shape[:2]
    writer = png.Writer(
        width, height, greyscale=arr.ndim == 2, bitdepth=8 * arr.dtype.itemsize, compression=6
    )
    with open(path, "wb") as f:
        writer.write(f, arr.reshape(height, -1))


@contextlib.contextmanager
def _quiet_tifffile():
    """tifffile's own log lines about a damaged file silenced while it is
    read: the reader's one error names the file and the problem."""
    log = logging.getLogger("tifffile")
    level = log.level
    log.setLevel(logging.CRITICAL + 1)
    try:
        yield
    finally:
        log.setLevel(level)


def read_tiff(path: str | os.PathLike) -> np.ndarray:
    """First image of a TIFF file, shape (H, W) or (H, W, C), as stored (tifffile)."""
    import tifffile

    with _quiet_tifffile(), tifffile.TiffFile(os.fspath(path)) as tif:
        page = tif.pages[0]
        arr = page.asarray()
        if arr.ndim == 3 and page.planarconfig == tifffile.PLANARCONFIG.SEPARATE:
            arr = np.moveaxis(arr, 0, -1)
    return arr


def write_tiff(path: str | os.PathLike, pixels: np.ndarray) -> None:
    """Write a grey or RGB uint8, uint16 or float32 array as TIFF (zlib)."""
    import tifffile

    arr = np.asarray(pixels)
    if arr.dtype not in (np.uint8, np.uint16, np.float32):
        raise ValueError(f"write_tiff needs uint8, uint16 or float32 pixels, got {arr.dtype}")
    rgb = arr.ndim == 3 and arr.shape[-1] == 3
    if not (arr.ndim == 2 or rgb):
        raise ValueError(f"write_tiff needs shape (H, W) or (H, W, 3), got {arr.shape}")
    tifffile.imwrite(
        os.fspath(path),
        arr,
        photometric="rgb" if rgb else "minisblack",
        compression="zlib",
    )


def _openexr():
    try:
        import OpenEXR
    except ImportError:
        raise RuntimeError(
            "reading or writing OpenEXR needs the optional dependency 'openexr' "
            "(pip install 'bayesgloss[exr]' or pip install openexr)"
        ) from None
    return OpenEXR


def read_exr(path: str | os.PathLike) -> np.ndarray:
    """Read the R, G, B (or Y) channels of an OpenEXR file, (H, W, 3) or (H, W) float.

    Needs the optional ``openexr`` package.
    """
    exr = _openexr()
    with exr.File(os.fspath(path), separate_channels=True) as f:
        channels = {name: ch.pixels for name, ch in f.channels().items()}
    if all(c in channels for c in "RGB"):
        return np.stack([channels[c] for c in "RGB"], axis=-1)
    if "Y" in channels:
        return channels["Y"]
    raise ValueError(f"OpenEXR file has no R, G, B or Y channels: {sorted(channels)}")


def write_exr(path: str | os.PathLike, rgb: np.ndarray) -> None:
    """Write (H, W, 3) float32 (or float16) RGB as a ZIP-compressed OpenEXR file."""
    exr = _openexr()
    arr = np.asarray(rgb)
    if arr.dtype not in (np.float16, np.float32):
        arr = arr.astype(np.float32)
    if arr.ndim != 3 or arr.shape[-1] != 3:
        raise ValueError(f"write_exr needs shape (H, W, 3), got {arr.shape}")
    channels = {c: np.ascontiguousarray(arr[..., i]) for i, c in enumerate("RGB")}
    header = {"compression": exr.ZIP_COMPRESSION, "type": exr.scanlineimage}
    with exr.File(header, channels) as f:
        f.write(os.fspath(path))


def image_info(path: str | os.PathLike) -> ImageInfo:
    """Size, channels and sample type of an image, from its header only."""
    path = Path(path)
    kind = image_kind(path)
    if kind == "hdr":
        head = b""
        with open(path, "rb") as f:
            while True:  # read on until the resolution string
                chunk = f.read(65536)
                head += chunk
                end = head.find(b"\n\n")
                if not chunk or (end >= 0 and head.find(b"\n", end + 2) >= 0):
                    break
        header = _parse_hdr_header(head)
        n1, n2 = header.shape
        height, width = (n2, n1) if header.axes[0][1] == "X" else (n1, n2)
        return ImageInfo(height, width, 3, np.dtype(np.float32), kind)
    if kind == "png":
        with open(path, "rb") as f:
            head = f.read(33)
        if len(head) < 33 or head[12:16] != b"IHDR":
            raise ValueError(f"{path.name}: PNG without an IHDR chunk")
        width, height, depth, colour = struct.unpack(">IIBB", head[16:26])
        channels = {0: 1, 2: 3, 3: 3, 4: 2, 6: 4}.get(colour)
        if channels is None or width < 1 or height < 1:
            raise ValueError(f"{path.name}: bad PNG header")
        dtype = np.uint16 if depth == 16 and colour != 3 else np.uint8
        return ImageInfo(height, width, channels, np.dtype(dtype), kind, int(depth))
    if kind == "tiff":
        import tifffile

        with _quiet_tifffile(), tifffile.TiffFile(os.fspath(path)) as tif:
            page = tif.pages[0]
            return ImageInfo(
                int(page.imagelength),
                int(page.imagewidth),
                int(page.samplesperpixel),
                np.dtype(page.dtype),
                kind,
            )
    exr = _openexr()
    with exr.File(os.fspath(path), header_only=True) as f:
        header = f.header()  # emptied when the file closes
        low, high = (np.array(v) for v in header["dataWindow"])
        names = {ch.name for ch in header["channels"]}
    channels = 3 if names >= {"R", "G", "B"} else 1
    return ImageInfo(
        int(high[1] - low[1] + 1), int(high[0] - low[0] + 1), channels, np.dtype(np.float32), kind
    )


def decode_raw_linear(raw, white_balance: str = "camera") -> np.ndarray:
    """An open ``rawpy.RawPy`` decoded as :func:`read_raw` decodes a file.

    The one place that holds LibRaw's options for a linear decode, so that a
    check can decode a RAW file's own data changed in memory (e.g. scaled,
    ``studies/raw_check.py``) exactly as ``bundle make`` decodes photos.

    Parameters
    ----------
    raw : rawpy.RawPy
        An open RAW file (``rawpy.imread``). -
    white_balance : {"camera", "daylight"}
        As :func:`read_raw`. -

    Returns
    -------
    ndarray (H, W, 3) of uint16
        Linear RGB codes [-].
    """
    import rawpy

    return raw.postprocess(
        gamma=(1.0, 1.0),  # linear: no transfer curve
        no_auto_bright=True,
        adjust_maximum_thr=0.0,  # the file's white level, never the frame's own maximum
        output_bps=16,
        use_camera_wb=white_balance == "camera",
        use_auto_wb=False,
        user_flip=0,
        output_color=rawpy.ColorSpace.sRGB,
    )


def read_raw(path: str | os.PathLike, white_balance: str = "camera") -> np.ndarray:
    """A camera RAW file decoded linearly by LibRaw (``rawpy``): RGB linear in radiance.

    LibRaw subtracts the black level, scales to the white level, applies the
    white balance, demosaics (AHD) and converts the camera's colours to
    linear sRGB primaries (the file's colour matrix), with no transfer curve
    (``gamma=(1, 1)``), no automatic brightening and the image as stored
    (``user_flip=0``: EXIF orientation not applied, as for other photos):
    each output value is a fixed linear combination of the raw values, so
    pixel ratios are radiance ratios. The scale is the file's white level,
    never the frame's own brightest value (LibRaw's default
    ``adjust_maximum_thr=0.75`` rescales any frame whose maximum exceeds 75 %
    of white to its maximum, which would decode a frame 10 % darker than
    another near saturation as equally bright: time-lapse frames must keep
    their ratios). Saturated photosites clip at the top
    code (65535), which the bundle reader flags.

    Parameters
    ----------
    path : str or path-like
        A RAW file of a format LibRaw reads (DNG, NEF, CR2, CR3, ARW, RAF, ...). -
    white_balance : {"camera", "daylight"}
        The camera's as-shot white balance (LibRaw falls back to its daylight
        multipliers where the file has none), or LibRaw's daylight
        multipliers for the camera. -

    Returns
    -------
    ndarray (H, W, 3) of uint16
        Linear RGB codes [-].

    Raises
    ------
    ImportError
        Without ``rawpy`` (``pip install bayesgloss[raw]``).
    ValueError
        A file LibRaw cannot decode, naming it and LibRaw's reason.
    """
    if white_balance not in ("camera", "daylight"):
        raise ValueError(f"white_balance must be camera or daylight, got {white_balance!r}")
    try:
        import rawpy
    except ImportError:
        raise ImportError(
            "reading camera RAW files needs rawpy: pip install 'bayesgloss[raw]'"
        ) from None
    path = Path(path)
    try:
        with rawpy.imread(os.fspath(path)) as raw:
            rgb = decode_raw_linear(raw, white_balance)
    except (rawpy.LibRawError, rawpy.NotSupportedError) as err:
        reason = err.args[0] if err.args else type(err).__name__
        if isinstance(reason, bytes):  # LibRaw's message, as rawpy passes it
            reason = reason.decode(errors="replace")
        raise ValueError(f"{path.name}: rawpy (LibRaw) cannot decode it: {reason}") from None
    return np.ascontiguousarray(rgb, dtype=np.uint16)


def read_image(path: str | os.PathLike) -> tuple[np.ndarray, int | None]:
    """Read any image a bundle may hold, recognised by its magic bytes.

    Returns
    -------
    pixels : ndarray, shape (H, W) or (H, W, C)
        As stored: uint8/uint16 code values or floats.
    max_code : int or None
        Top code of an integer image (saturation level); None for floats.
    """
    path = Path(path)
    kind = image_kind(path)
    if kind == "hdr":
        return read_hdr(path), None
    if kind == "png":
        return read_png(path)
    arr = read_tiff(path) if kind == "tiff" else read_exr(path)
    if arr.dtype == np.uint8 or arr.dtype == np.uint16:
        return arr, int(np.iinfo(arr.dtype).max)
    if arr.dtype.kind == "f":
        return arr, None
    raise ValueError(f"{path.name}: unsupported sample type {arr.dtype}")


# ---------------------------------------------------------------------------
# pixel encodings
# ---------------------------------------------------------------------------


def srgb_to_linear(value: Any) -> np.ndarray:
    """Invert the sRGB transfer curve (IEC 61966-2-1:1999, eq. for C'_sRGB).

    ``linear = value / 12.92`` for value <= 0.04045, else
    ``((value + 0.055) / 1.055) ** 2.4``.

    Parameters
    ----------
    value : array_like
        Encoded values, normalised to [0, 1]. -

    Returns
    -------
    ndarray
        Linear values, same shape; NaN stays NaN. -
    """
    v = np.asarray(value, dtype=float)
    return np.where(v <= 0.04045, v / 12.92, ((np.maximum(v, 0.04045) + 0.055) / 1.055) ** 2.4)


def linear_to_srgb(linear: Any) -> np.ndarray:
    """The sRGB transfer curve, the inverse of :func:`srgb_to_linear`.

    ``12.92 linear`` for linear <= 0.0031308, else ``1.055 linear^(1/2.4) - 0.055``.
    """
    v = np.asarray(linear, dtype=float)
    return np.where(
        v <= 0.0031308, 12.92 * v, 1.055 * np.maximum(v, 0.0031308) ** (1 / 2.4) - 0.055
    )


def parse_pixel_encoding(encoding: str) -> tuple[str, float | None]:
    """Split ``camera.pixel_encoding`` into its name and gamma.

    Returns
    -------
    name : str
        One of ``linear-radiance``, ``linear``, ``srgb``, ``gamma``, ``unknown``.
    gamma : float or None
        G of ``gamma:G``, else None.

    Raises
    ------
    ValueError
        For an unknown name or a ``gamma:G`` whose G is not a positive number.
    """
    if not isinstance(encoding, str):
        raise ValueError(f"pixel encoding must be a string, got {encoding!r}")
    if encoding.startswith("gamma:"):
        try:
            gamma = float(encoding[len("gamma:") :])
        except ValueError:
            gamma = math.nan
        if not (math.isfinite(gamma) and gamma > 0):
            raise ValueError(f"pixel encoding {encoding!r} needs a positive number G in 'gamma:G'")
        return "gamma", gamma
    if encoding in PIXEL_ENCODINGS and encoding != "gamma:G":
        return encoding, None
    raise ValueError(f"unknown pixel encoding {encoding!r}; valid: {', '.join(PIXEL_ENCODINGS)}")


def decode_pixels(
    pixels: np.ndarray, encoding: str, max_code: int | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Linear RGB and the saturation mask of stored pixels.

    Parameters
    ----------
    pixels : ndarray, shape (..., C) with C = 3 or 4 (RGB, alpha ignored), or (...) grey
        Code values (integer images) or floats, as :func:`read_image` gives.
        For a grey image pass ``pixels[..., None]``. -
    encoding : str
        ``camera.pixel_encoding`` (see :data:`PIXEL_ENCODINGS`). -
    max_code : int, optional
        Top code of an integer image: values are divided by it, and a pixel
        with any channel at it is saturated. None for float images. -

    Returns
    -------
    rgb : ndarray of float32, shape (..., 3)
        Linear RGB: radiance for ``linear-radiance``, relative otherwise,
        normalised code values for ``unknown``.
    saturated : ndarray of bool, shape (...)
        Pixels at the top code in any channel (all False for floats).
    """
    name, gamma = parse_pixel_encoding(encoding)
    arr = np.asarray(pixels)
    channels = arr.shape[-1]
    if channels in (1, 2):  # grey (+ alpha): equal RGB; luminance weights sum to 1
        arr = np.repeat(arr[..., :1], 3, axis=-1)
    elif channels in (3, 4):
        arr = arr[..., :3]
    else:
        raise ValueError(f"pixels need 1-4 channels on the last axis, got {channels}")
    if max_code is None:
        saturated = np.zeros(arr.shape[:-1], bool)
        value = arr.astype(np.float32, copy=False)
    else:
        saturated = np.any(arr >= max_code, axis=-1)
        value = arr.astype(np.float32) / np.float32(max_code)
    if name == "srgb":
        value = srgb_to_linear(value).astype(np.float32)
    elif name == "gamma":
        value = np.power(np.maximum(value, 0), np.float32(gamma), dtype=np.float32)
    return value, saturated

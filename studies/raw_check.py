"""Check: real camera RAW files are read as ``bundle make`` needs them.

The tests decode DNGs the test writes itself. This script checks the same
reading on RAW files from real cameras, which nobody here wrote and which
are not committed (their licences do not allow it): give their paths. For
each file it measures

1. **Linearity of the decode at the file's own scale.** The file's raw
   photosite values are scaled in memory by k = 0.9, 0.7 and 0.5 (black
   level kept) and decoded with :func:`bayesgloss.images.decode_raw_linear`,
   the options ``bundle make`` uses. A linear decode at a fixed scale gives
   pixel ratios k on every unsaturated pixel; the same with LibRaw's default
   ``adjust_maximum_thr`` (0.75), and with all of LibRaw's defaults (its
   BT.709 transfer curve too), are measured beside it, to show the check
   tells them apart.
2. **Linearity against the sensor.** Mean photosite values per colour over
   smooth 32 x 32 blocks against the decoded block means: the relative rms
   residual of the best 3 x 3 linear map (demosaicking and the colour matrix
   are linear; a transfer curve is not).
3. **Metadata.** :func:`bayesgloss.exif.photo_time` (at ``--utc-offset``
   where the file has none) and :func:`bayesgloss.exif.photo_exposure`,
   beside LibRaw's own reading of shutter, aperture and ISO.

Usage: python studies/raw_check.py FILE [FILE ...] [--utc-offset +00:00]
       [--out studies/results/raw_check.json]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from bayesgloss import exif, images
from bayesgloss.camera_model import CaptureError

SCALES = (0.9, 0.7, 0.5)
BLOCK = 32


def _decode_scaled(path: Path, scale: float, how: str) -> np.ndarray:
    """The file decoded after its photosites above black are scaled by ``scale``."""
    import rawpy

    with rawpy.imread(str(path)) as raw:
        black = np.asarray(raw.black_level_per_channel, dtype=float)[raw.raw_colors]
        values = raw.raw_image.astype(float)
        raw.raw_image[:] = np.rint(black + scale * (values - black)).astype(np.uint16)
        if how == "bayesgloss":
            return images.decode_raw_linear(raw).astype(float)
        options = {"no_auto_bright": True, "output_bps": 16, "use_camera_wb": True, "user_flip": 0}
        if how == "linear, LibRaw's adjust_maximum_thr":
            options["gamma"] = (1.0, 1.0)
        return raw.postprocess(**options).astype(float)


def scale_ratios(path: Path, how: str) -> dict:
    """Pixel ratios decode(k raw) / decode(raw) on pixels 2 % to 90 % of full scale."""
    full = _decode_scaled(path, 1.0, how)
    top = 65535.0
    out = {}
    for k in SCALES:
        ratio = _decode_scaled(path, k, how) / np.where(full > 0, full, np.nan)
        keep = (full > 0.02 * top) & (full < 0.9 * top)
        q = ratio[keep]
        out[str(k)] = {
            "median": float(np.median(q)),
            "p01": float(np.quantile(q, 0.01)),
            "p99": float(np.quantile(q, 0.99)),
            "pixels": int(q.size),
        }
    return out


def sensor_fit(path: Path) -> dict:
    """Relative rms residual of decoded block means against a 3 x 3 map of raw ones."""
    import rawpy

    with rawpy.imread(str(path)) as raw:
        colours = raw.raw_colors_visible.copy()
        black = np.asarray(raw.black_level_per_channel, dtype=float)[colours]
        values = raw.raw_image_visible.astype(float) - black
        white = float(raw.white_level) - black.max()
        decoded = images.decode_raw_linear(raw).astype(float)
    h, w = (s // BLOCK for s in values.shape)

    def blocks(a):
        return (
            a[: h * BLOCK, : w * BLOCK].reshape(h, BLOCK, w, BLOCK, *a.shape[2:]).mean(axis=(1, 3))
        )

    sensor = []
    for group in ((0,), (1, 3), (2,)):  # R, both greens, B as LibRaw numbers them
        mask = np.isin(colours, group)
        sensor.append(blocks(np.where(mask, values, 0.0)) / blocks(mask.astype(float)))
    x = np.stack(sensor, axis=-1).reshape(-1, 3)
    y = blocks(decoded).reshape(-1, 3)
    spread = np.sqrt(np.maximum(blocks(values**2) - blocks(values) ** 2, 0.0)) / blocks(values)
    clipped = (values >= 0.98 * white) | (decoded.min(-1) <= 0) | (decoded.max(-1) >= 65000)
    keep = (blocks(clipped.astype(float)).reshape(-1) == 0) & (spread.reshape(-1) < 0.3)
    coef, *_ = np.linalg.lstsq(x[keep], y[keep], rcond=None)
    residual = y[keep] - x[keep] @ coef
    rel = float(np.sqrt(np.mean(residual**2) / np.mean(y[keep] ** 2)))
    # the same map fitted to the decode through sRGB's transfer curve, for contrast
    curved = images.linear_to_srgb(np.clip(y / 65535.0, 0, 1))
    coef_c, *_ = np.linalg.lstsq(x[keep], curved[keep], rcond=None)
    res_c = curved[keep] - x[keep] @ coef_c
    rel_c = float(np.sqrt(np.mean(res_c**2) / np.mean(curved[keep] ** 2)))
    return {"blocks": int(keep.sum()), "relative_rms": rel, "relative_rms_srgb_curve": rel_c}


def metadata(path: Path, utc_offset: str | None) -> dict:
    import rawpy

    with rawpy.imread(str(path)) as raw:
        other = raw.other
        libraw = {"shutter_s": float(other.shutter_speed), "f_number": float(other.aperture),
                  "iso": float(other.iso_speed)}  # fmt: skip
    out = {"libraw": libraw}
    out["libraw_relative_exposure"] = libraw["shutter_s"] * libraw["iso"] / libraw["f_number"] ** 2
    out["relative_exposure"] = exif.photo_exposure(path)
    try:
        out["time_utc"] = str(exif.photo_time(path))
    except CaptureError as err:
        out["time_error_without_offset"] = str(err)
        out["time_utc"] = str(exif.photo_time(path, utc_offset)) if utc_offset else None
    return out


def check(path: Path, utc_offset: str | None) -> dict:
    import rawpy

    with rawpy.imread(str(path)) as raw:
        sizes = raw.sizes
        info = {"file": path.name, "bytes": path.stat().st_size, "raw_type": str(raw.raw_type),
                "size": [int(sizes.raw_width), int(sizes.raw_height)],
                "white_level": int(raw.white_level),
                "black_levels": [int(b) for b in raw.black_level_per_channel]}  # fmt: skip
    info["metadata"] = metadata(path, utc_offset)
    info["scale_ratios"] = {
        how: scale_ratios(path, how)
        for how in ("bayesgloss", "linear, LibRaw's adjust_maximum_thr", "LibRaw's defaults")
    }
    info["sensor_fit"] = sensor_fit(path)
    return info


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("files", nargs="+", type=Path)
    ap.add_argument("--utc-offset", default="+00:00")
    ap.add_argument(
        "--out", type=Path, default=Path(__file__).parent / "results" / "raw_check.json"
    )
    args = ap.parse_args(argv)
    results = [check(p, args.utc_offset) for p in args.files]
    for r in results:
        print(r["file"], r["raw_type"], r["size"], "white", r["white_level"])
        m = r["metadata"]
        print(f"  time {m['time_utc']}  exposure {m['relative_exposure']:.6g} "
              f"(LibRaw's own {m['libraw_relative_exposure']:.6g})")  # fmt: skip
        for how, ratios in r["scale_ratios"].items():
            cells = "  ".join(
                f"k={k}: {v['median']:.4f} [{v['p01']:.4f}, {v['p99']:.4f}]"
                for k, v in ratios.items()
            )
            print(f"  {how:38s} {cells}")
        f = r["sensor_fit"]
        print(f"  against the sensor ({f['blocks']} blocks): rms {f['relative_rms']:.4f} linear, "
              f"{f['relative_rms_srgb_curve']:.4f} through sRGB's curve")  # fmt: skip
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(results, indent=1) + "\n")
    print("wrote", args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

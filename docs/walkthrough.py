"""The README's walk-through "From photos and a mesh": the user's files, the commands, the figure.

A user has a folder of tripod photos (JPEGs with EXIF times and exposures),
a mesh of the object and the camera's calibration. Here Radiance stands in
for the day of photography: :func:`prepare` writes such files for the
non-convex :func:`bayesgloss.geometry.l_building` (an OBJ), a camera file
with OpenCV lens distortion, and seven JPEGs rendered through that lens
under gensky's clear sky with per-frame auto-exposure. :func:`run` then does
what the README tells a user to do, with the ``bayesgloss`` command itself,
and saves what each command printed; :func:`figure` draws the made label
image over its frame and the facets' curves from the made bundle.

Run as ``python docs/walkthrough.py [--out out/walkthrough]``: about 4 min on
2 cores (the estimate at the command line's defaults is most of it). Writes
``docs/figures/walkthrough.png`` and ``docs/results/walkthrough.json``; the
user's files and the bundle stay under ``--out``.
"""

from __future__ import annotations

import argparse
import json
import shlex
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
FIGURE = HERE / "figures" / "walkthrough.png"
RESULTS = HERE / "results" / "walkthrough.json"
#: The scene of the photos (seed: the configuration's hash seeds its exposure jitter).
CONFIG = dict(
    name="walkthrough",
    shape="mesh",
    view="SW",
    camera_height=4.0,
    image_size=160,
    solar_hours=(6.0, 8.0, 10.0, 12.0, 14.0, 16.0, 18.0),
    colour=0.5,
    specularity=0.5,
    roughness=0.0,
    pixel_encoding="srgb",
    exposure="auto",
    exposure_jitter=0.3,
    distortion=(-1.0, 0.5, 0.002, -0.001, 0.0),
)


def prepare(out: Path) -> dict:
    """The user's files: ``building.obj``, ``camera.json`` and ``photos/*.JPG``."""
    from PIL import Image, TiffImagePlugin

    from bayesgloss import bundle, geometry, sequences

    out.mkdir(parents=True, exist_ok=True)
    mesh = out / "building.obj"
    geometry.write_obj(geometry.l_building(), mesh)
    cfg = sequences.SequenceConfig(mesh_file=str(mesh), **CONFIG)
    (path,) = sequences.render_bundles([cfg], out / "radiance", jobs=2, progress=False)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", bundle.BundleWarning)
        rendered = bundle.read_bundle(path)
    cam = sequences.opencv_camera(cfg)
    fields = {k: getattr(cam, k) for k in ("width", "height", "fx", "fy", "cx", "cy")}
    fields |= {k: getattr(cam, k).tolist() for k in ("distortion", "rotation", "position")}
    (out / "camera.json").write_text(json.dumps(fields, indent=1) + "\n")
    photos = out / "photos"
    photos.mkdir(exist_ok=True)
    gains = np.asarray(rendered.truth["exposure"])
    local = rendered.times.tz_convert("+02:00")  # the camera's clock: summer time
    for t in range(len(rendered)):
        exif = Image.Exif()
        sub = exif.get_ifd(0x8769)
        sub[0x9003] = local[t].strftime("%Y:%m:%d %H:%M:%S")  # DateTimeOriginal
        sub[0x9011] = "+02:00"  # OffsetTimeOriginal
        sub[0x829A] = TiffImagePlugin.IFDRational(int(round(gains[t] * 1e6)), 250_000_000)
        sub[0x829D] = TiffImagePlugin.IFDRational(8, 1)  # FNumber
        sub[0x8827] = 200  # ISO
        Image.fromarray(rendered.read_frame(t)[0]).save(
            photos / f"DSC{t:05d}.JPG", exif=exif.tobytes(), quality=95, subsampling=0
        )
    return {"rendered": str(path), "true_gamma": rendered.truth["gloss"]}


def _bayesgloss(args: list[str], log: list) -> str:
    """Run the ``bayesgloss`` command as a user would; keep the command and its output."""
    command = [sys.executable, "-m", "bayesgloss.cli", *args]
    start = time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True)
    seconds = time.perf_counter() - start
    if done.returncode:
        raise SystemExit(f"bayesgloss {shlex.join(args)} failed:\n{done.stderr}")
    log.append({"command": "bayesgloss " + shlex.join(args), "seconds": round(seconds, 1),
                "stdout": done.stdout})  # fmt: skip
    return done.stdout


def run(out: Path) -> dict:
    """The README's commands, on the prepared files."""
    import shutil

    for old in ("building-bundle", "estimate"):
        shutil.rmtree(out / old, ignore_errors=True)
    log: list = []
    _bayesgloss(
        ["bundle", "make", "--mesh", str(out / "building.obj"), "--camera",
         str(out / "camera.json"), "--photos", str(out / "photos"), "--out",
         str(out / "building-bundle"), "--latitude", "40", "--longitude", "0",
         "--overlay", str(out / "labels.png")], log,
    )  # fmt: skip
    _bayesgloss(["curves", str(out / "building-bundle")], log)
    _bayesgloss(["estimate", str(out / "building-bundle"), "--out", str(out / "estimate"),
                 "--quiet"], log)  # fmt: skip
    _bayesgloss(["report", str(out / "estimate")], log)
    (out / "commands.json").write_text(json.dumps(log, indent=1) + "\n")
    return {"commands": log}


def figure(out: Path, results: dict) -> None:
    """The made label image over a photo, and the facets' curves with the shadowed entries."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from bayesgloss import bundle, capture, visibility

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", bundle.BundleWarning)
        made = bundle.read_bundle(out / "building-bundle")
    middle = len(made) // 2
    photo = made.read_frame(middle)[0]
    overlay = capture.label_overlay(photo, made.labels)
    curves = visibility.shadow_flags(made, bundle.facet_curves(made))
    partly = (curves.flag_bits >> bundle.FLAG_REASONS.index("partly-shadowed")) & 1 > 0
    hours = np.asarray(made.times.tz_convert("+02:00").hour + made.times.minute / 60)
    relative = curves.luminance / made.exposure[None, :]
    relative = relative / np.nanmax(relative)
    hue = (np.arange(made.facets.ids.max() + 1) * 0.381966) % 1.0  # label_overlay's colours
    colour = 0.5 + 0.5 * np.cos(2 * np.pi * (hue[:, None] + np.array([0.0, 1 / 3, 2 / 3])))

    fig, axes = plt.subplots(1, 3, figsize=(12.5, 4.3), width_ratios=[1, 1, 1.25])
    axes[0].imshow(photo, interpolation="nearest")
    axes[0].set_title(f"photo {middle + 1} of {len(made)} (JPEG, lens distortion)", fontsize=10)
    axes[1].imshow(overlay, interpolation="nearest")
    axes[1].set_title("bundle make's labels over it (--overlay)", fontsize=10)
    for fid in made.facets.ids:
        rows, cols = np.nonzero(made.labels == fid)
        axes[1].text(np.median(cols), np.median(rows), str(fid), ha="center", va="center",
                     fontsize=9, weight="bold", color="black")  # fmt: skip
    for ax in axes[:2]:
        ax.set_xticks([])
        ax.set_yticks([])
    ax = axes[2]
    for k, fid in enumerate(made.facets.ids):
        ok = curves.valid[k]
        ax.plot(hours[ok], relative[k, ok], "-o", color=colour[fid], ms=4, label=f"facet {fid}")
        ax.plot(hours[partly[k]], relative[k, partly[k]], "x", color="black", ms=8, mew=2)
    ax.plot([], [], "x", color="black", ms=8, mew=2, label="partly shadowed:\nleft out")
    ax.set_xlabel("camera clock (UTC+02:00) [h]")
    ax.set_ylabel("facet luminance / EXIF exposure (relative)")
    ax.set_title("the made bundle's curves (bayesgloss curves)", fontsize=10)
    ax.legend(fontsize=7, loc="upper left", ncol=2)
    fig.tight_layout()
    FIGURE.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(FIGURE, dpi=110)
    plt.close(fig)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="out/walkthrough", help="folder for the user's files")
    parser.add_argument("--figure-only", action="store_true", help="redraw from --out's bundle")
    args = parser.parse_args(argv)
    out = Path(args.out)
    if args.figure_only:
        results = json.loads(RESULTS.read_text())
    else:
        results = {"config": CONFIG, **prepare(out), **run(out)}
        summary = json.loads((out / "estimate" / "summary.json").read_text())
        results["estimate"] = {"object_gamma": summary["object"]["gamma"],
                               "flags": summary["object"].get("flags", [])}  # fmt: skip
        RESULTS.parent.mkdir(parents=True, exist_ok=True)
        RESULTS.write_text(json.dumps(results, indent=1) + "\n")
    figure(out, results)
    print(f"wrote {FIGURE} and {RESULTS}")


if __name__ == "__main__":
    main()

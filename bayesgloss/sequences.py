"""Test sequences rendered with the real Radiance, written as sequence bundles.

A :class:`SequenceConfig` says everything about one sequence: site, day and
frame times, object, camera, material, sky, ground, image size and Radiance's
ambient settings. :func:`render_bundles` renders any number of them:

- configurations that differ only in the camera share one scene per frame,
  and one ``rtrace`` process traces all their cameras' pixels, so Radiance's
  irradiance cache is shared between views;
- frames render in parallel (``jobs`` processes of ``rtrace``);
- each bundle is written atomically into ``cache_dir/<name>-<hash>/``, the
  hash being that of its configuration, so a finished bundle is never
  rendered again and an interrupted run resumes where it stopped.

Images are traced with ``rtrace`` on bayesgloss's own pinhole camera rays, so
the image and the facet label pass use exactly the same rays. A pixel is
labelled with a facet only when its centre and its four corners all hit that
facet (wholly inside); the other pixels are background (0).

The sun of every frame is bayesgloss's SPA position (apparent, as the bundle
reader computes it), handed to ``gensky -ang`` or ``gendaylit -ang``.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from . import geometry, radiance, reflectance, sky, sun

__all__ = [
    "SequenceConfig",
    "paper_configs",
    "render_bundles",
    "camera_rays",
    "label_image",
    "DEFAULT_AMBIENT",
]

#: rtrace settings for the test sequences: two bounces (facet -> ground ->
#: sky), irradiance cache at 10 % accuracy with a resolution fine for the
#: 40 m scene (-ar 512: 8 cm), 512 stratified samples, repeatable sampling.
DEFAULT_AMBIENT = (
    "-ab",
    "2",
    "-aa",
    "0.1",
    "-ar",
    "512",
    "-ad",
    "512",
    "-as",
    "256",
    "-lr",
    "6",
    "-lw",
    "1e-4",
    "-u-",
)

SKIES = ("gensky-clear", "gensky-intermediate", "gensky-overcast", "gensky-uniform", "perez")
SHAPES = ("hemisphere", "box")


@dataclass(frozen=True)
class SequenceConfig:
    """One test sequence. Every field has a documented default (the paper's scene).

    Site and time: ``latitude``, ``longitude`` (deg, east positive),
    ``elevation`` (m); frames at ``solar_hours`` (local apparent solar time,
    h) on ``date``, or at ``times`` (ISO 8601 with UTC offsets) when given.
    Object: ``shape`` ("hemisphere": ``radius``, ``n_rings``, ``n_segments``;
    "box": ``box_size`` (x, y, z) m, standing on the ground, turned by
    ``box_azimuth`` deg). Camera: ``view`` (a paper view name or bearing in
    degrees), ``camera_distance`` and ``camera_height`` (m), square image of
    ``image_size`` pixels framing the object. Material: Radiance ``material``
    ("plastic" or "metal"), grey ``colour``, ``specularity``, ``roughness``.
    Sky: ``sky`` (one of :data:`SKIES`), gensky's ``turbidity``, Perez's
    clear-sky ``linke_turbidity``. Ground: ``ground_reflectance`` and a disc
    of ``ground_radius`` m (beyond it, the sky description's ground glow).
    ``ambient``: rtrace options.
    """

    name: str = "sequence"
    latitude: float = 40.0
    longitude: float = 0.0
    elevation: float = 0.0
    date: str = "1996-06-21"
    solar_hours: tuple = tuple(float(h) for h in range(4, 23))
    times: tuple | None = None
    shape: str = "hemisphere"
    radius: float = 1.0
    n_rings: int = 6
    n_segments: int = 16
    box_size: tuple = (1.0, 1.0, 1.0)
    box_azimuth: float = 0.0
    view: str | float = "W"
    camera_distance: float = 10.0
    camera_height: float = 2.0
    image_size: int = 128
    material: str = "plastic"
    colour: float = 0.5
    specularity: float = 0.0
    roughness: float = 0.0
    sky: str = "gensky-clear"
    turbidity: float = 2.45
    linke_turbidity: float = 3.0
    ground_reflectance: float = 0.2
    ground_radius: float = 20.0
    ambient: tuple = field(default=DEFAULT_AMBIENT)

    def __post_init__(self):
        problems = []
        if not -90 <= self.latitude <= 90:
            problems.append(f"latitude {self.latitude} outside [-90, 90]")
        if not -180 <= self.longitude <= 180:
            problems.append(f"longitude {self.longitude} outside [-180, 180]")
        if self.shape not in SHAPES:
            problems.append(f"shape {self.shape!r} not one of {', '.join(SHAPES)}")
        if self.sky not in SKIES:
            problems.append(f"sky {self.sky!r} not one of {', '.join(SKIES)}")
        if self.material not in reflectance.MATERIAL_KINDS:
            problems.append(f"material {self.material!r} not one of plastic, metal")
        if not 0 <= self.specularity <= 1:
            problems.append(f"specularity {self.specularity} outside [0, 1]")
        if not 0 <= self.colour <= 1:
            problems.append(f"colour {self.colour} outside [0, 1]")
        if not 8 <= self.image_size <= 4096:
            problems.append(f"image_size {self.image_size} outside [8, 4096]")
        if problems:
            raise ValueError(f"sequence config {self.name!r}: " + "; ".join(problems))

    @classmethod
    def from_dict(cls, values: dict) -> SequenceConfig:
        """A configuration from a JSON-like dict; unknown keys are an error."""
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise ValueError(
                f"unknown sequence config field(s): {', '.join(unknown)}; "
                f"valid: {', '.join(sorted(known))}"
            )
        tuples = {"solar_hours", "times", "box_size", "ambient"}
        clean = {k: (tuple(v) if k in tuples and v is not None else v) for k, v in values.items()}
        return cls(**clean)

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    def key(self) -> str:
        """Hash of everything that changes the rendered bundle (not the name)."""
        d = self.to_dict()
        d.pop("name")
        d["renderer"] = _renderer_version()
        return hashlib.sha256(json.dumps(d, sort_keys=True).encode()).hexdigest()[:12]

    def scene_key(self) -> str:
        """Hash of the scene only: configs sharing it differ only in the camera."""
        d = self.to_dict()
        for k in ("name", "view", "camera_distance", "camera_height", "image_size"):
            d.pop(k)
        return hashlib.sha256(json.dumps(d, sort_keys=True).encode()).hexdigest()[:12]

    # -- derived scene quantities ------------------------------------------

    def facets(self) -> geometry.Facets:
        if self.shape == "hemisphere":
            return geometry.tessellated_hemisphere(self.radius, self.n_rings, self.n_segments)
        return geometry.box(self.box_size, self.box_azimuth)

    def camera_position(self) -> np.ndarray:
        return geometry.camera_position(self.view, self.camera_distance, self.camera_height)

    def frame_times(self) -> pd.DatetimeIndex:
        if self.times is not None:
            return pd.DatetimeIndex([pd.Timestamp(t) for t in self.times]).tz_convert("UTC")
        return sun.times_at_local_solar_time(
            self.date, np.asarray(self.solar_hours), self.longitude, self.latitude
        )

    def sun_directions(self) -> np.ndarray:
        return sun.sun_direction_at(
            self.frame_times(), self.latitude, self.longitude, self.elevation
        )

    def truth(self) -> dict:
        return {
            "material": self.material,
            "colour": self.colour,
            "specularity": self.specularity,
            "roughness": self.roughness,
            "sky": self.sky,
            "renderer": "radiance",
            "gloss": float(
                reflectance.gloss_of_radiance_material(self.material, self.specularity, self.colour)
            ),
            "config": self.to_dict(),
        }


def _renderer_version() -> str:
    from . import __version__

    return f"bayesgloss-{__version__}"


def paper_configs(image_size: int = 128, **overrides) -> list[SequenceConfig]:
    """The paper's 60 sequences: 5 views x plastic/metal x specularity 0, 0.5, 1
    x CIE clear and intermediate skies with sun (Love & Efford, sec. 4)."""
    out = []
    for sky_name in ("gensky-clear", "gensky-intermediate"):
        for kind in ("plastic", "metal"):
            for spec in (0.0, 0.5, 1.0):
                for view in geometry.CAMERA_AZIMUTHS:
                    name = f"paper-{view}-{kind}-{spec:g}-{sky_name.split('-')[1]}"
                    out.append(
                        SequenceConfig(
                            name=name,
                            view=view,
                            material=kind,
                            specularity=spec,
                            sky=sky_name,
                            image_size=image_size,
                            **overrides,
                        )
                    )
    return out


# -- camera and labels ---------------------------------------------------------


def _camera_frame(config: SequenceConfig, facets: geometry.Facets):
    """Camera position, look direction, right and up vectors, tan of half the FOV."""
    verts = np.concatenate(facets.polygons)
    lo, hi = verts.min(0), verts.max(0)
    target = 0.5 * (lo + hi)
    bound = 0.5 * np.linalg.norm(hi - lo)  # bounding-sphere radius about the centre
    cam = config.camera_position()
    fwd = target - cam
    dist = np.linalg.norm(fwd)
    fwd /= dist
    right = np.cross(fwd, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    tan_half = 1.08 * bound / np.sqrt(max(dist**2 - bound**2, 1e-9))  # 8 % margin
    return cam, fwd, right, up, tan_half


def camera_rays(config: SequenceConfig, facets: geometry.Facets, corners: bool = False):
    """Pinhole rays through pixel centres (or the pixel grid's corners).

    Returns origins and unit directions, shape (H*W, 3) with rows top to
    bottom, or ((H+1)*(W+1), 3) for corners.
    """
    cam, fwd, right, up, tan_half = _camera_frame(config, facets)
    n = config.image_size
    grid = np.arange(n + 1) if corners else np.arange(n) + 0.5
    x = (grid / n * 2 - 1) * tan_half
    y = (1 - grid / n * 2) * tan_half
    d = fwd + x[None, :, None] * right + y[:, None, None] * up
    d = (d / np.linalg.norm(d, axis=-1, keepdims=True)).reshape(-1, 3)
    return np.broadcast_to(cam, d.shape), d


def label_image(config: SequenceConfig, facets: geometry.Facets) -> np.ndarray:
    """Facet label image (H, W): facet id where the pixel lies wholly inside it, else 0."""
    scene = "".join(radiance.material(f"f{i}", "plastic", 0.5, 0.0, 0.0) for i in facets.ids)
    scene += "".join(
        radiance.polygons([p], f"f{i}", prefix=f"poly{i}_")
        for i, p in zip(facets.ids, facets.polygons, strict=True)
    )
    n = config.image_size
    oc, dc = camera_rays(config, facets, corners=False)
    ok, dk = camera_rays(config, facets, corners=True)
    rays = np.concatenate([np.concatenate([oc, dc], 1), np.concatenate([ok, dk], 1)])
    with tempfile.TemporaryDirectory(prefix="bayesgloss-label-") as tmp:
        octree = radiance.oconv(scene, Path(tmp) / "labels.oct")
        out = radiance.run(
            ["rtrace", "-h-", "-ff", "-om", "-ab", "0", str(octree)],
            input=rays.astype(np.float32).tobytes(),
        )
    names = out.decode().split()
    ids = np.array([int(s[1:]) if s.startswith("f") else 0 for s in names])
    centre = ids[: n * n].reshape(n, n)
    corner = ids[n * n :].reshape(n + 1, n + 1)
    whole = (
        (corner[:-1, :-1] == centre)
        & (corner[:-1, 1:] == centre)
        & (corner[1:, :-1] == centre)
        & (corner[1:, 1:] == centre)
    )
    return np.where(whole, centre, 0)


# -- scene text ----------------------------------------------------------------


def _sky_text(config: SequenceConfig, sun_direction: np.ndarray, day_of_year: int) -> str:
    if config.sky.startswith("gensky-"):
        return radiance.gensky_ang(
            sun_direction,
            config.sky.split("-", 1)[1],
            ground_reflectance=config.ground_reflectance,
            turbidity=config.turbidity,
        )
    dni, dhi = sky.clear_sky_irradiance(sun_direction, day_of_year, config.linke_turbidity)
    return radiance.gendaylit_ang(
        sun_direction, float(dni), float(dhi), ground_reflectance=config.ground_reflectance
    )


def _object_text(config: SequenceConfig, facets: geometry.Facets) -> str:
    mat = radiance.material(
        "object_material", config.material, config.colour, config.specularity, config.roughness
    )
    r = config.ground_radius
    a = np.linspace(0, 2 * np.pi, 64, endpoint=False)
    disc = np.column_stack([r * np.cos(a), r * np.sin(a), np.zeros_like(a)])
    return (
        mat
        + radiance.polygons(facets.polygons, "object_material")
        + radiance.material("ground_material", "plastic", config.ground_reflectance, 0, 0)
        + radiance.polygons([disc], "ground_material", prefix="ground")
    )


# -- rendering -----------------------------------------------------------------


def _bundle_dir(cache_dir: Path, config: SequenceConfig) -> Path:
    return cache_dir / f"{config.name}-{config.key()}"


def _render_frame(scene_text: str, sky_text: str, rays: np.ndarray, ambient) -> np.ndarray:
    with tempfile.TemporaryDirectory(prefix="bayesgloss-frame-") as tmp:
        octree = radiance.oconv(
            sky_text + radiance.sky_glow(ground=True) + scene_text, Path(tmp) / "frame.oct"
        )
        return radiance.rtrace(octree, rays[:, :3], rays[:, 3:], ambient)


def render_bundles(configs, cache_dir, *, jobs: int = 2, progress: bool = True) -> list[Path]:
    """Render sequences into bundles (cached by configuration hash).

    Parameters
    ----------
    configs : iterable of SequenceConfig
    cache_dir : path
        Bundles are written to ``cache_dir/<name>-<hash>/``.
    jobs : int
        Radiance processes running at once.
    progress : bool
        Print a progress line to stderr.

    Returns
    -------
    list of Path
        The bundle folders, in the order of ``configs``.
    """
    from . import bundle as bundle_io

    configs = list(configs)
    cache_dir = Path(cache_dir)
    cache_dir.mkdir(parents=True, exist_ok=True)
    paths = [_bundle_dir(cache_dir, c) for c in configs]
    todo = [c for c, p in zip(configs, paths, strict=True) if not (p / "sequence.json").exists()]
    groups: dict[str, list[SequenceConfig]] = {}
    for c in todo:
        groups.setdefault(c.scene_key(), []).append(c)

    tasks, plans = [], {}
    for key, members in groups.items():
        first = members[0]
        facets = first.facets()
        suns = first.sun_directions()
        day = int(first.frame_times()[0].day_of_year)
        rays = [np.concatenate(camera_rays(m, facets), axis=1) for m in members]
        plans[key] = dict(
            members=members,
            facets=facets,
            suns=suns,
            rays=rays,
            frames=[None] * len(suns),
            scene=_object_text(first, facets),
        )
        for t, s in enumerate(suns):
            tasks.append((key, t, _sky_text(first, s, day)))

    done, start = 0, time.perf_counter()
    with ThreadPoolExecutor(max_workers=max(1, jobs)) as pool:
        futures = {
            pool.submit(
                _render_frame,
                plans[k]["scene"],
                sky_text,
                np.concatenate(plans[k]["rays"]),
                plans[k]["members"][0].ambient,
            ): (k, t)
            for k, t, sky_text in tasks
        }
        for fut in as_completed(futures):
            k, t = futures[fut]
            plans[k]["frames"][t] = fut.result()
            done += 1
            if progress:
                el = time.perf_counter() - start
                print(
                    f"\rbayesgloss render: {done}/{len(tasks)} frames, {el:.0f} s",
                    end="",
                    file=sys.stderr,
                    flush=True,
                )
            plan = plans[k]
            if all(f is not None for f in plan["frames"]):
                _write_group(plan, cache_dir, bundle_io)
                plan["frames"] = []  # free memory
    if progress and tasks:
        print(file=sys.stderr)
    return paths


def _write_group(plan, cache_dir: Path, bundle_io) -> None:
    facets = plan["facets"]
    n_pix = [len(r) for r in plan["rays"]]
    offsets = np.cumsum([0, *n_pix])
    for i, config in enumerate(plan["members"]):
        n = config.image_size
        labels = label_image(config, facets)
        present = np.isin(facets.ids, np.unique(labels[labels > 0]))
        frames = [
            f[offsets[i] : offsets[i + 1]].reshape(n, n, 3).astype(np.float32)
            for f in plan["frames"]
        ]
        times = config.frame_times()
        bundle_io.write_bundle(
            _bundle_dir(cache_dir, config),
            site={
                "latitude": config.latitude,
                "longitude": config.longitude,
                "elevation": config.elevation,
            },
            camera_position=config.camera_position(),
            pixel_encoding="linear-radiance",
            frames=frames,
            times=[t.isoformat() for t in times],
            facets=facets.subset(np.flatnonzero(present)),
            labels=labels,
            ground_reflectance=config.ground_reflectance,
            truth=config.truth(),
            frame_format="hdr",
        )

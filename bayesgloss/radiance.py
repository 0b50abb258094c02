"""Driving the real Radiance binaries shipped in the ``pyradiance`` wheel.

Scene descriptions are written as Radiance text; ``gensky``/``gendaylit``,
``oconv`` and ``rtrace`` run as subprocesses with ``RAYPATH`` pointing at the
wheel's library folder (``skybright.cal``, ``perezlum.cal``).

Radiance conventions met here: gensky's ``-ang`` azimuth is measured from
south, positive toward west; its ``-o`` longitude and ``-m`` meridian are
west-positive. ``rtrace`` samples with ``-u-`` (repeatable) by default here.
"""

from __future__ import annotations

import contextlib
import os
import re
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np

__all__ = [
    "binary",
    "run",
    "gensky_ang",
    "gendaylit_ang",
    "sky_glow",
    "material",
    "polygons",
    "oconv",
    "rtrace",
    "scratch_folder",
    "remove_orphan_scratch",
    "RTRACE_ACCURATE",
]

#: rtrace options for sky-lit facets: one ambient bounce reaches the sky glow,
#: no irradiance caching, dense stratified hemisphere sampling.
RTRACE_ACCURATE = (
    "-ab",
    "1",
    "-aa",
    "0",
    "-ad",
    "4096",
    "-as",
    "2048",
    "-lr",
    "6",
    "-lw",
    "1e-5",
    "-u-",
)


def _pyradiance_dir() -> Path:
    import pyradiance

    return Path(pyradiance.__file__).parent


def binary(name: str) -> str:
    """Path of a Radiance program from the pyradiance wheel."""
    path = _pyradiance_dir() / "bin" / name
    if not path.exists():
        raise FileNotFoundError(f"Radiance program {name!r} not found in {path.parent}")
    return str(path)


def _env() -> dict:
    env = dict(os.environ)
    lib = str(_pyradiance_dir() / "lib")
    env["RAYPATH"] = os.pathsep.join([".", lib] + ([env["RAYPATH"]] if "RAYPATH" in env else []))
    return env


def run(args, input: bytes | str | None = None, cwd=None) -> bytes:
    """Run a Radiance program; raise RuntimeError with its stderr on failure."""
    args = [binary(args[0]), *map(str, args[1:])]
    if isinstance(input, str):
        input = input.encode()
    proc = subprocess.run(args, input=input, capture_output=True, env=_env(), cwd=cwd)
    if proc.returncode != 0:
        raise RuntimeError(
            f"{Path(args[0]).name} failed ({proc.returncode}): {proc.stderr.decode().strip()}"
        )
    return proc.stdout


def gensky_ang(
    sun_direction,
    sky_type: str = "clear",
    *,
    sun: bool = True,
    ground_reflectance: float = 0.2,
    turbidity: float | None = None,
) -> str:
    """Radiance sky description from the real ``gensky -ang``.

    Parameters
    ----------
    sun_direction : array_like (3,)
        Unit vector toward the sun, world frame.
    sky_type : {"clear", "intermediate", "overcast", "uniform"}
    sun : bool
        Include the solar source (``+s``/``+i``) for clear and intermediate.
    ground_reflectance : float
        gensky's ``-g`` [-].
    turbidity : float, optional
        gensky's ``-t``.
    """
    altitude, azimuth_gensky = _gensky_angles(sun_direction)
    flag = {
        "clear": ("+s" if sun else "-s"),
        "intermediate": ("+i" if sun else "-i"),
        "overcast": "-c",
        "uniform": "-u",
    }
    if sky_type not in flag:
        raise ValueError(f"unknown gensky sky {sky_type!r}; valid: {', '.join(flag)}")
    args = [
        "gensky",
        "-ang",
        f"{altitude:.6f}",
        f"{azimuth_gensky:.6f}",
        flag[sky_type],
        "-g",
        ground_reflectance,
    ]
    if turbidity is not None:
        args += ["-t", turbidity]
    return run(args).decode()


def gendaylit_ang(
    sun_direction,
    direct_normal_irradiance: float,
    diffuse_horizontal_irradiance: float,
    *,
    ground_reflectance: float = 0.2,
) -> str:
    """Radiance Perez sky description from the real ``gendaylit -ang ... -W``.

    Parameters
    ----------
    sun_direction : array_like (3,)
    direct_normal_irradiance, diffuse_horizontal_irradiance : float
        Broadband irradiances [W m^-2].
    ground_reflectance : float
        gendaylit's ``-g`` [-].
    """
    altitude, azimuth_gensky = _gensky_angles(sun_direction)
    args = [
        "gendaylit",
        "-ang",
        f"{altitude:.6f}",
        f"{azimuth_gensky:.6f}",
        "-W",
        f"{direct_normal_irradiance:.6g}",
        f"{diffuse_horizontal_irradiance:.6g}",
        "-g",
        ground_reflectance,
    ]
    return run(args).decode()


def _gensky_angles(sun_direction) -> tuple[float, float]:
    """Solar altitude and gensky's azimuth (from south, west positive) [deg]."""
    s = np.asarray(sun_direction, dtype=float)
    altitude = np.degrees(np.arcsin(np.clip(s[2], -1, 1)))
    return float(altitude), float(np.degrees(np.arctan2(s[0], s[1])) - 180.0)


def sky_glow(ground: bool = True) -> str:
    """The glow hemispheres that show ``skyfunc`` as sky (and ground)."""
    text = "skyfunc glow skyglow\n0\n0\n4 1 1 1 0\n\nskyglow source sky\n0\n0\n4 0 0 1 180\n"
    if ground:
        text += "\nskyglow source ground\n0\n0\n4 0 0 -1 180\n"
    return text


def material(name: str, kind: str, colour, specularity: float, roughness: float) -> str:
    """A Radiance ``plastic`` or ``metal`` material."""
    if kind not in ("plastic", "metal"):
        raise ValueError(f"unknown material kind {kind!r}; valid: plastic, metal")
    rgb = np.broadcast_to(np.asarray(colour, dtype=float), (3,))
    return (
        f"void {kind} {name}\n0\n0\n5 {rgb[0]:.6g} {rgb[1]:.6g} {rgb[2]:.6g} "
        f"{specularity:.6g} {roughness:.6g}\n"
    )


def polygons(polys, modifiers, prefix: str = "facet") -> str:
    """Radiance ``polygon`` primitives, one per vertex array (V, 3)."""
    if isinstance(modifiers, str):
        modifiers = [modifiers] * len(polys)
    out = []
    for i, (poly, mod) in enumerate(zip(polys, modifiers, strict=True)):
        v = np.asarray(poly, dtype=float).ravel()
        coords = " ".join(f"{x:.9g}" for x in v)
        out.append(f"{mod} polygon {prefix}{i}\n0\n0\n{len(v)} {coords}\n")
    return "\n".join(out)


def oconv(scene: str, path: str | os.PathLike) -> Path:
    """Compile scene text into an octree at ``path``."""
    path = Path(path)
    path.write_bytes(run(["oconv", "-"], input=scene))
    return path


def rtrace(octree, origins, directions, options=RTRACE_ACCURATE) -> np.ndarray:
    """RGB radiance along rays, (N, 3) [W sr^-1 m^-2].

    Parameters
    ----------
    octree : path
    origins, directions : array_like (N, 3)
        Ray origins [m] and unit directions.
    options : sequence of str
        rtrace options (``-h- -ff -ov`` are added).
    """
    o = np.asarray(origins, dtype=np.float32).reshape(-1, 3)
    d = np.asarray(directions, dtype=np.float32).reshape(-1, 3)
    rays = np.concatenate([o, d], axis=1).astype(np.float32)
    out = run(["rtrace", "-h-", "-ff", "-ov", *options, str(octree)], input=rays.tobytes())
    return np.frombuffer(out, dtype=np.float32).reshape(-1, 3).astype(float)


#: Scratch folders in the temporary directory: ``bayesgloss-<kind>-<pid>-<random>``.
_SCRATCH = re.compile(r"bayesgloss-[a-z]+-(\d+)-")


def _running(pid: int) -> bool:
    """Whether a process ``pid`` exists (of any user)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's
        return True
    return True


def remove_orphan_scratch(folder=None) -> list[Path]:
    """Remove the scratch folders of processes that no longer run.

    A render killed with SIGKILL cannot remove its scratch folder (an octree
    of up to tens of MB); the next one does, here. Only this user's folders
    whose name carries a process id that no longer exists are removed.

    Returns
    -------
    list of Path
        The folders removed.
    """
    removed = []
    folder = Path(folder or tempfile.gettempdir())
    for path in folder.glob("bayesgloss-*-*-*"):
        match = _SCRATCH.match(path.name)
        if not match or not path.is_dir() or path.is_symlink():
            continue
        try:
            mine = path.stat().st_uid == os.getuid()
        except OSError:
            continue
        if mine and not _running(int(match.group(1))):
            shutil.rmtree(path, ignore_errors=True)
            removed.append(path)
    return removed


@contextlib.contextmanager
def scratch_folder(kind: str):
    """A temporary folder ``bayesgloss-<kind>-<pid>-...`` for Radiance's files,
    removed on exit; orphans of killed processes are removed on entry
    (:func:`remove_orphan_scratch`)."""
    remove_orphan_scratch()
    with tempfile.TemporaryDirectory(prefix=f"bayesgloss-{kind}-{os.getpid()}-") as tmp:
        yield tmp


def rtrace_scene(scene: str, origins, directions, options=RTRACE_ACCURATE) -> np.ndarray:
    """Compile ``scene`` in a temporary folder and trace rays through it."""
    with scratch_folder("rad") as tmp:
        octree = oconv(scene, Path(tmp) / "scene.oct")
        return rtrace(octree, origins, directions, options)

"""OpenCV's pinhole camera with lens distortion, read from a camera file.

The camera of :mod:`bayesgloss.capture` (``bayesgloss bundle make``).

The camera file
---------------
One JSON object, OpenCV's conventions throughout::

    {"width": 4000, "height": 3000,
     "fx": 3200.0, "fy": 3200.0, "cx": 1999.5, "cy": 1499.5,
     "distortion": [k1, k2, p1, p2, k3],
     "rotation": [[r11, r12, r13], [r21, r22, r23], [r31, r32, r33]],
     "position": [x, y, z]}

``width``, ``height``: the photos' size in pixels, as stored (EXIF
orientation is not applied). ``fx``, ``fy``, ``cx``, ``cy``: focal lengths and
principal point in pixels, in OpenCV's pixel coordinates: u to the right, v
down, the *centre* of the top-left pixel at (0, 0) (so the image's centre is
((width - 1) / 2, (height - 1) / 2)). ``distortion``: OpenCV's
``distCoeffs`` (k1, k2, p1, p2[, k3]), optional, default none; a point of
normalised coordinates (x, y) = (X_c / Z_c, Y_c / Z_c) is imaged at
u = fx x'' + cx, v = fy y'' + cy with (:func:`distort`)
x'' = x (1 + k1 r^2 + k2 r^4 + k3 r^6) + 2 p1 x y + p2 (r^2 + 2 x^2),
y'' = y (1 + k1 r^2 + k2 r^4 + k3 r^6) + p1 (r^2 + 2 y^2) + 2 p2 x y,
r^2 = x^2 + y^2 (Brown 1966, as ``cv::projectPoints``). ``rotation``:
OpenCV's R, world to camera, as a 3 x 3 matrix or a Rodrigues vector
(``rvec``); its rows are the camera's axes in the world frame (x east, y
north, z up): x to the right of the image, y down it, z along the optical
axis. ``position``: the camera's centre C in the world frame [m]; or,
instead, ``translation``: OpenCV's ``tvec`` t, with C = -R^T t. A world point
X is then at X_c = R (X - C) in the camera.

:class:`CaptureError`, the error of every bad input of a capture (this
file, the mesh, the photos), lives here, the lowest of the capture modules,
so that :mod:`bayesgloss.exif` and :mod:`bayesgloss.capture` raise it
without importing each other.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "Camera",
    "CaptureError",
    "distort",
    "undistort",
    "read_camera",
    "read_colmap",
    "transform_camera",
    "COLMAP_MODELS",
    "camera_rays",
    "project",
]


class CaptureError(ValueError):
    """Bad input of :func:`bayesgloss.capture.make_bundle`: names the file, the
    field and the problem.

    Attributes
    ----------
    kind : str
        What the file is: "mesh", "camera", "photo", "photos", "bundle" (the
        output folder), "site" or "transform" (a command-line value).
    file : str
    field : str
        The file's field (``"fx"``, ``"DateTimeOriginal"``) or part.
    problem : str
    """

    def __init__(self, kind: str, file: Any, field: str, problem: str):
        self.kind, self.file, self.field, self.problem = kind, str(file), field, problem
        super().__init__(f"{kind} '{self.file}': field '{field}': {problem}")

    def __reduce__(self):
        return (type(self), (self.kind, self.file, self.field, self.problem))


@dataclass(frozen=True)
class Camera:
    """OpenCV's pinhole camera with distortion (see the module docstring).

    Attributes
    ----------
    width, height : int
        Image size [pixels].
    fx, fy, cx, cy : float
        Focal lengths and principal point, OpenCV pixel coordinates [pixels].
    distortion : ndarray (5,)
        k1, k2, p1, p2, k3 [-].
    rotation : ndarray (3, 3)
        World to camera (OpenCV's R) [-].
    position : ndarray (3,)
        Centre of projection, world frame [m].
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    distortion: np.ndarray
    rotation: np.ndarray
    position: np.ndarray


def distort(xy: np.ndarray, distortion: Sequence[float]) -> np.ndarray:
    """OpenCV's lens distortion of normalised image coordinates.

    Brown-Conrady radial (k1, k2, k3) and tangential (p1, p2) terms, as
    ``cv::projectPoints`` applies them (module docstring).

    Parameters
    ----------
    xy : ndarray (..., 2)
        Undistorted normalised coordinates (X_c / Z_c, Y_c / Z_c) [-].
    distortion : sequence of 4 or 5 float
        k1, k2, p1, p2[, k3] [-].

    Returns
    -------
    ndarray (..., 2)
        Distorted normalised coordinates [-].
    """
    k1, k2, p1, p2, k3 = _coefficients(distortion)
    x, y = np.asarray(xy, dtype=float)[..., 0], np.asarray(xy, dtype=float)[..., 1]
    r2 = x * x + y * y
    radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return np.stack([xd, yd], axis=-1)


def undistort(
    xy: np.ndarray, distortion: Sequence[float], tol: float = 1e-12, max_iter: int = 50
) -> np.ndarray:
    """Invert :func:`distort` by Newton's method, point by point (vectorised).

    Parameters
    ----------
    xy : ndarray (..., 2)
        Distorted normalised coordinates [-].
    distortion : sequence of 4 or 5 float
        k1, k2, p1, p2[, k3] [-].
    tol : float
        Largest residual |distort(x) - xy| accepted [-].
    max_iter : int
        Newton steps at most [-].

    Returns
    -------
    ndarray (..., 2)
        Undistorted normalised coordinates; NaN where Newton's method did not
        reach ``tol``, or reached a root past the model's fold (radial factor
        <= 0 or Jacobian determinant <= 0): points beyond where the model is
        invertible [-].
    """
    target = np.asarray(xy, dtype=float)
    k1, k2, p1, p2, k3 = _coefficients(distortion)
    if not any((k1, k2, p1, p2, k3)):
        return target.copy()
    x, y = target[..., 0].copy(), target[..., 1].copy()
    for _ in range(max_iter):
        r2 = x * x + y * y
        radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
        slope = k1 + r2 * (2 * k2 + 3 * k3 * r2)  # d radial / d r^2
        ex = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x) - target[..., 0]
        ey = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y - target[..., 1]
        if np.nanmax(np.abs(np.concatenate([np.ravel(ex), np.ravel(ey)])), initial=0) < tol:
            break
        a = radial + 2 * x * x * slope + 2 * p1 * y + 6 * p2 * x  # d xd / dx
        b = 2 * x * y * slope + 2 * p1 * x + 2 * p2 * y  # d xd / dy = d yd / dx
        d = radial + 2 * y * y * slope + 6 * p1 * y + 2 * p2 * x  # d yd / dy
        det = a * d - b * b
        with np.errstate(divide="ignore", invalid="ignore"):
            x, y = x - (d * ex - b * ey) / det, y - (a * ey - b * ex) / det
    residual = np.hypot(*np.moveaxis(distort(np.stack([x, y], -1), distortion) - target, -1, 0))
    bad = ~(residual < max(tol, 1e-9))
    # a root past the fold of the lens model is not the ray: there the radial
    # factor is <= 0 (the point mapped through the centre) or the map's Jacobian
    # is not positive (it turns back on itself)
    r2 = x * x + y * y
    radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    slope = k1 + r2 * (2 * k2 + 3 * k3 * r2)
    a = radial + 2 * x * x * slope + 2 * p1 * y + 6 * p2 * x
    b = 2 * x * y * slope + 2 * p1 * x + 2 * p2 * y
    d = radial + 2 * y * y * slope + 6 * p1 * y + 2 * p2 * x
    with np.errstate(invalid="ignore"):
        bad |= ~((radial > 0) & (a * d - b * b > 0))
    x, y = np.where(bad, np.nan, x), np.where(bad, np.nan, y)
    return np.stack([x, y], axis=-1)


def _coefficients(distortion) -> tuple[float, ...]:
    d = [float(v) for v in distortion]
    if len(d) not in (4, 5):
        raise ValueError(f"distortion needs k1, k2, p1, p2[, k3], got {len(d)} values")
    return (*d, 0.0) if len(d) == 4 else tuple(d)


def _rodrigues(rvec: np.ndarray) -> np.ndarray:
    """Rotation matrix of a rotation vector (axis x angle, rad), as cv::Rodrigues."""
    theta = float(np.linalg.norm(rvec))
    if theta < 1e-15:
        return np.eye(3)
    k = rvec / theta
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(theta) * kx + (1 - math.cos(theta)) * (kx @ kx)


def read_camera(path: str | os.PathLike) -> Camera:
    """Read a camera file (JSON; the module docstring gives its fields).

    Raises
    ------
    CaptureError
        For a file that is not a JSON object, a missing field, a value of the
        wrong form (a rotation that is not a proper rotation within 1e-6,
        focal lengths or an image size that are not positive).
    """

    def fail(field: str, problem: str) -> CaptureError:
        return CaptureError("camera", path, field, problem)

    try:
        data = json.loads(Path(path).read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise fail("file", "no such file") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise fail("file", f"not a readable JSON file: {err}") from None
    if not isinstance(data, dict):
        raise fail("file", f"must be a JSON object, got {type(data).__name__}")

    def number(key: str, positive: bool = False) -> float:
        if key not in data:
            raise fail(key, "missing required field")
        value = data[key]
        if (
            isinstance(value, bool)
            or not isinstance(value, int | float)
            or not math.isfinite(value)
        ):
            raise fail(key, f"must be a finite number, got {value!r}")
        if positive and not value > 0:
            raise fail(key, f"must be > 0, got {value!r}")
        return float(value)

    def array(key: str, shapes: tuple) -> np.ndarray:
        try:
            value = np.asarray(data[key], dtype=float)
        except (TypeError, ValueError):
            raise fail(key, f"must be numbers, got {data[key]!r}") from None
        if value.shape not in shapes or not np.all(np.isfinite(value)):
            raise fail(key, f"must be {' or '.join(_shape(s) for s in shapes)}, got {data[key]!r}")
        return value

    size = {}
    for key in ("width", "height"):
        value = number(key, positive=True)
        if not value.is_integer():
            raise fail(key, f"must be a whole number of pixels, got {data[key]!r}")
        size[key] = int(value)
    intrinsics = {k: number(k, positive=k in ("fx", "fy")) for k in ("fx", "fy", "cx", "cy")}
    distortion = np.zeros(5)
    if data.get("distortion") is not None:
        given = array("distortion", ((4,), (5,)))
        distortion[: len(given)] = given
    if "rotation" not in data:
        raise fail("rotation", "missing required field")
    rotation = array("rotation", ((3, 3), (3,)))
    if rotation.shape == (3,):
        rotation = _rodrigues(rotation)
    if not (
        np.allclose(rotation @ rotation.T, np.eye(3), atol=1e-6) and np.linalg.det(rotation) > 0
    ):
        raise fail("rotation", "is not a rotation (R R^T = I and det R = +1 within 1e-6)")
    if ("position" in data) == ("translation" in data):
        raise fail("position", "give exactly one of position (C) or translation (t = -R C)")
    if "position" in data:
        position = array("position", ((3,),))
    else:
        position = -rotation.T @ array("translation", ((3,),))
    return Camera(
        size["width"], size["height"], **intrinsics, distortion=distortion,
        rotation=rotation, position=position,
    )  # fmt: skip


def _shape(shape: tuple) -> str:
    return {(3, 3): "a 3 x 3 matrix", (3,): "3 numbers"}.get(shape, f"{shape[0]} numbers")


#: COLMAP's camera models this module reads: id, name, parameter names.
COLMAP_MODELS = {
    0: ("SIMPLE_PINHOLE", ("f", "cx", "cy")),
    1: ("PINHOLE", ("fx", "fy", "cx", "cy")),
    2: ("SIMPLE_RADIAL", ("f", "cx", "cy", "k1")),
    3: ("RADIAL", ("f", "cx", "cy", "k1", "k2")),
    4: ("OPENCV", ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2")),
    6: ("FULL_OPENCV", ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6")),
}
#: Parameter counts of COLMAP's other models (fisheye and others), to skip them in a binary file.
_COLMAP_OTHER = {5: 8, 7: 5, 8: 4, 9: 5, 10: 12, 11: 5, 12: 13}


def read_colmap(folder: str | os.PathLike, image_names: Sequence[str]) -> Camera:
    """The camera of a COLMAP sparse model (``cameras`` and ``images``, .bin or .txt).

    The pose is that of the first of ``image_names`` the model holds (a static
    camera: its images' poses agree). COLMAP's pose is OpenCV's (world to
    camera, qvec = (w, x, y, z), t), in the reconstruction's frame: give the
    transform into the world frame with the mesh's (both are in that frame).
    COLMAP puts the centre of the top-left pixel at (0.5, 0.5): cx and cy are
    moved by -0.5 to OpenCV's convention. Models SIMPLE_PINHOLE, PINHOLE,
    SIMPLE_RADIAL, RADIAL, OPENCV and FULL_OPENCV (with k4 = k5 = k6 = 0).

    Parameters
    ----------
    folder : str or path-like
        The model's folder (``sparse/0``). -
    image_names : sequence of str
        Photo file names, matched against the model's image names (their
        last path component). -

    Raises
    ------
    CaptureError
        Missing files, no image of those names, an unsupported camera model.
    """
    import struct

    folder = Path(folder)

    def fail(field: str, problem: str) -> CaptureError:
        return CaptureError("camera", folder, field, problem)

    binary = (folder / "cameras.bin").is_file() and (folder / "images.bin").is_file()
    if not binary and not (
        (folder / "cameras.txt").is_file() and (folder / "images.txt").is_file()
    ):
        raise fail("file", "not a COLMAP model: needs cameras.bin and images.bin (or .txt)")
    cameras, images = {}, {}
    try:
        if binary:
            data = (folder / "cameras.bin").read_bytes()
            (count,), at = struct.unpack_from("<Q", data), 8
            for _ in range(count):
                cam_id, model, width, height = struct.unpack_from("<iiQQ", data, at)
                at += 24
                n = len(COLMAP_MODELS[model][1]) if model in COLMAP_MODELS else _COLMAP_OTHER[model]
                cameras[cam_id] = (model, width, height, struct.unpack_from(f"<{n}d", data, at))
                at += 8 * n
            data = (folder / "images.bin").read_bytes()
            (count,), at = struct.unpack_from("<Q", data), 8
            for _ in range(count):
                _, *pose, cam_id = struct.unpack_from("<i7di", data, at)
                at += 64
                end = data.index(b"\0", at)
                name, at = data[at:end].decode(), end + 1
                (n_points,) = struct.unpack_from("<Q", data, at)
                at += 8 + 24 * n_points
                images[Path(name).name] = (pose, cam_id)
        else:
            names = {v[0]: k for k, v in COLMAP_MODELS.items()}
            for line in (folder / "cameras.txt").read_text().splitlines():
                if line.strip() and not line.startswith("#"):
                    cam_id, model, width, height, *params = line.split()
                    model_id = names.get(model, -1)
                    cameras[int(cam_id)] = (model_id, int(width), int(height),
                                            tuple(map(float, params)))  # fmt: skip
            lines = [x for x in (folder / "images.txt").read_text().splitlines()
                     if not x.startswith("#")]  # fmt: skip
            for line in lines[::2]:  # each image's line, then its points' (maybe empty)
                _, *pose, cam_id, name = line.split(maxsplit=9)
                images[Path(name).name] = (tuple(map(float, pose)), int(cam_id))
    except (struct.error, KeyError, ValueError, IndexError, UnicodeDecodeError) as err:
        raise fail("file", f"cannot read the COLMAP model: {type(err).__name__}: {err}") from None
    found = [n for n in image_names if Path(n).name in images]
    if not found:
        raise fail("images", f"holds none of the photos (e.g. '{image_names[0]}')")
    pose, cam_id = images[Path(found[0]).name]
    if cam_id not in cameras:
        raise fail("cameras", f"no camera {cam_id}, which image '{found[0]}' names")
    model, width, height, params = cameras[cam_id]
    if model not in COLMAP_MODELS:
        raise fail("cameras", f"camera {cam_id}'s model is not one of "
                   + ", ".join(m for m, _ in COLMAP_MODELS.values()))  # fmt: skip
    name, keys = COLMAP_MODELS[model]
    values = dict(zip(keys, params, strict=True))
    if any(values.get(k, 0.0) for k in ("k4", "k5", "k6")):
        raise fail("cameras", f"camera {cam_id} ({name}) has k4-k6 (rational distortion)")
    fx, fy = values.get("fx", values.get("f")), values.get("fy", values.get("f"))
    distortion = np.array([values.get(k, 0.0) for k in ("k1", "k2", "p1", "p2", "k3")])
    qw, qx, qy, qz, *t = pose
    q = np.array([qw, qx, qy, qz]) / np.linalg.norm([qw, qx, qy, qz])
    w, x, y, z = q
    rotation = np.array([  # unit quaternion to rotation matrix
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])  # fmt: skip
    return Camera(
        int(width), int(height), float(fx), float(fy),
        values["cx"] - 0.5, values["cy"] - 0.5,  # COLMAP's pixel centres at +0.5
        distortion=distortion, rotation=rotation, position=-rotation.T @ np.asarray(t),
    )  # fmt: skip


def transform_camera(camera: Camera, transform: np.ndarray) -> Camera:
    """The same camera in another frame, by a similarity transform (scale, turn, shift).

    Parameters
    ----------
    camera : Camera
    transform : ndarray (4, 4)
        New = M @ old (homogeneous); its 3 x 3 part s Q, Q a rotation, s > 0 [-].

    Raises
    ------
    ValueError
        For a transform that is not a similarity (a camera's angles would change).
    """
    m = np.asarray(transform, dtype=float)
    linear = m[:3, :3]
    scale = np.cbrt(np.linalg.det(linear))
    turn = linear / scale if scale > 0 else linear
    if not (scale > 0 and np.allclose(turn @ turn.T, np.eye(3), atol=1e-6)):
        raise ValueError("a camera moves only by a similarity transform (scale, rotation, shift)")
    return Camera(
        camera.width, camera.height, camera.fx, camera.fy, camera.cx, camera.cy,
        distortion=camera.distortion, rotation=camera.rotation @ turn.T,
        position=linear @ camera.position + m[:3, 3],
    )  # fmt: skip


def camera_rays(camera: Camera, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Unit world directions of the rays that image at pixel coordinates (u, v).

    Parameters
    ----------
    camera : Camera
    u, v : ndarray
        OpenCV pixel coordinates, broadcast together [pixels].

    Returns
    -------
    ndarray (..., 3)
        Unit vectors from the camera's centre, world frame; NaN where the
        distortion cannot be inverted [-].
    """
    xd = (np.asarray(u, dtype=float) - camera.cx) / camera.fx
    yd = (np.asarray(v, dtype=float) - camera.cy) / camera.fy
    xy = undistort(np.stack(np.broadcast_arrays(xd, yd), axis=-1), camera.distortion)
    d_cam = np.concatenate([xy, np.ones(xy.shape[:-1] + (1,))], axis=-1)
    d = d_cam @ camera.rotation  # R^T d_cam, on the last axis
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def project(camera: Camera, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixel coordinates (u, v) of world points, and whether each is in front.

    Parameters
    ----------
    camera : Camera
    points : ndarray (..., 3)
        World points [m].

    Returns
    -------
    uv : ndarray (..., 2)
        OpenCV pixel coordinates [pixels].
    in_front : ndarray (...) of bool
        Z_c > 0.
    """
    pc = (np.asarray(points, dtype=float) - camera.position) @ camera.rotation.T
    z = pc[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        xy = pc[..., :2] / z[..., None]
    xyd = distort(xy, camera.distortion)
    uv = np.stack([camera.fx * xyd[..., 0] + camera.cx, camera.fy * xyd[..., 1] + camera.cy], -1)
    return uv, z > 0

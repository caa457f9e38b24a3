"""nerfstudio / instant-ngp / Blender ``transforms.json`` camera files.

Conventions read:

- Intrinsics at the top level (``fl_x``, ``fl_y``, ``cx``, ``cy``, ``w``, ``h``,
  ``camera_model``, ``k1``..``k4``, ``p1``, ``p2``), each overridable per frame.
- Blender style: without ``fl_x``, ``fl_x = 0.5 · w / tan(camera_angle_x / 2)`` (and
  ``fl_y`` from ``camera_angle_y`` likewise, else ``fl_y = fl_x``); ``cx``/``cy`` default to
  the image centre ``w/2``, ``h/2``.
- Without ``w``/``h``, the size of the **first frame's image** is read (``file_path``
  relative to the JSON's folder; ``.png``/``.jpg`` appended when the path has no
  extension, as in the Blender synthetic scenes).
- ``camera_model``: ``OPENCV`` (the nerfstudio default), ``PINHOLE`` or ``OPENCV_FISHEYE``
  (→ :class:`FisheyeLens` with ``max_theta`` = π/2 unless given). Non-zero OPENCV
  distortion follows the same policy as :func:`~spacedg.scene.io.colmap.read_colmap`:
  ``opencv_distortion="error"`` refuses it, ``"drop"`` renders an ideal pinhole and warns.
- ``transform_matrix`` is camera-to-world with **OpenGL** camera axes (x right, y up,
  z backwards); spacedg's OpenCV pose is ``c2w @ diag(1, −1, −1, 1)``. It must be rigid.
- Poses are taken in the file's own world frame. ``applied_transform`` (nerfstudio's record
  of how it moved the COLMAP world: ``p_json = A · p_colmap``, 3×4) is **not** applied by
  :func:`read_transforms`; :func:`read_applied_transform` returns it for the importer.
- ``frames`` **and** ``test_frames`` (ScanNet++'s held-out views, one in eight) are read, in
  that order; a ``file_path`` in both is an error.
- The view name is ``file_path`` exactly as written.

splatfacto (``ns-train splatfacto``) trains in a normalised frame and writes
``dataparser_transforms.json`` = ``{"transform": 3×4, "scale": s}`` with
``p_norm = s · (T · [p_json; 1])``; ``ns-export gaussian-splat`` writes the Gaussians in that
normalised frame. :func:`read_dataparser_transforms` reads it, and
:func:`~spacedg.scene.io.nerfstudio.denormalising_similarity` gives the similarity that takes
normalised points back to the ``transforms.json`` frame.
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path
from typing import Any, Literal

import numpy as np

from spacedg._checks import require_homogeneous
from spacedg.errors import FileFormatError, InvalidDataError
from spacedg.files import FileValueError, PathLike, as_path, read_json
from spacedg.render.camera import Camera, FisheyeLens
from spacedg.scene.io.colmap import DEFAULT_FISHEYE_MAX_THETA
from spacedg.scene.io.fields import named_record

_INTRINSIC_KEYS = (
    "fl_x", "fl_y", "cx", "cy", "w", "h", "camera_model", "camera_angle_x", "camera_angle_y",
    "k1", "k2", "k3", "k4", "p1", "p2",
)
_MODELS = ("OPENCV", "PINHOLE", "OPENCV_FISHEYE")
_GL_TO_CV = np.diag([1.0, -1.0, -1.0, 1.0])
#: Largest |RᵀR − I| accepted for a transform_matrix rotation (larger: scaled or sheared).
RIGID_TOL = 1e-4
_IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".PNG", ".JPG", ".JPEG")


def _number(where: str, key: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise FileFormatError(f"{where}: '{key}' must be a number, got {value!r}")
    out = float(value)
    if not math.isfinite(out):
        raise FileValueError(f"{where}: '{key}' is {value!r}; it must be a finite number")
    return out


def _size(where: str, key: str, value: Any) -> int:
    out = _number(where, key, value)
    if out != int(out) or out < 1:
        raise FileValueError(f"{where}: '{key}' must be a positive whole number of pixels, got {value!r}")
    return int(out)


def _image_size(folder: Path, file_path: str, where: str) -> tuple[int, int]:
    import cv2

    if not isinstance(file_path, str) or not file_path:
        raise FileFormatError(f"{where}: the JSON gives no image size ('w', 'h') and frames[0] has no usable 'file_path'")
    base = folder / file_path
    candidates = [base] if base.suffix else [base, *(base.with_name(base.name + s) for s in _IMAGE_SUFFIXES)]
    for candidate in candidates:
        if candidate.is_file():
            image = cv2.imread(str(candidate), cv2.IMREAD_UNCHANGED)
            if image is None:
                raise FileFormatError(f"{where}: cannot decode image {candidate} to learn the image size; add 'w' and 'h' to the JSON")
            return int(image.shape[1]), int(image.shape[0])
    raise FileFormatError(
        f"{where}: the JSON gives no image size ('w', 'h') and the first frame's image {base} was not found; "
        "add 'w' and 'h' (pixels) at the top level"
    )


def _as_4x4(where: str, key: str, value: Any) -> np.ndarray:
    """The JSON field ``key``: a 4×4 float64 matrix (a 3×4 one gets the row ``0 0 0 1``)."""
    try:
        matrix = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise FileFormatError(f"{where}: '{key}' must be a 4×4 (or 3×4) list of numbers") from None
    if matrix.shape == (3, 4):
        matrix = np.vstack([matrix, [0.0, 0.0, 0.0, 1.0]])
    if matrix.shape != (4, 4):
        raise FileFormatError(f"{where}: '{key}' must be 4×4 (or 3×4), got shape {matrix.shape}")
    return matrix


def _pose(where: str, value: Any) -> np.ndarray:
    matrix = _as_4x4(where, "transform_matrix", value)
    require_homogeneous(matrix, f"{where}: 'transform_matrix'", FileValueError)
    rot = matrix[:3, :3]
    err = float(np.abs(rot.T @ rot - np.eye(3)).max())
    if err > RIGID_TOL:
        raise FileValueError(
            f"{where}: 'transform_matrix' is not rigid (max |RᵀR − I| = {err:.3g}); it holds a scale or shear. "
            "Export camera-to-world poses without scaling (scale the scene with scene_from_files(scale=...) instead)"
        )
    if np.linalg.det(rot) < 0:
        raise FileValueError(f"{where}: 'transform_matrix' rotation is a reflection (det < 0)")
    if err > 1e-9:  # re-orthonormalise the rounding noise of printed matrices
        u, _, vt = np.linalg.svd(rot)
        matrix[:3, :3] = u @ vt
    return matrix @ _GL_TO_CV



def _focal(where: str, params: dict[str, Any], axis: str, size: int) -> float | None:
    """Focal length in pixels along ``axis`` from ``fl_<axis>`` or ``camera_angle_<axis>`` (radians), else None."""
    if f"fl_{axis}" in params:
        return _number(where, f"fl_{axis}", params[f"fl_{axis}"])
    key = f"camera_angle_{axis}"
    if key not in params:
        return None
    angle = _number(where, key, params[key])
    if not 0.0 < angle < math.pi:
        raise FileValueError(f"{where}: {key} must be in (0, π) radians, got {angle}")
    return 0.5 * size / math.tan(0.5 * angle)

def _camera(
    where: str, params: dict[str, Any], pose: np.ndarray, size: tuple[int, int], max_theta: float
) -> tuple[Camera, bool]:
    w = _size(where, "w", params["w"]) if "w" in params else size[0]
    h = _size(where, "h", params["h"]) if "h" in params else size[1]
    model = params.get("camera_model", "OPENCV")
    if model not in _MODELS:
        raise FileFormatError(f"{where}: camera_model {model!r} is not supported (supported: {', '.join(_MODELS)})")
    fx = _focal(where, params, "x", w)
    if fx is None:
        raise FileFormatError(f"{where}: no focal length: give 'fl_x' (pixels) or 'camera_angle_x' (radians)")
    fy = _focal(where, params, "y", h)
    if fy is None:
        fy = fx
    cx = _number(where, "cx", params["cx"]) if "cx" in params else w / 2.0
    cy = _number(where, "cy", params["cy"]) if "cy" in params else h / 2.0
    dist = {k: _number(where, k, params[k]) for k in ("k1", "k2", "k3", "k4", "p1", "p2") if k in params}
    lens = None
    distorted = False
    if model == "OPENCV_FISHEYE":
        lens = FisheyeLens(dist.get("k1", 0.0), dist.get("k2", 0.0), dist.get("k3", 0.0), dist.get("k4", 0.0), max_theta)
    else:
        distorted = any(v != 0.0 for v in dist.values())
    try:
        return Camera(fx, fy, cx, cy, w, h, pose, lens), distorted
    except InvalidDataError as err:
        raise FileValueError(f"{where}: {err}") from err


def read_transforms(
    path: PathLike,
    *,
    opencv_distortion: Literal["error", "drop"] = "error",
    fisheye_max_theta: float = DEFAULT_FISHEYE_MAX_THETA,
    include_test_frames: bool = True,
) -> dict[str, Camera]:
    """Read a ``transforms.json`` into cameras keyed by ``file_path`` (``frames`` then ``test_frames``).

    Args:
        path: the JSON file.
        opencv_distortion: ``"error"`` or ``"drop"`` (see the module docstring).
        fisheye_max_theta: ``max_theta`` (radians) of ``OPENCV_FISHEYE`` lenses.
        include_test_frames: also read ``test_frames`` (ScanNet++), default True.

    Raises:
        FileFormatError: not JSON, missing ``frames``/``file_path``/``transform_matrix``/
            focal length/size, unknown camera model, distortion (with ``"error"``),
            duplicate names; :class:`FileValueError` for NaN or non-rigid poses.
    """
    if opencv_distortion not in ("error", "drop"):
        raise InvalidDataError(f"read_transforms: opencv_distortion must be 'error' or 'drop', got {opencv_distortion!r}")
    p = as_path(path, "transforms.json")
    data = read_json(p, "transforms.json")
    if not isinstance(data, dict):
        raise FileFormatError(f"{p}: expected a JSON object with 'frames', got a {type(data).__name__}")
    frames = data.get("frames")
    if not isinstance(frames, list) or not frames:
        raise FileFormatError(f"{p}: 'frames' must be a non-empty list of frames (each with 'file_path' and 'transform_matrix')")
    test_frames = data.get("test_frames", []) if include_test_frames else []
    if not isinstance(test_frames, list):
        raise FileFormatError(f"{p}: 'test_frames' must be a list of frames like 'frames', got {type(test_frames).__name__}")
    listed = [("frames", i, f) for i, f in enumerate(frames)] + [("test_frames", i, f) for i, f in enumerate(test_frames)]
    top = {k: data[k] for k in _INTRINSIC_KEYS if k in data}
    size: tuple[int, int] | None = None
    out: dict[str, Camera] = {}
    dropped: list[str] = []
    for key, index, frame in listed:
        name, where = named_record(f"{p}: {key}[{index}]", frame, "file_path", ("file_path", "transform_matrix"), out,
                                   "a frame has 'file_path' and 'transform_matrix'")
        params = {**top, **{k: frame[k] for k in _INTRINSIC_KEYS if k in frame}}
        if ("w" not in params or "h" not in params) and size is None:
            size = _image_size(p.parent, frames[0].get("file_path"), where)
        camera, distorted = _camera(where, params, _pose(where, frame["transform_matrix"]), size or (0, 0), fisheye_max_theta)
        if distorted:
            if opencv_distortion == "error":
                raise FileFormatError(
                    f"{where}: non-zero OPENCV distortion (k1..k4, p1, p2); spacedg renders pinhole and equidistant-fisheye "
                    "lenses only: undistort the images first, or pass opencv_distortion='drop' to render ideal pinholes"
                )
            dropped.append(name)
        out[name] = camera
    if dropped:
        warnings.warn(
            f"{p}: lens distortion ignored for {len(dropped)} view(s) (opencv_distortion='drop'), e.g. {dropped[:3]}; "
            "they render as ideal pinholes and will not match the photos exactly",
            stacklevel=2,
        )
    return out


def _rows34(where: str, key: str, value: Any) -> np.ndarray:
    matrix = _as_4x4(where, key, value)
    if not np.isfinite(matrix).all():
        raise FileFormatError(f"{where}: '{key}' must be finite numbers")
    rot = matrix[:3, :3]
    if float(np.abs(rot.T @ rot - np.eye(3)).max()) > RIGID_TOL or np.linalg.det(rot) < 0:
        raise FileValueError(f"{where}: '{key}' rotation part is not a rotation (scaled, sheared or reflected)")
    return matrix


def read_applied_transform(path: PathLike) -> np.ndarray | None:
    """nerfstudio's ``applied_transform`` of a ``transforms.json`` as a 4×4 (``p_json = A · p_colmap``),
    or ``None`` when the file has none."""
    p = as_path(path, "transforms.json")
    data = read_json(p, "transforms.json")
    if not isinstance(data, dict) or "applied_transform" not in data:
        return None
    return _rows34(str(p), "applied_transform", data["applied_transform"])


def read_dataparser_transforms(path: PathLike) -> tuple[np.ndarray, float]:
    """splatfacto's ``dataparser_transforms.json``: ``(T 4×4 rigid, s)`` with ``p_norm = s · T · p``.

    Raises:
        FileFormatError: missing ``transform`` / ``scale`` or malformed values.
    """
    p = as_path(path, "dataparser_transforms.json")
    data = read_json(p, "dataparser_transforms.json")
    if not isinstance(data, dict) or "transform" not in data or "scale" not in data:
        raise FileFormatError(f"{p}: expected {{'transform': 3×4, 'scale': number}} (nerfstudio's dataparser_transforms.json)")
    scale = _number(str(p), "scale", data["scale"])
    if scale <= 0:
        raise FileValueError(f"{p}: 'scale' must be positive, got {scale}")
    return _rows34(str(p), "transform", data["transform"]), scale


def denormalising_similarity(transform: np.ndarray, scale: float) -> tuple[np.ndarray, np.ndarray, float]:
    """``(R, t, k)`` with ``p = k · R p_norm + t`` undoing ``p_norm = scale · (transform · p)``."""
    rot = transform[:3, :3]
    return rot.T, -rot.T @ transform[:3, 3], 1.0 / scale

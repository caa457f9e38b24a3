"""INRIA 3D Gaussian Splatting output folders (``train.py -m OUT``): what they hold, read once.

Layout written by the original code (and by gsplat's / PGSR's copies of it)::

    OUT/
      cfg_args                                 repr of the argparse Namespace: source_path, images, ...
      cameras.json                             every train + test camera (below)
      point_cloud/iteration_<N>/point_cloud.ply  the Gaussians after N iterations (INRIA .ply)
      input.ply                                the COLMAP points it started from (not Gaussians)

``cameras.json`` is a JSON list of ``{id, img_name, width, height, position, rotation, fx, fy}``:

- ``position``: camera centre in the world frame (the COLMAP frame the model was trained in).
- ``rotation``: 3×3 rows of the **camera-to-world** rotation with OpenCV camera axes (x right,
  y down, z forward): the INRIA writer inverts its world-to-camera matrix ``[Rᵀ | T]``.
- ``fx``, ``fy``: focal lengths in pixels at ``width × height`` (the training resolution,
  possibly downscaled); the principal point is not stored: the image centre is assumed.
- ``img_name``: the image file name **without extension** (the view name spacedg uses).

``cfg_args`` is read without evaluating it (:func:`read_cfg_args` parses the Namespace call
with :mod:`ast` and accepts only literals).
"""

from __future__ import annotations

import ast
import math
import re
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from spacedg.errors import FileFormatError, InvalidDataError
from spacedg.files import FileValueError, PathLike, as_path, read_json
from spacedg.render.camera import Camera
from spacedg.scene.io.fields import matrix_field, named_record

__all__ = ["read_inria_cameras", "read_cfg_args", "latest_point_cloud", "is_inria_output", "training_width", "at_training_scale"]

_ITERATION = re.compile(r"^iteration_(\d+)$")
#: Largest |RᵀR − I| accepted for a cameras.json rotation.
RIGID_TOL = 1e-4


def is_inria_output(folder: Path) -> bool:
    """Whether ``folder`` looks like an INRIA output folder (a ``point_cloud/iteration_*`` ply)."""
    return folder.is_dir() and any((folder / "point_cloud").glob("iteration_*/point_cloud.ply"))


def latest_point_cloud(folder: PathLike) -> Path:
    """``point_cloud/iteration_<N>/point_cloud.ply`` with the largest ``N`` (numeric, not lexical)."""
    root = as_path(folder, "INRIA output folder")
    found = []
    for ply in (root / "point_cloud").glob("iteration_*/point_cloud.ply"):
        match = _ITERATION.match(ply.parent.name)
        if match:
            found.append((int(match.group(1)), ply))
    if not found:
        raise FileFormatError(
            f"{root}: no point_cloud/iteration_<N>/point_cloud.ply; is this the folder passed to the INRIA train.py -m?"
        )
    return max(found)[1]


def read_cfg_args(path: PathLike) -> dict[str, Any]:
    """The keyword arguments of the ``Namespace(...)`` written to ``cfg_args`` (literals only).

    Raises:
        FileFormatError: not a ``Namespace(key=literal, ...)`` expression.
    """
    p = as_path(path, "cfg_args")
    try:
        text = p.read_text(encoding="utf-8")
        tree = ast.parse(text.strip(), mode="eval")
    except (OSError, UnicodeDecodeError, SyntaxError) as err:
        raise FileFormatError(f"{p}: cannot read cfg_args as a Namespace(...) repr ({err})") from None
    call = tree.body
    if not isinstance(call, ast.Call) or getattr(call.func, "id", None) != "Namespace":
        raise FileFormatError(f"{p}: expected 'Namespace(key=value, ...)', got {text[:60]!r}")
    out: dict[str, Any] = {}
    for keyword in call.keywords:
        if keyword.arg is None:
            continue
        try:
            out[keyword.arg] = ast.literal_eval(keyword.value)
        except ValueError:
            out[keyword.arg] = None  # not a literal (never evaluated)
    return out


_IMAGES_FACTOR = re.compile(r"(?:^|[/\\])images_(\d+)[/\\]?$")


def training_width(width: int, resolution: Any, images: Any = None) -> int:
    """The width (px) INRIA 3DGS trained on for a camera ``width`` px wide, from ``cfg_args``:
    ``images`` (``-i``) ``images_N`` loads the images downscaled N× first (Mip-NeRF 360's
    ``images_4``; the camera files keep the full size), then ``resolution`` (``-r``): 1, 2, 4 or 8
    divide the image (rounded); -1 (the default) keeps it up to 1600 px and scales wider images down
    to 1600; any other positive value is the width itself (``utils/camera_utils.loadCam``). An
    unreadable value keeps the width."""
    match = _IMAGES_FACTOR.search(images) if isinstance(images, str) else None
    if match and int(match.group(1)) > 0:
        width = max(1, round(width / int(match.group(1))))
    if isinstance(resolution, bool) or not isinstance(resolution, (int, float)) or not math.isfinite(resolution):
        return int(width)
    if resolution in (1, 2, 4, 8):
        return max(1, round(width / resolution))
    if resolution == -1:
        return min(int(width), 1600)
    return max(1, int(resolution)) if resolution > 0 else int(width)


def at_training_scale(views: dict[str, Camera], resolution: Any, images: Any = None) -> tuple[dict[str, Camera], str | None]:
    """``views`` with ``capture_focal`` at the size INRIA 3DGS trained on (:func:`training_width`), and a
    note saying so when that differs from the images' size (else ``None``)."""
    out, scaled = {}, set()
    for name, camera in views.items():
        trained = training_width(camera.width, resolution, images)
        scale = trained / camera.width
        out[name] = replace(camera, capture_focal=(camera.fx * scale, camera.fy * scale))
        if scale != 1.0:
            scaled.add(trained)
    if not scaled:
        return out, None
    return out, (f"Gaussians trained at {', '.join(map(str, sorted(scaled)))} px wide (cfg_args images {images!r}, "
                 f"resolution {resolution!r}: INRIA's rule): the cameras' capture focal is taken at that size")


def _number(where: str, key: str, value: Any, positive: bool = True) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or (positive and value <= 0):
        raise FileValueError(f"{where}: '{key}' must be a {'positive ' if positive else ''}finite number, got {value!r}")
    return float(value)


def read_inria_cameras(path: PathLike) -> dict[str, Camera]:
    """Read an INRIA ``cameras.json`` into cameras keyed by ``img_name`` (file order).

    Raises:
        FileFormatError: not a list of camera records, missing fields, duplicate names;
            :class:`FileValueError` for non-rigid rotations or non-positive sizes/focals.
    """
    p = as_path(path, "cameras.json")
    data = read_json(p, "cameras.json")
    if not isinstance(data, list) or not data:
        raise FileFormatError(f"{p}: expected a non-empty JSON list of cameras (the INRIA 3DGS cameras.json)")
    out: dict[str, Camera] = {}
    for index, record in enumerate(data):
        name, where = named_record(f"{p}: [{index}]", record, "img_name", ("img_name", "width", "height", "position", "rotation", "fx", "fy"),
                                   out, "an INRIA camera has id, img_name, width, height, position, rotation, fx, fy")
        rot = matrix_field(where, "rotation", record["rotation"], (3, 3))
        err = float(np.abs(rot.T @ rot - np.eye(3)).max())
        if err > RIGID_TOL or np.linalg.det(rot) < 0:
            raise FileValueError(f"{where}: 'rotation' is not a rotation matrix (max |RᵀR − I| = {err:.3g}, det {np.linalg.det(rot):.3f})")
        u, _, vt = np.linalg.svd(rot)
        pose = np.eye(4)
        pose[:3, :3] = u @ vt
        pose[:3, 3] = matrix_field(where, "position", record["position"], (3,))
        width = _number(where, "width", record["width"])
        height = _number(where, "height", record["height"])
        if width != int(width) or height != int(height):
            raise FileValueError(f"{where}: width/height must be whole pixels, got {width}×{height}")
        fx, fy = _number(where, "fx", record["fx"]), _number(where, "fy", record["fy"])
        try:
            out[name] = Camera(fx, fy, width / 2.0, height / 2.0, int(width), int(height), pose)
        except InvalidDataError as error:
            raise FileValueError(f"{where}: {error}") from error
    return out

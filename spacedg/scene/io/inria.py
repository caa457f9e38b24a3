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
from pathlib import Path
from typing import Any

import numpy as np

from spacedg.errors import FileFormatError, InvalidDataError
from spacedg.files import FileValueError, PathLike, as_path, read_json
from spacedg.render.camera import Camera

__all__ = ["read_inria_cameras", "read_cfg_args", "latest_point_cloud", "is_inria_output"]

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


def _matrix(where: str, key: str, value: Any, shape: tuple[int, ...]) -> np.ndarray:
    try:
        array = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise FileFormatError(f"{where}: '{key}' must be numbers of shape {shape}") from None
    if array.shape != shape:
        raise FileFormatError(f"{where}: '{key}' must have shape {shape}, got {array.shape}")
    if not np.isfinite(array).all():
        raise FileValueError(f"{where}: '{key}' holds NaN or Inf")
    return array


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
        where = f"{p}: [{index}]"
        if not isinstance(record, dict):
            raise FileFormatError(f"{where}: expected an object, got {type(record).__name__}")
        missing = [k for k in ("img_name", "width", "height", "position", "rotation", "fx", "fy") if k not in record]
        if missing:
            raise FileFormatError(f"{where}: missing {missing}; an INRIA camera has id, img_name, width, height, position, rotation, fx, fy")
        name = record["img_name"]
        if not isinstance(name, str) or not name:
            raise FileFormatError(f"{where}: 'img_name' must be a non-empty string, got {name!r}")
        where = f"{where} ({name!r})"
        if name in out:
            raise FileFormatError(f"{where}: img_name {name!r} appears twice")
        rot = _matrix(where, "rotation", record["rotation"], (3, 3))
        err = float(np.abs(rot.T @ rot - np.eye(3)).max())
        if err > RIGID_TOL or np.linalg.det(rot) < 0:
            raise FileValueError(f"{where}: 'rotation' is not a rotation matrix (max |RᵀR − I| = {err:.3g}, det {np.linalg.det(rot):.3f})")
        u, _, vt = np.linalg.svd(rot)
        pose = np.eye(4)
        pose[:3, :3] = u @ vt
        pose[:3, 3] = _matrix(where, "position", record["position"], (3,))
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

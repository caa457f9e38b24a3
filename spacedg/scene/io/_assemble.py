"""Assemble a :class:`Scene` from foreign files: Gaussians + cameras + optional instances."""

from __future__ import annotations

import functools
import math
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any, Literal

import numpy as np

from spacedg.errors import FileFormatError, InvalidDataError
from spacedg.files import PathLike, as_path, require_file
from spacedg.render.camera import Camera
from spacedg.render.gaussians import Gaussians
from spacedg.scene.io.capture import find_cameras, read_cameras, scale_gaussians, scale_instances, scale_views
from spacedg.scene.io.instances import read_instances
from spacedg.scene.io.ply import read_ply
from spacedg.scene.io.splat import read_splat
from spacedg.scene.io.spz import read_spz
from spacedg.scene.model import Scene

#: Smallest length of the mean camera −y axis accepted as an up estimate (1 = all agree).
MIN_UP_AGREEMENT = 0.5


#: Gaussian file suffixes :func:`read_gaussians` reads.
GAUSSIAN_SUFFIXES = (".ply", ".splat", ".spz")


def read_gaussians(path: PathLike) -> Gaussians:
    """Read Gaussians from a ``.ply`` (INRIA 3DGS, PlayCanvas compressed, colour-only), ``.splat``
    or ``.spz`` file, chosen by suffix. ``.ksplat`` is refused with a conversion hint."""
    p = as_path(path, "Gaussians file")
    suffix = p.suffix.lower()
    if suffix == ".ply":
        return read_ply(p)
    if suffix == ".splat":
        return read_splat(p)
    if suffix == ".spz":
        return read_spz(p)
    if suffix == ".ksplat":
        raise FileFormatError(
            f"{p}: .ksplat (GaussianSplats3D's viewer format) is not read: it has versioned, quantised sections with no "
            "published spec outside that viewer. Export the scene as .ply (or convert with that viewer's tools) and import the .ply"
        )
    raise FileFormatError(f"{p}: unknown Gaussians file type {p.suffix!r}; use a .ply (INRIA 3DGS / compressed), .splat or .spz file")


def load_scaled_gaussians(path: str, scale: float) -> Gaussians:
    """Read Gaussians and scale them to metres (module-level so a partial of it pickles)."""
    return scale_gaussians(read_gaussians(path), scale)


def read_views(source: PathLike | Mapping[str, Camera], opencv_distortion: Literal["error", "drop"] = "error") -> dict[str, Camera]:
    """Cameras from a COLMAP model folder (or a project with ``sparse/0``), a ``transforms.json``
    (or a folder holding one and no COLMAP model), an INRIA ``cameras.json``, or a ready mapping
    name → Camera. The format is told by :func:`~spacedg.scene.io.capture.find_cameras`."""
    if isinstance(source, Mapping):
        return dict(source)
    return read_cameras(find_cameras(as_path(source, "views")), opencv_distortion)


def estimate_up(views: Mapping[str, Camera]) -> np.ndarray:
    """Up estimated as the normalised mean of the cameras' −y axes (image "up" in the world).

    Photographs are mostly taken upright, so the image's up direction averages to gravity's.
    Raises when there are no cameras or their up axes disagree (mean length <
    :data:`MIN_UP_AGREEMENT`), e.g. for a camera looking straight down: pass ``up`` then.
    """
    if not views:
        raise InvalidDataError("cannot estimate up without cameras; pass up=(x, y, z)")
    axes = np.array([-cam.cam_to_world[:3, 1] for cam in views.values()])
    mean = axes.mean(axis=0)
    norm = float(np.linalg.norm(mean))
    if norm < MIN_UP_AGREEMENT:
        raise InvalidDataError(
            f"cannot estimate up: the {len(views)} cameras' up axes disagree (mean length {norm:.2f} < {MIN_UP_AGREEMENT}); pass up=(x, y, z)"
        )
    return mean / norm


def scene_from_files(
    id: str,
    gaussians_path: PathLike,
    views: PathLike | Mapping[str, Camera],
    instances_path: PathLike | None = None,
    up: Iterable[float] | None = None,
    scale: float = 1.0,
    *,
    opencv_distortion: Literal["error", "drop"] = "error",
    metadata: Mapping[str, Any] | None = None,
) -> Scene:
    """Build a :class:`Scene` from a Gaussians file, cameras and (optionally) instance boxes.

    Args:
        id: scene id.
        gaussians_path: ``.ply`` (INRIA 3DGS) or ``.splat``; loaded lazily on first use.
        views: a COLMAP model folder, a ``transforms.json`` (or its folder), an INRIA
            ``cameras.json``, or a mapping name → Camera (see :func:`read_views`).
        instances_path: instance JSON (:func:`read_instances`, Holi-Spatial's layout included);
            image references must resolve to views.
        up: unit vector against gravity, in the **files'** world frame; ``None`` estimates it
            with :func:`estimate_up` (recorded in ``metadata["up_source"]``).
        scale: metres per file unit, applied once to Gaussians (positions and sizes), camera
            centres and boxes. Up is a direction and is not scaled.
        opencv_distortion: passed to the camera reader.
        metadata: extra facts; ``source``, ``scale_to_metres`` and ``up_source`` are added.
    """
    if isinstance(scale, bool) or not isinstance(scale, (int, float)) or not (math.isfinite(scale) and scale > 0):
        raise InvalidDataError(f"scene_from_files: scale (metres per file unit) must be a positive number, got {scale!r}")
    scale = float(scale)
    gpath = as_path(gaussians_path, "Gaussians file")
    require_file(gpath, "Gaussians file")
    if gpath.suffix.lower() not in GAUSSIAN_SUFFIXES:
        read_gaussians(gpath)  # raises the suffix's own message
    cameras = read_views(views, opencv_distortion)
    instances = read_instances(instances_path, views=cameras.keys()) if instances_path is not None else []
    if up is None:
        up_vec = estimate_up(cameras)
        up_source = f"estimated: normalised mean of the -y axes of {len(cameras)} cameras"
    else:
        up_vec = np.asarray(list(up), dtype=np.float64)
        up_source = "given"
    if scale != 1.0:
        cameras = scale_views(cameras, scale)
        instances = scale_instances(instances, scale)
    meta: dict[str, Any] = dict(metadata or {})
    meta.update(
        source={
            "gaussians": str(gpath),
            "views": "<memory>" if isinstance(views, Mapping) else str(Path(views)),
            "instances": None if instances_path is None else str(Path(instances_path)),
        },
        scale_to_metres=scale,
        up_source=up_source,
    )
    loader = functools.partial(load_scaled_gaussians, str(gpath), scale)
    return Scene(id, loader, cameras, instances, up_vec.tolist(), None, meta)

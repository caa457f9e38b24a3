"""The parts of a foreign capture, found and brought to metres in one place.

- :func:`find_cameras`: the **one** rule that tells a camera source's format (an INRIA
  ``cameras.json``, a nerfstudio ``transforms.json`` or a folder holding one, a COLMAP model
  folder or a project with ``sparse/0``), inspecting the path once; the result, a
  :class:`CameraFiles` value, is passed along and read by :func:`read_cameras`.
- :func:`colmap_model`: where a folder's COLMAP model is (itself, ``sparse/0`` or ``sparse``).
- :func:`scale_views`, :func:`scale_instances`, :func:`scale_gaussians`: ``metres_per_unit``
  applied once to camera centres, boxes and Gaussians (positions and sizes); directions (up,
  rotations) are not scaled.

Used by :func:`~spacedg.scene.io.scene_from_files` and :func:`~spacedg.scene.importer.import_scene`.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Literal

import numpy as np

from spacedg.errors import FileFormatError
from spacedg.render.camera import Camera
from spacedg.render.gaussians import Gaussians
from spacedg.scene.io.colmap import read_colmap
from spacedg.scene.io.inria import read_inria_cameras
from spacedg.scene.io.nerfstudio import read_transforms
from spacedg.scene.io.scannetpp_iphone import POSE_FILE, read_pose_intrinsic_imu
from spacedg.scene.model import Instance

__all__ = [
    "CameraFiles",
    "colmap_model",
    "find_cameras",
    "read_cameras",
    "scale_gaussians",
    "scale_instances",
    "scale_views",
]

CameraKind = Literal["inria", "nerfstudio", "colmap", "scannetpp-iphone"]


@dataclass(frozen=True)
class CameraFiles:
    """A camera source whose format is known.

    Attributes:
        kind: ``"inria"`` (``cameras.json``), ``"nerfstudio"`` (``transforms.json``), ``"colmap"`` or
            ``"scannetpp-iphone"`` (ScanNet++'s ``iphone/pose_intrinsic_imu.json``).
        path: what was given (a file or folder; named in reports and metadata).
        read_path: what is read: the ``cameras.json`` / ``transforms.json`` file, or the COLMAP
            model folder (``path`` itself when no model was found: the reader then names what is missing).
    """

    kind: CameraKind
    path: Path
    read_path: Path

    def test_frames(self) -> int:
        """How many ``test_frames`` a nerfstudio ``transforms.json`` lists (0 for other kinds, or unreadable)."""
        if self.kind != "nerfstudio":
            return 0
        try:
            data = json.loads(self.read_path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return 0
        frames = data.get("test_frames") if isinstance(data, dict) else None
        return len(frames) if isinstance(frames, list) else 0


def colmap_model(folder: Path) -> Path | None:
    """The COLMAP model folder of ``folder`` (itself, ``sparse/0`` or ``sparse``: the first holding
    both ``cameras`` and ``images`` as ``.bin`` or ``.txt``), or ``None``."""
    for candidate in (folder, folder / "sparse" / "0", folder / "sparse"):
        if any((candidate / f"cameras.{ext}").is_file() and (candidate / f"images.{ext}").is_file() for ext in ("bin", "txt")):
            return candidate
    return None


def find_cameras(path: Path) -> CameraFiles:
    """The format of the camera source ``path`` (the one detection rule, in this order):

    1. a file named ``cameras.json``: INRIA; one named ``pose_intrinsic_imu.json``: ScanNet++'s iPhone ARKit
       cameras (:mod:`spacedg.scene.io.scannetpp_iphone`);
    2. any other ``.json`` path: a nerfstudio ``transforms.json``;
    3. a folder with a COLMAP model (:func:`colmap_model`): COLMAP, read from the model;
    4. a folder with a ``transforms.json``: nerfstudio;
    5. any other folder: COLMAP (its reader names the missing files).

    Raises:
        FileFormatError: ``path`` does not exist, or is a file that is neither.
    """
    if path.is_file():
        if path.name == "cameras.json":
            return CameraFiles("inria", path, path)
        if path.name == POSE_FILE:
            return CameraFiles("scannetpp-iphone", path, path)
        if path.suffix.lower() == ".json":
            return CameraFiles("nerfstudio", path, path)
        raise FileFormatError(f"{path}: views must be a COLMAP model folder or a transforms.json file")
    if path.is_dir():
        model = colmap_model(path)
        if model is not None:
            return CameraFiles("colmap", path, model)
        if (path / "transforms.json").is_file():
            return CameraFiles("nerfstudio", path, path / "transforms.json")
        return CameraFiles("colmap", path, path)
    if path.suffix.lower() == ".json":
        return CameraFiles("nerfstudio", path, path)  # its reader says it is missing
    raise FileFormatError(f"{path}: views not found; pass a COLMAP model folder or a transforms.json")


def read_cameras(files: CameraFiles, opencv_distortion: Literal["error", "drop"] = "error") -> dict[str, Camera]:
    """The cameras of ``files`` (name → :class:`Camera`, OpenCV axes, file units), each marked as the
    capture's own (:meth:`Camera.as_captured`: the Gaussians were trained on these images, so a render
    at another size keeps their look, :func:`spacedg.render.settings.footprint_dilation`)."""
    if files.kind == "inria":
        cameras = read_inria_cameras(files.read_path)
    elif files.kind == "nerfstudio":
        cameras = read_transforms(files.read_path, opencv_distortion=opencv_distortion)
    elif files.kind == "scannetpp-iphone":
        cameras = read_pose_intrinsic_imu(files.read_path)
    else:
        cameras = read_colmap(files.read_path, opencv_distortion=opencv_distortion)
    return {name: camera.as_captured() for name, camera in cameras.items()}


def scale_views(views: Mapping[str, Camera], scale: float) -> dict[str, Camera]:
    """Cameras with their centres multiplied by ``scale`` (metres per file unit); rotations kept."""
    out = {}
    for name, cam in views.items():
        pose = cam.cam_to_world.copy()
        pose[:3, 3] *= scale
        out[name] = cam.with_pose(pose)
    return out


def scale_instances(instances: Iterable[Instance], scale: float) -> list[Instance]:
    """Instances with their boxes' centres and extents multiplied by ``scale``."""
    return [replace(inst, box=inst.box.transformed(np.eye(3), np.zeros(3), scale)) for inst in instances]


def scale_gaussians(gaussians: Gaussians, scale: float) -> Gaussians:
    """Gaussians with positions and sizes multiplied by ``scale`` (the same object when ``scale == 1``)."""
    return gaussians if scale == 1.0 else gaussians.transformed(scale=scale)

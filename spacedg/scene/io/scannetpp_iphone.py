"""ScanNet++'s iPhone ARKit cameras: ``<scene>/iphone/pose_intrinsic_imu.json``, read as published.

The format, as the ScanNet++ toolkit names and reads it (``common/scene_release.py``:
``iphone_pose_intrinsic_imu_path``; ``iphone/arkit_pcl.py`` back-projects the iPhone depth with it):
one JSON object keyed by frame id ``frame_NNNNNN`` (the frame's number in ``iphone/rgb.mkv``, the
name of the extracted ``iphone/rgb/frame_NNNNNN.jpg``), each value an object with

- ``aligned_pose``: 4×4 **camera-to-world**, OpenCV camera axes (x right, y down, z forward:
  ``arkit_pcl.py`` maps ``K⁻¹ [u, v, 1]ᵀ · depth`` through it), in the laser scan's frame (metres,
  z up: the frame of ``scans/mesh_aligned_0.05.ply`` and ``scans/segments_anno.json``);
- ``pose``: the same camera in ARKit's own session world, **not** aligned to the scan (not used:
  its boxes would not line up);
- ``intrinsic``: 3×3 ``K`` in pixels of the full RGB frames, 1920×1440 (:data:`IPHONE_RGB_SIZE`);
- ``timestamp``, ``imu``: not used.

Image size: the frames extracted in ``iphone/rgb/`` when there are any (their JPEG header; ``K`` is
scaled per axis from 1920×1440 when they were extracted smaller), else 1920×1440. Views: the frames
extracted in ``iphone/rgb/`` when that folder holds any (the toolkit's ``prepare_iphone_data``
extracts the frames of the COLMAP model), else every frame of the JSON (60 per second of video).
Views are named ``frame_NNNNNN.jpg``, as the iPhone COLMAP model and nerfstudio JSON name them.

**Both this file and ``iphone/colmap/``**: the COLMAP model holds the same frames' poses refined by
bundle adjustment, in the same scan frame, for the frames chosen for the release; ScanNet++'s
iPhone nerfstudio JSON is made from it. :func:`~spacedg.scene.io.scannetpp.scannetpp_cameras`
therefore prefers ``iphone/nerfstudio`` then ``iphone/colmap`` and reads this file only when
neither exists (or when it is given with ``--cameras``); the importer then reports how far the
ARKit poses lie from the COLMAP ones (:func:`arkit_agreement`).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from spacedg.errors import FileFormatError, InvalidDataError
from spacedg.files import FileValueError, PathLike, as_path, read_json
from spacedg.render.camera import Camera
from spacedg.scene.io.fields import matrix_field

__all__ = ["IPHONE_RGB_SIZE", "POSE_FILE", "arkit_agreement", "read_pose_intrinsic_imu", "rgb_frames"]

#: The file's name inside ``<scene>/iphone/``.
POSE_FILE = "pose_intrinsic_imu.json"
#: (width, height) of ScanNet++'s iPhone RGB frames, the pixels ``intrinsic`` is given in.
IPHONE_RGB_SIZE = (1920, 1440)
#: Largest |RᵀR − I| accepted for ``aligned_pose`` (ARKit writes float32).
RIGID_TOL = 1e-3


def rgb_frames(iphone_dir: Path) -> dict[str, Path]:
    """The extracted frames ``iphone/rgb/frame_*.jpg`` by frame id (empty without any)."""
    folder = iphone_dir / "rgb"
    return {p.stem: p for p in sorted(folder.glob("frame_*.jpg"))} if folder.is_dir() else {}


def _jpeg_size(path: Path) -> tuple[int, int]:
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(path) as image:
            return int(image.width), int(image.height)
    except (OSError, UnidentifiedImageError) as err:
        raise FileFormatError(f"{path}: not a readable JPEG frame ({err})") from None


def _matrix(where: str, key: str, value: Any, n: int) -> np.ndarray:
    """An ``n × n`` matrix given nested or flat (row-major), as ``arkit_pcl.py`` reshapes it."""
    flat = isinstance(value, list) and len(value) == n * n and not any(isinstance(v, list) for v in value)
    return matrix_field(where, key, value, (n * n,)).reshape(n, n) if flat else matrix_field(where, key, value, (n, n))


def _pose(where: str, record: Mapping[str, Any]) -> np.ndarray:
    if "aligned_pose" not in record:
        extra = " (it has 'pose': ARKit's own world, not aligned to the scan)" if "pose" in record else ""
        raise FileFormatError(f"{where}: missing 'aligned_pose' (camera-to-world in the scan frame){extra}")
    pose = _matrix(where, "aligned_pose", record["aligned_pose"], 4)
    rot = pose[:3, :3]
    err = float(np.abs(rot.T @ rot - np.eye(3)).max())
    if err > RIGID_TOL or np.linalg.det(rot) < 0 or not np.allclose(pose[3], [0.0, 0.0, 0.0, 1.0], atol=1e-6):
        raise FileValueError(f"{where}: 'aligned_pose' is not a rigid camera-to-world (max |RᵀR − I| = {err:.3g}, "
                             f"det {np.linalg.det(rot):.3f}, last row {pose[3].tolist()})")
    u, _, vt = np.linalg.svd(rot)
    pose[:3, :3] = u @ vt
    return pose


def _camera(where: str, record: Any, size: tuple[int, int]) -> Camera:
    if not isinstance(record, dict):
        raise FileFormatError(f"{where}: expected an object with aligned_pose and intrinsic, got {type(record).__name__}")
    if "intrinsic" not in record:
        raise FileFormatError(f"{where}: missing 'intrinsic' (3×3 K of the {IPHONE_RGB_SIZE[0]}×{IPHONE_RGB_SIZE[1]} frames)")
    k = _matrix(where, "intrinsic", record["intrinsic"], 3)
    fx, fy, cx, cy = float(k[0, 0]), float(k[1, 1]), float(k[0, 2]), float(k[1, 2])
    full_w, full_h = IPHONE_RGB_SIZE
    if not (fx > 0 and fy > 0 and 0 < cx < full_w and 0 < cy < full_h) or abs(k[0, 1]) > 1e-6 * fx or not np.allclose(k[2], [0, 0, 1]):
        raise FileValueError(f"{where}: 'intrinsic' is not a pinhole K of a {full_w}×{full_h} frame "
                             f"(fx {fx:g}, fy {fy:g}, cx {cx:g}, cy {cy:g}, skew {k[0, 1]:g})")
    sx, sy = size[0] / full_w, size[1] / full_h
    try:
        return Camera(fx * sx, fy * sy, cx * sx, cy * sy, size[0], size[1], _pose(where, record))
    except InvalidDataError as error:
        raise FileValueError(f"{where}: {error}") from error


def read_pose_intrinsic_imu(path: PathLike, *, frames: Mapping[str, Path] | None = None) -> dict[str, Camera]:
    """The cameras of a ScanNet++ ``iphone/pose_intrinsic_imu.json`` (module docstring): name
    ``frame_NNNNNN.jpg`` → :class:`Camera` (OpenCV axes, scan frame, metres), in frame order.

    Args:
        path: the JSON file.
        frames: extracted frames by frame id (default: :func:`rgb_frames` of the file's folder); when
            any, only those frames are read and their JPEG size is the image size.

    Raises:
        FileFormatError: not an object of frame records, a record without ``aligned_pose`` / ``intrinsic``,
            no frame of ``rgb/`` in the file; :class:`FileValueError` for non-rigid poses or a bad ``K``.
    """
    p = as_path(path, POSE_FILE)
    data = read_json(p, POSE_FILE)
    if not isinstance(data, dict) or not data:
        raise FileFormatError(f"{p}: expected a non-empty object keyed by frame id (frame_000000: {{aligned_pose, intrinsic, ...}})")
    extracted = rgb_frames(p.parent) if frames is None else dict(frames)
    names = sorted(data) if not extracted else sorted(set(data) & set(extracted))
    if not names:
        raise FileFormatError(f"{p}: none of the {len(extracted)} frames in {p.parent / 'rgb'} (e.g. {next(iter(extracted))}) "
                              "has a record here; is this the scene's own pose_intrinsic_imu.json?")
    size = _jpeg_size(extracted[names[0]]) if extracted else IPHONE_RGB_SIZE
    return {f"{name}.jpg": _camera(f"{p}: {name!r}", data[name], size) for name in names}


def arkit_agreement(views: Mapping[str, Camera], path: Path) -> str:
    """How far the ARKit poses of ``path`` lie from ``views`` (e.g. the COLMAP ones) on their shared frames:
    median and largest centre distance (metres) and viewing-direction angle (degrees), one line."""
    try:
        arkit = read_pose_intrinsic_imu(path, frames={})
    except (FileFormatError, InvalidDataError) as err:
        return f"{path.name} present but not compared ({err})"
    shared = [n for n in views if n in arkit]
    if not shared:
        return f"{path.name} present; no frame in common with the cameras used"
    dist = np.array([float(np.linalg.norm(views[n].center - arkit[n].center)) for n in shared])
    cos = np.clip([float(views[n].forward @ arkit[n].forward) for n in shared], -1.0, 1.0)
    angle = np.degrees(np.arccos(cos))
    return (f"{path.name} (ARKit aligned_pose) vs these cameras on {len(shared)} shared frames: centres "
            f"{float(np.median(dist)) * 100:.1f} cm apart (median; largest {float(dist.max()) * 100:.1f} cm), "
            f"directions {float(np.median(angle)):.2f}° (largest {float(angle.max()):.2f}°)")

"""ScanNet++ scene folders: cameras (DSLR / iPhone nerfstudio JSON) and ``segments_anno.json`` boxes.

A ScanNet++ scene folder (as downloaded, v1/v2)::

    <scene id>/
      dslr/nerfstudio/transforms_undistorted.json   PINHOLE cameras of the undistorted DSLR images
      dslr/nerfstudio/transforms.json               OPENCV_FISHEYE cameras of the raw DSLR images
      dslr/resized_images/, dslr/resized_undistorted_images/, dslr/colmap/
      iphone/nerfstudio/transforms.json             iPhone cameras, same JSON layout (one OPENCV camera:
                                                    fl_x, fl_y, cx, cy, w, h, k1, k2, p1, p2 at the top level)
      iphone/colmap/                                iPhone COLMAP text model (frame_NNNNNN.jpg), scan frame
      iphone/pose_intrinsic_imu.json                ARKit cameras of every frame (aligned_pose: scan frame;
                                                    :mod:`spacedg.scene.io.scannetpp_iphone`)
      iphone/rgb.mkv, rgb/, depth.bin, exif.json    video, extracted frames, depth
      scans/mesh_aligned_0.05.ply                   the laser-scan mesh (not Gaussians)
      scans/segments_anno.json                      annotated instances

The nerfstudio JSON files list ``frames`` and ``test_frames`` (one DSLR view in eight is held out)
and are read by :func:`~spacedg.scene.io.nerfstudio.read_transforms`. Their world is **not** the
scan's: ScanNet++ converts its COLMAP poses (scan frame, metres, z up, like the mesh and the boxes)
with nerfstudio's convention, world rows (y, x, −z) (``common/utils/nerfstudio.py``
``convert_frames`` in the ScanNet++ toolkit; its issue #160), i.e. ``p_json = NERFSTUDIO_FROM_SCAN · p_scan``.
The importer takes cameras, and Gaussians trained on these JSON files, back to the scan frame with
:data:`NERFSTUDIO_FROM_SCAN` (an involution), so everything is metric and z up. ScanNet++ ships no
Gaussians: train them on the DSLR images (INRIA, gsplat or splatfacto) and pass the result.

``segments_anno.json``: ``{"sceneId", "segGroups": [{"id", "objectId", "label", "segments",
"obb": {"centroid": [3], "axesLengths": [3], "normalizedAxes": [9], "min", "max"}}]}``.
``normalizedAxes`` holds the three unit box axes one after the other (``[0:3]`` is the axis of
``axesLengths[0]``, ...), so the box rotation's **columns** are ``reshape(3, 3).T``;
``axesLengths`` are full side lengths. Groups without ``obb`` are skipped (counted in the
warning); labels are kept as written.
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

import numpy as np

from spacedg.errors import FileFormatError, InvalidDataError
from spacedg.files import FileValueError, PathLike, as_path, read_json
from spacedg.scene.box import OrientedBox
from spacedg.scene.io.annotation_limits import check_box_size, check_instance_id
from spacedg.scene.io.scannetpp_iphone import POSE_FILE
from spacedg.scene.model import Instance

__all__ = ["NERFSTUDIO_FROM_SCAN", "read_segments_anno", "scannetpp_cameras", "is_scannetpp_scene"]

#: World change of ScanNet++'s nerfstudio JSON (DSLR and iPhone): ``p_json = M p_scan`` (rows y, x, −z;
#: a rotation, its own inverse).
NERFSTUDIO_FROM_SCAN = np.array([[0.0, 1.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0], [0.0, 0.0, -1.0, 0.0], [0.0, 0.0, 0.0, 1.0]])

#: Largest |RᵀR − I| accepted for normalizedAxes (annotations are written with a few decimals).
AXES_TOL = 1e-3


def is_scannetpp_scene(folder: Path) -> bool:
    """Whether ``folder`` looks like a ScanNet++ scene (DSLR / iPhone nerfstudio JSON or scans/segments_anno.json)."""
    return folder.is_dir() and (
        (folder / "scans" / "segments_anno.json").is_file()
        or any((folder / cam / "nerfstudio").is_dir() for cam in ("dslr", "iphone"))
        or (folder / "iphone" / "pose_intrinsic_imu.json").is_file()
    )


def scannetpp_cameras(folder: PathLike, device: str = "dslr") -> Path:
    """The cameras of ``device``: its nerfstudio JSON (``"dslr"``: the undistorted one when present), else
    (iPhone) its COLMAP model ``iphone/colmap`` (bundle-adjusted, already in the scan frame), else its ARKit
    ``iphone/pose_intrinsic_imu.json`` (``aligned_pose``: scan frame; :mod:`spacedg.scene.io.scannetpp_iphone`)."""
    root = as_path(folder, "ScanNet++ scene folder")
    if device not in ("dslr", "iphone"):
        raise InvalidDataError(f"ScanNet++ camera must be 'dslr' or 'iphone', got {device!r}")
    names = ("transforms_undistorted.json", "transforms.json") if device == "dslr" else ("transforms.json",)
    for name in names:
        path = root / device / "nerfstudio" / name
        if path.is_file():
            return path
    if device == "iphone" and (root / "iphone" / "colmap").is_dir():
        return root / "iphone" / "colmap"
    if device == "iphone" and (root / "iphone" / POSE_FILE).is_file():
        return root / "iphone" / POSE_FILE
    extra = f", iphone/colmap nor iphone/{POSE_FILE}" if device == "iphone" else ""
    raise FileFormatError(
        f"{root}: no {device}/nerfstudio/{' or '.join(names)}{extra}; is this a ScanNet++ scene folder "
        f"(<scene id>/{device}/nerfstudio/...)?"
    )


def _box(where: str, obb: Any) -> OrientedBox:
    if not isinstance(obb, dict):
        raise FileFormatError(f"{where}: 'obb' must be an object with centroid, axesLengths, normalizedAxes")
    try:
        center = np.array(obb["centroid"], dtype=np.float64)
        lengths = np.array(obb["axesLengths"], dtype=np.float64)
        axes = np.array(obb["normalizedAxes"], dtype=np.float64).reshape(3, 3)
    except KeyError as err:
        raise FileFormatError(f"{where}: 'obb' lacks {err}; ScanNet++ boxes have centroid, axesLengths, normalizedAxes") from None
    except (TypeError, ValueError):
        raise FileFormatError(f"{where}: 'obb' centroid/axesLengths must be 3 numbers and normalizedAxes 9") from None
    if center.shape != (3,) or lengths.shape != (3,):
        raise FileFormatError(f"{where}: 'obb' centroid and axesLengths must be 3 numbers each")
    rot = axes.T
    err = float(np.abs(rot.T @ rot - np.eye(3)).max()) if np.isfinite(rot).all() else float("inf")
    if err > AXES_TOL:
        raise FileValueError(f"{where}: 'normalizedAxes' are not orthonormal (max |AᵀA − I| = {err:.3g})")
    u, _, vt = np.linalg.svd(rot)
    rot = u @ vt
    if np.linalg.det(rot) < 0:
        rot[:, 2] *= -1.0  # a left-handed axis triple describes the same box
    try:
        return OrientedBox(center, lengths, rot)
    except InvalidDataError as error:
        raise FileValueError(f"{where}: {error}") from error


def read_segments_anno(path: PathLike, *, data: Any = None) -> list[Instance]:
    """Instances (id = ``objectId`` else ``id``, label, box) from a ScanNet++ ``segments_anno.json``
    (``data``: its content already parsed, then not read again).

    Raises:
        FileFormatError: no ``segGroups`` list, malformed groups or boxes, duplicate ids.
    """
    p = as_path(path, "segments_anno.json")
    data = read_json(p, "segments_anno.json") if data is None else data
    groups = data.get("segGroups") if isinstance(data, dict) else None
    if not isinstance(groups, list):
        raise FileFormatError(f"{p}: expected an object with a 'segGroups' list (ScanNet++ segments_anno.json)")
    out: list[Instance] = []
    seen: set[int] = set()
    skipped = 0
    for index, group in enumerate(groups):
        where = f"{p}: segGroups[{index}]"
        if not isinstance(group, dict):
            raise FileFormatError(f"{where}: expected an object")
        if "obb" not in group:
            skipped += 1
            continue
        raw_id = group.get("objectId", group.get("id"))
        if isinstance(raw_id, bool) or not isinstance(raw_id, int) or raw_id < 0:
            raise FileValueError(f"{where}: 'objectId'/'id' must be an integer >= 0, got {raw_id!r}")
        check_instance_id(where, "objectId", raw_id)
        if raw_id in seen:
            raise FileValueError(f"{where}: object id {raw_id} is used twice")
        seen.add(raw_id)
        label = group.get("label")
        if not isinstance(label, str) or not label.strip():
            raise FileValueError(f"{where} (id {raw_id}): 'label' must be a non-empty string, got {label!r}")
        segments = group.get("segments", [])
        if not isinstance(segments, list):
            raise FileFormatError(f"{where} (id {raw_id}): 'segments' must be a list of segment ids, got {type(segments).__name__}")
        out.append(Instance(raw_id, label.strip(), "", check_box_size(f"{where} (id {raw_id})", _box(f"{where} (id {raw_id})", group["obb"])),
                            attributes={"source": "scannetpp", "segments": len(segments)}))
    if skipped:
        warnings.warn(f"{p}: {skipped} segment group(s) without an 'obb' were skipped", stacklevel=2)
    return out

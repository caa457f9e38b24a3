"""Readers and writers: every conversion from another convention happens here, once.

- Gaussians: :func:`read_ply` / :func:`write_ply` (INRIA 3DGS ``.ply``), :func:`read_splat` /
  :func:`write_splat` (``.splat``), :func:`quantize_for_ply`.
- Cameras: :func:`read_colmap` (COLMAP text/binary via pycolmap), :func:`read_transforms`
  (nerfstudio / Blender ``transforms.json``).
- Instances: :func:`read_instances` / :func:`write_instances` (Holi-Spatial-style JSON).
- Scenes: :func:`save_scene` / :func:`load_scene` (native folder), :func:`scene_from_files`.
- Foreign captures: :mod:`spacedg.scene.io.capture` tells a camera source's format (one rule,
  :func:`~spacedg.scene.io.capture.find_cameras`) and brings every part to metres once.

Errors: malformed files raise :class:`~spacedg.errors.FileFormatError`; files that parse but
hold values breaking a convention raise :class:`FileValueError` (both a ``FileFormatError``
and an ``InvalidDataError``); every message names the file and the record.
"""

from spacedg.files import FileValueError
from spacedg.scene.io._assemble import (
    GAUSSIAN_SUFFIXES,
    read_gaussians,
    read_views,
    scene_from_files,
)
from spacedg.scene.io.colmap import read_colmap
from spacedg.scene.io.instances import read_instances, write_instances
from spacedg.scene.io.native import load_scene, save_scene
from spacedg.scene.io.nerfstudio import read_transforms
from spacedg.scene.io.ply import quantize_for_ply, read_ply, write_ply
from spacedg.scene.io.splat import read_splat, write_splat
from spacedg.scene.up_evidence import MIN_UP_AGREEMENT, estimate_up

__all__ = [
    "GAUSSIAN_SUFFIXES",
    "FileValueError",
    "MIN_UP_AGREEMENT",
    "estimate_up",
    "load_scene",
    "quantize_for_ply",
    "read_colmap",
    "read_gaussians",
    "read_instances",
    "read_ply",
    "read_splat",
    "read_transforms",
    "read_views",
    "save_scene",
    "scene_from_files",
    "write_instances",
    "write_ply",
    "write_splat",
]

"""Holi-Spatial's released scenes: the scene folder, its box JSON and the COCO RLE masks in it.

The release (Hugging Face ``Holi-Spatial/ScanNetPP`` and ``Holi-Spatial/ScanNet_v2``) holds two
folders per dataset: the PGSR models with their meshes, in tar shards (``GS_model_w_mesh_pp/<k>.tar``,
``GS_model_w_mesh/<k>.tar`` for ScanNet v2), and one box JSON per scene
(``3d_bounding_box_pp/<scene id>.json``, ``3d_bounding_box/<scene id>.json``). Unpacked, a scene reads::

    <release>/GS_model_w_mesh_pp/<scene id>/      a PGSR output folder (the INRIA layout)
        cfg_args, cameras.json, input.ply, multi_view.json
        point_cloud/iteration_30000/point_cloud.ply   the Gaussians (INRIA ply)
        mesh/tsdf_fusion_post.ply                     the TSDF mesh (not read)
    <release>/3d_bounding_box_pp/<scene id>.json  the instances (below)

:func:`find_release_boxes` looks for the box JSON beside the scene folder's ancestors (up to three
levels), so the scene folder alone is a complete import source.

The PGSR models are trained on ScanNet++'s ``dslr/nerfstudio/transforms_undistorted.json`` poses
(ScanNet v2: ``pose/*.txt``) without normalisation, so the Gaussians, cameras and boxes are in the
dataset's scan frame: **metres, z up**.

The box JSON is a list of instances, each ``{"ins_id": "<n>", "label", "bounding_box": 8 × {x, y, z},
"obb_transform": 4×4, "obb_extents": 3 full sides, "images": [mask paths], "highest_confidence_mask",
"mask_encodings": [RLE], "description"?}`` (read by :func:`~spacedg.scene.io.instances.read_instances`).
``images`` are absolute paths of SAM3 mask files on the authors' machine,
``<mask root>/<scene id>/<image stem>/<label>[_NN].png``; ``mask_encodings[i]`` is the COCO RLE of
``images[i]`` (both sorted by path), ``{"size": [height, width], "counts": "<compressed string>"}``
as ``pycocotools.mask.encode`` writes it (column-major runs, starting with a run of zeros).
The mask files are not released: the RLE strings are the masks.
"""

from __future__ import annotations

import re
import warnings
from collections.abc import Iterable, Mapping
from pathlib import Path, PurePath
from typing import Any

import numpy as np

from spacedg.errors import FileFormatError
from spacedg.files import FileValueError, PathLike, as_path, read_json
from spacedg.scene.io.inria import is_inria_output

__all__ = [
    "BOX_FOLDERS", "MESH_FILE", "RleMasks", "decode_rle", "find_release_boxes", "is_release_scene",
    "read_mask_encodings", "rle_run_lengths",
]

#: Folders of the release that hold ``<scene id>.json`` (ScanNet++, ScanNet v2).
BOX_FOLDERS = ("3d_bounding_box_pp", "3d_bounding_box")
#: The TSDF mesh PGSR's mesh step leaves in a scene folder.
MESH_FILE = "mesh/tsdf_fusion_post.ply"
#: Scene ids of the released datasets: ScanNet++ (10 hex digits), ScanNet v2 (``sceneNNNN_NN``).
RELEASE_SCENE_ID = re.compile(r"[0-9a-f]{10}|scene\d{4}_\d{2}")
#: Largest relative difference between a mask's and its view's aspect ratio.
ASPECT_TOL = 0.01


def find_release_boxes(scene_dir: Path) -> Path | None:
    """``<ancestor>/3d_bounding_box[_pp]/<scene id>.json`` for the scene folder's three nearest ancestors."""
    name = scene_dir.name
    for ancestor in list(scene_dir.resolve().parents)[:3]:
        for folder in BOX_FOLDERS:
            candidate = ancestor / folder / f"{name}.json"
            if candidate.is_file():
                return candidate
    return None


def is_release_scene(folder: Path) -> bool:
    """A PGSR/INRIA output folder with its box JSON beside it, or with the release's mesh and a ScanNet++ /
    ScanNet v2 scene id (another PGSR output with a mesh stays an INRIA folder)."""
    if not is_inria_output(folder):
        return False
    return find_release_boxes(folder) is not None or ((folder / MESH_FILE).is_file() and RELEASE_SCENE_ID.fullmatch(folder.name) is not None)


# --------------------------------------------------------------------------- COCO RLE
def _counts_from_string(text: str) -> list[int]:
    """The run lengths of COCO's compressed counts string (5-bit groups, continuation bit 0x20,
    sign-extended, each count after the second stored as a difference to the count two before)."""
    counts: list[int] = []
    pos = 0
    while pos < len(text):
        value, shift, more = 0, 0, True
        while more:
            if pos >= len(text):
                raise ValueError("the string ends inside a count")
            code = ord(text[pos]) - 48
            if not 0 <= code < 64:
                raise ValueError(f"character {text[pos]!r} at {pos} is outside COCO's alphabet ('0'..'o')")
            value |= (code & 0x1F) << shift
            more = bool(code & 0x20)
            pos += 1
            shift += 5
            if not more and code & 0x10:
                value |= -1 << shift
        if len(counts) > 2:
            value += counts[-2]
        counts.append(value)
    return counts


def rle_run_lengths(encoding: Any) -> tuple[tuple[int, int], list[int]]:
    """``((height, width), run lengths)`` of one COCO RLE, checked: the runs are >= 0 and cover
    ``height × width`` pixels exactly. Raises ``ValueError`` with the reason."""
    if not isinstance(encoding, Mapping) or "size" not in encoding or "counts" not in encoding:
        raise ValueError("expected an object {'size': [height, width], 'counts': ...}")
    size = encoding["size"]
    if not (isinstance(size, list) and len(size) == 2 and all(isinstance(v, int) and not isinstance(v, bool) and 0 < v < 1 << 16 for v in size)):
        raise ValueError(f"'size' must be [height, width] (positive integers), got {size!r}")
    counts = encoding["counts"]
    if isinstance(counts, str):
        runs = _counts_from_string(counts)
    elif isinstance(counts, list) and all(isinstance(v, int) and not isinstance(v, bool) for v in counts):
        runs = list(counts)
    else:
        raise ValueError("'counts' must be COCO's compressed string or a list of run lengths")
    if any(v < 0 for v in runs):
        raise ValueError("a run length is negative")
    total = sum(runs)
    if total != size[0] * size[1]:
        raise ValueError(f"the runs cover {total} pixels, 'size' {size} has {size[0] * size[1]}")
    return (size[0], size[1]), runs


def decode_rle(encoding: Any) -> np.ndarray:
    """A COCO RLE as an (H, W) bool mask, decoded by pycocotools after :func:`rle_run_lengths` checked it."""
    from pycocotools import mask as coco_mask

    (height, width), runs = rle_run_lengths(encoding)
    counts = encoding["counts"]
    rle = {"size": [height, width], "counts": counts.encode("ascii") if isinstance(counts, str) else None}
    with warnings.catch_warnings():  # pycocotools 2.0.x's decode warns under NumPy 2 (the copy keyword)
        warnings.simplefilter("ignore", DeprecationWarning)
        if rle["counts"] is None:
            rle = coco_mask.frPyObjects({"size": [height, width], "counts": runs}, height, width)
        return coco_mask.decode(rle).astype(bool)


def _encodings_of(where: str, item: Any) -> dict[str, Any]:
    if not isinstance(item, dict) or "mask_encodings" not in item:
        return {}
    images, encodings = item.get("images", []), item["mask_encodings"]
    if not isinstance(encodings, list) or not isinstance(images, list):
        raise FileFormatError(f"{where}: 'mask_encodings' and 'images' must be lists (one RLE per mask path)")
    if encodings and len(encodings) != len(images):
        raise FileValueError(
            f"{where}: {len(encodings)} 'mask_encodings' for {len(images)} 'images'; Holi-Spatial writes one RLE per mask path, "
            "in the same order"
        )
    out = {}
    for k, (ref, enc) in enumerate(zip(images, encodings)):
        try:
            rle_run_lengths(enc)
        except ValueError as err:
            raise FileValueError(f"{where}: mask_encodings[{k}] (mask {ref!r}) is not a valid COCO RLE: {err}") from None
        out[str(ref)] = enc
    return out


def read_mask_encodings(path: PathLike, data: Any = None) -> dict[int, dict[str, Any]]:
    """Instance id → {mask path as written → COCO RLE}, every RLE checked (:func:`rle_run_lengths`);
    ``data``: the box JSON already parsed (read from ``path`` when ``None``).

    Raises:
        FileValueError: a malformed RLE or a count mismatch, naming the file, the instance and the mask.
    """
    p = as_path(path, "Holi-Spatial box JSON")
    data = read_json(p, "Holi-Spatial box JSON") if data is None else data
    items = data.get("instances", []) if isinstance(data, dict) else data
    out: dict[int, dict[str, Any]] = {}
    for index, item in enumerate(items if isinstance(items, list) else []):
        raw = item.get("ins_id", item.get("id", item.get("instance_id"))) if isinstance(item, dict) else None
        where = f"{p}: instance [{index}] (ins_id {raw!r})"
        found = _encodings_of(where, item)
        if found and raw is not None:
            out[int(str(raw).strip())] = found
    return out


class RleMasks:
    """The mask source of :func:`~spacedg.scene.labelling.assign_instances` for RLE masks: called
    with ``(instance id, mask path as written)``, it returns the decoded (H, W) bool mask, or ``None``
    when the instance has no RLE for that path.

    Args:
        path: the box JSON (for messages).
        encodings: :func:`read_mask_encodings` of it.
        views: view name → ``(width, height)``, to refuse a mask whose aspect ratio differs from its view's.
        view_of: mask path → view name (the instances' ``attributes["masks"]`` inverted).
    """

    def __init__(self, path: PathLike, encodings: Mapping[int, Mapping[str, Any]], views: Mapping[str, tuple[int, int]],
                 view_of: Mapping[str, str]) -> None:
        self.path, self.encodings, self.views, self.view_of = str(path), encodings, views, view_of

    @property
    def count(self) -> int:
        """Number of RLE masks held."""
        return sum(len(v) for v in self.encodings.values())

    def __call__(self, instance_id: int, mask_path: str) -> np.ndarray | None:
        enc = self.encodings.get(instance_id, {}).get(mask_path)
        if enc is None:
            return None
        mask = decode_rle(enc)
        view = self.view_of.get(mask_path)
        if view in self.views:
            width, height = self.views[view]
            if abs(mask.shape[1] / mask.shape[0] - width / height) > ASPECT_TOL * width / height:
                raise FileValueError(
                    f"{self.path}: instance {instance_id}, mask {PurePath(mask_path).name!r} of view {view!r} is "
                    f"{mask.shape[1]}×{mask.shape[0]} but the view is {width}×{height} (another aspect ratio): the mask was "
                    "made on other images than these cameras'"
                )
        return mask


def rle_masks(path: PathLike, instances: Iterable[Any], views: Mapping[str, Any], *, data: Any = None) -> RleMasks:
    """:class:`RleMasks` for the box JSON ``path`` (``data``: already parsed) and the read ``instances`` (with
    ``attributes["masks"]``)."""
    view_of = {}
    for inst in instances:
        for view, ref in (inst.attributes.get("masks") or {}).items():
            view_of[str(ref)] = str(view)
    sizes = {name: (int(cam.width), int(cam.height)) for name, cam in views.items()}
    return RleMasks(path, read_mask_encodings(path, data), sizes, view_of)

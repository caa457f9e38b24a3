"""EmbodiedScan 9-DoF boxes from a JSON export of its annotation infos.

EmbodiedScan ships ``embodiedscan_infos_*.pkl`` (mmengine): ``{"metainfo": {"categories":
{name: id}}, "data_list": [{"sample_idx": "scannet/scene0000_00", "instances": [{"bbox_3d":
[9], "bbox_label_3d": int, "bbox_id": int}, ...], ...}]}``. spacedg reads that structure as
JSON (``json.dump`` of the loaded pickle; spacedg never unpickles files): the whole infos
object (pick the scene with ``sample_idx``), one ``data_list`` entry, or a bare list of
instances. A per-instance ``"label"`` string is used when present, else the category name of
``bbox_label_3d`` from ``metainfo.categories``.

``bbox_3d = [x, y, z, x_size, y_size, z_size, α, β, γ]``: the box **centre** (metres),
full side lengths along the box's own axes, and Euler angles (radians) in EmbodiedScan's
``"ZXY"`` convention: ``R = R_z(α) · R_x(β) · R_y(γ)`` (pytorch3d's
``euler_angles_to_matrix(angles, "ZXY")``), whose columns are the box axes in the world.
The world is the one of EmbodiedScan's poses for that scan (for ScanNet, the axis-aligned
ScanNet frame): the importer's frame check tells when it is not the Gaussians' frame.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from spacedg.errors import FileFormatError, InvalidDataError
from spacedg.files import FileValueError, PathLike, as_path, read_json
from spacedg.scene.box import OrientedBox
from spacedg.scene.io.fields import instance_list
from spacedg.scene.io.annotation_limits import check_box_size, check_instance_id
from spacedg.scene.model import Instance

__all__ = ["read_embodiedscan_boxes", "euler_zxy_to_matrix"]


def euler_zxy_to_matrix(angles: np.ndarray) -> np.ndarray:
    """``R_z(a0) · R_x(a1) · R_y(a2)`` for angles (radians), shape (..., 3) → (..., 3, 3)."""
    a = np.asarray(angles, dtype=np.float64)
    c, s = np.cos(a), np.sin(a)
    one, zero = np.ones_like(a[..., 0]), np.zeros_like(a[..., 0])
    rz = np.stack([np.stack([c[..., 0], -s[..., 0], zero], -1), np.stack([s[..., 0], c[..., 0], zero], -1), np.stack([zero, zero, one], -1)], -2)
    rx = np.stack([np.stack([one, zero, zero], -1), np.stack([zero, c[..., 1], -s[..., 1]], -1), np.stack([zero, s[..., 1], c[..., 1]], -1)], -2)
    ry = np.stack([np.stack([c[..., 2], zero, s[..., 2]], -1), np.stack([zero, one, zero], -1), np.stack([-s[..., 2], zero, c[..., 2]], -1)], -2)
    return rz @ rx @ ry


def _entry(p: object, data: Any, scene: str | None) -> tuple[list[Any], dict[str, int]]:
    categories: dict[str, int] = {}
    if isinstance(data, dict) and "data_list" in data:
        meta = data.get("metainfo", {})
        raw = meta.get("categories", {}) if isinstance(meta, dict) else {}
        if not isinstance(raw, dict):
            raise FileFormatError(f"{p}: 'metainfo.categories' must be an object (label → class index), got {type(raw).__name__}")
        categories = dict(raw)
        entries = data["data_list"]
        if not isinstance(entries, list) or not entries:
            raise FileFormatError(f"{p}: 'data_list' must be a non-empty list")
        if scene is not None:
            picked = [e for e in entries if isinstance(e, dict) and str(e.get("sample_idx", "")).split("/")[-1] == scene]
            if not picked:
                known = [str(e.get("sample_idx")) for e in entries[:5] if isinstance(e, dict)]
                raise FileFormatError(f"{p}: no data_list entry with sample_idx ending in {scene!r} (e.g. {known})")
            data = picked[0]
        elif len(entries) == 1:
            data = entries[0]
        else:
            raise FileFormatError(f"{p}: {len(entries)} scans in data_list; name one (scene=..., the end of its sample_idx)")
    return instance_list(p, data, "'instances' (EmbodiedScan info entry), 'data_list', or a list of instances"), categories


def read_embodiedscan_boxes(path: PathLike, scene: str | None = None, *, data: Any = None) -> list[Instance]:
    """Instances from EmbodiedScan 9-DoF boxes (see the module docstring).

    Args:
        path: the JSON file.
        scene: with several scans in ``data_list``, the one whose ``sample_idx`` ends with it.
        data: the file's content already parsed (it is then not read again).

    Raises:
        FileFormatError: unknown layout, malformed boxes, labels that cannot be named, duplicate ids.
    """
    p = as_path(path, "EmbodiedScan JSON")
    items, categories = _entry(p, read_json(p, "EmbodiedScan JSON") if data is None else data, scene)
    names = {int(v): str(k) for k, v in categories.items() if isinstance(v, int)}
    out: list[Instance] = []
    seen: set[int] = set()
    for index, item in enumerate(items):
        where = f"{p}: instances[{index}]"
        if not isinstance(item, dict) or "bbox_3d" not in item:
            raise FileFormatError(f"{where}: expected an object with 'bbox_3d' (9 numbers)")
        try:
            box = np.array(item["bbox_3d"], dtype=np.float64).reshape(9)
        except (TypeError, ValueError):
            raise FileFormatError(f"{where}: 'bbox_3d' must be 9 numbers [x, y, z, x_size, y_size, z_size, α, β, γ]") from None
        if not np.isfinite(box).all():
            raise FileValueError(f"{where}: 'bbox_3d' holds NaN or Inf")
        iid = item.get("bbox_id", index)
        if isinstance(iid, bool) or not isinstance(iid, int) or iid < 0 or iid in seen:
            raise FileValueError(f"{where}: 'bbox_id' must be a unique integer >= 0, got {iid!r}")
        check_instance_id(where, "bbox_id", iid)
        seen.add(iid)
        label = item.get("label")
        if not isinstance(label, str) or not label.strip():
            code = item.get("bbox_label_3d")
            label = names.get(code) if isinstance(code, int) else None
            if label is None:
                raise FileFormatError(f"{where}: no 'label' and bbox_label_3d {code!r} is not in metainfo.categories")
        try:
            obb = OrientedBox(box[:3], box[3:6], euler_zxy_to_matrix(box[6:9]))
        except InvalidDataError as err:
            raise FileValueError(f"{where}: {err}") from err
        out.append(Instance(iid, label.strip(), "", check_box_size(f"{where} (id {iid})", obb), attributes={"source": "embodiedscan"}))
    return out

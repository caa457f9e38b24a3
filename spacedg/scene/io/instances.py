"""Instance annotation JSON (Holi-Spatial style): labelled oriented 3D boxes.

Accepted layout: a JSON list of instances, or an object ``{"instances": [...]}``. Each
instance is an object with:

- ``id`` (or ``instance_id``, or Holi-Spatial's ``ins_id``): integer >= 0 (a string of
  digits, as Holi-Spatial writes it, is accepted), unique in the file.
- ``label`` (or ``category``): category word.
- ``description`` (optional, default ``""``): view-invariant description.
- the box, either
  - ``obb_transform`` (4×4 local-to-world, rigid) + ``obb_extents`` (3 **full** side
    lengths), or
  - 8 corners in any order under ``corners``, ``bbox_corners``, ``obb_corners`` or
    ``bounding_box`` (Holi-Spatial), each ``[x, y, z]`` or ``{"x", "y", "z"}``.
  A reflected ``obb_transform`` (det −1, as ``trimesh.bounds.oriented_bounds`` may return)
  describes the same box and is turned into a rotation.
  When both are present they must describe the same box (the transform is used).
- ``images`` (or ``visible_images``, optional): the views the object was annotated in. With
  ``views`` given, each reference is resolved to a view name: the exact name, else the same
  file name, else the same file stem (INRIA names views by stem), else the **parent folder**
  of a mask file (Holi-Spatial writes mask paths ``<mask_root>/<image stem>/<label>.png``);
  such mask paths are kept in ``attributes["masks"]`` (view → path as written).
- ``best_image`` / ``best_view`` / ``highest_confidence_mask`` (optional): stored in
  ``attributes["best_image"]`` (resolved the same way).
- ``mask_encodings`` (Holi-Spatial's COCO RLE masks, one per ``images`` entry) are not read here:
  :mod:`spacedg.scene.io.holispatial` reads and checks them for the importer's mask voting.
- ``attributes`` (optional object) and ``visibility`` (optional, as written by
  :func:`write_instances`) are kept.

Units are those of the file (metres for spacedg scenes; ``scene_from_files`` scales).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import replace
from pathlib import PurePath
from typing import Any

import numpy as np

from spacedg.errors import FileFormatError, InvalidDataError
from spacedg.files import (
    FileValueError,
    PathLike,
    as_path,
    atomic_write,
    dump_json,
    read_json,
)
from spacedg.scene.box import OrientedBox
from spacedg.scene.io.fields import instance_list, matrix_field
from spacedg.scene.io.annotation_limits import check_box_size, check_coordinates, check_instance_id
from spacedg.scene.model import Instance, InstanceVisibility

_CORNER_KEYS = ("corners", "bbox_corners", "obb_corners", "bounding_box")
_IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".npy")
#: Largest disagreement between given corners and obb_transform/extents, relative to the box diagonal.
CORNER_AGREEMENT_TOL = 1e-4


def _first_key(item: Mapping[str, Any], keys: Sequence[str]) -> str | None:
    for key in keys:
        if key in item:
            return key
    return None


def _box(where: str, item: Mapping[str, Any]) -> OrientedBox:
    corner_key = _first_key(item, _CORNER_KEYS)
    has_transform = "obb_transform" in item or "obb_extents" in item
    if not has_transform and corner_key is None:
        raise FileFormatError(
            f"{where}: no box; give 'obb_transform' (4×4) + 'obb_extents' (3 full side lengths) or 8 'corners'"
        )
    try:
        box = None
        if has_transform:
            for key in ("obb_transform", "obb_extents"):
                if key not in item:
                    raise FileFormatError(f"{where}: '{key}' is missing; 'obb_transform' and 'obb_extents' go together")
            transform = matrix_field(where, "obb_transform", item["obb_transform"], (4, 4))
            if not np.allclose(transform[3], [0.0, 0.0, 0.0, 1.0], atol=1e-9):
                raise FileValueError(f"{where}: 'obb_transform' last row must be [0, 0, 0, 1], got {transform[3].tolist()}")
            extents = matrix_field(where, "obb_extents", item["obb_extents"], (3,))
            box = OrientedBox.from_transform(transform, extents)  # a reflection becomes a rotation
        if corner_key is not None:
            raw = item[corner_key]
            if isinstance(raw, list) and raw and all(isinstance(c, dict) for c in raw):
                try:
                    raw = [[c["x"], c["y"], c["z"]] for c in raw]
                except KeyError:
                    raise FileFormatError(f"{where}: '{corner_key}' corners must each have 'x', 'y' and 'z'") from None
            corners = check_coordinates(where, corner_key, matrix_field(where, corner_key, raw, (8, 3)))
            from_corners = OrientedBox.from_corners(corners)
            if box is None:
                check_box_size(where, from_corners)
                return from_corners
            diag = float(np.linalg.norm(box.extents)) or 1.0
            dist = np.linalg.norm(box.corners()[:, None, :] - corners[None, :, :], axis=2)
            gap = float(max(dist.min(axis=0).max(), dist.min(axis=1).max()))
            if gap > CORNER_AGREEMENT_TOL * diag:
                raise FileValueError(
                    f"{where}: '{corner_key}' and 'obb_transform'/'obb_extents' describe different boxes "
                    f"(corners differ by {gap:.3g}); keep one of them"
                )
        assert box is not None
        check_box_size(where, box)
        return box
    except FileFormatError:
        raise
    except InvalidDataError as err:
        hint = " ('obb_transform' must be rigid: put the side lengths in 'obb_extents', not in the matrix)" if has_transform else ""
        raise FileValueError(f"{where}: {err}{hint}") from err


def _names(where: str, key: str, value: Any) -> tuple[str, ...]:
    if not isinstance(value, list) or not all(isinstance(v, str) and v for v in value):
        raise FileFormatError(f"{where}: '{key}' must be a list of view names (non-empty strings)")
    return tuple(value)


def _instance(where: str, item: Any) -> Instance:
    if not isinstance(item, dict):
        raise FileFormatError(f"{where}: expected an object, got {type(item).__name__}")
    id_key = _first_key(item, ("id", "instance_id", "ins_id"))
    if id_key is None:
        raise FileFormatError(f"{where}: missing 'id' (or 'instance_id' / 'ins_id')")
    inst_id = item[id_key]
    if isinstance(inst_id, str) and inst_id.strip().isdigit():
        inst_id = int(inst_id.strip())
    if isinstance(inst_id, bool) or not isinstance(inst_id, int) or inst_id < 0:
        raise FileValueError(f"{where}: '{id_key}' must be an integer >= 0 (or a string of digits), got {inst_id!r}")
    check_instance_id(where, id_key, inst_id)
    where = f"{where} (id {inst_id})"
    label_key = _first_key(item, ("label", "category"))
    if label_key is None:
        raise FileFormatError(f"{where}: missing 'label' (or 'category')")
    label = item[label_key]
    if not isinstance(label, str) or not label.strip():
        raise FileValueError(f"{where}: '{label_key}' must be a non-empty string, got {label!r}")
    description = item.get("description", "")
    if not isinstance(description, str):
        raise FileValueError(f"{where}: 'description' must be a string, got {type(description).__name__}")
    image_key = _first_key(item, ("images", "visible_images"))
    images = _names(where, image_key, item[image_key]) if image_key else ()
    attributes = item.get("attributes", {})
    if not isinstance(attributes, dict):
        raise FileFormatError(f"{where}: 'attributes' must be an object, got {type(attributes).__name__}")
    attributes = dict(attributes)
    best_key = _first_key(item, ("best_image", "best_view", "highest_confidence_mask"))
    if best_key is not None:
        best = item[best_key]
        if not isinstance(best, str) or not best:
            raise FileFormatError(f"{where}: '{best_key}' must be a view name, got {best!r}")
        attributes["best_image"] = best
    visibility = _visibility(where, item.get("visibility", {}))
    return Instance(inst_id, label, description, _box(where, item), images, visibility, attributes)


def _visibility(where: str, value: Any) -> dict[str, InstanceVisibility]:
    if not isinstance(value, dict):
        raise FileFormatError(f"{where}: 'visibility' must be an object of view → {{visible_pixels, visible_fraction}}")
    out = {}
    for view, record in value.items():
        if not isinstance(record, dict) or set(record) != {"visible_pixels", "visible_fraction"}:
            raise FileFormatError(f"{where}: visibility[{view!r}] must be {{'visible_pixels': int, 'visible_fraction': float}}")
        try:
            out[view] = InstanceVisibility(**record)
        except (InvalidDataError, TypeError, ValueError) as err:
            raise FileValueError(f"{where}: visibility[{view!r}]: {err}") from err
    return out


class _ViewResolver:
    """Maps an image reference to a view name (see the module docstring for the rules)."""

    def __init__(self, views: Iterable[str]) -> None:
        self.known = set(views)
        self.by_name: dict[str, set[str]] = {}
        self.by_stem: dict[str, set[str]] = {}
        for view in self.known:
            name = PurePath(view).name
            self.by_name.setdefault(name, set()).add(view)
            self.by_stem.setdefault(name.rsplit(".", 1)[0] if "." in name else name, set()).add(view)

    @staticmethod
    def _one(found: set[str] | None) -> str | None:
        return next(iter(found)) if found is not None and len(found) == 1 else None

    def __call__(self, ref: str) -> tuple[str | None, bool]:
        """``(view or None, is_mask_path)``."""
        if ref in self.known:
            return ref, False
        path = PurePath(ref.replace("\\", "/"))
        view = self._one(self.by_name.get(path.name)) or self._one(self.by_stem.get(path.stem))
        if view is not None:
            return view, False
        if path.suffix.lower() in _IMAGE_SUFFIXES and path.parent.name:
            view = self._one(self.by_stem.get(path.parent.name))
            if view is not None:
                return view, True
        return None, False


def _resolve_views(path: str, instances: list[Instance], views: Iterable[str]) -> list[Instance]:
    resolve = _ViewResolver(views)
    known = resolve.known
    unknown: list[tuple[int, str]] = []
    out = []
    for inst in instances:
        images: list[str] = []
        masks: dict[str, str] = dict(inst.attributes.get("masks", {}) or {})
        for ref in inst.images:
            view, is_mask = resolve(ref)
            if view is None:
                unknown.append((inst.id, ref))
                continue
            if view not in images:
                images.append(view)
            if is_mask:
                masks.setdefault(view, ref)
        attributes = dict(inst.attributes)
        best = attributes.get("best_image")
        if isinstance(best, str):
            view, _ = resolve(best)
            if view is None:
                unknown.append((inst.id, best))
            else:
                attributes["best_image"] = view
        unknown += [(inst.id, n) for n in inst.visibility if n not in known]
        if masks:
            attributes["masks"] = masks
        out.append(replace(inst, images=tuple(images), attributes=attributes))
    if unknown:
        shown = ", ".join(f"{name!r} (instance {iid})" for iid, name in unknown[:5])
        raise FileValueError(
            f"{path}: {len(unknown)} image reference(s) name views the scene does not have, e.g. {shown}; "
            f"known views are e.g. {sorted(known)[:5]}. Check that the annotation and the cameras come from the same capture "
            "(references are matched by name, file name, file stem, or a mask file's parent folder)"
        )
    return out


def read_instances(path: PathLike, views: Iterable[str] | None = None, *, data: Any = None) -> list[Instance]:
    """Read annotated instances (see the module docstring for the accepted layout).

    Args:
        path: the JSON file.
        views: if given, the scene's view names; every image the annotation names must resolve
            to one of them (name, file name, stem, or a mask file's parent folder).
        data: the file's JSON already parsed (the importer parses a box file once); read from ``path`` when ``None``.

    Raises:
        FileFormatError: bad JSON (line and column named), missing id/label/box, malformed
            fields, duplicate ids, image names not in ``views``.
    """
    p = as_path(path, "instance JSON")
    data = instance_list(p, read_json(p, "instance JSON") if data is None else data, "a list of instances or an object with an 'instances' list")
    instances = [_instance(f"{p}: instance [{i}]", item) for i, item in enumerate(data)]
    dup = sorted(i for i, n in Counter(inst.id for inst in instances).items() if n > 1)
    if dup:
        raise FileValueError(f"{p}: instance ids {dup[:10]} are used more than once; ids must be unique")
    if views is not None:
        instances = _resolve_views(str(p), instances, views)
    return instances


def instance_record(inst: Instance) -> dict[str, Any]:
    """The JSON record :func:`write_instances` writes for one instance."""
    transform = np.eye(4)
    transform[:3, :3] = inst.box.rotation
    transform[:3, 3] = inst.box.center
    out: dict[str, Any] = {
        "id": inst.id,
        "label": inst.label,
        "description": inst.description,
        "obb_transform": transform.tolist(),
        "obb_extents": inst.box.extents.tolist(),
        "corners": inst.box.corners().tolist(),
        "images": list(inst.images),
    }
    if inst.attributes:
        out["attributes"] = dict(inst.attributes)
    if inst.visibility:
        out["visibility"] = {view: vis.to_dict() for view, vis in inst.visibility.items()}
    return out


def write_instances(path: PathLike, instances: Iterable[Instance]) -> None:
    """Write instances as ``{"format": "spacedg-instances", "version": 1, "instances": [...]}``, atomically.

    Each record has ``obb_transform`` + ``obb_extents`` (exact) and ``corners`` (for other
    tools), plus id, label, description, images, attributes and visibility.
    """
    items = list(instances)
    for item in items:
        if not isinstance(item, Instance):
            raise InvalidDataError(f"write_instances: expected Instance objects, got {type(item).__name__}")
    text = dump_json({"format": "spacedg-instances", "version": 1, "instances": [instance_record(i) for i in items]})
    with atomic_write(path, "w") as handle:
        handle.write(text)

"""Instance JSON: both box forms, aliases, view checks, errors, writer round trip."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from spacedg.scene.box import OrientedBox
from spacedg.scene.io import FileValueError, read_instances, write_instances
from spacedg.scene.model import Instance, InstanceVisibility
from spacedg.errors import FileFormatError


def rotation_z(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


BOX = OrientedBox(center=[1.0, 2.0, 0.5], extents=[0.8, 0.4, 1.0], rotation=rotation_z(0.3))


def transform_of(box: OrientedBox) -> list[list[float]]:
    t = np.eye(4)
    t[:3, :3] = box.rotation
    t[:3, 3] = box.center
    return t.tolist()


def write(path: Path, data: Any) -> Path:
    path.write_text(json.dumps(data, indent=1))
    return path


def test_corners_in_any_order(tmp_path: Path) -> None:
    corners = BOX.corners()[np.random.default_rng(0).permutation(8)]
    items = [
        {"id": 3, "label": "chair", "description": "a red wooden chair", "bbox_corners": corners.tolist(), "images": ["v1", "v2"]},
        {"instance_id": 4, "category": "lamp", "obb_corners": BOX.corners().tolist(), "visible_images": ["v2"], "best_view": "v2"},
    ]
    got = read_instances(write(tmp_path / "i.json", items), views=["v1", "v2", "v3"])
    assert [i.id for i in got] == [3, 4] and [i.label for i in got] == ["chair", "lamp"]
    assert got[0].description == "red wooden chair" and got[1].description == ""
    assert got[0].images == ("v1", "v2") and got[1].images == ("v2",)
    assert got[1].attributes == {"best_image": "v2"}
    for inst in got:
        np.testing.assert_allclose(inst.box.center, BOX.center, atol=1e-12)
        np.testing.assert_allclose(np.sort(inst.box.extents), np.sort(BOX.extents), atol=1e-12)
        assert inst.box.volume == pytest.approx(BOX.volume)
        assert inst.box.contains(BOX.corners(), tol=1e-9).all()


def test_transform_and_extents(tmp_path: Path) -> None:
    items = {"instances": [{"id": 0, "label": "table", "obb_transform": transform_of(BOX), "obb_extents": BOX.extents.tolist()}]}
    (inst,) = read_instances(write(tmp_path / "i.json", items))
    np.testing.assert_array_equal(inst.box.center, BOX.center)
    np.testing.assert_array_equal(inst.box.extents, BOX.extents)  # full side lengths, not halves
    np.testing.assert_array_equal(inst.box.rotation, BOX.rotation)
    assert inst.images == ()


def test_writer_round_trip(tmp_path: Path) -> None:
    instances = [
        Instance(1, "chair", "a chair", BOX, ("a", "b"), {"a": InstanceVisibility(120, 0.25)}, {"colour": "red", "best_image": "a"}),
        Instance(7, "sofa", "", OrientedBox([0, 0, 0], [2, 1, 0.0])),
    ]
    path = tmp_path / "out.json"
    write_instances(path, instances)
    raw = json.loads(path.read_text())
    assert raw["format"] == "spacedg-instances" and set(raw["instances"][0]) >= {"obb_transform", "obb_extents", "corners"}
    back = read_instances(path, views=["a", "b"])
    for a, b in zip(instances, back, strict=True):
        assert a.to_dict() == b.to_dict()
    assert [p.name for p in tmp_path.iterdir()] == ["out.json"]  # no temporary files left


def test_corners_and_transform_must_agree(tmp_path: Path) -> None:
    other = OrientedBox(BOX.center + 0.5, BOX.extents, BOX.rotation)
    item = {"id": 0, "label": "x", "obb_transform": transform_of(BOX), "obb_extents": BOX.extents.tolist(), "corners": other.corners().tolist()}
    with pytest.raises(FileValueError, match="describe different boxes"):
        read_instances(write(tmp_path / "i.json", [item]))


def test_unknown_views_listed(tmp_path: Path) -> None:
    items = [{"id": i, "label": "cup", "corners": BOX.corners().tolist(), "images": [f"frame_{i}", "v1"]} for i in range(8)]
    with pytest.raises(FileValueError, match=r"8 image reference\(s\).*'frame_0' \(instance 0\).*known views are e.g. \['v1'\]"):
        read_instances(write(tmp_path / "i.json", items), views=["v1"])


@pytest.mark.parametrize(
    ("item", "error", "match"),
    [
        ({"id": 0, "label": "x"}, FileFormatError, "no box"),
        ({"id": 0, "label": "x", "corners": [[0, 0, 0]] * 7}, FileFormatError, r"shape \(8, 3\)"),
        ({"id": 0, "label": "x", "corners": (BOX.corners() + np.random.default_rng(1).normal(0, 0.2, (8, 3))).tolist()}, FileValueError, "do not form a box"),
        ({"id": 0, "label": "x", "obb_transform": transform_of(BOX)}, FileFormatError, "'obb_extents' is missing"),
        ({"id": 0, "label": "x", "obb_transform": (2 * np.eye(4)).tolist(), "obb_extents": [1, 1, 1]}, FileValueError, "last row"),
        ({"id": 0, "label": "x", "obb_transform": np.diag([2.0, 1, 1, 1]).tolist(), "obb_extents": [1, 1, 1]}, FileValueError, "must be rigid"),
        ({"id": 0, "label": "x", "obb_transform": transform_of(BOX), "obb_extents": [1, -1, 1]}, FileValueError, "extents"),
        ({"id": 0, "corners": BOX.corners().tolist()}, FileFormatError, "missing 'label'"),
        ({"id": 0, "label": "  ", "corners": BOX.corners().tolist()}, FileValueError, "non-empty string"),
        ({"label": "x", "corners": BOX.corners().tolist()}, FileFormatError, "missing 'id'"),
        ({"id": -2, "label": "x", "corners": BOX.corners().tolist()}, FileValueError, "integer >= 0"),
        ({"id": "3a", "label": "x", "corners": BOX.corners().tolist()}, FileValueError, "integer >= 0"),
        ({"id": 0, "label": "x", "corners": BOX.corners().tolist(), "images": "v1"}, FileFormatError, "list of view names"),
        ({"id": 0, "label": "x", "corners": BOX.corners().tolist(), "description": 5}, FileValueError, "description"),
        ("not an object", FileFormatError, "expected an object"),
    ],
)
def test_bad_items(tmp_path: Path, item: Any, error: type, match: str) -> None:
    path = write(tmp_path / "i.json", [item])
    with pytest.raises(error, match=match) as info:
        read_instances(path)
    assert str(path) in str(info.value) and "instance [0]" in str(info.value)


def test_duplicate_ids(tmp_path: Path) -> None:
    items = [{"id": i % 2, "label": "x", "corners": BOX.corners().tolist()} for i in range(3)]
    with pytest.raises(FileValueError, match=r"ids \[0\] are used more than once"):
        read_instances(write(tmp_path / "i.json", items))


def test_bad_layout(tmp_path: Path) -> None:
    """(Broken JSON and missing files: tests/scene/io/test_json_readers.py, for every JSON reader.)"""
    path = tmp_path / "i.json"
    with pytest.raises(FileFormatError, match="'instances' list"):
        read_instances(write(path, {"objects": []}))
    with pytest.raises(FileFormatError, match="must be a list"):
        read_instances(write(path, {"instances": 5}))
    path.write_bytes(b"\xff\xfe[]")
    with pytest.raises(FileFormatError, match="not UTF-8"):
        read_instances(path)
    assert read_instances(write(path, [])) == []

"""Boxes must hold their objects (issue 28 item 3) and hostile annotations stay clear errors (item 5).

Captures are written in published layouts (INRIA output + COLMAP model + Holi-Spatial JSON) by
tests/scene/capture_layouts.py and imported through the real readers.
"""

from __future__ import annotations

import json
import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from spacedg.errors import FileValueError
from spacedg.scene.box_fill import BoxFillError, measure_box_fill
from spacedg.scene.frame_check import normalised_hint
from spacedg.scene.importer import import_scene
from spacedg.scene.io.instances import read_instances
from spacedg.scene.model import Scene
from tests.scene import capture_layouts as cl

CUP = 16  # a cup on the table of truth_room(seed=5)
SHIFT = np.array([0.0, -0.07, 0.0])  # 7 cm


@pytest.fixture(scope="module")
def room():
    return cl.truth_room(seed=5, gaussians=20_000, views=8)


@pytest.fixture(scope="module")
def capture(tmp_path_factory, room) -> Path:
    root = tmp_path_factory.mktemp("capture")
    return cl.write_inria_output(root, room)


def _moved(room, ids: set[int] | None, shift: np.ndarray):
    insts = [replace(i, box=i.box.transformed(np.eye(3), shift)) if ids is None or i.id in ids else i for i in room.instances]
    return Scene(room.id, room.gaussians, room.views, insts, room.up, room.vocabulary, room.metadata)


def _write_holi(path: Path, scene) -> Path:
    path.write_text(json.dumps(cl.holi_spatial_json(scene, {})))
    return path


def _shift_in(message: str, box: int) -> np.ndarray:
    match = re.search(rf"box {box} '[^']+' is [\w ]+ \(.*?moving it by \(([-+.\d]+), ([-+.\d]+), ([-+.\d]+)\)", message)
    assert match, message
    return np.array([float(v) for v in match.groups()])


@pytest.mark.parametrize("seed", [1, 3, 5, 7])
def test_correct_boxes_are_all_ok(seed: int) -> None:
    room = cl.truth_room(seed=seed)
    report = measure_box_fill(room.gaussians.means, room.instances)
    assert report.bad == [] and report.holding == len(room.instances)
    assert all(0 < r.fill <= 1 for r in report.rows)


def test_a_box_moved_7cm_is_mostly_outside_and_the_shift_back_is_found(room) -> None:
    report = measure_box_fill(room.gaussians.means, _moved(room, {CUP}, SHIFT).instances)
    (bad,) = report.bad
    assert (bad.id, bad.label, bad.status) == (CUP, "cup", "outside")
    assert np.linalg.norm(np.array(bad.shift) + SHIFT) < 0.02
    assert bad.shifted_inside >= 2 * bad.inside


def test_summary_and_table_agree(room) -> None:
    moved = _moved(room, {CUP}, np.array([0.0, 0.0, 3.0]))  # far above the table: holds nothing
    report = measure_box_fill(room.gaussians.means, moved.instances)
    rows = [line.split() for line in report.table(limit=100).splitlines()[1:]]
    holding_in_table = sum(int(r[-5 if r[-1] == "-" else -9].replace(",", "")) > 0 for r in rows)
    summary = report.summary()
    assert f"boxes holding Gaussians {holding_in_table} of {len(rows)}" in summary
    assert report.holding == holding_in_table == len(room.instances) - 1
    assert report.table().splitlines()[1].split()[:2] == [str(CUP), "cup"]  # bad boxes come first
    text = report.text(limit=5)
    assert text.splitlines()[0] == summary and "... 19 more" in text and "empty" in text.splitlines()[2]


def test_import_of_a_correct_capture_reports_consistent_fill(tmp_path: Path, capture: Path, room) -> None:
    holi = _write_holi(tmp_path / "holi.json", room)
    _, report = import_scene(capture, None, instances=holi, up="+z", progress=False)
    fill = report.box_fill
    assert fill is not None and fill.bad == [] and fill.holding == len(room.instances)
    text = report.text()
    assert f"boxes holding Gaussians {fill.held_share:.0%}" in text  # the frame-check line
    assert f"box fill     boxes holding Gaussians {fill.holding} of {len(room.instances)}" in text
    assert report.frame.boxes_with_gaussians == fill.held_share
    assert report.to_dict()["box_fill"]["holding"] == fill.holding


def test_import_refuses_a_box_moved_7cm_naming_it_and_the_shift(tmp_path: Path, capture: Path, room) -> None:
    holi = _write_holi(tmp_path / "holi.json", _moved(room, {CUP}, SHIFT))
    with pytest.raises(BoxFillError) as err:
        import_scene(capture, tmp_path / "scene", instances=holi, up="+z", progress=False)
    message = str(err.value)
    assert "box 16 'cup' is mostly outside its object" in message and "holi.json" in message
    assert np.linalg.norm(_shift_in(message, CUP) + SHIFT) < 0.02
    assert "correct their position" in message and "--allow-frame-mismatch" in message
    assert not (tmp_path / "scene").exists()
    # written anyway when asked, with the bad box in the table and the notes
    _, report = import_scene(capture, None, instances=holi, up="+z", progress=False, frame_check="warn")
    assert "BOXES NOT HOLDING THEIR OBJECTS" in report.text() and "outside" in report.box_fill.table()


def test_boxes_far_away_name_causes_of_the_layout(tmp_path: Path, capture: Path, room) -> None:
    holi = _write_holi(tmp_path / "holi.json", _moved(room, None, np.array([5.0, 0.0, 0.0])))
    with pytest.raises(BoxFillError) as err:
        import_scene(capture, None, instances=holi, up="+z", progress=False)
    message = str(err.value)
    assert "dataparser" not in message and "normalised" not in message
    assert "another reconstruction" in message and "COLMAP / INRIA" in message
    assert "of 24 boxes do not hold their objects" in message



def test_normalised_frame_hint_only_where_a_splatfacto_export_can_be(room) -> None:
    small = Scene(room.id, room.gaussians.transformed(scale=0.1), room.views, room.instances, room.up)
    assert normalised_hint(room) is None
    assert "normalised frame" in (normalised_hint(small) or "")
    assert "normalised frame" in (normalised_hint(small, layout="nerfstudio") or "")
    assert normalised_hint(small, layout="inria") is None and normalised_hint(small, layout="colmap") is None
    assert "normalised frame" in (normalised_hint(small, layout="inria", gaussians_given=True) or "")


# ----------------------------------------------------------------------------- hostile annotations
def _record(**changes) -> dict:
    base = {"id": 1, "label": "cup", "obb_transform": np.eye(4).tolist(), "obb_extents": [0.1, 0.1, 0.1]}
    base.update(changes)
    return base


@pytest.mark.parametrize("changes, pattern", [
    ({"id": 2**70}, r"instance \[0\]: 'id' a 22-digit number is out of range: instance ids are integers in \[0, 2147483647\]"),
    ({"ins_id": str(2**70)}, r"'ins_id' a 22-digit number is out of range.*renumber"),
    ({"id": 2**31}, r"'id' 2147483648 is out of range"),
    ({"obb_extents": [1e308, 1, 1]}, r"\(id 1\): box side lengths .* out of range.*at most 1e\+06 file units"),
    ({"obb_extents": [-0.1, 0.1, 0.1]}, r"\(id 1\): .*extents must be 3 finite full side lengths >= 0"),
    ({"obb_extents": [0, 0, 0]}, r"\(id 1\): box side lengths .* out of range"),
    ({"obb_extents": [float("nan"), 1, 1]}, r"\(id 1\): 'obb_extents' holds NaN or Inf"),
    ({"obb_extents": [float("inf"), 1, 1]}, r"\(id 1\): 'obb_extents' holds NaN or Inf"),
    ({"obb_transform": (np.diag([2.0, 1, 1, 1])).tolist()}, r"\(id 1\): .*'obb_transform' must be rigid"),
    ({"obb_transform": [[1, 0, 0, 1e300], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]}, r"box centre .* from the origin"),
])
def test_hostile_annotations_are_clear_errors(tmp_path: Path, changes: dict, pattern: str) -> None:
    record = _record(**changes)
    if "ins_id" in changes:
        del record["id"]
    path = tmp_path / "inst.json"
    path.write_text(json.dumps([record]))
    with pytest.raises(FileValueError, match=pattern) as err:
        read_instances(path)
    assert "inst.json" in str(err.value)


def test_largest_int32_id_is_accepted(tmp_path: Path) -> None:
    path = tmp_path / "inst.json"
    path.write_text(json.dumps([_record(id=2**31 - 1)]))
    assert read_instances(path)[0].id == 2**31 - 1


def test_import_with_a_2_to_70_id_is_a_clear_error(tmp_path: Path, capture: Path, room) -> None:
    records = cl.holi_spatial_json(room, {})
    records[3]["ins_id"] = str(2**70)
    (tmp_path / "holi.json").write_text(json.dumps(records))
    with pytest.raises(FileValueError, match=r"holi.json: instance \[3\]: 'ins_id' .* out of range"):
        import_scene(capture, None, instances=tmp_path / "holi.json", up="+z", progress=False)


def test_cli_exit_2_for_a_misplaced_box_and_info_prints_the_fill(tmp_path: Path, capture: Path, room, capsys) -> None:
    from spacedg.cli import main

    bad = _write_holi(tmp_path / "bad.json", _moved(room, {CUP}, SHIFT))
    assert main(["scenes", "import", str(capture), "--out", str(tmp_path / "s"), "--instances", str(bad), "--up", "+z"]) == 2
    assert "box 16 'cup' is mostly outside its object" in capsys.readouterr().err
    good = _write_holi(tmp_path / "good.json", room)
    assert main(["scenes", "import", str(capture), "--out", str(tmp_path / "s"), "--instances", str(good), "--up", "+z"]) == 0
    assert main(["scenes", "info", str(tmp_path / "s")]) == 0
    assert f"box fill: boxes holding Gaussians {len(room.instances)} of {len(room.instances)} (100%), 0 empty" in capsys.readouterr().out


def test_hostile_corners_and_other_annotation_formats(tmp_path: Path, room) -> None:
    from spacedg.scene.io.embodiedscan import read_embodiedscan_boxes
    from spacedg.scene.io.scannetpp import read_segments_anno

    corners = (np.array(list(np.ndindex(2, 2, 2)), dtype=np.float64) * 1e308).tolist()
    (tmp_path / "c.json").write_text(json.dumps([{"id": 1, "label": "cup", "corners": corners}]))
    with pytest.raises(FileValueError, match=r"c.json: instance \[0\] \(id 1\): .corners. holds coordinates beyond 1e\+07"):
        read_instances(tmp_path / "c.json")
    anno = cl.segments_anno(room)
    anno["segGroups"][2]["objectId"] = 2**70
    (tmp_path / "segments_anno.json").write_text(json.dumps(anno))
    with pytest.raises(FileValueError, match=r"segments_anno.json.*'objectId' a 22-digit number is out of range"):
        read_segments_anno(tmp_path / "segments_anno.json")
    anno = cl.segments_anno(room)
    anno["segGroups"][1]["obb"]["axesLengths"] = [1e308, 1.0, 1.0]
    (tmp_path / "segments_anno.json").write_text(json.dumps(anno))
    with pytest.raises(FileValueError, match=r"segments_anno.json.*box side lengths .* out of range"):
        read_segments_anno(tmp_path / "segments_anno.json")
    infos = cl.embodiedscan_infos(room)
    infos["data_list"][1]["instances"][0]["bbox_id"] = 2**70
    (tmp_path / "es.json").write_text(json.dumps(infos))
    with pytest.raises(FileValueError, match=r"es.json.*'bbox_id' a 22-digit number is out of range"):
        read_embodiedscan_boxes(tmp_path / "es.json", room.id)


def test_native_scene_with_a_huge_id_or_box_is_a_clear_error(tmp_path: Path, room) -> None:
    from spacedg.scene.io import load_scene, save_scene

    save_scene(room, tmp_path / "s")
    path = tmp_path / "s" / "scene.json"
    original = json.loads(path.read_text())
    for change, pattern in (({"id": 2**70}, r"scene.json.*instances\[0\].*id must be an integer in \[0, 2\*\*31 - 1\]"),):
        record = json.loads(json.dumps(original))
        record["instances"][0].update(change)
        path.write_text(json.dumps(record))
        with pytest.raises(FileValueError, match=pattern):
            load_scene(tmp_path / "s")


@pytest.mark.parametrize("layout, expected, absent", [
    ("inria", "every COLMAP / INRIA run", "dataparser"),
    ("colmap", "every COLMAP run", "dataparser"),
    ("nerfstudio", "--dataparser-transforms", "INRIA"),
    ("scannetpp", "transforms_undistorted.json", "dataparser"),
])
def test_causes_fit_the_layout(layout: str, expected: str, absent: str) -> None:
    from spacedg.scene.box_fill import layout_causes

    text = layout_causes(layout, frame_wide=True, common=np.array([5.0, 0.0, 0.0]))
    assert expected in text and absent not in text and "(+5.000, +0.000, +0.000)" in text
    assert "dataparser" not in layout_causes(layout, frame_wide=False)

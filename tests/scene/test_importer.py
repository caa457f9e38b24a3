"""Round trips of every capture layout: write the fixture → import → render non-empty → questions build."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from spacedg.qa.build import build_scene_index
from spacedg.qa.index import QABuildConfig
from spacedg.errors import FileFormatError, ParameterError
from spacedg.render import render
from spacedg.scene.frame_check import FrameMismatchError
from spacedg.scene.importer import detect_layout, import_scene, parse_up
from spacedg.scene.io import load_scene, write_ply
from tests.scene import capture_layouts as cl

QA = QABuildConfig(per_sub_type=2)


@pytest.fixture(scope="module")
def room():
    return cl.truth_room(seed=5, gaussians=20_000, views=10)


@pytest.fixture(scope="module")
def far_room():
    """The same kind of room 12 m from the origin (so a normalised copy at the origin is out of view)."""
    return cl.truth_room(seed=6, gaussians=10_000, views=12, shift=(12.0, -9.0, 0.0))


def _round_trip(folder: Path, n_instances: int) -> None:
    scene = load_scene(folder)
    assert scene.gaussians.instance_ids is not None, "the importer gives the Gaussians instance ids"
    assert len(scene.instances) == n_instances
    cam = next(iter(scene.views.values()))
    assert all(v.capture_focal == (v.fx, v.fy) for v in scene.views.values()), "imported views are the capture's own"
    assert (render(scene.gaussians, cam.resized(80, 60), outputs="alpha").alpha > 0.5).mean() > 0.5
    qa = build_scene_index(folder, QA, progress=False)
    types = set(qa.counts())
    assert "camera_translation" in types and types & {"object_counting", "inter_object_distance", "object_size_comparison"}


def test_inria_colmap_holi_spatial(tmp_path: Path, room) -> None:
    out = cl.write_inria_output(tmp_path, room)
    masks = cl.render_masks(room, tmp_path / "masks" / room.id)
    (tmp_path / "holi.json").write_text(json.dumps(cl.holi_spatial_json(room, masks)))
    assert detect_layout(out) == "inria"
    scene, report = import_scene(out, tmp_path / "scene", instances=tmp_path / "holi.json", up="+z", progress=False)
    assert report.layout == "inria" and report.gaussians == len(room.gaussians) and report.views == len(room.views)
    assert "COLMAP model of cfg_args" in report.text() and report.frame.ok
    assert report.assignment is not None and report.assignment.method == "boxes"
    iou = report.assignment.mean_mask_iou()
    assert iou is not None and iou > 0.6
    # box assignment recovers the truth for most annotated Gaussians
    truth = room.gaussians.instance_ids
    got = scene.gaussians.instance_ids
    labelled = truth >= 0
    assert (got[labelled] == truth[labelled]).mean() > 0.8
    assert scene.metadata["source"]["instances_format"] == "holi-spatial"
    _round_trip(tmp_path / "scene", len(room.instances))
    # without the COLMAP model: cameras.json (principal point at the centre, as INRIA assumes)
    shutil.rmtree(tmp_path / "data")
    # trained with -r 2: the cameras' capture focal is taken at half the images' size
    (out / "cfg_args").write_text((out / "cfg_args").read_text().replace("resolution=-1", "resolution=2"))
    scene2, report = import_scene(out, tmp_path / "scene2", instances=tmp_path / "holi.json", progress=False)
    assert report.cameras_path.endswith("cameras.json") and report.frame.ok
    assert "trained at" in report.text()
    for view in load_scene(tmp_path / "scene2").views.values():
        assert view.capture_focal == pytest.approx((view.fx * round(view.width / 2) / view.width, view.fy * round(view.width / 2) / view.width))
    with pytest.raises(ParameterError, match="already exists"):
        import_scene(out, tmp_path / "scene2", progress=False)


def test_masks_voting(tmp_path: Path, room) -> None:
    out = cl.write_inria_output(tmp_path, room)
    masks = cl.render_masks(room, tmp_path / "elsewhere" / room.id)
    (tmp_path / "holi.json").write_text(json.dumps(cl.holi_spatial_json(room, masks)))
    moved = tmp_path / "masks_here"
    shutil.move(str(tmp_path / "elsewhere" / room.id), str(moved))  # recorded absolute paths no longer exist
    scene, report = import_scene(out, None, instances=tmp_path / "holi.json", assign="masks", masks=moved, progress=False)
    assert report.assignment is not None and report.assignment.method == "masks"
    truth, got = room.gaussians.instance_ids, scene.gaussians.instance_ids
    voted = got >= 0
    assert voted.sum() > 1000 and (got[voted] == truth[voted]).mean() > 0.9


def test_nerfstudio_splatfacto_and_mismatch(tmp_path: Path, far_room) -> None:
    data = tmp_path / "data"
    data.mkdir()
    (data / "transforms.json").write_text(json.dumps(cl.transforms_json(far_room, world=cl.APPLIED)))
    exports = tmp_path / "outputs" / "room" / "splatfacto" / "2024-01-01_000000"
    ply, _ = cl.write_splatfacto(exports, far_room, cl.APPLIED)
    (tmp_path / "inst.json").write_text(json.dumps(cl.holi_spatial_json(far_room, {}, world=cl.APPLIED)))
    scene, report = import_scene(data, tmp_path / "scene", gaussians=ply, instances=tmp_path / "inst.json", progress=False)
    assert report.layout == "nerfstudio" and report.views == len(far_room.views) and report.test_views == 1
    assert any("normalised frame" in n for n in report.notes) and report.frame.ok
    np.testing.assert_allclose(scene.gaussians.means, far_room.gaussians.transformed(cl.APPLIED[:3, :3]).means, atol=2e-3)
    _round_trip(tmp_path / "scene", len(far_room.instances))
    # the ply alone, its dataparser_transforms.json elsewhere: refused, naming the cause and the file
    lone = tmp_path / "exports" / "splat.ply"
    lone.parent.mkdir()
    shutil.copy(ply, lone)
    with pytest.raises(FrameMismatchError, match=r"Gaussians and the cameras disagree.*normalised frame.*dataparser_transforms\.json"):
        import_scene(data, None, gaussians=lone, progress=False)
    _, report = import_scene(data, None, gaussians=lone, frame_check="warn", progress=False)
    assert not report.frame.ok and any("FRAME MISMATCH" in n for n in report.notes)


def test_nerfstudio_cameras_with_colmap_gaussians(tmp_path: Path, far_room) -> None:
    (tmp_path / "transforms.json").write_text(json.dumps(cl.transforms_json(far_room, world=cl.APPLIED)))
    write_ply(tmp_path / "point_cloud.ply", cl.without_ids(far_room.gaussians))  # INRIA, COLMAP frame
    with pytest.raises(FrameMismatchError, match="undo-applied-transform"):
        import_scene(tmp_path, None, progress=False)
    _, report = import_scene(tmp_path, None, undo_applied_transform=True, progress=False)
    assert report.frame.ok


def test_scannetpp_scene_folder(tmp_path: Path, room) -> None:
    scene_dir = cl.write_scannetpp_dslr(tmp_path / "0a5c013435", room)  # as ScanNet++ publishes it
    assert detect_layout(scene_dir) == "scannetpp"
    with pytest.raises(FileFormatError, match="ScanNet\\+\\+ ships no Gaussians"):
        import_scene(scene_dir, None, progress=False)
    in_json = room.transformed(cl.SCANNETPP_JSON[:3, :3], np.zeros(3))
    cl.write_inria_output(scene_dir / "gs", in_json, with_colmap=False)  # trained on the DSLR JSON, found below
    scene, report = import_scene(scene_dir, tmp_path / "scene", progress=False)
    assert report.layout == "scannetpp" and report.up == [0.0, 0.0, 1.0] and report.test_views == 1 and report.frame.ok
    assert report.instances == len(room.instances) and any("back to the scan frame" in n for n in report.notes)
    np.testing.assert_allclose(scene.gaussians.means, room.gaussians.means, atol=1e-4)  # back in the scan frame
    _round_trip(tmp_path / "scene", len(room.instances))


def test_gaussian_file_variants_and_embodiedscan(tmp_path: Path, room) -> None:
    write_colmap_model = cl.write_colmap_text(tmp_path / "sparse" / "0", room)
    (tmp_path / "es.json").write_text(json.dumps(cl.embodiedscan_infos(room)))
    cl.write_compressed_ply(tmp_path / "room.compressed.ply", cl.without_ids(room.gaussians))
    _, report = import_scene(tmp_path / "room.compressed.ply", tmp_path / "compressed", cameras=write_colmap_model,
                             instances=tmp_path / "es.json", embodiedscan_scene=room.id, progress=False)
    assert report.layout == "gaussians" and report.frame.ok and report.instances == len(room.instances)
    _round_trip(tmp_path / "compressed", len(room.instances))
    cl.write_spz(tmp_path / "room.spz", cl.without_ids(room.gaussians))
    _, report = import_scene(tmp_path / "room.spz", tmp_path / "spz", cameras=tmp_path / "sparse" / "0",
                             instances=tmp_path / "es.json", embodiedscan_scene=room.id, progress=False)
    assert report.frame.ok
    _round_trip(tmp_path / "spz", len(room.instances))


def test_colour_only_points_with_colmap(tmp_path: Path, room) -> None:
    plyfile = pytest.importorskip("plyfile")
    g = room.gaussians
    pts = np.zeros(len(g), dtype=[("x", "f4"), ("y", "f4"), ("z", "f4"), ("red", "u1"), ("green", "u1"), ("blue", "u1")])
    for j, a in enumerate("xyz"):
        pts[a] = g.means[:, j]
    rgb = np.clip(g.base_colors() * 255, 0, 255).astype(np.uint8)
    pts["red"], pts["green"], pts["blue"] = rgb[:, 0], rgb[:, 1], rgb[:, 2]
    cl.write_colmap_text(tmp_path / "sparse" / "0", room)
    plyfile.PlyData([plyfile.PlyElement.describe(pts, "vertex")]).write(str(tmp_path / "points.ply"))
    (tmp_path / "seg.json").write_text(json.dumps(cl.segments_anno(room)))
    assert detect_layout(tmp_path) == "colmap"
    _, report = import_scene(tmp_path, tmp_path / "scene", instances=tmp_path / "seg.json", progress=False)
    assert report.frame.ok and report.sh_degree == 0
    _round_trip(tmp_path / "scene", len(room.instances))


def test_up_and_errors(tmp_path: Path) -> None:
    np.testing.assert_allclose(parse_up("-y"), [0, -1, 0])
    np.testing.assert_allclose(parse_up("0,0,2"), [0, 0, 1])
    assert parse_up("auto") is None
    with pytest.raises(ParameterError, match="--up"):
        parse_up("upwards")
    with pytest.raises(FileFormatError, match="no known layout"):
        detect_layout(tmp_path)
    with pytest.raises(ParameterError, match="--cameras"):
        (tmp_path / "a.ply").write_bytes(b"ply\n")
        import_scene(tmp_path / "a.ply", None)


def test_a_spacedg_scene_folder_needs_no_import(tmp_path: Path) -> None:
    (tmp_path / "scene.json").write_text("{}")
    with pytest.raises(FileFormatError, match=r"already a spacedg scene folder.*nothing to import.*spacedg scenes info"):
        detect_layout(tmp_path)

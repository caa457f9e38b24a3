"""``spacedg scenes import`` and the Python API ``scene_from_files`` run the same checks
(:mod:`spacedg.scene.capture_checks`): the same errors, the same override arguments."""

from __future__ import annotations

import json
import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from spacedg.errors import ParameterError
from spacedg.scene.box_fill import BoxFillError
from spacedg.scene.capture_checks import parse_up
from spacedg.scene.importer import import_scene
from spacedg.scene.io import scene_from_files
from spacedg.scene.model import Scene
from spacedg.scene.units import UnitsImplausibleError
from spacedg.scene.up_evidence import UpContradictedError
from tests.scene import capture_layouts as cl
from tests.scene.unit_captures import MPU, in_file_units


@pytest.fixture(scope="module")
def room() -> Scene:
    return cl.truth_room(seed=5, gaussians=10_000, views=8)


def _write(root: Path, scene: Scene) -> tuple[Path, Path, Path, Path]:
    """An INRIA output + its COLMAP model + a Holi-Spatial JSON: (INRIA folder, Gaussians file, COLMAP project, JSON)."""
    out = cl.write_inria_output(root, scene)
    holi = root / "holi.json"
    holi.write_text(json.dumps(cl.holi_spatial_json(scene, {})))
    return out, out / "point_cloud" / "iteration_30000" / "point_cloud.ply", root / "data", holi


def _estimate(message: str) -> float:
    match = re.search(r"Pass --metres-per-unit ([\d.]+)", message)
    assert match, message
    return float(match.group(1))


def test_unknown_units_refused_alike_and_given_alike(tmp_path: Path, room: Scene) -> None:
    src, ply, colmap, holi = _write(tmp_path, in_file_units(room))
    with pytest.raises(UnitsImplausibleError) as by_import:
        import_scene(src, None, instances=holi, assign="none", progress=False)
    with pytest.raises(UnitsImplausibleError) as by_api:
        scene_from_files("room", ply, colmap, holi)
    assert _estimate(str(by_api.value)) == _estimate(str(by_import.value)) and abs(_estimate(str(by_api.value)) / MPU - 1) < 0.15
    assert "--units metric" in str(by_api.value) and "colmap capture" in str(by_api.value)
    scene = scene_from_files("room", ply, colmap, holi, metres_per_unit=MPU)
    assert scene.metadata["units"]["kind"] == "given" and scene.metadata["scale_to_metres"] == MPU
    assert scene.metadata["up_evidence"]["decision"] == "supported" and scene.metadata["box_fill"]["boxes"] == len(room.instances)
    truth = {i.id: i.box.extents for i in room.instances}
    assert all(np.allclose(i.box.extents, truth[i.id], rtol=1e-4) for i in scene.instances)
    assert scene_from_files("room", ply, colmap, holi, units="metric").metadata["units"]["kind"] == "metric"
    with pytest.raises(ParameterError, match="metres-per-unit"):
        scene_from_files("room", ply, colmap, holi, metres_per_unit=-1.0)
    with pytest.raises(ParameterError, match="--units metric and --metres-per-unit 2 contradict"):
        scene_from_files("room", ply, colmap, holi, units="metric", metres_per_unit=2.0)


def test_contradicted_up_refused_alike_and_trusted_alike(tmp_path: Path, room: Scene) -> None:
    src, ply, colmap, holi = _write(tmp_path, room)
    with pytest.raises(UpContradictedError) as by_import:
        import_scene(src, None, instances=holi, up="-z", assign="none", progress=False)
    with pytest.raises(UpContradictedError) as by_api:
        scene_from_files("room", ply, colmap, holi, up="-z")
    for err in (by_import.value, by_api.value):
        assert "up -z (given) is contradicted" in str(err) and "--up +z" in str(err) and "--trust-up" in str(err)
    scene = scene_from_files("room", ply, colmap, holi, up=(0.0, 0.0, -1.0), trust_up=True)
    assert scene.metadata["up_evidence"]["decision"] == "overridden" and list(scene.up) == [0.0, 0.0, -1.0]
    auto = scene_from_files("room", ply, colmap)  # no boxes: Gaussians stay lazy, up from the cameras
    assert float(np.asarray(auto.up)[2]) > 0.95 and auto.metadata["up_evidence"]["decided_by"] == "cameras"
    assert auto.metadata["units"]["kind"] == "unknown" and "not verified" in auto.metadata["units"]["how"] and not auto.gaussians_loaded


def test_misplaced_box_refused_by_the_api_as_by_the_import(tmp_path: Path, room: Scene) -> None:
    cup = 16  # a cup on the table of truth_room(seed=5), moved off its object (15 cm: it holds few Gaussians at 10k)
    moved = [replace(i, box=i.box.transformed(np.eye(3), np.array([0.0, -0.15, 0.0]))) if i.id == cup else i for i in room.instances]
    _, ply, colmap, _ = _write(tmp_path, room)
    holi = tmp_path / "moved.json"
    holi.write_text(json.dumps(cl.holi_spatial_json(Scene(room.id, room.gaussians, room.views, moved, room.up, None, {}), {})))
    with pytest.raises(BoxFillError, match=r"box 16 'cup' is misplaced.*--allow-frame-mismatch"):
        scene_from_files("room", ply, colmap, holi, up="+z")
    scene = scene_from_files("room", ply, colmap, holi, up="+z", frame_check="warn")
    assert any("BOXES NOT HOLDING THEIR OBJECTS" in n for n in scene.metadata["notes"])
    with pytest.raises(ParameterError, match="frame_check"):
        scene_from_files("room", ply, colmap, holi, frame_check="ignore")  # type: ignore[arg-type]


def test_parse_up_takes_text_and_vectors() -> None:
    assert np.allclose(parse_up((0, 0, 2)), [0, 0, 1]) and np.allclose(parse_up("-y"), [0, -1, 0]) and parse_up("auto") is None
    for bad in ("upwards", (0, 0, 0), (1, 2), (np.nan, 0, 1)):
        with pytest.raises(ParameterError, match="--up"):
            parse_up(bad)  # type: ignore[arg-type]

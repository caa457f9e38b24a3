"""Up is verified, never assumed: captures in published layouts imported with a right, a contradicted, an
overridden and an undecidable up (spacedg.scene.up_evidence through import_scene and ``spacedg scenes``)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from spacedg.cli import main
from spacedg.scene.importer import import_scene
from spacedg.scene.io import load_scene, write_ply
from spacedg.scene.model import Scene
from spacedg.scene.up_evidence import (
    estimate_up,
    level_up,
    refine_up,
    UpContradictedError,
    UpUndecidedError,
    axis_name,
    evidence_report,
    gather_up_evidence,
)
from tests.scene import capture_layouts as cl

#: z-up → y-down (COLMAP's usual frame: the first camera's, image y pointing down): p' = M p, M z = -y.
Z_TO_MINUS_Y = np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])


@pytest.fixture(scope="module")
def room() -> Scene:
    return cl.truth_room(seed=5, gaussians=10_000, views=8)


@pytest.fixture(scope="module")
def y_down_inria(room, tmp_path_factory) -> tuple[Path, Path, Scene]:
    """An INRIA output folder + its COLMAP model whose cameras say up is -y, + a Holi-Spatial JSON."""
    root = tmp_path_factory.mktemp("ydown")
    scene = room.transformed(Z_TO_MINUS_Y, np.zeros(3))
    out = cl.write_inria_output(root, scene)
    (root / "holi.json").write_text(json.dumps(cl.holi_spatial_json(scene, {})))
    return out, root / "holi.json", scene


def _rolled(room: Scene) -> Scene:
    """The same room with every camera rolled about its viewing axis by a different angle (all over the circle)."""
    views = {}
    for k, (name, cam) in enumerate(room.views.items()):
        a = 2 * math.pi * k / len(room.views)
        roll = np.eye(4)
        roll[:2, :2] = [[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]]
        views[name] = cam.with_pose(np.asarray(cam.cam_to_world, dtype=np.float64) @ roll)
    return Scene(room.id, room.gaussians, views, room.instances, room.up)


def test_evidence_numbers_on_the_truth(room) -> None:
    ev = gather_up_evidence(room.views, room.instances, [0, 0, 1], means=room.gaussians.means)
    assert ev.decision == "supported" and ev.decided_by == "cameras" and ev.supported == "+z"
    assert ev.cameras.resultant > 0.9 and ev.cameras.angle_deg < 20 and ev.cameras.within["+z"] >= 0.75
    assert ev.floor.verdict == "supports" and ev.floor.resting_up >= 5 > ev.floor.resting_down
    assert ev.floor.slab_low is not None and ev.floor.slab_low > ev.floor.slab_high and ev.floor.cameras_above == 1.0
    assert ev.box_axes.verdict == "supports" and ev.box_axes.along_up == 1.0
    flipped = gather_up_evidence(room.views, room.instances, [0, 0, -1], means=room.gaussians.means)
    assert flipped.decision == "contradicted" and flipped.supported == "+z" and flipped.cameras.angle_deg > 150
    assert flipped.floor.verdict == "contradicts" and flipped.box_axes.verdict == "supports"  # the axis is right, the sign is not
    sideways = gather_up_evidence(room.views, room.instances, [1, 0, 0])
    assert sideways.decision == "contradicted" and sideways.box_axes.verdict == "contradicts" and sideways.box_axes.other_axis == "z"
    text = evidence_report(flipped)
    assert text.startswith("up -z (given): contradicted by the cameras; the evidence supports +z")
    assert "resultant" in text and "boxes rest on one lowest level" in text and "box axes supports" in text
    assert evidence_report(flipped.to_dict()) == text
    assert axis_name([0.01, -0.99, 0.02]) == "-y" and axis_name([1, 1, 0]) == "0.707,0.707,0.000"


def test_colmap_y_down_capture(y_down_inria, tmp_path: Path) -> None:
    out, holi, truth = y_down_inria
    # auto: the cameras' mean image-up, close to -y
    scene, report = import_scene(out, None, instances=holi, assign="none", progress=False)
    assert axis_name(scene.up) == "-y" and scene.metadata["up_evidence"]["decision"] == "supported"
    up = np.asarray(scene.up, dtype=np.float64)
    assert float(up @ [0.0, -1.0, 0.0]) / float(np.linalg.norm(up)) > math.cos(math.radians(0.5))  # exact, not the cameras' lean
    assert any(n.startswith("up evidence  up -y supported by the cameras") for n in report.notes)
    # the right axis given: accepted
    scene, _ = import_scene(out, None, instances=holi, up="-y", assign="none", progress=False)
    assert scene.metadata["up_evidence"]["decided_by"] == "cameras"
    # the opposite sign given: refused, with the evidence and the fix
    with pytest.raises(UpContradictedError) as caught:
        import_scene(out, tmp_path / "bad", instances=holi, up="+y", assign="none", progress=False)
    message = str(caught.value)
    assert "up +y (given) is contradicted" in message and "resultant" in message and "--up -y" in message and "--trust-up" in message
    assert caught.value.evidence.floor.verdict == "contradicts"
    assert not (tmp_path / "bad").exists()


def test_cli_contradicted_up_exits_2_and_trust_up_records_the_override(y_down_inria, tmp_path: Path, capsys) -> None:
    out, holi, _ = y_down_inria
    args = ["scenes", "import", str(out), "--instances", str(holi), "--assign", "none"]
    assert main([*args, "--up", "+y", "--out", str(tmp_path / "bad")]) == 2
    err = capsys.readouterr().err
    assert "contradicted" in err and "mean image-up" in err and "--up -y" in err and "--trust-up" in err
    assert not (tmp_path / "bad" / "scene.json").exists()
    assert main([*args, "--up", "+y", "--trust-up", "--out", str(tmp_path / "trusted")]) == 0
    assert "up +y overridden by the cameras" in capsys.readouterr().out
    record = load_scene(tmp_path / "trusted").metadata["up_evidence"]
    assert record["decision"] == "overridden" and record["supported"] == "-y" and any("--trust-up" in n for n in record["notes"])
    assert main(["scenes", "info", str(tmp_path / "trusted")]) == 0
    info = capsys.readouterr().out
    assert "up +y (given): overridden by the cameras; the evidence supports -y" in info and "cameras  contradicts" in info
    assert main([*args, "--up", "-y", "--out", str(tmp_path / "good")]) == 0
    capsys.readouterr()
    assert main(["scenes", "info", str(tmp_path / "good"), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)[0]["up_evidence"]["decision"] == "supported"


def test_nerfstudio_z_up_capture(room, tmp_path: Path) -> None:
    (tmp_path / "transforms.json").write_text(json.dumps(cl.transforms_json(room, applied=False)))
    write_ply(tmp_path / "point_cloud.ply", cl.without_ids(room.gaussians))
    (tmp_path / "inst.json").write_text(json.dumps(cl.holi_spatial_json(room, {})))
    scene, _ = import_scene(tmp_path, None, instances=tmp_path / "inst.json", up="+z", assign="none", progress=False)
    assert scene.metadata["up_evidence"]["decision"] == "supported"
    for wrong, why in (("-z", r"--up \+z"), ("+y", r"--up \+z")):
        with pytest.raises(UpContradictedError, match=why):
            import_scene(tmp_path, None, instances=tmp_path / "inst.json", up=wrong, assign="none", progress=False)


def test_rolled_cameras_undecidable(room, tmp_path: Path, capsys) -> None:
    rolled = _rolled(room)
    out = cl.write_inria_output(tmp_path / "cap", rolled)
    (tmp_path / "holi.json").write_text(json.dumps(cl.holi_spatial_json(rolled, {})))
    # no boxes: auto cannot decide, and says so (exit 2 on the command line)
    with pytest.raises(UpUndecidedError, match=r"cannot decide up: the cameras are undecided .*resultant 0\.\d+.*Pass --up"):
        import_scene(out, None, assign="none", progress=False)
    assert main(["scenes", "import", str(out), "--out", str(tmp_path / "s"), "--assign", "none"]) == 2
    assert "cannot decide up" in capsys.readouterr().err
    # with boxes: the boxes' axes give z, their bottoms the sign; recorded as such
    scene, _ = import_scene(out, None, instances=tmp_path / "holi.json", assign="none", progress=False)
    record = scene.metadata["up_evidence"]
    assert axis_name(scene.up) == "+z" and record["source"].startswith("estimated from the boxes") and record["decided_by"] == "floor"
    assert record["cameras"]["verdict"] == "undecided"
    # a given up the cameras cannot judge is judged by the floor
    with pytest.raises(UpContradictedError, match=r"(?s)decided by the floor.*--up \+z"):
        import_scene(out, None, instances=tmp_path / "holi.json", up="-z", assign="none", progress=False)
    scene, _ = import_scene(out, None, up="-z", assign="none", progress=False)  # nothing decides: kept, unverified
    assert scene.metadata["up_evidence"]["decision"] == "unverified"


def test_top_down_capture(room) -> None:
    """Cameras looking straight down: their image-up (here +y) says nothing about up; the boxes judge instead."""
    from spacedg.render.camera import look_at
    from spacedg.scene.up_evidence import decide_up

    centre = np.median(room.gaussians.means, axis=0)
    views = {}
    for k, cam in enumerate(room.views.values()):
        eye = centre + np.array([0.3 * math.cos(k), 0.3 * math.sin(k), 0.0])
        eye[2] = 2.3
        views[f"v{k}"] = cam.with_pose(look_at(eye, eye - [0, 0, 2.0], np.array([0.0, 1.0, 0.0])))
    with pytest.raises(UpUndecidedError, match=r"mean image-up is \+y .*boxes' axes reject .*--up"):
        decide_up(views, room.instances, given=None)
    up, _, ev = decide_up(views, room.instances, given=np.array([0.0, 0.0, 1.0]), means=room.gaussians.means)
    assert ev.decision == "supported" and ev.decided_by == "floor" and ev.cameras.looking_along_up == 1.0
    with pytest.raises(UpContradictedError, match=r"--up \+z"):
        decide_up(views, room.instances, given=np.array([0.0, 0.0, -1.0]))


def test_scene_up_evidence_and_bad_vectors(room) -> None:
    from spacedg.errors import ParameterError
    from spacedg.scene.up_evidence import decide_up, scene_up_evidence

    ev = scene_up_evidence(room)
    assert ev.decision == "supported" and ev.source == "the scene's up"
    first = ev.report().splitlines()[0]
    assert first == "up +z (the scene's up): supported by the cameras"
    with pytest.raises(ParameterError, match="three finite numbers"):
        decide_up(room.views, room.instances, given=np.zeros(3))
    with pytest.raises(UpUndecidedError, match="cannot decide up"):
        decide_up({}, [], given=None)


def test_an_estimated_up_is_made_exact_by_level_cameras_and_upright_boxes(room) -> None:
    """The cameras look down, so their mean image-up leans ~11° towards where they look; the plane of their level
    x axes and the boxes' upright axes do not lean."""
    truth = np.array([0.0, 0.0, 1.0])

    def degrees(v: np.ndarray) -> float:
        return math.degrees(math.acos(min(1.0, float(v @ truth) / float(np.linalg.norm(v)))))

    mean = estimate_up(room.views)
    assert degrees(mean) > 5.0
    level = level_up(room.views, mean)
    assert level is not None and degrees(level) < 1.5
    exact, how = refine_up(room.views, room.instances, mean)
    assert degrees(exact) < 0.1 and "upright axes" in how
    without_boxes, how = refine_up(room.views, [], mean)
    assert degrees(without_boxes) < 1.5 and "level x axes" in how
    same_yaw = {name: cam for name, cam in list(room.views.items())[:1]} | {"b": next(iter(room.views.values()))}
    assert level_up(same_yaw, mean) is None  # x axes that do not spread in yaw define no plane

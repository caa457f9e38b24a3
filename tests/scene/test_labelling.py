"""Instance ids by box containment (rules), frame checks (measures and named causes), description articles."""

from __future__ import annotations

import numpy as np
import pytest

from spacedg.render.camera import Camera, look_at
from spacedg.render.gaussians import Gaussians
from spacedg.scene.box import OrientedBox
from spacedg.scene.frame_check import FrameMismatchError, check_frame, require_frame
from spacedg.scene.labelling import assign_by_boxes, assign_instances
from spacedg.scene.model import Instance, Scene


def _gaussians(means, scales=0.005, opacities=0.9) -> Gaussians:
    means = np.asarray(means, dtype=np.float64)
    n = len(means)
    quats = np.tile([1.0, 0, 0, 0], (n, 1))
    return Gaussians.from_colors(means, quats, np.broadcast_to(np.asarray(scales, float).reshape(-1, 1), (n, 3)),
                                 np.broadcast_to(opacities, (n,)), np.full((n, 3), 0.5))


def test_smallest_box_wins_margin_floaters_structural() -> None:
    table = Instance(1, "table", "", OrientedBox([0, 0, 0.4], [1.0, 1.0, 0.8]))
    cup = Instance(2, "cup", "", OrientedBox([0, 0, 0.85], [0.1, 0.1, 0.1]))
    wall = Instance(3, "wall", "", OrientedBox([0, 0, 0.5], [0.2, 0.2, 0.2]))  # small, but structural: last
    means = [[0, 0, 0.85], [0, 0, 0.91], [0.3, 0.3, 0.5], [0.3, 0.3, 0.5], [0.3, 0.3, 0.5], [0, 0, 0.5], [2, 2, 2]]
    g = _gaussians(means, scales=[0.005, 0.005, 0.005, 0.005, 2.0, 0.005, 0.005], opacities=[0.9, 0.9, 0.9, 0.01, 0.9, 0.9, 0.9])
    ids = assign_by_boxes(g, [table, cup, wall], margin=0.02)
    # cup (inside both), cup by margin, table, low-opacity floater, huge background splat, table over wall, outside
    assert ids.tolist() == [2, 2, 1, -1, -1, 1, -1]
    assert assign_by_boxes(g, [table, cup, wall], margin=0.0)[1] == -1  # only the margin kept the boundary Gaussian on the cup


def test_assignment_report() -> None:
    box = OrientedBox([0, 0, 0], [1, 1, 1])
    rng = np.random.default_rng(0)
    g = _gaussians(rng.uniform(-0.5, 0.5, (4000, 3)))
    cam = Camera(100, 100, 50, 40, 100, 80, look_at(np.array([0, -3.0, 0]), np.zeros(3), np.array([0, 0, 1.0])))
    scene = Scene("s", g, {"v": cam}, [Instance(1, "cube", "", box), Instance(2, "ghost", "", OrientedBox([9, 9, 9], [1, 1, 1]))], (0, 0, 1))
    out, report = assign_instances(scene, progress=False)
    assert (out.gaussians.instance_ids == 1).all() and report.assigned == 4000 and report.empty_instances == [2]
    cube = report.instances[0]
    assert cube.gaussians == 4000 and cube.box_coverage > 0.95 and cube.mask_iou is None
    assert "cube" in report.table()


def _looking_scene(flip: bool = False) -> Scene:
    rng = np.random.default_rng(1)
    g = _gaussians(rng.uniform(-0.5, 0.5, (3000, 3)), scales=0.03)
    views = {}
    for k, angle in enumerate(np.linspace(0, 2 * np.pi, 8, endpoint=False)):
        eye = np.array([3 * np.cos(angle), 3 * np.sin(angle), 0.5])
        pose = look_at(eye, np.zeros(3), np.array([0, 0, 1.0]))
        if flip:
            pose = pose @ np.diag([1.0, -1.0, -1.0, 1.0])  # an OpenGL pose read as OpenCV
        views[f"v{k}"] = Camera(80, 80, 40, 30, 80, 60, pose)
    return Scene("s", g, views, [Instance(1, "cube", "", OrientedBox([0, 0, 0], [1, 1, 1]))], (0, 0, 1))


def test_frame_check_measures_and_names_the_cause() -> None:
    good = check_frame(_looking_scene())
    assert good.ok and good.gaussians_in_view == 1.0 and good.views_seeing == 1.0 and good.boxes_with_gaussians == 1.0
    assert min(good.render_coverage) > 0.1
    bad = check_frame(_looking_scene(flip=True))
    assert not bad.ok and bad.gaussians_in_view == 0.0
    with pytest.raises(FrameMismatchError, match="Gaussians and the cameras disagree.*OpenGL axes"):
        require_frame(_looking_scene(flip=True))
    moved = _looking_scene().with_instances([Instance(1, "cube", "", OrientedBox([50, 0, 0], [1, 1, 1]))])
    with pytest.raises(FrameMismatchError, match="boxes and the Gaussians disagree"):
        require_frame(moved)


@pytest.mark.parametrize(("given", "kept"), [("a round white lace doily", "round white lace doily"), ("An oak desk", "oak desk"),
                                             ("the red cup", "red cup"), ("A-frame ladder", "A-frame ladder"), ("", "")])
def test_leading_article_stripped_once(given: str, kept: str) -> None:
    inst = Instance(0, "thing", given, OrientedBox([0, 0, 0], [1, 1, 1]))
    assert inst.description == kept
    assert Instance.from_dict(inst.to_dict()).description == kept

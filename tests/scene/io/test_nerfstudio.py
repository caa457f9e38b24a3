"""nerfstudio / Blender transforms.json: OpenGL poses, intrinsics variants, errors."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from spacedg.scene.io import FileValueError, read_transforms
from spacedg.errors import FileFormatError


def write_json(path: Path, data: Any) -> Path:
    path.write_text(json.dumps(data))
    return path


def gl_pose(rotation: np.ndarray, center: np.ndarray) -> list[list[float]]:
    pose = np.eye(4)
    pose[:3, :3] = rotation
    pose[:3, 3] = center
    return pose.tolist()


def rot_y(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


BASE = {"fl_x": 400.0, "fl_y": 410.0, "cx": 320.0, "cy": 240.0, "w": 640, "h": 480, "camera_model": "PINHOLE"}


def test_opengl_pose_sees_point_at_expected_pixel(tmp_path: Path) -> None:
    # OpenGL camera at (0, 0, 5), identity rotation: looks down world -z, world +y is image up.
    frames = [
        {"file_path": "images/a.png", "transform_matrix": gl_pose(np.eye(3), np.array([0.0, 0.0, 5.0]))},
        # rotated 90° about +y: the camera's back (+z) points to world +x, so it looks down world -x
        {"file_path": "images/b.png", "transform_matrix": gl_pose(rot_y(math.pi / 2), np.array([5.0, 0.0, 0.0]))},
    ]
    cams = read_transforms(write_json(tmp_path / "transforms.json", {**BASE, "frames": frames}))
    assert list(cams) == ["images/a.png", "images/b.png"]
    uv, depth, valid = cams["images/a.png"].project(np.array([[1.0, 2.0, 0.0]]))
    assert valid[0] and depth[0] == pytest.approx(5.0)
    np.testing.assert_allclose(uv[0], [320.0 + 400.0 * 1 / 5, 240.0 - 410.0 * 2 / 5], atol=1e-9)  # +y is up: smaller v
    uv, depth, valid = cams["images/b.png"].project(np.array([[0.0, 1.0, -2.0]]))
    # camera right = R @ x = world -z, image down = world -y, forward = world -x
    assert valid[0] and depth[0] == pytest.approx(5.0)
    np.testing.assert_allclose(uv[0], [320.0 + 400.0 * 2 / 5, 240.0 - 410.0 * 1 / 5], atol=1e-9)
    np.testing.assert_allclose(cams["images/b.png"].forward, [-1.0, 0.0, 0.0], atol=1e-12)


def test_fisheye_matches_cv2(tmp_path: Path) -> None:
    k = [0.02, -0.005, 0.001, -0.0002]
    data = {**BASE, "camera_model": "OPENCV_FISHEYE", "k1": k[0], "k2": k[1], "k3": k[2], "k4": k[3],
            "frames": [{"file_path": "f.png", "transform_matrix": gl_pose(rot_y(0.3), np.array([0.5, -0.2, 4.0]))}]}
    cam = read_transforms(write_json(tmp_path / "t.json", data))["f.png"]
    assert cam.fisheye is not None and cam.fisheye.coeffs == tuple(k) and cam.fisheye.max_theta == pytest.approx(math.pi / 2)
    rng = np.random.default_rng(0)
    local = rng.uniform([-2, -2, 1], [2, 2, 6], (20, 3))  # OpenCV camera coordinates
    world = local @ cam.rotation.T + cam.center
    ref, _ = cv2.fisheye.projectPoints(local.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), cam.K, np.array(k))
    uv, _, valid = cam.project(world)
    assert valid.all()
    np.testing.assert_allclose(uv, ref.reshape(-1, 2), atol=1e-6)


def test_blender_camera_angle_and_image_size(tmp_path: Path) -> None:
    (tmp_path / "train").mkdir()
    cv2.imwrite(str(tmp_path / "train" / "r_0.png"), np.zeros((30, 40, 3), np.uint8))
    angle = 0.6911112070083618
    data = {"camera_angle_x": angle, "frames": [
        {"file_path": "./train/r_0", "transform_matrix": gl_pose(np.eye(3), np.zeros(3))},
        {"file_path": "./train/r_1", "transform_matrix": gl_pose(np.eye(3), np.ones(3))},
    ]}
    cams = read_transforms(write_json(tmp_path / "transforms_train.json", data))
    cam = cams["./train/r_0"]
    assert (cam.width, cam.height) == (40, 30)
    assert cam.fx == pytest.approx(0.5 * 40 / math.tan(angle / 2)) and cam.fy == cam.fx
    assert (cam.cx, cam.cy) == (20.0, 15.0)
    assert cams["./train/r_1"].width == 40


def test_per_frame_intrinsics_override(tmp_path: Path) -> None:
    frames = [
        {"file_path": "a", "transform_matrix": gl_pose(np.eye(3), np.zeros(3))},
        {"file_path": "b", "transform_matrix": gl_pose(np.eye(3), np.zeros(3)), "fl_x": 999.0, "w": 800, "h": 600},
    ]
    cams = read_transforms(write_json(tmp_path / "t.json", {**BASE, "frames": frames}))
    assert cams["a"].fx == 400.0 and cams["b"].fx == 999.0 and cams["b"].width == 800 and cams["b"].fy == 410.0


def test_opencv_distortion_policy(tmp_path: Path) -> None:
    data = {**BASE, "camera_model": "OPENCV", "k1": 0.1, "frames": [{"file_path": "a", "transform_matrix": gl_pose(np.eye(3), np.zeros(3))}]}
    path = write_json(tmp_path / "t.json", data)
    with pytest.raises(FileFormatError, match="distortion.*opencv_distortion='drop'"):
        read_transforms(path)
    with pytest.warns(UserWarning, match="distortion ignored for 1 view"):
        cams = read_transforms(path, opencv_distortion="drop")
    assert cams["a"].fisheye is None
    data["k1"] = 0.0
    assert read_transforms(write_json(tmp_path / "z.json", data))["a"].fx == 400.0  # zero distortion: pinhole


def test_applied_transform_is_ignored(tmp_path: Path) -> None:
    frames = [{"file_path": "a", "transform_matrix": gl_pose(np.eye(3), np.array([1.0, 2.0, 3.0]))}]
    data = {**BASE, "applied_transform": [[0, 1, 0, 0], [1, 0, 0, 0], [0, 0, -1, 0]], "frames": frames}
    cam = read_transforms(write_json(tmp_path / "t.json", data))["a"]
    np.testing.assert_array_equal(cam.center, [1.0, 2.0, 3.0])


def _frame(**kw: Any) -> dict[str, Any]:
    return {"file_path": "a.png", "transform_matrix": gl_pose(np.eye(3), np.zeros(3)), **kw}


@pytest.mark.parametrize(
    ("data", "error", "match"),
    [
        ({**BASE}, FileFormatError, "'frames' must be a non-empty list"),
        ({**BASE, "frames": []}, FileFormatError, "non-empty"),
        ({**BASE, "frames": [{"file_path": "a"}]}, FileFormatError, r"frames\[0\]: missing 'transform_matrix'"),
        ({**BASE, "frames": [{"transform_matrix": np.eye(4).tolist()}]}, FileFormatError, "missing 'file_path'"),
        ({**BASE, "frames": [_frame(transform_matrix=[[1, 0, 0, float("nan")], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]])]}, FileValueError, "NaN"),
        ({**BASE, "frames": [_frame(transform_matrix=(2 * np.eye(4)).tolist())]}, FileValueError, r"last row|not rigid"),
        ({**BASE, "frames": [_frame(transform_matrix=np.diag([2.0, 2.0, 2.0, 1.0]).tolist())]}, FileValueError, "not rigid"),
        ({**BASE, "frames": [_frame(transform_matrix=np.diag([1.0, 1.0, -1.0, 1.0]).tolist())]}, FileValueError, "reflection"),
        ({**BASE, "frames": [_frame(transform_matrix=[[1, 2], [3, 4]])]}, FileFormatError, "4×4"),
        ({**BASE, "frames": [_frame(), _frame()]}, FileFormatError, "appears twice"),
        ({**{k: v for k, v in BASE.items() if k != "fl_x"}, "frames": [_frame()]}, FileFormatError, "no focal length"),
        ({**BASE, "fl_x": "400", "frames": [_frame()]}, FileFormatError, "'fl_x' must be a number"),
        ({**BASE, "fl_x": float("nan"), "frames": [_frame()]}, FileValueError, "finite"),
        ({**BASE, "w": 640.5, "frames": [_frame()]}, FileValueError, "whole number"),
        ({**BASE, "camera_model": "EQUIRECTANGULAR", "frames": [_frame()]}, FileFormatError, "'EQUIRECTANGULAR' is not supported"),
        ({**{k: v for k, v in BASE.items() if k not in ("w", "h")}, "frames": [_frame()]}, FileFormatError, "no image size"),
        ([1, 2], FileFormatError, "expected a JSON object"),
    ],
)
def test_errors(tmp_path: Path, data: Any, error: type, match: str) -> None:
    path = tmp_path / "t.json"
    path.write_text(json.dumps(data))  # json.dumps writes NaN as the (non-standard) token NaN
    with pytest.raises(error, match=match) as info:
        read_transforms(path)
    assert str(path) in str(info.value)

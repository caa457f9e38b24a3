"""ScanNet++'s iPhone cameras, in the layout its toolkit documents (``common/scene_release.py``, ``common/utils/nerfstudio.py``):
``iphone/nerfstudio/transforms.json`` with one OPENCV camera at the top level and the world rows (y, x, -z) of the
scan frame; ``iphone/colmap/`` in the scan frame; ``iphone/pose_intrinsic_imu.json`` (ARKit cameras, ``aligned_pose`` in the
scan frame, as ``iphone/arkit_pcl.py`` reads it), ``rgb/frame_NNNNNN.jpg``."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from spacedg.cli import main
from spacedg.errors import FileFormatError
from spacedg.scene.importer import detect_layout, import_scene
from spacedg.scene.io import load_scene, write_ply
from spacedg.scene.io.scannetpp_iphone import read_pose_intrinsic_imu
from tests.scene import capture_layouts as cl
from tests.scene import holi_release as hr


@pytest.fixture(scope="module")
def truth():
    return hr.tiny_scene()


def _iphone_json(truth, k1: float) -> dict:
    """One shared OPENCV camera at the top level, frames named frame_NNNNNN.jpg, one test frame."""
    per_frame = cl.transforms_json(truth, world=cl.SCANNETPP_JSON, test_every=4, applied=False)
    cam = next(iter(truth.views.values()))
    data = {"fl_x": cam.fx, "fl_y": cam.fy, "cx": cam.cx, "cy": cam.cy, "w": cam.width, "h": cam.height,
            "k1": k1, "k2": 0.0, "p1": 0.0, "p2": 0.0, "camera_model": "OPENCV", "frames": [], "test_frames": []}
    for key in ("frames", "test_frames"):
        for frame in per_frame[key]:
            data[key].append({"file_path": f"frame_{int(frame['file_path'][-8:-4]) % 10000:06d}.jpg",
                              "transform_matrix": frame["transform_matrix"]})
    return data


def _scene_folder(root: Path, truth, k1: float = 0.0) -> Path:
    folder = root / "0a5c013435"
    (folder / "iphone" / "nerfstudio").mkdir(parents=True)
    (folder / "iphone" / "nerfstudio" / "transforms.json").write_text(json.dumps(_iphone_json(truth, k1)))
    (folder / "iphone" / "pose_intrinsic_imu.json").write_text("{}")
    (folder / "scans").mkdir()
    (folder / "scans" / "segments_anno.json").write_text(json.dumps(cl.segments_anno(truth)))
    return folder


def test_iphone_cameras_come_back_to_the_scan_frame(tmp_path: Path, truth) -> None:
    folder = _scene_folder(tmp_path, truth, k1=0.01)
    gs = folder / "gs" / "point_cloud" / "iteration_30000"
    gs.mkdir(parents=True)
    write_ply(gs / "point_cloud.ply", cl.without_ids(hr.released(truth).gaussians))  # trained on the iPhone JSON
    assert detect_layout(folder) == "scannetpp"
    with pytest.raises(FileFormatError, match="non-zero OPENCV distortion"):  # the iPhone lens is not an ideal pinhole
        import_scene(folder, None, device="iphone", progress=False)
    scene, report = import_scene(folder, None, device="iphone", opencv_distortion="drop", progress=False)
    assert report.cameras_path.endswith("iphone/nerfstudio/transforms.json") and report.views == 4 and report.test_views == 1
    assert report.up == [0.0, 0.0, 1.0] and report.frame.ok
    np.testing.assert_allclose(scene.gaussians.means, truth.gaussians.means, atol=1e-5)
    ref = truth.views["DSC05860"].cam_to_world
    np.testing.assert_allclose(scene.views["frame_005860.jpg"].cam_to_world, ref, atol=1e-9)


def test_iphone_colmap_model_when_no_nerfstudio_json(tmp_path: Path, truth) -> None:
    folder = _scene_folder(tmp_path, truth)
    (folder / "iphone" / "nerfstudio" / "transforms.json").unlink()
    (folder / "iphone" / "nerfstudio").rmdir()
    cl.write_colmap_text(folder / "iphone" / "colmap", truth)
    write_ply(tmp_path / "splat.ply", cl.without_ids(truth.gaussians))  # trained on the COLMAP model: scan frame
    assert detect_layout(folder) == "scannetpp"  # pose_intrinsic_imu.json marks an iPhone capture
    scene, report = import_scene(folder, None, device="iphone", gaussians=tmp_path / "splat.ply", progress=False)
    assert report.cameras_path.endswith("iphone/colmap") and report.frame.ok and report.up == [0.0, 0.0, 1.0]
    np.testing.assert_allclose(scene.gaussians.means, truth.gaussians.means, atol=1e-6)


# ----------------------------------------------------------------------------- iphone/pose_intrinsic_imu.json (ARKit)
def _arkit_folder(root: Path, truth, **kw) -> Path:
    folder = cl.write_scannetpp_iphone(root / "0a5c013435", truth, **kw)
    gs = folder / "gs" / "point_cloud" / "iteration_30000"
    gs.mkdir(parents=True)
    write_ply(gs / "point_cloud.ply", cl.without_ids(truth.gaussians))  # trained on the ARKit poses: scan frame
    return folder


def test_pose_intrinsic_imu_through_the_command_line(tmp_path: Path, truth, capsys: pytest.CaptureFixture[str]) -> None:
    folder = _arkit_folder(tmp_path, truth)
    assert detect_layout(folder) == "scannetpp"
    assert main(["scenes", "import", str(folder), "--scannetpp-camera", "iphone", "--out", str(tmp_path / "scene")]) == 0
    out = capsys.readouterr().out
    assert "iphone/pose_intrinsic_imu.json" in out and "ARKit aligned_pose" in out
    assert "1 m per file unit: ScanNet++ scenes are metric by construction" in out and "up           [0.0, 0.0, 1.0]" in out
    scene = load_scene(tmp_path / "scene")
    assert list(scene.views) == [f"frame_{10 * k:06d}.jpg" for k in range(4)]  # the extracted frames only
    for k, cam in enumerate(truth.views.values()):
        got = scene.views[f"frame_{10 * k:06d}.jpg"]
        np.testing.assert_allclose(got.cam_to_world, cam.cam_to_world, atol=1e-9)  # aligned_pose, not ARKit's own pose
        np.testing.assert_allclose([got.fx, got.fy, got.cx, got.cy, got.width, got.height],
                                   [cam.fx, cam.fy, cam.cx, cam.cy, cam.width, cam.height], atol=1e-9)  # K from 1920×1440 to the frames
    assert scene.metadata["frame_check"]["problems"] == [] and scene.metadata["up_evidence"]["decision"] == "supported"


def test_every_frame_at_full_size_without_extracted_frames(tmp_path: Path, truth) -> None:
    folder = cl.write_scannetpp_iphone(tmp_path / "s", truth, rgb=False, extra_frames=2)
    views = read_pose_intrinsic_imu(folder / "iphone" / "pose_intrinsic_imu.json")
    assert len(views) == 6 and {(c.width, c.height) for c in views.values()} == {(1920, 1440)}
    cam = next(iter(truth.views.values()))
    assert views["frame_000000.jpg"].fx == pytest.approx(cam.fx * 12) and views["frame_000000.jpg"].cy == pytest.approx(cam.cy * 12)
    flat = tmp_path / "flat" / "pose_intrinsic_imu.json"
    flat.parent.mkdir()
    flat.write_text(json.dumps(cl.pose_intrinsic_imu(truth, flat=True)))
    np.testing.assert_array_equal(read_pose_intrinsic_imu(flat)["frame_000010.jpg"].cam_to_world, views["frame_000010.jpg"].cam_to_world)


def test_colmap_model_preferred_and_arkit_compared(tmp_path: Path, truth) -> None:
    folder = _arkit_folder(tmp_path, truth, colmap=0.02)
    _, report = import_scene(folder, None, device="iphone", progress=False)
    assert report.cameras_path.endswith("iphone/colmap") and report.views == 4
    assert any("pose_intrinsic_imu.json (ARKit aligned_pose) vs these cameras on 4 shared frames: centres 2.0 cm apart" in n
               for n in report.notes), report.notes
    _, given = import_scene(folder, None, device="iphone", cameras=folder / "iphone" / "pose_intrinsic_imu.json", progress=False)
    assert given.cameras_path.endswith("pose_intrinsic_imu.json") and given.frame.ok


def test_bad_pose_intrinsic_imu_records(tmp_path: Path, truth, capsys: pytest.CaptureFixture[str]) -> None:
    folder = _arkit_folder(tmp_path, truth)
    path = folder / "iphone" / "pose_intrinsic_imu.json"
    good = json.loads(path.read_text())
    cases = [("aligned_pose", None, "missing 'aligned_pose'.*ARKit's own world"), ("intrinsic", [[0, 0, 0], [0, 0, 0], [0, 0, 1]], "not a pinhole K"),
             ("aligned_pose", (2 * np.eye(4)).tolist(), "not a rigid camera-to-world")]
    for key, value, why in cases:
        data = json.loads(json.dumps(good))
        if value is None:
            del data["frame_000000"][key]
        else:
            data["frame_000000"][key] = value
        path.write_text(json.dumps(data))
        with pytest.raises(FileFormatError, match=why):
            read_pose_intrinsic_imu(path)
    path.write_text(json.dumps({"frame_999999": good["frame_000000"]}))
    assert main(["scenes", "import", str(folder), "--scannetpp-camera", "iphone", "--out", str(tmp_path / "no")]) == 2
    assert "none of the 4 frames" in capsys.readouterr().err

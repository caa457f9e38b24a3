"""ScanNet++'s iPhone cameras, in the layout its toolkit documents (``common/scene_release.py``, ``common/utils/nerfstudio.py``):
``iphone/nerfstudio/transforms.json`` with one OPENCV camera at the top level and the world rows (y, x, -z) of the
scan frame; ``iphone/colmap/`` in the scan frame; ``iphone/pose_intrinsic_imu.json``, ``rgb.mkv``, ``depth.bin``."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from spacedg.errors import FileFormatError
from spacedg.scene.importer import detect_layout, import_scene
from spacedg.scene.io import write_ply
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

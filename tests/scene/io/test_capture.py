"""The one camera-format rule (find_cameras) and the capture layout detected once."""

from __future__ import annotations

from pathlib import Path

import pytest

from spacedg.errors import FileFormatError
from spacedg.scene.importer import CaptureLayout, detect_capture, detect_layout
from spacedg.scene.io.capture import CameraFiles, colmap_model, find_cameras


def _touch(*paths: Path) -> None:
    for path in paths:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text("{}")


def test_find_cameras_tells_each_format_once(tmp_path: Path) -> None:
    _touch(tmp_path / "inria" / "cameras.json", tmp_path / "ns" / "transforms.json", tmp_path / "t.json")
    model = tmp_path / "project" / "sparse" / "0"
    _touch(model / "cameras.txt", model / "images.txt", tmp_path / "project" / "transforms.json")
    assert find_cameras(tmp_path / "inria" / "cameras.json") == CameraFiles("inria", tmp_path / "inria" / "cameras.json", tmp_path / "inria" / "cameras.json")
    assert find_cameras(tmp_path / "t.json").kind == "nerfstudio"
    assert find_cameras(tmp_path / "ns") == CameraFiles("nerfstudio", tmp_path / "ns", tmp_path / "ns" / "transforms.json")
    # a COLMAP model (here or in sparse/0) wins over a transforms.json beside it
    assert find_cameras(tmp_path / "project") == CameraFiles("colmap", tmp_path / "project", model)
    assert colmap_model(tmp_path / "project") == model and colmap_model(tmp_path / "ns") is None
    with pytest.raises(FileFormatError, match="views not found"):
        find_cameras(tmp_path / "missing")
    (tmp_path / "cams.txt").write_text("")
    with pytest.raises(FileFormatError, match="views must be a COLMAP model folder"):
        find_cameras(tmp_path / "cams.txt")


def test_detect_capture_keeps_the_colmap_model_it_found(tmp_path: Path) -> None:
    model = tmp_path / "sparse" / "0"
    _touch(model / "cameras.bin", model / "images.bin")
    assert detect_capture(tmp_path) == CaptureLayout("colmap", model)
    assert detect_layout(tmp_path) == "colmap"

"""The size policy (spacedg.limits): Camera, every camera reader and the command line refuse images over
16384 px a side or 2²⁵ px per view, with the reason."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from spacedg.cli import main
from spacedg.errors import FileFormatError, InvalidDataError
from spacedg.limits import MAX_IMAGE_PIXELS, MAX_IMAGE_SIDE, image_size_problem
from spacedg.render.camera import Camera

REASON = "spacedg renders at most 16384 pixels a side and 33,554,432 pixels per view"


def test_policy_numbers() -> None:
    assert MAX_IMAGE_SIDE == 16384 and MAX_IMAGE_PIXELS == 2**25
    assert image_size_problem(7680, 4320) is None and image_size_problem(7008, 4672) is None  # 8K UHD, 33 MP DSLR
    assert image_size_problem(16384, 1) is None and image_size_problem(16385, 1) is not None
    assert image_size_problem(8192, 8192) is not None  # 67 MP


@pytest.mark.parametrize("width, height", [(10**6, 480), (640, 2**63), (16384, 16384), (10**300, 1)], ids=["1e6", "2^63", "16384^2", "1e300"])
def test_camera_refuses_sizes_over_the_cap(width: int, height: int) -> None:
    with pytest.raises(InvalidDataError, match=REASON):
        Camera(500.0, 500.0, 320.0, 240.0, width, height, np.eye(4))
    with pytest.raises(InvalidDataError, match="Camera.resized"):
        Camera(500.0, 500.0, 320.0, 240.0, 640, 480, np.eye(4)).resized(min(width, 10**7), min(height, 10**7))


def test_huge_focal_lengths_are_clear_errors() -> None:
    with pytest.raises(InvalidDataError, match="fx must be finite, got an integer of about 401 digits"):
        Camera(10**400, 500.0, 320.0, 240.0, 640, 480, np.eye(4))


def test_scene_json_width_is_checked_at_read_time(tmp_path: Path) -> None:
    from tests.fuzz_cases import tiny_scene
    from spacedg.scene.io import load_scene, save_scene

    save_scene(tiny_scene(), tmp_path / "s")
    record = json.loads((tmp_path / "s" / "scene.json").read_text())
    record["views"]["v0"]["width"] = 10**6
    (tmp_path / "s" / "scene.json").write_text(json.dumps(record))
    with pytest.raises(FileFormatError, match=r"scene.json: view 'v0': Camera: 1000000×24 pixels is over the limit"):
        load_scene(tmp_path / "s")


def test_transforms_and_inria_sizes_are_checked_at_read_time(tmp_path: Path) -> None:
    from tests.fuzz_cases import tiny_scene
    from tests.scene import capture_layouts as cl
    from spacedg.scene.io.inria import read_inria_cameras
    from spacedg.scene.io.nerfstudio import read_transforms

    scene = tiny_scene()
    data = cl.transforms_json(scene)
    data["frames"][0]["w"] = 10**12
    (tmp_path / "transforms.json").write_text(json.dumps(data))
    with pytest.raises(FileFormatError, match="over the limit"):
        read_transforms(tmp_path / "transforms.json")
    cams = cl.inria_cameras(scene)
    cams[0]["height"] = 100_000
    (tmp_path / "cameras.json").write_text(json.dumps(cams))
    with pytest.raises(FileFormatError, match="over the limit"):
        read_inria_cameras(tmp_path / "cameras.json")


@pytest.mark.parametrize("width", [10**9, 2**63])
def test_colmap_sizes_are_checked_at_read_time(tmp_path: Path, width: int) -> None:
    from tests.fuzz_cases import tiny_scene
    from tests.scene import capture_layouts as cl
    from spacedg.scene.io.colmap import read_colmap

    folder = cl.write_colmap_text(tmp_path / "m", tiny_scene())
    lines = (folder / "cameras.txt").read_text().split("\n")
    row = next(i for i, line in enumerate(lines) if line and not line.startswith("#"))
    tokens = lines[row].split()
    tokens[2] = str(width)
    lines[row] = " ".join(tokens)
    (folder / "cameras.txt").write_text("\n".join(lines))
    with pytest.raises(FileFormatError, match="over the limit"):
        read_colmap(folder)


@pytest.mark.parametrize(
    "argv, fragment",
    [
        (["scenes", "synth", "--n", "1", "--out", "X", "--width", "100000"], "argument --width: 100000 pixels is over the limit"),
        (["export", "--out", "X", "--image-size", "100000x100000"], "argument --image-size: 100000×100000 pixels is over the limit"),
        (["export", "--out", "X", "--image-size", "8192x8192"], "8192×8192 = 67,108,864 pixels is over the limit"),
        (["render", "S", "--view", "v", "--out", "o.png", "--width", "16385"], "argument --width: 16385 pixels is over the limit"),
        (["predict", "--model", "m", "--bench", "b", "--out", "o.jsonl", "--max-pixels", "99999999999"], "argument --max-pixels"),
        (["scenes", "synth", "--n", "1", "--out", "X", "--height", "9" * 5000], "must be a whole number of pixels"),
    ],
)
def test_cli_sizes_are_usage_errors_with_the_reason(argv: list[str], fragment: str, capsys) -> None:
    with pytest.raises(SystemExit) as exit_:
        main(argv)
    assert exit_.value.code == 2
    assert fragment in capsys.readouterr().err


def test_render_cli_checks_the_pixel_count_before_reading(tmp_path: Path, capsys) -> None:
    code = main(["render", str(tmp_path / "missing"), "--view", "v", "--out", str(tmp_path / "o.png"),
                 "--width", "16384", "--height", "16384"])
    assert code == 2
    assert "16384×16384 = 268,435,456 pixels is over the limit" in capsys.readouterr().err


@pytest.mark.parametrize(
    "kwargs, fragment",
    [
        ({"width": 100_000}, "over the limit"),
        ({"min_views": 4, "max_views": -1}, "max_views must be a positive integer"),
        ({"min_views": 9, "max_views": 4}, "1 <= min_views <= max_views"),
    ],
)
def test_synthetic_capture_config_is_checked(kwargs: dict, fragment: str) -> None:
    from spacedg.scene.synthetic import CaptureConfig

    with pytest.raises(InvalidDataError, match=fragment):
        CaptureConfig(**kwargs)


def test_generate_room_refuses_a_negative_seed() -> None:
    from spacedg.scene.synthetic import generate_room

    with pytest.raises(InvalidDataError, match="seed must be an integer >= 0"):
        generate_room(-1)

"""``spacedg render``: one view of a native scene folder to PNGs, through the real console entry point."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

import spacedg
from spacedg.cli import main
from spacedg.scene.synthetic import CaptureConfig

W, H = 160, 120


@pytest.fixture(scope="module")
def scene_dir(tmp_path_factory):
    """A small room (10k Gaussians, 4 views at 320×240) saved as a native scene folder."""
    folder = tmp_path_factory.mktemp("render") / "room"
    room = spacedg.generate_room(0, spacedg.RoomConfig(gaussians=10_000, capture=CaptureConfig(320, 240, 4, 4)))
    spacedg.save_scene(room, folder)
    return folder


def _render(scene_dir, out, *extra):
    return main(["render", str(scene_dir), "--view", "frame_0001", "--image-size", f"{W}x{H}",
                 "--backend", "cpu", "--out", str(out), *extra])


def test_render_rgb_and_depth(scene_dir, tmp_path, capsys):
    out, depth_out = tmp_path / "view.png", tmp_path / "depth.png"
    assert _render(scene_dir, out, "--depth-out", str(depth_out)) == 0
    text = capsys.readouterr().out
    assert "view frame_0001" in text and f"{W}x{H}" in text and "backend cpu" in text and "sub-steps 1" in text
    assert "depth " in text and " m over " in text

    image = cv2.imread(str(out), cv2.IMREAD_UNCHANGED)
    assert image is not None and image.shape == (H, W, 3) and image.dtype == np.uint8
    assert image.mean() > 10  # not black
    depth = cv2.imread(str(depth_out), cv2.IMREAD_UNCHANGED)
    assert depth is not None and depth.shape == (H, W) and depth.dtype == np.uint16
    assert (depth > 0).mean() > 0.5 and 300 < np.median(depth[depth > 0]) < 20_000  # millimetres in a room
    assert not list(tmp_path.glob(".*"))  # no temporary file left behind

    # the same image as the library's render, encoded to sRGB and channel-swapped for OpenCV
    scene = spacedg.load_scene(scene_dir)
    frame = spacedg.render(scene.gaussians, scene.views["frame_0001"].resized(W, H), backend="cpu")
    expected = np.round(np.clip(spacedg.render.linear_to_srgb(frame.rgb), 0, 1) * 255).astype(np.uint8)
    assert np.abs(image[:, :, ::-1].astype(int) - expected).max() <= 1


def test_list_views(scene_dir, capsys):
    assert main(["render", str(scene_dir), "--list-views"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 4 and lines[0].startswith("frame_0000") and "320x240" in lines[0]


@pytest.mark.parametrize(
    "flags",
    [
        ["--defocus", "6,0.8"],
        ["--fisheye", "-0.05,0,0,0"],
        ["--fisheye", "0,0,0,0,1.2"],
        ["--motion", "0.1,0,0,0,0.05,0", "--sub-steps", "4"],
        ["--motion", "0.2,0,0,0,0.1,0", "--sub-steps", "6", "--fast-motion"],
    ],
)
def test_degradation_flags_change_the_image(scene_dir, tmp_path, capsys, flags):
    sharp, out = tmp_path / "sharp.png", tmp_path / "degraded.png"
    assert _render(scene_dir, sharp) == 0
    assert _render(scene_dir, out, *flags) == 0
    text = capsys.readouterr().out.splitlines()[-1]
    if "--motion" in flags:
        assert "sub-steps 1" not in text
    a, b = cv2.imread(str(sharp)).astype(int), cv2.imread(str(out)).astype(int)
    assert b.shape == (H, W, 3) and b.mean() > 10
    assert np.abs(a - b).mean() > 1.0


@pytest.mark.parametrize(
    "flags, message",
    [
        (["--view", "nope"], "--view 'nope': no such view"),
        (["--fisheye", "1,2"], "--fisheye expects 4 to 5 comma-separated numbers K1,K2,K3,K4[,MAX_THETA], got 2"),
        (["--fisheye", "0,0,0,0,4"], "max_theta must be in (0, π)"),
        (["--defocus", "4"], "--defocus expects 2 comma-separated numbers APERTURE_PX,FOCUS_M"),
        (["--motion", "0,0,x,0,0,0"], "--motion expects numbers TX,TY,TZ,RX,RY,RZ; TZ is 'x'"),
        (["--sub-steps", "4"], "pass --motion"),
    ],
)
def test_bad_input_gives_one_clear_error(scene_dir, tmp_path, capsys, flags, message):
    argv = ["render", str(scene_dir), "--view", "frame_0001", "--out", str(tmp_path / "x.png"), *flags]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    if "nope" in flags:
        assert "frame_0000" in err  # lists available names
    assert not (tmp_path / "x.png").exists()


@pytest.mark.parametrize("flags", [["--image-size", "0x0"], ["--image-size", "20000x10"], ["--image-size", "abc"],
                                   ["--image-size", "160"], ["--width", "0"], ["--height", "20000"]])
def test_bad_sizes_are_usage_errors(scene_dir, tmp_path, capsys, flags):
    """Sizes parse with the size policy's argparse type: a usage error (exit 2) before the scene is read."""
    with pytest.raises(SystemExit) as exit_:
        main(["render", str(scene_dir), "--view", "frame_0001", "--out", str(tmp_path / "x.png"), *flags])
    assert exit_.value.code == 2 and f"argument {flags[0]}:" in capsys.readouterr().err


def test_deprecated_width_alone_keeps_the_aspect_ratio(scene_dir, tmp_path, capsys):
    """The old --width (one release more) still renders, keeping the view's 4:3, with one warning line."""
    out = tmp_path / "w.png"
    with pytest.warns(DeprecationWarning, match="--width is deprecated"):
        assert main(["render", str(scene_dir), "--view", "frame_0001", "--width", "80", "--backend", "cpu", "--out", str(out)]) == 0
    warning = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert warning == ["spacedg render: warning: --width is deprecated and goes in the next release; use --image-size WxH"]
    assert cv2.imread(str(out)).shape == (60, 80, 3)
    with pytest.warns(DeprecationWarning):
        assert main(["render", str(scene_dir), "--view", "frame_0001", "--width", "80", "--image-size", "80x60",
                     "--out", str(out)]) == 2
    assert "alternatives; pass --image-size WxH" in capsys.readouterr().err


def test_missing_scene_and_wrong_suffix(tmp_path, capsys):
    assert main(["render", str(tmp_path / "none"), "--view", "a", "--out", str(tmp_path / "x.png")]) == 2
    assert "scene not found" in capsys.readouterr().err
    assert main(["render", str(tmp_path), "--view", "a", "--out", str(tmp_path / "x.jpg")]) == 2
    assert "write a .png file" in capsys.readouterr().err

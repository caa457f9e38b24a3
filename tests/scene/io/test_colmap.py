"""COLMAP models: pycolmap-written (binary, text) and hand-written classic text files."""

from __future__ import annotations

import struct
from pathlib import Path

import cv2
import numpy as np
import pycolmap
import pytest

from spacedg.scene.io import read_colmap
from spacedg.scene.io import colmap as colmap_io
from spacedg.errors import FileFormatError
from spacedg.render.camera import Camera

MODELS = {
    "SIMPLE_PINHOLE": [500.0, 320.0, 240.0],
    "PINHOLE": [500.0, 520.0, 321.5, 239.25],
    "SIMPLE_RADIAL": [480.0, 320.0, 240.0, 0.0],
    "OPENCV": [450.0, 460.0, 330.0, 250.0, 0.0, 0.0, 0.0, 0.0],
    "OPENCV_FISHEYE": [300.0, 310.0, 320.0, 240.0, 0.01, -0.002, 0.0003, -0.00004],
}


def random_pose(rng: np.random.Generator) -> pycolmap.Rigid3d:
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    return pycolmap.Rigid3d(pycolmap.Rotation3d(q), rng.normal(0.0, 2.0, 3))  # quaternion x, y, z, w


def build_reconstruction(models: dict[str, list[float]], image_ids: list[int] | None = None, seed: int = 0) -> pycolmap.Reconstruction:
    rng = np.random.default_rng(seed)
    recon = pycolmap.Reconstruction()
    for camera_id, (model, params) in enumerate(models.items(), start=1):
        recon.add_camera_with_trivial_rig(pycolmap.Camera(model=model, width=640, height=480, params=params, camera_id=camera_id))
    ids = image_ids or list(range(1, len(models) + 1))
    for k, image_id in enumerate(ids):
        camera_id = k % len(models) + 1
        image = pycolmap.Image(name=f"img_{image_id:03d}.jpg", camera_id=camera_id, image_id=image_id)
        recon.add_image_with_trivial_frame(image, random_pose(rng))
    return recon


def points_in_front(cam: Camera, rng: np.random.Generator, n: int = 20, max_angle: float = 0.9) -> np.ndarray:
    """World points inside a cone of half-angle ``max_angle`` around the optical axis."""
    theta = rng.uniform(0.0, max_angle, n)
    phi = rng.uniform(0.0, 2 * np.pi, n)
    depth = rng.uniform(0.5, 20.0, n)
    local = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], axis=1) * depth[:, None]
    return local @ cam.rotation.T + cam.center


def assert_projections_agree(recon: pycolmap.Reconstruction, cams: dict[str, Camera]) -> None:
    rng = np.random.default_rng(1)
    for image in recon.images.values():
        cam = cams[image.name]
        pts = points_in_front(cam, rng)
        uv, _, valid = cam.project(pts)
        assert valid.all()
        cam_from_world = image.cam_from_world()
        ref = recon.cameras[image.camera_id].img_from_cam(np.array([cam_from_world * p for p in pts]))
        np.testing.assert_allclose(uv, ref, atol=1e-6, rtol=0)


@pytest.mark.parametrize("fmt", ["binary", "text"])
def test_pycolmap_written_models(tmp_path: Path, fmt: str) -> None:
    recon = build_reconstruction(MODELS, image_ids=[7, 3, 11, 1, 5])
    (recon.write_binary if fmt == "binary" else recon.write_text)(str(tmp_path))
    cams = read_colmap(tmp_path)
    assert list(cams) == ["img_001.jpg", "img_003.jpg", "img_005.jpg", "img_007.jpg", "img_011.jpg"]  # image-id order
    assert_projections_agree(recon, cams)
    by_model = {recon.cameras[img.camera_id].model.name: cams[img.name] for img in recon.images.values()}
    assert by_model["OPENCV_FISHEYE"].fisheye is not None
    assert by_model["OPENCV_FISHEYE"].fisheye.coeffs == tuple(MODELS["OPENCV_FISHEYE"][4:])
    assert by_model["OPENCV_FISHEYE"].fisheye.max_theta == pytest.approx(np.pi / 2)
    assert all(by_model[m].fisheye is None for m in ("SIMPLE_PINHOLE", "PINHOLE", "OPENCV", "SIMPLE_RADIAL"))
    assert (by_model["PINHOLE"].fx, by_model["PINHOLE"].fy, by_model["PINHOLE"].cx) == (500.0, 520.0, 321.5)
    assert by_model["SIMPLE_PINHOLE"].fx == by_model["SIMPLE_PINHOLE"].fy == 500.0
    assert all((c.width, c.height) == (640, 480) for c in cams.values())


def test_points3d_are_not_needed(tmp_path: Path) -> None:
    recon = build_reconstruction({"PINHOLE": MODELS["PINHOLE"]})
    recon.add_point3D(np.array([0.0, 0.0, 5.0]), pycolmap.Track())
    recon.write_binary(str(tmp_path))
    (tmp_path / "points3D.bin").write_bytes(b"garbage that would not parse")
    assert list(read_colmap(tmp_path)) == ["img_001.jpg"]


CAMERAS_TXT = """# Camera list with one line of data per camera:
#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]
# Number of cameras: 2
1 PINHOLE 800 600 700.5 710.25 401 299.5
2 SIMPLE_PINHOLE 640 480 555 320 240
"""
# Classic COLMAP 3.x layout: IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME, then a POINTS2D line.
IMAGES_TXT = """# Image list with two lines of data per image:
#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME
#   POINTS2D[] as (X, Y, POINT3D_ID)
# Number of images: 2, mean observations per image: 0
2 0.9238795325112867 0 0.3826834323650898 0 0.5 -0.25 3.0 1 left/frame_002.png

1 0.7071067811865476 0.7071067811865476 0 0 -1.0 2.0 0.5 2 right/frame_001.png

"""
POINTS_TXT = """# 3D point list with one line of data per point:
#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)
# Number of points: 0, mean track length: 0
"""


def write_classic(folder: Path, cameras: str = CAMERAS_TXT, images: str = IMAGES_TXT) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "cameras.txt").write_text(cameras)
    (folder / "images.txt").write_text(images)
    (folder / "points3D.txt").write_text(POINTS_TXT)
    return folder


def quat_wxyz_to_matrix(w: float, x: float, y: float, z: float) -> np.ndarray:
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def test_hand_written_classic_text(tmp_path: Path) -> None:
    cams = read_colmap(write_classic(tmp_path / "sparse" / "0"))
    assert list(cams) == ["right/frame_001.png", "left/frame_002.png"]
    rng = np.random.default_rng(2)
    for line in IMAGES_TXT.splitlines():
        if not line or line.startswith("#"):
            continue
        parts = line.split()
        qw, qx, qy, qz, tx, ty, tz = map(float, parts[1:8])
        cam = cams[parts[9]]
        rot = quat_wxyz_to_matrix(qw, qx, qy, qz)  # world → camera
        pts = points_in_front(cam, rng)
        ref, _ = cv2.projectPoints(pts, cv2.Rodrigues(rot)[0], np.array([tx, ty, tz]), cam.K, None)
        uv, _, valid = cam.project(pts)
        assert valid.all()
        np.testing.assert_allclose(uv, ref.reshape(-1, 2), atol=1e-6, rtol=0)
    assert (cams["left/frame_002.png"].fx, cams["left/frame_002.png"].cy) == (700.5, 299.5)


def test_opencv_distortion_policy(tmp_path: Path) -> None:
    models = {"OPENCV": [450.0, 460.0, 330.0, 250.0, 0.1, -0.02, 0.001, 0.0], "PINHOLE": MODELS["PINHOLE"]}
    build_reconstruction(models).write_text(str(tmp_path))
    with pytest.raises(FileFormatError, match=r"camera\(s\) \[1\].*distortion.*image_undistorter.*opencv_distortion='drop'"):
        read_colmap(tmp_path)
    with pytest.warns(UserWarning, match=r"camera\(s\) \[1\].*ignored.*img_001.jpg"):
        cams = read_colmap(tmp_path, opencv_distortion="drop")
    assert cams["img_001.jpg"].fisheye is None and cams["img_001.jpg"].fx == 450.0
    with pytest.raises(ValueError, match="opencv_distortion"):
        read_colmap(tmp_path, opencv_distortion="ignore")  # type: ignore[arg-type]


def test_unsupported_model_lists_supported(tmp_path: Path) -> None:
    build_reconstruction({"FULL_OPENCV": [400.0, 400.0, 320.0, 240.0] + [0.0] * 8}).write_binary(str(tmp_path))
    with pytest.raises(FileFormatError, match=r"FULL_OPENCV is not supported.*SIMPLE_PINHOLE, PINHOLE.*OPENCV_FISHEYE"):
        read_colmap(tmp_path)


def test_images_without_pose_are_skipped_with_warning(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    recon = build_reconstruction({"PINHOLE": MODELS["PINHOLE"]}, image_ids=[1, 2, 3])
    recon.deregister_frame(recon.images[2].frame_id)
    monkeypatch.setattr(colmap_io, "_load_reconstruction", lambda folder: recon)
    with pytest.warns(UserWarning, match=r"skipped 1 image\(s\) without a pose.*img_002.jpg"):
        cams = read_colmap(tmp_path)
    assert list(cams) == ["img_001.jpg", "img_003.jpg"]


def test_zero_quaternion_is_an_error(tmp_path: Path) -> None:
    write_classic(tmp_path, images=IMAGES_TXT.replace("0.7071067811865476 0.7071067811865476 0 0", "0 0 0 0"))
    with pytest.raises(FileFormatError, match=r"image 1 \('right/frame_001.png'\).*non-zero"):
        read_colmap(tmp_path)


def test_missing_and_garbage_models(tmp_path: Path) -> None:
    with pytest.raises(FileFormatError, match="not found"):
        read_colmap(tmp_path / "nowhere")
    (tmp_path / "file.txt").write_text("x")
    with pytest.raises(FileFormatError, match="got a file"):
        read_colmap(tmp_path / "file.txt")
    (tmp_path / "empty").mkdir()
    with pytest.raises(FileFormatError, match=r"no COLMAP model here.*sparse/0"):
        read_colmap(tmp_path / "empty")
    garbage = write_classic(tmp_path / "garbage", cameras="1 PINHOLE not numbers\n")
    with pytest.raises(FileFormatError, match=rf"{garbage}/cameras.txt:1: WIDTH is 'not', not a whole number"):
        read_colmap(garbage)


def _text_model(folder: Path) -> Path:
    """A pycolmap-written text model with rigs and frames (two images, one camera, one rig)."""
    folder.mkdir()
    build_reconstruction({"PINHOLE": MODELS["PINHOLE"]}, image_ids=[1, 2]).write_text(str(folder))
    return folder


def _replace(path: Path, old: str, new: str) -> None:
    text = path.read_text()
    assert old in text, (old, text)
    path.write_text(text.replace(old, new, 1))


@pytest.mark.parametrize(("name", "old", "new", "match"), [
    ("frames.txt", "\n1 1 ", "\n1 7 ", r"frames.txt:\d+: frame 1 refers to rig 7, which rigs.txt does not define \(its rigs: 1\)"),
    ("images.txt", " 1 img_001.jpg", " x img_001.jpg", r"images.txt:\d+: CAMERA_ID is 'x', not a whole number"),
    ("images.txt", " 1 img_001.jpg", " 9 img_001.jpg", r"images.txt:\d+: image 1 uses camera 9, which cameras.txt does not define"),
    ("cameras.txt", " 321.5 239.25", "", r"cameras.txt:\d+: camera 1: a PINHOLE camera takes 4 parameters \(fx, fy, cx, cy\), the line has 2"),
    ("cameras.txt", "PINHOLE", "PINHOL", r"cameras.txt:\d+: camera 1: unknown camera model 'PINHOL'"),
    ("rigs.txt", "1 1 CAMERA 1", "1 1 CAMERA 5", r"rigs.txt:\d+: rig 1 lists camera 5, which cameras.txt does not define"),
    ("frames.txt", "CAMERA 1 2\n", "CAMERA 1 9\n", r"frames.txt:\d+: frame 2 lists image 9, which images.txt does not define"),
    ("frames.txt", "CAMERA 1 2\n", "CAMERA 1\n", r"frames.txt:\d+: the line ends before DATA_ID"),
    ("images.txt", " 1 img_001.jpg", " " + "9" * 5000 + " img_001.jpg", r"images.txt:\d+: CAMERA_ID has 5,000 digits, more than any 64-bit id"),
])
def test_text_model_errors_name_file_line_and_fix(tmp_path: Path, name: str, old: str, new: str, match: str) -> None:
    """The finding: pycolmap's "Rig with ID 7 does not exist" and "Check failed: line_stream1 >> …"."""
    folder = _text_model(tmp_path / "m")
    _replace(folder / name, old, new)
    with pytest.raises(FileFormatError, match=match) as info:
        read_colmap(folder)
    message = str(info.value)
    assert "Check failed" not in message and ".cc:" not in message and "model_converter" in message


@pytest.mark.parametrize(("name", "offset", "value", "match"), [
    ("frames.bin", 12, 7, r"frames.bin refers to rig 7, which rigs.bin does not define"),
    ("rigs.bin", 20, 5, r"rigs.bin: rig 1 lists camera 5, which cameras.bin does not define"),
    ("images.bin", 68, 9, r"image 1 of images.bin is not listed in frame 1 of frames.bin"),
])
def test_binary_model_dangling_ids_name_the_file(tmp_path: Path, name: str, offset: int, value: int, match: str) -> None:
    folder = _binary_model(tmp_path / "m")
    data = (folder / name).read_bytes()
    (folder / name).write_bytes(data[:offset] + struct.pack("<I", value) + data[offset + 4:])
    with pytest.raises(FileFormatError, match=match) as info:
        read_colmap(folder)
    assert "Check failed" not in str(info.value) and "does not exist" not in str(info.value)


def test_unknown_pycolmap_messages_lose_their_cpp_location() -> None:
    from spacedg.scene.io.colmap_check import pycolmap_message

    message = pycolmap_message(Path("/m"), "txt", RuntimeError("[foo_bar.cc:12] Check failed: x >> y Something odd happened"))
    assert message.startswith("/m: pycolmap could not read this COLMAP text model (Something odd happened)")
    assert ".cc" not in message and "Check failed" not in message


def _binary_model(folder: Path) -> Path:
    folder.mkdir()
    build_reconstruction({"PINHOLE": MODELS["PINHOLE"]}, image_ids=[1, 2]).write_binary(str(folder))
    return folder


@pytest.mark.parametrize(
    ("name", "mutate", "match"),
    [
        ("cameras.bin", lambda b: struct.pack("<Q", 10**15) + b[8:], "declares 1000000000000000 cameras"),
        ("images.bin", lambda b: struct.pack("<Q", 10**12) + b[8:], "declares 1000000000000 images"),
        ("images.bin", lambda b: b[: len(b) - 3], "images.bin"),
        ("images.bin", lambda b: b[:84] + struct.pack("<Q", 2**40) + b[92:], "images.bin"),
        ("frames.bin", lambda b: b[:72] + struct.pack("<I", 2**31) + b[76:], "frames.bin"),
        ("rigs.bin", lambda b: b[:12] + struct.pack("<I", 2**31) + b[16:], "rigs.bin"),
        ("cameras.bin", lambda b: bytes(len(b)), "pycolmap could not read|cameras"),
    ],
)
def test_corrupt_binary_fails_clearly(tmp_path: Path, name: str, mutate, match: str) -> None:  # noqa: ANN001
    folder = _binary_model(tmp_path / "m")
    path = folder / name
    path.write_bytes(mutate(path.read_bytes()))
    with pytest.raises(FileFormatError, match=match):
        read_colmap(folder)


def test_random_bytes_binary_model(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    for trial in range(10):
        folder = tmp_path / f"r{trial}"
        folder.mkdir()
        for name in ("cameras", "images", "points3D"):
            (folder / f"{name}.bin").write_bytes(rng.integers(0, 256, int(rng.integers(0, 200)), dtype=np.uint8).tobytes())
        with pytest.raises(FileFormatError, match=str(folder)):
            read_colmap(folder)

"""COLMAP sparse models (cameras and image poses) through pycolmap.

``read_colmap(model_dir)`` reads a COLMAP model folder, text (``cameras.txt``,
``images.txt``, ...) or binary (``.bin``), in the classic three-file layout or the newer
layout with ``rigs`` and ``frames`` files, and returns one :class:`Camera` per posed image,
keyed by the image name, in image-id order.

Conventions:

- COLMAP stores ``cam_from_world`` (world → camera) with OpenCV camera axes (x right,
  y down, z forward), which are spacedg's; ``cam_to_world`` is its inverse. The quaternion
  is normalised in float64 (a zero quaternion is an error).
- Units are the model's (COLMAP reconstructions are not metric; ``scene_from_files`` takes a
  ``scale``).
- Camera models: ``SIMPLE_PINHOLE`` (f, cx, cy), ``PINHOLE`` (fx, fy, cx, cy),
  ``SIMPLE_RADIAL`` (f, cx, cy, k), ``RADIAL`` (f, cx, cy, k1, k2), ``OPENCV`` (fx, fy,
  cx, cy, k1, k2, p1, p2) and ``OPENCV_FISHEYE`` (fx, fy, cx, cy, k1..k4). spacedg renders
  pinhole and equidistant-fisheye lenses only: a radial/OPENCV camera whose distortion is
  all zero is a pinhole; otherwise ``opencv_distortion="error"`` (default) refuses it and
  ``"drop"`` renders it as the ideal pinhole with a warning naming the cameras.
  ``OPENCV_FISHEYE`` becomes a :class:`FisheyeLens` with ``max_theta`` =
  :data:`DEFAULT_FISHEYE_MAX_THETA` (π/2, a 180° field of view) unless given.
- The sparse 3D points (``points3D``) are not read: spacedg does not use them, and skipping
  them makes large models load fast. Binary files are walked record by record before
  pycolmap sees them, so a corrupt count fails with a clear error instead of a huge allocation.
"""

from __future__ import annotations

import math
import os
import shutil
import struct
import tempfile
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Literal

import numpy as np

from spacedg.errors import FileFormatError, InvalidDataError, error_context
from spacedg.files import FileValueError, PathLike, as_path
from spacedg.render.camera import Camera, FisheyeLens
from spacedg.render.gaussians import quat_to_matrix
from spacedg.scene.io.colmap_check import check_text_model, pycolmap_message

#: Field of view limit of COLMAP fisheye cameras, radians from the optical axis.
DEFAULT_FISHEYE_MAX_THETA = math.pi / 2
#: Camera models read_colmap understands.
SUPPORTED_MODELS = ("SIMPLE_PINHOLE", "PINHOLE", "SIMPLE_RADIAL", "RADIAL", "OPENCV", "OPENCV_FISHEYE")
_UNDISTORT_HINT = (
    "spacedg renders pinhole and equidistant-fisheye lenses only: undistort the images first "
    "(`colmap image_undistorter --image_path ... --input_path ... --output_path ...` writes a PINHOLE model), "
    "or pass opencv_distortion='drop' to render these cameras as ideal pinholes"
)
_NAMES = ("rigs", "cameras", "frames", "images", "points3D")
_MAX_NAME_BYTES = 64 * 1024


# --------------------------------------------------------------------- binary walking
class _Walker:
    """Bounded little-endian reader of one COLMAP binary file."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.size = path.stat().st_size
        self.handle = open(path, "rb")  # noqa: SIM115 - closed in close()

    def close(self) -> None:
        self.handle.close()

    def fail(self, what: str) -> FileFormatError:
        return FileFormatError(
            f"{self.path}: truncated or corrupt COLMAP binary file ({what}); re-export the model "
            "(`colmap model_converter --output_type BIN`) or use the text format"
        )

    def remaining(self) -> int:
        return self.size - self.handle.tell()

    def read(self, n: int, what: str) -> bytes:
        data = self.handle.read(n)
        if len(data) != n:
            raise self.fail(f"file ends inside {what}")
        return data

    def u32(self, what: str) -> int:
        return struct.unpack("<I", self.read(4, what))[0]

    def u64(self, what: str) -> int:
        return struct.unpack("<Q", self.read(8, what))[0]

    def skip(self, n: int, what: str) -> None:
        if n > self.remaining():
            raise self.fail(f"{what} needs {n} bytes, {self.remaining()} left")
        self.handle.seek(n, os.SEEK_CUR)

    def count(self, min_record: int, what: str) -> int:
        n = self.u64(f"the number of {what}")
        if n * min_record > self.remaining():
            raise self.fail(f"it declares {n} {what} of at least {min_record} bytes, but only {self.remaining()} bytes follow")
        return n

    def cstring(self, what: str) -> None:
        start = self.handle.tell()
        while True:
            pos = self.handle.tell()
            block = self.handle.read(256)
            if not block:
                raise self.fail(f"file ends inside {what}")
            end = block.find(b"\0")
            if end >= 0:
                self.handle.seek(pos + end + 1)
                return
            if pos + len(block) - start > _MAX_NAME_BYTES:
                raise self.fail(f"{what} is not terminated within {_MAX_NAME_BYTES} bytes")


def _walk_cameras(w: _Walker) -> None:
    # camera_id u32, model i32, width u64, height u64, params f64 × (≥ 3)
    w.count(48, "cameras")


def _walk_images(w: _Walker) -> None:
    for i in range(w.count(73, "images")):
        w.skip(4 + 32 + 24 + 4, f"image record {i}")
        w.cstring(f"the name of image record {i}")
        n = w.u64(f"the point count of image record {i}")
        w.skip(n * 24, f"the {n} 2D points of image record {i}")


def _walk_rigs(w: _Walker) -> None:
    for i in range(w.count(8, "rigs")):
        w.skip(4, f"rig record {i}")
        sensors = w.u32(f"the sensor count of rig record {i}")
        if sensors == 0:
            continue
        w.skip(8, f"the reference sensor of rig record {i}")
        if (sensors - 1) * 9 > w.remaining():
            raise w.fail(f"rig record {i} declares {sensors} sensors")
        for _ in range(sensors - 1):
            w.skip(8, f"a sensor of rig record {i}")
            has_pose = w.read(1, f"a sensor of rig record {i}")[0]
            if has_pose:
                w.skip(56, f"a sensor pose of rig record {i}")


def _walk_frames(w: _Walker) -> None:
    for i in range(w.count(68, "frames")):
        w.skip(4 + 4 + 56, f"frame record {i}")
        n = w.u32(f"the data count of frame record {i}")
        w.skip(n * 16, f"the {n} data ids of frame record {i}")


_WALKERS = {"cameras": _walk_cameras, "images": _walk_images, "rigs": _walk_rigs, "frames": _walk_frames}


def _check_binary(folder: Path) -> None:
    for name, walk in _WALKERS.items():
        path = folder / f"{name}.bin"
        if path.is_file():
            w = _Walker(path)
            try:
                walk(w)
            finally:
                w.close()


# ---------------------------------------------------------------------- staging
def _detect_format(folder: Path) -> str:
    if not folder.exists():
        raise FileFormatError(f"{folder}: COLMAP model folder not found; pass the folder holding cameras/images files (often sparse/0)")
    if not folder.is_dir():
        raise FileFormatError(f"{folder}: expected a COLMAP model folder (holding cameras.bin/images.bin or .txt), got a file")
    for ext in ("bin", "txt"):
        if (folder / f"cameras.{ext}").is_file() and (folder / f"images.{ext}").is_file():
            return ext
    present = sorted(p.name for p in folder.iterdir())[:10]
    raise FileFormatError(
        f"{folder}: no COLMAP model here (need cameras.bin + images.bin or cameras.txt + images.txt; found {present}); "
        "point to the model folder, often <project>/sparse/0"
    )


@contextmanager
def _staged(folder: Path, ext: str) -> Iterator[Path]:
    """A temporary folder with the model's files linked and an empty points3D file."""
    with tempfile.TemporaryDirectory(prefix="spacedg-colmap-") as tmp:
        stage = Path(tmp)
        for name in _NAMES:
            src = folder / f"{name}.{ext}"
            dst = stage / src.name
            if name == "points3D":
                dst.write_bytes(struct.pack("<Q", 0) if ext == "bin" else b"")
            elif src.is_file():
                try:
                    os.symlink(src.resolve(), dst)
                except OSError:
                    shutil.copyfile(src, dst)
        yield stage


def _load_reconstruction(folder: Path) -> Any:
    try:
        import pycolmap
    except ImportError as err:  # pragma: no cover - pycolmap is a dependency
        raise FileFormatError(f"{folder}: reading COLMAP models needs pycolmap (`pip install pycolmap`)") from err
    ext = _detect_format(folder)
    if ext == "bin":
        _check_binary(folder)
    else:
        check_text_model(folder)  # file:line messages for what pycolmap reports as C++ "Check failed" text
    with _staged(folder, ext) as stage:
        try:
            return pycolmap.Reconstruction(str(stage))
        except Exception as err:  # pycolmap raises ValueError/RuntimeError with C++ messages
            raise FileFormatError(pycolmap_message(folder, ext, err)) from err


# ------------------------------------------------------------------- conversion
def _model_name(camera: Any) -> str:
    model = camera.model
    return str(getattr(model, "name", None) or getattr(camera, "model_name", model))


def _intrinsics(
    camera: Any, max_theta: float
) -> tuple[tuple[float, float, float, float], FisheyeLens | None, bool]:
    """((fx, fy, cx, cy), fisheye lens or None, has_nonzero_distortion)."""
    name = _model_name(camera)
    p = [float(v) for v in np.asarray(camera.params, dtype=np.float64)]
    if name == "SIMPLE_PINHOLE":
        return (p[0], p[0], p[1], p[2]), None, False
    if name == "PINHOLE":
        return (p[0], p[1], p[2], p[3]), None, False
    if name in ("SIMPLE_RADIAL", "RADIAL"):
        return (p[0], p[0], p[1], p[2]), None, any(v != 0.0 for v in p[3:])
    if name == "OPENCV":
        return (p[0], p[1], p[2], p[3]), None, any(v != 0.0 for v in p[4:8])
    if name == "OPENCV_FISHEYE":
        return (p[0], p[1], p[2], p[3]), FisheyeLens(p[4], p[5], p[6], p[7], max_theta), False
    raise InvalidDataError(
        f"camera model {name} is not supported (supported: {', '.join(SUPPORTED_MODELS)}); "
        "undistort the images with `colmap image_undistorter` to get a PINHOLE model"
    )


def _cam_to_world(image: Any) -> np.ndarray:
    pose = image.cam_from_world
    pose = pose() if callable(pose) else pose
    qx, qy, qz, qw = (float(v) for v in np.asarray(pose.rotation.quat, dtype=np.float64))
    t = np.asarray(pose.translation, dtype=np.float64).reshape(3)
    q = np.array([qw, qx, qy, qz])
    norm = float(np.linalg.norm(q))
    if not math.isfinite(norm) or norm < 1e-12 or not np.isfinite(t).all():
        raise InvalidDataError(
            f"cam_from_world has quaternion (w, x, y, z) = {q.tolist()} and translation {t.tolist()}; "
            "the quaternion must be finite and non-zero"
        )
    rot = quat_to_matrix((q / norm)[None])[0]
    out = np.eye(4)
    out[:3, :3] = rot.T
    out[:3, 3] = -rot.T @ t
    return out


def read_colmap(
    model_dir: PathLike,
    *,
    opencv_distortion: Literal["error", "drop"] = "error",
    fisheye_max_theta: float = DEFAULT_FISHEYE_MAX_THETA,
) -> dict[str, Camera]:
    """Read the posed images of a COLMAP model as spacedg cameras.

    Args:
        model_dir: folder with ``cameras`` and ``images`` files (``.bin`` preferred over
            ``.txt`` when both exist), e.g. ``<project>/sparse/0``.
        opencv_distortion: ``"error"`` refuses cameras with non-zero radial/tangential
            distortion; ``"drop"`` renders them as ideal pinholes and warns (naming them).
        fisheye_max_theta: ``max_theta`` (radians) of ``OPENCV_FISHEYE`` lenses.

    Returns:
        image name → :class:`Camera` (OpenCV axes, model units), in image-id order. Images
        without a pose are skipped with one warning giving their count.

    Raises:
        FileFormatError: missing folder or files, a file pycolmap cannot parse, corrupt
            binary counts, duplicate image names, unsupported or distorted camera models.
    """
    if opencv_distortion not in ("error", "drop"):
        raise InvalidDataError(f"read_colmap: opencv_distortion must be 'error' or 'drop', got {opencv_distortion!r}")
    folder = as_path(model_dir, "COLMAP model folder")
    recon = _load_reconstruction(folder)
    intrinsics: dict[int, tuple[tuple[float, float, float, float], FisheyeLens | None, bool]] = {}
    for camera_id, camera in recon.cameras.items():
        try:
            intrinsics[int(camera_id)] = _intrinsics(camera, fisheye_max_theta)
        except InvalidDataError as err:
            raise FileFormatError(f"{folder}: camera {camera_id}: {err}") from err
    distorted = sorted(cid for cid, (_, _, bad) in intrinsics.items() if bad)
    if distorted and opencv_distortion == "error":
        models = {cid: _model_name(recon.cameras[cid]) for cid in distorted}
        raise FileFormatError(f"{folder}: camera(s) {distorted[:10]} ({sorted(set(models.values()))}) have non-zero lens distortion; {_UNDISTORT_HINT}")
    out: dict[str, Camera] = {}
    unposed: list[str] = []
    dropped: list[str] = []
    for image_id in sorted(int(i) for i in recon.images.keys()):
        image = recon.images[image_id]
        try:
            name = str(image.name)
        except UnicodeDecodeError as err:
            raise FileFormatError(f"{folder}: image {image_id}: its name is not UTF-8 text ({err.reason} at byte {err.start}); the model is corrupt") from None
        if not getattr(image, "has_pose", True):
            unposed.append(name)
            continue
        if name in out:
            raise FileFormatError(f"{folder}: image name {name!r} appears twice (image ids must map to distinct names)")
        camera = recon.cameras[image.camera_id]
        (fx, fy, cx, cy), lens, bad = intrinsics[int(image.camera_id)]
        if bad:
            dropped.append(name)
        with error_context(f"{folder}: image {image_id} ({name!r}), camera {image.camera_id}"):
            try:
                out[name] = Camera(fx, fy, cx, cy, int(camera.width), int(camera.height), _cam_to_world(image), lens)
            except InvalidDataError as err:
                raise FileValueError(str(err)) from err
    if unposed:
        warnings.warn(
            f"{folder}: skipped {len(unposed)} image(s) without a pose (not registered), e.g. {unposed[:3]}",
            stacklevel=2,
        )
    if dropped:
        warnings.warn(
            f"{folder}: camera(s) {distorted[:10]} have lens distortion that is ignored (opencv_distortion='drop'); "
            f"{len(dropped)} view(s), e.g. {dropped[:3]}, render as ideal pinholes and will not match the photos exactly",
            stacklevel=2,
        )
    return out

"""Camera model: projection against OpenCV, conventions, validation."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from spacedg.errors import InvalidDataError
from spacedg.render.camera import Camera, FisheyeLens, look_at


def _camera(lens: FisheyeLens | None = None) -> Camera:
    return Camera(500.0, 505.0, 321.5, 238.0, 640, 480, look_at([0.5, -1.0, 1.5], [3.0, 1.0, 1.0], [0.0, 0.0, 1.0]), lens)


def _points(rng: np.random.Generator, n: int = 200) -> np.ndarray:
    return rng.normal(size=(n, 3)) * 1.5 + [3.0, 1.0, 1.0]


def _rvec_tvec(cam: Camera) -> tuple[np.ndarray, np.ndarray]:
    rvec, _ = cv2.Rodrigues(cam.world_to_cam[:3, :3])
    return rvec, cam.world_to_cam[:3, 3]


def test_pinhole_projection_matches_opencv(rng):
    cam = _camera()
    pts = _points(rng)
    uv, depth, valid = cam.project(pts)
    ref, _ = cv2.projectPoints(pts[valid], *_rvec_tvec(cam), cam.K, None)
    np.testing.assert_allclose(uv[valid], ref.reshape(-1, 2), atol=1e-6)
    np.testing.assert_allclose(depth, cam.to_camera(pts)[:, 2])
    assert valid.sum() > 150


def test_fisheye_projection_matches_opencv_fisheye(rng):
    lens = FisheyeLens(0.1, 0.01, 0.001, 0.0001, max_theta=1.5)
    cam = _camera(lens)
    pts = _points(rng)
    uv, depth, valid = cam.project(pts)
    front = valid & (depth > 0)
    ref, _ = cv2.fisheye.projectPoints(pts[front].reshape(-1, 1, 3), *_rvec_tvec(cam), cam.K, np.array(lens.coeffs))
    np.testing.assert_allclose(uv[front], ref.reshape(-1, 2), atol=1e-6)


def test_fisheye_on_axis_and_beyond_max_theta_stay_finite():
    cam = _camera(FisheyeLens(-0.24, 2e-4, 1e-4, 0.0, max_theta=1.5))
    on_axis = cam.center + cam.forward * 2.0
    behind = cam.center - cam.forward * 2.0
    uv, _, valid = cam.project(np.stack([on_axis, behind, cam.center]))
    assert np.isfinite(uv).all()
    np.testing.assert_allclose(uv[0], [cam.cx, cam.cy], atol=1e-9)
    assert valid[0] and not valid[1]


def test_opencv_axes_and_look_at():
    pose = look_at([0, 0, 0], [0, 5, 0], [0, 0, 1])
    cam = Camera(100, 100, 50, 50, 100, 100, pose)
    np.testing.assert_allclose(cam.forward, [0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(cam.rotation[:, 1], [0, 0, -1], atol=1e-12)  # image down = world down
    np.testing.assert_allclose(cam.rotation[:, 0], [1, 0, 0], atol=1e-12)  # image right = world +x
    uv, _, _ = cam.project(np.array([[1.0, 5.0, 1.0]]))  # right of and above the axis
    assert uv[0, 0] > 50 and uv[0, 1] < 50


def test_resized_scales_intrinsics_and_round_trips_through_dict():
    cam = _camera(FisheyeLens(0.1, 0, 0, 0, 1.2))
    small = cam.resized(320, 240)
    assert (small.fx, small.cx, small.height) == (250.0, 160.75, 240)
    again = Camera.from_dict(cam.to_dict())
    assert again.fisheye == cam.fisheye
    np.testing.assert_array_equal(again.cam_to_world, cam.cam_to_world)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(fx=-1.0), "focal lengths must be > 0"),
        (dict(fy=float("nan")), "fy must be finite"),
        (dict(width=0), "width must be a positive integer"),
        (dict(height=480.5), "height must be a positive integer"),
        (dict(cam_to_world=np.diag([1.0, 1.0, 2.0, 1.0])), "not orthonormal"),
        (dict(cam_to_world=np.diag([1.0, 1.0, -1.0, 1.0])), "reflection"),
        (dict(cam_to_world=np.eye(3)), "must be 4×4"),
    ],
)
def test_invalid_cameras_are_rejected(kwargs, message):
    base = dict(fx=100.0, fy=100.0, cx=50.0, cy=50.0, width=100, height=100, cam_to_world=np.eye(4))
    base.update(kwargs)
    with pytest.raises(InvalidDataError, match=message):
        Camera(**base)


def test_invalid_fisheye_is_rejected():
    with pytest.raises(InvalidDataError, match="max_theta must be in"):
        FisheyeLens(max_theta=math.pi)
    with pytest.raises(InvalidDataError, match="k1 must be a finite number"):
        FisheyeLens(k1=float("inf"))


def test_the_compiled_fisheye_inverse_is_the_numpy_bisection_bit_for_bit() -> None:
    """:meth:`FisheyeLens.undistort_theta` (compiled, :mod:`spacedg.render.lens_cpu`) returns the bits of the
    vectorised numpy bisection it replaced: 60 halvings of [0, effective max θ] on every radius, for lenses
    with and without a fold, radii inside and beyond the image circle, NaN, a scalar (a numpy scalar back)."""
    from spacedg.render.camera import FisheyeLens

    def numpy_bisection(lens: FisheyeLens, theta_d: np.ndarray) -> np.ndarray:
        target = np.asarray(theta_d, dtype=np.float64)
        lo, hi = np.zeros_like(target), np.full_like(target, lens.effective_max_theta)
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            below = lens.distort_theta(mid) < target
            lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
        return 0.5 * (lo + hi)

    rng = np.random.default_rng(31)
    for k1, k2, k3, k4 in [(0.0, 0.0, 0.0, 0.0), (-0.24, 0.01, 0.0, 0.0), (0.08, -0.02, 0.004, -0.001), tuple(rng.normal(0.0, 0.05, 4))]:
        lens = FisheyeLens(k1=k1, k2=k2, k3=k3, k4=k4)
        radii = rng.uniform(0.0, 2.5, (17, 9))
        radii[0, :3] = (np.nan, 0.0, 1e9)
        assert lens.undistort_theta(radii).tobytes() == numpy_bisection(lens, radii).tobytes()
        scalar = lens.undistort_theta(np.float64(0.4))
        assert isinstance(scalar, np.float64) and scalar == numpy_bisection(lens, np.float64(0.4))

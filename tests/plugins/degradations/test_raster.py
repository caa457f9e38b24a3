"""Raster-stage degradations (defocus, distortion, motion_blur): declarations and physical invariants."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.render_helpers import camera, random_gaussians
from spacedg.errors import ParameterError
from spacedg.plugins import Category, Stage
from spacedg.plugins.degradations import defocus, distortion, motion_blur
from spacedg.render import Camera, Gaussians, render
from spacedg.render.request import RenderRequest

PAPER_BENCH = {
    "defocus": {"aperture": [10.0, 15.0], "depth": [1.0, 8.0]},
    "distortion": {"k1": [-0.24, -0.23], "k2": [1e-4, 3e-4], "k3": [1e-4, 2e-4], "k4": [0.0, 1e-4], "max_theta": [1.5, 1.5]},
    "motion_blur": {"trans": [0.2, 0.35], "rot": [0.06, 0.12], "sub_steps": [80, 80]},
}
MODULES = {"defocus": defocus, "distortion": distortion, "motion_blur": motion_blur}


@pytest.mark.parametrize("name", sorted(MODULES))
def test_declaration_matches_paper_table(name: str) -> None:
    spec = MODULES[name].SPEC
    assert spec.name == name and spec.stage is Stage.RASTER and spec.category is Category.OPTICAL_DYNAMIC
    assert {k: r.to_list() for k, r in spec.presets["bench"].items()} == PAPER_BENCH[name]
    assert spec.needs == frozenset()


@pytest.mark.parametrize("name", sorted(MODULES))
def test_apply_returns_a_new_request_and_is_deterministic(name: str) -> None:
    spec = MODULES[name].SPEC
    request = RenderRequest(camera(64, 48))
    params = spec.sample_params("bench", np.random.default_rng(0))
    first = spec.apply(request, params, np.random.default_rng(5))
    again = spec.apply(request, params, np.random.default_rng(5))
    assert isinstance(first, RenderRequest) and first is not request
    assert request.defocus is None and request.motion is None and request.camera.fisheye is None  # input untouched
    assert first == again if name != "distortion" else first.camera.fx == again.camera.fx


def _single_gaussian(depth: float, sigma_m: float, opacity: float = 0.5) -> Gaussians:
    sh = np.zeros((1, 1, 3))
    sh[0, 0] = 1.0
    return Gaussians(np.array([[0.02, -0.01, depth]]), np.array([[1.0, 0, 0, 0]]), np.full((1, 3), sigma_m), np.array([opacity]), sh)


@pytest.mark.parametrize("extent", [2.5, None])
@pytest.mark.parametrize(("aperture", "focus"), [(3.0, 1.0), (6.0, 8.0), (12.0, 0.5)])
def test_defocus_conserves_energy(aperture: float, focus: float, extent: float | None) -> None:
    from spacedg.render import RasterSettings

    cam = camera(160, 120, focal=200.0)
    gauss = _single_gaussian(depth=2.0, sigma_m=0.01)  # σ = 1 px on screen
    sharp = render(gauss, cam, outputs="rgb")
    request = defocus.defocus(RenderRequest(cam), aperture, focus)
    blurred = request.render(gauss, settings=RasterSettings(defocus_extent=extent))
    radius = aperture * abs(2.0 - focus) / 2.0
    assert blurred.alpha.max() < sharp.alpha.max()  # spread out …
    assert np.count_nonzero(blurred.alpha > 1e-3) > np.count_nonzero(sharp.alpha > 1e-3)
    assert blurred.alpha.sum() == pytest.approx(sharp.alpha.sum(), rel=0.03), radius  # … with the same energy


def test_defocus_zero_aperture_is_the_sharp_render() -> None:
    gauss = random_gaussians(400, np.random.default_rng(1))
    cam = camera(64, 48)
    sharp = render(gauss, cam, outputs="rgb,depth")
    request = defocus.SPEC.apply(RenderRequest(cam, outputs=frozenset({"rgb", "depth"})), {"aperture": 0.0, "depth": 3.0}, np.random.default_rng(0))
    same = request.render(gauss)
    assert np.array_equal(same.rgb, sharp.rgb) and np.array_equal(same.depth, sharp.depth)


def _unproject_valid(cam: Camera) -> np.ndarray:
    """Unit rays (camera frame) of every pixel centre the fisheye camera images."""
    lens = cam.fisheye
    u, v = np.meshgrid(np.arange(cam.width) + 0.5, np.arange(cam.height) + 0.5)
    xn, yn = (u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy
    rho = np.hypot(xn, yn)
    inside = rho <= lens.distort_theta(np.float64(lens.effective_max_theta))
    theta = lens.undistort_theta(rho[inside])
    scale = np.where(rho[inside] > 0, np.sin(theta) / np.maximum(rho[inside], 1e-300), 1.0)
    return np.stack([xn[inside] * scale, yn[inside] * scale, np.cos(theta)], axis=1)


@pytest.mark.parametrize("k1", [-0.24, -0.05, 0.0, 0.1, -1.0])
def test_contained_distortion_never_shows_what_the_clean_view_does_not(k1: float) -> None:
    clean = camera(320, 240)
    distorted = distortion.distort_contained(RenderRequest(clean), k1, 2e-4, 1e-4, 5e-5, 1.5).camera
    assert distorted.fisheye is not None and np.array_equal(distorted.cam_to_world, clean.cam_to_world)
    rays = _unproject_valid(distorted)
    assert rays.shape[0] > 0.5 * clean.width * clean.height
    assert np.all(rays[:, 2] > 0)
    u = clean.fx * rays[:, 0] / rays[:, 2] + clean.cx
    v = clean.fy * rays[:, 1] / rays[:, 2] + clean.cy
    tol = 1e-6
    assert u.min() >= -tol and v.min() >= -tol and u.max() <= clean.width + tol and v.max() <= clean.height + tol


def test_contained_distortion_corners_reach_the_clean_corners() -> None:
    clean = camera(320, 240)
    distorted = distortion.distort_contained(RenderRequest(clean), -0.24, 2e-4, 1e-4, 5e-5, 1.5).camera
    lens = distorted.fisheye
    # the farthest corner of the frame: its ray angle equals the clean camera's there
    xs = np.array([-clean.cx, clean.width - clean.cx])
    ys = np.array([-clean.cy, clean.height - clean.cy])
    far = (xs[np.argmax(np.abs(xs))], ys[np.argmax(np.abs(ys))])
    clean_theta = math.atan(math.hypot(far[0] / clean.fx, far[1] / clean.fy))
    fisheye_theta = float(lens.undistort_theta(np.float64(math.hypot(far[0] / distorted.fx, far[1] / distorted.fy))))
    assert fisheye_theta == pytest.approx(clean_theta, abs=1e-4)
    assert 1.2 < distorted.fx / clean.fx < 1.6

def _width_at_half_alpha(alpha: np.ndarray) -> float:
    """Width (px) of the covered columns of the row through the image centre, with sub-pixel ends."""
    row = alpha[alpha.shape[0] // 2].astype(np.float64)
    return float(np.sum(np.clip(row, 0.0, 1.0)))


@pytest.mark.parametrize("k1", [-0.24, -0.05])
def test_distortion_keeps_the_apparent_size_at_the_centre(k1: float) -> None:
    # The paper's lens on the camera's own focal lengths: a subject at the image centre keeps its
    # size within 2 % (the contained variant grows it by its zoom, 1.2–1.4×).
    rng = np.random.default_rng(11)
    n = 400
    means = np.column_stack([rng.uniform(-0.12, 0.12, n), rng.uniform(-0.02, 0.02, n), np.full(n, 2.0)])
    gauss = Gaussians.from_colors(means, np.tile([1.0, 0, 0, 0], (n, 1)), np.full((n, 3), 0.012), np.full(n, 1.0), np.full((n, 3), 0.8))
    clean = camera(320, 240)
    sharp = _width_at_half_alpha(render(gauss, clean).alpha)
    distorted = distortion.distort(RenderRequest(clean), k1, 2e-4, 1e-4, 5e-5, 1.5)
    assert distorted.camera.fx == clean.fx and distorted.camera.fy == clean.fy and distorted.camera.cx == clean.cx
    lensed = _width_at_half_alpha(distorted.render(gauss).alpha)
    assert 30.0 < sharp < 60.0 and lensed / sharp == pytest.approx(1.0, abs=0.02)
    contained = _width_at_half_alpha(distortion.distort_contained(RenderRequest(clean), k1, 2e-4, 1e-4, 5e-5, 1.5).render(gauss).alpha)
    assert contained / sharp > 1.1


def test_distortion_lets_new_content_enter_and_reports_the_captured_share() -> None:
    from spacedg.render.coverage import captured_share

    clean = camera(320, 240)
    distorted = distortion.distort(RenderRequest(clean), -0.24, 2e-4, 1e-4, 5e-5, 1.5).camera
    rays = _unproject_valid(distorted)
    u = clean.fx * rays[:, 0] / rays[:, 2] + clean.cx
    outside = (u < 0) | (u > clean.width)
    assert outside.mean() > 0.05  # the border shows what the clean view did not
    share = captured_share(clean, distorted)
    assert 0.5 < share < 0.95 and share == pytest.approx(1.0 - outside.mean(), abs=0.12)
    contained = distortion.distort_contained(RenderRequest(clean), -0.24, 2e-4, 1e-4, 5e-5, 1.5).camera
    assert captured_share(clean, contained) > 0.995
    assert captured_share(clean, clean) == 1.0


def test_distortion_at_the_fold_limit_and_beyond_stays_finite() -> None:
    gauss = random_gaussians(600, np.random.default_rng(2), half_width=3.0)
    clean = camera(96, 72)
    corner_theta = math.atan(math.hypot(clean.width / 2 / clean.fx, clean.height / 2 / clean.fy))
    fold_k1 = -1.0 / (3.0 * corner_theta**2)  # dθ_d/dθ = 0 exactly at the corner ray
    for k1 in (fold_k1, -1.0, 1.0):
        request = distortion.distort(RenderRequest(clean, outputs=frozenset({"rgb", "depth"})), k1, 0.0, 0.0, 0.0, 1.5)
        frame = request.render(gauss)
        assert np.isfinite(frame.rgb).all() and np.isfinite(frame.depth).all()
        assert frame.valid is not None
    assert not frame.valid.all() or k1 == 1.0


def test_distortion_tends_to_the_pinhole_for_a_narrow_field() -> None:
    gauss = random_gaussians(300, np.random.default_rng(3), half_width=0.05, scale=(0.001, 0.004))
    narrow = camera(64, 48, focal=3000.0)  # ~1.2° field: θ and tan θ agree to 2e-5 px
    pinhole = render(gauss, narrow)
    fisheye = distortion.distort(RenderRequest(narrow), 0.0, 0.0, 0.0, 0.0, 1.5).render(gauss)
    assert np.abs(fisheye.rgb - pinhole.rgb).max() < 2e-3


def test_distortion_of_a_fisheye_view_uses_its_own_lens() -> None:
    from spacedg.render import FisheyeLens

    base = camera(160, 120)
    fish = Camera(base.fx, base.fy, base.cx, base.cy, 160, 120, np.eye(4), FisheyeLens(-0.05, 0, 0, 0, 1.5))
    zoom = distortion.containing_zoom(fish, FisheyeLens(-0.24, 0, 0, 0, 1.5))
    assert 1.0 < zoom < distortion.containing_zoom(base, FisheyeLens(-0.24, 0, 0, 0, 1.5))


def test_motion_blur_static_is_the_sharp_render_and_pose_is_mid_exposure() -> None:
    gauss = random_gaussians(400, np.random.default_rng(4))
    cam = camera(64, 48)
    sharp = render(gauss, cam)
    static = motion_blur.SPEC.apply(RenderRequest(cam), {"trans": 0.0, "rot": 0.0, "sub_steps": 80}, np.random.default_rng(0))
    assert static.motion.is_static and np.array_equal(static.render(gauss).rgb, sharp.rgb)
    moving = motion_blur.SPEC.apply(RenderRequest(cam), {"trans": 0.3, "rot": 0.1, "sub_steps": 8}, np.random.default_rng(0))
    assert np.linalg.norm(moving.motion.translation) == pytest.approx(0.3)
    assert np.linalg.norm(moving.motion.rotation) == pytest.approx(0.1)
    frame = moving.render(gauss)
    assert np.array_equal(frame.camera.cam_to_world, cam.cam_to_world)
    assert np.isfinite(frame.rgb).all() and not np.array_equal(frame.rgb, sharp.rgb)


def test_motion_blur_directions_are_uniform_and_per_view() -> None:
    rng = np.random.default_rng(6)
    dirs = np.array([motion_blur.random_unit_vector(rng) for _ in range(4000)])
    assert np.allclose(np.linalg.norm(dirs, axis=1), 1.0)
    assert np.abs(dirs.mean(axis=0)).max() < 0.05  # no preferred direction
    assert np.allclose(np.cov(dirs.T), np.eye(3) / 3.0, atol=0.03)
    a = motion_blur.SPEC.apply(RenderRequest(camera()), {"trans": 0.2, "rot": 0.1, "sub_steps": 80}, np.random.default_rng([9, 0]))
    b = motion_blur.SPEC.apply(RenderRequest(camera()), {"trans": 0.2, "rot": 0.1, "sub_steps": 80}, np.random.default_rng([9, 1]))
    assert a.motion.translation != b.motion.translation


def test_motion_blur_takes_its_rotation_limit_on_every_axis() -> None:
    """``rot = π`` is the hard limit: on a quarter of the random axes ``π · axis`` has a norm a few ulps above π,
    which the settings refused (stop 64's sweep at the limits); beyond π is still refused."""
    from spacedg.render.settings import MotionBlur

    axes = np.random.default_rng(4108)
    above = 0
    for view in range(400):
        request = motion_blur.SPEC.apply(RenderRequest(camera()), {"trans": 0.0, "rot": math.pi, "sub_steps": 80}, np.random.default_rng([4108, view]))
        above += float(np.linalg.norm(request.motion.rotation)) > math.pi
        MotionBlur(rotation=tuple(math.pi * motion_blur.random_unit_vector(axes)))
    assert above > 0  # the case the limit's slack is for was met
    with pytest.raises(ParameterError, match="must be <= π"):
        MotionBlur(rotation=(0.0, math.nextafter(math.pi * (1 + 1e-11), 4.0), 0.0))


@pytest.mark.parametrize(
    ("name", "params", "pattern"),
    [
        ("defocus", {"aperture": -1.0, "depth": 2.0}, "outside its hard limits"),
        ("defocus", {"aperture": 5.0, "focus": 2.0}, "unknown parameter 'focus'"),
        ("distortion", {"k1": -2.0, "k2": 0, "k3": 0, "k4": 0, "max_theta": 1.5}, "outside its hard limits"),
        ("motion_blur", {"trans": 0.2, "rot": 4.0, "sub_steps": 80}, "outside its hard limits"),
        ("motion_blur", {"trans": 0.2, "rot": 0.1, "sub_steps": 2.5}, "must be an integer"),
    ],
)
def test_bad_parameters_fail_clearly(name: str, params: dict, pattern: str) -> None:
    with pytest.raises(ParameterError, match=pattern):
        MODULES[name].SPEC.apply(RenderRequest(camera()), params, np.random.default_rng(0))

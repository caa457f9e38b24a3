"""Defocus and motion blur inside the renderer; pose interpolation; request validation."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.render_helpers import camera, random_gaussians
from spacedg.errors import ParameterError
from spacedg.render import Defocus, MotionBlur, RasterSettings, render
from spacedg.render.camera import exposure_poses, interpolate_pose, look_at, matrix_to_rotvec, rotvec_to_matrix
from spacedg.render.gaussians import Gaussians
from spacedg.render.motion import MotionJob, choose_sub_steps, motion_extent, render_motion_substeps, sub_exposure_times


def one_gaussian(z: float = 2.0, scale: float = 0.01, opacity: float = 0.5) -> Gaussians:
    return Gaussians([[0.0, 0.0, z]], [[1.0, 0, 0, 0]], [[scale, scale, scale]], [opacity], np.full((1, 1, 3), 1.0))


# ---------------------------------------------------------------- defocus
def test_defocus_in_focus_is_the_sharp_render_bit_for_bit() -> None:
    """Every Gaussian at the focus depth has r = 0: the compensation is exactly 1."""
    rng = np.random.default_rng(0)
    g = random_gaussians(400, rng, depth=(3.0, 3.0))
    cam = camera(96, 72)
    sharp = render(g, cam, outputs="all")
    focused = render(g, cam, outputs="all", defocus=Defocus(aperture=12.0, focus=3.0))
    for name in ("rgb", "alpha", "depth", "median_depth", "instance_ids"):
        np.testing.assert_array_equal(getattr(focused, name), getattr(sharp, name), err_msg=name)


@pytest.mark.parametrize("backend", ["cpu", "torch"])
def test_defocus_conserves_the_energy_of_an_isolated_gaussian(backend: str) -> None:
    """Σ alpha over the image stays put as the circle of confusion grows (tails below 1/255 aside)."""
    g = one_gaussian(z=2.0, scale=0.012, opacity=0.4)  # ~3 px standard deviation at f = 480
    cam = camera(96, 72, focal=480.0)
    totals = []
    for aperture in (0.0, 2.0, 4.0, 8.0):
        frame = render(g, cam, defocus=Defocus(aperture=aperture, focus=1.0), backend=backend)  # r = aperture / 2
        totals.append(frame.alpha.sum())
    assert totals[0] == pytest.approx(0.4 * 2 * math.pi * ((0.012 * 480 / 2) ** 2 + 0.3), rel=0.03)  # o·2π·det(Σ)^½
    np.testing.assert_allclose(totals[1:], totals[0], rtol=0.03)
    peak_sharp = render(g, cam).alpha.max()
    peak_blur = render(g, cam, defocus=Defocus(aperture=8.0, focus=1.0)).alpha.max()
    assert peak_blur < 0.5 * peak_sharp  # spread out, not dimmed


def test_defocus_radius_is_clamped() -> None:
    d = Defocus(aperture=10.0, focus=4.0)
    assert d.max_radius == 30.0
    r = d.radius(np.array([0.01, 1.0, 4.0, 1e6]))
    np.testing.assert_allclose(r, [30.0, 30.0, 0.0, 10.0], rtol=1e-5)
    assert Defocus(aperture=10.0, focus=4.0, max_radius=12.0).radius(np.array([0.5]))[0] == 12.0


@pytest.mark.parametrize(
    "kwargs, fragment",
    [({"aperture": -1.0, "focus": 2.0}, "aperture"), ({"aperture": 5.0, "focus": 0.0}, "focus"), ({"aperture": math.nan, "focus": 1.0}, "finite")],
)
def test_bad_defocus_is_refused(kwargs: dict, fragment: str) -> None:
    with pytest.raises(ParameterError, match=fragment):
        Defocus(**kwargs)


# ---------------------------------------------------------------- motion
def test_pose_interpolation_endpoints_and_constant_speed() -> None:
    a = look_at([0.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0])
    b = look_at([1.0, 0.5, 0.2], [2.0, 0.1, 1.0], [0.0, -1.0, 0.0])
    np.testing.assert_array_equal(interpolate_pose(a, b, 0.0), a)
    np.testing.assert_array_equal(interpolate_pose(a, b, 1.0), b)
    total = np.linalg.norm(matrix_to_rotvec(a[:3, :3].T @ b[:3, :3]))
    for u in (0.25, 0.5, 0.8):
        mid = interpolate_pose(a, b, u)
        np.testing.assert_allclose(np.linalg.norm(matrix_to_rotvec(a[:3, :3].T @ mid[:3, :3])), u * total, rtol=1e-9)
        np.testing.assert_allclose(mid[:3, 3], (1 - u) * a[:3, 3] + u * b[:3, 3])
    vec = np.array([0.3, -0.2, 0.1])
    np.testing.assert_allclose(matrix_to_rotvec(rotvec_to_matrix(vec)), vec, atol=1e-12)


def test_exposure_path_is_centred_on_the_camera_and_matches_slerp() -> None:
    cam = camera(64, 48, pose=look_at([0.5, 0.2, -1.0], [0.0, 0.0, 3.0], [0.0, -1.0, 0.0]))
    translation, rotation = np.array([0.3, 0.0, 0.1]), np.array([0.0, 0.1, 0.02])
    start, mid, end = exposure_poses(cam, translation, rotation, np.array([-0.5, 0.0, 0.5]))
    np.testing.assert_allclose(mid, cam.cam_to_world, atol=1e-15)
    np.testing.assert_allclose(end[:3, 3] - start[:3, 3], cam.rotation @ translation, atol=1e-12)
    for s in (-0.3, 0.1, 0.45):
        (pose,) = exposure_poses(cam, translation, rotation, np.array([s]))
        np.testing.assert_allclose(pose, interpolate_pose(start, end, s + 0.5), atol=1e-12)
    np.testing.assert_allclose(sub_exposure_times(4), [-0.375, -0.125, 0.125, 0.375])


def test_zero_motion_and_one_sub_step_are_the_sharp_render() -> None:
    g = random_gaussians(500, np.random.default_rng(2))
    cam = camera(80, 60)
    sharp = render(g, cam, outputs="all")
    still = render(g, cam, outputs="all", motion=MotionBlur())
    np.testing.assert_array_equal(still.rgb, sharp.rgb)
    single = render(g, cam, outputs="all", motion=MotionBlur(translation=(0.3, 0, 0), rotation=(0, 0.1, 0), sub_steps=1))
    for name in ("rgb", "alpha", "depth", "median_depth", "instance_ids"):
        np.testing.assert_array_equal(getattr(single, name), getattr(sharp, name), err_msg=name)


def test_motion_blur_of_a_uniform_wall_keeps_its_colour() -> None:
    """A constant image stays constant under blur (averaging in linear light is energy-preserving)."""
    grid = np.stack(np.meshgrid(np.arange(-6.0, 6.0, 0.05), np.arange(-5.0, 5.0, 0.05)), -1).reshape(-1, 2)
    n = grid.shape[0]
    wall = Gaussians(
        np.column_stack([grid, np.full(n, 4.0)]), np.tile([1.0, 0, 0, 0], (n, 1)), np.tile([0.04, 0.04, 1e-4], (n, 1)),
        np.ones(n), np.full((n, 1, 3), 0.3),
    )
    cam = camera(64, 48)
    sharp = render(wall, cam)
    blurred = render(wall, cam, motion=MotionBlur(translation=(0.4, 0.1, 0.0), rotation=(0.0, 0.1, 0.0), sub_steps=12))
    level = sharp.rgb.mean()
    ripple = np.abs(sharp.rgb - level).max()  # the splat grid's own ±1–2 % ripple
    assert ripple < 0.03 * level
    assert abs(blurred.rgb.mean() - level) < 2e-3 * level
    assert np.abs(blurred.rgb - level).max() <= ripple + 1e-6  # averaging never leaves the range


def test_sub_step_fast_path_chooses_sub_steps_from_displacement_and_matches_the_reference() -> None:
    """The sub-step fast path (fisheye cameras; the keyframe path is tested in test_motion_keyframes.py)."""
    rng = np.random.default_rng(3)
    g = random_gaussians(3000, rng, scale=(0.02, 0.15), opacity=(0.5, 1.0))
    cam = camera(96, 72)
    motion = dict(translation=(0.2, 0.05, 0.0), rotation=(0.0, 0.05, 0.0))
    displacement, feature = motion_extent(g, cam, MotionBlur(**motion))
    assert 10 < displacement < 60 and 0.5 < feature < 5  # ~0.2 m at 2–6 m and 0.05 rad at f ≈ 77 px
    fast = render_motion_substeps(MotionJob(g, cam, MotionBlur(**motion, fast=True), frozenset({"rgb"})))
    assert fast.stats["sub_steps"] == choose_sub_steps(displacement, feature, 80) < 40
    reference = render(g, cam, motion=MotionBlur(**motion, sub_steps=80))
    assert reference.stats["sub_steps"] == 80
    from spacedg.render.colour import linear_to_srgb

    mse = np.mean((np.clip(linear_to_srgb(fast.rgb), 0, 1) - np.clip(linear_to_srgb(reference.rgb), 0, 1)) ** 2)
    # sparse opaque blobs on black are the hardest case for few sub-steps (33 dB here with
    # 2 sub-steps); textured rooms reach ~50 dB, see benchmarks/render.py
    assert 10 * math.log10(1 / mse) > 30


def test_the_compiled_path_length_is_the_camera_loop_it_replaced() -> None:
    """``motion_extent``'s longest path on a pinhole camera (compiled, :func:`~spacedg.render.motion_error_cpu.longest_path`)
    against the loop over one camera a pose it replaced, within float64 rounding: a camera that moves through the cloud
    (points pass behind it, their steps then count 0) and turns."""
    from spacedg.render.camera import exposure_poses

    rng = np.random.default_rng(5)
    g = random_gaussians(4000, rng, scale=(0.02, 0.1), opacity=(0.5, 1.0))
    cam = camera(96, 72)
    for motion in (MotionBlur(translation=(0.3, 0.1, 2.5), rotation=(0.05, 0.4, 0.1)), MotionBlur(translation=(0.0, 0.0, 0.0), rotation=(0.0, 0.0, 0.3))):
        points = g.means.astype(np.float64)
        uv, depth, ok = cam.project(points)
        points = points[ok & cam.in_image(uv) & (depth > 1e-3)]
        length, previous = np.zeros(len(points)), None
        for pose in exposure_poses(cam, np.array(motion.translation), np.array(motion.rotation), np.linspace(-0.5, 0.5, 9)):
            uv, depth, ok = cam.with_pose(pose).project(points)
            uv = np.where((ok & (depth > 1e-3))[:, None], uv, np.nan)
            if previous is not None:
                length += np.nan_to_num(np.linalg.norm(uv - previous, axis=1), nan=0.0)
            previous = uv
        assert motion_extent(g, cam, motion)[0] == pytest.approx(float(length.max()), rel=1e-12)


def test_motion_depth_and_ids_are_those_of_mid_exposure() -> None:
    g = random_gaussians(500, np.random.default_rng(4))
    cam = camera(64, 48)
    sharp = render(g, cam, outputs="all")
    moving = render(g, cam, outputs="all", motion=MotionBlur(translation=(0.2, 0, 0), sub_steps=6))
    np.testing.assert_array_equal(moving.instance_ids, sharp.instance_ids)
    np.testing.assert_array_equal(moving.median_depth, sharp.median_depth)
    assert np.isfinite(moving.depth).all() and not np.array_equal(moving.rgb, sharp.rgb)


@pytest.mark.parametrize(
    "kwargs, fragment",
    [
        ({"translation": (1.0, 2.0)}, "translation"),
        ({"rotation": (0.0, 4.0, 0.0)}, "π"),
        ({"sub_steps": 0}, "sub_steps"),
        ({"translation": (math.inf, 0, 0)}, "finite"),
    ],
)
def test_bad_motion_is_refused(kwargs: dict, fragment: str) -> None:
    with pytest.raises(ParameterError, match=fragment):
        MotionBlur(**kwargs)


# ---------------------------------------------------------------- requests
def test_bad_requests_name_the_problem() -> None:
    g = one_gaussian()
    cam = camera()
    with pytest.raises(ParameterError, match="unknown render output"):
        render(g, cam, outputs="rgb,normals")
    with pytest.raises(ParameterError, match="unknown render backend"):
        render(g, cam, backend="vulkan")
    with pytest.raises(ParameterError, match="CPU only"):
        render(g, cam, backend="cpu", device="meta")
    with pytest.raises(ParameterError, match="alpha_max"):
        RasterSettings(alpha_max=1.0)
    with pytest.raises(ParameterError, match="needs a Camera"):
        render(g, "camera")  # type: ignore[arg-type]


def test_empty_scene_renders_black() -> None:
    frame = render(Gaussians.empty(), camera(), outputs="all")
    assert not frame.alpha.any() and not frame.rgb.any() and (frame.instance_ids == -1).all()
    frame = render(Gaussians.empty(), camera(), outputs="all", backend="torch")
    assert not frame.alpha.any()


def test_spacedg_render_is_the_package_and_the_function() -> None:
    import spacedg
    import spacedg.render.motion as motion_module

    assert callable(spacedg.render) and spacedg.render.Camera is spacedg.Camera
    assert motion_module.STEP_SIGMAS > 0
    frame = spacedg.render(one_gaussian(), camera())
    assert frame.alpha.max() > 0


@pytest.mark.parametrize("defocus", [Defocus(6.0, 2.0), Defocus(12.0, 5.0)])
def test_defocus_compiled_and_torch_paths_agree(defocus: Defocus, monkeypatch) -> None:
    """Both paths apply the same energy-keeping alpha floor and 2.5 σ truncation of blurred footprints (the
    compiled path's per-tile sampling of widely blurred tiles, which the torch path does not do, turned off)."""
    from spacedg.render import defocus as model

    monkeypatch.setattr(model, "TILE_SAMPLE_MIN_COC", 0.0)
    gaussians = random_gaussians(3000, np.random.default_rng(0))
    cam = camera(96, 72)
    compiled = render(gaussians, cam, defocus=defocus, backend="cpu")
    reference = render(gaussians, cam, defocus=defocus, backend="torch")
    assert np.abs(compiled.rgb - reference.rgb).max() < 1e-3
    assert np.abs(compiled.alpha - reference.alpha).max() < 1e-4

"""Projection oracles: gsplat 1.5.3's torch reference, OpenCV's fisheye model, finite differences."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
import torch

from tests.render_helpers import random_gaussians
from spacedg.render import RasterSettings
from spacedg.render import project_torch
from spacedg.render import project_cpu, raster_cpu
from spacedg.render.camera import Camera, FisheyeLens, look_at
from spacedg.render.project_cpu import CA, CB, CC, OPA, PX, PY, RADX, RADY

gsplat_ref = pytest.importorskip("gsplat.cuda._torch_impl", reason="gsplat==1.5.3 is a test dependency")

COMPAT = RasterSettings(opacity_extent=False, tight_tiles=False)


def scene(seed: int, n: int = 1500):
    """Random Gaussians around the origin seen by a camera at a random pose, some behind it."""
    rng = np.random.default_rng(seed)
    g = random_gaussians(n, rng, depth=(-2.0, 8.0), half_width=4.0, scale=(0.005, 0.3))
    eye = rng.normal(0, 0.3, 3)
    pose = look_at(eye, eye + np.array([0.1, -0.05, 1.0]), np.array([0.0, -1.0, 0.0]))
    return g, pose


def gsplat_projection(g, cam: Camera, model: str, antialiased: bool):
    t = lambda a: torch.from_numpy(np.array(a, dtype=np.float64))  # noqa: E731
    covars, _ = gsplat_ref._quat_scale_to_covar_preci(t(g.quats), t(g.scales), compute_preci=False)
    radii, means2d, depths, conics, comp = gsplat_ref._fully_fused_projection(
        t(g.means), covars, t(cam.world_to_cam)[None], t(cam.K)[None], cam.width, cam.height,
        eps2d=0.3, near_plane=0.01, far_plane=1e10, calc_compensations=antialiased, camera_model=model,
    )
    opacity = t(g.opacities) * (comp[0] if antialiased else 1.0)
    return radii[0].numpy(), means2d[0].numpy(), conics[0].numpy(), opacity.numpy(), depths[0].numpy()


def our_projections(g, cam: Camera, settings: RasterSettings):
    packed, rects = project_cpu.project_gaussians(g, cam, settings)
    gs = project_torch.GaussianTensors.of(g, "cpu", torch.float64)
    proj = project_torch.project_gaussians(gs, cam, settings)
    return packed, rects, proj


@pytest.mark.parametrize("antialiased", [False, True])
@pytest.mark.parametrize("model", ["pinhole", "fisheye"])
def test_projection_matches_gsplat_reference(model: str, antialiased: bool) -> None:
    g, pose = scene(1)
    lens = FisheyeLens() if model == "fisheye" else None
    cam = Camera(420.0, 415.0, 161.3, 119.2, 320, 240, pose, lens)
    settings = RasterSettings(opacity_extent=False, tight_tiles=False, antialiased=antialiased)
    radii, means2d, conics, opacity, _ = gsplat_projection(g, cam, model, antialiased)
    packed, rects, proj = our_projections(g, cam, settings)
    ref_visible = (radii > 0).all(1)
    assert 200 < ref_visible.sum() < len(g)  # some culled, many kept
    for name, visible, ours_means, ours_conics, ours_opacity, ours_radii in (
        ("compiled", rects[:, 1] > rects[:, 0], packed[:, [PX, PY]], packed[:, [CA, CB, CC]], packed[:, OPA], packed[:, [RADX, RADY]]),
        ("torch", proj.visible.numpy(), proj.means2d.numpy(), proj.conics.numpy(), proj.opacities.numpy(), proj.radii.numpy()),
    ):
        np.testing.assert_array_equal(visible, ref_visible, err_msg=name)
        v = ref_visible
        np.testing.assert_array_equal(ours_radii[v], radii[v], err_msg=name)
        np.testing.assert_allclose(ours_means[v], means2d[v], atol=1e-3, err_msg=name)
        np.testing.assert_allclose(ours_conics[v], conics[v], rtol=1e-4, atol=1e-9, err_msg=name)
        np.testing.assert_allclose(ours_opacity[v], opacity[v], rtol=1e-5, err_msg=name)


def test_tile_intersections_match_gsplat_isect_tiles() -> None:
    g, pose = scene(2, n=800)
    cam = Camera(300.0, 300.0, 160.0, 120.0, 320, 240, pose)
    radii, means2d, _, _, depths = gsplat_projection(g, cam, "pinhole", False)
    tiles_per_gauss, isect_ids, flatten_ids = gsplat_ref._isect_tiles(
        torch.from_numpy(means2d)[None], torch.from_numpy(radii)[None], torch.from_numpy(depths)[None], 16, 20, 15
    )
    packed, rects = project_cpu.project_gaussians(g, cam, COMPAT)
    visible = np.flatnonzero(rects[:, 1] > rects[:, 0])
    order = raster_cpu.depth_order(visible, np.ascontiguousarray(packed[:, project_cpu.DEPTH]))
    areas = (rects[:, 1] - rects[:, 0]).astype(np.int64) * (rects[:, 3] - rects[:, 2])
    offsets, gauss = raster_cpu.bin_tiles(order, rects, packed, 20, 15, 320, 240, False, int(areas.sum()))
    assert gauss.shape[0] == int(tiles_per_gauss.sum()) == isect_ids.shape[0] > 1000
    np.testing.assert_array_equal(areas, tiles_per_gauss[0].numpy())
    ref_tiles = (isect_ids >> 32).numpy()
    ref_counts = np.bincount(ref_tiles, minlength=300)
    np.testing.assert_array_equal(np.diff(offsets), ref_counts)
    np.testing.assert_array_equal(gauss, flatten_ids.numpy())  # same Gaussians, same depth order in every tile


FISHEYE_CASES = [
    FisheyeLens(0.0, 0.0, 0.0, 0.0),
    FisheyeLens(-0.24, 2e-4, 1.5e-4, 5e-5, 1.5),  # the bench preset (folds near 1.18 rad)
    FisheyeLens(0.05, -0.01, 0.002, -0.0003),
]


@pytest.mark.parametrize("lens", FISHEYE_CASES)
def test_fisheye_means_match_opencv(lens: FisheyeLens) -> None:
    rng = np.random.default_rng(3)
    theta = rng.uniform(0.0, min(lens.effective_max_theta, 1.4) - 1e-3, 500)
    theta[:3] = [0.0, 1e-9, 1e-5]
    phi = rng.uniform(0, 2 * math.pi, 500)
    dist = rng.uniform(0.5, 5.0, 500)
    pts = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], 1) * dist[:, None]
    cam = Camera(200.0, 198.0, 320.5, 240.25, 640, 480, np.eye(4), lens)
    ref, _ = cv2.fisheye.projectPoints(pts[None], np.zeros(3), np.zeros(3), cam.K, np.array(lens.coeffs))
    ref = ref[0]
    uv, _, valid = cam.project(pts)
    assert valid.all()
    np.testing.assert_allclose(uv, ref, atol=1e-3)
    uv_torch, _, _ = project_torch.fisheye_jacobian(torch.from_numpy(pts), cam)
    np.testing.assert_allclose(uv_torch.numpy(), ref, atol=1e-3)
    # the compiled kernel projects the same means
    from spacedg.render.gaussians import Gaussians

    n = len(pts)
    g = Gaussians(pts, np.tile([1.0, 0, 0, 0], (n, 1)), np.full((n, 3), 1e-3), np.ones(n), np.zeros((n, 1, 3)))
    packed, rects = project_cpu.project_gaussians(g, cam, COMPAT)
    shown = rects[:, 1] > rects[:, 0]
    assert shown.mean() > 0.9
    np.testing.assert_allclose(packed[shown][:, [PX, PY]], ref[shown], atol=1e-3)


@pytest.mark.parametrize("lens", FISHEYE_CASES)
def test_fisheye_jacobian_matches_finite_differences(lens: FisheyeLens) -> None:
    rng = np.random.default_rng(4)
    pts = np.concatenate(
        [
            rng.uniform([-2, -2, 0.5], [2, 2, 4], (200, 3)),
            np.array([[0.0, 0.0, 1.0], [1e-7, -2e-7, 2.0], [3e-5, 1e-5, 0.5], [1e-3, 0.0, 1.0]]),
        ]
    )
    theta = np.arctan2(np.hypot(pts[:, 0], pts[:, 1]), pts[:, 2])
    pts = pts[theta < lens.effective_max_theta - 1e-3]
    cam = Camera(300.0, 310.0, 320.0, 240.0, 640, 480, np.eye(4), lens)
    x = torch.from_numpy(pts)
    _, jac, _ = project_torch.fisheye_jacobian(x, cam)
    h = 1e-6
    fd = np.zeros((len(pts), 2, 3))
    for k in range(3):
        step = torch.zeros(3, dtype=torch.float64)
        step[k] = h
        plus, _, _ = project_torch.fisheye_jacobian(x + step, cam)
        minus, _, _ = project_torch.fisheye_jacobian(x - step, cam)
        fd[:, :, k] = ((plus - minus) / (2 * h)).numpy()
    np.testing.assert_allclose(jac.numpy(), fd, rtol=1e-5, atol=1e-4)


@pytest.mark.parametrize("lens", FISHEYE_CASES[1:])
def test_compiled_fisheye_covariances_match_torch_float64(lens: FisheyeLens) -> None:
    g, _ = scene(5, n=1000)
    cam = Camera(200.0, 200.0, 320.0, 240.0, 640, 480, np.eye(4), lens)
    packed, rects, proj = our_projections(g, cam, RasterSettings())
    visible = rects[:, 1] > rects[:, 0]
    np.testing.assert_array_equal(visible, proj.visible.numpy())
    ours, ref = packed[visible][:, [CA, CB, CC]], proj.conics.numpy()[visible]
    # relative to each conic's size: the off-diagonal b can be ~0, where float32 storage dominates
    scale = np.abs(ref).max(axis=1, keepdims=True)
    assert (np.abs(ours - ref) <= 1e-4 * scale).all()


def test_fold_is_the_effective_max_theta() -> None:
    bench = FisheyeLens(-0.24, 2e-4, 1.5e-4, 5e-5, 1.5)
    fold = bench.effective_max_theta
    assert 1.1 < fold < 1.25
    assert bench.distort_theta_derivative(np.float64(fold)) == pytest.approx(0.0, abs=1e-9)
    assert FisheyeLens(max_theta=1.2).effective_max_theta == 1.2
    # a Gaussian beyond the fold is culled, not mirrored back into the image
    from spacedg.render.gaussians import Gaussians

    theta = fold + 0.05
    p = np.array([[math.sin(theta), 0.0, math.cos(theta)]])
    g = Gaussians(p, [[1.0, 0, 0, 0]], [[0.01] * 3], [1.0], np.zeros((1, 1, 3)))
    _, rects = project_cpu.project_gaussians(g, Camera(200.0, 200.0, 320.0, 240.0, 640, 480, np.eye(4), bench), RasterSettings())
    assert rects[0, 1] == rects[0, 0]


def test_sh_colour_matches_numpy_evaluation() -> None:
    from spacedg.render.gaussians import eval_sh

    for degree in range(4):
        rng = np.random.default_rng(degree)
        g = random_gaussians(300, rng, sh_degree=degree)
        cam = Camera(100.0, 100.0, 64.0, 48.0, 128, 96, look_at([0.2, 0.1, -0.5], [0, 0, 4], [0, -1, 0]))
        packed, rects = project_cpu.project_gaussians(g, cam, RasterSettings())
        dirs = g.means.astype(np.float64) - cam.center
        dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
        expected = np.maximum(eval_sh(g.sh.astype(np.float64), dirs), 0.0)
        shown = rects[:, 1] > rects[:, 0]
        np.testing.assert_allclose(packed[shown][:, project_cpu.CR : project_cpu.CBL + 1], expected[shown], atol=2e-6)


@pytest.mark.parametrize("lens", [None, FisheyeLens(0.05, -0.01, 0.0, 0.0, max_theta=1.4)], ids=["pinhole", "fisheye"])
def test_the_blocks_of_the_parallel_projection_change_no_row(lens) -> None:
    """The parallel kernel projects blocks of Gaussians (project_block): every row is the projection of that
    Gaussian alone, whatever the block size, with kept Gaussians on the first and last rows of every block and
    of the set; with the paired sharp pass too, and on the serial twin."""
    from spacedg.render.settings import Defocus
    from spacedg.render.threads import serial_kernels

    g, pose = scene(31, n=600)
    cam = Camera(fx=300.0, fy=300.0, cx=160.0, cy=120.0, width=320, height=240, cam_to_world=pose, fisheye=lens)
    settings = RasterSettings()
    alone, alone_rects = project_cpu.project_gaussians(g, cam, settings)
    kept, culled = np.flatnonzero(alone_rects[:, 1] > alone_rects[:, 0]), np.flatnonzero(alone_rects[:, 1] <= alone_rects[:, 0])
    n, block = 30, 7
    edges = sorted({0, n - 1} | {e for b in range(0, n, block) for e in (b, min(b + block, n) - 1)})
    order = np.array([kept[k] if k in edges else culled[k] for k in range(n)])  # kept rows on every block's edges
    h = g.subset(order)
    expected = project_cpu._project(h, cam, settings, None, True, None, None, block=1)
    assert np.array_equal(expected[0], alone[order]) and np.array_equal(expected[1], alone_rects[order])
    assert (expected[1][edges, 1] > expected[1][edges, 0]).all()
    defocus = Defocus(aperture=4.0, focus=3.0, max_radius=30.0)
    paired = project_cpu._project(h, cam, settings, defocus, True, cam, settings, block=1)
    for size in (2, block, n - 1, n, 4 * n, None):
        got = project_cpu._project(h, cam, settings, None, True, None, None, block=size)
        assert all(np.array_equal(a, b) for a, b in zip(got, expected)), size
        got = project_cpu._project(h, cam, settings, defocus, True, cam, settings, block=size)
        assert all(np.array_equal(a, b) for a, b in zip(got, paired)), size
    with serial_kernels():
        twin = project_cpu._project(h, cam, settings, None, True, None, None, block=block)
    assert all(np.array_equal(a, b) for a, b in zip(twin, expected))
    empty = project_cpu.project_gaussians(g.subset(slice(0, 0)), cam, settings)
    assert empty[0].shape == (0, project_cpu.PACKED) and empty[1].shape == (0, 4)

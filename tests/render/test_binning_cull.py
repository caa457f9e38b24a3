"""Tight tile binning (per-row strip test) and the projection's coarse frustum pre-cull.

The binning must keep every tile where some pixel centre has ``α >= f`` (``σ <= ln(o / f)``) and
only tiles of the footprint's rectangle, each list in depth order; the pre-cull must change no
projected Gaussian (a camera looking across a scene, most of it out of view)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from spacedg.render import RasterSettings, project_cpu, raster_cpu
from spacedg.render.camera import Camera, FisheyeLens, look_at
from spacedg.render.project_cpu import AMIN, CA, CB, CC, DEPTH, OPA, PACKED, PX, PY
from spacedg.render.settings import Defocus, footprint_dilation
from tests.render_helpers import random_gaussians

W, H, TX, TY = 320, 240, 20, 15


def _random_conics(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    """``n`` random footprints (some nearly degenerate) and their 3.33-sigma tile rectangles."""
    packed = np.zeros((n, PACKED), np.float32)
    packed[:, PX], packed[:, PY] = rng.uniform(-40, W + 40, n), rng.uniform(-40, H + 40, n)
    sx, sy = np.exp(rng.uniform(-1, 4, n)), np.exp(rng.uniform(-1, 4, n))
    rho = rng.uniform(-0.999, 0.999, n)
    det = (sx * sy) ** 2 * (1 - rho**2)
    packed[:, CA], packed[:, CB], packed[:, CC] = sy**2 / det, -rho * sx * sy / det, sx**2 / det
    packed[:, OPA], packed[:, AMIN], packed[:, DEPTH] = rng.uniform(0.01, 1, n), 1 / 255, rng.uniform(1, 5, n)
    u, v = packed[:, PX].astype(np.float64), packed[:, PY].astype(np.float64)
    rx, ry = np.ceil(3.33 * sx), np.ceil(3.33 * sy)
    rects = np.stack([np.clip(np.floor((u - rx) / 16), 0, TX), np.clip(np.ceil((u + rx) / 16), 0, TX),
                      np.clip(np.floor((v - ry) / 16), 0, TY), np.clip(np.ceil((v + ry) / 16), 0, TY)], 1)
    return packed, rects.astype(np.int32)


def _reached_tiles(p: np.ndarray, rect: np.ndarray) -> set[int]:
    """Tiles of ``rect`` with a pixel centre where ``σ <= ln(o / f)`` (brute force)."""
    ys, xs = np.mgrid[rect[2] * 16 : min(rect[3] * 16, H), rect[0] * 16 : min(rect[1] * 16, W)]
    dx, dy = xs + 0.5 - p[PX], ys + 0.5 - p[PY]
    sigma = 0.5 * (p[CA] * dx * dx + p[CC] * dy * dy) + p[CB] * dx * dy
    hit = sigma <= math.log(p[OPA] / p[AMIN])
    return set((ys[hit] // 16 * TX + xs[hit] // 16).tolist())


def test_tight_binning_keeps_every_reached_tile_in_depth_order() -> None:
    packed, rects = _random_conics(np.random.default_rng(7), 150)
    offsets, gauss = raster_cpu.bin_visible(packed, rects, W, H, True)
    kept: dict[int, set[int]] = {}
    for t in range(TX * TY):
        members = gauss[offsets[t] : offsets[t + 1]]
        assert np.all(np.diff(packed[members, DEPTH]) >= 0)
        for g in members.tolist():
            kept.setdefault(g, set()).add(t)
    dropped = 0
    for g in range(len(packed)):
        x0, x1, y0, y1 = rects[g]
        box = {ty * TX + tx for ty in range(y0, y1) for tx in range(x0, x1)}
        assert _reached_tiles(packed[g], rects[g]) <= kept.get(g, set()) <= box
        dropped += len(box) - len(kept.get(g, set()))
    assert dropped > 50  # the tight test did drop tiles


def _near_the_fisheye_edges(g, cam: Camera, rng: np.random.Generator):  # type: ignore[no-untyped-def]
    """``g`` with its first half moved onto rays near ``cam``'s image edges (up to 40 px beyond them, by the lens's
    own mapping) and near its max θ (±0.05 rad), 0.5–8 m away, in world coordinates."""
    from dataclasses import replace

    lens = cam.fisheye
    n = len(g) // 2
    edge = rng.integers(0, 5, n)  # left, right, top, bottom edge; 4: the lens's max θ
    u = np.where(edge == 0, rng.uniform(-40, 0, n), np.where(edge == 1, rng.uniform(W, W + 40, n), rng.uniform(0, W, n)))
    v = np.where(edge == 2, rng.uniform(-40, 0, n), np.where(edge == 3, rng.uniform(H, H + 40, n), rng.uniform(0, H, n)))
    x, y = (u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy
    theta_d = np.hypot(x, y)
    theta = np.array([_undistort(float(t), lens) for t in theta_d])
    theta = np.where(edge == 4, lens.effective_max_theta + rng.uniform(-0.05, 0.05, n), theta)
    phi = np.arctan2(y, x)
    rays = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], 1)
    points = rays * rng.uniform(0.5, 8.0, n)[:, None]
    means = g.means.copy()
    means[:n] = (cam.center + points @ cam.rotation.T).astype(means.dtype)
    return replace(g, means=means)


def _undistort(theta_d: float, lens: FisheyeLens) -> float:
    """θ with ``lens.distort_theta(θ) = theta_d`` (bisection over [0, π), where the polynomial rises)."""
    lo, hi = 0.0, math.pi - 1e-6
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if float(lens.distort_theta(np.float64(mid))) < theta_d else (lo, mid)
    return 0.5 * (lo + hi)


@pytest.mark.parametrize("lens", [None, FisheyeLens(-0.05, 0.01, 0.0, 0.0, 1.4), FisheyeLens(0.02, -0.01, 0.001, 0.0, 2.0)], ids=["pinhole", "fisheye", "wide-fisheye"])
@pytest.mark.parametrize("defocus", [None, Defocus(8.0, 2.0), Defocus(60.0, 0.5)], ids=["sharp", "defocus", "wide-defocus"])
def test_pre_cull_changes_no_projection(defocus: Defocus | None, lens: FisheyeLens | None) -> None:
    """The frustum pre-cull (also under defocus, widened by each Gaussian's circle of confusion; through a fisheye
    lens with its Jacobian, beyond its max θ as the full test) culls only what the full test culls: the projection
    is the same with it disabled."""
    g = random_gaussians(3000, np.random.default_rng(3), depth=(-6.0, 6.0), half_width=6.0, scale=(0.01, 0.3))
    pose = look_at(np.array([0.0, 0.0, 0.0]), np.array([5.0, 0.5, 3.0]), np.array([0.0, -1.0, 0.0]))
    cam = Camera(200.0 if lens is None else 90.0, 200.0 if lens is None else 90.0, 160.0, 120.0, W, H, pose, fisheye=lens)
    if lens is not None:  # half of them where the fisheye pre-cull decides: rays just off the image's edges and its max θ
        g = _near_the_fisheye_edges(g, cam, np.random.default_rng(4))
    packed, rects = project_cpu.project_gaussians(g, cam, RasterSettings(), defocus)
    assert 0 < np.count_nonzero(rects[:, 1] > rects[:, 0]) < len(g) // 2
    # the same projection with the pre-cull disabled (a rotation norm of infinity never culls)
    ref_packed, ref_rects = np.empty_like(packed), np.empty_like(rects)
    view, s = cam.world_to_cam, RasterSettings()
    project_cpu._project_kernel(
        g.means, g.quats, g.scales, g.opacities, g.sh, g.sh_degree, True,
        np.ascontiguousarray(view[:3, :3]), np.ascontiguousarray(view[:3, 3]), np.array(cam.center), math.inf,
        cam.fx, cam.fy, cam.cx, cam.cy, W, H, lens is not None, *(lens.coeffs if lens else (0.0, 0.0, 0.0, 0.0)),
        lens.effective_max_theta if lens else math.pi,
        s.near, s.far, *footprint_dilation(cam, s), s.opacity_extent,
        defocus.aperture if defocus else 0.0, defocus.focus if defocus else 1.0, defocus.max_radius if defocus else 0.0,
        s.defocus_extent or 0.0, ref_packed, ref_rects, project_cpu._NO_SHARP_VIEW,
        np.empty((0, project_cpu.PACKED), np.float32), np.empty((0, 4), np.int32), project_cpu.project_block(len(g), 2),
    )
    np.testing.assert_array_equal(packed, ref_packed)
    np.testing.assert_array_equal(rects, ref_rects)

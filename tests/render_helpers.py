"""Shared builders and the tile-free brute-force compositor used by the renderer tests."""

from __future__ import annotations

import numpy as np

from spacedg.render.camera import Camera
from spacedg.render.gaussians import Gaussians


def random_gaussians(
    n: int,
    rng: np.random.Generator,
    *,
    depth: tuple[float, float] = (2.0, 6.0),
    half_width: float = 1.5,
    scale: tuple[float, float] = (0.01, 0.1),
    sh_degree: int = 1,
    instances: int = 5,
    opacity: tuple[float, float] = (0.05, 1.0),
) -> Gaussians:
    """``n`` random Gaussians in front of an identity-pose camera (z in ``depth``)."""
    means = np.stack(
        [rng.uniform(-half_width, half_width, n), rng.uniform(-half_width * 0.75, half_width * 0.75, n), rng.uniform(*depth, n)], 1
    )
    quats = rng.normal(size=(n, 4))
    quats /= np.linalg.norm(quats, axis=1, keepdims=True)
    scales = np.exp(rng.uniform(np.log(scale[0]), np.log(scale[1]), (n, 3)))
    opacities = rng.uniform(*opacity, n)
    sh = rng.normal(0.0, 0.4, (n, (sh_degree + 1) ** 2, 3))
    ids = rng.integers(-1, instances, n)
    return Gaussians(means, quats, scales, opacities, sh, ids.astype(np.int32))


def camera(width: int = 64, height: int = 48, focal: float | None = None, pose: np.ndarray | None = None) -> Camera:
    """A pinhole camera with ~65° horizontal field of view, principal point off-centre by a bit."""
    f = focal if focal is not None else width * 0.8
    return Camera(f, f * 1.01, width / 2 + 0.37, height / 2 - 0.21, width, height, np.eye(4) if pose is None else pose)


def brute_force_composite(packed: np.ndarray, rects: np.ndarray, ids: np.ndarray, width: int, height: int, alpha_max: float) -> dict:
    """Every visible Gaussian against every pixel, front to back, in float64, one pixel at a time.

    Implements the compositing rules literally (no tiles, no vectorisation): the oracle for
    both compositors.
    """
    from spacedg.render.project_cpu import AMIN, CA, CB, CBL, CC, CG, CR, DEPTH, OPA, PX, PY

    visible = np.flatnonzero(rects[:, 1] > rects[:, 0])
    order = visible[np.argsort(packed[visible, DEPTH], kind="stable")]
    rgb = np.zeros((height, width, 3))
    alpha = np.zeros((height, width))
    depth = np.zeros((height, width))
    median = np.zeros((height, width))
    inst = np.full((height, width), -1, np.int64)
    for i in range(height):
        for j in range(width):
            t = 1.0
            acc = np.zeros(3)
            acc_d = 0.0
            med, mid = 0.0, -1
            for g in order:
                rec = packed[g].astype(np.float64)
                dx, dy = j + 0.5 - rec[PX], i + 0.5 - rec[PY]
                sigma = 0.5 * (rec[CA] * dx * dx + rec[CC] * dy * dy) + rec[CB] * dx * dy
                if sigma < 0:
                    continue
                a = min(alpha_max, rec[OPA] * np.exp(-sigma))
                if a < rec[AMIN]:
                    continue
                t_next = t * (1.0 - a)
                if t_next <= 1e-4:
                    break
                w = a * t
                acc += w * rec[[CR, CG, CBL]]
                acc_d += w * rec[DEPTH]
                if t > 0.5:
                    med, mid = rec[DEPTH], int(ids[g])
                t = t_next
            rgb[i, j] = acc
            alpha[i, j] = 1.0 - t
            depth[i, j] = acc_d / (1.0 - t) if t < 1.0 else 0.0
            median[i, j] = med
            inst[i, j] = mid if t <= 0.5 else -1
    return {"rgb": rgb, "alpha": alpha, "depth": depth, "median_depth": median, "instance_ids": inst}


def uniform_wall(extent_px: float, focal: float = 40.0, depth: float = 3.0, sigma_px: float = 5.0, colour: float = 0.45) -> Gaussians:
    """An opaque uniformly coloured plane of splats at ``depth`` m, ±``extent_px`` pixels wide for a camera
    of focal length ``focal`` px at the origin looking down +z (sigma ``sigma_px`` px, spacing 1.6 σ)."""
    metres_per_px = depth / focal
    spacing = 1.6 * sigma_px * metres_per_px
    half = extent_px * metres_per_px
    axis = np.arange(-half, half + spacing, spacing)
    grid = np.stack(np.meshgrid(axis, axis), -1).reshape(-1, 2)
    n = grid.shape[0]
    means = np.column_stack([grid, np.full(n, depth)])
    scales = np.tile([sigma_px * metres_per_px, sigma_px * metres_per_px, 1e-4], (n, 1))
    return Gaussians.from_colors(means, np.tile([1.0, 0, 0, 0], (n, 1)), scales, np.ones(n), np.full((n, 3), colour))


def thin_lens_means(gaussians: Gaussians, camera: Camera, aperture: float, focus: float, samples: int = 32, seed: int = 0) -> tuple[float, float]:
    """Mean linear radiance and alpha coverage of the thin-lens reference (:func:`spacedg.render.thin_lens.thin_lens_render`)."""
    from spacedg.render import Defocus
    from spacedg.render.thin_lens import thin_lens_render

    ref = thin_lens_render(gaussians, camera, Defocus(aperture, focus), samples=samples, seed=seed)
    return float(ref["rgb"].mean()), float(ref["alpha"].mean())


def opaque_ball(n: int = 1500, radius: float = 0.5, depth: float = 3.0, colour: float = 0.6, seed: int = 0) -> Gaussians:
    """An opaque ball of ``n`` splats (σ = radius/12) on a sphere of ``radius`` m centred ``depth`` m down +z:
    an object in front of an empty background."""
    rng = np.random.default_rng(seed)
    normals = rng.normal(size=(n, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    means = normals * radius + np.array([0.0, 0.0, depth])
    scales = np.full((n, 3), radius / 12.0)
    return Gaussians.from_colors(means, np.tile([1.0, 0, 0, 0], (n, 1)), scales, np.full(n, 0.95), np.full((n, 3), colour))

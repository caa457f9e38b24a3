"""Motion blur: average sub-exposure renders over the camera's path, in linear light.

The render's camera is the **mid-exposure** pose (the question's ground truth). The path
over the exposure is :func:`~spacedg.render.camera.exposure_poses` (slerp rotation, lerp
centre); sub-exposure k of K is centred at time ``s_k = (k + ½)/K − ½``.

- Reference (``MotionBlur(fast=False)``): K = ``sub_steps`` sharp renders (80 is the
  paper's reference), averaged.
- Fast (``fast=True``): K is chosen from the largest on-screen path length D (pixels) of
  the scene's visible Gaussians during the exposure and the scene's feature size: ghosts
  between sub-steps vanish once the step is small against the footprints being swept, so
  ``step = clamp(STEP_SIGMAS · σ_med, MIN_STEP_PX, MAX_STEP_PX)`` with σ_med the median
  on-screen standard deviation of the visible Gaussians, and ``K = ceil(D / step)`` clamped
  to [1, sub_steps]. ``benchmarks/render.py`` measures time and PSNR against N = 80.
  The 5 px cap is what the real plant capture needs for > 40 dB (its texture is finer than
  its Gaussians: 8 sub-steps over 75 px gave 35.6 dB, 16 gave 43.7 dB); the procedural
  rooms are smoother (8 sub-steps over 143 px already gave 43 dB), so the cap costs them
  time. Measuring texture instead of footprint size would let smooth scenes use fewer steps.

  Tried and dropped: stretching each Gaussian along its own on-screen sweep inside a
  sub-exposure (covariance ``+ d dᵀ/12``, energy-compensated) to stand in for the missing
  sub-steps. A Gaussian streak is not the box-shaped sweep the reference averages, and it
  enlarges every footprint: at equal K it was 0–2 dB *worse* and 10–40 % slower.

Outputs under motion: ``rgb`` and ``alpha`` are exposure averages; ``depth`` is the
alpha-weighted average of the sub-exposure depths; ``median_depth`` and ``instance_ids`` are
those of the mid-exposure pose (a sharp render), since they label what the question asks about.
"""

from __future__ import annotations

import math
import time
from typing import TYPE_CHECKING

import numpy as np

from spacedg.render.camera import Camera, exposure_poses
from spacedg.render.composite import composite_view, frame_from_images
from spacedg.render.frame import Frame
from spacedg.render.gaussians import Gaussians
from spacedg.render.settings import Defocus, MotionBlur, RasterSettings

if TYPE_CHECKING:
    import torch

#: Fast path: sub-exposure step as a multiple of the median footprint standard deviation …
STEP_SIGMAS = 5.0
#: … clamped to this range of on-screen pixels.
MIN_STEP_PX, MAX_STEP_PX = 1.5, 5.0
#: Gaussians sampled (evenly strided) to measure the on-screen displacement.
_DISPLACEMENT_SAMPLE = 8192


def sub_exposure_times(count: int) -> np.ndarray:
    """Centres of ``count`` equal sub-exposures, as fractions of the exposure in [-½, ½]."""
    return (np.arange(count, dtype=np.float64) + 0.5) / count - 0.5


def motion_extent(gaussians: Gaussians, camera: Camera, motion: MotionBlur, pieces: int = 8) -> tuple[float, float]:
    """``(D, σ_med)``: the largest on-screen path length (pixels) of a Gaussian mean visible
    at mid-exposure, and the median on-screen standard deviation (pixels) of those Gaussians.

    Measured on an evenly strided sample of the means, along the path cut into ``pieces``
    straight segments (so a rotation's curved sweep is not underestimated). σ is
    approximated as ``f · max(scale) / z`` (a surfel's in-plane size; enough to choose a step).
    """
    stride = max(1, len(gaussians) // _DISPLACEMENT_SAMPLE)
    points = gaussians.means[::stride].astype(np.float64)
    if points.shape[0] == 0:
        return 0.0, 0.0
    uv_mid, depth_mid, ok_mid = camera.project(points)
    visible = ok_mid & camera.in_image(uv_mid) & (depth_mid > 1e-3)
    if not visible.any():
        return 0.0, 0.0
    points = points[visible]
    sizes = gaussians.scales[::stride][visible].astype(np.float64).max(axis=1)
    sigma = float(np.median(0.5 * (camera.fx + camera.fy) * sizes / depth_mid[visible]))
    poses = exposure_poses(camera, np.array(motion.translation), np.array(motion.rotation), np.linspace(-0.5, 0.5, pieces + 1))
    length = np.zeros(points.shape[0])
    previous = None
    for pose in poses:
        uv, depth, ok = camera.with_pose(pose).project(points)
        uv = np.where((ok & (depth > 1e-3))[:, None], uv, np.nan)
        if previous is not None:
            length += np.nan_to_num(np.linalg.norm(uv - previous, axis=1), nan=0.0)
        previous = uv
    return float(length.max()), sigma


def choose_sub_steps(displacement_px: float, feature_px: float, max_steps: int) -> int:
    """Fast-path sub-exposure count for a sweep of ``displacement_px`` over features of ``feature_px``."""
    step = min(max(STEP_SIGMAS * feature_px, MIN_STEP_PX), MAX_STEP_PX)
    return int(min(max(math.ceil(displacement_px / step), 1), max_steps))


def render_motion(
    gaussians: Gaussians,
    camera: Camera,
    motion: MotionBlur,
    wanted: frozenset[str],
    backend: str,
    device: torch.device | None,
    settings: RasterSettings,
    defocus: Defocus | None,
) -> Frame:
    """Render a motion-blurred frame (see the module docstring)."""
    t0 = time.perf_counter()
    translation, rotation = np.array(motion.translation), np.array(motion.rotation)
    if motion.fast:
        displacement, feature = motion_extent(gaussians, camera, motion)
        count = choose_sub_steps(displacement, feature, motion.sub_steps)
    else:
        displacement, count = math.nan, motion.sub_steps
    times = sub_exposure_times(count)
    poses = exposure_poses(camera, translation, rotation, times)
    blur_outputs = frozenset(wanted & {"rgb", "depth"})
    rgb = np.zeros((camera.height, camera.width, 3), np.float64) if "rgb" in wanted else None
    alpha = np.zeros((camera.height, camera.width), np.float64)
    depth_sum = np.zeros((camera.height, camera.width), np.float64) if "depth" in wanted else None
    pairs = 0
    for pose in poses:
        images, stats = composite_view(
            gaussians, camera.with_pose(pose), blur_outputs or frozenset({"alpha"}), backend, device, settings, defocus
        )
        pairs += stats["pairs"]
        alpha += images["alpha"]
        if rgb is not None:
            rgb += images["rgb"]
        if depth_sum is not None:
            depth_sum += images["depth"] * images["alpha"]
    images = {"alpha": (alpha / count).astype(np.float32)}
    if rgb is not None:
        images["rgb"] = (rgb / count).astype(np.float32)
    if depth_sum is not None:
        images["depth"] = np.where(alpha > 0, depth_sum / np.maximum(alpha, 1e-30), 0.0).astype(np.float32)
    if wanted & {"median_depth", "instance_ids"}:
        sharp, _ = composite_view(gaussians, camera, frozenset({"instance_ids"}), backend, device, settings, defocus)
        images["median_depth"], images["instance_ids"] = sharp["median_depth"], sharp["instance_ids"]
    frame = frame_from_images(images, camera, wanted)
    frame.stats = {
        "sub_steps": count,
        "displacement_px": displacement,
        "pairs": pairs,
        "ms": (time.perf_counter() - t0) * 1e3,
    }
    return frame

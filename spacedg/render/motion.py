"""Motion blur: average sub-exposure renders over the camera's path, in linear light.

The render's camera is the **mid-exposure** pose (the question's ground truth). The path
over the exposure is :func:`~spacedg.render.camera.exposure_poses` (slerp rotation, lerp
centre); sub-exposure k of K is centred at time ``s_k = (k + ½)/K − ½``.

- Reference (``MotionBlur(fast=False)``): K = ``sub_steps`` sharp renders (80 is the
  paper's reference), averaged.
- Fast (``fast=True``, pinhole cameras): ``K`` keyframes and depth-reprojected path gathers
  (:func:`render_motion_keyframes`, kernels in :mod:`spacedg.render.motion_warp`). The
  exposure is cut into ``K`` equal intervals, ``K`` the smallest count whose predicted error meets
  the goal (:mod:`spacedg.render.motion_error`: a quarter-resolution render of the view gives the
  contrast times the parallax across its depth edges, where the warp errs; skipped without
  translation or when the path alone asks for the most), at least one per 128 px of the longest
  on-screen path (:func:`motion_extent`) and at most :data:`MAX_KEYFRAMES`; each interval's
  centre pose is rendered once (with depth, on a canvas widened by the path so what the camera
  sweeps in is rendered) and every output pixel
  averages the keyframe along the segment it sees during the interval, sampled every ≤ 1 px
  (up to :data:`DOUBLING_PASSES` box-doubling passes for long paths, :func:`doubling_passes`, then a
  gather every ``PATH_SPACING_PX``; segments over
  empty canvas are skipped). The smear
  is integrated continuously, so there are no stroboscopic copies at any path length; the cost
  is ``K`` canvas renders (and the quarter-resolution one) plus ~1–2 render-equivalents of warping per keyframe on a 165k-Gaussian
  room (more, relative, on cheap scenes: the warp costs per pixel) (``benchmarks/render.py`` prints
  time, PSNR vs N = 80 and N = 256, and a ghosting measure per scene and severity;
  ``benchmarks/motion_keyframes.py`` the counts and PSNR per view of the dataset's rooms). Where the
  approximation is inexact: the depth of what a pixel sees during an interval is taken from the
  keyframe at that pixel (off in a band of the interval's parallax around depth edges), and
  view-dependent colour is that of the keyframe's pose.
- Fast on a fisheye camera (no closed-form reprojection here): the sub-step fast path below
  (:func:`choose_sub_steps`), the previous default.

  Sub-step fast path: K is chosen from the largest on-screen path length D (pixels) of
  the scene's visible Gaussians during the exposure and the scene's feature size: ghosts
  between sub-steps vanish once the step is small against the footprints being swept, so
  ``step = clamp(STEP_SIGMAS · σ_med, MIN_STEP_PX, MAX_STEP_PX)`` with σ_med the median
  on-screen standard deviation of the visible Gaussians, and ``K = ceil(D / step)`` clamped
  to [1, sub_steps]. It needed 16–35 renders for 40 dB against N = 80.

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
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from spacedg.render import motion_error
from spacedg.render.camera import Camera, exposure_poses
from spacedg.render.composite import composite_view, frame_from_images
from spacedg.render.frame import Frame, expected_depth
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
    approximated as ``f · max(scale) / z`` (a surfel's in-plane size; enough to choose a step). On a pinhole
    camera the path is summed compiled (:func:`~spacedg.render.motion_error_cpu.longest_path`, within float64
    rounding of the numpy loop over one camera a pose it replaced: 3.7 → 1.7 ms a dataset view).
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
    if camera.fisheye is None:  # compiled, without a camera a pose (their checks were a quarter of this call)
        from spacedg.render.motion_error_cpu import longest_path

        return float(longest_path(points, np.stack(poses), float(camera.fx), float(camera.fy), float(camera.cx), float(camera.cy))), sigma
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


@dataclass(frozen=True, eq=False)
class MotionJob:
    """One motion-blurred view to render: the scene, the **mid-exposure** camera, the motion and
    the outputs wanted, and how each sub-exposure is composited (backend, torch device,
    rasterizer settings, defocus), as :func:`spacedg.render.render` resolved them. Built once by
    the caller; every path of this module reads it."""

    gaussians: Gaussians
    camera: Camera
    motion: MotionBlur
    wanted: frozenset[str]
    backend: str = "cpu"
    device: torch.device | None = None
    settings: RasterSettings = field(default_factory=RasterSettings)
    defocus: Defocus | None = None

    def composite(self, camera: Camera, outputs: frozenset[str]) -> tuple[dict[str, np.ndarray], dict[str, float]]:
        """One sub-exposure (or keyframe canvas) render of the scene from ``camera``."""
        return composite_view(self.gaussians, camera, outputs, self.backend, self.device, self.settings, self.defocus)

    def poses(self, times: np.ndarray) -> list[np.ndarray]:
        """The camera's poses at ``times`` (fractions of the exposure in [-½, ½])."""
        return exposure_poses(self.camera, np.array(self.motion.translation), np.array(self.motion.rotation), times)

    def frame(self, images: dict[str, np.ndarray], t0: float, stats: dict[str, float]) -> Frame:
        """The blurred ``images`` as a :class:`Frame`, with the median depth and instance ids of the
        mid-exposure pose (a sharp render) where wanted, and ``stats`` plus the time since ``t0``."""
        if self.wanted & {"median_depth", "instance_ids"}:
            sharp, _ = self.composite(self.camera, frozenset({"instance_ids"}))
            images.update({"median_depth": sharp["median_depth"], "instance_ids": sharp["instance_ids"]})
        frame = frame_from_images(images, self.camera, self.wanted)
        frame.stats = {**stats, "ms": (time.perf_counter() - t0) * 1e3}
        return frame


def render_motion(job: MotionJob) -> Frame:
    """Render a motion-blurred frame (see the module docstring)."""
    if uses_keyframes(job.motion, job.camera):
        return render_motion_keyframes(job)
    return render_motion_substeps(job)


def uses_keyframes(motion: MotionBlur, camera: Camera) -> bool:
    """Whether ``motion`` renders through the keyframe warp (the fast path on a pinhole camera whose
    keyframe canvas fits), the rule every backend follows; otherwise sub-exposure renders."""
    return motion.fast and not motion.is_static and camera.fisheye is None and _canvas_fits(camera)


def _canvas_fits(camera: Camera) -> bool:
    """Whether the keyframe path can take this camera: at least 2 × 2 pixels (a bilinear tap
    reads a 2 × 2 block) and the widest keyframe canvas (half the longer side on every edge)
    within the size policy."""
    from spacedg.limits import image_size_problem

    if camera.width < 2 or camera.height < 2:
        return False
    margin = max(camera.width, camera.height) // 2
    return image_size_problem(camera.width + 2 * margin, camera.height + 2 * margin) is None


def sub_step_plan(gaussians: Gaussians, camera: Camera, motion: MotionBlur, fast: bool) -> tuple[float, int]:
    """``(displacement_px, count)`` of a sub-step render: with ``fast`` the largest on-screen path
    (:func:`motion_extent`) and :func:`choose_sub_steps`' count, else NaN and ``motion.sub_steps``."""
    if not fast:
        return math.nan, motion.sub_steps
    displacement, feature = motion_extent(gaussians, camera, motion)
    return displacement, choose_sub_steps(displacement, feature, motion.sub_steps)


def render_motion_substeps(job: MotionJob, fast: bool | None = None) -> Frame:
    """Average of sub-exposure renders: ``motion.sub_steps`` of them, or with ``fast`` (default
    ``motion.fast``) the count of :func:`choose_sub_steps`."""
    t0 = time.perf_counter()
    camera, motion, wanted = job.camera, job.motion, job.wanted
    displacement, count = sub_step_plan(job.gaussians, camera, motion, motion.fast if fast is None else fast)
    poses = job.poses(sub_exposure_times(count))
    blur_outputs = frozenset(wanted & {"rgb", "depth"})
    rgb = np.zeros((camera.height, camera.width, 3), np.float64) if "rgb" in wanted else None
    alpha = np.zeros((camera.height, camera.width), np.float64)
    depth_sum = np.zeros((camera.height, camera.width), np.float64) if "depth" in wanted else None
    pairs = 0
    for pose in poses:
        images, stats = job.composite(camera.with_pose(pose), blur_outputs or frozenset({"alpha"}))
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
        images["depth"] = expected_depth(depth_sum, alpha)
    return job.frame(images, t0, {"sub_steps": count, "displacement_px": displacement, "pairs": pairs})


#: The keyframe count's upper bound (8 renders at most: the issue's budget).
MAX_KEYFRAMES = 8
#: Box-doubling passes before the path gather: one per doubling of an interval's longest path past
#: ``DOUBLING_FROM_PX`` (:func:`doubling_passes`), at most this many. Each halves the samples the
#: gather takes but reads the whole canvas twice and resamples it once (~1 dB on the plant's fine
#: texture). Measured (640×480, one thread): 0 → 1 pass 2–8 % faster on rooms and the plant at
#: bench; with the error model's keyframe counts (longer intervals), at most 3 passes instead of 1
#: took the dataset's room views 103.4 → 93.0 ms (32 items, 55 views) and 121.9 → 112.9 ms (held-out
#: rooms of seed 8181; other runs than :mod:`spacedg.render.motion_error`'s), the worst view
#: 43.45 → 43.45 and 44.47 → 44.32 dB against N = 80 (mean −0.3 to −0.45 dB); the plant's close-ups (short intervals) unchanged in time, worst 43.10 → 43.08 dB
#: (``benchmarks/motion_keyframes.py --max-passes 1`` against the default).
DOUBLING_PASSES = 3
DOUBLING_FROM_PX = 24.0

#: Largest distance (pixels) between two of the path's samples (the gather walks ``2^-passes``
#: of each path at this spacing; the passes replicate its samples along the rest). Measured on
#: the room at bench (K = 3): 1.5 px is ~20 % faster at the same PSNR (45.6 dB), but the streak
#: of a sub-pixel point then ripples −15/+23 % (1.25 px: −4/+12 %; 1 px: ±2 %).
PATH_SPACING_PX = 1.0


def doubling_passes(longest_px: float) -> int:
    """Box-doubling passes for an interval whose longest path is ``longest_px`` pixels: one per
    doubling of it past :data:`DOUBLING_FROM_PX` (24, 48, 96 px: more than each), at most
    :data:`DOUBLING_PASSES`; none for a NaN path."""
    return sum(1 for n in range(DOUBLING_PASSES) if longest_px > DOUBLING_FROM_PX * 2**n)


def render_motion_keyframes(
    job: MotionJob, keyframes: int | None = None, passes: int | None = None, spacing: float | None = None,
) -> Frame:
    """Motion blur from ``K`` keyframes and depth-reprojected path gathers (:mod:`spacedg.render.motion_warp`).

    ``keyframes``, ``passes`` and ``spacing`` (pixels) override the count of
    :func:`~spacedg.render.motion_error.keyframes_for`,
    the pass count (default: :func:`doubling_passes` of the interval's longest path) and
    :data:`PATH_SPACING_PX` (for benchmarks and tests). Pinhole
    cameras only. Deterministic: no random numbers, every kernel writes each element in one order.
    """
    from spacedg.render import motion_warp

    t0 = time.perf_counter()
    camera, motion, wanted = job.camera, job.motion, job.wanted
    spacing = PATH_SPACING_PX if spacing is None else spacing
    displacement, _ = motion_extent(job.gaussians, camera, motion)
    summary: dict[str, float] = {"displacement_px": displacement}
    count = keyframes or 0
    if not count:
        most = min(MAX_KEYFRAMES, motion.sub_steps)
        count = motion_error.keyframes_for(0.0, displacement, most)  # the path's own floor
        if count < most and any(motion.translation):  # without translation no depth edge moves apart
            summary["edge_measure"] = motion_error.edge_parallax_contrast(
                job.gaussians, camera, motion, job.settings, job.backend, job.device
            )
            count = motion_error.keyframes_for(summary["edge_measure"], displacement, most)
    margin = int(min(math.ceil(0.6 * displacement / count) + 2, max(camera.width, camera.height) // 2))
    canvas = camera.widened(margin)
    want_depth = "depth" in wanted
    edges = np.linspace(-0.5, 0.5, count + 1)
    centres = 0.5 * (edges[:-1] + edges[1:])
    key_poses = job.poses(centres)
    end_poses = job.poses(edges)
    channels = 5 if want_depth else 4
    acc = np.zeros((camera.height, camera.width, channels), np.float32)
    pairs = 0
    # the canvas buffers, rewritten each keyframe (keyframe_source, flow_field; each doubling pass over the whole
    # canvas, or on a covered one where it is read: pass_regions)
    src = np.empty((canvas.height, canvas.width, channels), np.float32)
    dst = np.empty_like(src)
    geometry = np.empty((canvas.height, canvas.width), np.float32)
    field = np.empty((canvas.height, canvas.width, 4), np.float32)
    extents = np.empty(4, np.float32)  # the field's largest |c_u|, |c_v|, |d_u|, |d_v| (sanitise_field)
    for k, pose in enumerate(key_poses):
        images, stats = job.composite(canvas.with_pose(pose), frozenset({"rgb", "depth"}))
        pairs += stats["pairs"]
        alpha, depth = images["alpha"], images["depth"]
        lowest = alpha.min()
        # the fill depth only stands where alpha is at most COVERED_ALPHA: a covered canvas (a room) needs none
        fill = 1.0 if lowest > motion_warp.COVERED_ALPHA else motion_warp.fill_depth(alpha, depth)
        motion_warp.keyframe_source(images["rgb"], alpha, depth, fill, src, geometry)
        motion_warp.flow_field(geometry, camera.fx, camera.fy, canvas.cx, canvas.cy,
                               motion_warp.relative_transform(end_poses[k], pose),
                               motion_warp.relative_transform(end_poses[k + 1], pose), field)
        # a path longer than the canvas reads clamped texels anyway; a non-finite one (a surface at
        # the camera centre, metres of motion at 1e3) is no path: both bound the gather's work and reads
        reach = np.float32(2 * (canvas.width + canvas.height))
        longest = motion_warp.sanitise_field(field, reach, extents)
        n_passes = doubling_passes(longest) if passes is None else passes
        covered_all = bool(lowest > 0.0)  # nothing to skip (a room): no occupancy tables
        # covered: each pass only where the gather and the later passes read (an occupancy table would
        # count pixels a restricted pass left as they were, so a canvas with empty pixels takes every pixel)
        regions = motion_warp.pass_regions(src.shape[:2], margin, (camera.height, camera.width), n_passes, extents, spacing) if covered_all else None
        for j in range(n_passes):
            sat = motion_warp.FULL if covered_all else motion_warp.occupancy(src)
            motion_warp.doubling_pass(src, field, np.float32(0.25 / 2**j), sat, dst, regions[j] if regions else None)
            src, dst = dst, src
        sat = motion_warp.FULL if covered_all else motion_warp.occupancy(src)
        motion_warp.gather(src, field, margin, 1.0 / 2**n_passes, spacing, sat, acc)
    # the mean over the intervals; bilinear weights of a float32 path average may overshoot the keyframes'
    # range by rounding: alpha clipped to [0, 1], colour to ≥ 0
    images = {"alpha": np.empty((camera.height, camera.width), np.float32), "rgb": np.empty((camera.height, camera.width, 3), np.float32)}
    motion_warp.finish_average(acc, count, images["rgb"], images["alpha"])
    if "rgb" not in wanted:
        del images["rgb"]
    if want_depth:
        images["depth"] = expected_depth(acc[..., 4], acc[..., 3])
    # sub_steps: renders made (the keyframes)
    return job.frame(images, t0, {"sub_steps": count, "keyframes": count, **summary, "pairs": pairs})

"""How much of a lensed view the capture covers (:func:`captured_share`).

A raster-stage lens change (the ``distortion`` degradation) renders the scene through another
lens at the same pose: a fisheye on the camera's own focal lengths shows more than the captured
view near its border, where a reconstruction holds only what other views saw (or nothing).
:func:`captured_share` measures the share of the lensed image (inside its image circle) whose
rays the original camera's frame contains, i.e. the part of the new frame that the capture
covers.
"""

from __future__ import annotations

import numpy as np

from spacedg.render.camera import Camera

__all__ = ["captured_share", "pixel_rays"]

#: Longest side of the pixel grid :func:`captured_share` samples (pixel centres, evenly spread).
SHARE_GRID = 160


def pixel_rays(camera: Camera, cols: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit camera-frame rays (N, 3) through pixel centres ``(col + 0.5, row + 0.5)`` and whether
    the lens images them (pinhole: always; fisheye: inside the image circle of its effective max θ).

    OpenCV axes. A fisheye ray at angle θ from the axis is ``(sin θ · x̂, sin θ · ŷ, cos θ)``
    (θ from :meth:`~spacedg.render.camera.FisheyeLens.undistort_theta`), so rays beyond 90° are
    represented too."""
    x = (np.asarray(cols, np.float64) + 0.5 - camera.cx) / camera.fx
    y = (np.asarray(rows, np.float64) + 0.5 - camera.cy) / camera.fy
    lens = camera.fisheye
    if lens is None:
        rays = np.stack([x, y, np.ones_like(x)], axis=1)
        return rays / np.linalg.norm(rays, axis=1, keepdims=True), np.ones(x.shape, bool)
    radius = np.hypot(x, y)
    valid = radius <= float(lens.distort_theta(np.float64(lens.effective_max_theta)))
    theta = lens.undistort_theta(radius)
    scale = np.where(radius > 1e-12, np.sin(theta) / np.where(radius > 1e-12, radius, 1.0), 0.0)
    return np.stack([x * scale, y * scale, np.cos(theta)], axis=1), valid


def captured_share(clean: Camera, lensed: Camera) -> float:
    """Share (in [0, 1]) of ``lensed``'s valid pixels whose ray falls inside ``clean``'s image.

    Both cameras are taken at the same pose (``lensed``'s rays are expressed in ``clean``'s
    frame through their rotations). Sampled on a grid of at most :data:`SHARE_GRID` pixel
    centres on the longer side; 1.0 when ``lensed`` images no pixel at all (nothing uncaptured)."""
    step = max(1, -(-max(lensed.width, lensed.height) // SHARE_GRID))
    rows, cols = np.meshgrid(np.arange(0, lensed.height, step), np.arange(0, lensed.width, step), indexing="ij")
    rays, valid = pixel_rays(lensed, cols.ravel(), rows.ravel())
    if not valid.any():
        return 1.0
    world = lensed.center + rays[valid] @ lensed.rotation.T
    uv, _, in_front = clean.project(world)
    return float(np.mean(in_front & clean.in_image(uv)))

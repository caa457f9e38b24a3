"""The compiled part of motion blur's keyframe-count measure (:func:`spacedg.render.motion_error.edge_parallax_contrast`).

Its per-pair arithmetic over the coarse render (where each end of the exposure sees a pixel's ray at its
own depth and at its neighbour's, and the colour contrast across the pair), done in numpy, was a
dozen array passes and temporaries a view (~5 ms at 640 × 480, a fifth of the measure); here one
pass (no fast-math: numpy's float64 operations in their order, the same bits). Imported lazily: the
measure's module stays light for ``import spacedg``.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from spacedg.render import kernel_cache  # noqa: F401 - numba's cache entries checked before any kernel here compiles
from spacedg.render.threads import fork_safe

__all__ = ["edge_products", "longest_path"]

#: The largest float64 (``np.nan_to_num``'s stand-in for +inf).
_LARGEST = float(np.finfo(np.float64).max)


@fork_safe
@numba.njit(parallel=True, cache=True, fastmath=False)
def edge_products(x_ray, y_ray, z, end_a, end_b, fx, fy, reach, encoded, products_h, products_v):  # pragma: no cover - compiled
    """Per pair of horizontally (``products_h``) and vertically (``products_v``) neighbouring coarse pixels:
    ``c² · Δ`` (:func:`~spacedg.render.motion_error.edge_parallax_contrast`), in float64.

    ``Δ = max(0, min(gap_a, reach), min(gap_b, reach))``, ``gap`` the pixels (focal lengths ``fx``, ``fy``)
    between where the exposure's end (``end_a``, ``end_b``: :func:`~spacedg.render.motion_warp.relative_transform`
    from the view's frame) sees the first pixel's ray at its own depth ``z`` and at its neighbour's, 0 where
    either point is not in front of it; a NaN anywhere stays NaN. ``c²`` the mean over the channels of the
    squared difference of ``encoded`` (sRGB, (H, W, 3)). The float64 operations of the numpy expressions this
    replaced, in their order (no fast-math), so the same bits; the caller sums the products in numpy."""
    height, width = z.shape
    for i in numba.prange(height):  # rows in parallel: each product is its pair's alone (serially 3.7 ms a 160 × 120 view)
        for j in range(width):
            right, below = j + 1 < width, i + 1 < height
            delta_h = delta_v = 0.0
            for m in (end_a, end_b):
                own = _seen(m, x_ray[j], y_ray[i], z[i, j])  # the pixel's point, once for both neighbours
                if right:
                    delta_h = _widest(delta_h, _apart(own, _seen(m, x_ray[j], y_ray[i], z[i, j + 1]), fx, fy), reach)
                if below:
                    delta_v = _widest(delta_v, _apart(own, _seen(m, x_ray[j], y_ray[i], z[i + 1, j]), fx, fy), reach)
            if right:
                products_h[i, j] = _contrast(encoded, i, j, i, j + 1) * delta_h
            if below:
                products_v[i, j] = _contrast(encoded, i, j, i + 1, j) * delta_v


@numba.njit(cache=True, inline="always")
def _widest(delta, gap, reach):  # pragma: no cover - compiled
    """``np.maximum(delta, np.minimum(gap, reach))``: a NaN on either side stays NaN."""
    gap = gap if gap != gap else min(gap, reach)
    return delta if delta != delta else (gap if gap != gap else max(delta, gap))


@numba.njit(cache=True, inline="always")
def _contrast(encoded, i, j, n_i, n_j):  # pragma: no cover - compiled
    """Mean over the channels of the squared difference of ``encoded`` between pixels ``(i, j)`` and
    ``(n_i, n_j)``: numpy's ``np.mean(diff ** 2, axis=2)`` (a sum from 0, left to right, then ÷ 3)."""
    total = 0.0
    for c in range(3):
        step = encoded[n_i, n_j, c] - encoded[i, j, c]
        total += step * step
    return total / 3.0


@numba.njit(cache=True, inline="always")
def _seen(m, x_ray, y_ray, depth):  # pragma: no cover - compiled
    """``(x/z, y/z, ahead)`` of the point on the ray ``(x_ray, y_ray, 1)`` at ``depth`` in the frame of a
    camera (:func:`~spacedg.render.motion_warp.relative_transform` ``m`` from the view's frame);
    ``ahead`` false where the point is not in front of it (no path there, as the warp's flow field has it)."""
    x, y = x_ray * depth, y_ray * depth
    ze = m[6] * x + m[7] * y + m[8] * depth + m[11]
    ahead = ze > 1e-6
    ze = ze if ahead else 1.0
    return (m[0] * x + m[1] * y + m[2] * depth + m[9]) / ze, (m[3] * x + m[4] * y + m[5] * depth + m[10]) / ze, ahead


@numba.njit(cache=True, inline="always")
def _apart(own, other, fx, fy):  # pragma: no cover - compiled
    """Pixels (focal lengths ``fx``, ``fy``) between two points :func:`_seen` by one camera, 0 where either is
    not in front of it."""
    u, v, ahead = own
    other_u, other_v, other_ahead = other
    return math.hypot(fx * (u - other_u), fy * (v - other_v)) if ahead and other_ahead else 0.0


@numba.njit(cache=True, fastmath=False)
def longest_path(points, poses, fx, fy, cx, cy):  # pragma: no cover - compiled
    """The longest on-screen path (pixels) of ``points`` ((N, 3) float64, world, metres) seen by a pinhole camera
    (focal lengths ``fx``, ``fy`` and principal point ``cx``, ``cy`` in pixels) at ``poses`` ((P, 4, 4) cam-to-world,
    OpenCV axes) in turn: per point the sum of the straight steps between its pixels at consecutive poses, a step
    counting 0 where either end is not at least 1 mm in front of the camera; 0 without points.
    :func:`spacedg.render.motion.motion_extent`'s loop over the path's pieces, in one pass without a camera a pose."""
    longest = 0.0
    for n in range(points.shape[0]):
        length = 0.0
        previous_ok = False
        previous_u = previous_v = 0.0
        for p in range(poses.shape[0]):
            dx = points[n, 0] - poses[p, 0, 3]
            dy = points[n, 1] - poses[p, 1, 3]
            dz = points[n, 2] - poses[p, 2, 3]
            x = dx * poses[p, 0, 0] + dy * poses[p, 1, 0] + dz * poses[p, 2, 0]
            y = dx * poses[p, 0, 1] + dy * poses[p, 1, 1] + dz * poses[p, 2, 1]
            z = dx * poses[p, 0, 2] + dy * poses[p, 1, 2] + dz * poses[p, 2, 2]
            ok = z > 1e-3
            u = fx * x / z + cx if ok else 0.0
            v = fy * y / z + cy if ok else 0.0
            if ok and previous_ok:
                step = math.hypot(u - previous_u, v - previous_v)
                if step == step:  # a NaN step counts 0 and an infinite one the largest float, as the loop's nan_to_num had it
                    length += min(step, _LARGEST)
            previous_ok, previous_u, previous_v = ok, u, v
        longest = max(longest, length)
    return longest

"""Compiled (numba) steps of defocus's coarse composite (not a backend of its own).

:func:`coarse_projection` is :func:`spacedg.render.defocus.coarse_view`'s arithmetic and
:func:`bilinear` is :func:`spacedg.render.defocus.upsample`'s bilinear step, one pass over the data
each instead of a dozen numpy temporaries (the numpy forms took 23 ms and 5 ms on a 167k-Gaussian
room at 640 × 480). The same operations in the same precision and order, so the same bytes
(tests compare them with the numpy forms they replace).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from spacedg.render import kernel_cache  # noqa: F401 - numba's cache entries checked before any kernel here compiles
from spacedg.render.project_cpu import CA, CB, CC, PX, PY, RADX, RADY

__all__ = ["bilinear", "coarse_projection"]


@numba.njit(cache=True)
def coarse_projection(packed, rects, factor, tiles_x, tiles_y):  # pragma: no cover - compiled
    """``(packed, rects)`` of the projection ``packed`` (N, PACKED) float32 seen on a grid ``factor``
    times coarser with ``tiles_x × tiles_y`` tiles: means and footprint radii ÷ factor (radii rounded
    up), conics × factor², the rest unchanged; tile rectangles from the scaled footprints (float64,
    as the projection's), zero for a Gaussian not visible in ``rects`` or whose rectangle is empty.
    The radii must be finite (the projection caps them; numpy's form kept a NaN radius NaN, this one does not)."""
    n = packed.shape[0]
    out = packed.copy()
    out_rects = np.zeros_like(rects)
    f = np.float32(factor)
    f2 = np.float32(factor * factor)
    for g in range(n):
        px = packed[g, PX] / f
        py = packed[g, PY] / f
        rx = np.float32(math.ceil(packed[g, RADX] / f))
        ry = np.float32(math.ceil(packed[g, RADY] / f))
        out[g, PX] = px
        out[g, PY] = py
        out[g, CA] = packed[g, CA] * f2
        out[g, CB] = packed[g, CB] * f2
        out[g, CC] = packed[g, CC] * f2
        out[g, RADX] = rx
        out[g, RADY] = ry
        if not rects[g, 1] > rects[g, 0]:
            continue
        mx, my, rxd, ryd = float(px), float(py), float(rx), float(ry)
        x0 = min(max(math.floor((mx - rxd) / 16.0), 0.0), float(tiles_x))
        x1 = min(max(math.ceil((mx + rxd) / 16.0), 0.0), float(tiles_x))
        y0 = min(max(math.floor((my - ryd) / 16.0), 0.0), float(tiles_y))
        y1 = min(max(math.ceil((my + ryd) / 16.0), 0.0), float(tiles_y))
        if x1 > x0 and y1 > y0:
            out_rects[g, 0], out_rects[g, 1], out_rects[g, 2], out_rects[g, 3] = int(x0), int(x1), int(y0), int(y1)
    return out, out_rects


@numba.njit(cache=True, inline="always")
def bilinear_mix(top_left, bottom_left, top_right, bottom_right, vy, wy, vx, wx):
    """The bilinear mix of four float32 values, rows first: ``(top·vy + bottom·wy)`` per column, then
    ``left·vx + right·wx`` (the one order of :func:`bilinear` and the sampled tiles' upsampling)."""
    left = top_left * vy + bottom_left * wy
    right = top_right * vy + bottom_right * wy
    return left * vx + right * wx


@numba.njit(cache=True)
def bilinear(image, y0, y1, ty, x0, x1, tx):  # pragma: no cover - compiled
    """(len(y0), len(x0), C) float32: ``image`` (h, w, C) float32 sampled bilinearly, rows first: output
    row ``i`` mixes rows ``y0[i], y1[i]`` by ``ty[i]`` (float32), then columns ``x0[j], x1[j]`` by ``tx[j]``."""
    rows, cols, channels = y0.shape[0], x0.shape[0], image.shape[2]
    out = np.empty((rows, cols, channels), np.float32)
    one = np.float32(1.0)
    for i in range(rows):
        a, b, wy = y0[i], y1[i], ty[i]
        vy = one - wy
        for j in range(cols):
            c, d, wx = x0[j], x1[j], tx[j]
            vx = one - wx
            for k in range(channels):
                out[i, j, k] = bilinear_mix(image[a, c, k], image[b, c, k], image[a, d, k], image[b, d, k], vy, wy, vx, wx)
    return out

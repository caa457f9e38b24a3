"""Defocus keeps the view's light: blur each Gaussian by its circle of confusion, then conserve flux locally.

A thin lens redistributes light; it neither makes nor destroys it. Every point of the scene is
spread over a disc (here a Gaussian of standard deviation ``r``, its circle of confusion), so at
scales well above ``r`` the defocused image's low-pass equals the sharp image's low-pass, blurred
by ``r``: ``G_L * defocused = G_L * (PSF * sharp) ≈ G_√(L²+r²) * sharp`` (exact for one depth; what
differs is see-around at occlusion edges, a strip about ``r`` wide).

Per-Gaussian blur (``r²·I`` added to each 2D covariance, opacity scaled so the integrated alpha is
kept, :class:`~spacedg.render.settings.Defocus`) composited with the sharp rules does not obey that
law once splats overlap: spread-out splats of one surface occlude each other less (``1 − e^(−Σα)``
instead of ``1 − Π(1 − αᵢ)``: a room 2–4 % dark), and an object in front of an empty background
loses less of its light to self-occlusion (up to +10 %). Both are compositing artefacts, not optics.
:func:`conserve_light` corrects them where they happen: it multiplies the blurred linear image by
``(G_√(L²+r²) * S) / (G_L * D)`` per channel — ``S`` the sharp linear image, ``D`` the blurred one,
``L = max(FLUX_LENGTH · r₉₅, FLUX_MIN_SIGMA)`` px, ``r₉₅`` and ``r`` the 95th percentile and the
median of the circle of confusion over the sharp view's pixels weighted by their coverage — so that every
neighbourhood a few ``L`` wide holds the light the sharp view holds there. Guards: both low-passes
get ``ε = 10⁻³ ×`` the sharp image's mean added (no division by ~0 on black), and the ratio is
clipped to ``FLUX_RATIO`` (finite everywhere; a region the blurred view leaves empty cannot be
filled in by a factor). A local ratio keeps each neighbourhood's mean but not exactly the frame's
total (a footprint truncated at ``defocus_extent`` σ is narrower than the lens's Gaussian: −3 % of a
lone Gaussian's alpha), so the ratio is finally scaled per channel to give the frame the sharp
view's total.

The sharp image comes from one clean render of the view on the view's own frame (grown to whole
tiles; both low-passes mirror the same support, so no margin is rendered: a sharp pass wider than
the blurred view was measured to lose 1.6–2.6 % of a frame's light), at half the resolution when
``√(L²+r²) ≥ 2`` px (:func:`flux_scale`: its low-pass is then at least one half-resolution pixel
wide); the ratio is computed on that grid and upsampled bilinearly. Measured against the thin-lens reference (``benchmarks/defocus_reference.py``; the
table is in the module docstring of :mod:`spacedg.render.defocus`).
"""

from __future__ import annotations

import math
from typing import Any

import cv2
import numba
import numpy as np

from spacedg.render import kernel_cache  # noqa: F401 - numba's cache entries checked before any kernel here compiles
from spacedg.render.threads import fork_safe

__all__ = ["FLUX_LENGTH", "FLUX_MIN_SIGMA", "FLUX_RATIO", "flux_lengths", "flux_scale", "conserve_light", "linear_taps", "sample_shifted", "sharp_flux_lengths"]

#: ``L`` in multiples of the 95th-percentile circle of confusion of the covered pixels (measured on
#: the defocus table: 0.5 gave 35.9–57.5 dB against the thin lens, 1.0 35.1–57.5, 2.0 33.1–53.7).
FLUX_LENGTH = 0.5
#: Smallest ``L`` (px): below a pixel the low-pass is no low-pass.
FLUX_MIN_SIGMA = 1.0
#: Range of the correction factor.
FLUX_RATIO = (0.25, 4.0)

#: Bins of :func:`flux_lengths`' weighted histogram; numpy's block of values (``np.histogram``'s ``BLOCK``).
_FLUX_BINS = 1024
_HISTOGRAM_BLOCK = 65536


def flux_lengths(coc: np.ndarray, weight: np.ndarray | None = None) -> tuple[float, float]:
    """``(L, r)`` px from the circles of confusion ``coc`` (px) of the sharp view's pixels, each
    weighted by ``weight`` (its coverage; default 1): ``L = max(FLUX_LENGTH · r₉₅, FLUX_MIN_SIGMA)``,
    ``r`` the weighted median (0 with nothing covered)."""
    coc = np.asarray(coc, dtype=np.float64).ravel()
    weight = np.ones_like(coc) if weight is None else np.asarray(weight, dtype=np.float64).ravel()
    keep = np.isfinite(coc) & np.isfinite(weight) & (weight > 0.0)
    coc, weight = coc[keep], weight[keep]
    if coc.size == 0:
        return FLUX_MIN_SIGMA, 0.0
    top = float(coc.max())
    if top <= 0.0:
        return FLUX_MIN_SIGMA, 0.0
    # weighted quantiles from a 1024-bin histogram (O(n); resolution top/1024 px)
    return _lengths(*np.histogram(coc, bins=_FLUX_BINS, range=(0.0, top), weights=weight))


def _lengths(counts: np.ndarray, edges: np.ndarray) -> tuple[float, float]:
    """``(L, r)`` from the weighted histogram ``counts`` of the circles of confusion over ``edges``: the upper
    edge of the bin where the cumulative weight reaches 95 % (``L = max(FLUX_LENGTH · r₉₅, FLUX_MIN_SIGMA)``)
    and 50 % (``r``)."""
    cumulative = np.cumsum(counts)
    at = lambda q: float(edges[min(int(np.searchsorted(cumulative, q * cumulative[-1])) + 1, len(counts))])  # noqa: E731
    return max(FLUX_LENGTH * at(0.95), FLUX_MIN_SIGMA), at(0.5)


def sharp_flux_lengths(depth: np.ndarray, alpha: np.ndarray, aperture: float, focus: float, max_radius: float) -> tuple[float, float]:
    """:func:`flux_lengths` of the sharp pass's covered pixels, compiled: the same ``(L, r)`` bit for bit as
    ``flux_lengths(Defocus.radius(np.maximum(depth[seen], 1e-6)), alpha[seen])`` with ``seen = alpha > 1e-3``
    (``depth`` metres and ``alpha``, float32 (h, w); ``aperture``, ``focus``, ``max_radius`` the
    :class:`~spacedg.render.settings.Defocus`'s), without its temporary arrays (3.2 → 0.8 ms a 320 × 240 pass, most of it the Python around the two kernels).
    The circles of confusion in float64 as ``Defocus.radius`` forms them, the weighted histogram with numpy's
    bin assignment, its 65536-value blocks and its summation order (``np.histogram``, ``np.bincount``)."""
    depth = np.ascontiguousarray(depth, np.float32).reshape(-1)
    alpha = np.ascontiguousarray(alpha, np.float32).reshape(-1)
    if depth.shape != alpha.shape:
        raise ValueError(f"sharp_flux_lengths: depth and alpha must have one shape, got {depth.shape} and {alpha.shape}")
    coc = np.empty(depth.shape[0], np.float64)
    weight = np.empty(depth.shape[0], np.float64)
    count = _covered_cocs(depth, alpha, float(aperture), float(focus), float(max_radius), coc, weight)
    if count == 0:
        return FLUX_MIN_SIGMA, 0.0
    top = float(coc[:count].max())
    if top <= 0.0:
        return FLUX_MIN_SIGMA, 0.0
    edges = np.linspace(0.0, top, _FLUX_BINS + 1)
    return _lengths(_block_histogram(coc[:count], weight[:count], edges, top), edges)


@numba.njit(cache=True, error_model="numpy")
def _covered_cocs(depth, alpha, aperture, focus, max_radius, coc, weight):  # pragma: no cover - compiled
    """The covered pixels' (``alpha > 1e-3``) circles of confusion and weights, in pixel order, into ``coc`` and ``weight``
    (float64); returns how many. ``np.maximum(depth, float32(1e-6))`` (a NaN stays), widened to float64, then
    ``Defocus.radius``: ``min(aperture · |max(d, 1e-9) − focus| / max(d, 1e-9), max_radius)``; a value whose
    circle of confusion or weight is not finite is left out (:func:`flux_lengths`' ``keep``)."""
    floor = np.float32(1e-6)
    threshold = np.float32(1e-3)
    n = 0
    for i in range(depth.shape[0]):
        a = alpha[i]
        if not a > threshold:
            continue
        z = depth[i]
        z = z if (z != z or z >= floor) else floor  # np.maximum: NaN propagates
        d = np.float64(z)
        d = d if (d != d or d >= 1e-9) else 1e-9
        r = aperture * abs(d - focus) / d
        r = r if (r != r or r <= max_radius) else max_radius  # np.minimum: NaN propagates
        w = np.float64(a)
        if not (math.isfinite(r) and math.isfinite(w) and w > 0.0):
            continue
        coc[n] = r
        weight[n] = w
        n += 1
    return n


@numba.njit(cache=True, error_model="numpy")
def _block_histogram(values, weights, edges, top):  # pragma: no cover - compiled
    """``np.histogram(values, bins=len(edges) − 1, range=(0, top), weights=weights)[0]`` for values in [0, top]:
    each block of :data:`_HISTOGRAM_BLOCK` values binned as numpy bins them (``(v − 0) / top · bins``, truncated, the
    last edge in the last bin, corrected by one against ``edges``) and summed from 0 in value order, the blocks' sums
    then added to the histogram in turn."""
    bins = edges.shape[0] - 1
    counts = np.zeros(bins, np.float64)
    block = np.empty(bins, np.float64)
    for start in range(0, values.shape[0], _HISTOGRAM_BLOCK):
        block[:] = 0.0
        for i in range(start, min(start + _HISTOGRAM_BLOCK, values.shape[0])):
            v = values[i]
            if not (v >= 0.0 and v <= top):  # numpy's keep (a circle of confusion is never negative)
                continue
            k = int((v - 0.0) / top * bins)
            if k == bins:
                k -= 1
            if v < edges[k]:
                k -= 1
            if v >= edges[k + 1] and k != bins - 1:
                k += 1
            block[k] += weights[i]
        for k in range(bins):
            counts[k] += block[k]
    return counts


def flux_scale(coc_estimate: float) -> float:
    """Resolution of the sharp pass relative to the view for a circle of confusion ``coc_estimate``
    (px): ½ when the sharp image's low-pass ``√(L² + r²)`` is at least 2 px (one pixel of the
    half-resolution grid), else 1. Measured on the defocus table: half resolution everywhere lost
    up to 1.5 dB at sub-2-px blurs (plant at bench, 240 × 180: 35.9 → 34.4 dB)."""
    length = max(FLUX_LENGTH * coc_estimate, FLUX_MIN_SIGMA)
    return 0.5 if math.hypot(length, coc_estimate) >= 2.0 else 1.0


def _blur(image: np.ndarray, sigma: float) -> np.ndarray:
    """Gaussian low-pass of standard deviation ``sigma`` px (±3σ kernel, edges mirrored: a kernel wider than the image tends to its mean)."""
    if sigma <= 0.0:
        return image.copy()
    size = 2 * int(math.ceil(3.0 * sigma)) + 1
    return cv2.GaussianBlur(image, (size, size), sigmaX=sigma, sigmaY=sigma, borderType=cv2.BORDER_REFLECT)


def sample_shifted(image: np.ndarray, camera: Any, wide: Any, step: int, shape: tuple[int, int]) -> np.ndarray:
    """``image`` (h, w, 3) on ``wide``'s pixel grid sampled bilinearly at the centres of the
    ``shape`` = (rows, cols) cells of ``step × step`` pixels of ``camera`` (same pose; ``wide`` a
    widened, rescaled copy of it; edges repeated). When the cells are ``wide``'s own pixels (the same
    grid: an identity map), ``image`` itself, which is what the bilinear sampling returns there for
    finite values (OpenCV's would spread a NaN or an infinity to its neighbours)."""
    sx, sy = wide.fx / camera.fx, wide.fy / camera.fy
    # wide pixel index (centres at integers) of cell k's centre: ((k + ½)·step − c)·s + c_wide − ½
    affine = np.array([[step * sx, 0.0, (0.5 * step - camera.cx) * sx + wide.cx - 0.5],
                       [0.0, step * sy, (0.5 * step - camera.cy) * sy + wide.cy - 0.5]])
    if image.shape[:2] == tuple(shape) and np.array_equal(affine, [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]):
        return image
    return cv2.warpAffine(image, affine, (shape[1], shape[0]), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP, borderMode=cv2.BORDER_REPLICATE)


@numba.njit(cache=True, error_model="numpy")
def _cell_means(rgb, alpha, step):  # pragma: no cover - compiled
    """(rows, cols, 4) float32: ``rgb`` (H, W, 3) with ``alpha`` (H, W) as a fourth channel, at ``step = 1``
    as they are, at ``step = 2`` averaged over cells of 2 × 2 pixels, the last row and column of cells
    padded by repeating the edge pixels (``rows = ⌈H / 2⌉``): ``((a + b) + (c + d)) · ¼`` in float32 with
    ``a, b`` the cell's top pixels, the bytes of OpenCV's ``INTER_AREA`` on the padded image."""
    height, width = alpha.shape
    if step == 1:
        out = np.empty((height, width, 4), np.float32)
        for y in range(height):
            for x in range(width):
                out[y, x, 0] = rgb[y, x, 0]
                out[y, x, 1] = rgb[y, x, 1]
                out[y, x, 2] = rgb[y, x, 2]
                out[y, x, 3] = alpha[y, x]
        return out
    rows, cols = (height + 1) // 2, (width + 1) // 2
    out = np.empty((rows, cols, 4), np.float32)
    quarter = np.float32(0.25)
    for r in range(rows):
        ya, yb = 2 * r, min(2 * r + 1, height - 1)
        for q in range(cols):
            xa, xb = 2 * q, min(2 * q + 1, width - 1)
            for c in range(3):
                out[r, q, c] = ((rgb[ya, xa, c] + rgb[ya, xb, c]) + (rgb[yb, xa, c] + rgb[yb, xb, c])) * quarter
            out[r, q, 3] = ((alpha[ya, xa] + alpha[ya, xb]) + (alpha[yb, xa] + alpha[yb, xb])) * quarter
    return out


def linear_taps(n_out: int, n_in: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """OpenCV's ``INTER_LINEAR`` taps along one axis resized from ``n_in`` to ``n_out = n_in`` or
    ``2·n_in`` samples (the only factors checked against OpenCV; others place the taps slightly
    differently and are refused): ``(i0, i1, w0, w1)``, output ``k`` = ``src[i0]·w0 + src[i1]·w1``
    (float32 weights; source position ``(k + ½)·n_in/n_out − ½``; past either edge the edge sample with weight 1).
    Not :func:`spacedg.render.defocus._bilinear_axis`, which clamps the indices and keeps the fraction at
    the edges: the two give other bits there."""
    if n_out not in (n_in, 2 * n_in):
        raise ValueError(f"linear_taps: only the factors 1 and 2 are OpenCV's, got {n_in} → {n_out} samples")
    position = ((np.arange(n_out) + 0.5) * (n_in / n_out) - 0.5).astype(np.float32)
    i0 = np.floor(position).astype(np.int64)
    w1 = (position - i0).astype(np.float32)
    outside = (i0 < 0) | (i0 >= n_in - 1)
    w1[outside] = 0.0
    i0 = np.clip(i0, 0, n_in - 1)
    return i0, np.minimum(i0 + 1, n_in - 1), (np.float32(1.0) - w1).astype(np.float32), w1


@fork_safe
@numba.njit(parallel=True, cache=True, error_model="numpy")
def _apply_ratio(rgb, alpha, ratio, y0, y1, wy0, wy1, x0, x1, wx0, wx1):  # pragma: no cover - compiled
    """``(rgb × R, clip(alpha × R₄, 0, 1))`` (float32 (H, W, 3) and (H, W); NaN alpha stays NaN, as
    ``np.clip``) with ``R`` the ratio grid (rows, cols, 4) resized to (H, W) by the taps of
    :func:`linear_taps`, in OpenCV's order without IPP: each row of the grid resized along x (once),
    then two of those rows mixed along y, in float32."""
    height, width = alpha.shape
    rows = ratio.shape[0]
    wide_rows = np.empty((rows, width, 4), np.float32)
    for r in numba.prange(rows):
        for x in range(width):
            ca, cb, b0, b1 = x0[x], x1[x], wx0[x], wx1[x]
            for c in range(4):
                wide_rows[r, x, c] = ratio[r, ca, c] * b0 + ratio[r, cb, c] * b1
    out = np.empty((height, width, 3), np.float32)
    kept = np.empty((height, width), np.float32)
    zero, one = np.float32(0.0), np.float32(1.0)
    for y in numba.prange(height):
        ra, rb, a0, a1 = y0[y], y1[y], wy0[y], wy1[y]
        for x in range(width):
            for c in range(3):
                out[y, x, c] = rgb[y, x, c] * (wide_rows[ra, x, c] * a0 + wide_rows[rb, x, c] * a1)
            a = alpha[y, x] * (wide_rows[ra, x, 3] * a0 + wide_rows[rb, x, 3] * a1)
            kept[y, x] = a if a != a else min(max(a, zero), one)
    return out, kept


@numba.njit(cache=True, error_model="numpy")
def _flux_ratio(target, low, eps, lo, hi):  # pragma: no cover - compiled
    """``clip((target + eps) / (low + eps), lo, hi)`` per value, NaN → 1 (float32, written into ``target``;
    numpy's division rules: ``x / 0`` is ±inf or NaN, then clipped, never an exception)."""
    height, width, channels = target.shape
    one = np.float32(1.0)
    for y in range(height):
        for x in range(width):
            for c in range(channels):
                r = (target[y, x, c] + eps[c]) / (low[y, x, c] + eps[c])
                target[y, x, c] = one if r != r else min(max(r, lo), hi)
    return target


def conserve_light(
    rgb: np.ndarray, alpha: np.ndarray, sharp_rgb: np.ndarray, sharp_alpha: np.ndarray, camera: Any, wide: Any, length: float, coc: float,
) -> tuple[np.ndarray, np.ndarray]:
    """The blurred linear image ``rgb`` (H, W, 3) and its coverage ``alpha`` (H, W), each × its local
    flux ratio (see the module docstring): float32, alpha clipped to [0, 1]. ``sharp_rgb``,
    ``sharp_alpha``: the sharp view on ``wide``'s grid (the view widened and rescaled by
    ``wide.fx / camera.fx``, 1 or ½); ``length``, ``coc``: ``L`` and ``r`` in the view's pixels."""
    if rgb.shape != (*alpha.shape, 3) or sharp_rgb.shape != (*sharp_alpha.shape, 3):
        raise ValueError(
            f"conserve_light: rgb must be (H, W, 3) over its alpha (H, W), got {rgb.shape} over {alpha.shape} "
            f"and, sharp, {sharp_rgb.shape} over {sharp_alpha.shape}"
        )
    step = max(1, int(round(camera.fx / wide.fx)))
    if step > 2:
        raise ValueError(f"conserve_light: the sharp pass must be at full or half the view's resolution, got 1/{step}")
    height, width = alpha.shape
    rgb, alpha = np.ascontiguousarray(rgb, np.float32), np.ascontiguousarray(alpha, np.float32)
    blurred = _cell_means(rgb, alpha, step)  # the blurred view and its coverage on the grid of step × step cells
    rows, cols = blurred.shape[:2]
    sharp = _cell_means(np.ascontiguousarray(sharp_rgb, np.float32), np.ascontiguousarray(sharp_alpha, np.float32), 1)
    seen = sample_shifted(sharp, camera, wide, step, (rows, cols))
    target = _blur(seen, math.hypot(length, coc) / step)
    eps = (1e-3 * np.maximum(np.array(cv2.mean(target)), 0.0) + 1e-12).astype(np.float32)
    low = _blur(blurred, length / step)
    ratio = _flux_ratio(target, low, eps, np.float32(FLUX_RATIO[0]), np.float32(FLUX_RATIO[1]))
    # the local ratio holds each neighbourhood's mean; the frame's total, once more, exactly
    kept = np.array(cv2.sumElems(blurred * ratio))
    wanted = np.array(cv2.sumElems(seen))
    with np.errstate(divide="ignore", invalid="ignore"):
        total = np.where(kept > 1e-12 * max(float(wanted.max()), 1e-30), wanted / kept, 1.0)
    ratio *= np.clip(np.nan_to_num(total, nan=1.0), *FLUX_RATIO).astype(np.float32)[:4]
    # bilinear, cell centres to pixel centres (edges repeated; at step 1 the identity)
    y0, y1, wy0, wy1 = (taps[:height] for taps in linear_taps(rows * step, rows))
    x0, x1, wx0, wx1 = (taps[:width] for taps in linear_taps(cols * step, cols))
    return _apply_ratio(rgb, alpha, ratio, y0, y1, wy0, wy1, x0, x1, wx0, wx1)

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
median of the circle of confusion over the sharp view's covered pixels — so that every
neighbourhood a few ``L`` wide holds the light the sharp view holds there. Guards: both low-passes
get ``ε = 10⁻³ ×`` the sharp image's mean added (no division by ~0 on black), and the ratio is
clipped to ``FLUX_RATIO`` (finite everywhere; a region the blurred view leaves empty cannot be
filled in by a factor).

The sharp image comes from one clean render of the view, widened by ``3·√(L²+r²)`` px (so light
from just outside the frame is counted), at half the resolution when ``L ≥ 2`` px (its low-pass is
then at least one half-resolution pixel wide); the ratio is computed on that grid and upsampled
bilinearly. Measured against the thin-lens reference (``benchmarks/defocus_reference.py``; the
table is in the module docstring of :mod:`spacedg.render.defocus`).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy.ndimage import gaussian_filter

__all__ = ["FLUX_LENGTH", "FLUX_MIN_SIGMA", "FLUX_RATIO", "flux_lengths", "flux_margin", "flux_scale", "conserve_light", "sample_shifted"]

#: ``L`` in multiples of the 95th-percentile circle of confusion of the covered pixels (measured on
#: the defocus table: 0.5 gave 35.9–57.5 dB against the thin lens, 1.0 35.1–57.5, 2.0 33.1–53.7).
FLUX_LENGTH = 0.5
#: Smallest ``L`` (px): below a pixel the low-pass is no low-pass.
FLUX_MIN_SIGMA = 1.0
#: Range of the correction factor.
FLUX_RATIO = (0.25, 4.0)


def flux_lengths(coc: np.ndarray) -> tuple[float, float]:
    """``(L, r)`` px from the circles of confusion ``coc`` (px) of the sharp view's covered pixels:
    ``L = max(FLUX_LENGTH · r₉₅, FLUX_MIN_SIGMA)``, ``r`` the median (0 with no covered pixel)."""
    coc = np.asarray(coc, dtype=np.float64)
    coc = coc[np.isfinite(coc)]
    if coc.size == 0:
        return FLUX_MIN_SIGMA, 0.0
    return max(FLUX_LENGTH * float(np.percentile(coc, 95)), FLUX_MIN_SIGMA), float(np.median(coc))


def flux_margin(coc_estimate: float, width: int, height: int) -> int:
    """Pixels to widen the sharp pass by: ``3·√(L² + r²)`` for ``L``, ``r`` from a circle of
    confusion ``coc_estimate`` (px), at most a quarter of the view's longer side."""
    length = max(FLUX_LENGTH * coc_estimate, FLUX_MIN_SIGMA)
    reach = 3.0 * math.hypot(length, coc_estimate) if math.isfinite(coc_estimate) else 0.0
    return int(min(math.ceil(reach), max(width, height) // 4))


def flux_scale(coc_estimate: float) -> float:
    """Resolution of the sharp pass relative to the view: ½ when ``L ≥ 2`` px for a circle of
    confusion ``coc_estimate`` (px), else 1 (the low-pass must span at least one of its pixels)."""
    return 0.5 if FLUX_LENGTH * coc_estimate >= 2.0 * FLUX_MIN_SIGMA else 1.0


def _blur(image: np.ndarray, sigma: float) -> np.ndarray:
    return np.stack([gaussian_filter(image[..., c], sigma, mode="nearest", truncate=3.0) for c in range(image.shape[-1])], axis=-1)


def _axis(n: int, step: int, centre: float, scale: float, wide_centre: float, n_wide: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Indices and weight of the wide grid's samples around each coarse cell's centre."""
    x = ((np.arange(n) * step + 0.5 * step) - centre) * scale + wide_centre - 0.5
    i0 = np.floor(x).astype(np.int64)
    t = (x - i0)[:, None]
    return np.clip(i0, 0, n_wide - 1), np.clip(i0 + 1, 0, n_wide - 1), t


def sample_shifted(image: np.ndarray, camera: Any, wide: Any, step: int, shape: tuple[int, int]) -> np.ndarray:
    """``image`` (h, w, 3) on ``wide``'s pixel grid sampled bilinearly at the centres of the
    ``shape`` = (rows, cols) cells of ``step × step`` pixels of ``camera`` (same pose; ``wide`` a
    widened, rescaled copy of it)."""
    scale = wide.fx / camera.fx
    y0, y1, ty = _axis(shape[0], step, camera.cy, wide.fy / camera.fy, wide.cy, image.shape[0])
    x0, x1, tx = _axis(shape[1], step, camera.cx, scale, wide.cx, image.shape[1])
    rows = image[y0] * (1.0 - ty[:, :, None]) + image[y1] * ty[:, :, None]
    return rows[:, x0] * (1.0 - tx[None, :, :]) + rows[:, x1] * tx[None, :, :]


def _downsample(image: np.ndarray, step: int) -> np.ndarray:
    """Area mean over ``step × step`` cells (edge cells padded by repetition)."""
    if step == 1:
        return image
    h, w = image.shape[:2]
    padded = np.pad(image, ((0, -h % step), (0, -w % step), (0, 0)), mode="edge")
    return padded.reshape(padded.shape[0] // step, step, padded.shape[1] // step, step, -1).mean(axis=(1, 3))


def conserve_light(rgb: np.ndarray, sharp: np.ndarray, camera: Any, wide: Any, length: float, coc: float) -> np.ndarray:
    """The blurred linear image ``rgb`` (H, W, 3) × the local flux ratio (see the module docstring),
    float32. ``sharp``: the sharp linear image (h, w, 3) of ``wide`` (the view widened and rescaled by
    ``wide.fx / camera.fx``, 1 or ½); ``length``, ``coc``: ``L`` and ``r`` in the view's pixels."""
    from spacedg.render.defocus import _bilinear

    step = max(1, int(round(camera.fx / wide.fx)))
    scale = 1.0 / step
    blurred = _downsample(np.asarray(rgb, dtype=np.float64), step)
    target = sample_shifted(_blur(np.asarray(sharp, dtype=np.float64), math.hypot(length, coc) * scale), camera, wide, step, blurred.shape[:2])
    eps = 1e-3 * max(float(target.mean()), 0.0) + 1e-12
    ratio = np.clip((target + eps) / (_blur(blurred, length * scale) + eps), *FLUX_RATIO)
    ratio = np.nan_to_num(ratio, nan=1.0, posinf=FLUX_RATIO[1], neginf=FLUX_RATIO[0])
    if step > 1:
        ratio = _bilinear(ratio.astype(np.float32), step, camera.width, camera.height)
    return (rgb * ratio).astype(np.float32)

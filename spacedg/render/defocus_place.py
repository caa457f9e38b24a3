"""Blurred Gaussians placed where the sharp view shows them: the visible weight's first two moments.

The defocus model (:mod:`spacedg.render.defocus`) gives each blurred Gaussian the alpha the sharp view
shows of it. Spread over its **whole** footprint, that light lands in the wrong place when only part
of the Gaussian is visible: a splat half covered by its neighbours on one side would pour its visible
half over the covered side, where the neighbours' own light already is. Per pixel the sums of the
blurred weights then scatter around full coverage, and the compositor's saturation clips the excess
(a room at 160×120 lost 6 % of its coverage at a 1 px blur).

So each blurred Gaussian with a visible part is re-placed: its 2D mean moves to the centroid of its
visible weight, and its 2D covariance becomes the visible weight's covariance (plus the variance
``1/(12·s²)`` px² of a measurement pixel of side ``1/s`` full-resolution pixels, the sampling of
a point to its pixel) plus ``r²·I``. Its integrated alpha is unchanged: opacity and alpha floor are
multiplied by ``sqrt(det Σ_old / det Σ_new)``; a covariance so small that the opacity would pass
:data:`MAX_OPACITY` is widened isotropically until it does not. Every blurred Gaussian (``r`` > :data:`MIN_COC`) whose mass lies inside the measured frame is re-placed.
"""

from __future__ import annotations

import math

import numpy as np

from spacedg.render.project_cpu import AMIN, CA, CB, CC, COC, OPA, PX, PY, RADX, RADY

__all__ = ["MAX_OPACITY", "MIN_COC", "MIN_INSIDE", "placed_covariance", "place_visible"]

#: Smallest circle of confusion (px) for which a Gaussian is re-placed at its visible moments.
MIN_COC = 0.0
#: Smallest share of a Gaussian's mass inside the measured frame for it to be re-placed.
MIN_INSIDE = 0.99
#: Largest opacity a re-placed Gaussian may take (its covariance is widened beyond).
MAX_OPACITY = 0.5


def placed_covariance(old: np.ndarray, visible: np.ndarray, coc: np.ndarray, scale: float, opacity: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(Σ_new (N, 3) as xx, xy, yy, opacity factor (N,))`` for blurred covariances ``old`` (N, 3) and
    visible-weight covariances ``visible`` (N, 3, full-resolution px²), circles of confusion ``coc`` and
    opacities ``opacity`` (see the module docstring). float64."""
    floor = 1.0 / (12.0 * scale * scale)
    vxx, vyy = np.maximum(visible[:, 0], 0.0), np.maximum(visible[:, 2], 0.0)
    vxy = np.clip(visible[:, 1], -0.999 * np.sqrt(vxx * vyy), 0.999 * np.sqrt(vxx * vyy))
    add = coc * coc + floor
    new = np.stack([vxx + add, vxy, vyy + add], axis=1)
    det_old = np.maximum(old[:, 0] * old[:, 2] - old[:, 1] ** 2, 1e-300)
    det_new = new[:, 0] * new[:, 2] - new[:, 1] ** 2
    # widen isotropically (Σ + t·I) where the opacity would exceed MAX_OPACITY: det(Σ + tI) = target
    target = det_old * (opacity / MAX_OPACITY) ** 2
    trace = new[:, 0] + new[:, 2]
    grow = np.where(det_new < target, 0.5 * (-trace + np.sqrt(np.maximum(trace * trace - 4.0 * (det_new - target), 0.0))), 0.0)
    new[:, 0] += grow
    new[:, 2] += grow
    det_new = new[:, 0] * new[:, 2] - new[:, 1] ** 2
    return new, np.sqrt(det_old / np.maximum(det_new, 1e-300))


def place_visible(
    packed: np.ndarray, rects: np.ndarray, sums: np.ndarray, scale: float, width: int, height: int, inside: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """The blurred projection ``(packed, rects)`` (new arrays) with every Gaussian blurred by at least
    :data:`MIN_COC` px that the sharp view shows re-placed at its visible weight's moments.

    ``sums`` (N, 6): per Gaussian W, Σw·dx, Σw·dy, Σw·dx², Σw·dx·dy, Σw·dy² of the sharp measurement
    pass (its pixels are ``1/scale`` of the view's); ``inside`` (N,): the share of each Gaussian's mass inside
    the measured frame. A Gaussian cut by that frame (``inside`` < :data:`MIN_INSIDE`) keeps its place: its
    visible weight was measured on one side only."""
    packed, rects = packed.copy(), rects.copy()
    sums = np.asarray(sums, dtype=np.float64)
    w = sums[:, 0]
    pick = np.flatnonzero((packed[:, COC] > MIN_COC) & (w > 0) & (rects[:, 1] > rects[:, 0]) & (np.asarray(inside) >= MIN_INSIDE))
    if pick.size == 0:
        return packed, rects
    p = packed[pick].astype(np.float64)
    mx, my = sums[pick, 1] / w[pick], sums[pick, 2] / w[pick]
    visible = np.stack([sums[pick, 3] / w[pick] - mx * mx, sums[pick, 4] / w[pick] - mx * my, sums[pick, 5] / w[pick] - my * my], 1) / (scale * scale)
    det_c = p[:, CA] * p[:, CC] - p[:, CB] ** 2
    old = np.stack([p[:, CC], -p[:, CB], p[:, CA]], 1) / det_c[:, None]
    new, factor = placed_covariance(old, visible, p[:, COC], scale, p[:, OPA])
    det_new = new[:, 0] * new[:, 2] - new[:, 1] ** 2
    u, v = p[:, PX] + mx / scale, p[:, PY] + my / scale
    reach_x = p[:, RADX] / np.sqrt(np.maximum(old[:, 0], 1e-300))  # the footprint's extent in σ
    reach_y = p[:, RADY] / np.sqrt(np.maximum(old[:, 2], 1e-300))
    rad_x, rad_y = np.ceil(reach_x * np.sqrt(new[:, 0])), np.ceil(reach_y * np.sqrt(new[:, 2]))
    columns = {PX: u, PY: v, CA: new[:, 2] / det_new, CB: -new[:, 1] / det_new, CC: new[:, 0] / det_new,
               OPA: p[:, OPA] * factor, AMIN: p[:, AMIN] * factor, RADX: rad_x, RADY: rad_y}
    # a degenerate footprint (singular covariance, overflow) keeps its blurred projection as it was
    with np.errstate(over="ignore", invalid="ignore"):  # finite as stored (float32), not only in float64
        ok = (det_c > 0) & (det_new > 0) & np.isfinite(np.stack(list(columns.values()), 1).astype(np.float32)).all(axis=1)
    pick, u, v, rad_x, rad_y = pick[ok], u[ok], v[ok], rad_x[ok], rad_y[ok]
    for column, value in columns.items():
        packed[pick, column] = value[ok].astype(np.float32)
    tiles = np.array([math.ceil(width / 16), math.ceil(height / 16)], np.float64)
    lo = np.minimum(np.clip(np.floor((np.stack([u - rad_x, v - rad_y], 1)) / 16.0), 0, None), tiles)
    hi = np.minimum(np.clip(np.ceil((np.stack([u + rad_x, v + rad_y], 1)) / 16.0), 0, None), tiles)
    keep = (hi > lo).all(axis=1)
    rects[pick] = (np.stack([lo[:, 0], hi[:, 0], lo[:, 1], hi[:, 1]], 1) * keep[:, None]).astype(rects.dtype)
    return packed, rects

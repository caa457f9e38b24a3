"""Defocus: the model, its measured error, and the helpers both backends share.

Thin lens (:class:`~spacedg.render.settings.Defocus`): a Gaussian at depth ``d`` gets a circle of
confusion ``r = aperture·|d − focus|/d`` px; ``r²·I`` is added to its 2D covariance and its opacity
is multiplied by ``sqrt(det Σ / det(Σ + r² I))`` (its integrated alpha is unchanged), footprints cut
at ``defocus_extent`` σ with the mass renormalised, the alpha floor scaled alike. Every blur counts,
however small (:data:`~spacedg.render.settings.DEFOCUS_MIN_COC` = 0: a cut-off in output pixels
made the preset depend on the image size). The blurred Gaussians are composited by the sharp rules
(:func:`spacedg.render.composite.composite_view`), on a coarser grid when every visible blur is wide
(:func:`composite_factor`; on the compiled path otherwise per 16 × 16 tile, :data:`TILE_SAMPLE_MIN_COC`),
and then brought to the sharp view's **local flux**
(:mod:`spacedg.render.defocus_flux`): a lens redistributes light, it neither makes nor destroys it,
so every neighbourhood a little wider than the blur keeps the light (and the coverage) the sharp
view holds there. That step corrects what compositing blurred splats gets wrong about light —
spread-out splats of one surface occlude each other less (a room 2–4 % dark), an object's hidden
back shows through its thinned front (an object on an empty background up to +10 %) — from one
sharp pass (:func:`spacedg.render.composite.sharp_pass`, at half resolution once the low-pass is ≥ 2 px).
With nothing blurred in the view (every visible ``r = 0``) the sharp render is returned, bit for bit.

Measured against the thin-lens reference (:mod:`spacedg.render.thin_lens`, 48 lens points;
``benchmarks/defocus_reference.py --backends cpu --samples 48 --runs 2``; issue 29) on a built-in
room, the plant capture, its close-up and an object on an empty background, severities 1, 3 and
bench, at 240–320 and 480–640 px: light 1.000–1.002 of the clean render in every row (the
reference: 1.000), PSNR 36.2–56.8 dB (goal ≥ 35), cost 1.7–3.9× a clean render on the room, plant
and close-up on a loaded machine (object: 3.1–7.3×; a 10k-Gaussian render of a few ms, where the
sharp pass's and the flux step's fixed costs dominate); torch at 120 × 90: light 1.000 in every row,
34.7–59.0 dB. The earlier two-pass model (per-Gaussian visible shares measured from five lens
points) was 0.918–0.999 of the light, 29.3–52.4 dB, 2–43×. What still limits it: the blurred
splats' shape at scales below ``L`` — an opaque object of many stacked splats blurred far beyond
their own size saturates (``1 − e^(−Σα)``) out past its rim, so the blurred rim is steeper than the
lens's (a 10-px ball blurred by 1.5 px: light 0.9998, 30.9 dB); see-around at occluding edges (the
lens sees behind an edge, a strip about ``r`` wide) is not modelled; light that blur carries out of
the frame is not subtracted (the flux step conserves the light inside the frame). With the focus at the
preset's far end instead (``--focus high``: everything nearer blurred, the near furniture by the
``max_radius`` clamp), severity 3 and bench at 320–640 px: plant 34.4–37.1 dB, close-up 31.9–34.9,
object 41.1–44.8, but the room 24.9–27.0 dB with its reference converged to 36–39 dB: there the model
is below the 35 dB goal. The reference does not clamp (:mod:`spacedg.render.thin_lens`); without the
``max_radius`` clamp the room is 28.5–29.6 dB (the close-up 31.5–32.8), so the clamp accounts for
about 3.6 dB and the rest is most likely the see-around at the near furniture's edges, not modelled.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np

from spacedg.render.frame import expected_depth
from spacedg.render.project_cpu import COC

__all__ = ["COMPOSITE_MIN_COC", "COMPOSITE_MAX_FACTOR", "MEASURE_SCALE", "TILE_SAMPLE_MIN_COC", "blur_plan", "coarse_view", "composite_factor",
           "factor_for_coc", "measurement_camera", "measurement_settings", "tile_sample_min_coc", "upsample"]


def blur_plan(coc: np.ndarray, width: int, height: int) -> tuple[float, int] | None:
    """``(95th-percentile circle of confusion px, composite factor)`` of a defocused view from its
    visible Gaussians' circles of confusion ``coc`` (px, either backend's, as numpy), or ``None`` when
    none blurs (the view is the sharp render). The factor is :func:`composite_factor`'s."""
    if not (coc > 0.0).any():
        return None
    return float(np.percentile(coc, 95)), factor_for_coc(float(coc.min()), width, height)


#: Default resolution of the sharp pass relative to the view (see :func:`measurement_camera`;
#: :func:`spacedg.render.defocus_flux.flux_scale` chooses 1 or ½ per view).
MEASURE_SCALE = 0.5


def measurement_camera(camera: Any, margin: int, scale: float | None = None) -> Any:
    """``camera`` with its image widened by ``margin`` pixels on every side (same pose and lens),
    then imaged at ``scale`` (default :data:`MEASURE_SCALE`) of its resolution: intrinsics × scale,
    sides ``ceil((side + 2·margin)·scale)``."""
    scale = MEASURE_SCALE if scale is None else float(scale)
    if margin > 0:
        camera = camera.widened(margin)
    if scale == 1.0:
        return camera
    # whole tiles, grown evenly on both sides: the pass composites every pixel of a tile (also those
    # past the frame's edge), and a frame cut inside a tile would measure the Gaussians on its right
    # and bottom edges more fully than those on its left and top (on an opaque wall, 2 % more light)
    width, height = max(1, math.ceil(camera.width * scale)), max(1, math.ceil(camera.height * scale))
    grow_x, grow_y = -width % 16, -height % 16
    capture = camera.capture_focal
    return replace(
        camera, fx=camera.fx * scale, fy=camera.fy * scale,
        cx=camera.cx * scale + grow_x // 2, cy=camera.cy * scale + grow_y // 2, width=width + grow_x, height=height + grow_y,
        # the capture scale s unchanged: with measurement_settings' dilation_scale, the footprint_dilation
        # of the full-resolution view, × scale²
        capture_focal=None if capture is None else (capture[0] * scale, capture[1] * scale),
    )


def measurement_settings(settings: Any, scale: float | None = None) -> Any:
    """``settings`` for the sharp pass at ``scale`` (default :data:`MEASURE_SCALE`): the whole
    dilation (:func:`~spacedg.render.settings.footprint_dilation`, with its capture-scale low-pass)
    × scale², so that every measured footprint is the full-resolution one scaled (the ratios the
    pass yields then do not depend on the scale but through pixel sampling)."""
    scale = MEASURE_SCALE if scale is None else float(scale)
    return settings if scale == 1.0 else replace(settings, dilation_scale=settings.dilation_scale * scale)


#: Smallest circle of confusion (px) for which the blurred view is composited on a coarser grid: when
#: every visible Gaussian is blurred by at least this much, the image has no detail finer than a
#: Gaussian of that standard deviation and is composited at 1/factor of the resolution (factor 2 from
#: 4 px, 4 from 8 px: at least 2 px of blur on the coarse grid) and upsampled bilinearly.
COMPOSITE_MIN_COC = 4.0
COMPOSITE_MAX_FACTOR = 4
#: The same rule per 16 × 16 tile on the compiled path (:func:`spacedg.render.raster_cpu.rasterize`'s
#: ``sample_min_coc``): in a view composited at full resolution, a tile whose every Gaussian is blurred by
#: at least this much (px) is composited at the centres of its 2 × 2 blocks and upsampled. A far focus
#: leaves the background sharp and blurs the near furniture by 5–15 px: on the dataset benchmark's
#: defocus items about half the tiles of such views qualify, and their composite costs about half.
#: 0 turns it off (the torch path composites every tile in full). Measured against the thin lens
#: (``benchmarks/defocus_reference.py --focus high``): every row within 0.3 dB of the full composite.
#: On a 2× coarse grid the same rule applies from twice this (:func:`tile_sample_min_coc`).
TILE_SAMPLE_MIN_COC = COMPOSITE_MIN_COC


def tile_sample_min_coc(factor: int) -> float:
    """The per-tile sampling threshold (px of the view, :data:`TILE_SAMPLE_MIN_COC` × ``factor``) of a blurred
    composite on a grid ``factor`` times coarser than the view (:func:`factor_for_coc`), 0 (no tile sampled)
    where sampling would coarsen past :data:`COMPOSITE_MAX_FACTOR`.

    :func:`coarse_view` keeps the circles of confusion in the view's pixels, so on a 2× grid a tile whose every
    Gaussian is blurred by at least 8 px (4 coarse px) is composited every 2 coarse px: 4× in all, as the
    whole-view rule does from 8 px (which also asks a short side of at least 64 px; per tile, as at 1×, the
    side is not asked). On the dataset benchmark's defocus items, 5–82 % of the tiles of the views
    composited at 2× qualify (70–82 % in three of four), and the renders against the thin lens are unchanged
    to 0.02 dB."""
    if 2 * factor > COMPOSITE_MAX_FACTOR:
        return 0.0
    return TILE_SAMPLE_MIN_COC * factor


def composite_factor(packed: np.ndarray, rects: np.ndarray, width: int, height: int) -> int:
    """1, 2 or 4: the coarsening of the blurred composite (see :data:`COMPOSITE_MIN_COC`); 1 unless
    every visible Gaussian's circle of confusion is at least ``COMPOSITE_MIN_COC`` px and the coarse
    grid keeps at least 16 px on each side."""
    visible = rects[:, 1] > rects[:, 0]
    plan = blur_plan(packed[visible, COC], width, height)
    return 1 if plan is None else plan[1]


def factor_for_coc(smallest: float, width: int, height: int) -> int:
    """:func:`composite_factor` given the smallest visible circle of confusion ``smallest`` (px);
    shared by both backends."""
    if COMPOSITE_MIN_COC <= 0:
        return 1
    factor = 1
    while (
        factor < COMPOSITE_MAX_FACTOR and smallest >= COMPOSITE_MIN_COC * factor
        and min(width, height) >= 16 * 2 * factor
    ):
        factor *= 2
    return factor


def coarse_view(packed: np.ndarray, rects: np.ndarray, width: int, height: int, factor: int) -> tuple[np.ndarray, np.ndarray, int, int]:
    """The blurred projection seen on a grid ``factor`` times coarser: ``(packed, rects, width, height)``.

    Means and footprint radii ÷ factor, conics × factor² (the same footprint in coarse pixels),
    opacity and alpha floor unchanged; tile rectangles from the scaled footprints
    (:func:`spacedg.render.coarse_cpu.coarse_projection`)."""
    from spacedg.render.coarse_cpu import coarse_projection  # numba: compiled on first use

    w2, h2 = -(-width // factor), -(-height // factor)
    packed, rects = coarse_projection(np.ascontiguousarray(packed), np.ascontiguousarray(rects), int(factor), (w2 + 15) // 16, (h2 + 15) // 16)
    return packed, rects, w2, h2


def _bilinear_axis(n_out: int, n_in: int, factor: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Indices ``i0, i1`` and weight ``t`` of the coarse samples around each fine pixel centre (edge-clamped;
    not OpenCV's edge rule of :func:`spacedg.render.defocus_flux.linear_taps`, which gives other bits there)."""
    x = (np.arange(n_out) + 0.5) / factor - 0.5
    i0 = np.floor(x).astype(np.int64)
    t = (x - i0).astype(np.float32)
    return np.clip(i0, 0, n_in - 1), np.clip(i0 + 1, 0, n_in - 1), t


def _bilinear(image: np.ndarray, factor: int, width: int, height: int) -> np.ndarray:
    """``image`` (h, w) or (h, w, C) float32 upsampled to ``height × width`` (coarse cells centred on
    ``factor × factor`` pixels; :func:`spacedg.render.coarse_cpu.bilinear`)."""
    from spacedg.render.coarse_cpu import bilinear  # numba: compiled on first use

    y0, y1, ty = _bilinear_axis(height, image.shape[0], factor)
    x0, x1, tx = _bilinear_axis(width, image.shape[1], factor)
    stacked = np.ascontiguousarray(image if image.ndim == 3 else image[..., None], dtype=np.float32)
    out = bilinear(stacked, y0, y1, ty, x0, x1, tx)
    return out if image.ndim == 3 else out[..., 0]


def upsample(out: dict[str, np.ndarray], factor: int, width: int, height: int, want_color: bool, want_depth: bool, want_ids: bool) -> dict[str, np.ndarray]:
    """Coarse composite images → the view's size (new dict): colour, alpha and depth bilinear (depth as
    Σw·z over alpha, so uncovered pixels do not pull it to 0), median depth and ids nearest; images not
    wanted are passed through as they are."""
    alpha = out["alpha"]
    result = dict(out)
    result["alpha"] = _bilinear(alpha, factor, width, height)
    if want_color:
        result["rgb"] = _bilinear(out["rgb"], factor, width, height)
    if want_depth:
        weighted = _bilinear(out["depth"] * alpha, factor, width, height)
        result["depth"] = expected_depth(weighted, result["alpha"])
    if want_ids:
        rows, cols = (np.arange(height) // factor)[:, None], (np.arange(width) // factor)[None, :]
        for name in ("median_depth", "instance_ids"):
            result[name] = out[name][rows, cols]
    return result

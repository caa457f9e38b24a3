"""Defocus that keeps a view's light: the model, and its driver on the compiled CPU path.

Thin lens (:class:`~spacedg.render.settings.Defocus`): a Gaussian at depth ``d`` gets a circle of
confusion ``r = aperture·|d − focus|/d`` px; ``r²·I`` is added to its 2D covariance and its
opacity is multiplied by ``sqrt(det Σ / det(Σ + r² I))`` (its integrated alpha is unchanged),
footprints cut at ``defocus_extent`` σ with the mass renormalised, the alpha floor scaled alike.

That alone does not keep a **view's** light once many Gaussians overlap, for two reasons
measured on the built-in rooms (mean linear radiance 6–25 % low at the bench apertures):

1. *Coverage.* The splats of one surface overlap, and alpha compositing makes them occlude one
   another: a surface's coverage is ``1 − Π(1 − αᵢ)``. Spread thin, the same alpha mass
   covers ``1 − e^(−Σα)``: an opaque wall 95 % covered sharp was 88 % covered blurred.
2. *Colour.* 3DGS composites sRGB-encoded colour and the renderer decodes the mix; mixing
   many colours in encoded space before decoding (Jensen: the decode is convex) darkens a
   textured view, and more the wider the blur.

A third, at wide blurs: the pinhole Jacobian is evaluated at the mean clamped to the frustum
(widened by 30 %, as gsplat), so Gaussians far outside the view got a wrong, too small
footprint; under defocus the frustum is widened by the widest blurred footprint's reach, so
the light of Gaussians outside the view enters it with its true size (a room's coverage at
aperture 1000 px fell to a third without this).

The model here (two passes, both backends; issue 29 replaced the same-slab share ``κ = S/M``, which
gave hidden Gaussians — an object's back, everything behind a saturated pixel — light they never
show: +19 % to +490 % of the light around an object on an empty background):

1. **Measure the sharp view.** Composite the sharp projection as the sharp render does and,
   per Gaussian, sum over the pixels it reaches ``W = Σw`` (visible weight), ``U_c = Σw·ρ_c``
   (``ρ_c``: the pixel's decoded composite over the linear-light mix of the same splats) and the
   visible weight's first and second moments. The same pass from four more points of the lens
   (:mod:`spacedg.render.defocus_lens`, from a 2 px blur on) gives the lens-averaged visibility.
2. **Render the blurred view** with each blurred Gaussian's opacity (and alpha floor) scaled by
   ``κ`` — the share of its integrated alpha (:func:`alpha_mass`) that the lens sees — its colour
   replaced by linear light ``decode(c)·U_c / W``, and its 2D mean and covariance moved to its
   visible weight's (:mod:`spacedg.render.defocus_place`), so each Gaussian pours exactly the light
   the sharp view shows of it where it shows it. Blurred Gaussians **add** their weight
   ``w = min(α·T_f, T)`` until the pixel saturates (``T_f``: the transmittance through in-focus
   Gaussians in front); in-focus Gaussians (``r < 0.5 px`` counts as in focus,
   :data:`~spacedg.render.settings.DEFOCUS_MIN_COC`) follow the sharp rules in encoded colour. The
   pixel is ``decode(encoded mix) + linear mix``.

Measured against the thin-lens reference (:mod:`spacedg.render.thin_lens`,
``benchmarks/defocus_reference.py``): see that benchmark's table for light, PSNR and cost. What
still limits it: the per-pixel sums of blurred weights scatter around full coverage and the
saturation clips the excess (1–4 % of the light at blurs of 0.5–2 px); the lens-visibility is a
five-point estimate; the measurement passes cost several clean renders.

The sharp pass is rendered on the view widened by a margin (the largest blurred footprint
radius, at most half the view's longer side, :data:`MAX_MARGIN`), so Gaussians whose blur reaches into the view
are measured whole; a Gaussian whose sharp footprint still leaves the measured frame gets its
factors blended with the view's means in proportion to the part left out (a footprint cut by
the frame would otherwise be judged by its cut side alone), and Gaussians the sharp pass never
reached (farther out, or behind opaque surfaces) take the means. With nothing blurred in the view (every visible ``r = 0``) the
sharp render is returned, bit for bit.

Cost (issue 21 part 3; ``benchmarks/defocus_speed.py``). The pass yields ratios only, so it runs at
half the view's resolution (:data:`MEASURE_SCALE`; the ``eps2d`` dilation × ¼ so every footprint is
the full-resolution one scaled; the frame grown evenly to whole tiles, since the pass composites
every pixel of a tile); the factors are gathered and applied in one compiled pass
(:func:`spacedg.render.defocus_cpu.match_and_apply`). When every visible Gaussian is blurred by at
least :data:`COMPOSITE_MIN_COC` px, the image holds no detail finer than that and the blurred view
is composited on a 2× (from 4 px) or 4× (from 8 px) coarser grid and upsampled bilinearly
(median depth and ids: nearest). Against the full-resolution model: PSNR 45–53 dB on the built-in
rooms and the plant capture at presets 1–5 and bench; a wall keeps its light within 0.5 %. Tests: ``tests/render/test_defocus.py`` (a wall, rooms and an opaque ball on an empty background
against the thin lens; r = 0 is the sharp render bit for bit; the backends agree).
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np
from scipy.special import erf

from spacedg.limits import image_size_problem
from spacedg.render.colour import srgb_to_linear
from spacedg.render.frame import expected_depth
from spacedg.render.project_cpu import AMIN, CA, CB, CBL, CC, CG, COC, CR, DEPTH, OPA, PX, PY, RADX, RADY
from spacedg.render.defocus_lens import PRIOR, lens_camera, lens_defocus, lens_points, visibility
from spacedg.render.defocus_place import place_visible
from spacedg.render.settings import DEFOCUS_SLAB

__all__ = ["MAX_MARGIN", "MEASURE_SCALE", "margin_cap", "alpha_mass", "apply_match", "has_blur", "inside_fraction", "match_factors", "measurement_camera", "measurement_margin", "measurement_settings", "slab_of", "composite_factor", "coarse_view", "factor_for_coc", "upsample"]


def slab_of(depths: np.ndarray) -> np.ndarray:
    """Depth slab ``⌊ln z / ln(1 + DEFOCUS_SLAB)⌋`` (int64) of camera depths ``z`` (metres, > 0)."""
    z = np.maximum(np.asarray(depths, dtype=np.float64), 1e-30)
    return np.floor(np.log(z) / np.log1p(DEFOCUS_SLAB)).astype(np.int64)


def has_blur(packed: np.ndarray, rects: np.ndarray) -> bool:
    """Whether any visible Gaussian of a defocused projection has a circle of confusion > 0."""
    visible = rects[:, 1] > rects[:, 0]
    return bool((packed[visible, COC] > 0.0).any())


#: Largest margin of the sharp measurement pass, in multiples of the view's longer side. Gaussians
#: outside the measured frame take the frame's mean visible share, which counts every hidden layer
#: of a room, so a blur much wider than the view loses coverage: a room at a 1000-px aperture on a
#: 64 × 48 image keeps 0.65 of the sharp coverage at 0.5×; at 2× it keeps 0.88–0.98 per view, but
#: the torch path's measurement pass then took 6× longer (issue 29: kept at 0.5 for now).
MAX_MARGIN = 0.5


def margin_cap(width: int, height: int) -> int:
    """The largest margin (px) of the measurement pass for a ``width × height`` view (:data:`MAX_MARGIN`)."""
    return int(MAX_MARGIN * max(width, height))


def measurement_margin(packed: np.ndarray, rects: np.ndarray, width: int, height: int) -> int:
    """Pixels to widen the view by for the sharp pass: the largest blurred footprint radius among
    the visible Gaussians, at most :func:`margin_cap`, and within the size policy."""
    visible = rects[:, 1] > rects[:, 0]
    if not visible.any():
        return 0
    wanted = float(np.max(np.maximum(packed[visible, RADX], packed[visible, RADY])))
    margin = int(min(math.ceil(wanted), margin_cap(width, height)))
    while margin > 0 and image_size_problem(width + 2 * margin, height + 2 * margin) is not None:
        margin //= 2
    return margin


def inside_fraction(packed: np.ndarray, width: int, height: int) -> np.ndarray:
    """(N,) share of each Gaussian's mass inside ``[0, width] × [0, height]``: the product of its two
    marginal normal masses (standard deviations ``sqrt(Σxx)``, ``sqrt(Σyy)`` from the conic)."""
    u, v = packed[:, PX].astype(np.float64), packed[:, PY].astype(np.float64)
    a, b, c = (packed[:, k].astype(np.float64) for k in (CA, CB, CC))
    det = a * c - b * b
    with np.errstate(divide="ignore", invalid="ignore"):
        sx = np.sqrt(np.where(det > 0, c / np.where(det > 0, det, 1.0), 0.25))
        sy = np.sqrt(np.where(det > 0, a / np.where(det > 0, det, 1.0), 0.25))
    sx, sy = np.maximum(np.nan_to_num(sx, nan=0.5), 1e-6), np.maximum(np.nan_to_num(sy, nan=0.5), 1e-6)
    root2 = math.sqrt(2.0)
    fx = 0.5 * (erf((width - u) / (root2 * sx)) - erf(-u / (root2 * sx)))
    fy = 0.5 * (erf((height - v) / (root2 * sy)) - erf(-v / (root2 * sy)))
    return np.clip(fx * fy, 0.0, 1.0)


def alpha_mass(packed: np.ndarray, rects: np.ndarray | None = None) -> np.ndarray:
    """(N,) float64 integrated alpha ``o·2π·sqrt(det Σ)·(1 − f/o)`` of each projected Gaussian (pixels²
    of the projection's grid): opacity ``o``, 2D covariance ``Σ`` from the conic, the part above the
    alpha floor ``f`` kept. 0 for Gaussians culled (``rects`` empty, when given) or degenerate."""
    opa = packed[:, OPA].astype(np.float64)
    det_conic = packed[:, CA].astype(np.float64) * packed[:, CC] - np.square(packed[:, CB].astype(np.float64))
    ok = (opa > 0.0) & (det_conic > 0.0)
    if rects is not None:
        ok &= rects[:, 1] > rects[:, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        kept = 1.0 - np.clip(packed[:, AMIN].astype(np.float64) / np.where(ok, opa, 1.0), 0.0, 1.0)
        mass = opa * 2.0 * math.pi / np.sqrt(np.where(ok, det_conic, 1.0)) * kept
    return np.where(ok & np.isfinite(mass), mass, 0.0)


def match_factors(sums: np.ndarray, inside: np.ndarray, mass: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-Gaussian ``(κ (N,), ρ (N, 3))`` from the sharp pass's sums ``(N, 6)`` = M, S, W, U_r, U_g, U_b.

    ``κ = (W + p·mass·κ̄) / (mass·(inside + p))`` — the share of the Gaussian's alpha inside the
    measured frame (``mass·inside``, :func:`alpha_mass` of the sharp projection) that the sharp
    view shows, taken for the whole Gaussian, pulled towards the frame's mean ``κ̄ = ΣW / Σ(mass·inside)``
    by a prior of weight ``p`` = :data:`spacedg.render.defocus_lens.PRIOR` (a Gaussian barely inside
    the frame gets κ̄), clipped to [0, 1]; ``ρ = U / W`` (≥ 0)
    blended alike with ``ρ̄ = ΣU / ΣW`` (1 when the sharp view shows nothing). A Gaussian the pass
    reached but found hidden (W = 0) gets κ = 0; one outside the measured frame gets κ̄.
    """
    sums = np.asarray(sums, dtype=np.float64)
    w, u = sums[:, 2], sums[:, 3:6]
    share = np.clip(np.asarray(inside, dtype=np.float64), 0.0, 1.0)
    mass = np.asarray(mass, dtype=np.float64)
    expected = float((mass * share).sum())
    kappa_mean = min(w.sum() / expected, 1.0) if expected > 0 else 1.0
    rho_mean = u.sum(axis=0) / w.sum() if w.sum() > 0 else np.ones(3)
    with np.errstate(divide="ignore", invalid="ignore"):
        kappa = np.where(mass > 0, (w + PRIOR * mass * kappa_mean) / np.where(mass > 0, mass * (share + PRIOR), 1.0), kappa_mean)
        rho = np.where(
            (w > 0)[:, None], share[:, None] * (u / np.where(w > 0, w, 1.0)[:, None]) + (1.0 - share[:, None]) * rho_mean[None, :],
            rho_mean[None, :],
        )
    kappa = np.clip(np.nan_to_num(kappa, nan=kappa_mean), 0.0, 1.0)
    rho = np.maximum(np.nan_to_num(rho, nan=1.0, posinf=1.0), 0.0)
    return kappa.astype(np.float32), rho.astype(np.float32)


def apply_match(
    packed: np.ndarray, rects: np.ndarray, kappa: np.ndarray, rho: np.ndarray, want_color: bool
) -> tuple[np.ndarray, np.ndarray]:
    """The blurred projection with the measured factors applied (new arrays; see the module docstring).

    Blurred Gaussians: opacity and alpha floor × κ (a Gaussian with κ = 0 adds nothing and is
    culled), colour → ``decode(c)·ρ`` (linear light). In-focus Gaussians are left as they are.
    """
    packed = packed.copy()
    rects = rects.copy()
    blurred = packed[:, COC] > 0.0
    packed[blurred, OPA] *= kappa[blurred]
    packed[blurred, AMIN] *= kappa[blurred]
    rects[blurred & (kappa <= 0.0)] = 0
    if want_color:
        colours = packed[blurred][:, [CR, CG, CBL]].astype(np.float64)
        packed[np.ix_(blurred, [CR, CG, CBL])] = (srgb_to_linear(colours) * rho[blurred]).astype(np.float32)
    return packed, rects


#: Resolution of the sharp measurement pass relative to the view (see :func:`measurement_camera`).
#: The pass only yields per-Gaussian ratios (``κ = S/M``, ``ρ = U/W``), which do not depend on the
#: pixel size, so it runs at half the view's resolution: a quarter of the pixels (the pass was 44 %
#: of a defocus render). 1.0 measures at full resolution (the model before issue 21).
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
    return replace(
        camera, fx=camera.fx * scale, fy=camera.fy * scale,
        cx=camera.cx * scale + grow_x // 2, cy=camera.cy * scale + grow_y // 2, width=width + grow_x, height=height + grow_y,
    )


def measurement_settings(settings: Any, scale: float | None = None) -> Any:
    """``settings`` for the sharp pass at ``scale`` (default :data:`MEASURE_SCALE`): the ``eps2d``
    dilation × scale², so that every measured footprint is the full-resolution one scaled (the
    ratios the pass yields then do not depend on the scale but through pixel sampling)."""
    scale = MEASURE_SCALE if scale is None else float(scale)
    return settings if scale == 1.0 else replace(settings, eps2d=settings.eps2d * scale * scale)


def render_cpu(
    gaussians: object, camera: object, settings: object, packed: np.ndarray, rects: np.ndarray,
    instance_ids: np.ndarray, want_color: bool, want_depth: bool, want_ids: bool, defocus: Any,
) -> dict[str, np.ndarray]:
    """Both passes on the compiled path; ``rgb`` in the result is **linear** light."""
    from spacedg.render import defocus_cpu, raster_cpu
    from spacedg.render.colour_cpu import decode_srgb

    width, height = camera.width, camera.height  # type: ignore[attr-defined]
    tight = settings.tight_tiles and settings.opacity_extent  # type: ignore[attr-defined]
    tiles_x = (width + 15) // 16
    # pass 1: the sharp view, widened by a margin, measured from the lens centre and the other lens points
    margin = measurement_margin(packed, rects, width, height)
    wide = measurement_camera(camera, margin)
    sharp, sharp_rects, gauss, pair_out = _measure_cpu(gaussians, wide, settings, want_color)
    lens = lens_defocus(defocus, wide.fx / camera.fx, wide.fx)  # type: ignore[attr-defined]
    seen = np.zeros(packed.shape[0])
    visible = rects[:, 1] > rects[:, 0]
    centre_weight, points = lens_points(float(packed[visible, COC].max()) if visible.any() else 0.0)
    for offset, weight in points:
        seen_b, rects_b, gauss_b, pairs_b = _measure_cpu(gaussians, lens_camera(wide, lens, np.array(offset)), settings, False)
        w_b = np.bincount(gauss_b, weights=pairs_b[:, defocus_cpu.PAIR_W].astype(np.float64), minlength=packed.shape[0])
        seen += weight * visibility(w_b, alpha_mass(seen_b, rects_b), inside_fraction(seen_b, wide.width, wide.height))
    # pass 2: the blurred view, with the factors of match_factors / apply_match (compiled)
    mass = alpha_mass(sharp, sharp_rects)
    packed, rects = defocus_cpu.match_and_apply(
        gauss, pair_out, sharp, mass, wide.width, wide.height, packed, rects, want_color, centre_weight, seen, PRIOR,
    )
    moments = np.stack([np.bincount(gauss, weights=pair_out[:, j].astype(np.float64), minlength=packed.shape[0])
                        for j in (defocus_cpu.PAIR_W, *range(defocus_cpu.PAIR_MOMENTS, defocus_cpu.PAIR_COLUMNS))], axis=1)
    packed, rects = place_visible(
        packed, rects, moments, wide.fx / camera.fx, width, height, inside_fraction(sharp, wide.width, wide.height),  # type: ignore[attr-defined]
    )
    n_visible = np.int64(np.count_nonzero(rects[:, 1] > rects[:, 0]))
    factor = composite_factor(packed, rects, width, height)
    if factor > 1:  # every visible Gaussian blurred by >= COMPOSITE_MIN_COC px: composite on a coarser grid
        full = (width, height)
        packed, rects, width, height = coarse_view(packed, rects, width, height, factor)
        tiles_x = (width + 15) // 16
    offsets, gauss = raster_cpu.bin_visible(packed, rects, width, height, tight)
    out = {
        "alpha": np.zeros((height, width), np.float32),
        "enc": np.zeros((height, width, 3) if want_color else (1, 1, 3), np.float32),
        "lin": np.zeros((height, width, 3) if want_color else (1, 1, 3), np.float32),
        "depth": np.zeros((height, width) if want_depth else (1, 1), np.float32),
        "median_depth": np.zeros((height, width) if want_ids else (1, 1), np.float32),
        "instance_ids": np.full((height, width) if want_ids else (1, 1), -1, np.int32),
    }
    defocus_cpu.composite_defocus(
        offsets, gauss, packed, instance_ids, width, height, tiles_x, settings.alpha_max,  # type: ignore[attr-defined]
        want_color, want_depth, want_ids,
        out["enc"], out["lin"], out["alpha"], out["depth"], out["median_depth"], out["instance_ids"],
    )
    enc, lin = out.pop("enc"), out.pop("lin")
    out["rgb"] = decode_srgb(enc) + lin if want_color else enc
    if factor > 1:
        out = upsample(out, factor, *full, want_color, want_depth, want_ids)
    out["n_pairs"] = np.int64(gauss.shape[0])
    out["n_visible"] = n_visible
    return out


def _measure_cpu(gaussians: Any, camera: Any, settings: Any, want_color: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One sharp measurement pass on the compiled path: ``(sharp packed, rects, pair Gaussians, pair sums)``."""
    from spacedg.render import defocus_cpu, project_cpu, raster_cpu

    sharp, sharp_rects = project_cpu.project_gaussians(gaussians, camera, measurement_settings(settings), None, want_color)
    offsets, gauss = raster_cpu.bin_visible(sharp, sharp_rects, camera.width, camera.height, settings.tight_tiles and settings.opacity_extent)
    pair_out = np.zeros((gauss.shape[0], defocus_cpu.PAIR_COLUMNS), np.float32)
    lin = srgb_to_linear(sharp[:, [CR, CG, CBL]]).astype(np.float32)
    defocus_cpu.measure_sharp(offsets, gauss, sharp, lin, slab_of(sharp[:, DEPTH]), (camera.width + 15) // 16, settings.alpha_max, pair_out)
    return sharp, sharp_rects, gauss, pair_out


#: Smallest circle of confusion (px) for which the blurred view is composited on a coarser grid: when
#: every visible Gaussian is blurred by at least this much, the image has no detail finer than a
#: Gaussian of that standard deviation and is composited at 1/factor of the resolution (factor 2 from
#: 4 px, 4 from 8 px: at least 2 px of blur on the coarse grid) and upsampled bilinearly.
COMPOSITE_MIN_COC = 4.0
COMPOSITE_MAX_FACTOR = 4


def composite_factor(packed: np.ndarray, rects: np.ndarray, width: int, height: int) -> int:
    """1, 2 or 4: the coarsening of the blurred composite (see :data:`COMPOSITE_MIN_COC`); 1 unless
    every visible Gaussian's circle of confusion is at least ``COMPOSITE_MIN_COC`` px and the coarse
    grid keeps at least 16 px on each side."""
    visible = rects[:, 1] > rects[:, 0]
    if COMPOSITE_MIN_COC <= 0 or not visible.any():
        return 1
    return factor_for_coc(float(packed[visible, COC].min()), width, height)


def factor_for_coc(smallest: float, width: int, height: int) -> int:
    """:func:`composite_factor` given the smallest visible circle of confusion ``smallest`` (px);
    shared by both backends."""
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
    opacity and alpha floor unchanged; tile rectangles from the scaled footprints."""

    f = float(factor)
    w2, h2 = -(-width // factor), -(-height // factor)
    packed = packed.copy()
    packed[:, [PX, PY]] /= np.float32(f)
    packed[:, [CA, CB, CC]] *= np.float32(f * f)
    packed[:, [RADX, RADY]] = np.ceil(packed[:, [RADX, RADY]] / np.float32(f))
    visible = rects[:, 1] > rects[:, 0]
    tiles = np.array([(w2 + 15) // 16, (h2 + 15) // 16], np.float64)
    mean = packed[:, [PX, PY]].astype(np.float64)
    rad = packed[:, [RADX, RADY]].astype(np.float64)
    lo = np.minimum(np.clip(np.floor((mean - rad) / 16.0), 0, None), tiles)
    hi = np.minimum(np.clip(np.ceil((mean + rad) / 16.0), 0, None), tiles)
    keep = visible & (hi > lo).all(axis=1)
    rects = (np.stack([lo[:, 0], hi[:, 0], lo[:, 1], hi[:, 1]], axis=1) * keep[:, None]).astype(rects.dtype)
    return packed, rects, w2, h2


def _bilinear_axis(n_out: int, n_in: int, factor: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Indices ``i0, i1`` and weight ``t`` of the coarse samples around each fine pixel centre (edge-clamped)."""
    x = (np.arange(n_out) + 0.5) / factor - 0.5
    i0 = np.floor(x).astype(np.int64)
    t = (x - i0).astype(np.float32)
    return np.clip(i0, 0, n_in - 1), np.clip(i0 + 1, 0, n_in - 1), t


def _bilinear(image: np.ndarray, factor: int, width: int, height: int) -> np.ndarray:
    y0, y1, ty = _bilinear_axis(height, image.shape[0], factor)
    x0, x1, tx = _bilinear_axis(width, image.shape[1], factor)
    shape = (-1, 1) + (1,) * (image.ndim - 2)
    rows = image[y0] * (1 - ty.reshape(shape)) + image[y1] * ty.reshape(shape)
    shape = (1, -1) + (1,) * (image.ndim - 2)
    return (rows[:, x0] * (1 - tx.reshape(shape)) + rows[:, x1] * tx.reshape(shape)).astype(np.float32)


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

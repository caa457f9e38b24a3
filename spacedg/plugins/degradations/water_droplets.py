"""Water droplets on the lens (meteorological, linear stage): refraction, blur and highlights.

Model: the paper's "Water Droplets" — a procedural multi-layer height map ``h(x, y)`` of drops
gives surface normals ``n = normalize(-∂h/∂x, -∂h/∂y, 1)``; the content seen through a drop is
sampled at a refraction offset ``Δu ∝ n_x``, ``Δv ∝ n_y``, blurred (Gaussian), lit by a Phong
specular highlight and blended in with a soft drop edge. Outside the drops the image is
untouched, bit for bit.

Drop field (all randomness from ``rng``, a :class:`numpy.random.Generator`)
--------------------------------------------------------------------------

- Image coordinates: x right, y down, in pixels, pixel centres at ``(j + 0.5, i + 0.5)``;
  ``S = min(H, W)`` is the shorter side.
- :data:`N_LAYERS` = 3 layers ``l = 0, 1, 2`` of square cells of side ``c_l = S / (scale · 2^l)``
  px, anchored at the image's top-left corner: ``scale`` cells of the largest layer span the
  shorter side. Along the longer side the cells are counted and laid as the view's common aspect
  has it (:func:`~.common.snapped_size`: a 584 × 389 image is 3:2, as 1752 × 1168), stretched
  by the image's own side over that (1 for an exact aspect), so every size of one view gets the
  same drops at the same fractions of the image. Each cell holds at most one drop, present with probability
  :data:`PRESENCE` ``[l]`` (0.9, 0.7, 0.5): finer layers have more, smaller, sparser drops.
- Drop radius ``r = radius · (c_l / 2) · f`` px with a size factor ``f ~ U[`` :data:`MIN_SIZE` ``, 1]``:
  ``radius`` is the largest drop radius as a fraction of its cell's half-size. The centre is
  jittered uniformly but the drop stays inside its cell, so a pixel only examines its own cell
  in each layer.
- Height: a hemisphere, ``h = sqrt(r² − d²)`` px at distance ``d`` from the centre. Where drops
  of several layers overlap, the highest one wins (its normal, edge and highlight are used).
  Its normal is ``n = ((x − c_x) / r, (y − c_y) / r, h / r)``, finite up to the rim.
- Soft edge: coverage ``α = smoothstep`` from ``d = r`` (0) to ``d = (1 −`` :data:`EDGE_WIDTH` ``) r`` (1).
  The drop mask is ``α > 0``, i.e. ``d < r``.

Optics (in linear light, HDR values above 1 kept, nothing clipped)
------------------------------------------------------------------

A drop is a small positive lens: it shows the scene behind it **flipped and minified**, as
physically based raindrop rendering finds (Garg & Nayar 2006; Roser & Geiger 2009: each drop is
a wide-angle lens showing an inverted image of the environment), lit by a specular highlight,
and it creates no light: over a black scene it stays black outside its highlight.

- Refraction, the paper's "simplified Snell's law" ``Δu ∝ n_x, Δv ∝ n_y``: a thin prism of
  index ``n`` tilted by ``t`` deviates a ray by ``δ ≈ (n − 1) t ≈ (n − 1) sin t``, and a
  deviation ``δ`` moves the sampled scene point by ``F·δ`` px, ``F`` the focal length in pixels.
  So the pixel at ``p`` shows the scene at ``p − strength · F · n_xy``: ``strength`` is the
  deviation per unit of surface slope, ``n − 1`` for a thin drop (water 0.33; the bench range
  0.3–0.5 allows for the drop's shape) and ``F`` = :data:`REFRACTION_FOCAL`
  × the image's longer side (a nominal 53° horizontal view: the linear stage has no camera; in
  units of the image, so the drop's optics do not depend on the output size). With
  ``n_xy = (p − c) / r`` this is ``c − (strength·F/r − 1)(p − c)``: the drop of radius ``r``
  shows the scene within ``strength·F − r`` px of its centre, inverted and minified
  ``strength·F/r − 1`` times (bench at 640×360: about 3× for the largest drops, over 100× for the
  smallest); ``strength = 0`` shows the scene behind undeviated. Sampling (:func:`refracted_view`):
  where the drop magnifies, :func:`cv2.remap` (bilinear, ``BORDER_REFLECT`` for rays leaving the
  frame; coordinates are always finite); where it minifies ``k = |1 − strength·F/r| > 1`` times, the
  mean of the scene over the ``k × k`` px square the pixel spans (a summed-area table of the
  reflect-padded frame), as the lens integrates it: a point sample would alias, and differ between
  image sizes (1920 × 1080 area-downsampled against 640 × 360 on an imported capture: 34.4–36.0 dB
  with point samples, 39.8–42.6 with the mean). Either way radiance is moved, never amplified (the
  brightness theorem: a lossless lens keeps radiance).
- In-drop optical blur: :func:`cv2.GaussianBlur` of the refracted image, ``blur_sigma`` px (in
  image pixels) with an odd ``blur_kernel`` px square kernel (OpenCV ``ksize``; a kernel
  narrower than ``±2σ`` truncates the Gaussian, as in OpenCV). No blur when ``blur_sigma = 0``
  or ``blur_kernel = 1`` (OpenCV would otherwise derive σ from the kernel).
- Transmission: the Fresnel transmittance of the air–water surface (unpolarised, water's index
  :data:`WATER_INDEX` = 1.333, a property of the material whatever the drop's shape) at the
  ray's incidence angle ``θ_i = acos n_z``, relative to normal incidence: ``τ = T(θ_i) / T(0)``
  (1 at the centre, 0 at the grazing rim, so drops show a dark outline; the clean image already
  carries the lens's own surface losses at normal incidence). Averaged over a drop, weighted by
  its coverage, τ is 0.983: outside the highlights a drop carries 98.3 % of the light of the
  refracted background it shows (98.2–98.4 % measured over whole drop fields, every preset, on
  textured frames; ``benchmarks/drops_distortion.py``).
  ``rim`` weights this loss (1 = the Fresnel law, 0 = lossless).
- Phong specular highlight, white, added in linear light: ``α · k_s · max(0, R·V)^shininess``
  with ``R = 2(n·L)n − L``, view ``V = (0, 0, 1)`` (towards the camera), light from the upper
  left ``L = normalize(−1, −1, 2)`` (:data:`LIGHT_DIRECTION`), ``k_s`` = :data:`SPECULAR_INTENSITY`
  = 0.5 (linear units, 1 = diffuse white: the mirror image of a lamp, about 25× diffuse white
  seen at water's 2 % reflectance), shininess :data:`SHININESS` = 16. It is the only light a
  drop adds.
- Composite inside drops: ``out = (1 − α) · I + α · τ · blur(refract(I)) + highlight``: outside
  the highlights, a drop's light is the refracted background's, less the Fresnel loss.

Identity, limits and errors
---------------------------

- ``radius = 0`` or ``scale = 0`` means no drops: the output is a bit-exact copy (``rng`` is
  not used). ``strength = 0`` still blurs, darkens the rims of and lights the drops.
- Input: float32 (H, W, 3), finite. NaN or ±inf is rejected with :class:`InvalidDataError`
  (blur and interpolation would turn ``inf · 0`` into NaN inside drops); finite values of any
  size (tested up to 1e30) give finite output.
- ``blur_kernel`` must be odd: an even value raises :class:`ParameterError` (never rounded).
- Deterministic for a given ``rng`` state; the compiled kernels compute each pixel (or each row of
  pixels) on its own, so the bytes do not depend on the number of numba threads.

Parameters (hard limits): ``scale`` 1/image [0, 100]; ``radius`` 1 [0, 1]; ``strength`` 1
[0, 5]; ``blur_sigma`` px [0, 20]; ``blur_kernel`` px, odd integer [1, 51].

Presets: ``bench`` = the paper's table (scale [2.5, 4], radius [0.25, 0.75], strength
[0.3, 0.5], blur_sigma [2, 2.5], blur_kernel 9). Severities ``1`` … ``5`` keep scale in
[2.5, 4] and raise radius, strength, blur_sigma and blur_kernel (5, 7, 9, 9, 11); ``4`` is
close to bench.

**Size-invariant** (decision): the drop field is already defined relative to the image (cells
across the shorter side, radii as fractions of a cell, the refraction offset proportional to
the radius), and it is drawn per cell, so the same ``rng`` gives the same drops at every size.
The presets' ``blur_sigma`` and ``blur_kernel`` are pixels of the reference image
(:data:`~spacedg.plugins.specs.REFERENCE_IMAGE_SIZE`, 1752 × 1168) and scale with the output's
shorter side (``ParamRange(per_size=True)``; the kernel's half-width is scaled, so it stays
odd): at 640 × 360 the bench blur is σ ≈ 0.6–0.8 px in a 3 px kernel. The provenance records
the pixels used. Explicit values are pixels of the output, as before.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import cv2
import numba
import numpy as np

from spacedg.errors import InvalidDataError, ParameterError
from spacedg.plugins.degradations.common import box_pad, check_linear_rgb, reflect_index, snapped_size
from spacedg.plugins.hookspecs import registering
from spacedg.plugins.specs import Category, DegradationSpec, ParamRange, ParamSpec, Stage
from spacedg.render import kernel_cache  # numba's cache entries checked before any kernel here compiles
from spacedg.render.threads import fork_safe

__all__ = [
    "SPEC",
    "DropletField",
    "droplet_field",
    "water_droplets",
    "N_LAYERS",
    "PRESENCE",
    "MIN_SIZE",
    "EDGE_WIDTH",
    "LIGHT_DIRECTION",
    "SPECULAR_INTENSITY",
    "SHININESS",
    "RIM_DARKENING",
    "REFRACTION_FOCAL",
    "WATER_INDEX",
    "fresnel_ratio",
]

NAME = "water_droplets"
#: Number of drop layers; layer ``l`` has cells of side ``min(H, W) / (scale · 2^l)`` px.
N_LAYERS = 3
#: Probability that a cell of layer ``l`` holds a drop.
PRESENCE: tuple[float, ...] = (0.9, 0.7, 0.5)
#: Smallest drop size factor: drop radii are ``U[MIN_SIZE, 1] · radius · cell / 2``.
MIN_SIZE = 0.5
#: Soft edge: coverage rises from 0 at the rim to 1 over this fraction of the radius.
EDGE_WIDTH = 0.15
#: Unit vector towards the light (x right, y down, z towards the camera): upper left, in front.
LIGHT_DIRECTION: tuple[float, float, float] = (-1.0 / math.sqrt(6.0), -1.0 / math.sqrt(6.0), 2.0 / math.sqrt(6.0))
#: Phong specular coefficient ``k_s`` in linear light (1 = diffuse white).
SPECULAR_INTENSITY = 0.5
#: Phong shininess exponent, ``2 ** SHININESS_LOG2`` (evaluated by repeated squaring).
SHININESS_LOG2 = 4
#: Weight of the Fresnel loss towards a drop's rim: ``τ = 1 − RIM_DARKENING · (1 − T(θ_i)/T(0))`` (1 = physical).
RIM_DARKENING = 1.0
#: Nominal focal length of the refraction, as a multiple of the image's longer side (a 53° view).
REFRACTION_FOCAL = 1.0
#: Refractive index of water (at 589 nm, 20 °C), for the Fresnel transmission of a drop's surface.
WATER_INDEX = 1.333
SHININESS = 2**SHININESS_LOG2
#: Most drop cells of the finest layer (guards extreme aspect ratios at high ``scale``).
MAX_CELLS = 10_000_000

SCALE = ParamSpec("scale", "1/image", "Drop-field frequency: cells of the largest drop layer across the image's shorter side (0 = no drops).", low=0.0, high=100.0)
RADIUS = ParamSpec("radius", "1", "Largest drop radius as a fraction of its cell's half-size (0 = no drops).", low=0.0, high=1.0, harsher="higher")
STRENGTH = ParamSpec("strength", "1", "Refraction (n - 1 for a thin drop): a pixel shows the scene at p - strength * F * n_xy (F = the image's longer side): a flipped, minified view.", low=0.0, high=5.0, harsher="higher")
BLUR_SIGMA = ParamSpec("blur_sigma", "px", "Standard deviation of the Gaussian blur inside drops (0 = no blur).", low=0.0, high=20.0, harsher="higher")
BLUR_KERNEL = ParamSpec("blur_kernel", "px", "Odd side of the square Gaussian kernel inside drops (OpenCV ksize; 1 = no blur).", low=1, high=51, integer=True, harsher="higher")


@dataclass(frozen=True)
class DropletField:
    """One drawn drop field on an (H, W) image (all arrays float32 (H, W)).

    Attributes:
        alpha: soft drop coverage in [0, 1]; 0 exactly outside every drop.
        height: height of the top drop in px (0 outside drops).
        highlight: ``alpha · max(0, R·V)^SHININESS``, the Phong term at unit ``k_s``.
        transmission: Fresnel transmittance of the top drop's surface relative to normal
            incidence, ``T(acos n_z) / T(0)`` at :data:`WATER_INDEX` (1 at its centre, 0 at
            its rim; 1 outside drops): the transmission at unit :data:`RIM_DARKENING`.
        map_x, map_y: :func:`cv2.remap` source coordinates (pixel index units, centre at
            integer) of the refracted view; the identity outside drops.
        spread: source pixels one output pixel spans under the drop, ``|1 − reach / r|`` (the
            map's Jacobian; > 1: the drop minifies, and the pixel averages that square of the
            scene, :func:`refracted_view`); 0 outside drops.
    """

    alpha: np.ndarray
    height: np.ndarray
    highlight: np.ndarray
    map_x: np.ndarray
    map_y: np.ndarray
    transmission: np.ndarray
    spread: np.ndarray


# ------------------------------------------------------------------ compiled kernels
def fresnel_ratio(cos_i: Any, index: float) -> Any:
    """Unpolarised Fresnel transmittance from air into a medium of ``index`` (>= 1) at incidence
    cosine ``cos_i`` in [0, 1], relative to normal incidence: 1 at ``cos_i = 1``, 0 at grazing.
    Floats and numpy arrays alike (and compiled by numba for the drop field)."""
    sin_t2 = (1.0 - cos_i * cos_i) / (index * index)
    cos_t = (1.0 - sin_t2) ** 0.5
    r_s = ((cos_i - index * cos_t) / (cos_i + index * cos_t)) ** 2
    r_p = ((index * cos_i - cos_t) / (index * cos_i + cos_t)) ** 2
    r_0 = ((index - 1.0) / (index + 1.0)) ** 2
    return (1.0 - 0.5 * (r_s + r_p)) / (1.0 - r_0)


_fresnel_ratio = numba.njit(cache=True, inline="always")(fresnel_ratio)


@fork_safe
@numba.njit(parallel=True, cache=True)
def _field_kernel(
    height: int,
    width: int,
    cell: np.ndarray,
    n_cols: np.ndarray,
    n_rows: np.ndarray,
    offset: np.ndarray,
    centre_x: np.ndarray,
    centre_y: np.ndarray,
    drop_r: np.ndarray,
    reach: float,
    index: float,
    light: np.ndarray,
    shininess_log2: int,
    edge: float,
    alpha: np.ndarray,
    height_map: np.ndarray,
    highlight: np.ndarray,
    map_x: np.ndarray,
    map_y: np.ndarray,
    transmission: np.ndarray,
    spread: np.ndarray,
) -> None:  # pragma: no cover - compiled
    """Per pixel: the highest drop over all layers, its coverage, highlight, Fresnel ratio, remap coordinates and spread.

    ``reach`` = strength · F px (the source moves by ``reach · n_xy``), ``index``: the Fresnel index.

    A pixel ``(j + ½, i + ½)`` looks at one cell per layer, ``min(⌊x / cell⌋, columns − 1)`` along each
    axis, and takes the highest drop of those that hold it (``d² < r²``; a tie keeps the earlier layer).
    Per row this runs drop by drop: each layer's cells of the row, each drop that reaches the row over
    the pixels of its cell within a pixel of its disk (most of an image lies in no drop; a pixel-by-pixel
    walk of the three layers spent ~3 ms a 640 × 480 view on them). The same float64 expressions
    per pixel and the same layer order: the same bytes."""
    n_layers = cell.shape[0]  # cell: (L, 2) cell width and height per layer, px
    lx, ly, lz = light[0], light[1], light[2]
    inv_cell_x = 1.0 / cell[:, 0]
    inv_cell_y = 1.0 / cell[:, 1]
    # each cell column's pixel columns [first[layer, c], first[layer, c + 1]): the pixel's own cell lookup
    first = np.zeros((n_layers, n_cols.max() + 1), np.int64)
    for layer in range(n_layers):
        c = 0
        for j in range(width):
            k = min(int((j + 0.5) * inv_cell_x[layer]), n_cols[layer] - 1)
            while c < k:
                c += 1
                first[layer, c] = j
        for rest in range(c + 1, n_cols[layer] + 1):
            first[layer, rest] = width
    for i in numba.prange(height):
        y = i + 0.5
        best_h = np.full(width, -1.0)
        best_dx = np.zeros(width)
        best_dy = np.zeros(width)
        best_r = np.ones(width)
        for layer in range(n_layers):
            row = min(int(y * inv_cell_y[layer]), n_rows[layer] - 1)
            base = offset[layer] + row * n_cols[layer]
            for c in range(n_cols[layer]):
                k = base + c
                r = drop_r[k]
                dy = y - centre_y[k]
                r2 = r * r
                if dy * dy >= r2:  # d² = dx² + dy² ≥ dy² (float addition of a non-negative term): no pixel of the row; also an empty cell
                    continue
                half_chord = math.sqrt(r2 - dy * dy)
                cx = centre_x[k]
                # the cell's pixels [start, stop) within a pixel of the chord, clamped as floats before any integer
                # conversion (a chord or centre beyond the int64 range would wrap): a NaN bound walks the whole span
                # with the exact test, as every pixel did
                start, stop = first[layer, c], first[layer, c + 1]
                lo_x = np.floor(cx - half_chord - 0.5) - 1.0
                hi_x = np.floor(cx + half_chord - 0.5) + 2.0
                lo = int(lo_x) if start < lo_x < stop else (stop if lo_x >= stop else start)
                hi = int(hi_x) if start < hi_x < stop else (start if hi_x <= start else stop)
                for j in range(lo, hi):
                    dx = (j + 0.5) - cx
                    d2 = dx * dx + dy * dy
                    if d2 >= r2:
                        continue
                    h = np.sqrt(r2 - d2)
                    if h > best_h[j]:
                        best_h[j], best_dx[j], best_dy[j], best_r[j] = h, dx, dy, r
        for j in range(width):
            x = j + 0.5
            if best_h[j] < 0.0:
                alpha[i, j] = 0.0
                height_map[i, j] = 0.0
                highlight[i, j] = 0.0
                map_x[i, j] = j
                map_y[i, j] = i
                transmission[i, j] = 1.0
                spread[i, j] = 0.0
                continue
            nx = best_dx[j] / best_r[j]
            ny = best_dy[j] / best_r[j]
            nz = best_h[j] / best_r[j]
            t = min((1.0 - np.sqrt(nx * nx + ny * ny)) / edge, 1.0)
            a = t * t * (3.0 - 2.0 * t)
            spec = max(2.0 * (nx * lx + ny * ly + nz * lz) * nz - lz, 0.0)  # R·V, R = 2(n·L)n − L, V = +z
            for _ in range(shininess_log2):
                spec *= spec
            alpha[i, j] = a
            height_map[i, j] = best_h[j]
            highlight[i, j] = a * spec
            map_x[i, j] = x - reach * nx - 0.5
            map_y[i, j] = y - reach * ny - 0.5
            transmission[i, j] = _fresnel_ratio(nz, index)
            spread[i, j] = abs(1.0 - reach / best_r[j])


@fork_safe
@numba.njit(parallel=True, cache=True)
def _composite_kernel(
    rgb: np.ndarray, seen: np.ndarray, alpha: np.ndarray, highlight: np.ndarray, k_s: float,
    transmission: np.ndarray, rim: float, out: np.ndarray,
) -> None:  # pragma: no cover - compiled
    """``out = (1 − α) rgb + α τ seen + k_s highlight``, ``τ = 1 − rim (1 − t)``, where ``α > 0``; others untouched."""
    for i in numba.prange(rgb.shape[0]):
        for j in range(rgb.shape[1]):
            a = alpha[i, j]
            if a <= 0.0:
                continue
            spec = k_s * highlight[i, j]
            through = a * (1.0 - rim * (1.0 - transmission[i, j]))
            for ch in range(3):
                out[i, j, ch] = (1.0 - a) * rgb[i, j, ch] + through * seen[i, j, ch] + spec


# ------------------------------------------------------------------ python side
def _check_params(scale: float, radius: float, strength: float, blur_sigma: float, blur_kernel: int) -> dict[str, Any]:
    params = SPEC.validate_params(
        {"scale": scale, "radius": radius, "strength": strength, "blur_sigma": blur_sigma, "blur_kernel": blur_kernel}
    )
    k = params["blur_kernel"]
    if k % 2 == 0:
        raise ParameterError(
            f"degradation {NAME!r}: parameter 'blur_kernel' = {k} must be odd (OpenCV GaussianBlur ksize); "
            f"use {k - 1} or {k + 1}"
        )
    return params


def _draw_drops(shape: tuple[int, int], scale: float, radius: float, rng: np.random.Generator) -> tuple[np.ndarray, ...]:
    """Per-layer grids (``cells`` (L, 2): cell width and height, px) and per-cell drops (centre x, y and
    radius in px; radius 0 = no drop)."""
    height, width = shape
    finest = min(height, width) / (scale * 2.0 ** (N_LAYERS - 1))
    if np.ceil(width / finest) * np.ceil(height / finest) > MAX_CELLS:
        raise ParameterError(
            f"degradation {NAME!r}: scale {scale:g} on a {height}×{width} image needs more than {MAX_CELLS:.0e} drop "
            "cells (the frequency counts cells across the shorter side); lower scale or use a less elongated image"
        )
    cells, cols, rows, offsets, cx, cy, rr = [], [], [], [], [], [], []
    total = 0
    # the sides as the view's common aspect has them: every size of one view gets the same cells and
    # drops, at the same fractions of the image (cells stretched by the image's side over that, exactly 1
    # for the shorter side and for an exact aspect)
    snapped_w, snapped_h = snapped_size(width, height)
    for layer in range(N_LAYERS):
        c = min(height, width) / (scale * 2.0**layer)
        n_cols, n_rows = max(1, int(np.ceil(snapped_w / c))), max(1, int(np.ceil(snapped_h / c)))
        c_x, c_y = c * (width / snapped_w), c * (height / snapped_h)
        u = rng.random((4, n_rows, n_cols))
        r = np.where(u[0] < PRESENCE[layer], radius * 0.5 * c * (MIN_SIZE + (1.0 - MIN_SIZE) * u[1]), 0.0)
        # the centre may move this far from the cell centre, keeping the drop inside
        room_x, room_y = 0.5 * c_x - r, 0.5 * c_y - r
        cx.append(((np.arange(n_cols) + 0.5) * c_x + room_x * (2.0 * u[2] - 1.0)).ravel())
        cy.append(((np.arange(n_rows)[:, None] + 0.5) * c_y + room_y * (2.0 * u[3] - 1.0)).ravel())
        rr.append(r.ravel())
        cells.append((c_x, c_y))
        cols.append(n_cols)
        rows.append(n_rows)
        offsets.append(total)
        total += n_cols * n_rows
    return (
        np.asarray(cells, np.float64),
        np.asarray(cols, np.int64),
        np.asarray(rows, np.int64),
        np.asarray(offsets, np.int64),
        np.concatenate(cx),
        np.concatenate(cy),
        np.concatenate(rr),
    )


def refraction_reach(shape: tuple[int, int], strength: float) -> float:
    """``strength · F`` px: how far a drop's rim samples the scene from the rim's own pixel
    (``F`` = :data:`REFRACTION_FOCAL` × the longer side of an image of ``shape = (H, W)``)."""
    return float(strength) * REFRACTION_FOCAL * float(max(shape))


def droplet_field(
    shape: tuple[int, int], scale: float, radius: float, strength: float, rng: np.random.Generator
) -> DropletField:
    """Draw a drop field on an image of ``shape = (H, W)`` (see the module docstring for units).

    :func:`water_droplets` calls this first with its ``rng``, so the same seed gives the same
    field here and there. ``scale = 0`` or ``radius = 0`` gives an empty field without using ``rng``.
    """
    height, width = (int(v) for v in shape)
    p = SPEC.validate_params({"scale": scale, "radius": radius, "strength": strength}, partial=True)
    scale, radius, strength = p["scale"], p["radius"], p["strength"]
    if not isinstance(rng, np.random.Generator):
        raise InvalidDataError(f"{NAME}: rng must be a numpy.random.Generator, got {type(rng).__name__}; use np.random.default_rng(seed)")
    field = DropletField(*(np.empty((height, width), np.float32) for _ in range(7)))
    if scale == 0.0 or radius == 0.0:
        for array in (field.alpha, field.height, field.highlight, field.spread):
            array.fill(0.0)
        field.map_x[:] = np.arange(width, dtype=np.float32)
        field.map_y[:] = np.arange(height, dtype=np.float32)[:, None]
        field.transmission.fill(1.0)
        return field
    drops = _draw_drops((height, width), scale, radius, rng)
    _field_kernel(
        height, width, *drops, refraction_reach((height, width), strength), WATER_INDEX, np.asarray(LIGHT_DIRECTION, np.float64), SHININESS_LOG2, EDGE_WIDTH,
        field.alpha, field.height, field.highlight, field.map_x, field.map_y, field.transmission, field.spread,
    )
    return field


@fork_safe
@numba.njit(parallel=True, cache=True)
def _box_kernel(
    sat: np.ndarray, pad: int, map_x: np.ndarray, map_y: np.ndarray, spread: np.ndarray, lo: np.ndarray, hi: np.ndarray,
    out: np.ndarray,
) -> None:  # pragma: no cover - compiled
    """Where ``spread > 1``: ``out`` = the mean of the scene over the ``spread``-px square centred on the
    source point (mirrored into the frame as ``BORDER_REFLECT`` does), from ``sat``, the summed-area
    table ((H + 2 pad + 1, W + 2 pad + 1, 3) float64) of the frame padded by ``pad`` px with
    ``BORDER_REFLECT``: the table interpolated bilinearly between its nodes is the exact integral of
    the pixels as constant squares, so the mean is exact for a fractional square (cut at the padding's
    edge beyond ``pad``) up to float64 cancellation: a frame that holds values ~1e12 times its others
    loses ~1e-3 of them, so a mean is clamped to the frame's range per channel ``[lo, hi]`` (finite)."""
    full_h, full_w = sat.shape[0] - 1, sat.shape[1] - 1
    height, width = full_h - 2 * pad, full_w - 2 * pad
    for i in numba.prange(out.shape[0]):
        for j in range(out.shape[1]):
            s = spread[i, j]
            if not s > 1.0:
                continue
            # pixel-index coordinates (centres at integers) to edge coordinates of the padded frame
            u = _mirror(map_x[i, j] + 0.5, width) + pad
            v = _mirror(map_y[i, j] + 0.5, height) + pad
            u0, u1 = max(u - 0.5 * s, 0.0), min(u + 0.5 * s, float(full_w))
            v0, v1 = max(v - 0.5 * s, 0.0), min(v + 0.5 * s, float(full_h))
            area = (u1 - u0) * (v1 - v0)
            if not area > 0.0:
                continue
            for ch in range(3):
                total = _sat_at(sat, v1, u1, ch) - _sat_at(sat, v0, u1, ch) - _sat_at(sat, v1, u0, ch) + _sat_at(sat, v0, u0, ch)
                out[i, j, ch] = min(max(total / area, lo[ch]), hi[ch])


@numba.njit(cache=True, inline="always")
def _mirror(x: float, size: int) -> float:  # pragma: no cover - compiled
    """``x`` (edge coordinates) folded into ``[0, size]`` by mirroring at the edges (period ``2 size``)."""
    period = 2.0 * size
    x = x - period * math.floor(x / period)
    return period - x if x > size else x


@numba.njit(cache=True, inline="always")
def _sat_at(sat: np.ndarray, v: float, u: float, ch: int) -> float:  # pragma: no cover - compiled
    """The summed-area table at fractional node coordinates ``(v, u)`` (rows, columns), bilinear."""
    i0 = min(int(v), sat.shape[0] - 2)
    j0 = min(int(u), sat.shape[1] - 2)
    fv, fu = v - i0, u - j0
    top = sat[i0, j0, ch] * (1.0 - fu) + sat[i0, j0 + 1, ch] * fu
    bottom = sat[i0 + 1, j0, ch] * (1.0 - fu) + sat[i0 + 1, j0 + 1, ch] * fu
    return top * (1.0 - fv) + bottom * fv


def refracted_view(rgb: np.ndarray, field: DropletField) -> np.ndarray:
    """What each pixel sees through its drop: float32 (H, W, 3), from finite ``rgb`` (the caller's check:
    a NaN would spread over every minifying pixel). Bilinear at the source point
    (:func:`cv2.remap`, ``BORDER_REFLECT``) where the drop magnifies or keeps the scale; where it
    minifies (``spread > 1``), the mean of the scene over the ``spread``-px square the pixel spans
    (a summed-area table), as a lens integrates it: a point sample there would alias, and differ
    between image sizes (issue 29: 34.4–36.0 dB between a 640 × 360 image and a 1920 × 1080 one
    downsampled, 39.8–42.6 with the mean; ``benchmarks/resolution.py``)."""
    seen = cv2.remap(rgb, field.map_x, field.map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
    widest = float(field.spread.max(initial=0.0))
    if widest > 1.0:
        pad = box_pad(widest, rgb.shape[:2])
        lo, hi = np.empty(3, np.float64), np.empty(3, np.float64)
        sat = _padded_sat(kernel_cache.read_only(rgb), reflect_index(rgb.shape[0], pad), reflect_index(rgb.shape[1], pad), lo, hi)
        _box_kernel(sat, pad, field.map_x, field.map_y, field.spread, lo, hi, seen)
    return seen


@fork_safe
@numba.njit(parallel=True, cache=True)
def _padded_sat(rgb: np.ndarray, rows: np.ndarray, cols: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:  # pragma: no cover - compiled
    """The float64 summed-area table ``(len(rows) + 1, len(cols) + 1, 3)`` of ``rgb[rows][:, cols]`` (the
    frame padded by those source indices), node ``(i, j)`` = the sum over rows < i, columns < j; and, in
    ``lo`` and ``hi`` (3,) float64, each channel's smallest and largest value over the padded frame (every
    pixel of the frame when ``rows`` and ``cols`` reach them all, as a reflected pad does).

    Two passes with the sums of one: each row's running sums (rows in parallel, each left to right), then
    each node plus the node above it (top to bottom, a row at a time): node ``(i + 1, j + 1)`` is
    ``node(i, j + 1) + run(i, j)``, as a single pass adds them, so the same bits."""
    n_rows, n_cols = rows.shape[0], cols.shape[0]
    sat = np.empty((n_rows + 1, n_cols + 1, 3), np.float64)
    sat[0] = 0.0
    row_lo = np.empty((n_rows, 3), np.float64)
    row_hi = np.empty((n_rows, 3), np.float64)
    for i in numba.prange(n_rows):
        src = rows[i]
        run0 = run1 = run2 = 0.0
        low0 = low1 = low2 = np.inf
        high0 = high1 = high2 = -np.inf
        sat[i + 1, 0] = 0.0
        for j in range(n_cols):
            c = cols[j]
            v0, v1, v2 = rgb[src, c, 0], rgb[src, c, 1], rgb[src, c, 2]
            low0, high0 = min(low0, v0), max(high0, v0)
            low1, high1 = min(low1, v1), max(high1, v1)
            low2, high2 = min(low2, v2), max(high2, v2)
            run0 += v0
            run1 += v1
            run2 += v2
            sat[i + 1, j + 1, 0] = run0
            sat[i + 1, j + 1, 1] = run1
            sat[i + 1, j + 1, 2] = run2
        row_lo[i, 0], row_lo[i, 1], row_lo[i, 2] = low0, low1, low2
        row_hi[i, 0], row_hi[i, 1], row_hi[i, 2] = high0, high1, high2
    flat = sat.reshape(n_rows + 1, (n_cols + 1) * 3)
    for i in range(1, n_rows + 1):
        above = flat[i - 1]
        here = flat[i]
        for k in range(flat.shape[1]):
            here[k] = above[k] + here[k]
    for ch in range(3):
        lo[ch] = row_lo[:, ch].min()  # n_rows >= 3: the image has a row, the padding one each side
        hi[ch] = row_hi[:, ch].max()
    return sat


def water_droplets(
    rgb: np.ndarray,
    scale: float,
    radius: float,
    strength: float,
    blur_sigma: float,
    blur_kernel: int,
    rng: np.random.Generator,
    *,
    specular: float = SPECULAR_INTENSITY,
    rim: float = RIM_DARKENING,
) -> np.ndarray:
    """Water drops on the lens over linear-light ``rgb`` (see the module docstring for the model).

    Args:
        rgb: float32 (H, W, 3) linear light, unclamped, finite; not modified.
        scale: largest-layer cells across the shorter side (1/image), [0, 100].
        radius: largest drop radius / cell half-size, [0, 1].
        strength: refraction strength (dimensionless), [0, 5].
        blur_sigma: in-drop Gaussian σ in px, [0, 20].
        blur_kernel: odd in-drop kernel side in px, [1, 51].
        rng: source of the drop placement.
        specular: Phong ``k_s`` in linear light (0 disables the highlights).
        rim: weight of the Fresnel loss towards the rim, in [0, 1] (1 = physical, 0 = lossless).

    Returns:
        A new float32 (H, W, 3) array, equal to ``rgb`` bit for bit outside the drops.
    """
    # C-contiguous: the kernels then see the one array layout `spacedg kernels` compiled (a strided view,
    # a cropped or channel-sliced image, compiled two more specialisations: ~12 s in every process)
    rgb = np.ascontiguousarray(check_linear_rgb(rgb, NAME))
    params = _check_params(scale, radius, strength, blur_sigma, blur_kernel)
    if not (math.isfinite(specular) and specular >= 0.0):
        raise ParameterError(f"{NAME}: specular must be a finite number >= 0 (linear light), got {specular!r}")
    if not (math.isfinite(rim) and 0.0 <= rim <= 1.0):
        raise ParameterError(f"{NAME}: rim must be a number in [0, 1] (weight of the Fresnel rim loss), got {rim!r}")
    if not np.isfinite(rgb).all():
        bad = np.argwhere(~np.isfinite(rgb))
        raise InvalidDataError(
            f"{NAME}: rgb has {len(bad)} non-finite value(s) (NaN or inf), first at (row, col, channel) "
            f"{tuple(int(v) for v in bad[0])}; fix the render (linear light must be finite)"
        )
    out = rgb.copy()
    if params["scale"] == 0.0 or params["radius"] == 0.0:
        return out
    field = droplet_field(rgb.shape[:2], params["scale"], params["radius"], params["strength"], rng)
    seen = refracted_view(rgb, field)
    k, sigma = params["blur_kernel"], params["blur_sigma"]
    if k > 1 and sigma > 0.0:
        seen = cv2.GaussianBlur(seen, (k, k), sigma, borderType=cv2.BORDER_REFLECT)
    _composite_kernel(kernel_cache.read_only(rgb), seen, field.alpha, field.highlight, float(specular), field.transmission, float(rim), out)
    return out


def apply(rgb: np.ndarray, aux: Mapping[str, np.ndarray], params: Mapping[str, Any], rng: np.random.Generator) -> np.ndarray:
    """Linear-stage ``apply``: ``params`` = scale, radius, strength, blur_sigma, blur_kernel; ``aux`` unused."""
    p = SPEC.validate_params(params)
    return water_droplets(rgb, p["scale"], p["radius"], p["strength"], p["blur_sigma"], p["blur_kernel"], rng)


def apply_torch(rgb: Any, aux: Mapping[str, Any], params: Mapping[str, Any], rng: np.random.Generator) -> Any:
    """Device twin of :func:`apply` on torch tensors (:mod:`spacedg.plugins.degradations.device`, imported here lazily)."""
    import torch

    from spacedg.plugins.degradations import device

    p = _check_params(**SPEC.validate_params(params))
    if not bool(torch.isfinite(rgb).all()):
        raise InvalidDataError(f"{NAME}: rgb has non-finite values; fix the render (linear light must be finite)")
    if p["scale"] == 0.0 or p["radius"] == 0.0:
        return rgb.clone()
    drops = _draw_drops(tuple(rgb.shape[:2]), p["scale"], p["radius"], rng)  # the CPU path's numbers, from the same rng
    return device.droplet_composite_torch(
        rgb, drops, refraction_reach(tuple(rgb.shape[:2]), p["strength"]), WATER_INDEX, p["blur_sigma"],
        p["blur_kernel"], specular=SPECULAR_INTENSITY, rim=RIM_DARKENING,
        edge=EDGE_WIDTH, light=LIGHT_DIRECTION, shininess_log2=SHININESS_LOG2,
    )


def _preset(radius: tuple[float, float], strength: tuple[float, float], sigma: tuple[float, float], kernel: int) -> dict[str, ParamRange]:
    """One preset: scale in [2.5, 4]; the blur's pixels stated at the reference image size (``per_size``)."""
    return {
        "scale": ParamRange(2.5, 4.0), "radius": ParamRange(*radius), "strength": ParamRange(*strength),
        "blur_sigma": ParamRange(*sigma, per_size=True), "blur_kernel": ParamRange(kernel, kernel, per_size=True),
    }


SPEC = DegradationSpec(
    name=NAME, category=Category.METEOROLOGICAL, stage=Stage.LINEAR,
    params=(SCALE, RADIUS, STRENGTH, BLUR_SIGMA, BLUR_KERNEL),
    presets={
        "bench": _preset((0.25, 0.75), (0.3, 0.5), (2.0, 2.5), 9),
        "1": _preset((0.15, 0.25), (0.1, 0.2), (0.5, 1.0), 5),
        "2": _preset((0.25, 0.4), (0.2, 0.3), (1.0, 1.5), 7),
        "3": _preset((0.35, 0.55), (0.3, 0.4), (1.5, 2.0), 9),
        "4": _preset((0.5, 0.75), (0.4, 0.5), (2.0, 2.5), 9),
        "5": _preset((0.7, 0.9), (0.5, 0.7), (2.5, 3.0), 11),
    },
    apply=apply,
    apply_torch=apply_torch,
    needs=frozenset(),
    description=(
        "Drops on the lens: 3-layer hemispherical height map (scale = cells across the shorter side, radius = "
        "fraction of the half-cell); each drop shows the scene behind it flipped and minified (refraction "
        "p - strength*F*n_xy) with water's Fresnel transmission, in-drop Gaussian blur (blur_sigma px, "
        "odd blur_kernel px) and a Phong highlight, soft edges; untouched outside drops; adds no light but the highlight."
    ),
    order=20.0,
)

spacedg_register_degradations = registering(SPEC)

"""Compiled (numba) tile binning and compositing, the CPU production path.

Pipeline (see :func:`rasterize`):

1. one ``argsort`` of the visible Gaussians by camera depth;
2. counting-sort binning into 16×16 tiles in that order, so every tile's list comes out
   already depth-sorted (no 64-bit keys, no per-tile sort). With ``tight`` binning a tile is
   kept only if the Gaussian's ``alpha >= f`` ellipse (its alpha floor, 1/255 when sharp) reaches one of its pixel centres;
3. compositing, parallel over tiles, in a kernel compiled once per combination of requested
   outputs (the flags are constants, so unused planes cost nothing): each tile keeps one flat
   state buffer (transmittance, whose sign is the live flag, and the accumulators) for its 256
   pixels and walks its depth-ordered list front to back in batches of 32 Gaussians, first
   gathering a batch's parameters into a small contiguous buffer (independent loads, so their
   cache misses overlap), then updating for every Gaussian only the tile rows its footprint
   covers, 16 pixels at a time with branch-free selects and a polynomial exp so LLVM
   vectorises the row. A tile stops after a batch that left all its pixels saturated.

Compositing rules (3DGS / gsplat): pixel centres at (j + ½, i + ½); ``σ = ½(a dx² + c dy²)
+ b dx dy``; ``α = min(alpha_max, o·e^(−σ))``; skip ``σ < 0`` or ``α < f`` (the Gaussian's alpha floor); stop before the
Gaussian that would take transmittance ``T`` to ``<= 1e-4``. Depth outputs: expected depth
``Σ wᵢ zᵢ / Σ wᵢ`` and median depth = z of the last Gaussian added while ``T > ½`` before it;
the instance id is that Gaussian's id where the pixel's ``T`` ends ``<= ½``, else -1.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from spacedg.render.coarse_cpu import bilinear_mix
from spacedg.render.project_cpu import AMIN, CA, CB, CBL, CC, CG, COC, CR, DEPTH, OPA, PX, PY, RADY
from spacedg.render import kernel_cache  # numba's cache entries checked before any kernel here compiles
from spacedg.render.threads import fork_safe

@numba.njit(cache=True, inline="always")
def _exp_neg(s):
    """``e^(−s)`` for s in [0, 8] as a polynomial (vectorisable; relative error < 3e-6).

    ``e^(−s) = (e^(−s/16))^16`` with a degree-6 Taylor polynomial on [0, ½]; inputs are
    clamped to [0, 8] by the caller (beyond 8, ``o e^(−σ) < f`` for every ``o / f <= 255``: skipped anyway).
    """
    x = s * np.float32(0.0625)
    p = np.float32(1.0) - x * (
        np.float32(1.0) - x * (
            np.float32(0.5) - x * (
                np.float32(1.0 / 6.0) - x * (
                    np.float32(1.0 / 24.0) - x * (np.float32(1.0 / 120.0) - x * np.float32(1.0 / 720.0))
                )
            )
        )
    )
    p = p * p
    p = p * p
    p = p * p
    return p * p


@numba.njit(cache=True, inline="always")
def _f32_constants(alpha_max):
    """The compositors' float32 constants: ``alpha_max``, the stop transmittance 1e-4, ½, 0 and 1."""
    return np.float32(alpha_max), np.float32(1e-4), np.float32(0.5), np.float32(0.0), np.float32(1.0)


@numba.njit(cache=True, inline="always")
def _tile_span(offsets, tile, tiles_x):
    """Tile ``tile``'s list range ``start, end`` and the pixel ``x0, y0`` of its top-left corner."""
    ty = tile // tiles_x
    tx = tile - ty * tiles_x
    return offsets[tile], offsets[tile + 1], tx * 16, ty * 16


@numba.njit(cache=True, inline="always")
def _tile_state(planes, t_planes):
    """A tile's flat state buffer: ``planes`` planes of 256 float32, the first ``t_planes`` at 1, the rest 0."""
    state = np.zeros(256 * planes, np.float32)
    state[: 256 * t_planes] = 1.0
    return state


@numba.njit(cache=True, inline="always")
def _row_span(gy, ry):
    """Tile rows ``[r0, r1)`` within ``ry`` of a footprint centred ``gy`` rows below the first pixel centre."""
    return max(int(math.ceil(gy - ry)), 0), min(int(math.floor(gy + ry)) + 1, 16)


@numba.njit(cache=True, inline="always")
def _pair_rows(packed, g, x0, y0):
    """Gaussian ``g``'s mean relative to the first pixel centre of the tile at ``x0, y0`` and the tile
    rows ``[r0, r1)`` its footprint reaches (:func:`_row_span`)."""
    gx = packed[g, PX] - np.float32(x0 + 0.5)
    gy = packed[g, PY] - np.float32(y0 + 0.5)
    r0, r1 = _row_span(gy, packed[g, RADY])
    return gx, gy, r0, r1


@numba.njit(cache=True, inline="always")
def _conic(packed, g):
    """Gaussian ``g``'s halved conic ``a/2, b, c/2``, its opacity and its alpha floor (float32)."""
    return np.float32(0.5) * packed[g, CA], packed[g, CB], np.float32(0.5) * packed[g, CC], packed[g, OPA], packed[g, AMIN]


@numba.njit(cache=True, inline="always")
def _row_terms(row, gy, cb, cc):
    """One tile row's share of ``σ``: ``b dy`` and ``c/2 dy²``, and the row's first index into a state plane."""
    dy = np.float32(row) - gy
    return cb * dy, cc * dy * dy, np.uint64(row * 16)


@numba.njit(cache=True, inline="always")
def _gauss_alpha(col, gx, ca, bdy, cdy, opa, amin, amax, zero):
    """A Gaussian's alpha at column ``col`` of a row (:func:`_row_terms`): ``min(alpha_max, o e^(−σ))``,
    0 where ``σ < 0`` or below the alpha floor ``amin``. Branch-free, so LLVM vectorises the row.

    ``zero`` (float32 0) comes from the caller: the raster kernel's own, hoisted out of its tile loop,
    keeps it as fast as when this was written out in the kernel (a literal here costs it about 2 %)."""
    return _alpha_at(np.float32(col) - gx, ca, bdy, cdy, opa, amin, amax, zero)


@numba.njit(cache=True, inline="always")
def _alpha_at(dx, ca, bdy, cdy, opa, amin, amax, zero):
    """:func:`_gauss_alpha` at the offset ``dx`` from the mean along the row."""
    sigma = ca * dx * dx + bdy * dx + cdy
    alpha = min(amax, opa * _exp_neg(min(max(sigma, zero), np.float32(8.0))))
    return alpha if (sigma >= zero and alpha >= amin) else zero


@numba.njit(cache=True, inline="always")
def _add_rgb(state, q, w, r, g, b):
    """Add ``w`` times a colour into three consecutive state planes starting at index ``q``."""
    state[q] += w * r
    state[q + np.uint64(256)] += w * g
    state[q + np.uint64(512)] += w * b


@numba.njit(cache=True, inline="always")
def _accumulate(state, p, w, rgb_q, r, g, b, d_q, z, want_color, want_depth):
    """Add a Gaussian's weight ``w`` at pixel ``p``: its colour into the planes from ``rgb_q``, ``w z`` into ``d_q``."""
    if want_color:
        _add_rgb(state, p + rgb_q, w, r, g, b)
    if want_depth:
        state[p + d_q] += w * z


@numba.njit(cache=True, inline="always")
def _put_rgb(out, py, px, state, q):
    """Write the three consecutive state planes from index ``q`` into pixel ``(py, px)`` of an (H, W, 3) image."""
    out[py, px, 0] = state[q]
    out[py, px, 1] = state[q + 256]
    out[py, px, 2] = state[q + 512]


@numba.njit(cache=True, inline="always")
def _put_pixel(state, p, py, px, t, rgb_q, d_q, out_alpha, out_rgb, out_depth, want_color, want_depth, zero, one):
    """Write one pixel of a finished tile: alpha ``1 − t`` (``t``: its final transmittance), the colour
    planes from ``rgb_q`` and the expected depth ``Σ w z / Σ w`` (plane ``d_q``, 0 where alpha is 0)."""
    a = one - t
    out_alpha[py, px] = a
    if want_color:
        _put_rgb(out_rgb, py, px, state, rgb_q + p)
    if want_depth:
        out_depth[py, px] = state[d_q + p] / a if a > zero else zero


@numba.njit(cache=True, inline="always")
def _edge_min(a, b, c, fixed, lo, hi, fixed_is_x):
    """Smallest ``σ`` on one tile edge: ``dx`` (or ``dy``) = ``fixed``, the other in [lo, hi]."""
    if fixed_is_x:
        dy = min(max(-b * fixed / c, lo), hi)
        return 0.5 * (a * fixed * fixed + c * dy * dy) + b * fixed * dy
    dx = min(max(-b * fixed / a, lo), hi)
    return 0.5 * (a * dx * dx + c * fixed * fixed) + b * dx * fixed


@numba.njit(cache=True, inline="always")
def _tile_reached(a, b, c, limit, x_lo, x_hi, y_lo, y_hi):
    """Whether ``σ <= limit`` somewhere on the rectangle ``[x_lo, x_hi] × [y_lo, y_hi]`` (relative to the
    mean) that does not hold the mean: its smallest ``σ`` is on one of the four edges."""
    best = min(
        min(_edge_min(a, b, c, x_lo, y_lo, y_hi, True), _edge_min(a, b, c, x_hi, y_lo, y_hi, True)),
        min(_edge_min(a, b, c, y_lo, x_lo, x_hi, False), _edge_min(a, b, c, y_hi, x_lo, x_hi, False)),
    )
    return best <= limit


@numba.njit(cache=True, inline="always")
def _strip_reach(a, b, c, det, limit, x_half, y_ext, y_lo, y_hi):
    """The x-extent ``[x_min, x_max]`` of the ellipse ``σ <= limit`` inside the strip ``y ∈ [y_lo, y_hi]``
    (coordinates relative to the mean; ``x_min > x_max`` when the strip misses it).

    On the ellipse ``x = (−b y ± sqrt(2 a limit − det y²)) / a``: the + branch is concave in ``y`` with
    its top at ``y = −b x_half / c`` (``x_half``: the ellipse's exact x half-extent), the − branch
    convex with its bottom at ``+b x_half / c``; each is evaluated at its optimum clamped into the strip."""
    lo = max(y_lo, -y_ext)
    hi = min(y_hi, y_ext)
    if lo > hi:
        return math.inf, -math.inf
    y_top = min(max(-b * x_half / c, lo), hi)
    y_bottom = min(max(b * x_half / c, lo), hi)
    x_max = (-b * y_top + math.sqrt(max(2.0 * a * limit - det * y_top * y_top, 0.0))) / a
    x_min = (-b * y_bottom - math.sqrt(max(2.0 * a * limit - det * y_bottom * y_bottom, 0.0))) / a
    return x_min, x_max


@numba.njit(cache=True, inline="always")
def _conic_limits(packed, g):
    """Gaussian ``g``'s mean ``u, v``, conic ``a, b, c`` (float64), the binning limit ``ln(o / f) + 1e-3`` on ``σ``
    and whether its ellipse is well conditioned (``det > 1e-9 a c``, ``a, c > 0``, limit > 0)."""
    u, v = float(packed[g, PX]), float(packed[g, PY])
    a, b, c = float(packed[g, CA]), float(packed[g, CB]), float(packed[g, CC])
    limit = math.log(max(float(packed[g, OPA]), 1e-30) / float(packed[g, AMIN])) + 1e-3
    det = a * c - b * b
    return u, v, a, b, c, limit, det, det > 1e-9 * a * c and a > 0.0 and c > 0.0 and limit > 0.0


@numba.njit(cache=True, inline="always")
def _tight_row(pair_tile, counts, n_pairs, g_row, a, b, c, limit, det, box, x_half, y_ext, u, v, tx0, tx1, tiles_x, width,
               y_lo, y_hi):
    """Append the tiles ``[tx0, tx1)`` of tile row ``g_row`` that the ellipse ``σ <= limit`` reaches; returns ``n_pairs``.

    A well-conditioned ellipse (``box``) is first reduced to its x-extent inside the row's strip
    (:func:`_strip_reach`): tiles clear of it by a margin (1e-6 relative, far above the rounding
    error) are dropped, tiles overlapping it by that margin kept, and only the rest take the exact
    edge test (:func:`_tile_reached`), so the kept tiles are exactly those of the edge test alone.
    ``x_half``: the ellipse's exact x half-extent; ``y_ext``: its y half-extent widened by the margin."""
    x_lo_keep, x_hi_keep, x_lo_drop, x_hi_drop = math.inf, -math.inf, -math.inf, math.inf
    if box:
        x_min, x_max = _strip_reach(a, b, c, det, limit, x_half, y_ext, y_lo, y_hi)
        margin = 1e-6 * x_half + 1e-6
        x_lo_drop, x_hi_drop = x_min - margin, x_max + margin
        x_lo_keep, x_hi_keep = x_min + margin, x_max - margin
    inside_y = y_lo <= 0.0 <= y_hi
    for tx in range(tx0, tx1):
        x_lo = tx * 16 + 0.5 - u
        x_hi = min(tx * 16 + 16, width) - 0.5 - u
        if not (inside_y and x_lo <= 0.0 <= x_hi) and a > 0.0 and c > 0.0:
            if x_hi < x_lo_drop or x_lo > x_hi_drop:
                continue
            if not (x_hi >= x_lo_keep and x_lo <= x_hi_keep and x_lo_keep <= x_hi_keep):
                if not _tile_reached(a, b, c, limit, x_lo, x_hi, y_lo, y_hi):
                    continue
        t = g_row * tiles_x + tx
        pair_tile[n_pairs] = t
        counts[t + 1] += 1
        n_pairs += 1
    return n_pairs


@numba.njit(cache=True)
def bin_tiles(order, rects, packed, tiles_x, tiles_y, width, height, tight, capacity):  # pragma: no cover - compiled
    """Counting-sort (Gaussian, tile) pairs by tile, keeping depth order inside each tile.

    With ``tight``, a tile of a footprint's bounding rectangle (when that rectangle spans at
    least 2×2 tiles; smaller ones are kept whole) is dropped unless the ``α >= f``
    ellipse ``σ <= ln(o / f)`` reaches the rectangle of the tile's pixel centres: the minimum
    of ``σ`` over that rectangle is 0 if the mean is inside, else the smallest clamped 1-D
    minimum along its four edges (decided per tile row by :func:`_tight_row`, which gives the
    same tiles). Dropped tiles would have composited nothing.

    Two passes: the kept tiles of every listed Gaussian in index order (its parameters read
    sequentially) with each tile's count, then, after a prefix sum, every Gaussian's index
    scattered into its tiles' lists in depth order. A Gaussian listed twice in ``order`` is binned once.

    Args:
        order: visible Gaussian indices sorted by depth (front to back).
        rects: (N, 4) tile rectangles ``x0, x1, y0, y1`` (exclusive ends).
        capacity: an upper bound on the number of pairs (sum of rectangle areas).

    Returns:
        ``(offsets, gauss)``: offsets (tiles+1,) int64 into gauss (pairs,) int32.
    """
    n_tiles, n = tiles_x * tiles_y, rects.shape[0]
    listed = np.zeros(n, np.bool_)
    for k in range(order.shape[0]):
        listed[order[k]] = True
    pair_tile = np.empty(capacity, np.int32)
    first = np.zeros(n + 1, np.int64)  # Gaussian g's kept tiles are pair_tile[first[g]:first[g + 1]]
    counts = np.zeros(n_tiles + 1, np.int64)
    n_pairs = 0
    for g in range(n):  # index order: the parameters are read sequentially
        first[g] = n_pairs
        if not listed[g]:
            continue
        tx0, tx1, ty0, ty1 = rects[g, 0], rects[g, 1], rects[g, 2], rects[g, 3]
        if not (tight and tx1 - tx0 >= 2 and ty1 - ty0 >= 2):
            for ty in range(ty0, ty1):
                for tx in range(tx0, tx1):
                    t = ty * tiles_x + tx
                    pair_tile[n_pairs] = t
                    counts[t + 1] += 1
                    n_pairs += 1
            continue
        u, v, a, b, c, limit, det, box = _conic_limits(packed, g)
        x_half = math.sqrt(2.0 * limit * c / det) if box else 0.0
        y_ext = math.sqrt(2.0 * limit * a / det) * (1.0 + 1e-6) + 1e-6 if box else 0.0
        for ty in range(ty0, ty1):
            y_lo = ty * 16 + 0.5 - v
            y_hi = min(ty * 16 + 16, height) - 0.5 - v
            n_pairs = _tight_row(pair_tile, counts, n_pairs, ty, a, b, c, limit, det, box, x_half, y_ext, u, v,
                                 tx0, tx1, tiles_x, width, y_lo, y_hi)
    first[n] = n_pairs
    for t in range(n_tiles):
        counts[t + 1] += counts[t]
    cursor = counts[:n_tiles].copy()
    gauss = np.empty(n_pairs, np.int32)
    for k in range(order.shape[0]):  # depth order: each tile's list comes out front to back
        g = order[k]
        if not listed[g]:  # a repeat in order: binned once
            continue
        listed[g] = False
        for p in range(first[g], first[g + 1]):
            t = pair_tile[p]
            gauss[cursor[t]] = g
            cursor[t] += 1
    return counts, gauss


# offsets of the per-pixel state planes inside one tile's flat buffer (256 floats each); the
# transmittance plane's sign is the live flag (a saturated pixel keeps -T)
_T, _R, _G, _B, _D = (np.uint64(256 * k) for k in range(5))
#: Gaussians gathered per batch before compositing them (also the saturation-check period)
_BATCH = 32
# columns of the per-batch gathered parameters (one row of _BATCH floats each)
_GX, _GY, _CA, _CB, _CC, _OPA, _AMIN, _CR, _CG, _CBL, _Z = range(11)


@numba.njit(cache=True, inline="always")
def _composite_lane(state, last, p, alpha, at, cr, cg, cbl, z, t_min, half, zero, one, want_color, want_depth, want_ids):
    """Composite one Gaussian of alpha ``alpha`` (list position ``at``) over state index ``p``: its weight
    ``alpha·T`` into the colour and depth planes while ``T`` stays above ``t_min``, the median hit into
    ``last``, the new ``T`` (negative once saturated: a dead pixel)."""
    t_before = state[p]
    t_after = t_before * (one - alpha)
    take = t_after > t_min  # false for a saturated pixel (negative T)
    w = alpha * t_before if take else zero
    _accumulate(state, p, w, _R, cr, cg, cbl, _D, z, want_color, want_depth)
    if want_ids:
        hit = w > zero and t_before > half
        last[p] = at if hit else last[p]
    state[p] = t_after if take else -abs(t_before)


@numba.njit(cache=True, inline="always")
def _median_hit(at, gauss, start, packed, instance_ids, t, half, zero):
    """``(median depth, id)`` of a pixel whose median Gaussian is at list position ``at`` of the tile's list
    from ``start`` (−1: none: 0 and −1) and whose final transmittance is ``t``: the id only where the pixel
    is covered (``t <= ½``)."""
    if at < 0:
        return zero, np.int32(-1)
    g = gauss[start + at]
    return packed[g, DEPTH], np.int32(np.float32(instance_ids[g])) if t <= half else np.int32(-1)


def _make_composite(want_color: bool, want_depth: bool, want_ids: bool):
    """The compositing kernel with the output flags compiled in as constants (one specialisation each).

    Each specialisation gets its own qualified name, so its on-disk numba cache has its own index
    file: numba names a cache by qualified name and line, and two processes compiling *different*
    specialisations of one shared index at once (two test lanes, DataLoader workers, ``qa build
    --jobs``) could each pick the same data file for their own entry, leaving an index entry that
    loads the other specialisation (a colour render without colour, seen once in CI). Every spacedg
    kernel's cache now refuses such an entry (:mod:`spacedg.render.kernel_cache`: a recompile, not
    a wrong result); the separate names still spare the eight specialisations that recompile."""

    def composite_tiles(
        offsets, gauss, packed, instance_ids, width, height, tiles_x, alpha_max,
        out_rgb, out_alpha, out_depth, out_median, out_ids, coarse, samples, sample_median, sample_ids,
    ):  # pragma: no cover - compiled; covered through render() and the oracle tests
        n_tiles = offsets.shape[0] - 1
        amax, t_min, half, zero, one = _f32_constants(alpha_max)
        coarsening = coarse.shape[0] > 0
        for tile in numba.prange(n_tiles):
            start, end, x0, y0 = _tile_span(offsets, tile, tiles_x)
            state = _tile_state(5, 1)
            # a sampled tile: 8 × 8 samples at the centres of its 2 × 2 blocks, sample (r, c) at state index
            # 8r + c (two sample rows per 16-lane row, so the row loop stays 16 lanes wide)
            sampled = coarsening and coarse[tile] != 0
            if sampled:
                for p in range(64, 256):
                    state[p] = zero  # not a sample: dead from the start
            last = np.full(256 if want_ids else 1, -1, np.int32)  # list position of the median Gaussian
            par = np.empty((11, _BATCH), np.float32)
            rows = np.empty((2, _BATCH), np.int64)
            for b0 in range(start, end, _BATCH):
                nb = min(_BATCH, end - b0)
                for j in range(nb):  # gather: independent loads, so their cache misses overlap
                    g = gauss[b0 + j]
                    par[_GX, j], par[_GY, j], rows[0, j], rows[1, j] = _pair_rows(packed, g, x0, y0)
                    if sampled:  # sample rows r (at 2r + ½ rows below the first pixel centre) within the footprint
                        ry = packed[g, RADY]
                        rows[0, j] = max(int(math.ceil((par[_GY, j] - ry - half) * half)), 0)
                        rows[1, j] = min(int(math.floor((par[_GY, j] + ry - half) * half)) + 1, 8)
                    par[_CA, j], par[_CB, j], par[_CC, j], par[_OPA, j], par[_AMIN, j] = _conic(packed, g)
                    if want_color:
                        par[_CR, j] = packed[g, CR]
                        par[_CG, j] = packed[g, CG]
                        par[_CBL, j] = packed[g, CBL]
                    if want_depth or want_ids:
                        par[_Z, j] = packed[g, DEPTH]
                for j in range(nb):
                    gx, gy = par[_GX, j], par[_GY, j]
                    ca, cb, cc = par[_CA, j], par[_CB, j], par[_CC, j]
                    opa, amin = par[_OPA, j], par[_AMIN, j]
                    cr, cg, cbl = par[_CR, j], par[_CG, j], par[_CBL, j]
                    z = par[_Z, j]
                    at = np.int32(b0 + j - start)
                    if sampled:
                        for pair in range(rows[0, j] // 2, (rows[1, j] + 1) // 2):
                            dy_top = np.float32(4 * pair) + half - gy  # sample rows 2·pair and 2·pair + 1
                            base = np.uint64(pair * 16)
                            for lane in range(16):
                                p = base + np.uint64(lane)
                                dy = dy_top if lane < 8 else dy_top + np.float32(2.0)
                                dx = np.float32(2 * (lane & 7)) + half - gx
                                alpha = _alpha_at(dx, ca, cb * dy, cc * dy * dy, opa, amin, amax, zero)
                                _composite_lane(state, last, p, alpha, at, cr, cg, cbl, z, t_min, half, zero, one,
                                                want_color, want_depth, want_ids)
                        continue
                    for row in range(rows[0, j], rows[1, j]):
                        bdy, cdy, base = _row_terms(row, gy, cb, cc)
                        for col in range(16):
                            p = base + np.uint64(col)
                            alpha = _gauss_alpha(col, gx, ca, bdy, cdy, opa, amin, amax, zero)
                            _composite_lane(state, last, p, alpha, at, cr, cg, cbl, z, t_min, half, zero, one,
                                            want_color, want_depth, want_ids)
                if nb == _BATCH:
                    live = 0
                    for p in range(256):
                        live += 1 if state[p] > zero else 0
                    if live == 0:
                        break
            if sampled:  # the samples, for upsample_sampled_tiles: transmittance, colour, Σw·z, median depth, id
                for k in range(64):
                    p = k
                    t = abs(state[p])
                    samples[tile, k, 0] = t
                    if want_color:
                        samples[tile, k, 1] = state[p + 256]
                        samples[tile, k, 2] = state[p + 512]
                        samples[tile, k, 3] = state[p + 768]
                    if want_depth:
                        samples[tile, k, 4] = state[p + 1024]
                    if want_ids:
                        sample_median[tile, k], sample_ids[tile, k] = _median_hit(last[p], gauss, start, packed, instance_ids, t, half, zero)
                continue
            for row in range(min(16, height - y0)):
                for col in range(min(16, width - x0)):
                    p = row * 16 + col
                    py, px = y0 + row, x0 + col
                    t = abs(state[p])
                    _put_pixel(state, p, py, px, t, 256, 1024, out_alpha, out_rgb, out_depth, want_color, want_depth, zero, one)
                    if want_ids:
                        out_median[py, px], out_ids[py, px] = _median_hit(last[p], gauss, start, packed, instance_ids, t, half, zero)

    composite_tiles.__qualname__ = f"composite_tiles_rgb{int(want_color)}_depth{int(want_depth)}_ids{int(want_ids)}"
    return fork_safe(numba.njit(parallel=True, fastmath=True, cache=True)(composite_tiles))


_COMPOSITE_KERNELS: dict[tuple[bool, bool, bool], object] = {}


def composite(
    offsets, gauss, packed, instance_ids, width, height, tiles_x, alpha_max,
    want_color, want_depth, want_ids,
    out_rgb, out_alpha, out_depth, out_median, out_ids, coarse=None,
):
    """Composite every tile front to back into the output images (in place).

    ``coarse`` (one uint8 per tile, optional): the marked tiles are composited at the 8 × 8 centres
    of their 2 × 2 pixel blocks only and their pixels upsampled from those samples
    (:func:`upsample_sampled_tiles`), for tiles whose every Gaussian is widely blurred (defocus).

    Per tile: one flat float32 buffer holds its state planes (transmittance, whose sign is the
    live flag, r, g, b, Σw·z; with ids, an int32 plane holds the list position of each pixel's
    median Gaussian, whose depth and id are read at the end), indexed with unsigned integers (signed
    indices make numba emit wraparound checks that stop LLVM from vectorising the row). The
    tile's list is walked in batches of 32: each batch's parameters are first gathered into a
    small contiguous buffer, then composited; the tile stops after a batch that left every
    pixel saturated. The output flags select a specialisation compiled with them as constants.
    """
    key = (bool(want_color), bool(want_depth), bool(want_ids))
    kernel = _COMPOSITE_KERNELS.get(key)
    if kernel is None:
        kernel = _COMPOSITE_KERNELS[key] = _make_composite(*key)
    if coarse is None:  # nothing sampled: the kernel writes no sample
        tiles, (samples, sample_median, sample_ids) = _NO_TILES, _NO_SAMPLES
    else:
        n_tiles = offsets.shape[0] - 1
        tiles = coarse
        samples = np.empty((n_tiles, 64, 5), np.float32)
        sample_median = np.empty((n_tiles, 64), np.float32)
        sample_ids = np.empty((n_tiles, 64), np.int32)
    kernel(
        offsets, gauss, packed, kernel_cache.read_only(instance_ids), width, height, tiles_x, alpha_max,
        out_rgb, out_alpha, out_depth, out_median, out_ids, tiles, samples, sample_median, sample_ids,
    )
    if coarse is not None:
        upsample_sampled_tiles(
            coarse, samples, sample_median, sample_ids, tiles_x, width, height,
            out_rgb, out_alpha, out_depth, out_median, out_ids, want_color, want_depth, want_ids,
        )


#: The sampled tiles' outputs of a view without sampled tiles.
_NO_SAMPLES = (np.empty((0, 64, 5), np.float32), np.empty((0, 64), np.float32), np.empty((0, 64), np.int32))
#: ``coarse`` of a composite at full resolution everywhere.
_NO_TILES = np.zeros(0, np.uint8)


@numba.njit(cache=True)
def sampled_tiles(offsets, gauss, packed, min_coc):  # pragma: no cover - compiled
    """uint8 per tile: 1 where the tile lists a Gaussian and every Gaussian it lists has a circle of
    confusion (``packed[:, COC]``, px) of at least ``min_coc`` (its image has no detail finer than a
    Gaussian of that standard deviation: :func:`composite` may sample it every 2 px)."""
    n_tiles = offsets.shape[0] - 1
    out = np.zeros(n_tiles, np.uint8)
    for tile in range(n_tiles):
        start, end = offsets[tile], offsets[tile + 1]
        wide = end > start
        for k in range(start, end):
            if not packed[gauss[k], COC] >= min_coc:
                wide = False
                break
        out[tile] = 1 if wide else 0
    return out


@numba.njit(cache=True, inline="always")
def _block_value(coarse, samples, tiles_x, width, height, block_y, block_x, out_rgb, out_alpha, out_depth, grid, gi, gj,
                 want_color, want_depth):
    """``grid[gi, gj] = (α, r, g, b, Σw·z)`` of the 2 × 2 block ``(block_y, block_x)`` of the image (clamped
    into it): a sampled tile's sample there, else the mean of the block's composited pixels in the image."""
    blocks_y, blocks_x = (height + 1) // 2, (width + 1) // 2
    by = min(max(block_y, 0), blocks_y - 1)
    bx = min(max(block_x, 0), blocks_x - 1)
    owner = (by // 8) * tiles_x + bx // 8
    if coarse[owner]:  # the sample of that block: (α, r, g, b, Σw·z), the channels asked for
        k = (by % 8) * 8 + bx % 8
        grid[gi, gj, 0] = np.float32(1.0) - samples[owner, k, 0]
        if want_color:
            for c in range(1, 4):
                grid[gi, gj, c] = samples[owner, k, c]
        if want_depth:
            grid[gi, gj, 4] = samples[owner, k, 4]
        return
    for c in range(5):
        grid[gi, gj, c] = np.float32(0.0)
    n = 0
    for py in range(2 * by, min(2 * by + 2, height)):
        for px in range(2 * bx, min(2 * bx + 2, width)):
            a = out_alpha[py, px]
            grid[gi, gj, 0] += a
            if want_color:
                for c in range(3):
                    grid[gi, gj, 1 + c] += out_rgb[py, px, c]
            if want_depth:
                grid[gi, gj, 4] += out_depth[py, px] * a
            n += 1
    inv = np.float32(1.0) / np.float32(n)
    for c in range(5):
        grid[gi, gj, c] *= inv


@numba.njit(cache=True, inline="always")
def _bilinear_at(grid, i0, j0, c, vy, wy, vx, wx):
    """Channel ``c`` of ``grid`` between rows ``i0, i0 + 1`` (weights ``vy, wy``) and columns ``j0, j0 + 1``
    (``vx, wx``), rows first (:func:`spacedg.render.coarse_cpu.bilinear_mix`)."""
    return bilinear_mix(grid[i0, j0, c], grid[i0 + 1, j0, c], grid[i0, j0 + 1, c], grid[i0 + 1, j0 + 1, c], vy, wy, vx, wx)


@fork_safe
@numba.njit(parallel=True, cache=True)
def upsample_sampled_tiles(
    coarse, samples, sample_median, sample_ids, tiles_x, width, height,
    out_rgb, out_alpha, out_depth, out_median, out_ids, want_color, want_depth, want_ids,
):  # pragma: no cover - compiled
    """The pixels of the sampled tiles (:func:`sampled_tiles`), from their 8 × 8 block samples and a ring of
    the blocks around them (a sampled neighbour's samples, else the mean of its composited block; the
    image's edge blocks repeated past it, also for the tile's own samples there): alpha, colour and
    ``Σw·z`` bilinearly (block centres at ``2b + 1`` px; the taps of :func:`spacedg.render.defocus.upsample`,
    which mixes decoded linear light where this mixes the colour as composited, sRGB-encoded: under
    4 px of blur the two differ by far less than the sampling), depth ``Σw·z / α`` (0 where α is 0),
    median depth and ids those of the pixel's own block."""
    one, zero = np.float32(1.0), np.float32(0.0)
    for tile in numba.prange(coarse.shape[0]):
        if not coarse[tile]:
            continue
        ty, tx = tile // tiles_x, tile % tiles_x
        grid = np.zeros((10, 10, 5), np.float32)  # the tile's 8 × 8 blocks and the ring around them
        for gi in range(10):
            for gj in range(10):  # its own sample, a neighbour's block, or past the image's edge its edge block
                _block_value(coarse, samples, tiles_x, width, height, ty * 8 + gi - 1, tx * 8 + gj - 1, out_rgb, out_alpha, out_depth,
                             grid, gi, gj, want_color, want_depth)
        for row in range(min(16, height - ty * 16)):
            i0 = (row + 1) // 2  # grid row of the block centre at or above the pixel centre (row + ½ − 1) / 2
            wy = np.float32(0.75) if row % 2 == 0 else np.float32(0.25)  # weight of grid row i0 + 1
            vy = one - wy
            py = ty * 16 + row
            for col in range(min(16, width - tx * 16)):
                j0 = (col + 1) // 2
                wx = np.float32(0.75) if col % 2 == 0 else np.float32(0.25)
                vx = one - wx
                px = tx * 16 + col
                a = _bilinear_at(grid, i0, j0, 0, vy, wy, vx, wx)
                out_alpha[py, px] = a
                if want_color:
                    for c in range(3):
                        out_rgb[py, px, c] = _bilinear_at(grid, i0, j0, 1 + c, vy, wy, vx, wx)
                if want_depth:
                    out_depth[py, px] = _bilinear_at(grid, i0, j0, 4, vy, wy, vx, wx) / a if a > zero else zero
                if want_ids:
                    k = (row // 2) * 8 + col // 2
                    out_median[py, px] = sample_median[tile, k]
                    out_ids[py, px] = sample_ids[tile, k]


@numba.njit(cache=True)
def depth_order(visible, depths):  # pragma: no cover - compiled
    """Indices ``visible`` stably sorted by ``depths`` (positive float32): LSD radix sort, 3×11 bits.

    Positive IEEE floats order like their bit patterns, so the sort runs on integers; being
    stable, equal depths keep index order (the torch path's stable sort gives the same order).
    """
    n = visible.shape[0]
    keys = np.empty(n, np.float32)
    for i in range(n):
        keys[i] = depths[visible[i]]
    bits = keys.view(np.uint32)
    order = visible.copy()
    tmp_order = np.empty_like(order)
    tmp_bits = np.empty_like(bits)
    for shift in (0, 11, 22):
        counts = np.zeros(2049, np.int64)
        for i in range(n):
            counts[((bits[i] >> shift) & 2047) + 1] += 1
        for b in range(2048):
            counts[b + 1] += counts[b]
        for i in range(n):
            bucket = (bits[i] >> shift) & 2047
            dst = counts[bucket]
            tmp_order[dst] = order[i]
            tmp_bits[dst] = bits[i]
            counts[bucket] = dst + 1
        order, tmp_order = tmp_order, order
        bits, tmp_bits = tmp_bits, bits
    return order


def bin_visible(packed: np.ndarray, rects: np.ndarray, width: int, height: int, tight: bool) -> tuple[np.ndarray, np.ndarray]:
    """Depth-sort the visible Gaussians and bin them into tiles: ``(offsets, gauss)`` (see :func:`bin_tiles`)."""
    tiles_x, tiles_y = (width + 15) // 16, (height + 15) // 16
    visible = np.flatnonzero(rects[:, 1] > rects[:, 0])
    order = depth_order(visible, packed[:, DEPTH])  # the column read in place (a strided view)
    return bin_tiles(order, rects, packed, tiles_x, tiles_y, width, height, tight, pair_capacity(order, rects))


@numba.njit(cache=True)
def pair_capacity(order, rects):  # pragma: no cover - compiled
    """The sum of the tile rectangles' areas of the Gaussians ``order``: an upper bound on the pairs."""
    total = 0
    for k in range(order.shape[0]):
        g = order[k]
        total += (rects[g, 1] - rects[g, 0]) * np.int64(rects[g, 3] - rects[g, 2])
    return total


def rasterize(packed: np.ndarray, rects: np.ndarray, instance_ids: np.ndarray, width: int, height: int,
              alpha_max: float, want_color: bool, want_depth: bool, want_ids: bool, tight: bool,
              sample_min_coc: float = 0.0) -> dict[str, np.ndarray]:
    """Sort, bin and composite projected Gaussians; returns the requested float32/int32 images.

    ``sample_min_coc`` > 0: tiles whose every Gaussian has a circle of confusion of at least that many
    pixels are composited every 2 px and upsampled (:func:`composite`'s ``coarse``; defocus)."""
    tiles_x = (width + 15) // 16
    offsets, gauss = bin_visible(packed, rects, width, height, tight)
    coarse = None
    if sample_min_coc > 0.0:
        coarse = sampled_tiles(offsets, gauss, packed, np.float32(sample_min_coc))
        coarse = coarse if coarse.any() else None
    # the composite writes every pixel of every image it is asked for (each pixel lies in one tile):
    # those start empty; the 1×1 stand-ins of images not asked for keep their fill
    out = {
        "alpha": np.empty((height, width), np.float32),
        "rgb": np.empty((height, width, 3), np.float32) if want_color else np.zeros((1, 1, 3), np.float32),
        "depth": np.empty((height, width), np.float32) if want_depth else np.zeros((1, 1), np.float32),
        "median_depth": np.empty((height, width), np.float32) if want_ids else np.zeros((1, 1), np.float32),
        "instance_ids": np.empty((height, width), np.int32) if want_ids else np.full((1, 1), -1, np.int32),
    }
    composite(
        offsets, gauss, packed, instance_ids, width, height, tiles_x, alpha_max,
        want_color, want_depth, want_ids,
        out["rgb"], out["alpha"], out["depth"], out["median_depth"], out["instance_ids"], coarse,
    )
    out["n_pairs"] = np.int64(gauss.shape[0])
    out["n_visible"] = np.int64(np.count_nonzero(rects[:, 1] > rects[:, 0]))
    return out

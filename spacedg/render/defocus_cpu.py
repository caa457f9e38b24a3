"""Compiled (numba) defocus compositing: the sharp measurement pass and the blurred composite.

The model (see :mod:`spacedg.render.defocus`) renders defocus in two passes:

1. :func:`measure_sharp` composites the **sharp** view exactly as the sharp render does and, for
   every (tile, Gaussian) pair, sums over the tile's pixels

   - ``M = Σ α`` — alpha composited,
   - ``S = Σ α·T_slab`` — alpha not hidden by earlier Gaussians of the **same depth slab**
     (``T_slab``: transmittance through the Gaussians of the Gaussian's slab in front of it;
     slabs are the bins of ``⌊ln z / ln(1 + DEFOCUS_SLAB)⌋`` and every pixel of a tile changes
     slab together, as the tile's list is depth-sorted),
   - ``W = Σ w`` — the visible weight ``w = α·T``,
   - ``U_c = Σ w·ρ_c`` per channel, with ``ρ_c = decode(C_c) / Σ w·decode(c_c)`` the pixel's
     ratio of its sRGB-decoded composite to the linear-light mix of the same splats (a second
     sweep over the list, once the pixel's composite is final).

2. :func:`composite_defocus` composites the blurred projection front to back. A Gaussian in
   focus (``COC = 0``) follows the sharp rules exactly (``α``, ``T ← T(1 − α)``, stop before
   ``T ≤ 10⁻⁴``) into the sRGB-encoded accumulator; a blurred one **adds** its weight
   ``w = min(α·T_f, T)`` (``T_f``: transmittance through the in-focus Gaussians in front) into
   the linear-light accumulator until the pixel saturates. Its colour is already linear and
   its opacity already scaled by its same-slab visibility ``S / M`` (done between the passes).

Both kernels keep one flat float32 state buffer per tile, indexed with unsigned integers so
that LLVM vectorises the 16-pixel rows, like :func:`spacedg.render.raster_cpu.composite`.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from spacedg.render.colour_cpu import _DECODE_LUT, _TOE
from spacedg.render.project_cpu import AMIN, CA, CB, CBL, CC, CG, COC, CR, DEPTH, OPA, PX, PY, RADX, RADY
from spacedg.render.raster_cpu import (
    _accumulate, _add_rgb, _conic, _f32_constants, _gauss_alpha, _pair_rows, _put_pixel, _put_rgb, _row_terms, _tile_span, _tile_state,
)
from spacedg.render.threads import fork_safe

__all__ = ["composite_defocus", "match_and_apply", "measure_sharp", "PAIR_M", "PAIR_S", "PAIR_W", "PAIR_U", "PAIR_COLUMNS"]

#: Columns of :func:`measure_sharp`'s per-pair sums: M, S, W, then U for r, g, b, then the visible
#: weight's moments about the Gaussian's mean (measurement pixels): Σw·dx, Σw·dy, Σw·dx², Σw·dx·dy, Σw·dy².
PAIR_M, PAIR_S, PAIR_W, PAIR_U, PAIR_MOMENTS = 0, 1, 2, 3, 6
PAIR_COLUMNS = 11
_ROOT2 = math.sqrt(2.0)


@numba.njit(cache=True, inline="always")
def _decode(x, lut):
    """sRGB-encoded value → linear light (negative → 0), float64: the table of
    :func:`spacedg.render.colour_cpu.decode_srgb` on [0.04045, 1), the exact curve elsewhere."""
    if not x > 0.0:
        return 0.0
    if x <= _TOE:
        return x / 12.92
    if x < 1.0:
        s = (x - _TOE) * ((lut.shape[0] - 1) / (1.0 - _TOE))
        j = min(int(s), lut.shape[0] - 2)
        return lut[j] + (s - j) * (lut[j + 1] - lut[j])
    return ((x + 0.055) / 1.055) ** 2.4


# state planes of measure_sharp (256 floats each)
_MT, _MLIVE, _ER, _EG, _EB, _LR, _LG, _LB, _TS = (np.uint64(256 * k) for k in range(9))


@numba.njit(cache=True, inline="always")
def _sharp_step(alpha, t_before, t_min, zero, one):
    """The sharp rule at one pixel: transmittance after a Gaussian of alpha ``alpha`` and whether it
    is taken (``one``, or ``zero`` where it would take ``T`` to ``<= t_min``), float32."""
    t_after = t_before * (one - alpha)
    return t_after, zero if t_after <= t_min else one


@numba.njit(cache=True, inline="always")
def _median_hit(state, p, w, t_before, z, gid, zero, half):
    """Keep Gaussian ``z, gid`` as pixel ``p``'s median while it adds weight with ``T > ½`` before it."""
    hit = w > zero and t_before > half
    state[p + _MED] = z if hit else state[p + _MED]
    state[p + _ID] = gid if hit else state[p + _ID]


@numba.njit(cache=True, inline="always")
def _measure_sweep(state, packed, lin, g, x0, y0, amax, pair_out, k, second):
    """Composite Gaussian ``g`` into one tile's state (sharp rules). Sweep 1 (``second`` false): add
    its M, S, W and the two colour mixes. Sweep 2, once every pixel's ρ is known (in the
    linear-mix planes): the same composite again, adding ``U = Σ w·ρ``."""
    _, t_min, _, zero, one = _f32_constants(amax)
    gx, gy, r0, r1 = _pair_rows(packed, g, x0, y0)
    ca, cb, cc, opa, amin = _conic(packed, g)
    cr, cg, cbl = packed[g, CR], packed[g, CG], packed[g, CBL]
    lr, lg, lb = lin[g, 0], lin[g, 1], lin[g, 2]
    m_sum = zero  # sweep 1: M, S, W and the visible weight's moments
    s_sum = zero
    w_sum = zero
    wx = zero
    wy = zero
    wxx = zero
    wxy = zero
    wyy = zero
    ur = zero  # sweep 2: U
    ug = zero
    ub = zero
    for row in range(r0, r1):
        bdy, cdy, base = _row_terms(row, gy, cb, cc)
        dy = np.float32(row) - gy
        for col in range(16):
            p = base + np.uint64(col)
            alpha = _gauss_alpha(col, gx, ca, bdy, cdy, opa, amin, amax, zero) * state[p + _MLIVE]
            t_before = state[p + _MT]
            t_after, take = _sharp_step(alpha, t_before, t_min, zero, one)
            a_taken = alpha * take
            w = a_taken * t_before
            if second:
                ur += w * state[p + _LR]
                ug += w * state[p + _LG]
                ub += w * state[p + _LB]
            else:
                m_sum += a_taken
                s_sum += a_taken * state[p + _TS]
                w_sum += w
                dx = np.float32(col) - gx
                wx += w * dx
                wy += w * dy
                wxx += w * dx * dx
                wxy += w * dx * dy
                wyy += w * dy * dy
                state[p + _TS] = state[p + _TS] * (one - a_taken)
                _add_rgb(state, p + _ER, w, cr, cg, cbl)
                _add_rgb(state, p + _LR, w, lr, lg, lb)
            state[p + _MT] = t_after if take > zero else t_before
            state[p + _MLIVE] *= take
    if second:
        pair_out[k, 3] += ur
        pair_out[k, 4] += ug
        pair_out[k, 5] += ub
    else:
        pair_out[k, 0] += m_sum
        pair_out[k, 1] += s_sum
        pair_out[k, 2] += w_sum
        pair_out[k, 6] += wx
        pair_out[k, 7] += wy
        pair_out[k, 8] += wxx
        pair_out[k, 9] += wxy
        pair_out[k, 10] += wyy


@numba.njit(cache=True, inline="always")
def _all_dead(state):
    live = np.float32(0.0)
    for p in range(256):
        live += state[256 + p]
    return live == np.float32(0.0)


@fork_safe
@numba.njit(parallel=True, fastmath=True, cache=True)
def measure_sharp(offsets, gauss, packed, lin, slab, tiles_x, alpha_max, pair_out, lut=_DECODE_LUT):  # pragma: no cover - compiled
    """Fill ``pair_out`` (pairs, :data:`PAIR_COLUMNS`) float32 with each pair's sums (see the module docstring).

    Args:
        offsets, gauss: the sharp projection's tile lists (:func:`spacedg.render.raster_cpu.bin_tiles`).
        packed: the sharp projection (:func:`spacedg.render.project_cpu.project_gaussians`, no defocus).
        lin: (N, 3) float32 linear-light colours (the sRGB decode of the packed colours).
        slab: (N,) int64 depth slab of every Gaussian.
    """
    n_tiles = offsets.shape[0] - 1
    amax = np.float32(alpha_max)
    for tile in numba.prange(n_tiles):
        start, end, x0, y0 = _tile_span(offsets, tile, tiles_x)
        if end == start:
            continue
        state = _tile_state(9, 2)
        state[2048:] = 1.0
        stop = end
        for k in range(start, end):
            g = gauss[k]
            if k > start and slab[g] != slab[gauss[k - 1]]:
                state[2048:] = 1.0  # a new depth slab starts for every pixel of the tile
            _measure_sweep(state, packed, lin, g, x0, y0, amax, pair_out, k, False)
            if (k - start) % 32 == 31 and _all_dead(state):
                stop = k + 1
                break
        # ρ_c per pixel: decoded composite over the linear mix of the same splats
        for p in range(256):
            for c in range(3):
                mix = np.float64(state[1280 + 256 * c + p])
                if mix > 0.0:
                    state[1280 + 256 * c + p] = np.float32(_decode(np.float64(state[512 + 256 * c + p]), lut) / mix)
                else:
                    state[1280 + 256 * c + p] = np.float32(1.0)
            state[p] = 1.0
            state[256 + p] = 1.0
        for k in range(start, stop):
            _measure_sweep(state, packed, lin, gauss[k], x0, y0, amax, pair_out, k, True)


# state planes of composite_defocus (256 floats each)
_T, _LIVE, _ER2, _EG2, _EB2, _LR2, _LG2, _LB2, _D, _MED, _ID, _TF = (np.uint64(256 * k) for k in range(12))


@fork_safe
@numba.njit(parallel=True, fastmath=True, cache=True)
def composite_defocus(
    offsets, gauss, packed, instance_ids, width, height, tiles_x, alpha_max,
    want_color, want_depth, want_ids,
    out_enc, out_lin, out_alpha, out_depth, out_median, out_ids,
):  # pragma: no cover - compiled; covered through render() and the oracle tests
    """Composite the blurred projection (see the module docstring); writes the images in place.

    ``out_enc`` receives the sRGB-encoded mix of the in-focus Gaussians, ``out_lin`` the
    linear-light light of the blurred ones; the caller decodes the first and adds the second.
    """
    n_tiles = offsets.shape[0] - 1
    amax, t_min, half, zero, one = _f32_constants(alpha_max)
    for tile in numba.prange(n_tiles):
        start, end, x0, y0 = _tile_span(offsets, tile, tiles_x)
        state = _tile_state(12, 2)
        state[2560:2816] = -1.0
        state[2816:] = 1.0
        for k in range(start, end):
            g = gauss[k]
            gx, gy, r0, r1 = _pair_rows(packed, g, x0, y0)
            ca, cb, cc, opa, amin = _conic(packed, g)
            cr, cg, cbl = packed[g, CR], packed[g, CG], packed[g, CBL]
            z = packed[g, DEPTH]
            gid = np.float32(instance_ids[g])
            blurred = packed[g, COC] > zero
            for row in range(r0, r1):
                bdy, cdy, base = _row_terms(row, gy, cb, cc)
                if blurred:
                    for col in range(16):
                        p = base + np.uint64(col)
                        alpha = _gauss_alpha(col, gx, ca, bdy, cdy, opa, amin, amax, zero) * state[p + _LIVE]
                        t_before = state[p]
                        w = min(alpha * state[p + _TF], t_before)
                        t_after = t_before - w
                        _accumulate(state, p, w, _LR2, cr, cg, cbl, _D, z, want_color, want_depth)
                        if want_ids:
                            _median_hit(state, p, w, t_before, z, gid, zero, half)
                        state[p] = t_after
                        state[p + _LIVE] *= zero if t_after <= t_min else one
                else:
                    for col in range(16):
                        p = base + np.uint64(col)
                        alpha = _gauss_alpha(col, gx, ca, bdy, cdy, opa, amin, amax, zero) * state[p + _LIVE]
                        t_before = state[p]
                        t_after, take = _sharp_step(alpha, t_before, t_min, zero, one)
                        w = alpha * t_before * take
                        _accumulate(state, p, w, _ER2, cr, cg, cbl, _D, z, want_color, want_depth)
                        if want_ids:
                            _median_hit(state, p, w, t_before, z, gid, zero, half)
                        state[p] = t_after if take > zero else t_before
                        state[p + _TF] = state[p + _TF] * (one - alpha * take)
                        state[p + _LIVE] *= take
            if (k - start) % 32 == 31 and _all_dead(state):
                break
        for row in range(min(16, height - y0)):
            for col in range(min(16, width - x0)):
                p = row * 16 + col
                py, px = y0 + row, x0 + col
                _put_pixel(state, p, py, px, state[p], 512, 2048, out_alpha, out_enc, out_depth, want_color, want_depth, zero, one)
                if want_color:
                    _put_rgb(out_lin, py, px, state, 1280 + p)
                if want_ids:
                    out_median[py, px] = state[2304 + p]
                    out_ids[py, px] = np.int32(state[2560 + p]) if state[p] <= half else -1


@numba.njit(cache=True)
def match_and_apply(gauss, pair_out, sharp, mass, mwidth, mheight, packed, rects, want_color, centre_weight, seen, prior):  # pragma: no cover - compiled
    """:func:`spacedg.render.defocus.match_factors` and :func:`~spacedg.render.defocus.apply_match` in one
    compiled pass (the numpy versions took as long as the blurred composite at 448×336).

    Sums each pair's row of ``pair_out`` into its Gaussian (in pair order, as ``np.bincount``),
    takes every Gaussian's share of its footprint box inside the measured frame
    (``mwidth`` × ``mheight``, from the ``sharp`` projection) and its integrated alpha ``mass``
    (:func:`spacedg.render.defocus.alpha_mass` of the sharp projection), and returns the blurred
    projection ``(packed, rects)`` (copies) with κ and ρ applied: κ is ``centre_weight`` times the
    centre's share plus ``seen`` (N,), the other lens points' weighted shares
    (:mod:`spacedg.render.defocus_lens`). Means are over float64 totals;
    κ and ρ are rounded to float32 before they are applied, as the numpy path does.
    """
    n = packed.shape[0]
    sums = np.zeros((n, PAIR_COLUMNS), np.float64)
    for k in range(gauss.shape[0]):
        g = gauss[k]
        for j in range(PAIR_COLUMNS):
            sums[g, j] += np.float64(pair_out[k, j])
    share = np.zeros(n, np.float64)
    expected = 0.0
    tot = np.zeros(PAIR_COLUMNS, np.float64)
    for g in range(n):
        for j in range(PAIR_COLUMNS):
            tot[j] += sums[g, j]
        # share of the sharp Gaussian's mass inside the measured frame (product of its marginals)
        u, v = np.float64(sharp[g, PX]), np.float64(sharp[g, PY])
        ca, cb, cc = np.float64(sharp[g, CA]), np.float64(sharp[g, CB]), np.float64(sharp[g, CC])
        det = ca * cc - cb * cb
        sx = math.sqrt(cc / det) if det > 0.0 else 0.5
        sy = math.sqrt(ca / det) if det > 0.0 else 0.5
        sx = max(sx, 1e-6) if sx == sx else 0.5
        sy = max(sy, 1e-6) if sy == sy else 0.5
        fx = 0.5 * (math.erf((np.float64(mwidth) - u) / (_ROOT2 * sx)) - math.erf(-u / (_ROOT2 * sx)))
        fy = 0.5 * (math.erf((np.float64(mheight) - v) / (_ROOT2 * sy)) - math.erf(-v / (_ROOT2 * sy)))
        share[g] = min(max(fx * fy, 0.0), 1.0)
        expected += mass[g] * share[g]
    kappa_mean = min(tot[2] / expected, 1.0) if expected > 0.0 else 1.0
    rho_mean = np.ones(3, np.float64)
    if tot[2] > 0.0:
        for c in range(3):
            rho_mean[c] = tot[3 + c] / tot[2]
    out = packed.copy()
    out_rects = rects.copy()
    for g in range(n):
        if not packed[g, COC] > 0.0:
            continue
        w = sums[g, 2]
        kappa = (w + prior * mass[g] * kappa_mean) / (mass[g] * (share[g] + prior)) if mass[g] > 0.0 else kappa_mean
        if kappa != kappa:
            kappa = kappa_mean
        kappa = centre_weight * min(max(kappa, 0.0), 1.0) + seen[g]
        kappa32 = np.float32(min(max(kappa, 0.0), 1.0))
        out[g, OPA] = packed[g, OPA] * kappa32
        out[g, AMIN] = packed[g, AMIN] * kappa32
        if kappa32 <= 0.0:
            out_rects[g, 0] = 0
            out_rects[g, 1] = 0
            out_rects[g, 2] = 0
            out_rects[g, 3] = 0
        if want_color:
            for c in range(3):
                rho = share[g] * (sums[g, 3 + c] / w) + (1.0 - share[g]) * rho_mean[c] if w > 0.0 else rho_mean[c]
                if rho != rho:
                    rho = 1.0
                elif rho == np.inf:
                    rho = 1.0
                rho32 = np.float32(max(rho, 0.0))
                x = max(np.float64(packed[g, CR + c]), 0.0)
                lin = x / 12.92 if x <= 0.04045 else ((x + 0.055) / 1.055) ** 2.4
                out[g, CR + c] = np.float32(lin * np.float64(rho32))
    return out, out_rects

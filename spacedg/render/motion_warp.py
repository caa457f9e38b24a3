"""Motion blur from a few keyframes: depth-reprojected, path-integrated gathers (compiled CPU).

The exposure ``[-½, ½]`` is cut into ``K`` equal intervals; keyframe ``k`` is a sharp render
(premultiplied linear colour, alpha, expected depth) at the pose of its interval's centre, on a
canvas widened by ``margin`` pixels on every side (same focal lengths, principal point shifted
by ``margin``) so that what the moving camera sweeps in is rendered too. Per interval:

1. :func:`flow_field`: for every canvas pixel ``p``, the point the cameras at the interval's
   ends see at ``p`` (depth = the keyframe's depth at ``p``) is projected into the keyframe:
   ``q_a``, ``q_b``. During the interval ``p`` sees the keyframe along the parabola from
   ``q_a`` through ``p`` itself (the keyframe's pose is the interval's centre) to ``q_b``.
2. ``P`` :func:`doubling_pass` es: ``B(q) = ½[B(q − s·d) + B(q + s·d)]`` with ``s = ¼, ⅛, …``:
   each pass replaces every sample by two, ``2 s |d|`` apart along the pixel's own segment. On a
   covered canvas each pass writes only the pixels the gather and the later passes read
   (:func:`pass_regions`, from the field's largest offsets): ~18 % fewer pixels on the dataset's
   room views, the same bytes.
3. :func:`gather`: each output pixel averages ``B`` along the central ``2^-P`` of its path
   (times evenly spaced, ≤ ``spacing`` pixels apart along the chord): in all ``|d| / spacing``
   samples of the keyframe along the whole path for ``|d| / (2^P spacing) + 2P`` bilinear
   taps (the passes shift along the chord ``d``: exact for a straight path).

The exposure average is the mean over intervals. Sampling every ≤ 1 px along the path
integrates the smear continuously: no stroboscopic copies however long the path is.
Approximations (their error shrinks as ``K`` grows): what ``p`` sees during the interval is at
the keyframe's depth at ``p`` (wrong in a band of the interval's parallax around depth edges);
the doubling passes use the field at the sample's pixel, not the output pixel's (equal where
the flow is smooth; each pass also adds one bilinear resampling); view-dependent colour and
the depth order of overlapping Gaussians are the keyframe's.

Units: pixel coordinates with centres at ``+½`` (array-index coordinates inside the kernels:
centres at integers); depths in metres (camera z); ``spacing`` in pixels.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from llvmlite import ir
from numba.core import types
from numba.extending import intrinsic

from spacedg.render import kernel_cache  # noqa: F401 - numba's cache entries checked before any kernel here compiles
from spacedg.render.threads import fork_safe

__all__ = ["COVERED_ALPHA", "doubling_pass", "fill_depth", "finish_average", "flow_field", "gather", "keyframe_source", "pass_regions", "relative_transform", "sanitise_field"]


def relative_transform(pose_from: np.ndarray, pose_to: np.ndarray) -> np.ndarray:
    """(12,) float64 ``R, t`` (row-major R then t) taking camera-``pose_from`` coordinates to
    camera-``pose_to`` coordinates (both cam-to-world 4×4, metres)."""
    r = pose_to[:3, :3].T @ pose_from[:3, :3]
    t = pose_to[:3, :3].T @ (pose_from[:3, 3] - pose_to[:3, 3])
    return np.concatenate([r.reshape(9), t]).astype(np.float64)


#: fast-math flags of :func:`gather` and :func:`doubling_pass`: ``fastmath=True`` less ``reassoc``.
#: With ``reassoc`` LLVM may re-associate their float sums differently when a parallel kernel is
#: compiled fresh (its parfor gufunc optimised on its own, then linked into the caller) than when
#: the same kernel is loaded from numba's on-disk cache (the linked copy): the first process on a
#: machine rendered other bits than later ones. Without it the sums keep the source order; FMA
#: contraction (``contract``) stays and was measured to give identical bits both ways
#: (``benchmarks/numba_cache_determinism.py``). Nor ``arcp`` and ``afn``: :func:`gather` computes its
#: per-pixel sample counts and steps (a square root, two divisions) in a loop of their own that LLVM
#: vectorises, where they would let it use reciprocal and square-root estimates or turn one division
#: into a product with the other's reciprocal: without them both stay correctly rounded, as the
#: scalar code they came from compiled (the kernels have no other division or square root).
_FASTMATH = {"nnan", "ninf", "nsz", "contract"}


#: Path samples :func:`gather` places before it sums them (its scratch buffers' length).
_PATH_CHUNK = 64
#: Paths of at most this many samples (4 channels) are walked in one loop, each sample's weights and taps at
#: once (the chunked loops cost three loop exits a pixel, the fused one a store and load of the sums a
#: sample): on a 720 × 560 canvas, one thread, 13 against 20 ns a pixel at 1 sample, 31 against 39 at 5,
#: about even at 9 and behind beyond (61 against 89 at 17). The dataset's gathers take 7.6 samples a
#: pixel on average (median 7, 90th percentile 12). The same bits either way.
_FUSED_MAX = 8


def _weighted_sum(builder: ir.IRBuilder, kind: ir.Type, data: ir.Value, taps: list, weights: list) -> ir.Value:
    """LLVM IR of ``Σ weights[n] · texel(taps[n])``, each texel a ``kind`` (a float or a float vector) loaded at
    flat index ``taps[n]`` of ``data``, each weight a float spread over the lanes: ``fmul`` then ``fadd``
    left to right, ``((w₀t₀ + w₁t₁) + w₂t₂) + …``, with no fast-math flags of their own (numba gives
    them the calling kernel's). The one emitter of the intrinsics below, so they agree by construction."""
    total = None
    for tap, weight in zip(taps, weights):
        texel = builder.load(builder.bitcast(builder.gep(data, [tap]), kind.as_pointer()), align=4)
        if isinstance(kind, ir.VectorType):
            spread = ir.Constant(kind, ir.Undefined)
            for lane in range(kind.count):
                spread = builder.insert_element(spread, weight, ir.Constant(ir.IntType(32), lane))
            weight = spread
        term = builder.fmul(weight, texel)
        total = term if total is None else builder.fadd(total, term)
    return total


def _weighted_taps_intrinsic(lanes: int, accumulate: bool):
    """``dst[at : at + lanes] = Σ weights[n] · flat[taps[n] : taps[n] + lanes]`` (with ``accumulate``:
    ``+=``), each term one float32 vector of ``lanes`` (4: a texel's r, g, b, α; 1: the depth
    channel): a numba intrinsic for the kernels below.

    The four channels of a texel lie next to each other, so a tap is one vector load and each
    term one vector multiply and add, where the scalar form does four of each (LLVM does not find
    this itself). The terms are summed left to right, ``((w₀t₀ + w₁t₁) + w₂t₂) + …``, and the
    instructions carry no fast-math flags of their own: numba gives them the calling kernel's, as
    it does its scalar arithmetic. So every lane computes the caller's scalar
    ``w0 * flat[t0 + c] + w1 * flat[t1 + c] + …`` (``dst[c] += …``) with the same FMA contractions,
    the same bits (tested). Arguments: ``dst`` and ``flat`` 1-D C-contiguous float32 arrays, ``at``
    an integer index into ``dst``, ``taps`` a tuple of integer flat indices, ``weights`` a tuple of
    as many float32 (other types do not compile). No bounds checks: the callers clamp their taps
    to the canvas.
    """
    kind = ir.FloatType() if lanes == 1 else ir.VectorType(ir.FloatType(), lanes)

    def typer(typingctx, dst, at, flat, taps, weights):
        float_vector = [isinstance(a, types.Array) and a.dtype == types.float32 and a.ndim == 1 and a.layout == "C" for a in (dst, flat)]
        if not (all(float_vector) and isinstance(at, types.Integer)
                and isinstance(taps, types.UniTuple) and isinstance(taps.dtype, types.Integer)
                and isinstance(weights, types.UniTuple) and weights.dtype == types.float32 and taps.count == weights.count):
            return None

        def codegen(context, builder, signature, args):
            dst_value, at_value, flat_value, taps_value, weights_value = args
            data = context.make_array(signature.args[2])(context, builder, flat_value).data
            count = signature.args[3].count
            total = _weighted_sum(builder, kind, data, [builder.extract_value(taps_value, n) for n in range(count)],
                                  [builder.extract_value(weights_value, n) for n in range(count)])
            first = builder.gep(context.make_array(signature.args[0])(context, builder, dst_value).data, [at_value])
            target = builder.bitcast(first, kind.as_pointer())
            if accumulate:
                total = builder.fadd(builder.load(target, align=4), total)
            builder.store(total, target, align=4)
            return context.get_dummy_value()

        return types.void(dst, at, flat, taps, weights), codegen

    typer.__name__ = f"_{'add_' if accumulate else ''}weighted_taps{lanes}"
    return intrinsic(typer)


@intrinsic
def _path_taps4(typingctx, acc, flat, corners, weights, count, row, nc):
    """``acc + Σₖ (((w0ₖ·t00ₖ + w1ₖ·t01ₖ) + w2ₖ·t10ₖ) + w3ₖ·t11ₖ)`` over the path samples ``k < count``, each
    term a float32 vector of a texel's four channels (r, g, b, α), added to the running sum one sample
    after another: the four channels of :func:`gather`'s sum over a chunk of its path, as a numba
    intrinsic that keeps the running sum in a vector register.

    The same instructions per sample as :func:`_add_weighted_taps4` (so the same bits: the products and
    sums in the same order, the calling kernel's fast-math flags), but the sum is one SSA value of a loop
    written here instead of a store to and a load from the kernel's ``lanes`` array per sample: that
    round trip through memory was the critical path of a long path (≈ 3 ns a sample). Arguments: ``acc``
    a 4-tuple of float32 (the sums so far), ``flat`` the canvas as a 1-D C float32 array (4 channels
    a texel), ``corners`` 1-D C uint64 (each sample's top-left texel, a flat index), ``weights`` 1-D C
    float32 of ``4 · _PATH_CHUNK`` (row ``r`` of the bilinear weights at ``r · _PATH_CHUNK``), ``count``
    an integer ≤ ``_PATH_CHUNK``, ``row`` and ``nc`` uint64 (a canvas row's and a texel's length in
    floats). No bounds checks: the caller clamps its taps to the canvas. Returns the new 4-tuple."""
    float32 = types.float32
    ok = (isinstance(acc, types.UniTuple) and acc.count == 4 and acc.dtype == float32
          and all(isinstance(a, types.Array) and a.ndim == 1 and a.layout == "C" for a in (flat, corners, weights))
          and flat.dtype == float32 and weights.dtype == float32 and corners.dtype == types.uint64
          and isinstance(count, types.Integer) and row == types.uint64 and nc == types.uint64)
    if not ok:
        return None

    def codegen(context, builder, signature, args):
        from numba.core import cgutils

        acc_value, flat_value, corners_value, weights_value, count_value, row_value, nc_value = args
        kind = ir.VectorType(ir.FloatType(), 4)
        lane_index = [ir.Constant(ir.IntType(32), lane) for lane in range(4)]
        texels = context.make_array(signature.args[1])(context, builder, flat_value).data
        corner_data = context.make_array(signature.args[2])(context, builder, corners_value).data
        weight_data = context.make_array(signature.args[3])(context, builder, weights_value).data
        start = ir.Constant(kind, ir.Undefined)
        for lane in range(4):
            start = builder.insert_element(start, builder.extract_value(acc_value, lane), lane_index[lane])
        running = cgutils.alloca_once_value(builder, start)  # promoted to a register (mem2reg)
        stop = context.cast(builder, count_value, signature.args[4], types.intp)
        with cgutils.for_range(builder, stop) as loop:
            k = loop.index
            p00 = builder.load(builder.gep(corner_data, [k]))
            p10 = builder.add(p00, row_value)
            weights_k = [builder.load(builder.gep(weight_data, [builder.add(k, ir.Constant(k.type, r * _PATH_CHUNK))])) for r in range(4)]
            total = _weighted_sum(builder, kind, texels, [p00, builder.add(p00, nc_value), p10, builder.add(p10, nc_value)], weights_k)
            builder.store(builder.fadd(builder.load(running), total), running)
        result = builder.load(running)
        return context.make_tuple(builder, signature.return_type, [builder.extract_element(result, lane_index[lane]) for lane in range(4)])

    return acc(acc, flat, corners, weights, count, row, nc), codegen


_add_weighted_taps4 = _weighted_taps_intrinsic(4, accumulate=True)
_weighted_taps4 = _weighted_taps_intrinsic(4, accumulate=False)
_add_weighted_taps1 = _weighted_taps_intrinsic(1, accumulate=True)
_weighted_taps1 = _weighted_taps_intrinsic(1, accumulate=False)


@numba.njit(cache=True, inline="always")
def _project(m, x, y, z, fx, fy, cx, cy):
    """Point ``(x, y, z)`` in the source camera → keyframe pixel ``(u, v, depth)``."""
    xk = m[0] * x + m[1] * y + m[2] * z + m[9]
    yk = m[3] * x + m[4] * y + m[5] * z + m[10]
    zk = m[6] * x + m[7] * y + m[8] * z + m[11]
    if zk <= 1e-6:
        return 0.0, 0.0, -1.0
    return fx * xk / zk + cx, fy * yk / zk + cy, zk


@fork_safe
@numba.njit(parallel=True, fastmath=_FASTMATH, cache=True)
def gather(src, field, margin, length, spacing, sat, out):  # pragma: no cover - compiled
    """Add one keyframe interval's path average to ``out`` (in place).

    Args:
        src: (Hc, Wc, C) float32 keyframe canvas channels, C = 4 (premultiplied linear r, g, b,
            alpha) or 5 (and depth × alpha, for the depth output).
        field: (Hc, Wc, 4) float32 from :func:`flow_field`: segment centre offset and extent (pixels).
        margin: canvas border (pixels): output pixel (i, j) is canvas pixel (i + margin, j + margin).
        length: fraction of each segment walked (1; ``2^-p`` after ``p`` :func:`doubling_pass` es,
            whose samples already average the rest).
        spacing: largest distance (pixels) between two samples along the walked segment.
        sat: :func:`occupancy` of ``src``: a segment over empty texels adds nothing and is skipped.
        out: (H, W, C) float32 accumulators.
    """
    if src.shape[2] != 4 and src.shape[2] != 5:
        raise ValueError("gather: src must have 4 or 5 channels")
    if src.shape[0] < 2 or src.shape[1] < 2:  # a bilinear read takes a 2 × 2 block of texels
        raise ValueError("gather: the canvas must be at least 2 × 2 pixels")
    hc, wc = src.shape[0], src.shape[1]
    want_extra = src.shape[2] > 4
    # flat buffer, unsigned indices: numba's negative-index wraparound checks stay out of the loop
    flat = src.reshape(-1)
    nc = np.uint64(src.shape[2])
    row = np.uint64(wc) * nc
    c4 = np.uint64(4)
    scale = np.float32(length)
    height, width = out.shape[0], out.shape[1]
    xmax = np.float32(wc - 1.001)
    ymax = np.float32(hc - 1.001)
    zero = np.float32(0.0)
    one = np.float32(1.0)
    half = np.float32(0.5)
    four = np.float32(4.0)
    inv_spacing = np.float32(1.0 / spacing)
    for i in numba.prange(height):
        ci = i + margin
        lanes = np.empty(5, np.float32)  # the path's r, g, b, α (and depth·α) sums (a long colour-only path sums in a register)
        times = np.empty(_PATH_CHUNK, np.float32)  # a chunk of the path's samples: their times,
        corners = np.empty(_PATH_CHUNK, np.uint64)  # top-left texels
        weights = np.empty((4, _PATH_CHUNK), np.float32)  # and bilinear weights
        weights_flat = weights.reshape(-1)
        counts = np.empty(width, np.int64)  # per pixel of the row: samples, their spacing in time and the first
        steps = np.empty(width, np.float32)
        starts = np.empty(width, np.float32)
        norms = np.empty(width, np.float32)
        # first each pixel's sample count and times, over the whole row (no loop inside: the square root and
        # the divisions of neighbouring pixels overlap instead of heading every pixel's walk)
        for j in range(width):
            fu = field[ci, j + margin, 2]
            fv = field[ci, j + margin, 3]
            reach = scale * math.sqrt(fu * fu + fv * fv) * inv_spacing
            whole = int(reach)
            count = max(1, whole + (1 if reach > np.float32(whole) else 0))  # ⌈reach⌉ without a libm call
            step = scale / np.float32(count)
            counts[j] = count
            steps[j] = step
            starts[j] = half - half * scale + half * step
            norms[j] = one / np.float32(count)
        for j in range(width):
            cj = j + margin
            # the path through the keyframe, array-index coordinates (pixel centres at integers):
            # the parabola q(t) = A + t·d − 4t(1−t)·c from A = P + c − d/2 (t = 0) through the
            # pixel itself P (t = ½, the keyframe's own pose) to B = P + c + d/2 (t = 1); the
            # gather walks t ∈ ½ ± length/2 (the doubling passes cover the rest)
            cu = field[ci, cj, 0]
            cv = field[ci, cj, 1]
            fu = field[ci, cj, 2]
            fv = field[ci, cj, 3]
            pu = np.float32(cj)
            pv = np.float32(ci)
            if _empty(sat, min(pu + cu - half * abs(fu), pu - cu), max(pu + cu + half * abs(fu), pu - cu),
                      min(pv + cv - half * abs(fv), pv - cv), max(pv + cv + half * abs(fv), pv - cv)):
                continue
            au = pu + cu - half * fu
            av = pv + cv - half * fv
            count = counts[j]
            step = steps[j]
            t = starts[j]
            if not want_extra and count <= _FUSED_MAX:
                lanes[:4] = zero
                for k in range(count):
                    tk = t
                    t += step
                    bend = four * tk * (one - tk)
                    p00, ax, ay = _corner(au + tk * fu - bend * cu, av + tk * fv - bend * cv, xmax, ymax, row, nc)
                    p10 = p00 + row
                    _add_weighted_taps4(lanes, np.uint64(0), flat, (p00, p00 + nc, p10, p10 + nc),
                                        ((one - ax) * (one - ay), ax * (one - ay), (one - ax) * ay, ax * ay))
                norm = norms[j]
                for c in range(4):
                    out[i, j, c] += lanes[c] * norm
                continue
            # in chunks: the times (one float32 sum after another, as a single loop adds them), then
            # every sample's texel and weights (independent: LLVM vectorises this loop), then the sums
            if want_extra:  # with the depth channel: its sums
                lanes[:] = zero
            colour = (zero, zero, zero, zero)  # without: the r, g, b, α sums (in a register)
            for first in range(0, count, _PATH_CHUNK):
                n = min(_PATH_CHUNK, count - first)
                for k in range(n):
                    times[k] = t
                    t += step
                for k in range(n):
                    tk = times[k]
                    bend = four * tk * (one - tk)
                    corners[k], ax, ay = _corner(au + tk * fu - bend * cu, av + tk * fv - bend * cv, xmax, ymax, row, nc)
                    weights[0, k] = (one - ax) * (one - ay)
                    weights[1, k] = ax * (one - ay)
                    weights[2, k] = (one - ax) * ay
                    weights[3, k] = ax * ay
                if not want_extra:
                    colour = _path_taps4(colour, flat, corners, weights_flat, n, row, nc)
                    continue
                for k in range(n):
                    p00 = corners[k]
                    p10 = p00 + row
                    w00, w01, w10, w11 = weights[0, k], weights[1, k], weights[2, k], weights[3, k]
                    _add_weighted_taps4(lanes, np.uint64(0), flat, (p00, p00 + nc, p10, p10 + nc), (w00, w01, w10, w11))
                    _add_weighted_taps1(lanes, c4, flat, (p00 + c4, p00 + nc + c4, p10 + c4, p10 + nc + c4), (w00, w01, w10, w11))
            norm = norms[j]
            if want_extra:
                for c in range(5):
                    out[i, j, c] += lanes[c] * norm
            else:
                for c in range(4):
                    out[i, j, c] += colour[c] * norm


@fork_safe
@numba.njit(parallel=True, fastmath=True, cache=True)
def flow_field(depth, fx, fy, kcx, kcy, from_a, from_b, field):  # pragma: no cover - compiled
    """Per keyframe-canvas pixel ``p``: ``field[i, j] = (c_u, c_v, d_u, d_v)`` (pixels).

    The cameras at the interval's ends ``a`` and ``b`` (same intrinsics as the canvas) see at
    ``p`` the point at depth ``z = depth[i, j]`` (metres, the keyframe's depth at ``p``);
    ``from_a`` / ``from_b`` (:func:`relative_transform`) take it to the keyframe, where it
    projects to ``q_a`` / ``q_b``. During the interval ``p`` sees the keyframe segment centred
    at ``p + c`` with extent ``d``: ``c = (q_a + q_b)/2 − p``, ``d = q_b − q_a``.
    """
    hc, wc = depth.shape
    for i in numba.prange(hc):
        for j in range(wc):
            z = float(depth[i, j])
            u0, v0 = j + 0.5, i + 0.5
            x = (u0 - kcx) / fx * z
            y = (v0 - kcy) / fy * z
            ua, va, za = _project(from_a, x, y, z, fx, fy, kcx, kcy)
            ub, vb, zb = _project(from_b, x, y, z, fx, fy, kcx, kcy)
            if za <= 0.0 or zb <= 0.0:
                ua, va, ub, vb = u0, v0, u0, v0
            field[i, j, 0] = 0.5 * (ua + ub) - u0
            field[i, j, 1] = 0.5 * (va + vb) - v0
            field[i, j, 2] = ub - ua
            field[i, j, 3] = vb - va


#: Alpha (float32) above which a keyframe pixel's own depth is its flow geometry (below: the fill depth).
COVERED_ALPHA = np.float32(1e-3)


def fill_depth(alpha: np.ndarray, depth: np.ndarray) -> float:
    """The flow geometry's depth (metres) where a keyframe is uncovered: the alpha-weighted mean depth
    of ``alpha`` and ``depth`` (float32, numpy's float32 sums), 1.0 when no pixel's alpha exceeds
    :data:`COVERED_ALPHA`."""
    if not (alpha > COVERED_ALPHA).any():
        return 1.0
    return float(np.sum(depth * alpha) / max(float(alpha.sum()), 1e-30))


def keyframe_source(rgb: np.ndarray, alpha: np.ndarray, depth: np.ndarray, fill: float, src: np.ndarray, geometry: np.ndarray) -> None:
    """A keyframe's gather source and flow geometry, in one pass over its canvas (in place; see
    :func:`_keyframe_source`). ``rgb`` (Hc, Wc, 3), ``alpha`` and ``depth`` (Hc, Wc) float32,
    ``src`` (Hc, Wc, 4 or 5) and ``geometry`` (Hc, Wc) float32; other shapes are refused."""
    size = alpha.shape
    if rgb.shape != (*size, 3) or depth.shape != size or geometry.shape != size or src.shape[:2] != size or src.shape[2] not in (4, 5):
        raise ValueError(
            f"keyframe_source: shapes must be rgb (H, W, 3), alpha/depth/geometry (H, W), src (H, W, 4 or 5); got rgb {rgb.shape}, "
            f"alpha {alpha.shape}, depth {depth.shape}, src {src.shape}, geometry {geometry.shape}"
        )
    _keyframe_source(rgb, alpha, depth, fill, src, geometry)


@fork_safe
@numba.njit(parallel=True, cache=True)
def _keyframe_source(rgb, alpha, depth, fill, src, geometry):  # pragma: no cover - compiled
    """A keyframe's gather source and flow geometry, in one pass over its canvas (in place).

    ``src[i, j] = (r, g, b, α)``, and ``depth·α`` as a fifth channel when ``src`` has five
    (premultiplied linear colour, alpha, float32); ``geometry[i, j]`` = ``depth`` (metres) where
    ``α > COVERED_ALPHA`` (a float32 comparison, as numpy's of a float32 array), else ``fill``
    (float32). The same values as the numpy assignments and ``np.where`` it replaces; no
    fast-math (the product is the plain float32 one).
    """
    hc, wc = alpha.shape
    extra = src.shape[2] > 4
    other = np.float32(fill)
    for i in numba.prange(hc):
        for j in range(wc):
            a = alpha[i, j]
            d = depth[i, j]
            src[i, j, 0] = rgb[i, j, 0]
            src[i, j, 1] = rgb[i, j, 1]
            src[i, j, 2] = rgb[i, j, 2]
            src[i, j, 3] = a
            if extra:
                src[i, j, 4] = d * a
            geometry[i, j] = d if a > COVERED_ALPHA else other


def sanitise_field(field: np.ndarray, reach: np.float32, extents: np.ndarray | None = None) -> float:
    """A :func:`flow_field` ``field`` ((Hc, Wc, 4) float32; other shapes are refused) made safe to
    walk, in place (:func:`_sanitise_field`); returns its longest segment's extent (pixels): the
    float32 square root of the largest float32 ``d_u² + d_v²``. ``extents`` ((4,) float32, optional):
    filled with the largest ``|c_u|, |c_v|, |d_u|, |d_v|`` of the safe field (pixels), the bounds
    :func:`pass_regions` takes."""
    if field.ndim != 3 or field.shape[2] != 4:
        raise ValueError(f"sanitise_field: field must be (H, W, 4), got {field.shape}")
    if extents is None:
        extents = np.empty(4, np.float32)
    elif extents.shape != (4,) or extents.dtype != np.float32:
        raise ValueError(f"sanitise_field: extents must be a (4,) float32 array, got {extents.dtype} {extents.shape}")
    return float(np.sqrt(np.float32(_sanitise_field(field, np.float32(reach), extents))))


@fork_safe
@numba.njit(parallel=True, cache=True)
def _sanitise_field(field, reach, extents):  # pragma: no cover - compiled
    """A :func:`flow_field` made safe to walk, in place; returns its longest segment's squared
    extent ``max(d_u² + d_v²)`` (float32, pixels²), and writes the largest magnitude of each of the
    four components into ``extents``.

    NaN and ±inf become 0 (no path), then every value is clipped to ``[−reach, reach]``
    (``reach`` float32): ``np.clip(np.nan_to_num(field, nan=0, posinf=0, neginf=0), −reach, reach)``
    exactly, and the float32 sum of squares numpy forms. No fast-math: the NaN tests must stay.
    """
    hc, wc = field.shape[0], field.shape[1]
    zero = np.float32(0.0)
    top = np.float32(reach)
    row_longest = np.zeros(hc, np.float32)
    row_extents = np.zeros((hc, 4), np.float32)
    for i in numba.prange(hc):
        longest = zero
        e0, e1, e2, e3 = zero, zero, zero, zero
        for j in range(wc):
            cu = _safe(field[i, j, 0], top)
            cv = _safe(field[i, j, 1], top)
            du = _safe(field[i, j, 2], top)
            dv = _safe(field[i, j, 3], top)
            field[i, j, 0] = cu
            field[i, j, 1] = cv
            field[i, j, 2] = du
            field[i, j, 3] = dv
            e0 = max(e0, abs(cu))
            e1 = max(e1, abs(cv))
            e2 = max(e2, abs(du))
            e3 = max(e3, abs(dv))
            length2 = du * du + dv * dv
            if length2 > longest:
                longest = length2
        row_longest[i] = longest
        row_extents[i, 0], row_extents[i, 1], row_extents[i, 2], row_extents[i, 3] = e0, e1, e2, e3
    for c in range(4):
        extents[c] = row_extents[:, c].max() if hc > 0 else zero
    return row_longest.max() if hc > 0 else zero


@numba.njit(cache=True, inline="always")
def _safe(v, top):
    """A field value made safe to walk: NaN and ±inf → 0, then clipped to ``[−top, top]`` (float32)."""
    v = v if math.isfinite(v) else np.float32(0.0)
    return min(max(v, -top), top)


def pass_regions(
    canvas: tuple[int, int], margin: int, view: tuple[int, int], passes: int, extents: np.ndarray, spacing: float,
) -> list[tuple[int, int, int, int]]:
    """Where each of ``passes`` :func:`doubling_pass` es must write, so that :func:`gather` and the later
    passes read only pixels a pass wrote: ``[(row0, row1, col0, col1)]`` (half-open, canvas pixels),
    the first pass's first.

    ``canvas = (Hc, Wc)``, ``view = (H, W)`` at ``margin`` (the output rectangle), ``extents`` the field's
    largest ``|c_u|, |c_v|, |d_u|, |d_v|`` (:func:`sanitise_field`), ``spacing`` the gather's (pixels).
    The gather walks ``t ∈ ½ ± L/2`` of a path (``L = 2^-passes``), at most ``|c|·L² + |d|·L/2`` from its
    pixel, plus the drift of its sample times: each is the one before plus a step, in float32, so after ``n``
    samples it may be off by ``n·2⁻²⁴`` (``n`` at most ``L·(|d_u| + |d_v|) / spacing + 1``), which moves a
    sample by ``(|d| + 4|c|)`` times that (the parabola's ``4t(1 − t)`` changes by at most 4 per unit of
    ``t``): a few pixels only on paths of tens of thousands of pixels walked every fraction of a pixel. Pass
    ``j`` (scale ``s_j = ¼/2^(j-1)``) reads at most ``s_j |d|`` from its pixel, a position computed once. A
    bilinear read touches the texel after, and the other roundings move a position by far less than a pixel:
    each reach is taken 2 px wider (clamped to the canvas, as the reads are). Each pass computes every pixel
    from the pixel's own field and its source alone, so the pixels it writes hold the bytes of a pass over
    the whole canvas."""
    hc, wc = canvas
    height, width = view
    cu, cv, du, dv = (float(v) for v in extents)
    length = 2.0**-passes
    drift = (length * (du + dv) / float(spacing) + 3.0) * 2.0**-24  # the sample times' float32 sums, at most
    reach_y = cv * length * length + 0.5 * length * dv + (dv + 4.0 * cv) * drift + 2.0
    reach_x = cu * length * length + 0.5 * length * du + (du + 4.0 * cu) * drift + 2.0
    regions = []
    for j in range(passes, 0, -1):  # the last pass's region first: what the gather reads
        ry, rx = math.ceil(reach_y), math.ceil(reach_x)
        regions.append((max(0, margin - ry), min(hc, margin + height + ry), max(0, margin - rx), min(wc, margin + width + rx)))
        scale = 0.25 / 2 ** (j - 1)
        reach_y += scale * dv + 2.0
        reach_x += scale * du + 2.0
    return regions[::-1]


@fork_safe
@numba.njit(parallel=True, cache=True, fastmath=False)
def finish_average(acc, count, rgb, alpha):  # pragma: no cover - compiled
    """The exposure's mean from :func:`gather`'s sums over ``count`` intervals, in one pass: ``acc``
    ((H, W, 4 or 5) float32) divided by ``count`` in place (float32), ``alpha`` ((H, W)) its channel 3
    clipped to [0, 1] and ``rgb`` ((H, W, 3)) its channels 0–2 at least 0: numpy's ``acc /= count``,
    ``np.clip`` and ``np.maximum`` (a NaN stays NaN; −0 becomes +0 in ``alpha``, as ``np.clip`` has it, and
    stays −0 in ``rgb``, as ``np.maximum`` has it), the same bits."""
    scale = np.float32(count)
    zero = np.float32(0.0)
    one = np.float32(1.0)
    for i in numba.prange(acc.shape[0]):
        for j in range(acc.shape[1]):
            for c in range(acc.shape[2]):
                acc[i, j, c] = acc[i, j, c] / scale
            for c in range(3):
                v = acc[i, j, c]
                rgb[i, j, c] = v if (v >= zero or v != v) else zero
            a = acc[i, j, 3]  # np.clip: a NaN stays, −0 becomes +0
            a = a if (a > zero or a != a) else zero
            alpha[i, j] = a if (a < one or a != a) else one


def occupancy(src: np.ndarray) -> np.ndarray:
    """(Hc + 1, Wc + 1) int32 summed-area table of ``alpha > 0`` (channel 3) of a canvas: a
    premultiplied pixel with alpha 0 is 0 in every channel, so a region it counts 0 in is empty."""
    sat = np.zeros((src.shape[0] + 1, src.shape[1] + 1), np.int32)
    np.cumsum(np.cumsum(src[..., 3] > 0, axis=0, dtype=np.int32), axis=1, out=sat[1:, 1:])
    return sat


#: Stand-in occupancy table of a canvas with no empty pixel: :func:`_empty` never skips.
FULL = np.zeros((1, 1), np.int32)


@numba.njit(cache=True, inline="always")
def _empty(sat, xa, xb, ya, yb):
    """Whether the canvas texels a bilinear read anywhere in [xa, xb] × [ya, yb] (array-index
    coordinates, clamped like the reads) can touch are all empty."""
    hc, wc = sat.shape[0] - 1, sat.shape[1] - 1
    if hc < 1 or wc < 1:
        return False  # FULL: nothing is empty
    x0 = min(max(int(math.floor(min(xa, xb))), 0), wc - 1)
    x1 = min(max(int(math.floor(max(xa, xb))) + 2, 1), wc)
    y0 = min(max(int(math.floor(min(ya, yb))), 0), hc - 1)
    y1 = min(max(int(math.floor(max(ya, yb))) + 2, 1), hc)
    return sat[y1, x1] - sat[y0, x1] - sat[y1, x0] + sat[y0, x0] == 0


@numba.njit(cache=True, inline="always")
def _corner(x, y, xmax, ymax, row, nc):
    """Bilinear tap at array-index (x, y) clamped to the canvas: flat index of its top-left
    texel and the two fractions."""
    x = min(max(x, np.float32(0.0)), xmax)
    y = min(max(y, np.float32(0.0)), ymax)
    x0 = np.uint64(x)
    y0 = np.uint64(y)
    return y0 * row + x0 * nc, x - np.float32(x0), y - np.float32(y0)


def doubling_pass(src: np.ndarray, field: np.ndarray, scale: np.float32, sat: np.ndarray, dst: np.ndarray,
                  region: tuple[int, int, int, int] | None = None) -> None:
    """``dst(q) = ½ [src(q − s·d(q)) + src(q + s·d(q))]`` with ``s = scale``: one box-length doubling
    (a box of length ℓ along ``d`` becomes two of them ``2 s |d|`` apart). ``sat``:
    :func:`occupancy` of ``src``; pixels whose two reads fall on empty texels are set to 0.
    ``region = (row0, row1, col0, col1)`` (half-open canvas pixels, :func:`pass_regions`): only those
    pixels of ``dst`` are written (the others keep what they held); default the whole canvas."""
    hc, wc = src.shape[0], src.shape[1]
    if hc < 2 or wc < 2:  # a bilinear read takes a 2 × 2 block of texels
        raise ValueError(f"doubling_pass: the canvas must be at least 2 × 2 pixels, got {wc} × {hc}")
    row0, row1, col0, col1 = (0, hc, 0, wc) if region is None else (int(v) for v in region)
    if not (0 <= row0 <= row1 <= hc and 0 <= col0 <= col1 <= wc):
        raise ValueError(f"doubling_pass: region {region} must lie within the canvas's {hc} rows and {wc} columns")
    _doubling_pass(src, field, scale, sat, dst, row0, row1, col0, col1)


@fork_safe
@numba.njit(parallel=True, fastmath=_FASTMATH, cache=True)
def _doubling_pass(src, field, scale, sat, dst, row0, row1, col0, col1):  # pragma: no cover - compiled
    """:func:`doubling_pass` over rows ``[row0, row1)`` and columns ``[col0, col1)``."""
    hc, wc, n_ch = src.shape
    if n_ch != 4 and n_ch != 5:
        raise ValueError("doubling_pass: src must have 4 or 5 channels")
    xmax = np.float32(wc - 1.001)
    ymax = np.float32(hc - 1.001)
    half = np.float32(0.5)
    one = np.float32(1.0)
    s = np.float32(scale)
    flat = src.reshape(-1)
    out = dst.reshape(-1)
    nc = np.uint64(n_ch)
    c4 = np.uint64(4)
    row = np.uint64(wc) * nc
    for i in numba.prange(row0, row1):
        for j in range(col0, col1):
            su = s * field[i, j, 2]
            sv = s * field[i, j, 3]
            base = (np.uint64(i) * np.uint64(wc) + np.uint64(j)) * nc
            if _empty(sat, np.float32(j) - su, np.float32(j) + su, np.float32(i) - sv, np.float32(i) + sv):
                for c in range(n_ch):
                    out[base + np.uint64(c)] = np.float32(0.0)
                continue
            pa, ax, ay = _corner(np.float32(j) - su, np.float32(i) - sv, xmax, ymax, row, nc)
            pb, bx, by = _corner(np.float32(j) + su, np.float32(i) + sv, xmax, ymax, row, nc)
            wa00 = half * (one - ax) * (one - ay)
            wa01 = half * ax * (one - ay)
            wa10 = half * (one - ax) * ay
            wa11 = half * ax * ay
            wb00 = half * (one - bx) * (one - by)
            wb01 = half * bx * (one - by)
            wb10 = half * (one - bx) * by
            wb11 = half * bx * by
            _weighted_taps4(out, base, flat, (pa, pa + nc, pa + row, pa + row + nc, pb, pb + nc, pb + row, pb + row + nc),
                            (wa00, wa01, wa10, wa11, wb00, wb01, wb10, wb11))
            if n_ch > 4:
                _weighted_taps1(out, base + c4, flat, (pa + c4, pa + nc + c4, pa + row + c4, pa + row + nc + c4,
                                                       pb + c4, pb + nc + c4, pb + row + c4, pb + row + nc + c4),
                                (wa00, wa01, wa10, wa11, wb00, wb01, wb10, wb11))

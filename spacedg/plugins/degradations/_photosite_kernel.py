"""The photosites' noise binned to the output in one compiled pass (not a plugin): :func:`binned_noise`.

:func:`._photosites.binned_capture` resamples the exposed signal onto the photosite grid with OpenCV's
``INTER_AREA`` (sites smaller than pixels: an enlargement), draws every site's noise with
:func:`~._sensor.sensor_capture` and area-averages the noise back to the output with ``INTER_AREA`` (a
shrink). At 640 × 480 the grid holds 1557 × 1168 × 3 values: the two resamples cost ~6–10 ms a view and
the sites' signal and noise ~44 MB of memory traffic, around a draw of ~25–40 ms.

Here the same three steps run per output row, in rows of sites that stay in cache: each site row's signal
is made from the output's rows as OpenCV's enlargement makes it, its noise drawn by the sensor kernel's own
block functions (counters = the flat index into the (rows, columns, 3) site array, as there), and summed into
the output rows it overlaps as OpenCV's area shrink sums it. The float32 operations and their order are
OpenCV's (``resizeGeneric_`` with linear taps in area mode: a row along x, then two rows mixed along y;
``resizeArea_``: each source row's weighted sum along x, then the rows' weighted sum, in table order), so
the bytes are those of ``cv2.resize`` both ways (tested against it at many sizes). The output is split into
chunks of rows, one a thread at a time; a site row shared by the last output row of one chunk and the first
of the next is drawn in both (the same values: the draws are counter-based). Compiling it on an empty cache
takes ~12 s after the sensor kernel (``spacedg kernels``' images group), whose block functions it shares.
Used only where this process's OpenCV computes the two resamples as it does (:func:`opencv_agrees`).

Used where OpenCV takes those two paths: a grid larger than the image along both axes, and not an integer
multiple of it along both (OpenCV's fast area path sums 2 × 2 and other integer blocks in another order).
"""

from __future__ import annotations

import functools
import math

import numba
import numpy as np
from numba.core import types
from numba.core.imputils import impl_ret_borrowed
from numba.extending import intrinsic

from spacedg.errors import InvalidDataError
from spacedg.plugins.degradations._sensor import (
    _BLOCK, READ_GAUSSIAN, READ_LAMBDA_DEFAULT, _read_noise, _scalar_block, _stream_keys, _vector_block, check_sensor_parameters,
)
from spacedg.render import kernel_cache
from spacedg.render.cpu_target import vectorise_table_lookups
from spacedg.render.threads import fork_safe

__all__ = ["binned_noise", "enlarge_reference", "enlarge_taps", "fits", "opencv_agrees", "shrink_reference", "shrink_table"]


def fits(width: int, height: int, grid: tuple[int, int]) -> bool:
    """Whether ``cv2.resize`` takes the paths this module reproduces for a ``width × height`` image on a
    ``grid = (columns, rows)`` of sites: an enlargement along both axes, whose shrink back is OpenCV's
    general area resampling (not its fast path for integer ratios along both axes: ``|1/(n/N) − round| < ε``),
    and this process's OpenCV computes them as this module does (:func:`opencv_agrees`)."""
    columns, rows = grid
    if not (columns > width and rows > height):
        return False
    scale_x, scale_y = 1.0 / (width / columns), 1.0 / (height / rows)  # OpenCV's scale of the shrink
    integer = abs(scale_x - round(scale_x)) < np.finfo(np.float64).eps and abs(scale_y - round(scale_y)) < np.finfo(np.float64).eps
    return not integer and opencv_agrees()


@functools.lru_cache(maxsize=1)
def opencv_agrees() -> bool:
    """Whether this process's ``cv2.resize`` (``INTER_AREA``) gives the bytes of :func:`enlarge_reference` and
    :func:`shrink_reference` (the float32 operations the kernel does) on a fixed 64 × 48 image enlarged to
    157 × 117 and back, checked once. OpenCV's vertical enlargement step is a multiply-add
    (``v_muladd``): unfused on an x86 build whose baseline is SSE3 (the wheels this project pins), fused
    where the baseline has FMA (aarch64, some x86 builds), and a resize HAL may take over; there the
    photosites keep the two ``cv2.resize`` calls instead of this kernel, so the bytes stay OpenCV's."""
    import cv2

    rng = np.random.default_rng(0)
    image = (rng.random((48, 64, 3)) * 3.0 - 1.0).astype(np.float32)
    if enlarge_reference(image, 157, 117).tobytes() != cv2.resize(image, (157, 117), interpolation=cv2.INTER_AREA).tobytes():
        return False
    big = rng.standard_normal((117, 157, 3)).astype(np.float32)
    return shrink_reference(big, 64, 48).tobytes() == cv2.resize(big, (64, 48), interpolation=cv2.INTER_AREA).tobytes()


def enlarge_reference(image: np.ndarray, columns: int, rows: int) -> np.ndarray:
    """``image`` (h, w, c) float32 enlarged with :func:`enlarge_taps` in numpy: along x, then two rows mixed along y, the
    float32 multiplications and additions of the kernel (and of OpenCV's unfused build)."""
    x0, x1, a0, a1 = enlarge_taps(image.shape[1], columns)
    y0, y1, b0, b1 = enlarge_taps(image.shape[0], rows)
    tail = (x0 == x1)[None, :, None]
    wide = np.where(tail, image[:, x0] * np.float32(1.0), image[:, x0] * a0[None, :, None] + image[:, x1] * a1[None, :, None])
    return (wide[y0] * b0[:, None, None] + wide[y1] * b1[:, None, None]).astype(np.float32)


def shrink_reference(image: np.ndarray, width: int, height: int) -> np.ndarray:
    """``image`` (H, W, c) float32 shrunk with :func:`shrink_table` in numpy: each source row's sums along x from 0 in
    table order, then each output row the first row's sum times its weight plus the others' in order."""
    xs, xt, xw = shrink_table(image.shape[1], width)
    ys, yt, yw = shrink_table(image.shape[0], height)
    sums = np.zeros((image.shape[0], width, image.shape[2]), np.float32)
    counts = np.diff(xs)
    for m in range(int(counts.max())):  # the m-th tap of every output column at once: each column's taps in order
        has = counts > m
        at = xs[:-1][has] + m
        sums[:, has] = sums[:, has] + image[:, xt[at]] * xw[at][None, :, None]
    out = np.empty((height, width, image.shape[2]), np.float32)
    for dy in range(height):
        total = yw[ys[dy]] * sums[yt[ys[dy]]]
        for j in range(ys[dy] + 1, ys[dy + 1]):
            total = total + yw[j] * sums[yt[j]]
        out[dy] = total
    return out


def enlarge_taps(source: int, size: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """OpenCV's ``INTER_AREA`` taps of an enlargement along one axis, ``source`` samples to ``size > source``:
    ``(i0, i1, w0, w1)``, output ``k`` = ``src[i0]·w0 + src[i1]·w1`` (float32 weights), the second tap absent
    (``i1 == i0``, ``w1 == 0``) past the last source sample, where OpenCV copies ``src[i0]·1``.

    OpenCV (``resize``, area mode of its linear taps): ``sx = ⌊k·scale⌋``, ``f = (k + 1) − (sx + 1)/scale``
    in float32, ``f ≤ 0 → 0`` else its fractional part (the share of the output sample past the source
    sample's edge), ``scale = 1 / (size / source)``; at the last source sample ``f = 0``. Along x OpenCV copies
    that last sample; along y it mixes the clamped row with itself, ``S·w0 + S·w1`` with ``w1 < 1e-12`` (``w0``
    rounds to 1): ``S`` for any finite ``S``, which the exposed signal always is."""
    inverse = size / source
    scale = 1.0 / inverse
    first = np.empty(size, np.int64)
    second = np.empty(size, np.int64)
    weights = np.empty((2, size), np.float32)
    for k in range(size):
        sx = math.floor(k * scale)
        fraction = np.float32((k + 1) - (sx + 1) * inverse)
        fraction = np.float32(0.0) if fraction <= 0 else np.float32(fraction - math.floor(fraction))
        if sx >= source - 1:  # past the last sample: OpenCV's tail copies it
            sx, fraction = source - 1, np.float32(0.0)
        first[k] = sx
        second[k] = sx if sx >= source - 1 else sx + 1
        weights[0, k] = np.float32(1.0) - fraction
        weights[1, k] = fraction
    return first, second, weights[0], weights[1]


def shrink_table(source: int, size: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """OpenCV's ``INTER_AREA`` table of a shrink along one axis (``computeResizeAreaTab``), ``source`` samples to
    ``size < source``: ``(starts, taps, weights)``, output ``k`` = ``Σ src[taps[j]]·weights[j]`` over
    ``j ∈ [starts[k], starts[k + 1])`` in that order (source samples increasing). Each output sample covers
    ``scale = 1 / (size / source)`` source samples from ``k·scale``: the partly covered ones at its ends (more
    than 10⁻³ of a sample) weighted by their share, the whole ones by ``1 / scale``, all ÷ the cell's width."""
    scale = 1.0 / (size / source)
    starts = [0]
    taps: list[int] = []
    weights: list[np.float32] = []
    for k in range(size):
        start = k * scale
        end = start + scale
        cell = min(scale, source - start)
        first, last = math.ceil(start), math.floor(end)
        last = min(last, source - 1)
        first = min(first, last)
        if first - start > 1e-3:
            taps.append(first - 1)
            weights.append(np.float32((first - start) / cell))
        for sx in range(first, last):
            taps.append(sx)
            weights.append(np.float32(1.0 / cell))
        if end - last > 1e-3:
            taps.append(last)
            weights.append(np.float32(min(min(end - last, 1.0), cell) / cell))
        starts.append(len(taps))
    return np.array(starts, np.int64), np.array(taps, np.int64), np.array(weights, np.float32)


def binned_noise(
    signal: np.ndarray, grid: tuple[int, int], *, key: int, k: float, sigma_read: float, read_model: int = READ_GAUSSIAN,
    read_lambda: float = READ_LAMBDA_DEFAULT,
    out: np.ndarray | None = None, chunks: int | None = None,
) -> np.ndarray:
    """``cv2.resize(noise, (W, H), INTER_AREA)`` of ``noise = sensor_capture(cv2.resize(signal, grid, INTER_AREA),
    exposure=1, key=key, noise=True, k=…, sigma_read=…, read_model=…, read_lambda=…)``, bit for bit, without the
    grid's arrays (module docstring). ``signal``: float32 (H, W, 3), the exposed signal (finite, within the sensor's
    cap); ``grid``: ``(columns, rows)`` of sites, :func:`fits`. ``out``: float32 (H, W, 3) to write into (default new);
    ``chunks``: row chunks (default four a numba thread; the bytes do not depend on it)."""
    height, width = signal.shape[:2]
    if signal.dtype != np.float32 or signal.ndim != 3 or signal.shape[2] != 3 or not fits(width, height, grid):
        raise InvalidDataError(
            f"binned_noise: a float32 (H, W, 3) signal on a grid larger than it along both axes (not an integer multiple of it "
            f"along both), with an OpenCV that agrees (opencv_agrees()), got {signal.dtype} {signal.shape} on {grid}; use "
            "_photosites.binned_capture, which falls back to cv2.resize"
        )
    check_sensor_parameters("binned_noise", k=k, sigma_read=sigma_read, read_model=read_model, key=key)
    if out is not None and (
        out.dtype != np.float32 or out.shape != signal.shape or not out.flags.c_contiguous or not out.flags.writeable
        or np.may_share_memory(out, signal)
    ):
        raise InvalidDataError(
            f"binned_noise: out must be a writeable C-contiguous float32 array of the signal's shape {signal.shape} apart from it, "
            f"got {out.dtype} {out.shape}"
        )
    columns, rows = grid
    (x_first, x_second, x_w0, x_w1), (y_first, y_second, y_w0, y_w1), (x_starts, x_taps, x_weights), (y_starts, y_taps, y_weights) = _tables(
        width, height, columns, rows
    )
    out = np.empty(signal.shape, np.float32) if out is None else out
    read_scale, _ = _read_noise(float(sigma_read), int(read_model), float(read_lambda))
    if chunks is None:
        chunks = 4 * numba.get_num_threads()
    _binned_noise_kernel(
        kernel_cache.read_only(np.ascontiguousarray(signal)), x_first, x_second, x_w0, x_w1, y_first, y_second, y_w0, y_w1,
        x_starts, x_taps, x_weights, y_starts, y_taps, y_weights, columns, float(k), read_scale, int(read_model), float(read_lambda),
        np.uint64(key), max(1, min(int(chunks), height)), False, True, out,
    )
    return out


@functools.lru_cache(maxsize=16)
def _tables(width: int, height: int, columns: int, rows: int) -> tuple[tuple[np.ndarray, ...], ...]:
    """The enlargement taps and shrink tables of both axes of one (image, grid) size, read-only: built in Python
    (~13 ms at 640 × 480), kept for the last 16 sizes (every view of a size asks the same)."""
    tables = (enlarge_taps(width, columns), enlarge_taps(height, rows), shrink_table(columns, width), shrink_table(rows, height))
    return tuple(tuple(kernel_cache.read_only(array) for array in table) for table in tables)


@intrinsic
def _frozen(typingctx, array):  # type: ignore[no-untyped-def]
    """``array`` typed read-only (the same memory and data model): the sensor kernel hands its block functions slices of
    its frozen input, so a site row passed this way calls the same compiled functions (typed writable, it compiled
    each of them again: 26 s more for this kernel on an empty cache)."""
    if not isinstance(array, types.Array):
        return None

    def codegen(context, builder, signature, args):  # type: ignore[no-untyped-def]
        return impl_ret_borrowed(context, builder, signature.return_type, args[0])

    return array.copy(readonly=True)(array), codegen


@numba.njit(cache=True, inline="always")
def _enlarged_row(image, row, first, second, w0, w1, dest):  # pragma: no cover - compiled
    """Row ``row`` of ``image`` (H, W, 3) enlarged along x into ``dest`` (columns × 3, flat): OpenCV's horizontal step."""
    for k in range(first.shape[0]):
        a, b = first[k], second[k]
        if a == b:  # past the last sample: OpenCV's tail, the sample times one
            for c in range(3):
                dest[3 * k + c] = image[row, a, c] * np.float32(1.0)
        else:
            for c in range(3):
                dest[3 * k + c] = image[row, a, c] * w0[k] + image[row, b, c] * w1[k]


@numba.njit(cache=True, inline="always")
def _area_sums(row, starts, taps, weights, sums):  # pragma: no cover - compiled
    """``sums[3·dx + c] = Σ row[3·taps[t] + c]·weights[t]`` over ``t ∈ [starts[dx], starts[dx + 1])``, from 0 and in
    table order (OpenCV's ``buf``: the same float32 additions, kept in registers rather than its buffer)."""
    zero = np.float32(0.0)
    for dx in range(sums.shape[0] // 3):
        r, g, b = zero, zero, zero
        for t in range(starts[dx], starts[dx + 1]):
            at, weight = 3 * taps[t], weights[t]
            r = r + row[at] * weight
            g = g + row[at + 1] * weight
            b = b + row[at + 2] * weight
        sums[3 * dx] = r
        sums[3 * dx + 1] = g
        sums[3 * dx + 2] = b


@fork_safe
@numba.njit(parallel=True, cache=True, fastmath=False)
def _binned_noise_kernel(
    signal, x_first, x_second, x_w0, x_w1, y_first, y_second, y_w0, y_w1, x_starts, x_taps, x_weights, y_starts, y_taps, y_weights,
    columns, k, read_scale, read_model, read_lambda, key, chunks, clip, noise, out,
):  # pragma: no cover - compiled; tested against cv2.resize and sensor_capture
    """:func:`binned_noise`'s pass: the output's rows in ``chunks`` chunks, one a thread at a time (:func:`_binned_rows`).
    ``clip`` and ``noise`` are the sensor kernel's flags (False, True), passed as values: written as constants here, numba
    typed them as literals and compiled the sensor's block functions again for them (~25 s on an empty cache)."""
    height = signal.shape[0]
    keys, key_mix = _stream_keys(key)
    per_chunk = (height + chunks - 1) // chunks
    for chunk in numba.prange(chunks):
        _binned_rows(
            signal, x_first, x_second, x_w0, x_w1, y_first, y_second, y_w0, y_w1, x_starts, x_taps, x_weights, y_starts, y_taps, y_weights,
            columns, k, read_scale, read_model, read_lambda, keys, key_mix, chunk * per_chunk, min(chunk * per_chunk + per_chunk, height), clip,
            noise, out,
        )


@numba.njit(cache=True, fastmath=False)
def _binned_rows(
    signal, x_first, x_second, x_w0, x_w1, y_first, y_second, y_w0, y_w1, x_starts, x_taps, x_weights, y_starts, y_taps, y_weights,
    columns, k, read_scale, read_model, read_lambda, keys, key_mix, top, bottom, clip, noise, out,
):  # pragma: no cover - compiled; tested against cv2.resize and sensor_capture
    """Output rows ``[top, bottom)`` of :func:`binned_noise`: each site row they read once (its signal from the two output
    rows OpenCV mixes, kept while the next site row mixes the same; its noise in blocks of the sensor kernel's; its
    area sums along x), each output row the weighted sum of its site rows' sums. A compiled function of its own, not
    inlined into the parallel loop's body (which numba outlines into a function of its own): it carries the sensor
    blocks' table-lookup tuning (:func:`~spacedg.render.cpu_target.vectorise_table_lookups`; on a Zen 3 host, one thread,
    640 × 480 at low light's bench pitch: 163–180 → 113–140 ms with it here, where the blocks alone with it took 163–270)."""
    vectorise_table_lookups()
    width = signal.shape[1]
    read_key, shot_key = keys[0], keys[1]
    inv_k = 1.0 / k if k > 0.0 else 0.0
    gaussian = read_model == READ_GAUSSIAN
    length = 3 * columns  # values in a site row
    upper = np.empty(length, np.float32)  # the output rows enlarged along x: the upper and lower of a site row's two
    lower = np.empty(length, np.float32)
    upper_row, lower_row = -1, -1
    site = np.empty(length, np.float32)  # a site row's signal
    drawn = np.empty(length, np.float32)  # its noise
    staged = np.empty(_BLOCK, np.float32)
    to_scalar = np.zeros(_BLOCK, np.uint8)
    sums = np.empty(3 * width, np.float32)  # a site row's area sums along x
    total = np.empty(3 * width, np.float32)  # an output row's
    summed_row = -1
    for dy in range(top, bottom):
        for j in range(y_starts[dy], y_starts[dy + 1]):
            sy = y_taps[j]
            if sy != summed_row:
                a, b = y_first[sy], y_second[sy]
                if upper_row != a:
                    if lower_row == a:  # the lower row of the last site row is this one's upper
                        upper, lower = lower, upper
                        upper_row, lower_row = a, upper_row
                    else:
                        _enlarged_row(signal, a, x_first, x_second, x_w0, x_w1, upper)
                        upper_row = a
                if lower_row != b:
                    _enlarged_row(signal, b, x_first, x_second, x_w0, x_w1, lower)
                    lower_row = b
                b0, b1 = y_w0[sy], y_w1[sy]
                for i in range(length):
                    site[i] = upper[i] * b0 + lower[i] * b1
                frozen = _frozen(site)
                bits = frozen.view(np.int32)
                for lo in range(0, length, _BLOCK):
                    hi = min(lo + _BLOCK, length)
                    first = sy * length + lo
                    _vector_block(frozen[lo:hi], bits[lo:hi], first, staged, to_scalar, drawn[lo:hi], gaussian, 1.0, k, inv_k,
                                  read_key, shot_key, read_scale, clip, math.inf, noise)
                    _scalar_block(frozen[lo:hi], first, drawn[lo:hi], to_scalar, 1.0, k, inv_k, read_scale, read_model, read_lambda,
                                  clip, math.inf, keys, key_mix, noise)
                _area_sums(drawn, x_starts, x_taps, x_weights, sums)
                summed_row = sy
            beta = y_weights[j]
            if j == y_starts[dy]:
                for i in range(3 * width):
                    total[i] = beta * sums[i]
            else:
                for i in range(3 * width):
                    total[i] += beta * sums[i]
        for dx in range(width):
            for c in range(3):
                out[dy, dx, c] = total[3 * dx + c]

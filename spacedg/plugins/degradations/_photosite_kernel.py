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
takes ~13 s (``spacedg kernels``' images group), the sensor kernel's block functions shared with it.

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

from spacedg.plugins.degradations._sensor import (
    _BLOCK, _DRAW_KEYS, READ_GAUSSIAN, READ_LAMBDA_DEFAULT, _draw_key, _mix, _read_noise, _scalar_block, _vector_block,
)
from spacedg.render import kernel_cache
from spacedg.render.threads import fork_safe

__all__ = ["binned_noise", "fits", "enlarge_taps", "shrink_table"]


def fits(width: int, height: int, grid: tuple[int, int]) -> bool:
    """Whether ``cv2.resize`` takes the paths this module reproduces for a ``width × height`` image on a
    ``grid = (columns, rows)`` of sites: an enlargement along both axes, whose shrink back is OpenCV's
    general area resampling (not its fast path for integer ratios along both axes: ``|1/(n/N) − round| < ε``)."""
    columns, rows = grid
    if not (columns > width and rows > height):
        return False
    scale_x, scale_y = 1.0 / (width / columns), 1.0 / (height / rows)  # OpenCV's scale of the shrink
    return not (abs(scale_x - round(scale_x)) < np.finfo(np.float64).eps and abs(scale_y - round(scale_y)) < np.finfo(np.float64).eps)


def enlarge_taps(source: int, size: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """OpenCV's ``INTER_AREA`` taps of an enlargement along one axis, ``source`` samples to ``size > source``:
    ``(i0, i1, w0, w1)``, output ``k`` = ``src[i0]·w0 + src[i1]·w1`` (float32 weights), the second tap absent
    (``i1 == i0``, ``w1 == 0``) past the last source sample, where OpenCV copies ``src[i0]·1``.

    OpenCV (``resize``, area mode of its linear taps): ``sx = ⌊k·scale⌋``, ``f = (k + 1) − (sx + 1)/scale``
    in float32, ``f ≤ 0 → 0`` else its fractional part (the share of the output sample past the source
    sample's edge), ``scale = 1 / (size / source)``; at the last source sample ``f = 0``."""
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
        raise ValueError(f"binned_noise: a float32 (H, W, 3) signal on a grid larger than it along both axes, got {signal.dtype} {signal.shape} on {grid}")
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
    key_mix = _mix(key)
    keys = np.empty(_DRAW_KEYS, dtype=np.uint64)
    for draw in range(_DRAW_KEYS):
        keys[draw] = _draw_key(key_mix, draw)
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
    area sums along x), each output row the weighted sum of its site rows' sums."""
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

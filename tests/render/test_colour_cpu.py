"""Compiled sRGB decode / exact 8-bit encode against the float64 formulas."""

from __future__ import annotations

import numpy as np

from spacedg.render.colour import linear_to_srgb, srgb_to_linear
from spacedg.render.colour_cpu import decode_srgb, encode_srgb_u8, encode_thresholds


def test_decode_matches_formula() -> None:
    x = np.random.default_rng(0).uniform(-0.1, 1.5, 200_000).astype(np.float32)
    x[:4] = [0.0, 0.04045, 1.0, 3.0]
    ref = srgb_to_linear(x.astype(np.float64))
    out = decode_srgb(x)
    assert out.dtype == np.float32 and out.shape == x.shape
    in_range = x <= 1.0
    assert np.max(np.abs(out - ref)[in_range]) < 1e-7
    assert np.max(np.abs(out - ref) / np.maximum(ref, 1e-6)) < 3e-6
    assert decode_srgb(np.array([np.nan, -np.inf, -1.0], np.float32)).tolist() == [0.0, 0.0, 0.0]


def test_encode_is_exact_rounding_of_the_clipped_curve() -> None:
    thresholds = encode_thresholds()[1:]
    x = np.concatenate([
        np.random.default_rng(1).uniform(-0.05, 1.1, 500_000),
        thresholds, np.nextafter(thresholds, -np.inf), np.nextafter(thresholds, np.inf),
    ]).astype(np.float32)
    ref = np.round(255.0 * linear_to_srgb(np.clip(x.astype(np.float64), 0.0, 1.0))).astype(np.uint8)
    assert np.array_equal(encode_srgb_u8(x), ref)


def test_encode_extremes_and_round_trip() -> None:
    out = encode_srgb_u8(np.array([np.nan, np.inf, -np.inf, 1e30, -0.0, 1.0], np.float32))
    assert out.tolist() == [0, 255, 0, 255, 0, 255]
    codes = np.arange(256, dtype=np.float32) / 255.0
    assert np.array_equal(encode_srgb_u8(decode_srgb(codes)), np.arange(256, dtype=np.uint8))
    image = np.random.default_rng(2).random((7, 5, 3), dtype=np.float32)
    assert encode_srgb_u8(image).shape == (7, 5, 3)


def test_branch_free_kernels_take_each_values_own_case_on_any_bits() -> None:
    """The kernels are branch-free (every case computed, one kept): on float32 values drawn from
    every bit pattern (NaN payloads, infinities, subnormals, negatives, HDR) and on the edges of
    every case and table knot, each value gets exactly its own case's arithmetic, written out here
    in numpy float64 (the old branching kernels' rules; all 2³² patterns were compared once, 0 differed)."""
    from spacedg.render import colour_cpu

    rng = np.random.default_rng(7)
    lut = colour_cpu._DECODE_LUT
    scale = (lut.shape[0] - 1) / (1.0 - colour_cpu._TOE)
    knots = (colour_cpu._TOE + np.arange(lut.shape[0]) / scale).astype(np.float32)
    edges = np.array([0.0, -0.0, colour_cpu._TOE, 1.0, 1.0 / 8192, 8191.0 / 8192, 1e-45, 3e38], np.float32)
    x = np.concatenate([
        rng.integers(0, 2**32, 2_000_000, dtype=np.uint64).astype(np.uint32).view(np.float32),
        rng.uniform(-0.1, 1.2, 500_000).astype(np.float32),
        *(np.nextafter(v, t) for v in (knots, edges) for t in (np.float32(-np.inf), np.float32(np.inf))), knots, edges,
    ])
    with np.errstate(all="ignore"):  # NaN payloads, and the cases not taken overflow on purpose
        x64 = x.astype(np.float64)
        s = (x64 - colour_cpu._TOE) * scale
        j = np.clip(np.nan_to_num(np.floor(s), nan=0.0), 0, lut.shape[0] - 2).astype(np.int64)
        table = lut[j] + (s - j) * (lut[j + 1] - lut[j])
        power = colour_cpu._decode_exact(x64)  # the power law above the toe
        want = np.where(~(x64 > 0.0), 0.0, np.where(x64 <= colour_cpu._TOE, x64 / 12.92, np.where(x64 < 1.0, table, power))).astype(np.float32)
    assert np.array_equal(decode_srgb(x).view(np.uint32), want.view(np.uint32))

    base, nxt = colour_cpu._ENCODE_BASE, colour_cpu._ENCODE_NEXT
    b = np.clip(np.nan_to_num(np.floor(x64 * base.shape[0]), nan=0.0), 0, base.shape[0] - 1).astype(np.int64)
    codes = np.where(~(x64 > 0.0), 0, np.where(x64 >= 1.0, 255, base[b] + (x64 >= nxt[b]))).astype(np.uint8)
    assert np.array_equal(encode_srgb_u8(x), codes)

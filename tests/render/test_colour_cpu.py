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

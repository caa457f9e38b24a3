"""The torch 8-bit sRGB encode gives exactly the compiled encode's codes."""

from __future__ import annotations

import numpy as np
import torch

from spacedg.render import colour_torch
from spacedg.render.colour_cpu import encode_srgb_u8


def test_encode_is_exact() -> None:
    values = np.concatenate([np.linspace(-0.1, 1.2, 20011), [np.nan, np.inf, -np.inf, 0.0, 1.0]]).astype(np.float32)
    np.testing.assert_array_equal(colour_torch.encode_srgb_u8(torch.from_numpy(values)).numpy(), encode_srgb_u8(values))
    image = np.random.default_rng(0).uniform(0.0, 1.3, (48, 64, 3)).astype(np.float32) ** 2.2
    image[:8, :8] = 3.0  # HDR
    out = colour_torch.encode_srgb_u8(torch.from_numpy(image))
    assert out.dtype == torch.uint8 and out.shape == image.shape
    np.testing.assert_array_equal(out.numpy(), encode_srgb_u8(image))

"""sRGB transfer functions (IEC 61966-2-1), for numpy arrays and torch tensors.

3DGS captures store *display-referred* colour (the training images were sRGB-encoded), so
the compositor's output is sRGB-encoded light. The renderer decodes it once with
:func:`srgb_to_linear` to give linear HDR light (values above 1, such as a bright window,
continue the same power law and stay above 1); the degradation pipeline encodes back with
:func:`linear_to_srgb` after its linear-light stages. Negative inputs are treated as 0.
"""

from __future__ import annotations

from typing import TypeVar

import numpy as np

ArrayT = TypeVar("ArrayT")


def _ops(x: object) -> tuple:
    if type(x).__module__.startswith("torch"):
        import torch

        return torch.where, torch.clamp, lambda a, b: torch.pow(a, b)
    return np.where, lambda a, min: np.maximum(a, min), np.power


def srgb_to_linear(encoded: ArrayT) -> ArrayT:
    """sRGB-encoded values (0–1, HDR above 1 allowed) → linear light, same array type and dtype."""
    where, clamp_min, power = _ops(encoded)
    x = clamp_min(encoded, min=0.0)
    return where(x <= 0.04045, x / 12.92, power((x + 0.055) / 1.055, 2.4))


def linear_to_srgb(linear: ArrayT) -> ArrayT:
    """Linear light → sRGB-encoded values (inverse of :func:`srgb_to_linear`; no clipping above 1)."""
    where, clamp_min, power = _ops(linear)
    x = clamp_min(linear, min=0.0)
    return where(x <= 0.0031308, x * 12.92, 1.055 * power(x, 1.0 / 2.4) - 0.055)

"""The exact 8-bit sRGB encode on torch tensors, on the tensor's device: the twin of
:func:`spacedg.render.colour_cpu.encode_srgb_u8` (same codes, bit for bit).

Every linear value is looked up among the float64 decision thresholds of the 8-bit codes
(:func:`spacedg.render.colour_cpu.encode_thresholds`, computed once and kept per device), so the
code is ``round(255 · linear_to_srgb(clip(x, 0, 1)))`` evaluated exactly. Imported lazily by the
pipeline's device path: torch loads on first use, never with ``import spacedg``.
"""

from __future__ import annotations

import torch

__all__ = ["encode_srgb_u8"]

_THRESHOLDS: dict[torch.device, torch.Tensor] = {}


def _thresholds(device: torch.device) -> torch.Tensor:
    """(255,) float64 thresholds of codes 1..255 on ``device`` (built once per device)."""
    if device not in _THRESHOLDS:
        from spacedg.render.colour_cpu import encode_thresholds  # numpy tables (numba module)

        _THRESHOLDS[device] = torch.from_numpy(encode_thresholds()[1:].copy()).to(device)
    return _THRESHOLDS[device]


def encode_srgb_u8(linear: torch.Tensor) -> torch.Tensor:
    """Linear float32 tensor → uint8 sRGB codes on the same device, same shape.

    Clips to [0, 1] first; NaN and negative values give 0, values ≥ 1 and +inf give 255;
    exactly :func:`spacedg.render.colour_cpu.encode_srgb_u8` on the same values.
    """
    thresholds = _thresholds(linear.device)
    x = linear.to(torch.float64)
    code = torch.searchsorted(thresholds, x.reshape(-1).contiguous(), right=True).reshape(x.shape)
    code = torch.where(x > 0, code, torch.zeros_like(code))
    code = torch.where(x >= 1.0, torch.full_like(code, 255), code)
    return code.to(torch.uint8)

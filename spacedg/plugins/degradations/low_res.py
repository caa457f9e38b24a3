"""Low resolution (digital, display stage): area-downsample by ``scale``, then upsample back.

Model: the paper's "Low-resolution". The encoded 8-bit sRGB image (W × H) is reduced to
``max(1, round(W·s)) × max(1, round(H·s))`` with OpenCV's area averaging (``INTER_AREA``, the
box filter a sensor with larger pixels would apply), then enlarged back to W × H with bilinear
interpolation (``INTER_LINEAR``, pixel centres aligned), so the model input keeps its size
while the high frequencies are gone.

Conventions: uint8 (H, W, 3) RGB in and out; the averaging is done on the sRGB codes, as an
image pipeline that resizes a stored JPEG/PNG would (not in linear light). ``scale = 1`` is
the exact identity (a copy). Deterministic: ``rng`` is not used.

Parameter: ``scale`` ("1", hard limits [1e-6, 1]; lower is harsher; below ``1/W`` the image
becomes one pixel wide). Presets: ``bench`` [0.02, 0.05] (the paper's table: a 640-px image
becomes 13–32 px wide); severities ``1``–``5``: [0.5, 0.7], [0.3, 0.45], [0.15, 0.25],
[0.07, 0.12], [0.02, 0.05].

**Size-invariant** (decision): the presets' ``scale`` is stated at the reference image size
(:data:`~spacedg.plugins.specs.REFERENCE_IMAGE_SIZE`, 1752 × 1168: bench reduces its shorter
side to 23–58 px) and scales inversely with the output (``ParamRange(per_size=-1)``, clamped
at 1), so the reduced image has the same pixels whatever the output size: a low-resolution
camera's resolution does not depend on the size its picture is shown at. At 640 × 360 the bench
``scale`` is 0.065–0.16 (the reduced image is 42 × 23 to 104 × 58, as at 1920 × 1080); an
output already smaller than the reduced image is left as it is. The provenance records the
``scale`` used. An explicit ``scale`` is the output's fraction, as before.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import cv2
import numpy as np

from spacedg.plugins.degradations.common import check_display_image, severity_ladder
from spacedg.plugins.hookspecs import registering
from spacedg.plugins.specs import (
    Category,
    DegradationSpec,
    ParamSpec,
    Stage,
)

__all__ = ["SPEC", "low_res", "reduced_size"]


def reduced_size(width: int, height: int, scale: float) -> tuple[int, int]:
    """``(max(1, round(W·s)), max(1, round(H·s)))``: the size the image is reduced to."""
    return max(1, int(round(width * scale))), max(1, int(round(height * scale)))


def low_res(image: np.ndarray, scale: float) -> np.ndarray:
    """Area-downsample a uint8 RGB image by ``scale`` and bilinearly upsample it back (new array)."""
    image = check_display_image(image, "low_res")
    height, width = image.shape[:2]
    small_w, small_h = reduced_size(width, height, scale)
    if (small_w, small_h) == (width, height):
        return image.copy()
    small = cv2.resize(image, (small_w, small_h), interpolation=cv2.INTER_AREA)
    return cv2.resize(small, (width, height), interpolation=cv2.INTER_LINEAR)


def apply(image: np.ndarray, params: Mapping[str, Any], rng: np.random.Generator) -> np.ndarray:
    """Display-stage ``apply``: ``params = {"scale": s}``; ``rng`` unused."""
    return low_res(image, SPEC.validate_params(params)["scale"])


def apply_torch(image: Any, params: Mapping[str, Any], rng: np.random.Generator) -> Any:
    """Device twin of :func:`apply` on a uint8 torch tensor (:mod:`spacedg.plugins.degradations.device`, imported here lazily)."""
    from spacedg.plugins.degradations import device

    height, width = image.shape[:2]
    return device.low_res_torch(image, *reduced_size(width, height, SPEC.validate_params(params)["scale"]))


SPEC = DegradationSpec(
    name="low_res", category=Category.DIGITAL, stage=Stage.DISPLAY,
    params=(ParamSpec("scale", "1", "Linear size factor of the reduced image.", low=1e-6, high=1.0, harsher="lower"),),
    presets=severity_ladder("scale", ((0.5, 0.7), (0.3, 0.45), (0.15, 0.25), (0.07, 0.12), (0.02, 0.05)), per_size=-1),
    apply=apply,
    apply_torch=apply_torch,
    description="Area-downsample the 8-bit image by scale s to max(1, round(W·s)) × max(1, round(H·s)), bilinear upsample back.",
    order=10.0,
)

spacedg_register_degradations = registering(SPEC)

"""``Frame``: what one render returns."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from spacedg.render.camera import Camera


@dataclass
class Frame:
    """A rendered view. Images are (H, W[, 3]) numpy arrays; ``None`` where not requested.

    Attributes:
        rgb: float32 linear HDR light (sRGB-decoded composite, premultiplied over black),
            **unclamped** (a window can exceed 1).
        alpha: float32 accumulated opacity ``1 − T`` in [0, 1] (always computed: it is free).
        depth: float32 expected camera-space depth ``Σ w z / Σ w``, metres; 0 where alpha = 0.
        median_depth: float32 depth of the Gaussian that takes transmittance across ½
            (the last one added while ``T > ½``), metres; 0 where nothing was added.
        instance_ids: int32 id of that Gaussian's instance where ``T`` ends ``<= ½``, else -1.
        valid: bool mask of pixels whose ray the lens images (fisheye: inside the image
            circle; ``None`` for a pinhole, where every pixel is valid). Invalid pixels are 0.
        camera: the camera rendered (the mid-exposure camera under motion blur).
        stats: counters and timings (``visible``: Gaussians projected into the image,
            ``pairs``: Gaussian–tile pairs composited, ``sub_steps``, ``ms`` per stage).
        tensors: the same images as torch tensors on the render's device, where the backend
            kept them there (``backend="gsplat"``); ``None`` otherwise. The degradation
            pipeline's device path reads them instead of copying the numpy images back.
    """

    rgb: np.ndarray | None
    alpha: np.ndarray
    depth: np.ndarray | None
    median_depth: np.ndarray | None
    instance_ids: np.ndarray | None
    camera: Camera
    valid: np.ndarray | None = None
    stats: dict[str, Any] = field(default_factory=dict)
    tensors: dict[str, Any] | None = None

    @property
    def height(self) -> int:
        return int(self.alpha.shape[0])

    @property
    def width(self) -> int:
        return int(self.alpha.shape[1])


def expected_depth(weighted: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """``Σ w·z / α`` as float32: the expected depth image from a weighted depth sum, 0 where ``α`` is 0."""
    return np.where(alpha > 0, weighted / np.maximum(alpha, 1e-30), 0.0).astype(np.float32)

"""The sharp pass of defocus: the view rendered without blur, on the grid :mod:`spacedg.render.defocus_flux`
compares the blurred view with (``scale`` 1 or ½ of the view's resolution, the frame grown to whole
tiles, :func:`spacedg.render.defocus.measurement_camera`; the whole dilation × scale²,
:func:`spacedg.render.defocus.measurement_settings`, so every footprint is the full-resolution one
scaled). It is made by :func:`spacedg.render.composite.sharp_pass` (the clean raster of either
backend on that grid); numpy results.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["SharpPass"]


class SharpPass:
    """The sharp view on ``wide``'s grid: ``rgb`` (h, w, 3) linear light, ``alpha`` and ``depth``
    (h, w; depth the alpha-weighted mean, metres)."""

    def __init__(self, wide: Any, rgb: np.ndarray, alpha: np.ndarray, depth: np.ndarray) -> None:
        self.wide, self.rgb, self.alpha, self.depth = wide, rgb, alpha, depth

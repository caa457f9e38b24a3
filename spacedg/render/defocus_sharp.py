"""The sharp pass of defocus: the view rendered without blur, on the grid :mod:`spacedg.render.defocus_flux`
compares the blurred view with (``scale`` 1 or ½ of the view's resolution, the frame grown to whole
tiles, :func:`spacedg.render.defocus.measurement_camera`; the ``eps2d`` dilation × scale², so every
footprint is the full-resolution one scaled). Both backends; numpy results.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["SharpPass", "sharp_pass_cpu", "sharp_pass_torch"]


class SharpPass:
    """The sharp view on ``wide``'s grid: ``rgb`` (h, w, 3) linear light, ``alpha`` and ``depth``
    (h, w; depth the alpha-weighted mean, metres)."""

    def __init__(self, wide: Any, rgb: np.ndarray, alpha: np.ndarray, depth: np.ndarray) -> None:
        self.wide, self.rgb, self.alpha, self.depth = wide, rgb, alpha, depth


def sharp_pass_cpu(gaussians: Any, camera: Any, settings: Any, scale: float) -> SharpPass:
    """The sharp pass on the compiled path, at ``scale`` of ``camera``'s resolution: the clean render
    of :func:`spacedg.render.composite._raster_cpu` on the measurement grid."""
    from spacedg.render import composite, project_cpu
    from spacedg.render.defocus import measurement_camera, measurement_settings

    wide, measured = measurement_camera(camera, 0, scale), measurement_settings(settings, scale)
    sharp, rects = project_cpu.project_gaussians(gaussians, wide, measured, None, True)
    ids = np.full(sharp.shape[0], -1, np.int32)
    out, _ = composite._raster_cpu(gaussians, sharp, rects, ids, wide, measured, True, True, False, False)
    return SharpPass(wide, out["rgb"], out["alpha"], out["depth"])


def sharp_pass_torch(gs: Any, camera: Any, settings: Any, scale: float) -> SharpPass:
    """The sharp pass on the torch path (:func:`spacedg.render.composite._raster_torch`'s clean render)."""
    from spacedg.render import composite
    from spacedg.render.defocus import measurement_camera, measurement_settings
    from spacedg.render.project_torch import project_gaussians

    wide, measured = measurement_camera(camera, 0, scale), measurement_settings(settings, scale)
    out, _ = composite._raster_torch(gs, project_gaussians(gs, wide, measured, None, True), wide, measured, True, True, False, False)
    return SharpPass(wide, out["rgb"], out["alpha"], out["depth"])

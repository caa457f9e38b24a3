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
    """The sharp pass on the compiled path, at ``scale`` of ``camera``'s resolution."""
    from spacedg.render import project_cpu, raster_cpu
    from spacedg.render.colour_cpu import decode_srgb
    from spacedg.render.defocus import measurement_camera, measurement_settings

    wide = measurement_camera(camera, 0, scale)
    sharp, rects = project_cpu.project_gaussians(gaussians, wide, measurement_settings(settings, scale), None, True)
    ids = np.full(sharp.shape[0], -1, np.int32)
    out = raster_cpu.rasterize(sharp, rects, ids, wide.width, wide.height, settings.alpha_max, True, True, False,
                               settings.tight_tiles and settings.opacity_extent)
    return SharpPass(wide, decode_srgb(out["rgb"]), out["alpha"], out["depth"])


def sharp_pass_torch(gs: Any, camera: Any, settings: Any, scale: float) -> SharpPass:
    """The sharp pass on the torch path."""
    from spacedg.render import raster_torch
    from spacedg.render.colour_cpu import decode_srgb
    from spacedg.render.defocus import measurement_camera, measurement_settings
    from spacedg.render.project_torch import project_gaussians

    wide = measurement_camera(camera, 0, scale)
    sharp = project_gaussians(gs, wide, measurement_settings(settings, scale), None, True)
    offsets, gauss = raster_torch.bin_tiles(sharp, wide.width, wide.height, settings.tight_tiles and settings.opacity_extent)
    out = raster_torch.composite(sharp, offsets, gauss, gs.instance_ids, wide.width, wide.height, settings.alpha_max, True, True, False)
    return SharpPass(wide, decode_srgb(out["rgb"].cpu().numpy()), out["alpha"].cpu().numpy(), out["depth"].cpu().numpy())

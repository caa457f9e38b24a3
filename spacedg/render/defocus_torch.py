"""Torch twin of the defocus helpers of :mod:`spacedg.render.defocus` (whether anything is blurred,
the coarse composite grid) on a torch projection (:class:`spacedg.render.project_torch.Projected`).
The blurred view itself is composited by :func:`spacedg.render.raster_torch.composite` and brought
to the sharp view's local flux by :mod:`spacedg.render.defocus_flux` (see
:func:`spacedg.render.composite.composite_view`).
"""

from __future__ import annotations

from dataclasses import replace

import torch

from spacedg.render.project_torch import Projected
from spacedg.render.settings import TILE_SIZE

__all__ = ["coarse_view"]


def coarse_view(proj: Projected, width: int, height: int, factor: int) -> tuple[Projected, int, int]:
    """As :func:`spacedg.render.defocus.coarse_view`: the projection on a grid ``factor`` times coarser."""
    f = float(factor)
    w2, h2 = -(-width // factor), -(-height // factor)
    visible = proj.visible
    means2d = proj.means2d / f
    radii = torch.ceil(proj.radii.to(means2d.dtype) / f)
    wide = torch.float64 if means2d.device.type != "mps" else means2d.dtype
    limits = torch.tensor([(w2 + TILE_SIZE - 1) // TILE_SIZE, (h2 + TILE_SIZE - 1) // TILE_SIZE], dtype=wide, device=means2d.device)
    lo = torch.minimum(torch.clamp(torch.floor((means2d.to(wide) - radii.to(wide)) / TILE_SIZE), min=0), limits)
    hi = torch.minimum(torch.clamp(torch.ceil((means2d.to(wide) + radii.to(wide)) / TILE_SIZE), min=0), limits)
    keep = visible & (hi > lo).all(-1)
    rects = torch.stack([lo[:, 0], hi[:, 0], lo[:, 1], hi[:, 1]], dim=-1).to(torch.int32) * keep[:, None]
    radii = torch.where(keep[:, None], radii, torch.zeros_like(radii)).to(torch.int32)
    return replace(proj, means2d=means2d, conics=proj.conics * (f * f), radii=radii, rects=rects), w2, h2

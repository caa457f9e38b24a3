"""Defocus (optical-dynamic, raster stage): thin-lens depth of field inside the rasterizer.

Model: the paper's "Defocus". A Gaussian at camera depth ``d`` (metres, along the optical axis)
gets a circle of confusion of radius ``r = aperture · |d − depth| / d`` pixels, where ``depth``
is the focus distance; ``r² I`` is added to its projected 2D covariance (after the 0.3 px²
low-pass dilation) and its opacity is multiplied by ``sqrt(det Σ / det(Σ + r² I))``, so its
integrated alpha is unchanged (:class:`spacedg.render.Defocus`). So that the *view* keeps its
light, a sharp pass first measures each Gaussian's share of its surface's coverage and its
visible decoded colour, and blurred Gaussians add their light in linear light
(:mod:`spacedg.render.defocus`: a wall keeps its mean radiance and coverage within 1 % at
every aperture). Because the blur happens per Gaussian before compositing, occlusion
boundaries blur the way a real lens blurs them (a sharp foreground edge over a blurred
background), which an image-space blur of a depth map cannot do.

Units and decisions:

- ``aperture`` — pixels at the rendered resolution: the CoC radius of a point at infinity
  (the thin lens's ``f² / (N (S − f))`` scaled to pixels). A value given explicitly is used as
  is; the presets state it at :data:`~spacedg.plugins.specs.REFERENCE_IMAGE_SIZE` (1752 × 1168,
  a ScanNet++ DSLR frame) and scale it with the output (``ParamRange(per_size=True)``, ×
  ``min(W, H) / 1168``), so one preset blurs a 1920 × 1080 and a 640 × 360 render of the same
  view alike; the provenance records the pixels used.
- ``depth`` — the focus distance in metres (the paper's name; "depth (focus)" in its table).
- The radius is clamped to ``3 · aperture`` (the CoC of a point at a quarter of the focus
  distance): near objects with a far focus would otherwise reach hundreds of pixels, which
  is both numerically poor and slow (render time grows with footprint area).
- ``aperture = 0`` is the sharp render, bit for bit (the renderer skips defocus).
- Deterministic: ``rng`` is not used.

Presets: ``bench`` = the paper's table, aperture ∈ [10, 15] px, depth ∈ [1, 8] m. Severities
``1``–``5``: aperture [2, 3], [4, 5], [6, 8], [9, 11], [12, 15] px, depth ∈ [1, 8] m in all
(apertures in pixels of a 1752 × 1168 frame; at 640 × 360 they are × 0.308).

**Scale-aware** (decision): the focus ``depth`` ranges are stated for a scene whose median
depth is :data:`~spacedg.plugins.specs.REFERENCE_DEPTH_M` (2.5 m, a ScanNet++ room) and scale
with the sample's scene depth ``D`` (``ParamRange(per_depth=True)``): a plant filmed from 0.5 m
is focused at 0.2–1.6 m, as a room is at 1–8 m. The blur ``aperture · |d − f| / d`` depends only
on ``d / f``, so a tabletop and a room blur alike; ``aperture`` scales with the image size, not
the depth. At ``D = 2.5 m`` and 1752 × 1168 the presets are the paper's numbers; the provenance
records the resolved metres and pixels.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from typing import Any

import numpy as np

from spacedg.plugins.hookspecs import registering
from spacedg.plugins.specs import (
    Category,
    DegradationSpec,
    ParamRange,
    ParamSpec,
    Stage,
)
from spacedg.render.request import RenderRequest
from spacedg.render.settings import Defocus

__all__ = ["SPEC", "defocus"]

_FOCUS_RANGE = ParamRange(1.0, 8.0, per_depth=True)  # at REFERENCE_DEPTH_M; scales with the scene


def _px(low: float, high: float) -> ParamRange:
    """An aperture range in pixels at :data:`~spacedg.plugins.specs.REFERENCE_IMAGE_SIZE`, scaled with the output."""
    return ParamRange(low, high, per_size=True)


def defocus(request: RenderRequest, aperture: float, depth: float) -> RenderRequest:
    """``request`` with thin-lens defocus: CoC ``aperture · |d − depth| / d`` px, focus ``depth`` m."""
    return replace(request, defocus=Defocus(aperture=float(aperture), focus=float(depth)))


def apply(request: RenderRequest, params: Mapping[str, Any], rng: np.random.Generator) -> RenderRequest:
    """Raster-stage ``apply``: ``params = {"aperture": px, "depth": m}``; ``rng`` unused."""
    p = SPEC.validate_params(params)
    return defocus(request, p["aperture"], p["depth"])


SPEC = DegradationSpec(
    name="defocus", category=Category.OPTICAL_DYNAMIC, stage=Stage.RASTER,
    params=(
        ParamSpec("aperture", "px", "CoC radius of a point at infinity, pixels at the rendered resolution (presets: stated at 1752×1168, scaled with the output).", low=0.0, high=1000.0, harsher="higher"),
        ParamSpec("depth", "m", "Focus distance along the optical axis.", low=0.01, high=1e4),
    ),
    presets={
        "bench": {"aperture": _px(10.0, 15.0), "depth": _FOCUS_RANGE},
        "1": {"aperture": _px(2.0, 3.0), "depth": _FOCUS_RANGE},
        "2": {"aperture": _px(4.0, 5.0), "depth": _FOCUS_RANGE},
        "3": {"aperture": _px(6.0, 8.0), "depth": _FOCUS_RANGE},
        "4": {"aperture": _px(9.0, 11.0), "depth": _FOCUS_RANGE},
        "5": {"aperture": _px(12.0, 15.0), "depth": _FOCUS_RANGE},
    },
    apply=apply,
    description="Thin-lens defocus in the rasterizer: r = aperture·|d − depth|/d px added to each Gaussian's 2D covariance; the view keeps its light.",
    order=20.0,
)

spacedg_register_degradations = registering(SPEC)

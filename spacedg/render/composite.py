"""One composite of a set of Gaussians for one camera (no camera motion), and its :class:`Frame`.

:func:`composite_view` projects and composites on the compiled CPU path (numba tiles) or the
torch path and returns numpy images, the colour decoded to linear light (3DGS mixes
sRGB-encoded colour; under defocus the mix of :mod:`spacedg.render.defocus`);
:func:`frame_from_images` wraps them and masks pixels outside a fisheye image circle
(:func:`lens_valid_mask`). :func:`spacedg.render.render` and the motion-blur path
(:mod:`spacedg.render.motion`) both build on these two.
"""

from __future__ import annotations

import time
from functools import lru_cache
from typing import TYPE_CHECKING

import numpy as np

from spacedg.render.camera import Camera
from spacedg.render.frame import Frame
from spacedg.render.gaussians import Gaussians
from spacedg.render.settings import Defocus, RasterSettings

if TYPE_CHECKING:
    import torch

__all__ = ["composite_view", "frame_from_images", "lens_valid_mask"]


@lru_cache(maxsize=32)
def _fisheye_valid_mask(fx: float, fy: float, cx: float, cy: float, width: int, height: int, limit: float) -> np.ndarray:
    """Pixels whose normalised radius is within ``θ_d(effective max θ)`` (read-only cache)."""
    u = (np.arange(width) + 0.5 - cx) / fx
    v = (np.arange(height) + 0.5 - cy) / fy
    mask = (u[None, :] ** 2 + v[:, None] ** 2) <= limit * limit
    mask.flags.writeable = False
    return mask


def lens_valid_mask(camera: Camera) -> np.ndarray | None:
    """(H, W) bool mask of pixels inside the fisheye image circle; ``None`` for a pinhole."""
    lens = camera.fisheye
    if lens is None:
        return None
    theta_d = float(lens.distort_theta(np.float64(lens.effective_max_theta)))
    return _fisheye_valid_mask(camera.fx, camera.fy, camera.cx, camera.cy, camera.width, camera.height, theta_d)


def composite_view(
    gaussians: Gaussians,
    camera: Camera,
    outputs: frozenset[str],
    backend: str,
    device: torch.device | None,
    settings: RasterSettings,
    defocus: Defocus | None,
) -> tuple[dict[str, np.ndarray], dict[str, float]]:
    """One render (no camera motion) as numpy arrays; ``rgb`` is **linear** light.

    Without blur the composite is the sRGB-encoded mix of 3DGS, decoded once here; under
    defocus with anything blurred, the two passes of :mod:`spacedg.render.defocus`.
    """
    want_color = "rgb" in outputs
    want_depth = "depth" in outputs
    want_ids = "median_depth" in outputs or "instance_ids" in outputs
    stats: dict[str, float] = {}
    t0 = time.perf_counter()
    tight = settings.tight_tiles and settings.opacity_extent
    if backend == "cpu":
        from spacedg.render import defocus as defocus_model
        from spacedg.render import project_cpu, raster_cpu  # numba kernels: compiled on first render, not with spacedg
        from spacedg.render.colour_cpu import decode_srgb

        ids = gaussians.instance_ids if gaussians.instance_ids is not None else np.full(len(gaussians), -1, np.int32)
        packed, rects = project_cpu.project_gaussians(gaussians, camera, settings, defocus, want_color)
        t1 = time.perf_counter()
        if defocus is not None and defocus_model.has_blur(packed, rects):
            images = defocus_model.render_cpu(
                gaussians, camera, settings, packed, rects, ids, want_color, want_depth, want_ids, defocus
            )
        else:
            images = raster_cpu.rasterize(
                packed, rects, ids, camera.width, camera.height, settings.alpha_max,
                want_color, want_depth, want_ids, tight,
            )
            if want_color:
                images["rgb"] = decode_srgb(images["rgb"])
        stats["visible"] = int(images.pop("n_visible"))
        stats["pairs"] = int(images.pop("n_pairs"))
    else:
        import torch  # heavy: only the torch backend needs it

        from spacedg.render import defocus_torch, project_torch, raster_torch
        from spacedg.render.colour_cpu import decode_srgb

        gs = project_torch.GaussianTensors.of(gaussians, device, torch.float32)
        with torch.no_grad():
            proj = project_torch.project_gaussians(gs, camera, settings, defocus, want_color)
            t1 = time.perf_counter()
            blurred = defocus is not None and defocus_torch.has_blur(proj)
            factor = 1
            if blurred:
                result = defocus_torch.render_torch(gs, camera, settings, proj, want_color, want_depth, want_ids, defocus)
                stats["pairs"] = int(result.pop("n_pairs"))
                factor = int(result.pop("factor"))
            else:
                offsets, gauss = raster_torch.bin_tiles(proj, camera.width, camera.height, tight)
                result = raster_torch.composite(
                    proj, offsets, gauss, gs.instance_ids, camera.width, camera.height, settings.alpha_max,
                    want_color, want_depth, want_ids,
                )
                stats["pairs"] = int(gauss.numel())
        images = {k: v.cpu().numpy() for k, v in result.items()}
        if want_color and blurred:
            images["rgb"] = decode_srgb(images.pop("enc")) + images.pop("lin")
        elif want_color:
            images["rgb"] = decode_srgb(images["rgb"])
        if factor > 1:  # the blurred view was composited on a coarser grid
            from spacedg.render.defocus import upsample

            images = upsample(images, factor, camera.width, camera.height, want_color, want_depth, want_ids)
        stats["visible"] = int(proj.visible.sum())
    t2 = time.perf_counter()
    stats["project_ms"] = (t1 - t0) * 1e3
    stats["raster_ms"] = (t2 - t1) * 1e3
    return images, stats


def frame_from_images(images: dict[str, np.ndarray], camera: Camera, wanted: frozenset[str]) -> Frame:
    """Wrap composite images (``rgb`` in linear light, as :func:`composite_view` returns it) into a
    :class:`Frame`, masking pixels outside a fisheye image circle."""
    valid = lens_valid_mask(camera)
    rgb = images.get("rgb") if "rgb" in wanted else None
    frame = Frame(
        rgb=rgb,
        alpha=images["alpha"],
        depth=images.get("depth") if "depth" in wanted else None,
        median_depth=images.get("median_depth") if "median_depth" in wanted else None,
        instance_ids=images.get("instance_ids") if "instance_ids" in wanted else None,
        camera=camera,
        valid=valid,
    )
    if valid is not None:
        outside = ~valid
        for name in ("rgb", "alpha", "depth", "median_depth"):
            image = getattr(frame, name)
            if image is not None:
                image[outside] = 0.0
        if frame.instance_ids is not None:
            frame.instance_ids[outside] = -1
    return frame

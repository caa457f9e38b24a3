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
from typing import TYPE_CHECKING, Any

import numpy as np

from spacedg.render.camera import Camera
from spacedg.render.defocus_sharp import SharpPass
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


#: Largest share of a frame's pixels outside its image circle that :func:`_fisheye_outside` indexes (beyond, the mask).
_OUTSIDE_INDEXED = 0.5


@lru_cache(maxsize=32)
def _fisheye_outside(fx: float, fy: float, cx: float, cy: float, width: int, height: int, limit: float) -> np.ndarray | None:
    """The flat indices (row-major, int32) of the pixels outside :func:`_fisheye_valid_mask` (read-only cache), or
    ``None`` when more than :data:`_OUTSIDE_INDEXED` of the frame is outside (or it has 2³¹ pixels or more): a frame's
    outside pixels are zeroed through them, ~0.1 ms a 640 × 480 view at the bench distortion where the boolean mask
    took ~1 ms (2 % of the image outside). At most 2 bytes a pixel of the frame, twice the mask's cache."""
    outside = ~_fisheye_valid_mask(fx, fy, cx, cy, width, height, limit)
    if outside.size >= 2**31 or np.count_nonzero(outside) > _OUTSIDE_INDEXED * outside.size:
        return None
    indices = np.flatnonzero(outside).astype(np.int32)
    indices.flags.writeable = False
    return indices


def _image_circle(camera: Camera) -> tuple[float, float, float, float, int, int, float] | None:
    """The arguments of :func:`_fisheye_valid_mask` for ``camera`` (its intrinsics and ``θ_d`` of the lens's
    effective max θ); ``None`` for a pinhole."""
    lens = camera.fisheye
    if lens is None:
        return None
    theta_d = float(lens.distort_theta(np.float64(lens.effective_max_theta)))
    return (camera.fx, camera.fy, camera.cx, camera.cy, camera.width, camera.height, theta_d)


def lens_valid_mask(camera: Camera) -> np.ndarray | None:
    """(H, W) bool mask of pixels inside the fisheye image circle; ``None`` for a pinhole."""
    circle = _image_circle(camera)
    return None if circle is None else _fisheye_valid_mask(*circle)


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

    The composite is the sRGB-encoded mix of 3DGS, decoded once here. Under defocus with anything
    blurred, each Gaussian carries its circle of confusion (:class:`~spacedg.render.settings.Defocus`),
    the composite runs on a coarser grid when every visible blur is wide
    (:func:`spacedg.render.defocus.composite_factor`; on the compiled path also per tile on the full or
    the 2× grid, :func:`spacedg.render.defocus.tile_sample_min_coc`), and the colour is brought back to the
    sharp view's local flux (:mod:`spacedg.render.defocus_flux`).
    """
    want_color = "rgb" in outputs
    want_depth = "depth" in outputs
    want_ids = "median_depth" in outputs or "instance_ids" in outputs
    stats: dict[str, float] = {}
    t0 = time.perf_counter()
    if backend == "cpu":
        from spacedg.render import project_cpu  # numba kernels: compiled on first render, not with spacedg

        ids = gaussians.instance_ids if gaussians.instance_ids is not None else np.full(len(gaussians), -1, np.int32)
        sharp_projection = None
        if defocus is None or not _sharp_pass_may_be_coarse(defocus):
            packed, rects = project_cpu.project_gaussians(gaussians, camera, settings, defocus, want_color)
        else:  # with the sharp pass's projection at its usual scale, in the same pass (the same bytes as its own)
            from spacedg.render.defocus import MEASURE_SCALE, measurement_camera, measurement_settings

            wide, measured = measurement_camera(camera, 0, MEASURE_SCALE), measurement_settings(settings, MEASURE_SCALE)
            packed, rects, sharp_packed, sharp_rects = project_cpu.project_with_sharp(gaussians, camera, settings, defocus, want_color, wide, measured)
            sharp_projection = (sharp_packed, sharp_rects)
        t1 = time.perf_counter()
        images, sharp = _raster_cpu(gaussians, packed, rects, ids, camera, settings, want_color, want_depth, want_ids, defocus is not None, sharp_projection)
    else:
        import torch  # heavy: only the torch backend needs it

        from spacedg.render import project_torch

        gs = project_torch.GaussianTensors.of(gaussians, device, torch.float32)
        with torch.no_grad():
            proj = project_torch.project_gaussians(gs, camera, settings, defocus, want_color)
            t1 = time.perf_counter()
            images, sharp = _raster_torch(gs, proj, camera, settings, want_color, want_depth, want_ids, defocus is not None)
    if sharp is not None:  # the blurred view's light and coverage brought to the sharp view's local flux
        images["rgb"], images["alpha"] = _conserved(camera, defocus, images, sharp, want_color)  # type: ignore[arg-type]
    t2 = time.perf_counter()
    stats["project_ms"] = (t1 - t0) * 1e3
    stats["raster_ms"] = (t2 - t1) * 1e3
    stats["visible"] = int(images.pop("n_visible"))
    stats["pairs"] = int(images.pop("n_pairs"))
    return images, stats


def _sharp_pass_may_be_coarse(defocus: Defocus) -> bool:
    """Whether the sharp pass can be at :data:`~spacedg.render.defocus.MEASURE_SCALE`: its scale comes from the
    visible circles of confusion (:func:`~spacedg.render.defocus_flux.flux_scale`, which grows with them), and
    none exceeds ``max_radius``; when even that gives full resolution, projecting the sharp pass's coarse
    grid alongside the view would be thrown away (very mild blur: an aperture under 0.58 px by default)."""
    from spacedg.render.defocus import MEASURE_SCALE
    from spacedg.render.defocus_flux import flux_scale

    return flux_scale(float(defocus.max_radius)) == MEASURE_SCALE


def _raster_cpu(
    gaussians: Gaussians, packed: np.ndarray, rects: np.ndarray, ids: np.ndarray, camera: Camera, settings: RasterSettings,
    want_color: bool, want_depth: bool, want_ids: bool, defocused: bool,
    sharp_projection: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[dict[str, np.ndarray], SharpPass | None]:
    """Composite a CPU projection; when anything is blurred, also the sharp pass
    (:func:`sharp_pass`, from ``sharp_projection = (packed, rects)`` on the grid at
    :data:`~spacedg.render.defocus.MEASURE_SCALE` when that is its scale),
    and coarse when every visible blur is wide. ``(images, the sharp pass or None when nothing is blurred)``."""
    from spacedg.render import defocus as defocus_model
    from spacedg.render import raster_cpu
    from spacedg.render.colour_cpu import decode_srgb
    from spacedg.render.defocus_flux import flux_scale
    from spacedg.render.project_cpu import COC

    width, height, factor = camera.width, camera.height, 1
    sharp = None
    visible = rects[:, 1] > rects[:, 0] if defocused else None
    plan = defocus_model.blur_plan(packed[visible, COC], width, height) if defocused else None
    if plan is not None:
        scale = flux_scale(plan[0])
        sharp = sharp_pass(gaussians, camera, settings, scale, sharp_projection if scale == defocus_model.MEASURE_SCALE else None)
        factor = plan[1]
        if factor > 1:
            packed, rects, width, height = defocus_model.coarse_view(packed, rects, width, height, factor)
    images = raster_cpu.rasterize(
        packed, rects, ids, width, height, settings.alpha_max, want_color, want_depth, want_ids,
        settings.tight_tiles and settings.opacity_extent,
        defocus_model.tile_sample_min_coc(factor) if plan is not None else 0.0,
    )
    if want_color:
        images["rgb"] = decode_srgb(images["rgb"])
    if factor > 1:  # the count of the view's own projection, not the coarse grid's
        images = defocus_model.upsample(images, factor, camera.width, camera.height, want_color, want_depth, want_ids)
        images["n_visible"] = np.int64(np.count_nonzero(visible))
    return images, sharp


def _raster_torch(
    gs: object, proj: object, camera: Camera, settings: RasterSettings,
    want_color: bool, want_depth: bool, want_ids: bool, defocused: bool,
) -> tuple[dict[str, np.ndarray], SharpPass | None]:
    """As :func:`_raster_cpu` on the torch path (numpy images)."""
    from spacedg.render import defocus_torch, raster_torch
    from spacedg.render.colour_cpu import decode_srgb
    from spacedg.render.defocus import blur_plan, upsample
    from spacedg.render.defocus_flux import flux_scale

    width, height, factor = camera.width, camera.height, 1
    sharp = None
    n_visible = int(proj.visible.sum())  # type: ignore[attr-defined]
    plan = None
    if defocused and proj.coc is not None:  # type: ignore[attr-defined]
        plan = blur_plan(proj.coc[proj.visible].double().cpu().numpy(), width, height)  # type: ignore[attr-defined]
    if plan is not None:
        sharp = sharp_pass(gs, camera, settings, flux_scale(plan[0]))
        factor = plan[1]
        if factor > 1:
            proj, width, height = defocus_torch.coarse_view(proj, width, height, factor)  # type: ignore[arg-type]
    offsets, gauss = raster_torch.bin_tiles(proj, width, height, settings.tight_tiles and settings.opacity_extent)  # type: ignore[arg-type]
    result = raster_torch.composite(
        proj, offsets, gauss, gs.instance_ids, width, height, settings.alpha_max,  # type: ignore[attr-defined, arg-type]
        want_color, want_depth, want_ids,
    )
    images = {k: v.cpu().numpy() for k, v in result.items()}
    if want_color:
        images["rgb"] = decode_srgb(images["rgb"])
    if factor > 1:
        images = upsample(images, factor, camera.width, camera.height, want_color, want_depth, want_ids)
    images["n_visible"] = np.int64(n_visible)
    images["n_pairs"] = np.int64(gauss.numel())
    return images, sharp


def sharp_pass(
    gaussians: Any, camera: Camera, settings: RasterSettings, scale: float, projected: tuple[np.ndarray, np.ndarray] | None = None,
) -> SharpPass:
    """The sharp pass of defocus (:mod:`spacedg.render.defocus_sharp`) at ``scale`` of ``camera``'s
    resolution: the clean raster of the backend ``gaussians`` belong to (:class:`Gaussians`: the
    compiled path; tensors: the torch path) on the measurement grid. ``projected``: the compiled
    path's projection onto that grid when it was already made
    (:func:`spacedg.render.project_cpu.project_with_sharp`)."""
    from spacedg.render.defocus import measurement_camera, measurement_settings

    wide, measured = measurement_camera(camera, 0, scale), measurement_settings(settings, scale)
    if isinstance(gaussians, Gaussians):
        from spacedg.render import project_cpu

        packed, rects = projected if projected is not None else project_cpu.project_gaussians(gaussians, wide, measured, None, True)
        ids = np.full(packed.shape[0], -1, np.int32)
        out, _ = _raster_cpu(gaussians, packed, rects, ids, wide, measured, True, True, False, False)
    else:
        from spacedg.render.project_torch import project_gaussians

        out, _ = _raster_torch(gaussians, project_gaussians(gaussians, wide, measured, None, True), wide, measured, True, True, False, False)
    return SharpPass(wide, out["rgb"], out["alpha"], out["depth"])


def _conserved(
    camera: Camera, defocus: Defocus, images: dict[str, np.ndarray], sharp: SharpPass, want_color: bool,
) -> tuple[np.ndarray, np.ndarray]:
    """The blurred view's ``rgb`` (linear; the placeholder without ``want_color``) and ``alpha`` with the
    sharp view's local flux (:mod:`spacedg.render.defocus_flux`)."""
    from spacedg.render.defocus_flux import conserve_light, sharp_flux_lengths

    # flux_lengths of the covered pixels' circles of confusion (alpha > 1e-3), compiled
    length, blur = sharp_flux_lengths(sharp.depth, sharp.alpha, defocus.aperture, defocus.focus, defocus.max_radius)
    alpha = images["alpha"]
    rgb = images["rgb"] if want_color else np.zeros((*alpha.shape, 3), np.float32)
    rgb, alpha = conserve_light(rgb, alpha, sharp.rgb, sharp.alpha, camera, sharp.wide, length, blur)
    return (rgb if want_color else images["rgb"]), alpha


def frame_from_images(images: dict[str, np.ndarray], camera: Camera, wanted: frozenset[str]) -> Frame:
    """Wrap composite images (``rgb`` in linear light, as :func:`composite_view` returns it) into a
    :class:`Frame`, masking pixels outside a fisheye image circle."""
    circle = _image_circle(camera)
    valid, outside = (None, None) if circle is None else (_fisheye_valid_mask(*circle), _fisheye_outside(*circle))
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
        # the pixels outside set to 0 (ids −1): through their flat indices where an image is C-contiguous and of the
        # mask's size, else (also where more than half the frame is outside: no indices) by the mask, which refuses
        # an image of another size
        invalid = None
        for name in ("rgb", "alpha", "depth", "median_depth", "instance_ids"):
            image = getattr(frame, name)
            if image is None:
                continue
            value = -1 if name == "instance_ids" else 0.0
            if outside is not None and image.flags.c_contiguous and image.shape[:2] == valid.shape:
                image.reshape(valid.size, -1)[outside] = value
            else:
                invalid = ~valid if invalid is None else invalid
                image[invalid] = value
    return frame

"""``render()``: one view of a set of Gaussians, on the compiled CPU path or the torch path."""

from __future__ import annotations

import time
from functools import lru_cache
from typing import TYPE_CHECKING, Iterable

import numpy as np

from spacedg.errors import ParameterError
from spacedg.render.camera import Camera
from spacedg.render.frame import Frame
from spacedg.render.gaussians import Gaussians
from spacedg.render.settings import Defocus, MotionBlur, RasterSettings, parse_outputs

if TYPE_CHECKING:
    import torch

BACKENDS = ("auto", "cpu", "torch")
_DEFAULT_SETTINGS = RasterSettings()


def resolve_backend(backend: str, device: str | torch.device | None) -> tuple[str, torch.device | None]:
    """``auto`` → the compiled CPU path unless a non-CPU torch device is asked for.

    torch is imported here, not at module import, so ``import spacedg`` stays light.
    """
    if backend not in BACKENDS:
        raise ParameterError(f"unknown render backend {backend!r}; choose from {list(BACKENDS)}")
    if device is None and backend in ("auto", "cpu"):
        return "cpu", None  # the compiled path never touches torch
    import torch

    try:
        dev = torch.device(device) if device is not None else torch.device("cpu")
    except (RuntimeError, TypeError) as err:
        raise ParameterError(f"unknown torch device {device!r}: {err}") from None
    if backend == "cpu" and dev.type != "cpu":
        raise ParameterError(f"backend 'cpu' (compiled) renders on the CPU only; use backend='torch' for device {dev}")
    if backend == "auto":
        backend = "cpu" if dev.type == "cpu" else "torch"
    return backend, dev


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
    """One render (no camera motion): sRGB-encoded composite plus depth/id images, as numpy arrays."""
    want_color = "rgb" in outputs
    want_depth = "depth" in outputs
    want_ids = "median_depth" in outputs or "instance_ids" in outputs
    stats: dict[str, float] = {}
    t0 = time.perf_counter()
    if backend == "cpu":
        from spacedg.render import project_cpu, raster_cpu

        packed, rects = project_cpu.project_view(gaussians, camera, settings, defocus, want_color)
        t1 = time.perf_counter()
        ids = gaussians.instance_ids if gaussians.instance_ids is not None else np.full(len(gaussians), -1, np.int32)
        images = raster_cpu.rasterize(
            packed, rects, ids, camera.width, camera.height, settings.alpha_max,
            want_color, want_depth, want_ids, settings.tight_tiles and settings.opacity_extent,
        )
        stats["visible"] = int(images.pop("n_visible"))
        stats["pairs"] = int(images.pop("n_pairs"))
    else:
        import torch

        from spacedg.render import project, raster_torch

        gs = project.GaussianTensors.of(gaussians, device, torch.float32)
        with torch.no_grad():
            proj = project.project(gs, camera, settings, defocus, want_color)
            t1 = time.perf_counter()
            offsets, gauss = raster_torch.bin_tiles(proj, camera.width, camera.height, settings.tight_tiles and settings.opacity_extent)
            result = raster_torch.composite(
                proj, offsets, gauss, gs.instance_ids, camera.width, camera.height, settings.alpha_max,
                want_color, want_depth, want_ids,
            )
        images = {k: v.cpu().numpy() for k, v in result.items()}
        stats["visible"] = int(proj.visible.sum())
        stats["pairs"] = int(gauss.numel())
    t2 = time.perf_counter()
    stats["project_ms"] = (t1 - t0) * 1e3
    stats["raster_ms"] = (t2 - t1) * 1e3
    return images, stats


def render(
    gaussians: Gaussians,
    camera: Camera,
    *,
    defocus: Defocus | None = None,
    motion: MotionBlur | None = None,
    outputs: str | Iterable[str] = "rgb",
    backend: str = "auto",
    device: str | torch.device | None = None,
    settings: RasterSettings | None = None,
) -> Frame:
    """Render one view.

    Args:
        gaussians: the scene's Gaussians (world frame, metres).
        camera: intrinsics, pose (OpenCV axes) and lens; under ``motion`` the mid-exposure pose.
        defocus: thin-lens defocus inside the rasterizer (``None`` = pinhole sharp).
        motion: camera motion during the exposure (sub-step renders averaged in linear light).
        outputs: any of ``rgb, alpha, depth, median_depth, instance_ids`` (comma string or
            list, or ``"all"``); only these are computed (``alpha`` always is, it is free).
        backend: ``"cpu"`` (compiled numba tiles), ``"torch"`` (any device), ``"auto"``.
        device: torch device for the torch backend (``"cuda"`` selects it under ``auto``).
        settings: rasterizer constants (near/far, ``alpha_max`` = 0.99, dilation, …).

    Returns:
        A :class:`Frame`; ``rgb`` is linear light (the sRGB-encoded composite decoded).
    """
    if not isinstance(gaussians, Gaussians):
        raise ParameterError(f"render() needs a Gaussians, got {type(gaussians).__name__}")
    if not isinstance(camera, Camera):
        raise ParameterError(f"render() needs a Camera, got {type(camera).__name__}")
    if defocus is not None and not isinstance(defocus, Defocus):
        raise ParameterError(f"defocus must be a spacedg.render.Defocus, got {type(defocus).__name__}")
    if motion is not None and not isinstance(motion, MotionBlur):
        raise ParameterError(f"motion must be a spacedg.render.MotionBlur, got {type(motion).__name__}")
    wanted = parse_outputs(outputs)
    backend, dev = resolve_backend(backend, device)
    settings = settings or _DEFAULT_SETTINGS
    if defocus is not None and defocus.aperture == 0:
        defocus = None
    if motion is not None and not motion.is_static:
        from spacedg.render.motion import render_motion

        return render_motion(gaussians, camera, motion, wanted, backend, dev, settings, defocus)
    t0 = time.perf_counter()
    images, stats = composite_view(gaussians, camera, wanted, backend, dev, settings, defocus)
    frame = frame_from_images(images, camera, wanted)
    stats["sub_steps"] = 1
    stats["ms"] = (time.perf_counter() - t0) * 1e3
    frame.stats = stats
    return frame


def frame_from_images(images: dict[str, np.ndarray], camera: Camera, wanted: frozenset[str], linear_rgb: bool = False) -> Frame:
    """Wrap composite images into a :class:`Frame` (decoding sRGB unless ``linear_rgb``), masking the lens."""
    valid = lens_valid_mask(camera)
    rgb = images.get("rgb") if "rgb" in wanted else None
    if rgb is not None and not linear_rgb:
        from spacedg.render.colour_cpu import decode_srgb  # numba: imported on first render, not with spacedg

        rgb = decode_srgb(rgb)
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

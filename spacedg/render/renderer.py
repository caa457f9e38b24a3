"""``render()``: one view of a set of Gaussians, on the compiled CPU path or the torch path.

One render without camera motion is :func:`spacedg.render.composite.composite_view`; camera
motion is :func:`spacedg.render.motion.render_motion` (sub-step composites averaged in linear light).
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Iterable

from spacedg.errors import ParameterError
from spacedg.render.camera import Camera
from spacedg.render.composite import composite_view, frame_from_images
from spacedg.render.frame import Frame
from spacedg.render.gaussians import Gaussians
from spacedg.render.memory import keep_freed_memory
from spacedg.render.motion import MotionJob, render_motion
from spacedg.render.settings import Defocus, MotionBlur, RasterSettings, parse_outputs

if TYPE_CHECKING:
    import torch

BACKENDS = ("auto", "cpu", "torch", "gsplat")
_DEFAULT_SETTINGS = RasterSettings()


def resolve_backend(backend: str, device: str | torch.device | None) -> tuple[str, torch.device | None]:
    """``auto`` → the compiled CPU path unless a non-CPU torch device is asked for; on a CUDA
    device, ``gsplat`` when gsplat's CUDA extension loads, else ``torch``. ``gsplat`` without a
    device renders on CUDA when there is one, else on the CPU with gsplat's torch stand-ins
    (slow: for tests; see :mod:`spacedg.render.gsplat_backend`).

    torch is imported here, not at module import, so ``import spacedg`` stays light.
    """
    if backend not in BACKENDS:
        raise ParameterError(f"unknown render backend {backend!r}; choose from {list(BACKENDS)}")
    if device is None and backend in ("auto", "cpu"):
        return "cpu", None  # the compiled path never touches torch
    import torch

    if device is None and backend == "gsplat":
        device = "cuda" if torch.cuda.is_available() else "cpu"
    try:
        dev = torch.device(device) if device is not None else torch.device("cpu")
    except (RuntimeError, TypeError) as err:
        raise ParameterError(f"unknown torch device {device!r}: {err}") from None
    if backend == "cpu" and dev.type != "cpu":
        raise ParameterError(f"backend 'cpu' (compiled) renders on the CPU only; use backend='torch' for device {dev}")
    if backend == "auto":
        if dev.type == "cpu":
            backend = "cpu"
        else:
            from spacedg.render.gsplat_backend import gsplat_cuda_available

            backend = "gsplat" if dev.type == "cuda" and gsplat_cuda_available() else "torch"
    return backend, dev


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
        backend: ``"cpu"`` (compiled numba tiles), ``"torch"`` (any device), ``"gsplat"`` (our
            projection on gsplat's CUDA tiles and compositor; :mod:`spacedg.render.gsplat_backend`),
            ``"auto"`` (CPU → ``cpu``; CUDA → ``gsplat`` if its extension loads, else ``torch``).
        device: torch device for the torch and gsplat backends (``"cuda"`` under ``auto`` selects one of them).
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
    if backend == "cpu":
        keep_freed_memory()  # once per process: the compiled path's large arrays reused from the heap, not faulted in afresh
    settings = settings or _DEFAULT_SETTINGS
    if defocus is not None and defocus.aperture == 0:
        defocus = None
    if backend == "gsplat":
        from spacedg.render.gsplat_backend import render_gsplat  # torch and gsplat: imported on first use

        return render_gsplat(gaussians, camera, wanted, dev, settings, defocus, motion)
    if motion is not None and not motion.is_static:
        return render_motion(MotionJob(gaussians, camera, motion, wanted, backend, dev, settings, defocus))
    t0 = time.perf_counter()
    images, stats = composite_view(gaussians, camera, wanted, backend, dev, settings, defocus)
    frame = frame_from_images(images, camera, wanted)
    stats["sub_steps"] = 1
    stats["ms"] = (time.perf_counter() - t0) * 1e3
    frame.stats = stats
    return frame

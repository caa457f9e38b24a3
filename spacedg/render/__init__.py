"""Rendering: Gaussians + Camera → Frame (linear HDR light, alpha, depths, instance ids).

``render()`` picks a backend: the compiled CPU tile rasterizer (numba) or the readable torch
path (any device; the oracle on CPU). Defocus, fisheye distortion and motion blur happen
inside the rasterizer. See ``NOTES-RENDERER`` conventions in the docstrings of
:mod:`spacedg.render.project_cpu` and :mod:`spacedg.render.raster_cpu`.

The package itself is callable: ``spacedg.render(gaussians, camera, ...)`` is
:func:`spacedg.render.render`, so the front door's ``render`` and the subpackage
``spacedg.render`` (with ``spacedg.render.motion`` and friends) are one object.
"""

import sys
import types

from spacedg.render.camera import Camera, FisheyeLens, exposure_poses, fitted_size, interpolate_pose, look_at
from spacedg.render.colour import linear_to_srgb, srgb_to_linear
from spacedg.render.frame import Frame
from spacedg.render.gaussians import Gaussians
from spacedg.render.renderer import BACKENDS, render
from spacedg.render.request import RenderRequest
from spacedg.render.settings import OUTPUT_NAMES, Defocus, MotionBlur, RasterSettings

__all__ = [
    "BACKENDS",
    "OUTPUT_NAMES",
    "Camera",
    "Defocus",
    "FisheyeLens",
    "Frame",
    "Gaussians",
    "MotionBlur",
    "RasterSettings",
    "RenderRequest",
    "exposure_poses",
    "fitted_size",
    "interpolate_pose",
    "linear_to_srgb",
    "look_at",
    "render",
    "srgb_to_linear",
]


class _CallableModule(types.ModuleType):
    """Module type whose instances forward calls to :func:`render`."""

    def __call__(self, *args, **kwargs):  # type: ignore[no-untyped-def]
        return render(*args, **kwargs)


sys.modules[__name__].__class__ = _CallableModule

"""The clean image of a view, as the sample pipeline makes it: what the judge and the preview look at.

:func:`render_clean_view` renders a view without degradations and encodes it with the exact
8-bit sRGB encode, the same bytes as the clean image of :func:`spacedg.data.pipeline.degrade`
at the same size (the ``qa`` layer sits below ``data``, so it renders directly).
"""

from __future__ import annotations

import numpy as np

from spacedg.errors import InvalidDataError, ParameterError
from spacedg.limits import check_image_size
from spacedg.render import render
from spacedg.scene.model import Scene

__all__ = ["render_clean_view"]


def render_clean_view(scene: Scene, view: str, image_size: tuple[int, int] | None = None, backend: str = "auto") -> np.ndarray:
    """The clean sRGB image of ``view``, uint8 (H, W, 3): rendered (``backend`` of
    :func:`spacedg.render.render`) at the largest size of the view's aspect ratio within
    ``image_size`` ``(width, height)`` px (:meth:`~spacedg.render.camera.Camera.fitted`, intrinsics
    scaled, never squeezed; the view's own size when ``None``), then the exact 8-bit sRGB encode.

    Raises :class:`ParameterError` for a size beyond :mod:`spacedg.limits` and
    :class:`InvalidDataError` when the render holds non-finite light."""
    from spacedg.render.colour_cpu import encode_srgb_u8  # numba: compiled on first use

    camera = scene.camera(view)
    if image_size is not None:
        check_image_size(*image_size, "image_size", "render smaller", ParameterError)
        camera = camera.fitted(*image_size)
    rgb = render(scene.gaussians, camera, outputs="rgb", backend=backend).rgb
    if not np.isfinite(np.sum(rgb, dtype=np.float64)):  # a renderer bug: never write it out as black pixels
        raise InvalidDataError(f"scene {scene.id}, view {view!r}: the render holds non-finite light; please report this with the scene")
    return encode_srgb_u8(rgb)

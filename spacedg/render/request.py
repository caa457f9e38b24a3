"""``RenderRequest``: what to render for one view — the object raster-stage degradations edit.

A raster-stage degradation (``Stage.RASTER``) never sees pixels: its ``apply(request, params,
rng)`` returns a new :class:`RenderRequest` with another camera or lens (distortion), thin-lens
defocus, or camera motion over the exposure. The pipeline applies every raster degradation of a
chain to one request, so a chain with distortion + defocus + motion blur costs one (motion-blurred)
render per view, and then calls :meth:`RenderRequest.render` once.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

from spacedg.errors import ParameterError
from spacedg.render.camera import Camera
from spacedg.render.renderer import render
from spacedg.render.settings import Defocus, MotionBlur, RasterSettings, parse_outputs

if TYPE_CHECKING:
    import torch

    from spacedg.render.frame import Frame
    from spacedg.render.gaussians import Gaussians

__all__ = ["RenderRequest"]


@dataclass(frozen=True)
class RenderRequest:
    """One view's render settings (immutable; raster-stage degradations return edited copies).

    Attributes:
        camera: intrinsics, lens and pose (under motion blur: the mid-exposure pose, which stays
            the question's ground-truth pose).
        defocus: thin-lens defocus inside the rasterizer, or ``None`` (sharp pinhole).
        motion: camera motion during the exposure, or ``None``.
        outputs: render outputs to compute (see :data:`spacedg.render.OUTPUT_NAMES`).
    """

    camera: Camera
    defocus: Defocus | None = None
    motion: MotionBlur | None = None
    outputs: frozenset[str] = field(default_factory=lambda: frozenset({"rgb"}))

    def __post_init__(self) -> None:
        if not isinstance(self.camera, Camera):
            raise ParameterError(f"RenderRequest.camera must be a spacedg Camera, got {type(self.camera).__name__}")
        if self.defocus is not None and not isinstance(self.defocus, Defocus):
            raise ParameterError(f"RenderRequest.defocus must be a Defocus or None, got {type(self.defocus).__name__}")
        if self.motion is not None and not isinstance(self.motion, MotionBlur):
            raise ParameterError(f"RenderRequest.motion must be a MotionBlur or None, got {type(self.motion).__name__}")
        object.__setattr__(self, "outputs", parse_outputs(self.outputs))

    def with_outputs(self, *names: str) -> RenderRequest:
        """A copy that also computes ``names``."""
        return replace(self, outputs=self.outputs | parse_outputs(list(names)))

    def render(
        self,
        gaussians: Gaussians,
        *,
        backend: str = "auto",
        device: str | torch.device | None = None,
        settings: RasterSettings | None = None,
    ) -> Frame:
        """Render this request (see :func:`spacedg.render.render`)."""
        return render(
            gaussians, self.camera, defocus=self.defocus, motion=self.motion, outputs=self.outputs,
            backend=backend, device=device, settings=settings,
        )

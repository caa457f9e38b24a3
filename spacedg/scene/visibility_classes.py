"""Instance visibility classes: when is an object *clearly visible*, *partly visible*, *hidden*.

- :func:`classify`: visibility class of one instance in one view (thresholds below).
- computing :class:`~spacedg.scene.model.InstanceVisibility` from rendered instance ids lives in
  :mod:`spacedg.scene.visibility` (this module renders nothing, so question families can read
  the classes without reaching the renderer).

Classes (shared by every question family, e.g. counting and existence):

``HIDDEN``
    no record for the view, or 0 visible pixels: the image shows nothing of it.
``VISIBLE`` (clearly visible)
    ``visible_pixels >= min_pixels`` (scaled to the image, see below) **and**
    ``visible_fraction >= min_fraction``.
``PARTIAL``
    the grey zone in between: some pixels, but too few or too occluded/truncated to be sure a
    viewer counts it. Families that need certainty skip questions touching it.

Defaults (:data:`DEFAULT_THRESHOLDS`): ``min_pixels = 400`` at the reference image size
640×480 (0.13 % of the image, a 20×20 px patch), scaled linearly with the image area so a
view's classification does not change with its resolution; ``min_fraction = 0.5`` (at least
half of the object's unoccluded, untruncated projection is visible).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import StrEnum

from spacedg.errors import InvalidDataError
from spacedg.scene.model import InstanceVisibility

__all__ = ["VisibilityClass", "VisibilityThresholds", "DEFAULT_THRESHOLDS", "REFERENCE_AREA", "classify"]

#: Pixels of the reference image size 640×480 at which ``min_pixels`` is stated.
REFERENCE_AREA = 640 * 480


class VisibilityClass(StrEnum):
    """How well a view shows an instance."""

    VISIBLE = "visible"
    PARTIAL = "partial"
    HIDDEN = "hidden"


@dataclass(frozen=True)
class VisibilityThresholds:
    """Thresholds of :func:`classify`.

    Attributes:
        min_pixels: visible pixels needed for "clearly visible" at :attr:`reference_area`
            (> 0); scaled linearly with the image area.
        min_fraction: visible fraction of the instance's own projection needed, in (0, 1].
        reference_area: image area in pixels at which ``min_pixels`` holds (default 640×480).
    """

    min_pixels: float = 400.0
    min_fraction: float = 0.5
    reference_area: int = REFERENCE_AREA

    def __post_init__(self) -> None:
        if isinstance(self.min_pixels, bool) or not isinstance(self.min_pixels, (int, float)) or not math.isfinite(self.min_pixels) or self.min_pixels <= 0:
            raise InvalidDataError(f"VisibilityThresholds: min_pixels must be a number > 0 (pixels at 640×480), got {self.min_pixels!r}")
        if isinstance(self.min_fraction, bool) or not isinstance(self.min_fraction, (int, float)) or not 0.0 < self.min_fraction <= 1.0:
            raise InvalidDataError(f"VisibilityThresholds: min_fraction must be in (0, 1], got {self.min_fraction!r}")
        if isinstance(self.reference_area, bool) or not isinstance(self.reference_area, int) or self.reference_area < 1:
            raise InvalidDataError(f"VisibilityThresholds: reference_area must be a positive integer number of pixels, got {self.reference_area!r}")

    def pixels_for(self, image_area: int | None) -> float:
        """``min_pixels`` scaled to an image of ``image_area`` pixels (unscaled if ``None``)."""
        if image_area is None:
            return float(self.min_pixels)
        if isinstance(image_area, bool) or int(image_area) != image_area or image_area < 1:
            raise InvalidDataError(f"visibility: image_area must be a positive integer number of pixels, got {image_area!r}")
        return float(self.min_pixels) * float(image_area) / float(self.reference_area)

    def to_dict(self) -> dict[str, float]:
        return {"min_pixels": float(self.min_pixels), "min_fraction": float(self.min_fraction), "reference_area": self.reference_area}


DEFAULT_THRESHOLDS = VisibilityThresholds()


def classify(
    vis: InstanceVisibility | None,
    thresholds: VisibilityThresholds = DEFAULT_THRESHOLDS,
    image_area: int | None = None,
) -> VisibilityClass:
    """Classify one instance in one view.

    Args:
        vis: the instance's visibility in the view (``None``: no record → hidden).
        thresholds: see :class:`VisibilityThresholds`.
        image_area: the view's ``width * height`` in pixels, to scale ``min_pixels``; ``None``
            uses ``min_pixels`` as is.
    """
    if vis is None or vis.visible_pixels == 0:
        return VisibilityClass.HIDDEN
    if vis.visible_pixels >= thresholds.pixels_for(image_area) and vis.visible_fraction >= thresholds.min_fraction:
        return VisibilityClass.VISIBLE
    return VisibilityClass.PARTIAL

"""A warning for degraded views that show nothing: one flat colour where the render had content.

Every parameter of a degradation has hard limits, and within them some values erase the view:
haze of density 100 is pure airlight, over-exposure at a gain of 10⁶ is white, low light at an
exposure of 10⁻⁹ is black. Such an image is valid output (the user asked for it), but a question
about it measures nothing but priors, and a training sample teaches nothing. So the pipeline
says so: :func:`warn_if_erased` raises an :class:`~spacedg.errors.ErasedViewWarning` (a
:class:`~spacedg.errors.SpaceDGWarning`: the command line prints it on one line) for each view
whose final 8-bit image is one colour while what the chain started from, in 8 bits (the clean
render encoded, or the image handed to :func:`~spacedg.data.pipeline.degrade_image`), was not: a
render whose light varies below one 8-bit step (a dark wall) is flat already. Nothing is changed or
dropped.

Each process reports a chain (its degradations' names) once per scene: the parameters of a sample
vary (drawn from ranges, metres scaled to the sample's scene depth), so a message per setting would
repeat for every item of a run; the one report names the first erasing setting and the scene
(:data:`_REPORTED`; DataLoader workers report for themselves). Presets erase nothing and never
warn. A render that is flat itself (a camera facing a blank wall or empty space) is not the chain's
doing and is not reported here.

Cost: a strided sample of the image decides almost every view (an image with content differs
from its first pixel in the sample); the full comparison runs only on images that pass it.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence
from typing import Any, Union

import numpy as np

from spacedg.errors import ErasedViewWarning

__all__ = ["is_flat", "warn_if_erased"]

#: Strides (rows, columns) of the quick sample that rules out most images before the full test.
_SAMPLE_STRIDE = (7, 11)
#: ``(where, degradation names)`` already reported by this process.
_REPORTED: set[tuple[str, tuple[str, ...]]] = set()
#: What a chain started from: an image, a function that makes it (called only for a flat result), or unknown.
Source = Union[np.ndarray, Callable[[], Union[np.ndarray, None]], None]


def is_flat(image: np.ndarray) -> bool:
    """Whether every pixel of ``image`` ((H, W) or (H, W, C), any dtype) equals its first pixel
    (NaN never equals: an image holding NaN is not flat). An empty image is not flat."""
    if image.size == 0:
        return False
    first = image[0, 0]
    if not np.all(image[:: _SAMPLE_STRIDE[0], :: _SAMPLE_STRIDE[1]] == first):
        return False
    return bool(np.all(image == first))


def _has_content(source: Source) -> bool:
    """Whether ``source`` (:data:`Source`) is known and not flat."""
    image = source() if callable(source) else source
    return image is not None and not is_flat(image)


def _describe(chain: Sequence[Any]) -> str:
    """``haze {density: 100, airlight: 0.9}, jpeg_compression {quality: 30}``: each step's name and parameters."""
    parts = []
    for step in chain:
        params = ", ".join(f"{key}: {value:g}" if isinstance(value, float) else f"{key}: {value}" for key, value in step.params.items())
        parts.append(f"{step.name} {{{params}}}")
    return ", ".join(parts)


def warn_if_erased(
    images: Sequence[np.ndarray], sources: Sequence[Source], chain: Sequence[Any], where: str, once: bool = True,
) -> int:
    """Warn (:class:`~spacedg.errors.ErasedViewWarning`) if ``chain`` (resolved steps with ``name`` and
    ``params``) turned any source with content into a flat image, the first time this process sees that
    chain do so at ``where``; returns how many views it erased (reported or not).

    Args:
        images: the final images, one per view (uint8 (H, W, 3)).
        sources: what the chain started from in 8 bits, one per view (the clean render encoded, or the
            input image), or a function that makes it, called only where the image is flat; ``None`` where
            unknown (that view is not reported).
        chain: the resolved degradations applied (empty: nothing is checked).
        where: the scene (or input) the views belong to, for the message, e.g. ``"scene room-000001"``.
        once: report a chain once per ``where`` in this process (the pipeline's items); ``False``: every
            call (:func:`~spacedg.data.pipeline.degrade_image`, one image a call; Python's filter still
            shows a repeated message once).
    """
    if not chain:
        return 0
    erased = [image for image, source in zip(images, sources) if is_flat(image) and _has_content(source)]
    key = (where, tuple(step.name for step in chain))
    if erased and (not once or key not in _REPORTED):
        if once:
            _REPORTED.add(key)
        colour = tuple(int(v) for v in np.atleast_1d(erased[0][0, 0]))
        views = "every view" if len(erased) == len(images) else f"{len(erased)} of {len(images)} views"
        message = (
            f"{_describe(chain)} turned {views} of {where} into one flat colour (every pixel {colour}) though the "
            "undegraded view has content: the image shows nothing of the scene, so a question about it measures priors "
            "and a training sample teaches nothing. These parameters erase the view; weaken them toward the presets' "
            "ranges, which do not (docs/degradations.md; spacedg.plugins.get_degradation(name).presets)"
        )
        warnings.warn(ErasedViewWarning(message + (". Reported once per scene for this chain" if once else "")), stacklevel=2)
    return len(erased)

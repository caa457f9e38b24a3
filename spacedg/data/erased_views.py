"""A warning for degraded views that show nothing: one flat colour where the render had content.

Every parameter of a degradation has hard limits, and within them some values erase the view:
haze of density 100 is pure airlight, over-exposure at a gain of 10⁶ is white, low light at an
exposure of 10⁻⁹ is black. Such an image is valid output (the user asked for it), but a question
about it measures nothing but priors, and a training sample teaches nothing. So the pipeline
says so: :func:`warn_if_erased` raises an :class:`~spacedg.errors.ErasedViewWarning` (a
:class:`~spacedg.errors.SpaceDGWarning`: the command line prints it on one line) for each view
whose final 8-bit image is one colour while what its linear and display steps started from, in 8
bits, was not (the chain's render encoded: the clean render, or the render its raster steps (defocus,
distortion, motion blur) edited; or the image handed to :func:`~spacedg.data.pipeline.degrade_image`):
a render whose light varies below one 8-bit step (a dark wall) is flat already, and a raster step that
flattens the render itself is not reported. On a fisheye view only the pixels inside the image
circle count (those outside are black in every image). Nothing is changed or dropped.

Each process reports a chain (its degradations' names) once per scene: the parameters of a sample
vary (drawn from ranges, metres scaled to the sample's scene depth), so a message per setting would
repeat for every item of a run; the one report names the first erasing setting and the scene
(:data:`_REPORTED`: per process, so each DataLoader worker reports for itself, and two datasets of
one process over the same scene share one report). The presets are chosen not to erase a view, but
an extreme one can (over-exposure's bench gain of 7–10 whitens a close-up of a white wall), and is
then reported like any other setting. A render that is flat itself (a camera facing a blank wall or empty space) is not the chain's
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


def _pixels(image: np.ndarray, valid: np.ndarray | None) -> np.ndarray:
    """The pixels of ``image`` ((H, W) or (H, W, C)) along one axis, (N,) or (N, C): all of them (a view of a
    contiguous image), or those ``valid`` ((H, W) bool) marks."""
    return image[valid] if valid is not None else image.reshape(-1, *image.shape[2:])


def is_flat(image: np.ndarray, valid: np.ndarray | None = None) -> bool:
    """Whether every pixel of ``image`` ((H, W) or (H, W, C), any dtype) equals the first (NaN never equals:
    an image holding NaN is not flat); with ``valid`` ((H, W) bool), only the pixels it marks count. An image
    with no such pixel is not flat. A strided sample (:data:`_SAMPLE_STRIDE`) rules out almost every image
    before the whole is read (or, with ``valid``, copied)."""
    rows, cols = _SAMPLE_STRIDE
    if valid is None:
        if image.size and not np.all(image[::rows, ::cols] == image[0, 0]):  # a strided view: nothing copied
            return False
    else:
        sample = image[::rows, ::cols][valid[::rows, ::cols]]
        if sample.shape[0] and not np.all(sample == sample[0]):
            return False
    pixels = _pixels(image, valid)
    return pixels.shape[0] > 0 and bool(np.all(pixels == pixels[0]))


def _has_content(source: Source, valid: np.ndarray | None) -> bool:
    """Whether ``source`` (:data:`Source`) is known and not flat over ``valid``."""
    image = source() if callable(source) else source
    return image is not None and not is_flat(image, valid)


def _describe(chain: Sequence[Any]) -> str:
    """``haze {density: 100, airlight: 0.9}, jpeg_compression {quality: 30}``: each step's name and parameters."""
    parts = []
    for step in chain:
        params = ", ".join(f"{key}: {value:g}" if isinstance(value, float) else f"{key}: {value}" for key, value in step.params.items())
        parts.append(f"{step.name} {{{params}}}")
    return ", ".join(parts)


def warn_if_erased(
    images: Sequence[np.ndarray], sources: Sequence[Source], chain: Sequence[Any], where: str, once: bool = True,
    valid: Sequence[np.ndarray | None] | None = None,
) -> int:
    """Warn (:class:`~spacedg.errors.ErasedViewWarning`) if ``chain`` (resolved steps with ``name`` and
    ``params``) turned any source with content into a flat image, the first time this process sees that
    chain do so at ``where``; returns how many views it erased (0 without looking once the chain was
    reported at ``where``).

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
        valid: per view, the pixels that count ((H, W) bool: a fisheye's image circle), or ``None`` (all).
    """
    key = (where, tuple(step.name for step in chain))
    if not chain or (once and key in _REPORTED):
        return 0
    masks = [None] * len(images) if valid is None else valid
    erased = [
        _pixels(image, mask)[0]
        for image, source, mask in zip(images, sources, masks, strict=True)
        if is_flat(image, mask) and _has_content(source, mask)
    ]
    if erased:
        colour = tuple(int(v) for v in np.atleast_1d(erased[0]))
        views = "every view" if len(erased) == len(images) else f"{len(erased)} of {len(images)} views"
        message = (
            f"{_describe(chain)} turned {views} of {where} into one flat colour (every pixel {colour}) though its "
            "render has content: the image shows nothing of the scene, so a question about it measures priors "
            "and a training sample teaches nothing. These parameters erase the view; weaken them (the presets' ranges: "
            "docs/degradations.md; spacedg.plugins.get_degradation(name).presets)"
        )
        # warned before it is marked: under an "error" filter every erased item raises, not only the first
        warnings.warn(ErasedViewWarning(message + (". Reported once per scene for this chain" if once else "")), stacklevel=3)
        if once:
            _REPORTED.add(key)
    return len(erased)

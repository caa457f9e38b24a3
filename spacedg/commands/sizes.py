"""argparse types for image sizes: one rule (:mod:`spacedg.limits`) and one message for every command.

``--image-size WxH`` (``render``, ``scenes synth``, ``export``, ``predict``), the deprecated
``--width`` / ``--height`` (``render``, ``scenes synth``) and ``--min-pixels`` / ``--max-pixels``
(``predict``) parse with these, so a size over the policy is a usage error (exit 2) that says what
the limit is and why, before any scene is read.
"""

from __future__ import annotations

import argparse

from spacedg.limits import MAX_IMAGE_PIXELS, MAX_IMAGE_SIDE, POLICY, image_size_problem

__all__ = ["MIN_RENDER_SIDE", "image_side", "image_size", "pixel_budget"]

#: Smallest side of ``--image-size`` (a render of a dataset item), pixels.
MIN_RENDER_SIDE = 8
_MAX_DIGITS = 12  # longer digit strings are never a size (and int() of 5,000 digits raises)


def _whole(text: str, what: str) -> int:
    cleaned = text.strip()
    if not cleaned.isdigit() or len(cleaned) > _MAX_DIGITS:
        shown = cleaned if len(cleaned) <= 40 else f"{cleaned[:40]}… ({len(cleaned):,} characters)"
        raise argparse.ArgumentTypeError(f"{what} must be a whole number of pixels, got {shown!r}")
    return int(cleaned)


def image_side(text: str) -> int:
    """An image width or height: a whole number in [1, :data:`MAX_IMAGE_SIDE`] pixels."""
    value = _whole(text, "an image side")
    if value < 1:
        raise argparse.ArgumentTypeError("must be at least 1 pixel, got 0")
    if value > MAX_IMAGE_SIDE:
        raise argparse.ArgumentTypeError(f"{value} pixels is over the limit: {POLICY}")
    return value


def image_size(text: str) -> tuple[int, int]:
    """``WxH`` (e.g. ``640x480``): each side in [:data:`MIN_RENDER_SIDE`, :data:`MAX_IMAGE_SIDE`], W·H within the pixel limit."""
    parts = text.lower().split("x")
    if len(parts) != 2:
        shown = text if len(text) <= 40 else f"{text[:40]}…"
        raise argparse.ArgumentTypeError(f"must read WxH in pixels, e.g. 640x480, got {shown!r}")
    width, height = (_whole(part, "each side of WxH") for part in parts)
    if width < MIN_RENDER_SIDE or height < MIN_RENDER_SIDE:
        raise argparse.ArgumentTypeError(f"{width}x{height}: width and height must be >= {MIN_RENDER_SIDE} pixels")
    problem = image_size_problem(width, height)
    if problem is not None:
        raise argparse.ArgumentTypeError(f"{problem}; pick a smaller WxH")
    return width, height


def pixel_budget(text: str) -> int:
    """A number of pixels per image in [1, :data:`MAX_IMAGE_PIXELS`] (a VLM processor's image budget)."""
    value = _whole(text, "a pixel budget")
    if not 1 <= value <= MAX_IMAGE_PIXELS:
        raise argparse.ArgumentTypeError(f"must be in [1, {MAX_IMAGE_PIXELS:,}] pixels per image, got {value:,}: {POLICY}")
    return value

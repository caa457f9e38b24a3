"""Size policy: the largest image spacedg renders, reads or writes, in one place.

Every camera reader (through :class:`~spacedg.render.camera.Camera`), the render options of
the data pipeline and every command-line size argument check sizes here, so one message
explains the limit everywhere:

- :data:`MAX_IMAGE_SIDE` = 16384 pixels a side (panoramas and 16K frames fit);
- :data:`MAX_IMAGE_PIXELS` = 2²⁵ = 33,554,432 pixels per view (8K UHD 7680×4320 = 33.2 MP
  and 33 MP DSLR frames, e.g. 7008×4672, fit).

Why: one view's render holds about :data:`BYTES_PER_PIXEL` bytes per pixel at its peak
(float32 colour, alpha, expected and median depth, instance ids, the linear-light copies of
the degradation chain, motion blur's float64 accumulators), so the largest view needs about
3.4 GB; a camera record of 10⁶ or 2⁶³ pixels a side would only fail later with an
out-of-memory error far from its cause.
"""

from __future__ import annotations

from spacedg.errors import InvalidDataError

__all__ = [
    "BYTES_PER_PIXEL",
    "MAX_IMAGE_PIXELS",
    "MAX_IMAGE_SIDE",
    "POLICY",
    "check_image_size",
    "check_pixel_count",
    "image_size_problem",
]

#: Largest image width or height, pixels.
MAX_IMAGE_SIDE = 16384
#: Largest number of pixels of one view (width × height).
MAX_IMAGE_PIXELS = 1 << 25
#: Approximate peak working memory of one rendered and degraded view, bytes per pixel.
BYTES_PER_PIXEL = 100

#: The policy and its reason in one sentence, for error messages.
POLICY = (
    f"spacedg renders at most {MAX_IMAGE_SIDE} pixels a side and {MAX_IMAGE_PIXELS:,} pixels per view "
    f"(8K UHD fits; a view needs ~{BYTES_PER_PIXEL} bytes per pixel while it renders, "
    f"~{MAX_IMAGE_PIXELS * BYTES_PER_PIXEL / 1e9:.1f} GB at the limit)"
)


def _number(value: int) -> str:
    """``value`` in decimal, or ``"<a ~N-digit number>"`` when it is too long to be worth printing."""
    if abs(value) < 10**20:
        return str(value)
    return f"<a {int(abs(value).bit_length() * 0.30103) + 1:,}-digit number>"


def image_size_problem(width: int, height: int) -> str | None:
    """``None`` if ``width × height`` pixels is within the policy, else what is wrong and why."""
    if width > MAX_IMAGE_SIDE or height > MAX_IMAGE_SIDE:
        return f"{_number(width)}×{_number(height)} pixels is over the limit: {POLICY}"
    if width * height > MAX_IMAGE_PIXELS:
        return f"{width}×{height} = {width * height:,} pixels is over the limit: {POLICY}"
    return None


def check_image_size(width: int, height: int, what: str, fix: str, error: type[Exception] = InvalidDataError) -> None:
    """Raise ``error("<what>: <problem>; <fix>")`` when ``width × height`` (positive ints) breaks the policy.

    Args:
        width, height: image size, pixels (already checked to be positive integers).
        what: where the size came from, e.g. ``"Camera"`` or ``"--image-size"``.
        fix: how to get under the limit, e.g. ``"render smaller (image_size=...)"``.
        error: the exception type to raise (the caller's error type).
    """
    problem = image_size_problem(int(width), int(height))
    if problem is not None:
        raise error(f"{what}: {problem}; {fix}")


def check_pixel_count(pixels: int, what: str, error: type[Exception] = InvalidDataError) -> None:
    """Raise ``error`` when a per-image pixel budget ``pixels`` is not in [1, :data:`MAX_IMAGE_PIXELS`]."""
    if not 1 <= int(pixels) <= MAX_IMAGE_PIXELS:
        raise error(f"{what} must be in [1, {MAX_IMAGE_PIXELS:,}] pixels per image, got {_number(int(pixels))}: {POLICY}")

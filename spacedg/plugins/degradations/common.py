"""Input checks shared by the built-in degradations (not a plugin: no entry point).

Every stage contract of :mod:`spacedg.plugins.specs` starts by checking its input the same
way, so the messages are the same everywhere:

- linear stage: ``rgb`` float32 (H, W, 3), linear light, unclamped (values are not scanned:
  a model that would turn a non-finite input into NaN checks for it itself);
- display stage: ``image`` uint8 (H, W, 3), sRGB-encoded RGB;
- render outputs from ``aux``: present when the spec declared them in ``needs``, float32
  (H, W) matching the image.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from spacedg.errors import InvalidDataError
from spacedg.plugins.specs import ParamRange

__all__ = ["FAR_PERCENTILE", "COMMON_ASPECTS", "severity_ladder", "check_linear_rgb", "check_display_image", "aux_image", "stream_key",
           "box_pad", "reflect_index", "snapped_size", "surface_far_depth", "view_aspect"]


def _describe(value: object) -> str:
    if isinstance(value, np.ndarray):
        return f"{value.dtype} array of shape {value.shape}"
    return type(value).__name__


def check_linear_rgb(rgb: object, name: str) -> np.ndarray:
    """Return ``rgb`` if it is linear-light float32 (H, W, 3), else raise.

    Args:
        rgb: the linear-stage input.
        name: the degradation's name, for the message.
    """
    if not isinstance(rgb, np.ndarray) or rgb.dtype != np.float32 or rgb.ndim != 3 or rgb.shape[2] != 3:
        raise InvalidDataError(
            f"{name}: expected linear-light float32 RGB of shape (H, W, 3), got {_describe(rgb)}; "
            "decode sRGB with spacedg.render.colour.srgb_to_linear and cast to float32"
        )
    if rgb.shape[0] < 1 or rgb.shape[1] < 1:
        raise InvalidDataError(f"{name}: the image is empty (shape {rgb.shape})")
    return rgb


def check_display_image(image: object, name: str) -> np.ndarray:
    """Return ``image`` if it is an 8-bit sRGB RGB picture (uint8 (H, W, 3)), else raise.

    Float input is refused: OpenCV would silently cast a [0, 1] float image to 8 bits (black).
    """
    if not isinstance(image, np.ndarray):
        raise InvalidDataError(f"{name}: image must be a numpy array (uint8, H×W×3 RGB), got {type(image).__name__}")
    if image.dtype != np.uint8:
        raise InvalidDataError(
            f"{name}: image must be uint8 sRGB (H×W×3 RGB), got dtype {image.dtype}; encode linear light to sRGB and "
            "quantise to 8 bits first (spacedg.render.colour_cpu.encode_srgb_u8): OpenCV would silently cast floats, "
            "turning a [0, 1] image black"
        )
    if image.ndim != 3 or image.shape[2] != 3 or image.shape[0] < 1 or image.shape[1] < 1:
        raise InvalidDataError(f"{name}: image must have shape (H, W, 3) RGB, got {image.shape}")
    return image


def aux_image(aux: Mapping[str, np.ndarray], key: str, shape: tuple[int, int], name: str) -> np.ndarray:
    """The render output ``aux[key]`` as float32 (H, W), or a clear error if it is missing or mis-shaped."""
    if not isinstance(aux, Mapping) or key not in aux or aux[key] is None:
        have = sorted(aux) if isinstance(aux, Mapping) else []
        raise InvalidDataError(
            f"{name} needs the rendered {key!r} of the view, but it was not provided (aux has {have}); "
            f"render the view with outputs including {key!r} (the pipeline does this when the spec declares it in needs)"
        )
    value = np.asarray(aux[key])
    if value.shape != tuple(shape):
        raise InvalidDataError(f"{name}: rendered {key!r} has shape {value.shape}, but the image is {tuple(shape)}")
    return value.astype(np.float32, copy=False)


def stream_key(rng: np.random.Generator) -> int:
    """One 63-bit key drawn from ``rng``, for counter-based per-pixel random numbers.

    Per-pixel noise is generated in parallel compiled kernels from ``hash(key, pixel, draw)``,
    so the result is the same whatever the number of threads, and one call consumes exactly
    one draw of ``rng``.
    """
    if not isinstance(rng, np.random.Generator):
        raise InvalidDataError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}; use np.random.default_rng(seed)")
    return int(rng.integers(0, 2**63 - 1, dtype=np.int64))


#: Percentile of the surface depths taken as a view's far depth (robust to a few stray far splats).
FAR_PERCENTILE = 99.0
#: Subsampling stride (both axes) for :func:`surface_far_depth`; 1/16 of the pixels is plenty for a percentile.
_FAR_STRIDE = 4


def surface_far_depth(depth: np.ndarray, alpha: np.ndarray) -> float:
    """A view's far surface depth in metres: the 99th percentile of the depths of covered pixels.

    Covered = ``alpha > 0.5`` with a finite positive depth; pixels are subsampled with stride 4.
    Returns 0.0 when no pixel is covered.
    """
    d = np.asarray(depth)[::_FAR_STRIDE, ::_FAR_STRIDE]
    a = np.asarray(alpha)[::_FAR_STRIDE, ::_FAR_STRIDE]
    covered = d[(a > 0.5) & np.isfinite(d) & (d > 0)]
    if covered.size == 0:
        return 0.0
    return float(np.percentile(covered, FAR_PERCENTILE))


def severity_ladder(
    param: str, levels: tuple[tuple[float, float], ...], bench: int = 5, per_size: int = 0,
) -> dict[str, dict[str, ParamRange]]:
    """Presets of a one-parameter degradation: severities ``"1"``–``"5"`` from ``levels`` (five
    ``(low, high)`` ranges of ``param``, mildest first) and ``"bench"``, the paper's range, equal
    to severity ``bench``; ``per_size`` as :class:`~spacedg.plugins.specs.ParamRange`'s."""
    if len(levels) != 5:
        raise ValueError(f"severity_ladder({param!r}): give 5 ranges (severities 1-5), got {len(levels)}")
    presets = {str(level): {param: ParamRange(*bounds, per_size=per_size)} for level, bounds in enumerate(levels, start=1)}
    return {"bench": dict(presets[str(bench)]), **presets}


#: Aspect ratios (long side / short side) of common sensors and views. An image within one pixel of
#: one (a view fitted to a size: 1752 × 1168 at 584 × 389 or 640 × 427 is 3:2 up to rounding) counts
#: as that ratio wherever a degradation lays a grid over the image (photosites, drop cells), so every
#: size of one view gets the same grid: from the rounded size, 584 × 389 had 1754 photosite columns
#: against 1752 and its drop cells another count per row (new drops), 32 / 34.6 dB instead of ~40 in
#: ``benchmarks/resolution.py --high 1752x1168 --low 584x389``.
COMMON_ASPECTS = (1.0, 5 / 4, 4 / 3, 3 / 2, 16 / 10, 5 / 3, 16 / 9, 2.0, 21 / 9)


def view_aspect(width: int, height: int) -> float:
    """The image's aspect ratio, long side over short side (>= 1): the :data:`COMMON_ASPECTS` ratio
    nearest to it when one is within one pixel (an exact one is itself), else its own."""
    short, long = min(width, height), max(width, height)
    near = min(COMMON_ASPECTS, key=lambda c: abs(long - c * short))
    return near if abs(long - near * short) <= 1.0 else long / short


def snapped_size(width: int, height: int) -> tuple[float, float]:
    """``(width, height)`` in pixels as the image's :func:`view_aspect` has them: the longer side is
    ``aspect × shorter side``, or itself when that is exact (then bit for bit the image's own, as
    every grid laid over it was before); the shorter side is its own. Grids laid over the image
    (photosites, drop cells) count from these, so every size of one view gets the same grid."""
    short, long = min(width, height), max(width, height)
    snapped = view_aspect(width, height) * short
    side = float(long) if abs(snapped - long) < 1e-6 else snapped
    return (side, float(height)) if width >= height else (float(width), side)


def box_pad(spread: float, shape: tuple[int, int]) -> int:
    """Pixels of ``BORDER_REFLECT`` padding for squares of side up to ``spread`` px around points in the
    frame of ``shape``: half the side and one, at most the frame's longer side (a square wider than
    that is cut at the padding's edge). Shared by both backends of ``water_droplets``' refracted view."""
    return int(min(math.ceil(0.5 * spread) + 1, max(shape)))


def reflect_index(n: int, pad: int) -> np.ndarray:
    """Source indices of ``n`` pixels padded by ``pad`` on each side with OpenCV's ``BORDER_REFLECT``
    (``fedcba|abcdef|fedcba``), folded as often as the pad needs (period ``2n``)."""
    q = np.mod(np.arange(-pad, n + pad), 2 * n)
    return np.where(q < n, q, 2 * n - 1 - q)

"""Render requests: which outputs, rasterizer constants, defocus and motion blur.

Every value here is validated on construction; an impossible parameter raises
:class:`~spacedg.errors.ParameterError` naming the field and the allowed range.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Iterable

import numpy as np

from spacedg._checks import finite_float
from spacedg.errors import ParameterError

#: Names of the render outputs (``Frame`` attributes).
OUTPUT_NAMES = ("rgb", "alpha", "depth", "median_depth", "instance_ids")
#: Side of the square screen tiles, pixels (fixed: the compiled kernel vectorises 16-pixel rows).
TILE_SIZE = 16
#: Smallest per-pixel alpha that is composited (1/255), as in 3DGS and gsplat.
ALPHA_MIN = 1.0 / 255.0
#: Compositing stops *before* the Gaussian that would take transmittance to or below this.
TRANSMITTANCE_MIN = 1e-4
#: Footprint radii are capped at this many pixels: wider than any image the size policy allows
#: (16384 px), so the cap changes no pixel, and it keeps the radii exact integers in both
#: backends for Gaussians of any finite size (a Gaussian 10²⁰ m wide seen from 1 m away).
FOOTPRINT_CAP = float(1 << 30)
#: Smallest circle of confusion (px) that blurs: a Gaussian whose ``r`` is below it is rendered sharp
#: (``r = 0``). 0: every blur counts, however small — a cut-off in output pixels breaks size invariance
#: (issue 29: at 0.5 px, the room's defocus rows of ``benchmarks/resolution.py`` were 29.5 / 29.8 dB at
#: severities 1 / 2, because the 640-px render was sharp where the 1920-px one blurred). Sub-pixel
#: blur is exact in the per-Gaussian model (``r²·I`` added to a covariance), and
#: :mod:`spacedg.render.defocus_flux` keeps its light.
DEFOCUS_MIN_COC = 0.0
#: Relative slack of the motion rotation's π limit: ``rot · axis`` for a unit ``axis`` has a norm within
#: a few ulps of ``rot``, so the limit itself (the motion-blur degradation's ``rot`` hard limit, π) passes.
_ANGLE_ROUNDING = 1e-12


def _finite(name: str, value: object, low: float | None = None, high: float | None = None, *, open_low: bool = False) -> float:
    number = finite_float(value, name, ParameterError)
    if low is not None and (number < low or (open_low and number == low)):
        bound = ">" if open_low else ">="
        raise ParameterError(f"{name} must be {bound} {low}, got {number}")
    if high is not None and number > high:
        raise ParameterError(f"{name} must be <= {high}, got {number}")
    return number


def parse_outputs(outputs: str | Iterable[str]) -> frozenset[str]:
    """Normalise an output request (``"rgb,depth"``, a list, or ``"all"``)."""
    if isinstance(outputs, str):
        items = [o.strip() for o in outputs.split(",") if o.strip()]
    else:
        items = [str(o) for o in outputs]
    if items == ["all"]:
        items = list(OUTPUT_NAMES)
    unknown = sorted(set(items) - set(OUTPUT_NAMES))
    if unknown:
        raise ParameterError(f"unknown render output(s) {unknown}; choose from {list(OUTPUT_NAMES)} or 'all'")
    if not items:
        raise ParameterError(f"no render output requested; choose from {list(OUTPUT_NAMES)}")
    return frozenset(items)


@dataclass(frozen=True)
class RasterSettings:
    """Constants of the projection and compositing (defaults = 3DGS / gsplat).

    Attributes:
        near, far: depth range kept, metres along the optical axis (camera z).
        eps2d: low-pass dilation added to every 2D covariance, pixels² (of the output, or of the
            capture when the camera knows it: :func:`footprint_dilation`).
        alpha_max: cap on one Gaussian's alpha at one pixel (0.99 as in 3DGS; gsplat 1.5.3 used 0.999).
        antialiased: the Gaussians are exact (no training dilation): multiply opacity by
            ``sqrt(det Σ / det(Σ + eps2d I))`` (Mip-Splatting style), whatever the camera's ``capture_focal``.
        dilation_scale: the render's pixels are ``1 / dilation_scale`` times the view's (the defocus
            measurement pass on a coarser grid): every term of :func:`footprint_dilation` is
            multiplied by ``dilation_scale²``, so each footprint is the view's, scaled. 1: the view's own.
        opacity_extent: footprint radius ``min(3.33, sqrt(2 ln(255 o)))`` standard deviations and
            cull ``o < 1/255`` (gsplat's CUDA kernels); ``False`` gives the fixed 3.33 σ of
            gsplat's torch reference (used by the parity tests).
        tight_tiles: drop tiles that a footprint's bounding box touches but its
            ``alpha >= 1/255`` ellipse does not (exact: the image is unchanged, work is not).
        defocus_extent: footprint of a defocused Gaussian (CoC > 1 px) in standard deviations
            of its blurred covariance; its opacity is divided by the mass kept,
            ``1 − e^(−E²/2)``, so its energy is unchanged. 2.5 (95.6 % of the mass) is 1.6×
            faster than the full 3.33 σ at 43–46 dB PSNR (``benchmarks/degradations.py``
            prints the comparison); ``None`` keeps the full footprint.
    """

    near: float = 0.01
    far: float = 1e10
    eps2d: float = 0.3
    alpha_max: float = 0.99
    antialiased: bool = False
    dilation_scale: float = 1.0
    opacity_extent: bool = True
    tight_tiles: bool = True
    defocus_extent: float | None = 2.5

    def __post_init__(self) -> None:
        if self.defocus_extent is not None:
            _finite("defocus_extent", self.defocus_extent, 1.0, 3.33)
        _finite("near", self.near, 0.0, open_low=True)
        _finite("far", self.far, self.near, open_low=True)
        _finite("eps2d", self.eps2d, 0.0)
        _finite("dilation_scale", self.dilation_scale, 0.0, 1.0, open_low=True)
        _finite("alpha_max", self.alpha_max, ALPHA_MIN, 1.0)
        if self.alpha_max >= 1.0:
            raise ParameterError(f"alpha_max must be < 1 so transmittance never reaches 0 in one step, got {self.alpha_max}")


def footprint_dilation(camera: Any, settings: RasterSettings) -> tuple[float, float, float, float]:
    """``(model_x, model_y, filter_x, filter_y)``, px² of the output: what is added to every 2D
    covariance's diagonal before compositing.

    ``model`` is part of the Gaussians' look and is added as is; ``filter`` is a low-pass on top
    of it, with the opacity multiplied by ``sqrt(det(Σ + model) / det(Σ + model + filter))`` so the
    footprint's integrated alpha is unchanged (Mip-Splatting's 2D filter). Three cases:

    - ``settings.antialiased``: the Gaussians are exact: ``model = 0``, ``filter = eps2d``.
    - ``camera.capture_focal`` known, ``s = f / capture f`` per axis: ``model = eps2d · s²`` (the
      training dilation, 0.3 px² in the capture's pixels) and, for ``s < 1``, ``filter = (1 − s²)/12``:
      the variance of the mean of the ``1/s`` capture pixels an output pixel spans (a discrete box,
      ``(n² − 1)/(12 n²)``), so the render approximates the area-average of the native render. At
      ``s = 1`` this is the classic dilation, bit for bit. Measured (``benchmarks/resolution.py
      --scene plant``, capture focal at 1920×1080, 640×360 against the 1920×1080 render
      area-downsampled): 31.0 dB classic, 38.6 with Mip's ``filter = eps2d − model``, 45.4 with this
      box variance; the best total (0.085 px²) gave 46.1.
    - otherwise (classic 3DGS / gsplat): ``model = eps2d``, ``filter = 0``.

    Every term is then × ``settings.dilation_scale²`` (a pass on a coarser grid than the view's). On a
    fisheye the scale is the global focal's; the lens's local magnification is not followed (as in
    the classic dilation).
    """
    k = float(settings.dilation_scale)
    eps = float(settings.eps2d) * k * k
    if settings.antialiased:
        return 0.0, 0.0, eps, eps
    focal = getattr(camera, "capture_focal", None)
    if focal is None:
        return eps, eps, 0.0, 0.0
    sx, sy = float(camera.fx) / focal[0], float(camera.fy) / focal[1]  # at s = 1: eps, eps, 0, 0 (the classic)
    return eps * sx * sx, eps * sy * sy, _box_variance(sx) * k * k, _box_variance(sy) * k * k


def _box_variance(scale: float) -> float:
    """px²: the variance of the mean of ``1/scale`` capture pixels per output pixel (0 when ``scale >= 1``)."""
    return (1.0 - scale * scale) / 12.0 if scale < 1.0 else 0.0


@dataclass(frozen=True)
class Defocus:
    """Thin-lens defocus applied inside the rasterizer.

    A Gaussian at camera depth ``d`` (metres) gets a circle of confusion of radius
    ``r = aperture · |d − focus| / d`` pixels (at the rendered resolution), clamped to
    ``max_radius``; ``r² I`` is added to its 2D covariance (after the ``eps2d`` dilation) and
    its opacity is multiplied by ``sqrt(det Σ / det(Σ + r² I))`` so its integrated alpha is
    unchanged; the view keeps its light through the local flux step of :mod:`spacedg.render.defocus_flux`.
    ``aperture = 0``, or every visible Gaussian in focus, is the sharp render, bit for bit.

    Attributes:
        aperture: CoC radius in pixels for a point at infinity (the thin-lens a·f/N scaled to pixels).
        focus: focus distance, metres (> 0).
        max_radius: clamp on r, pixels. Near objects with a far focus would otherwise get
            radii of hundreds of pixels (and cost that many pixels² each). Default
            ``3 · aperture`` (at most 10⁴): the CoC of a point at a quarter of the focus distance.
    """

    aperture: float
    focus: float
    max_radius: float | None = None

    def __post_init__(self) -> None:
        _finite("defocus aperture", self.aperture, 0.0, 1e4)
        _finite("defocus focus", self.focus, 0.0, open_low=True)
        if self.max_radius is None:
            object.__setattr__(self, "max_radius", min(3.0 * float(self.aperture), 1e4))
        _finite("defocus max_radius", self.max_radius, 0.0, 1e4)

    def radius(self, depth: np.ndarray) -> np.ndarray:
        """CoC radius (pixels) for camera depths ``depth`` (metres, > 0)."""
        d = np.maximum(np.asarray(depth, dtype=np.float64), 1e-9)
        return np.minimum(self.aperture * np.abs(d - self.focus) / d, self.max_radius)


@dataclass(frozen=True)
class MotionBlur:
    """Camera motion during the exposure; the render's camera is the mid-exposure pose.

    Attributes:
        translation: (3,) total displacement over the exposure, metres, in the camera frame
            (x right, y down, z forward).
        rotation: (3,) total rotation over the exposure, axis-angle in radians, camera frame.
        sub_steps: number of sub-exposure renders averaged in linear light (80 = the reference).
        fast: choose fewer sub-steps from the largest on-screen displacement of the visible
            Gaussians (see ``spacedg.render.motion``); ``sub_steps`` is then the upper bound.
    """

    translation: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rotation: tuple[float, float, float] = (0.0, 0.0, 0.0)
    sub_steps: int = 80
    fast: bool = False

    def __post_init__(self) -> None:
        for name in ("translation", "rotation"):
            value = np.asarray(getattr(self, name), dtype=np.float64)
            if value.shape != (3,) or not np.isfinite(value).all():
                raise ParameterError(f"motion {name} must be 3 finite numbers, got {getattr(self, name)!r}")
            object.__setattr__(self, name, tuple(float(v) for v in value))
        # π itself is allowed: rot·axis of a unit axis can have a norm a few ulps above its angle
        if float(np.linalg.norm(self.rotation)) > math.pi * (1.0 + _ANGLE_ROUNDING):
            raise ParameterError(f"motion rotation angle must be <= π rad over one exposure, got {np.linalg.norm(self.rotation):.4g}")
        if isinstance(self.sub_steps, bool) or not isinstance(self.sub_steps, (int, np.integer)) or not 1 <= self.sub_steps <= 4096:
            raise ParameterError(f"motion sub_steps must be an integer in [1, 4096], got {self.sub_steps!r}")

    @property
    def is_static(self) -> bool:
        return not any(self.translation) and not any(self.rotation)

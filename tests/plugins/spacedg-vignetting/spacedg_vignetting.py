"""Natural lens vignetting for spacedg: the cos⁴ law (an example third-party plugin).

Model (linear stage, photometric). Off-axis image points receive less light: a chief ray at
angle θ from the optical axis sees the aperture foreshortened (cos θ), travels farther
(cos² θ, inverse square) and meets the sensor obliquely (cos θ), so the irradiance falls as
``E(θ) = E(0) · cos⁴ θ``. The gain applied to linear light is

    g = 1 − strength · (1 − cos⁴ θ),     tan θ = ρ · tan(half_fov),

where ``ρ`` is the pixel's distance from the image centre divided by the centre-to-corner
distance (0 at the centre, 1 at the corners; pixel centres at +0.5), so ``half_fov`` is the
angle of the chief ray reaching the image corner (half the diagonal field of view). The
principal point is taken at the image centre and pixels as square: the linear stage receives
no intrinsics. ``strength = 1`` is the physical law; lower values blend toward no falloff.
Identity: ``half_fov = 0`` or ``strength = 0`` (exactly, bit for bit).

Parameters:
    half_fov: rad, hard limits [0, 1.45] (83°); harsher when higher.
    strength: dimensionless "1", hard limits [0, 1]; harsher when higher.

Presets (corner gain at the range's middle, strength 1, in brackets): ``1`` half_fov
[0.35, 0.45] (≈ 0.72), ``2`` [0.50, 0.60] (≈ 0.53), ``3`` [0.65, 0.75] (≈ 0.34), ``4``
[0.80, 0.90] (≈ 0.19), ``5`` [0.95, 1.05] (≈ 0.085); ``bench`` = [0.80, 0.90], a wide-angle
lens (the paper has no vignetting). Strength is fixed
at 1 in every preset. Deterministic; ``rng`` is unused.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from spacedg.errors import InvalidDataError
from spacedg.plugins import Category, DegradationSpec, ParamRange, ParamSpec, Stage, hookimpl

__all__ = ["SPEC", "vignette", "vignetting_gain"]


def vignetting_gain(height: int, width: int, half_fov: float, strength: float = 1.0) -> np.ndarray:
    """(H, W) float32 gain of the cos⁴ law (see the module docstring)."""
    v = (np.arange(height, dtype=np.float64) + 0.5) - height / 2.0
    u = (np.arange(width, dtype=np.float64) + 0.5) - width / 2.0
    rho2 = (u[None, :] ** 2 + v[:, None] ** 2) / ((width / 2.0) ** 2 + (height / 2.0) ** 2)
    tan2 = rho2 * np.tan(half_fov) ** 2
    cos4 = 1.0 / (1.0 + tan2) ** 2
    return (1.0 - strength * (1.0 - cos4)).astype(np.float32)


def vignette(rgb: np.ndarray, half_fov: float, strength: float = 1.0) -> np.ndarray:
    """Apply natural vignetting to linear-light float32 (H, W, 3); returns a new array."""
    if not isinstance(rgb, np.ndarray) or rgb.dtype != np.float32 or rgb.ndim != 3 or rgb.shape[2] != 3:
        got = f"{rgb.dtype} {rgb.shape}" if isinstance(rgb, np.ndarray) else type(rgb).__name__
        raise InvalidDataError(f"vignetting: expected linear-light float32 (H, W, 3), got {got}")
    if half_fov == 0.0 or strength == 0.0:
        return rgb.copy()
    gain = vignetting_gain(rgb.shape[0], rgb.shape[1], half_fov, strength)
    return rgb * gain[:, :, None]


def apply(rgb: np.ndarray, aux: Mapping[str, np.ndarray], params: Mapping[str, Any], rng: np.random.Generator) -> np.ndarray:
    """Linear-stage ``apply``; ``aux`` is empty (nothing needed from the render)."""
    p = SPEC.validate_params(params)
    return vignette(rgb, p["half_fov"], p["strength"])


def _preset(lo: float, hi: float) -> dict[str, ParamRange]:
    return {"half_fov": ParamRange(lo, hi), "strength": ParamRange(1.0, 1.0)}


SPEC = DegradationSpec(
    name="vignetting",
    category=Category.PHOTOMETRIC,
    stage=Stage.LINEAR,
    params=(
        ParamSpec("half_fov", "rad", "Angle of the chief ray at the image corner (half the diagonal field of view).", low=0.0, high=1.45, harsher="higher"),
        ParamSpec("strength", "1", "Blend between no falloff (0) and the physical cos⁴ law (1).", low=0.0, high=1.0, harsher="higher"),
    ),
    presets={
        "bench": _preset(0.80, 0.90),
        "1": _preset(0.35, 0.45),
        "2": _preset(0.50, 0.60),
        "3": _preset(0.65, 0.75),
        "4": _preset(0.80, 0.90),
        "5": _preset(0.95, 1.05),
    },
    apply=apply,
    needs=frozenset(),
    description="Natural vignetting, cos⁴ law on linear light: g = 1 − s(1 − cos⁴θ), tanθ = ρ·tan(half_fov).",
    order=25.0,  # after water droplets on the front glass, before the sensor's exposure gain
)


@hookimpl
def spacedg_register_degradations(register):
    """Register :data:`SPEC`."""
    register(SPEC)

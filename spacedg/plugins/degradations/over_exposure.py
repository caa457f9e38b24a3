"""Over-exposure (photometric, linear stage): gain e ≫ 1, sensor noise, saturation at 1.

Model: the paper's "Over-exposure" on linear light — the same sensor as low light
(:mod:`._sensor`), then the clip:

    I' = clip(k · Poisson(e·I / k) + σ_read · R, 0, 1),     R ~ N(0, 1)  (or Tukey lambda, ELD).

The clip to [0, 1] happens here, **before** the sRGB encode: highlights saturate and their
detail is lost for good (a later stage cannot recover it). At the default sensor the noise is
small beside the signal (1 % at full scale: 10⁴ e⁻), so the effect is mostly the clipping.

Parameters:
    exposure: gain on linear light, unit "1", hard limits [1, 1e6]; harsher when higher.
    k, sigma_read, read_model, read_lambda: the sensor, as in :mod:`.low_light` (defaults
        k = 1e-4 per e⁻, i.e. full well ≈ 10⁴ e⁻; σ_read = 2.5e-4 ≈ 2.5 e⁻; Gaussian read noise).

Presets (``exposure``; sensor fixed at its defaults): ``bench`` [7, 10] (the paper's table);
severities ``1`` [1.5, 2], ``2`` [2.5, 3.5], ``3`` [4, 5.5], ``4`` [5.5, 7], ``5`` [7, 10] (= bench).

Conventions: ``rgb`` float32 (H, W, 3) linear light, unclamped, not modified; NaN values are
treated as 0, +inf saturates to 1. Output float32 in [0, 1]. ``apply`` consumes exactly one
draw of ``rng`` (:func:`._common.stream_key`) per call; the bytes do not depend on the thread
count. Identity: ``exposure = 1, k = 0, sigma_read = 0`` returns inputs within [0, 1] bit for
bit (values outside are clipped, as the pipeline would).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from spacedg.plugins.degradations.common import stream_key
from spacedg.plugins.degradations._sensor import (
    K_DEFAULT,
    READ_GAUSSIAN,
    READ_LAMBDA_DEFAULT,
    SENSOR_PARAMS,
    SENSOR_PRESET,
    SIGMA_READ_DEFAULT,
    capture_for,
)
from spacedg.plugins.hookspecs import hookimpl
from spacedg.plugins.specs import Category, DegradationSpec, ParamRange, ParamSpec, Stage

__all__ = ["SPEC", "over_expose"]

EXPOSURE = ParamSpec(
    name="exposure",
    unit="1",
    description="Gain on linear light (multiple of the normal exposure); 1 = unchanged.",
    low=1.0,
    high=1e6,
    harsher="higher",
)


def over_expose(
    rgb: np.ndarray,
    exposure: float,
    key: int,
    k: float = K_DEFAULT,
    sigma_read: float = SIGMA_READ_DEFAULT,
    read_model: int = READ_GAUSSIAN,
    read_lambda: float = READ_LAMBDA_DEFAULT,
) -> np.ndarray:
    """Over-expose linear light, add sensor noise and clip; returns new float32 (H, W, 3) in [0, 1].

    Args:
        rgb: float32 (H, W, 3) linear light, unclamped.
        exposure: gain in [1, 1e6].
        key: 63-bit noise key (``stream_key(rng)``).
        k, sigma_read, read_model, read_lambda: the sensor (module docstring).
    """
    return capture_for(SPEC, rgb, exposure, key, k, sigma_read, read_model, read_lambda, clip=True)


def apply(rgb: np.ndarray, aux: Mapping[str, np.ndarray], params: Mapping[str, Any], rng: np.random.Generator) -> np.ndarray:
    """Linear-stage ``apply``; ``aux`` is unused; one ``stream_key(rng)`` draw."""
    p = SPEC.validate_params(params)
    return over_expose(rgb, key=stream_key(rng), **p)


def _preset(low: float, high: float) -> dict[str, ParamRange]:
    return {"exposure": ParamRange(low, high), **SENSOR_PRESET}


SPEC = DegradationSpec(
    name="over_exposure",
    category=Category.PHOTOMETRIC,
    stage=Stage.LINEAR,
    params=(EXPOSURE, *SENSOR_PARAMS),
    presets={
        "bench": _preset(7.0, 10.0),
        "1": _preset(1.5, 2.0),
        "2": _preset(2.5, 3.5),
        "3": _preset(4.0, 5.5),
        "4": _preset(5.5, 7.0),
        "5": _preset(7.0, 10.0),
    },
    apply=apply,
    needs=frozenset(),
    description=(
        "Over-exposure on linear light: I' = clip(k·Poisson(e·I/k) + σ_read·N(0,1), 0, 1), e ≫ 1; saturates before "
        "the sRGB encode (k = 1e-4, σ_read = 2.5e-4 as in low_light)."
    ),
    order=30.0,
)


@hookimpl
def spacedg_register_degradations(register: Any) -> None:
    """Register :data:`SPEC`."""
    register(SPEC)

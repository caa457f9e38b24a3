"""Low light (photometric, linear stage): exposure e ≪ 1, photon shot noise and read noise.

Model: the paper's "Low-light" formula on linear light (the sensor of :mod:`._sensor`; this
degradation's spec and plain function are made by :class:`._exposure.SensorExposure`, shared
with ``over_exposure``),

    I' = k · Poisson(e·I / k) + σ_read · R,     R ~ N(0, 1)  (or Tukey lambda, ELD),

per channel value, with no brightening or ISO gain afterwards: the output is dark, as in the
paper (a mid-grey 0.2 at the bench exposure 0.004 gives 8 photo-electrons, linear 8e-4,
≈ 3/255 after the sRGB encode, with an SNR of about 2). The output is **not** clipped here
(the pipeline clips before the sRGB encode); it is always finite and may be slightly
negative (read noise).

Parameters:
    exposure: gain on linear light, unit "1", hard limits [0, 1]; harsher when lower.
    k: system gain, normalised full scale per photo-electron, unit "1/e-", hard limits [0, 1];
        default 1e-4 (full-well equivalent ≈ 10⁴ e⁻, photon-transfer / ELD literature for a
        mid-size CMOS pixel); 0 disables shot noise.
    sigma_read: read-noise std in normalised linear units, hard limits [0, 1]; default 2.5e-4
        (≈ 2.5 e⁻ at k = 1e-4); 0 disables read noise.
    read_model: 0 = Gaussian (the paper), 1 = Tukey lambda scaled to unit variance (ELD).
    read_lambda: Tukey λ, hard limits [-0.45, 1]; default 0.14 (≈ normal).

Presets (``exposure``; the sensor parameters fixed at their defaults, Gaussian read noise):
``bench`` [0.003, 0.005] (the paper's table); severities ``1`` [0.1, 0.2], ``2`` [0.04, 0.07],
``3`` [0.015, 0.03], ``4`` [0.007, 0.012], ``5`` [0.003, 0.005] (= bench).

Conventions: ``rgb`` float32 (H, W, 3) linear light, unclamped, not modified; NaN values are
treated as 0 and ±inf as ±1e12 (:data:`._sensor.SIGNAL_CAP`). ``apply`` consumes exactly one
draw of ``rng`` (:func:`.common.stream_key`) per call; the noise is counter-based, so the
bytes do not depend on the thread count. Identity: ``exposure = 1, k = 0, sigma_read = 0``
returns the input bit for bit.
"""

from __future__ import annotations

from spacedg.plugins.degradations._exposure import SensorExposure
from spacedg.plugins.hookspecs import registering
from spacedg.plugins.specs import ParamSpec

__all__ = ["SPEC", "low_light"]

EXPOSURE = ParamSpec("exposure", "1", "Gain on linear light (fraction of the normal exposure); 1 = unchanged.", low=0.0, high=1.0, harsher="lower")
_SENSOR = SensorExposure(
    "low_light", EXPOSURE, clip=False,
    presets={"bench": (0.003, 0.005), "1": (0.1, 0.2), "2": (0.04, 0.07), "3": (0.015, 0.03), "4": (0.007, 0.012), "5": (0.003, 0.005)},
    description=(
        "Low light on linear light: I' = k·Poisson(e·I/k) + σ_read·N(0,1), e ≪ 1, k = 1e-4 (10⁴ e⁻ full well), "
        "σ_read = 2.5e-4 (2.5 e⁻); dark output, no gain afterwards; Tukey-lambda read noise optional (ELD)."
    ),
)
SPEC = _SENSOR.spec
#: ``low_light(rgb, exposure, key, k=…, sigma_read=…, read_model=…, read_lambda=…)``: the plain function
#: (:meth:`~spacedg.plugins.degradations._exposure.SensorExposure.capture`).
low_light = _SENSOR.capture
spacedg_register_degradations = registering(SPEC)

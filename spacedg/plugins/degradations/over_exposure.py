"""Over-exposure (photometric, linear stage): gain e ≫ 1, sensor noise, saturation at 1.

Model: the paper's "Over-exposure" on linear light — the same sensor as low light
(:mod:`._sensor`; spec and plain function made by :class:`._exposure.SensorExposure`), then
the clip:

    I' = clip(k · Poisson(e·I / k) + σ_read · R, 0, 1),     R ~ N(0, 1)  (or Tukey lambda, ELD).

The clip to [0, 1] happens here, **before** the sRGB encode: highlights saturate and their
detail is lost for good (a later stage cannot recover it). At the default sensor the noise is
small beside the signal (1 % at full scale: 10⁴ e⁻), so the effect is mostly the clipping.

Parameters:
    exposure: gain on linear light, unit "1", hard limits [1, 1e6]; harsher when higher.
    k, sigma_read, read_model, read_lambda, pitch, per_pixel: the sensor, as in :mod:`.low_light`
        (defaults k = 1e-4 per e⁻, i.e. full well ≈ 10⁴ e⁻; σ_read = 2.5e-4 ≈ 2.5 e⁻; Gaussian read
        noise; photosites of 1 px at 1752 × 1168; ``per_pixel = 1``: one draw per output pixel).

Presets (``exposure``; sensor fixed at its defaults): ``bench`` [7, 10] (the paper's table);
severities ``1`` [1.5, 2], ``2`` [2.5, 3.5], ``3`` [4, 5.5], ``4`` [5.5, 7], ``5`` [7, 10] (= bench).

**One noise draw per pixel** (decision: the presets' ``per_pixel = 1``; low light keeps its
photosites). Each pixel's noise has the photosites' mean and variance at every output size
(:func:`._photosites.binned_capture`, tested within 2 % on flat patches); what it gives up is the
*same realisation* at every size of a view. Over-exposure does not need it: its noise is at most
1 % of the full scale (10⁴ e⁻) and the clip decides the picture, so a 1920 × 1080 render
area-downsampled to 640 × 360 still matches the direct 640 × 360 one at 50.2 dB with one draw per pixel
against 51.2 dB with the photosites (``benchmarks/resolution.py``, the room, every severity ≥ 49.8 dB;
the goal is 35). Low light, whose noise is the picture, falls to 34.9 dB that way and keeps the
photosites. The photosites cost a dataset sample about 4.4 × a clean one at 640 × 480 (the ~1.8 M
sites × 3, less those only saturated pixels read); one draw per pixel about 1.2–1.4 × (``benchmarks/dataset.py``).
``per_pixel = 0`` draws the photosites, as before, and is the plain function's default (:func:`over_expose`
called without ``per_pixel``): the presets set 1. On a device the per-pixel draw runs there, bit-identical
to the host's except where the device's libm rounds differently (:mod:`.device`).

Conventions: ``rgb`` float32 (H, W, 3) linear light, unclamped, not modified; NaN values are
treated as 0, +inf saturates to 1. Output float32 in [0, 1]. ``apply`` consumes exactly one
draw of ``rng`` (:func:`.common.stream_key`) per call; the bytes do not depend on the thread
count. Identity: ``exposure = 1, k = 0, sigma_read = 0`` returns inputs within [0, 1] bit for
bit (values outside are clipped, as the pipeline would).
"""

from __future__ import annotations

from spacedg.plugins.degradations._exposure import SensorExposure
from spacedg.plugins.hookspecs import registering
from spacedg.plugins.specs import ParamSpec

__all__ = ["SPEC", "over_expose"]

EXPOSURE = ParamSpec("exposure", "1", "Gain on linear light (multiple of the normal exposure); 1 = unchanged.", low=1.0, high=1e6, harsher="higher")
_SENSOR = SensorExposure(
    "over_exposure", EXPOSURE, clip=True, per_pixel=1,
    presets={"bench": (7.0, 10.0), "1": (1.5, 2.0), "2": (2.5, 3.5), "3": (4.0, 5.5), "4": (5.5, 7.0), "5": (7.0, 10.0)},
    description=(
        "Over-exposure on linear light: I' = clip(k·Poisson(e·I/k) + σ_read·N(0,1), 0, 1), e ≫ 1; saturates before "
        "the sRGB encode (k = 1e-4, σ_read = 2.5e-4 as in low_light)."
    ),
)
SPEC = _SENSOR.spec
#: ``over_expose(rgb, exposure, key, k=…, sigma_read=…, read_model=…, read_lambda=…)``: the plain function
#: (:meth:`~spacedg.plugins.degradations._exposure.SensorExposure.capture`).
over_expose = _SENSOR.capture
spacedg_register_degradations = registering(SPEC)

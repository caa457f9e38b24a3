"""Low light (photometric, linear stage): exposure e ≪ 1, photon shot noise and read noise.

Model: the paper's "Low-light" formula on linear light (the sensor of :mod:`._sensor`; this
degradation's spec and plain function are made by :class:`._exposure.SensorExposure`, shared
with ``over_exposure``),

    I' = k · Poisson(e·I / k) + σ_read · R,     R ~ N(0, 1)  (or Tukey lambda, ELD),

per channel value, then the camera's **gain** ``g`` (ISO / digital gain on the read-out signal,
noise amplified with it): ``I'' = g · I'``. The output is **not** clipped here (the pipeline
clips before the sRGB encode); it is always finite and may be slightly negative (read noise).

**Gain** (decision; the paper is silent on what the camera does after the dark exposure). A
phone or camera does not store a black frame: its auto-exposure raises the gain (ISO) until the
picture is bright enough to look at, so a night photo is *noisy*, not black. Without gain the
bench exposure 0.003–0.005 encodes a mid-grey to code ≈ 3/255: the built-in rooms kept their
named objects discernible in 35 % of items (:mod:`spacedg.data.answerability`, luminance
contrast alone, 2 rooms × 30 questions at 320×240), which
contradicts the paper's people answering 51.7 % of low-light items against 80.4 % clean and
about a third blind. The presets' gain restores at least :data:`BRIGHTNESS` = 10 % of the
normal exposure's brightness, ``g = max(1, 0.1 / e_mid)``: 25 at ``bench`` (ISO 1250 on an
ISO-50 base, inside a phone's range), 1 at severity 1 (bright enough already). The image stays
a dark night photo (a mid-grey reads ≈ 38/255 with an SNR of ≈ 3 per pixel), and its
objects stay discernible in 88 % of the rooms' items (same measure; the final table, colour
counted, is in ``docs/degradations-physics.md``). The
exposure is the paper's range unchanged; ``gain = 1`` is the former model.

Parameters:
    exposure: gain on linear light, unit "1", hard limits [0, 1]; harsher when lower.
    k: system gain, normalised full scale per photo-electron, unit "1/e-", hard limits [0, 1];
        default 1e-4 (full-well equivalent ≈ 10⁴ e⁻, photon-transfer / ELD literature for a
        mid-size CMOS pixel); 0 disables shot noise.
    sigma_read: read-noise std in normalised linear units, hard limits [0, 1]; default 2.5e-4
        (≈ 2.5 e⁻ at k = 1e-4); 0 disables read noise.
    read_model: 0 = Gaussian (the paper), 1 = Tukey lambda scaled to unit variance (ELD).
    read_lambda: Tukey λ, hard limits [-0.45, 1]; default 0.14 (≈ normal).
    gain: the camera's gain after read-out, unit "1", hard limits [1, 1000]; 1 = none.
    pitch: photosite side in output pixels (:mod:`._photosites`; presets: 1 px at 1752 × 1168,
        scaled with the output).
    per_pixel: 1 = one noise draw per output pixel with the photosites' mean and variance
        (:func:`._photosites.binned_capture`: several times faster below the reference size, but
        each output size gets its own noise); presets: 0.

Presets (``exposure``; the sensor parameters fixed at their defaults, Gaussian read noise;
``gain``): ``bench`` [0.003, 0.005] (the paper's table), gain 25; severities ``1`` [0.1, 0.2]
gain 1, ``2`` [0.04, 0.07] gain 1.8, ``3`` [0.015, 0.03] gain 4.4, ``4`` [0.007, 0.012] gain
10.5, ``5`` [0.003, 0.005] gain 25 (= bench).

Conventions: ``rgb`` float32 (H, W, 3) linear light, unclamped, not modified; NaN values are
treated as 0 and ±inf as ±1e12 (:data:`._sensor.SIGNAL_CAP`). ``apply`` consumes exactly one
draw of ``rng`` (:func:`.common.stream_key`) per call; the noise is counter-based, so the
bytes do not depend on the thread count. Identity: ``exposure = 1, k = 0, sigma_read = 0``
returns the input bit for bit (gain 1).
"""

from __future__ import annotations

from spacedg.plugins.degradations._exposure import SensorExposure
from spacedg.plugins.hookspecs import registering
from spacedg.plugins.specs import ParamSpec

__all__ = ["SPEC", "low_light"]

EXPOSURE = ParamSpec("exposure", "1", "Gain on linear light (fraction of the normal exposure); 1 = unchanged.", low=0.0, high=1.0, harsher="lower")
_EXPOSURES = {"bench": (0.003, 0.005), "1": (0.1, 0.2), "2": (0.04, 0.07), "3": (0.015, 0.03), "4": (0.007, 0.012), "5": (0.003, 0.005)}
#: Brightness (fraction of the normal exposure's) the camera's gain restores at least (decision: module docstring).
BRIGHTNESS = 0.1
_SENSOR = SensorExposure(
    "low_light", EXPOSURE, clip=False, presets=_EXPOSURES,
    gains={preset: max(1.0, round(BRIGHTNESS * 2.0 / (low + high), 1)) for preset, (low, high) in _EXPOSURES.items()},
    description=(
        "Low light on linear light: I' = g·(k·Poisson(e·I/k) + σ_read·N(0,1)), e ≪ 1, k = 1e-4 (10⁴ e⁻ full well), "
        "σ_read = 2.5e-4 (2.5 e⁻), camera gain g (presets: back to ≥ 10 % of the normal brightness, g = 25 at bench: "
        "a dark, noisy night photo); Tukey-lambda read noise optional (ELD)."
    ),
)
SPEC = _SENSOR.spec
#: ``low_light(rgb, exposure, key, k=…, sigma_read=…, read_model=…, read_lambda=…)``: the plain function
#: (:meth:`~spacedg.plugins.degradations._exposure.SensorExposure.capture`).
low_light = _SENSOR.capture
spacedg_register_degradations = registering(SPEC)

"""What ``low_light`` and ``over_exposure`` share (not a plugin: no entry point): the sensor as a degradation.

Both multiply linear light by a gain ``exposure`` and capture it with the shared sensor
(:mod:`._sensor`: photon shot noise and read noise); over-exposure then clips to [0, 1].
They differ only in their data: the name, the ``exposure`` parameter (hard limits, harsher
direction), the clip, the presets and the description. This module holds the rest:

- :data:`SENSOR_PARAMS` (``k``, ``sigma_read``, ``read_model``, ``read_lambda``, ``pitch``, after
  ``exposure`` in every spec), :data:`PER_PIXEL` (last in every spec) and :data:`SENSOR_PRESET`
  (every preset fixes them at the sensor's defaults, Gaussian read noise, one photosite per pixel
  of the 1752 × 1168 reference image: ``pitch`` = 1 px there, scaled with the output,
  :mod:`._photosites`; ``per_pixel`` as the degradation declares: 0 for low light, every photosite
  drawn; 1 for over-exposure, one draw per pixel with the photosites' statistics, see its module);
- :class:`SensorExposure`: one such degradation from its data. Its plain function is
  :meth:`SensorExposure.capture`; its :attr:`~SensorExposure.spec` is photometric, linear stage,
  order 30 (the sensor, after the optics), needs nothing from the render, and its ``apply``
  checks ``params`` against the spec, draws one :func:`.common.stream_key` of ``rng`` and captures.

Conventions: ``rgb`` float32 (H, W, 3) linear light, unclamped, not modified; the result is a
new float32 array (see :func:`._sensor.sensor_capture` for non-finite input and the noise).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from spacedg.plugins.degradations._photosites import binned_capture, pixel_sensor
from spacedg.plugins.degradations._sensor import (
    K_DEFAULT,
    READ_GAUSSIAN,
    READ_LAMBDA_DEFAULT,
    READ_TUKEY,
    SIGMA_READ_DEFAULT,
)
from spacedg.plugins.degradations.common import check_linear_rgb, stream_key
from spacedg.plugins.specs import (
    Category,
    DegradationSpec,
    ParamRange,
    ParamSpec,
    Stage,
)

__all__ = ["EXPOSURE_ORDER", "GAIN", "PER_PIXEL", "SENSOR_PARAMS", "SENSOR_PRESET", "SensorExposure"]

#: Position of the sensor within the linear stage (:data:`~spacedg.plugins.specs.ORDER_GUIDE`).
EXPOSURE_ORDER = 30.0

#: The sensor's parameters, declared by both exposure degradations after ``exposure``.
SENSOR_PARAMS: tuple[ParamSpec, ...] = (
    ParamSpec("k", "1/e-", "System gain: normalised full-scale signal per photo-electron (1/k electrons fill the full scale); 0 disables shot noise.", low=0.0, high=1.0, harsher="higher"),
    ParamSpec("sigma_read", "1", "Read-noise standard deviation in normalised linear units (full scale = 1); 0 disables read noise.", low=0.0, high=1.0, harsher="higher"),
    ParamSpec("read_model", "1", "Read-noise shape: 0 = Gaussian (the paper's formula), 1 = Tukey lambda scaled to unit variance (ELD).", low=READ_GAUSSIAN, high=READ_TUKEY, integer=True),
    ParamSpec("read_lambda", "1", "Tukey-lambda shape of the read noise (read_model = 1): 0.14 ≈ normal, < 0 heavy-tailed, 0 logistic.", low=-0.45, high=1.0),
    ParamSpec("pitch", "px", "Photosite side in output pixels: the noise is drawn per photosite and averaged over each pixel "
              "(1 = one photosite per pixel; presets: 1 px at 1752×1168, scaled with the image).", low=1e-4, high=1e4, recorded_default=1.0),
)

#: The camera's gain after read-out (ISO / digital gain), declared by ``low_light`` only.
GAIN = ParamSpec(
    "gain", "1", "Camera gain on the read-out signal (ISO / digital; the noise is amplified with the signal); 1 = none.",
    low=1.0, high=1000.0, recorded_default=1.0,
)

#: Draw the noise once per output pixel instead of per photosite (declared last by both exposure
#: degradations, so that every earlier parameter keeps its draw; presets: low light 0, the
#: photosites; over-exposure 1, see :mod:`.over_exposure`).
PER_PIXEL = ParamSpec(
    "per_pixel", "1", "1 = draw the noise once per output pixel with the photosites' mean and variance per pixel (gain k·q, "
    "read noise σ·√q): ~1/pitch² times fewer draws below 1752×1168, but another output size of the view gets other noise; "
    "0 = per photosite (low light's presets; over-exposure's presets draw per pixel).", low=0, high=1, integer=True, recorded_default=0,
)

#: Fixed sensor ranges every preset of the exposure degradations uses (``per_pixel``: each degradation's own, :class:`SensorExposure`).
SENSOR_PRESET: dict[str, ParamRange] = {
    "k": ParamRange(K_DEFAULT, K_DEFAULT),
    "sigma_read": ParamRange(SIGMA_READ_DEFAULT, SIGMA_READ_DEFAULT),
    "read_model": ParamRange(READ_GAUSSIAN, READ_GAUSSIAN),
    "read_lambda": ParamRange(READ_LAMBDA_DEFAULT, READ_LAMBDA_DEFAULT),
    "pitch": ParamRange(1.0, 1.0, per_size=True),
}


class SensorExposure:
    """One exposure degradation of the shared sensor: its plain function and its spec (module docstring).

    A class rather than closures so that the spec's ``apply`` pickles.

    Args:
        name: the degradation's name.
        exposure: its ``exposure`` parameter: the gain on linear light, unit "1".
        clip: clip the captured light to [0, 1] (saturation, over-exposure) or leave it unclipped.
        presets: preset name → ``(low, high)`` range of ``exposure``; the sensor parameters are
            fixed at :data:`SENSOR_PRESET` in every preset, ``per_pixel`` at ``per_pixel``.
        description: the spec's description (the model in a sentence, with units).
        per_pixel: the presets' ``per_pixel`` (0: the photosites; 1: one draw per pixel with their statistics).

    Attributes:
        clip: as given.
        spec: the :class:`~spacedg.plugins.specs.DegradationSpec`; its ``apply`` is :meth:`apply`.
    """

    def __init__(
        self, name: str, exposure: ParamSpec, *, clip: bool, presets: Mapping[str, tuple[float, float]], description: str,
        gains: Mapping[str, float] | None = None, per_pixel: int = 0,
    ) -> None:
        self.clip = clip
        self.has_gain = gains is not None
        gain = {preset: {"gain": ParamRange(gains[preset], gains[preset])} for preset in presets} if gains is not None else {}
        self.spec = DegradationSpec(
            name=name, category=Category.PHOTOMETRIC, stage=Stage.LINEAR,
            params=(exposure, *SENSOR_PARAMS, *((GAIN,) if self.has_gain else ()), PER_PIXEL),
            presets={
                preset: {"exposure": ParamRange(low, high), **SENSOR_PRESET, "per_pixel": ParamRange(per_pixel, per_pixel), **gain.get(preset, {})}
                for preset, (low, high) in presets.items()
            },
            apply=self.apply,
            apply_torch=self.apply_torch,
            needs=frozenset(),
            description=description,
            order=EXPOSURE_ORDER,
        )

    def capture(
        self,
        rgb: np.ndarray,
        exposure: float,
        key: int,
        k: float = K_DEFAULT,
        sigma_read: float = SIGMA_READ_DEFAULT,
        read_model: int = READ_GAUSSIAN,
        read_lambda: float = READ_LAMBDA_DEFAULT,
        pitch: float = 1.0,
        gain: float = 1.0,
        per_pixel: int = 0,
    ) -> np.ndarray:
        """Expose linear light by ``exposure``, add the sensor's noise, then the camera's ``gain`` (and
        clip if :attr:`clip`); returns new float32 (H, W, 3).

        Args:
            rgb: float32 (H, W, 3) linear light, unclamped.
            exposure: the gain, within the ``exposure`` parameter's hard limits.
            key: 63-bit noise key (``stream_key(rng)``).
            k, sigma_read, read_model, read_lambda: the sensor (:mod:`._sensor`; defaults: its defaults).
            pitch: photosite side in pixels (:mod:`._photosites`; 1 = one per pixel, the plain sensor).
            gain: the camera's gain on the read-out signal (ISO / digital gain, noise amplified with
                the signal); only for a degradation declared with ``gains``; 1 = none.
            per_pixel: 1 = where photosites are smaller than pixels, one draw per pixel with their
                statistics (:func:`._photosites.binned_capture`); 0 = the photosites.

        Raises:
            InvalidDataError: ``rgb`` is not float32 (H, W, 3).
            ParameterError: a parameter outside its hard limits.
        """
        rgb = check_linear_rgb(rgb, self.spec.name)
        values = {"exposure": exposure, "k": k, "sigma_read": sigma_read, "read_model": read_model, "read_lambda": read_lambda, "pitch": pitch,
                  "per_pixel": per_pixel}
        if self.has_gain or gain != 1.0:
            values["gain"] = gain  # a degradation without the parameter refuses any other gain than 1
        p = self.spec.validate_params(values)
        out = binned_capture(
            rgb, pitch=p["pitch"], exposure=p["exposure"], k=p["k"], sigma_read=p["sigma_read"], key=key,
            read_model=int(p["read_model"]), read_lambda=p["read_lambda"], clip=self.clip and not self.has_gain, per_pixel=bool(p["per_pixel"]),
        )
        return _apply_gain(out, p.get("gain", 1.0), self.clip and self.has_gain)

    def apply(self, rgb: np.ndarray, aux: Mapping[str, np.ndarray], params: Mapping[str, Any], rng: np.random.Generator) -> np.ndarray:
        """Linear-stage ``apply``: ``params`` checked against :attr:`spec` (a missing ``gain`` is 1: the
        model without gain); ``aux`` is unused; one ``stream_key(rng)`` draw."""
        p = self.spec.validate_params(params)
        return self.capture(rgb, key=stream_key(rng), **p)

    def apply_torch(self, rgb: Any, aux: Mapping[str, Any], params: Mapping[str, Any], rng: np.random.Generator) -> Any:
        """Device twin of :meth:`apply` on a torch tensor: the same ``stream_key(rng)`` draw, the same
        counter-based noise (:func:`spacedg.plugins.degradations.device.sensor_torch`: the same bytes)."""
        from spacedg.plugins.degradations import device

        p = self.spec.validate_params(params)
        key = stream_key(rng)
        per_pixel_sensor = pixel_sensor(p, int(rgb.shape[1]), int(rgb.shape[0]), p["pitch"]) if p["per_pixel"] else None
        if per_pixel_sensor is not None:  # one draw per pixel standing in for the photosites: on the device
            p = per_pixel_sensor
        elif p["pitch"] != 1.0:  # photosites off the pixel grid: the host's resampling, the same bytes
            import torch

            host = rgb.detach().cpu().numpy().astype(np.float32, copy=False)
            return torch.from_numpy(self.capture(host, key=key, **p)).to(rgb.device)
        gain = float(p.get("gain", 1.0))
        out = device.sensor_apply(rgb, p, key, self.clip and not self.has_gain)
        if gain != 1.0:
            out = out * gain
        return out.clamp(0.0, 1.0) if self.clip and self.has_gain else out


def _apply_gain(rgb: np.ndarray, gain: float, clip: bool) -> np.ndarray:
    """``rgb · gain`` (float32, in place on the new array ``rgb``), clipped to [0, 1] if ``clip``; ``rgb`` itself at gain 1."""
    if gain != 1.0:
        np.multiply(rgb, np.float32(gain), out=rgb)
    if clip:
        np.clip(rgb, 0.0, 1.0, out=rgb)
    return rgb

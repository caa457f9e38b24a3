"""Degradations on device: every built-in's ``apply_torch`` on CPU tensors against its numpy ``apply``.

The bounds asserted here are the tolerance table of :mod:`spacedg.plugins.degradations.device`
(measured values in its docstring). The pipeline's device path (``degrade_on="device"``) is run
for all nine built-ins against the host path, and a third-party degradation without
``apply_torch`` falls back to its numpy ``apply`` on the host, with a warning.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from spacedg.data.chain import BENCH_DEGRADATIONS
from spacedg.data.pipeline import PipelineOptions, degrade
from spacedg.plugins.degradations import haze, jpeg_compression, low_light, low_res, over_exposure, water_droplets
from spacedg.plugins.degradations.device import sensor_torch
from spacedg.render.colour_cpu import encode_srgb_u8

H, W = 120, 160


def _textured() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    y, x = np.mgrid[0:H, 0:W].astype(np.float64)
    base = np.stack([x / W, y / H, 0.5 + 0.4 * np.sin((x + y) / 9.0)], -1)
    image = (0.05 + 0.6 * base**2.2 + 0.1 * (np.sin(x / 2.3) * np.cos(y / 3.1))[..., None] ** 2).astype(np.float32)
    image[:8, :8] = 3.0  # HDR
    depth = (1 + 3 * x / W + np.sin(y / 7)).astype(np.float32)
    alpha = np.ones((H, W), np.float32)
    depth[:, :10], alpha[:, :10] = 0.0, 0.0  # no surface
    return image, depth, alpha


IMAGE, DEPTH, ALPHA = _textured()


def _linear(spec, seed: int) -> tuple[np.ndarray, np.ndarray]:
    params = spec.sample_params("bench", np.random.default_rng(seed))
    aux = {"depth": DEPTH, "alpha": ALPHA}
    host = spec.apply(IMAGE, aux, params, np.random.default_rng([seed, 0]))
    dev = spec.apply_torch(torch.from_numpy(IMAGE), {k: torch.from_numpy(v) for k, v in aux.items()}, params, np.random.default_rng([seed, 0]))
    assert dev.dtype == torch.float32 and dev.shape == IMAGE.shape
    return host, dev.numpy()


@pytest.mark.parametrize("spec, bound", [(haze.SPEC, 1e-5), (water_droplets.SPEC, 1e-4)], ids=["haze", "water_droplets"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_deterministic_linear_stage_matches(spec, bound: float, seed: int) -> None:
    host, dev = _linear(spec, seed)
    assert np.abs(host - dev).max() <= bound
    assert not np.array_equal(host, IMAGE)


@pytest.mark.parametrize("spec", [low_light.SPEC, over_exposure.SPEC], ids=["low_light", "over_exposure"])
@pytest.mark.parametrize("seed", [0, 1])
def test_sensor_noise_is_the_cpu_kernels_own(spec, seed: int) -> None:
    host, dev = _linear(spec, seed)
    np.testing.assert_array_equal(dev, host)


@pytest.mark.parametrize("spec", [low_light.SPEC, over_exposure.SPEC], ids=["low_light", "over_exposure"])
def test_per_pixel_sensor_runs_on_the_device_with_the_hosts_bytes(spec, monkeypatch: pytest.MonkeyPatch) -> None:
    """``per_pixel = 1`` below the reference size draws on the device (the photosites go through the
    host), the same bytes as the host."""
    from spacedg.plugins.degradations import _exposure

    params = {**spec.sample_params("bench", np.random.default_rng(3), image_size=(W, H)), "per_pixel": 1}
    assert params["pitch"] < 1.0
    host = spec.apply(IMAGE, {}, params, np.random.default_rng([3, 0]))
    photosites = spec.apply(IMAGE, {}, {**params, "per_pixel": 0}, np.random.default_rng([3, 0]))
    monkeypatch.setattr(_exposure, "binned_capture", lambda *a, **k: pytest.fail("the host path was taken"))
    dev = spec.apply_torch(torch.from_numpy(IMAGE), {}, params, np.random.default_rng([3, 0])).numpy()
    np.testing.assert_array_equal(dev, host)
    assert np.isfinite(host).all() and not np.array_equal(host, photosites)


SIGNALS = np.concatenate([
    np.random.default_rng(0).uniform(0, 1, 6000), np.random.default_rng(1).uniform(0, 0.01, 6000),
    [np.nan, np.inf, -np.inf, -1.0, 0.0, 1e20],
]).astype(np.float32)


@pytest.mark.parametrize("sensor", [
    {"exposure": 0.004, "k": 1e-4, "sigma_read": 2.5e-4},                      # Poisson table (< 64 e-)
    {"exposure": 0.05, "k": 1e-4, "sigma_read": 2.5e-4},                       # PTRS (64 to 10^3 e-)
    {"exposure": 1.0, "k": 1e-4, "sigma_read": 2.5e-4},                        # normal approximation
    {"exposure": 8.0, "k": 1e-4, "sigma_read": 2.5e-4, "clip": True},          # saturation shortcut
    {"exposure": 1.0, "k": 1e-2, "sigma_read": 1e-3, "read_model": 1, "read_lambda": -0.2},  # Tukey read noise
    {"exposure": 1.0, "k": 1e-2, "sigma_read": 1e-3, "read_model": 1, "read_lambda": 0.0},   # logistic limit
    {"exposure": 4.0, "k": 0.0, "sigma_read": 0.0},                             # no noise
], ids=["table", "ptrs", "normal", "saturated", "tukey", "logistic", "noiseless"])
def test_sensor_every_sampler_is_bit_identical(sensor) -> None:
    from spacedg.plugins.degradations._sensor import sensor_capture

    host = sensor_capture(SIGNALS, key=12345, **sensor)
    dev = sensor_torch(torch.from_numpy(SIGNALS), key=12345, **sensor).numpy()
    np.testing.assert_array_equal(dev, host)


@pytest.mark.parametrize("params", [{"scale": 0.03}, {"scale": 0.37}, {"scale": 0.5}, {"scale": 1.0}])
def test_low_res_within_two_codes(params) -> None:
    u8 = encode_srgb_u8(IMAGE)
    host = low_res.SPEC.apply(u8, params, None).astype(int)
    dev = low_res.SPEC.apply_torch(torch.from_numpy(u8), params, None).numpy()
    diff = np.abs(host - dev)
    assert diff.max() <= 2 and diff.mean() < 0.25


@pytest.mark.parametrize("quality, mean_codes", [(2, 4.0), (4, 4.0), (50, 2.5), (90, 1.5)])
def test_jpeg_is_kornias_codec_within_stated_codes(quality: int, mean_codes: float) -> None:
    u8 = encode_srgb_u8(IMAGE)
    host = jpeg_compression.SPEC.apply(u8, {"quality": quality}, None).astype(int)
    dev = jpeg_compression.SPEC.apply_torch(torch.from_numpy(u8), {"quality": quality}, None).numpy()
    assert dev.dtype == np.uint8 and dev.shape == u8.shape
    assert np.abs(host - dev).mean() < mean_codes


# ------------------------------------------------------------------ the pipeline's device path
HOST = PipelineOptions(image_size=(64, 48))
DEVICE = PipelineOptions(image_size=(64, 48), degrade_on="device")


@pytest.mark.parametrize("name", BENCH_DEGRADATIONS)
def test_pipeline_device_path_for_every_builtin(small_room, name: str) -> None:
    views = list(small_room.views)[:1]
    host = degrade(small_room, views, name, seed=3, options=HOST)
    dev = degrade(small_room, views, name, seed=3, options=DEVICE)
    assert dev.degradations == host.degradations  # same parameters and seeds
    assert dev.images.dtype == np.uint8 and dev.images.shape == host.images.shape
    diff = np.abs(host.images.astype(int) - dev.images)
    if name in ("defocus", "distortion", "motion_blur", "low_light", "over_exposure"):
        np.testing.assert_array_equal(dev.images, host.images)  # same render / same noise, exact encode
    elif name in ("haze", "water_droplets"):
        assert diff.max() <= 1, (name, diff.max())  # float rounding of the same formula
    elif name == "low_res":
        assert diff.max() <= 2
    else:  # jpeg_compression: kornia's codec, not libjpeg
        assert diff.mean() < 4.0


def test_third_party_without_apply_torch_falls_back_to_the_host(third_party, small_room) -> None:
    from spacedg.data import pipeline

    pipeline._HOST_FALLBACK_WARNED.discard("vignetting")
    views = list(small_room.views)[:1]
    host = degrade(small_room, views, "vignetting:5+low_res:1", seed=13, options=HOST)
    with pytest.warns(UserWarning, match="'vignetting' has no apply_torch"):
        dev = degrade(small_room, views, "vignetting:5+low_res:1", seed=13, options=DEVICE)
    assert dev.stats["host_fallbacks"] == 1.0
    assert np.abs(host.images.astype(int) - dev.images).max() <= 2  # low_res on the device: ≤ 2 codes


def test_where_the_chains_run(monkeypatch: pytest.MonkeyPatch) -> None:
    from spacedg.data.pipeline import degrade_device
    from spacedg.errors import ParameterError

    assert degrade_device(PipelineOptions()) is None
    assert degrade_device(PipelineOptions(device="cpu")) is None  # auto: a CPU device keeps the numpy path
    assert degrade_device(PipelineOptions(degrade_on="device")) == torch.device("cpu")
    monkeypatch.setattr(torch.version, "cuda", "12.8")  # a CUDA build of torch that sees no GPU
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    with pytest.raises(ParameterError, match="no CUDA device is visible"):  # checked when the options are made
        PipelineOptions(device="cuda:1")
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)  # two GPUs (never touched: deciding needs none)
    monkeypatch.setattr(torch.cuda, "device_count", lambda: 2)
    assert degrade_device(PipelineOptions(device="cuda:1")) == torch.device("cuda:1")
    assert degrade_device(PipelineOptions(device="cuda", degrade_on="host")) is None
    with pytest.raises(ParameterError, match="degrade_on"):
        PipelineOptions(degrade_on="gpu")

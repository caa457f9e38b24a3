"""Degradations on CUDA tensors: ``tests/plugins/degradations/test_device.py``'s device-vs-CPU
tolerances, checked on a real GPU. Skipped without a CUDA device (CI); ``benchmarks/gpu_check.sh``
runs them on a lent GPU.

The kernel-level checks use the same bounds as on CPU tensors (the README's table): the GPU must
not change them. The pipeline check renders on the GPU too (``device="cuda"``: gsplat's compositor,
or the torch twin for defocus), so its images differ from the compiled CPU path's by the render
tolerance as well (``tests/render/test_cuda.py``) and, through the noise draws that depend on the
signal, by a few pixels more: at most 1 % of the values more than 2 codes apart, mean < 0.5 code
(JPEG: kornia's codec, mean < 4 codes). Each pipeline case prints its measured differences
(``pytest -s``).
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from spacedg.data.chain import BENCH_DEGRADATIONS
from spacedg.data.pipeline import PipelineOptions, degrade
from spacedg.plugins.degradations import haze, jpeg_compression, low_light, low_res, over_exposure, water_droplets
from spacedg.plugins.degradations.device import sensor_torch
from spacedg.render import colour_torch
from spacedg.render.colour_cpu import encode_srgb_u8
from tests.plugins.degradations.test_device import ALPHA, DEPTH, IMAGE, SIGNALS

pytestmark = pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")

CUDA = "cuda"


def _on_cuda(array: np.ndarray) -> torch.Tensor:
    return torch.from_numpy(array).to(CUDA)


def _linear(spec, seed: int) -> tuple[np.ndarray, np.ndarray]:
    params = spec.sample_params("bench", np.random.default_rng(seed))
    aux = {"depth": DEPTH, "alpha": ALPHA}
    host = spec.apply(IMAGE, aux, params, np.random.default_rng([seed, 0]))
    dev = spec.apply_torch(_on_cuda(IMAGE), {k: _on_cuda(v) for k, v in aux.items()}, params, np.random.default_rng([seed, 0]))
    assert dev.device.type == "cuda" and dev.dtype == torch.float32 and dev.shape == IMAGE.shape
    return host, dev.cpu().numpy()


def test_encode_is_exact_on_cuda() -> None:
    values = np.concatenate([np.linspace(-0.1, 1.2, 20011), [np.nan, np.inf, -np.inf, 0.0, 1.0]]).astype(np.float32)
    np.testing.assert_array_equal(colour_torch.encode_srgb_u8(_on_cuda(values)).cpu().numpy(), encode_srgb_u8(values))
    np.testing.assert_array_equal(colour_torch.encode_srgb_u8(_on_cuda(IMAGE)).cpu().numpy(), encode_srgb_u8(IMAGE))


@pytest.mark.parametrize("spec, bound", [(haze.SPEC, 1e-5), (water_droplets.SPEC, 1e-4)], ids=["haze", "water_droplets"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_deterministic_linear_stage_matches_on_cuda(spec, bound: float, seed: int) -> None:
    host, dev = _linear(spec, seed)
    assert np.abs(host - dev).max() <= bound


@pytest.mark.parametrize("spec", [low_light.SPEC, over_exposure.SPEC], ids=["low_light", "over_exposure"])
@pytest.mark.parametrize("seed", [0, 1])
def test_sensor_noise_is_the_cpu_kernels_own_on_cuda(spec, seed: int) -> None:
    host, dev = _linear(spec, seed)
    np.testing.assert_array_equal(dev, host)


@pytest.mark.parametrize("spec", [low_light.SPEC, over_exposure.SPEC], ids=["low_light", "over_exposure"])
def test_per_pixel_sensor_is_the_hosts_on_cuda(spec) -> None:
    """``per_pixel = 1`` below the reference size draws on the GPU, the host's bytes."""
    height, width = IMAGE.shape[:2]
    params = {**spec.sample_params("bench", np.random.default_rng(3), image_size=(width, height)), "per_pixel": 1}
    host = spec.apply(IMAGE, {}, params, np.random.default_rng([3, 0]))
    dev = spec.apply_torch(_on_cuda(IMAGE), {}, params, np.random.default_rng([3, 0]))
    assert dev.device.type == "cuda"
    np.testing.assert_array_equal(dev.cpu().numpy(), host)


@pytest.mark.parametrize("sensor", [
    {"exposure": 0.004, "k": 1e-4, "sigma_read": 2.5e-4},
    {"exposure": 0.05, "k": 1e-4, "sigma_read": 2.5e-4},
    {"exposure": 1.0, "k": 1e-4, "sigma_read": 2.5e-4},
    {"exposure": 8.0, "k": 1e-4, "sigma_read": 2.5e-4, "clip": True},
    {"exposure": 1.0, "k": 1e-2, "sigma_read": 1e-3, "read_model": 1, "read_lambda": -0.2},
    {"exposure": 1.0, "k": 1e-2, "sigma_read": 1e-3, "read_model": 1, "read_lambda": 0.0},
    {"exposure": 4.0, "k": 0.0, "sigma_read": 0.0},
], ids=["table", "ptrs", "normal", "saturated", "tukey", "logistic", "noiseless"])
def test_sensor_every_sampler_is_bit_identical_on_cuda(sensor) -> None:
    from spacedg.plugins.degradations._sensor import sensor_capture

    host = sensor_capture(SIGNALS, key=12345, **sensor)
    dev = sensor_torch(_on_cuda(SIGNALS), key=12345, **sensor).cpu().numpy()
    different = dev != host
    assert not different.any(), f"{int(different.sum())} of {host.size} values differ; max |Δ| {np.nanmax(np.abs(dev - host)):.3g}"


@pytest.mark.parametrize("params", [{"scale": 0.03}, {"scale": 0.37}, {"scale": 0.5}, {"scale": 1.0}])
def test_low_res_within_two_codes_on_cuda(params) -> None:
    u8 = encode_srgb_u8(IMAGE)
    host = low_res.SPEC.apply(u8, params, None).astype(int)
    dev = low_res.SPEC.apply_torch(_on_cuda(u8), params, None).cpu().numpy()
    diff = np.abs(host - dev)
    assert diff.max() <= 2 and diff.mean() < 0.25


@pytest.mark.parametrize("quality, mean_codes", [(2, 4.0), (4, 4.0), (50, 2.5), (90, 1.5)])
def test_jpeg_within_stated_codes_on_cuda(quality: int, mean_codes: float) -> None:
    u8 = encode_srgb_u8(IMAGE)
    host = jpeg_compression.SPEC.apply(u8, {"quality": quality}, None).astype(int)
    dev = jpeg_compression.SPEC.apply_torch(_on_cuda(u8), {"quality": quality}, None)
    assert dev.device.type == "cuda" and dev.dtype == torch.uint8
    assert np.abs(host - dev.cpu().numpy()).mean() < mean_codes


@pytest.mark.parametrize("name", BENCH_DEGRADATIONS)
def test_pipeline_on_cuda_for_every_builtin(small_room, name: str) -> None:
    views = list(small_room.views)[:1]
    host = degrade(small_room, views, name, seed=3, options=PipelineOptions(image_size=(64, 48)))
    dev = degrade(small_room, views, name, seed=3, options=PipelineOptions(image_size=(64, 48), device=CUDA))
    assert dev.degradations == host.degradations  # same parameters and seeds
    assert dev.images.dtype == np.uint8 and dev.images.shape == host.images.shape
    diff = np.abs(host.images.astype(int) - dev.images)
    print(f"{name}: max {diff.max()} codes, mean {diff.mean():.3f}, > 2 codes {100 * (diff > 2).mean():.2f} %")
    if name == "jpeg_compression":
        assert diff.mean() < 4.0
    else:
        assert (diff > 2).mean() <= 0.01 and diff.mean() < 0.5, (name, diff.max(), diff.mean())

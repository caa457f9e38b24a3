"""The renderer's CUDA paths on a real GPU: gsplat's CUDA kernels and the torch backend on CUDA,
against the compiled CPU path. Skipped without a CUDA device (CI); ``benchmarks/gpu_check.sh``
runs them on a lent GPU.

Tolerances are the CPU-side ones of ``tests/render/test_gsplat_backend.py`` (the torch stand-ins
there are transcriptions of the kernels exercised here): at gsplat's alpha cap (0.999) rgb / alpha
/ expected depth within 1e-4, median depth and instance ids equal but for threshold flips at
T = ½ (≤ 0.2 % of pixels); at our default cap (0.99) mean |Δ| < 1e-4 and max < 1e-2.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from spacedg.render import FisheyeLens, MotionBlur, RasterSettings, render
from spacedg.render.camera import Camera
from tests.render.test_gsplat_backend import assert_close, assert_ids_close, scene  # one scene recipe and one frame comparison
from tests.render_helpers import camera

pytestmark = pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")

EXACT = RasterSettings(alpha_max=0.999)
ALL = ("rgb", "alpha", "depth", "median_depth", "instance_ids")


@pytest.fixture(scope="module")
def gsplat_cuda() -> None:
    """Skip when gsplat's CUDA extension does not load (the first import may JIT-compile it)."""
    from spacedg.render.gsplat_backend import gsplat_cuda_available

    if not gsplat_cuda_available():
        pytest.skip("gsplat's CUDA extension does not load")


def assert_on_cuda(frame) -> None:
    assert set(frame.tensors) == set(ALL)
    for name, tensor in frame.tensors.items():
        assert tensor.device.type == "cuda", name
        np.testing.assert_array_equal(tensor.cpu().numpy(), getattr(frame, name), err_msg=name)


@pytest.mark.parametrize("seed", [0, 1])
def test_gsplat_kernels_match_compiled_path(gsplat_cuda, seed: int) -> None:
    g, cam = scene(seed), camera(48, 32)
    got = render(g, cam, outputs="all", backend="gsplat", device="cuda", settings=EXACT)
    assert got.stats["ops"] == "cuda" and got.stats["visible"] > 100
    assert_on_cuda(got)
    assert_close(got, render(g, cam, outputs="all", backend="cpu", settings=EXACT))
    # the stand-ins (what CI checks) agree with the kernels
    assert_close(got, render(g, cam, outputs="all", backend="gsplat", device="cpu", settings=EXACT))


def test_gsplat_many_tiles(gsplat_cuda) -> None:
    """300 tiles, 4000 Gaussians: long float32 compositing chains (up to ~1e-3 apart at a few pixels)."""
    g, cam = scene(2, 4000), camera(320, 240)
    got = render(g, cam, outputs="all", backend="gsplat", device="cuda", settings=EXACT)
    ref = render(g, cam, outputs="all", backend="cpu", settings=EXACT)
    for name in ("rgb", "alpha", "depth"):
        diff = np.abs(getattr(got, name) - getattr(ref, name))
        assert diff.mean() < 1e-5 and diff.max() < 5e-3 and (diff > 1e-4).mean() < 0.01, (name, diff.mean(), diff.max())
    assert_ids_close(got, ref)


def test_gsplat_default_alpha_cap(gsplat_cuda) -> None:
    g, cam = scene(2), camera(48, 32)
    got = render(g, cam, outputs="all", backend="gsplat", device="cuda")
    ref = render(g, cam, outputs="all", backend="cpu")
    for name in ("rgb", "alpha", "depth"):
        diff = np.abs(getattr(got, name) - getattr(ref, name))
        assert diff.mean() < 1e-4 and diff.max() < 1e-2, (name, diff.mean(), diff.max())


def test_gsplat_fisheye(gsplat_cuda) -> None:
    g = scene(3)
    cam = Camera(20.0, 20.0, 24.2, 16.1, 48, 32, np.eye(4), FisheyeLens(-0.05, 0.01, 0.0, 0.0, max_theta=1.2))
    got = render(g, cam, outputs="all", backend="gsplat", device="cuda", settings=EXACT)
    assert got.valid is not None and not got.valid.all()
    assert_close(got, render(g, cam, outputs="all", backend="cpu", settings=EXACT))


def test_gsplat_motion_blur_batched(gsplat_cuda, monkeypatch: pytest.MonkeyPatch) -> None:
    import spacedg.render.gsplat_backend as backend

    monkeypatch.setattr(backend, "BATCH_ELEMENTS", 2 * 300)  # two sub-steps per batched call
    g, cam = scene(4), camera(48, 32)
    motion = MotionBlur(translation=(0.15, 0.0, 0.05), rotation=(0.0, 0.05, 0.0), sub_steps=5)
    got = render(g, cam, motion=motion, outputs="all", backend="gsplat", device="cuda", settings=EXACT)
    ref = render(g, cam, motion=motion, outputs="all", backend="cpu", settings=EXACT)
    assert got.stats["sub_steps"] == ref.stats["sub_steps"] == 5
    assert_close(got, ref)


def test_auto_picks_gsplat_on_cuda(gsplat_cuda) -> None:
    frame = render(scene(5), camera(48, 32), outputs="rgb", device="cuda")
    assert frame.stats["ops"] == "cuda" and frame.tensors["rgb"].device.type == "cuda"


@pytest.mark.parametrize("seed", [0, 1])
def test_torch_backend_on_cuda_matches_compiled_path(seed: int) -> None:
    g, cam = scene(seed), camera(48, 32)
    got = render(g, cam, outputs="all", backend="torch", device="cuda")
    assert got.tensors is None  # the torch backend hands back numpy images only
    assert_close(got, render(g, cam, outputs="all", backend="cpu"))


def test_torch_backend_on_cuda_equals_its_cpu_run() -> None:
    """The torch twin on CUDA and on the CPU: the same program, float32 rounding apart."""
    g, cam = scene(6), camera(64, 48)
    got = render(g, cam, outputs="all", backend="torch", device="cuda")
    assert_close(got, render(g, cam, outputs="all", backend="torch", device="cpu"))

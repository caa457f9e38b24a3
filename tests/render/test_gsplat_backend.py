"""``backend="gsplat"`` without a GPU: gsplat's CUDA calls swapped for torch stand-ins, against our compiled CPU path.

The stand-ins (:func:`~spacedg.render.gsplat_backend.reference_ops`) are gsplat's own torch
``_isect_offset_encode``, a vectorised twin of gsplat's torch ``_isect_tiles`` (checked equal to it
here) and a torch transcription of gsplat's CUDA forward compositor. Tolerances:

- ``alpha_max = 0.999`` (gsplat's hard-coded cap): rgb / alpha / expected depth within 1e-4
  (float32 order of summation); median depth and instance ids equal the torch twin's exactly and
  the compiled path's but for threshold flips at T = ½ (≤ 0.2 % of pixels; the twins flip alike);
- ``alpha_max = 0.99`` (our default; opacities clamped for gsplat): mean |Δ| < 1e-4, max < 1e-2;
  median depth and ids as above (our own second pass, with our alpha cap).
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from spacedg.errors import ParameterError
from spacedg.render import Defocus, FisheyeLens, MotionBlur, RasterSettings, render
from spacedg.render.camera import Camera
from spacedg.render.gsplat_backend import isect_tiles_torch, reference_ops
from spacedg.render.renderer import resolve_backend
from tests.render_helpers import camera, random_gaussians

EXACT = RasterSettings(alpha_max=0.999)


def scene(seed: int = 0, n: int = 300):
    return random_gaussians(n, np.random.default_rng(seed), scale=(0.03, 0.3), opacity=(0.3, 1.0))


def assert_close(got, ref, atol: float = 1e-4) -> None:
    for name in ("rgb", "alpha", "depth"):
        a, b = getattr(got, name), getattr(ref, name)
        if a is not None:
            np.testing.assert_allclose(a, b, atol=atol, rtol=1e-4, err_msg=name)
    assert_ids_close(got, ref)


def assert_ids_close(got, ref) -> None:
    """Median depth and instance ids equal but for threshold flips at T = ½ between float paths
    (≤ 0.2 % of pixels; the torch twin flips alike)."""
    for name in ("median_depth", "instance_ids"):
        a, b = getattr(got, name), getattr(ref, name)
        if a is not None:
            assert (a != b).mean() <= 0.002, (name, (a != b).sum())


def test_vectorised_isect_tiles_equals_gsplat_reference() -> None:
    from gsplat.cuda._torch_impl import _isect_tiles

    rng = np.random.default_rng(1)
    n = 120
    means2d = torch.tensor(rng.uniform(-20, 90, (2, n, 2)), dtype=torch.float32)
    radii = torch.tensor(rng.integers(0, 30, (2, n, 2)), dtype=torch.int32)
    depths = torch.tensor(rng.uniform(0.5, 9.0, (2, n)), dtype=torch.float32)
    ours = isect_tiles_torch(means2d, radii, depths, 16, 5, 4)
    theirs = _isect_tiles(means2d, radii, depths, 16, 5, 4)
    for a, b in zip(ours, theirs):
        torch.testing.assert_close(a, b.to(a.dtype), rtol=0, atol=0)


@pytest.mark.parametrize("seed", [0, 1])
def test_pinhole_matches_compiled_path_at_gsplats_alpha_cap(seed: int) -> None:
    g, cam = scene(seed), camera(48, 32)
    got = render(g, cam, outputs="all", backend="gsplat", device="cpu", settings=EXACT)
    ref = render(g, cam, outputs="all", backend="cpu", settings=EXACT)
    assert got.stats["ops"] == "torch-reference" and got.stats["visible"] > 100
    assert (ref.instance_ids >= 0).mean() > 0.3
    assert_close(got, ref)
    twin = render(g, cam, outputs="median_depth,instance_ids", backend="torch", device="cpu", settings=EXACT)
    np.testing.assert_array_equal(got.median_depth, twin.median_depth)
    np.testing.assert_array_equal(got.instance_ids, twin.instance_ids)


def test_default_alpha_cap_within_stated_tolerance() -> None:
    g, cam = scene(2), camera(48, 32)
    got = render(g, cam, outputs="all", backend="gsplat", device="cpu")
    ref = render(g, cam, outputs="all", backend="cpu")
    for name in ("rgb", "alpha", "depth"):
        diff = np.abs(getattr(got, name) - getattr(ref, name))
        assert diff.mean() < 1e-4 and diff.max() < 1e-2, (name, diff.mean(), diff.max())
    assert_close(got, ref, atol=1e-2)


def test_fisheye_and_device_tensors() -> None:
    g = scene(3)
    cam = Camera(20.0, 20.0, 24.2, 16.1, 48, 32, np.eye(4), FisheyeLens(-0.05, 0.01, 0.0, 0.0, max_theta=1.2))
    got = render(g, cam, outputs="all", backend="gsplat", device="cpu", settings=EXACT)
    ref = render(g, cam, outputs="all", backend="cpu", settings=EXACT)
    assert got.valid is not None and not got.valid.all()
    assert_close(got, ref)
    assert set(got.tensors) == {"rgb", "alpha", "depth", "median_depth", "instance_ids"}
    for name, tensor in got.tensors.items():
        np.testing.assert_array_equal(tensor.numpy(), getattr(got, name), err_msg=name)


def test_motion_blur_batched_matches_compiled_path(monkeypatch: pytest.MonkeyPatch) -> None:
    import spacedg.render.gsplat_backend as backend

    monkeypatch.setattr(backend, "BATCH_ELEMENTS", 2 * 300)  # two sub-steps per batched call
    g, cam = scene(4), camera(48, 32)
    motion = MotionBlur(translation=(0.15, 0.0, 0.05), rotation=(0.0, 0.05, 0.0), sub_steps=5)
    got = render(g, cam, motion=motion, outputs="all", backend="gsplat", device="cpu", settings=EXACT)
    ref = render(g, cam, motion=motion, outputs="all", backend="cpu", settings=EXACT)
    assert got.stats["sub_steps"] == ref.stats["sub_steps"] == 5
    assert_close(got, ref)


def test_fast_motion_takes_the_keyframe_path_on_every_backend() -> None:
    """Issue 32 (found on an H200): the gsplat backend chose its own sub-step count for fast motion
    while cpu and torch warp keyframes, so a bench motion_blur image differed from the CPU's by up to
    33 codes (12 % of pixels above 2 codes at 64x48). Fast motion is the keyframe warp on all three."""
    g, cam = scene(6), camera(64, 48)
    motion = MotionBlur(translation=(0.25, 0.0, 0.0), rotation=(0.0, 0.08, 0.0), sub_steps=8, fast=True)
    ref = render(g, cam, motion=motion, outputs="rgb,alpha", backend="cpu")
    for backend in ("gsplat", "torch"):
        got = render(g, cam, motion=motion, outputs="rgb,alpha", backend=backend, device="cpu")
        assert got.stats["sub_steps"] == ref.stats["sub_steps"], backend
        np.testing.assert_allclose(got.rgb, ref.rgb, atol=1e-4, err_msg=backend)
        np.testing.assert_allclose(got.alpha, ref.alpha, atol=1e-4, err_msg=backend)


def test_defocus_is_delegated_to_the_torch_twin() -> None:
    g, cam = scene(5, 150), camera(40, 30)
    defocus = Defocus(aperture=3.0, focus=3.0)
    got = render(g, cam, defocus=defocus, outputs="rgb,depth", backend="gsplat", device="cpu")
    ref = render(g, cam, defocus=defocus, outputs="rgb,depth", backend="torch", device="cpu")
    assert got.stats["delegated"] == "torch"
    np.testing.assert_array_equal(got.rgb, ref.rgb)


def test_backend_resolution_and_refusals() -> None:
    assert resolve_backend("auto", None) == ("cpu", None)
    assert resolve_backend("auto", "cpu")[0] == "cpu"
    backend, dev = resolve_backend("gsplat", None)
    assert backend == "gsplat" and dev.type == ("cuda" if torch.cuda.is_available() else "cpu")
    with pytest.raises(ParameterError, match="0.999"):
        render(scene(0, 20), camera(16, 16), backend="gsplat", device="cpu", settings=RasterSettings(alpha_max=0.9995))
    assert reference_ops().name == "torch-reference"


def test_auto_picks_gsplat_on_cuda_when_its_extension_loads(monkeypatch: pytest.MonkeyPatch) -> None:
    import spacedg.render.gsplat_backend as backend

    monkeypatch.setattr(backend, "gsplat_cuda_available", lambda: True)
    assert resolve_backend("auto", "cuda")[0] == "gsplat"
    monkeypatch.setattr(backend, "gsplat_cuda_available", lambda: False)
    assert resolve_backend("auto", "cuda")[0] == "torch"
    assert resolve_backend("auto", "mps")[0] == "torch"

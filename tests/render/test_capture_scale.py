"""The capture's pixel scale (``Camera.capture_focal``): trained Gaussians rendered smaller than their
capture look like the native render area-downsampled (issue 29, size invariance on real captures)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from tests.render_helpers import camera, random_gaussians
from spacedg.errors import InvalidDataError
from spacedg.render import Camera, RasterSettings, render
from spacedg.render.settings import footprint_dilation


def test_the_dilation_of_each_case() -> None:
    native = camera(90, 60).as_captured()
    third = native.resized(30, 20)
    classic = RasterSettings()
    assert footprint_dilation(camera(90, 60), classic) == (0.3, 0.3, 0.0, 0.0)
    assert footprint_dilation(native, classic) == (0.3, 0.3, 0.0, 0.0)
    assert footprint_dilation(third, RasterSettings(antialiased=True)) == (0.0, 0.0, 0.3, 0.3)
    model_x, model_y, filter_x, filter_y = footprint_dilation(third, classic)
    assert model_x == pytest.approx(0.3 / 9) and model_y == pytest.approx(0.3 / 9)
    assert filter_x == pytest.approx((1 - 1 / 9) / 12) and filter_y == pytest.approx((1 - 1 / 9) / 12)
    assert footprint_dilation(native.resized(180, 120), classic)[2:] == (0.0, 0.0)  # larger: no filter


@pytest.mark.parametrize("backend", ["cpu", "torch"])
def test_at_the_capture_size_the_render_is_the_classic_one_bit_for_bit(backend: str) -> None:
    gaussians = random_gaussians(400, np.random.default_rng(3), scale=(0.002, 0.05))
    plain = camera(64, 48)
    a = render(gaussians, plain, outputs="rgb,alpha", backend=backend)
    b = render(gaussians, plain.as_captured(), outputs="rgb,alpha", backend=backend)
    assert np.array_equal(a.rgb, b.rgb) and np.array_equal(a.alpha, b.alpha)


def _area_down(image: np.ndarray, factor: int) -> np.ndarray:
    h, w = image.shape[0] // factor, image.shape[1] // factor
    return image[: h * factor, : w * factor].reshape(h, factor, w, factor, -1).mean(axis=(1, 3))


@pytest.mark.parametrize("backend", ["cpu", "torch"])
def test_a_smaller_render_is_the_native_one_area_downsampled(backend: str) -> None:
    """A layer of fine Gaussians (a trained capture's statistics: about a native pixel each, at a
    third of the size mostly under an output pixel) rendered at 1/3 of their capture: the capture
    scale brings the direct render to the area-downsampled native one (mean error 0.0072 against the
    classic dilation's 0.049, which fattens every small Gaussian); the light stays within 4 % (what is
    left is compositing's non-linearity: small footprints that overlap at 1/3 did not at full size)."""
    gaussians = random_gaussians(6000, np.random.default_rng(7), depth=(3.0, 3.3), scale=(0.003, 0.02), opacity=(0.3, 1.0), sh_degree=0)
    native = camera(96, 72).as_captured()
    reference = _area_down(render(gaussians, native, outputs="rgb", backend=backend).rgb, 3)
    small = native.resized(32, 24)
    captured = render(gaussians, small, outputs="rgb", backend=backend).rgb
    classic = render(gaussians, replace(small, capture_focal=None), outputs="rgb", backend=backend).rgb
    err_captured = float(np.abs(captured - reference).mean())
    err_classic = float(np.abs(classic - reference).mean())
    assert np.isfinite(captured).all() and captured.min() >= 0.0
    assert err_captured < 0.25 * err_classic, (err_captured, err_classic)
    assert captured.mean() == pytest.approx(reference.mean(), rel=0.05)


def test_the_capture_focal_is_kept_saved_and_checked() -> None:
    cam = camera(90, 60).as_captured()
    assert cam.capture_focal == (cam.fx, cam.fy)
    assert cam.fitted(30, 30).capture_focal == cam.capture_focal
    assert Camera.from_dict(cam.to_dict()).capture_focal == cam.capture_focal
    assert "capture_focal" not in camera(90, 60).to_dict()
    assert cam.resized(1, 1).capture_focal == cam.capture_focal  # any resize the size policy allows keeps it
    for bad in ((1.0,), (0.0, 5.0), (float("nan"), 3.0), "wide", (1e-300, 1e-300), (1e300, 1e300), (cam.fx * 1e5, cam.fy)):
        with pytest.raises(InvalidDataError, match="capture_focal"):
            replace(cam, capture_focal=bad)


def test_the_defocus_sharp_pass_dilates_as_the_view_scaled() -> None:
    """The half-resolution sharp pass of defocus: its footprints are the view's × ½, the capture-scale
    low-pass included (its dilation is the view's × ¼ term by term)."""
    from spacedg.render.defocus import measurement_camera, measurement_settings

    view = camera(96, 72).as_captured().resized(32, 24)
    settings = RasterSettings()
    full = footprint_dilation(view, settings)
    half = footprint_dilation(measurement_camera(view, 0, 0.5), measurement_settings(settings, 0.5))
    assert half == pytest.approx(tuple(0.25 * v for v in full), rel=1e-12)
    plain = camera(32, 24)  # no capture focal: the classic eps2d × ¼, bit for bit as before
    assert footprint_dilation(measurement_camera(plain, 0, 0.5), measurement_settings(settings, 0.5)) == (0.075, 0.075, 0.0, 0.0)


def test_both_backends_agree_with_a_capture_scale() -> None:
    gaussians = random_gaussians(3000, np.random.default_rng(11), scale=(0.003, 0.05))
    view = camera(192, 144).as_captured().resized(64, 48)
    a = render(gaussians, view, outputs="rgb,alpha", backend="cpu")
    b = render(gaussians, view, outputs="rgb,alpha", backend="torch")
    for name in ("rgb", "alpha"):
        diff = np.abs(getattr(a, name) - getattr(b, name))
        assert diff.mean() < 1e-5 and diff.max() < 5e-3, (name, diff.mean(), diff.max())

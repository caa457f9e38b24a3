"""Local flux conservation of defocus (spacedg.render.defocus_flux): the step restores the sharp view's
light wherever the blurred composite lost or gained some, maps the half-resolution sharp grid onto the
view exactly, stays finite on black and empty images, and lets sub-pixel blur blur (issue 29)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from spacedg.render import Camera, Defocus, render
from spacedg.render.defocus import measurement_camera
from spacedg.render.defocus_flux import conserve_light, flux_lengths, flux_scale, sample_shifted, sharp_flux_lengths
from tests.render_helpers import camera, random_gaussians

CAM = Camera(40.0, 40.0, 32.0, 24.0, 64, 48, np.eye(4))


def _texture(seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return cv2.GaussianBlur(rng.uniform(0.0, 1.0, (48, 64, 3)).astype(np.float32), (5, 5), 1.0)


@pytest.mark.parametrize("scale", [1.0, 0.5])
def test_a_darkened_blur_gets_the_sharp_views_light_back(scale: float) -> None:
    """A blurred view that lost 12 % of the light on its left half and gained 8 % on its right comes back
    to the sharp view's light within 0.5 % on each half (the sharp pass at full or half resolution)."""
    sharp = _texture()
    wide = measurement_camera(CAM, 0, scale)
    sharp_wide = _on_grid(sharp, wide) if scale != 1.0 else sharp  # the half-resolution grid is centred in whole tiles
    blurred = cv2.GaussianBlur(sharp, (13, 13), 2.0)
    blurred[:, :32] *= 0.88
    blurred[:, 32:] *= 1.08
    alpha = np.ones((48, 64), np.float32)
    rgb, out_alpha = conserve_light(blurred, alpha, sharp_wide, np.ones(sharp_wide.shape[:2], np.float32), CAM, wide, 2.0, 2.0)
    for half in (slice(4, 28), slice(36, 60)):
        assert rgb[:, half].mean() == pytest.approx(sharp[:, half].mean(), rel=0.005)
    np.testing.assert_allclose(out_alpha, 1.0, atol=1e-6)


def _on_grid(image: np.ndarray, wide: Camera) -> np.ndarray:
    """``image`` (the view) area-downsampled by 2 and placed on ``wide``'s grid (edges repeated)."""
    half = cv2.resize(image, (image.shape[1] // 2, image.shape[0] // 2), interpolation=cv2.INTER_AREA)
    x0, y0 = int(round(wide.cx - CAM.cx / 2)), int(round(wide.cy - CAM.cy / 2))
    return cv2.copyMakeBorder(half, y0, wide.height - half.shape[0] - y0, x0, wide.width - half.shape[1] - x0, cv2.BORDER_REPLICATE)


def test_the_half_resolution_grid_maps_onto_the_view_exactly() -> None:
    """A linear ramp on the half-resolution measurement grid, sampled at the centres of the view's 2 × 2
    cells, is the ramp at those centres."""
    view = Camera(100.0, 100.0, 50.0, 30.0, 100, 60, np.eye(4))
    wide = measurement_camera(view, 0, 0.5)
    ys, xs = np.mgrid[0 : wide.height, 0 : wide.width].astype(np.float32)
    ramp = np.stack([xs, ys, xs + ys], axis=-1)
    got = sample_shifted(ramp, view, wide, 2, (30, 50))
    cx = (np.arange(50) * 2 + 1.0 - view.cx) * 0.5 + wide.cx - 0.5
    cy = (np.arange(30) * 2 + 1.0 - view.cy) * 0.5 + wide.cy - 0.5
    np.testing.assert_allclose(got[..., 0], np.broadcast_to(cx[None, :], (30, 50)), atol=1e-4)
    np.testing.assert_allclose(got[..., 1], np.broadcast_to(cy[:, None], (30, 50)), atol=1e-4)


def test_black_and_empty_images_stay_finite() -> None:
    """Zero light anywhere (blurred, sharp or both) gives finite output, black where the blurred view is black,
    and the factor never exceeds its bound."""
    zero, ones = np.zeros((48, 64, 3), np.float32), np.ones((48, 64, 3), np.float32)
    a0, a1 = np.zeros((48, 64), np.float32), np.ones((48, 64), np.float32)
    for blurred, sharp, alpha, sharp_alpha in ((zero, zero, a0, a0), (zero, ones, a0, a1), (ones, zero, a1, a0)):
        rgb, alpha_out = conserve_light(blurred, alpha, sharp, sharp_alpha, CAM, CAM, 1.0, 0.5)
        assert np.isfinite(rgb).all() and np.isfinite(alpha_out).all()
        assert rgb.max() <= 4.0 * blurred.max() + 1e-6 and 0.0 <= alpha_out.min() and alpha_out.max() <= 1.0
    assert flux_lengths(np.array([])) == (1.0, 0.0) and flux_lengths(np.array([np.nan, 8.0]))[0] == pytest.approx(4.0)
    assert flux_scale(0.5) == 1.0 and flux_scale(4.0) == 0.5 and flux_scale(float("nan")) == 1.0


@pytest.mark.parametrize("seed", range(40))
def test_compiled_flux_lengths_are_the_numpy_ones(seed: int) -> None:
    """:func:`sharp_flux_lengths` (the compiled path the renderer takes) gives :func:`flux_lengths` of the covered
    pixels' circles of confusion bit for bit: sizes of one pixel to two histogram blocks, NaN and infinite depths,
    NaN alphas, nothing covered, one depth everywhere (every circle of confusion equal), the focus in the scene."""
    rng = np.random.default_rng(4000 + seed)
    height, width = (480, 300) if seed == 0 else tuple(int(v) for v in rng.integers(1, 160, 2))
    depth = (rng.random((height, width)) * rng.choice([0.01, 5.0, 100.0]) + rng.choice([0.0, 0.5])).astype(np.float32)
    alpha = rng.random((height, width)).astype(np.float32)
    if seed % 4 == 1:
        depth.flat[rng.integers(0, depth.size, 3)] = np.nan
        depth.flat[rng.integers(0, depth.size, 3)] = np.inf
    if seed % 5 == 2:
        alpha.flat[rng.integers(0, alpha.size, 3)] = np.nan
    if seed % 7 == 3:
        alpha[:] = 0.0
    if seed % 6 == 4:
        depth[:] = 2.0
    defocus = Defocus(float(rng.choice([0.5, 20.0, 300.0])), float(rng.choice([0.3, 2.0, 50.0])), max_radius=float(rng.choice([3.0, 40.0])))
    seen = alpha > 1e-3
    with np.errstate(invalid="ignore"):
        expected = flux_lengths(defocus.radius(np.maximum(depth[seen], 1e-6)), alpha[seen])
    assert sharp_flux_lengths(depth, alpha, defocus.aperture, defocus.focus, defocus.max_radius) == expected


def test_sub_pixel_blur_blurs_and_keeps_the_light() -> None:
    """A blur of a third of a pixel is no longer rendered sharp (DEFOCUS_MIN_COC = 0: a cut-off in output pixels
    broke size invariance), and keeps the light within 0.5 %."""
    g = random_gaussians(400, np.random.default_rng(1), depth=(2.0, 4.0))
    cam = camera(96, 72)
    sharp = render(g, cam)
    blurred = render(g, cam, defocus=Defocus(1.0, 3.0))  # r <= 0.5 px over the depths
    assert not np.array_equal(sharp.rgb, blurred.rgb)
    assert blurred.rgb.mean() == pytest.approx(sharp.rgb.mean(), rel=0.005)
    assert np.abs(blurred.rgb - sharp.rgb).mean() < 0.02


def _conserve_numpy(rgb, alpha, sharp_rgb, sharp_alpha, camera, wide, length, coc):  # type: ignore[no-untyped-def]
    """conserve_light as plain numpy/OpenCV (its form before the compiled passes, with OpenCV's own bilinear
    upsampling written out: :func:`_resize_linear`): the reference of the bytes."""
    import math

    from spacedg.render.defocus_flux import FLUX_RATIO, _blur

    step = max(1, int(round(camera.fx / wide.fx)))
    image = np.ascontiguousarray(np.concatenate([rgb, alpha[..., None]], axis=-1), dtype=np.float32)
    rows, cols = -(-image.shape[0] // step), -(-image.shape[1] // step)
    if step > 1:
        padded = cv2.copyMakeBorder(image, 0, rows * step - image.shape[0], 0, cols * step - image.shape[1], cv2.BORDER_REPLICATE)
        blurred = cv2.resize(padded, (cols, rows), interpolation=cv2.INTER_AREA)
    else:
        blurred = image
    sharp = np.ascontiguousarray(np.concatenate([sharp_rgb, sharp_alpha[..., None]], axis=-1), dtype=np.float32)
    sx, sy = wide.fx / camera.fx, wide.fy / camera.fy
    affine = np.array([[step * sx, 0.0, (0.5 * step - camera.cx) * sx + wide.cx - 0.5],
                       [0.0, step * sy, (0.5 * step - camera.cy) * sy + wide.cy - 0.5]])
    seen = cv2.warpAffine(sharp, affine, (cols, rows), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP, borderMode=cv2.BORDER_REPLICATE)
    target = _blur(seen, math.hypot(length, coc) / step)
    eps = (1e-3 * np.maximum(np.array(cv2.mean(target)), 0.0) + 1e-12).astype(np.float32)
    low = _blur(blurred, length / step)
    low += eps
    target += eps
    ratio = np.clip(np.divide(target, low, out=target), *FLUX_RATIO, out=target)
    ratio[np.isnan(ratio)] = 1.0
    kept = np.array(cv2.sumElems(blurred * ratio))
    wanted = np.array(cv2.sumElems(seen))
    with np.errstate(divide="ignore", invalid="ignore"):
        total = np.where(kept > 1e-12 * max(float(wanted.max()), 1e-30), wanted / kept, 1.0)
    ratio = ratio * np.clip(np.nan_to_num(total, nan=1.0), *FLUX_RATIO).astype(np.float32)
    if step > 1:
        ratio = _resize_linear(ratio, cols * step, rows * step)[: image.shape[0], : image.shape[1]]
    out = image * ratio
    return out[..., :3], np.clip(out[..., 3], 0.0, 1.0)


def _resize_linear(image: np.ndarray, width: int, height: int) -> np.ndarray:
    """OpenCV's INTER_LINEAR resize of a float32 (h, w, C) image as numpy, without IPP: source position
    ``(k + ½)·n_in/n_out − ½``, the edge sample past either edge, rows resized along x first, float32."""
    def taps(n_out: int, n_in: int):  # type: ignore[no-untyped-def]
        position = ((np.arange(n_out) + 0.5) * (n_in / n_out) - 0.5).astype(np.float32)
        i0 = np.floor(position).astype(np.int64)
        w1 = (position - i0).astype(np.float32)
        w1[(i0 < 0) | (i0 >= n_in - 1)] = 0.0
        i0 = np.clip(i0, 0, n_in - 1)
        return i0, np.minimum(i0 + 1, n_in - 1), np.float32(1.0) - w1, w1

    x0, x1, wx0, wx1 = taps(width, image.shape[1])
    y0, y1, wy0, wy1 = taps(height, image.shape[0])
    rows = image[:, x0] * wx0[None, :, None] + image[:, x1] * wx1[None, :, None]
    return rows[y0] * wy0[:, None, None] + rows[y1] * wy1[:, None, None]


def test_the_written_out_bilinear_is_opencvs_without_ipp() -> None:
    """The reference's bilinear upsampling is OpenCV's own (IPP off: IPP's rounding depends on the build and the
    CPU, so conserve_light defines its bytes by OpenCV's formula) at factor 2, the one conserve_light uses, on an
    odd and an even size. (At other factors OpenCV places its taps slightly differently.)"""
    rng = np.random.default_rng(7)
    ipp = cv2.ipp.useIPP()
    cv2.ipp.setUseIPP(False)
    try:
        for height, width in ((31, 49), (24, 40)):
            image = (rng.uniform(0.0, 4.0, (height, width, 4)) * rng.uniform(0.0, 50.0, (height, width, 4))).astype(np.float32)
            want = cv2.resize(image, (2 * width, 2 * height), interpolation=cv2.INTER_LINEAR)
            assert np.array_equal(_resize_linear(image, 2 * width, 2 * height).view(np.uint32), want.view(np.uint32))
    finally:
        cv2.ipp.setUseIPP(ipp)


@pytest.mark.parametrize("scale", [1.0, 0.5])
def test_the_compiled_passes_give_the_numpy_bytes(scale: float) -> None:
    """conserve_light's fused passes against its plain numpy form, byte for byte: random light with black
    and saturated corners, an odd-sized view, the sharp pass at full and half resolution (grown to whole tiles)."""
    rng = np.random.default_rng(11)
    cam = Camera(60.0, 60.0, 48.5, 30.5, 97, 61, np.eye(4))
    wide = measurement_camera(cam, 0, scale)
    rgb = rng.uniform(0.0, 1.5, (61, 97, 3)).astype(np.float32)
    alpha = rng.uniform(0.0, 1.0, (61, 97)).astype(np.float32)
    rgb[:8, :8], alpha[:8, :8] = 0.0, 0.0
    alpha[-4:, -4:] = 1.0
    sharp_rgb = rng.uniform(0.0, 1.5, (wide.height, wide.width, 3)).astype(np.float32)
    sharp_alpha = rng.uniform(0.0, 1.0, (wide.height, wide.width)).astype(np.float32)
    for length, coc in ((1.0, 0.4), (2.5, 3.0)):
        got = conserve_light(rgb, alpha, sharp_rgb, sharp_alpha, cam, wide, length, coc)
        want = _conserve_numpy(rgb, alpha, sharp_rgb, sharp_alpha, cam, wide, length, coc)
        for g, w in zip(got, want):
            assert g.shape == w.shape and np.array_equal(np.ascontiguousarray(g).view(np.uint32), np.ascontiguousarray(w).view(np.uint32))

"""``haze`` (Koschmieder on rendered depth) and ``low_res`` (area down, bilinear up)."""

from __future__ import annotations

import numpy as np
import pytest

from spacedg.errors import InvalidDataError, ParameterError
from spacedg.plugins import Category, Stage
from spacedg.plugins.degradations import haze, low_res
from spacedg.plugins.degradations.low_res import reduced_size


def _scene_light(h: int = 48, w: int = 64, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    rgb = (rng.random((h, w, 3)) * 1.5).astype(np.float32)  # HDR: some values above 1
    depth = rng.uniform(0.5, 6.0, (h, w)).astype(np.float32)
    alpha = np.ones((h, w), np.float32)
    return rgb, depth, alpha


def test_haze_declaration() -> None:
    spec = haze.SPEC
    assert (spec.stage, spec.category, spec.needs) == (Stage.LINEAR, Category.METEOROLOGICAL, frozenset({"depth", "alpha"}))
    assert spec.presets["bench"]["density"].to_list() == [3.5, 6.0]


def test_haze_zero_density_is_identity() -> None:
    rgb, depth, alpha = _scene_light()
    out = haze.SPEC.apply(rgb, {"depth": depth, "alpha": alpha}, {"density": 0.0, "airlight": 0.8, "depth_ref": 0.0}, np.random.default_rng(0))
    assert out is not rgb and np.array_equal(out, rgb)


@pytest.mark.parametrize("depth_ref", [0.0, 7.5])
def test_haze_koschmieder_invariant(depth_ref: float) -> None:
    rgb, depth, alpha = _scene_light()
    airlight, density = 0.8, 4.0
    out = haze.haze(rgb, depth, alpha, density, airlight, depth_ref)
    far = haze.surface_far_depth(depth, alpha) if depth_ref == 0 else depth_ref
    beta = density / far
    ratio = (out.astype(np.float64) - airlight) / (rgb.astype(np.float64) - airlight)
    ok = np.abs(rgb - airlight) > 0.05
    np.testing.assert_allclose(ratio[ok], np.broadcast_to(np.exp(-beta * depth)[..., None], rgb.shape)[ok], rtol=2e-4, atol=2e-5)


def test_haze_uses_the_sample_far_depth_for_multi_view_consistency() -> None:
    rgb, depth, alpha = _scene_light()
    near_view = np.minimum(depth, 2.0)
    a = haze.SPEC.apply(rgb, {"depth": depth, "alpha": alpha, "far_depth": 9.0}, {"density": 3.0, "airlight": 0.8, "depth_ref": 0.0}, np.random.default_rng(0))
    b = haze.SPEC.apply(rgb, {"depth": near_view, "alpha": alpha, "far_depth": 9.0}, {"density": 3.0, "airlight": 0.8, "depth_ref": 0.0}, np.random.default_rng(0))
    same = depth <= 2.0  # the same surface at the same depth in both views: the same transmission
    assert np.array_equal(a[same], b[same])


def test_haze_no_surface_and_bad_depths_are_far_and_finite() -> None:
    rgb, depth, alpha = _scene_light()
    depth[0, :4] = [0.0, np.nan, np.inf, np.inf]
    depth[1, 0] = 1e30
    alpha[2, :3] = [0.0, 0.5, np.nan]
    for density in (1e-6, 4.0, 100.0):
        out = haze.haze(rgb, depth, alpha, density, 0.8)
        assert out.dtype == np.float32 and np.isfinite(out).all()
    out = haze.haze(rgb, depth, alpha, 100.0, 0.8)
    assert np.allclose(out[0, :4], 0.8, atol=1e-6)  # no surface → airlight (e^{-100} ≈ 0)
    far = haze.surface_far_depth(depth, alpha)
    out = haze.haze(rgb, depth, alpha, 2.0, 0.8)
    expected = rgb[0, 0] * np.exp(-2.0) + 0.8 * (1 - np.exp(-2.0))
    np.testing.assert_allclose(out[0, 0], expected, rtol=1e-5)
    assert far > 0
    depth[0, 3] = -1.0  # negative depth is invalid input (SPEC), not "no surface"
    with pytest.raises(InvalidDataError, match="negative"):
        haze.haze(rgb, depth, alpha, 2.0, 0.8)


def test_haze_partial_coverage_blends_background_airlight() -> None:
    rgb = np.zeros((1, 1, 3), np.float32)
    out = haze.haze(rgb, np.array([[2.0]], np.float32), np.array([[0.25]], np.float32), 1.0, 1.0, depth_ref=4.0, far_depth=8.0)
    # the uncovered quarter lies at the normalisation depth (4 m), not at the sample's far surface (8 m)
    t_surface, t_background = np.exp(-0.25 * 2.0), np.exp(-0.25 * 4.0)
    np.testing.assert_allclose(out[0, 0], 0.25 * (1 - t_surface) + 0.75 * (1 - t_background), rtol=1e-6)
    automatic = haze.haze(rgb, np.array([[2.0]], np.float32), np.array([[0.25]], np.float32), 1.0, 1.0, depth_ref=0.0, far_depth=8.0)
    np.testing.assert_allclose(automatic[0, 0], 0.25 * (1 - np.exp(-2.0 / 8.0)) + 0.75 * (1 - np.exp(-1.0)), rtol=1e-6)


def test_haze_needs_depth() -> None:
    rgb, _, alpha = _scene_light()
    with pytest.raises(InvalidDataError, match="haze needs the rendered 'depth'"):
        haze.SPEC.apply(rgb, {"alpha": alpha}, {"density": 1.0, "airlight": 0.8, "depth_ref": 0.0}, np.random.default_rng(0))
    with pytest.raises(InvalidDataError, match="shape"):
        haze.SPEC.apply(rgb, {"depth": np.ones((3, 3)), "alpha": alpha}, {"density": 1.0, "airlight": 0.8, "depth_ref": 0.0}, np.random.default_rng(0))


def test_haze_severity_is_monotone() -> None:
    rgb, depth, alpha = _scene_light()
    rgb = np.clip(rgb * 0.3, 0, 1)
    means = []
    for level in ("1", "2", "3", "4", "5"):
        p = haze.SPEC.sample_params(level, np.random.default_rng(3))
        out = haze.SPEC.apply(rgb, {"depth": depth, "alpha": alpha}, p, np.random.default_rng(0))
        means.append(float(np.abs(out - rgb).mean()))
    assert means == sorted(means) and means[0] > 0


def _texture(h: int = 120, w: int = 160) -> np.ndarray:
    """Detail at several scales (periods of ~10, ~40 and ~150 px), so each severity removes more."""
    y, x = np.mgrid[0:h, 0:w]
    base = 127 + 40 * np.sin(x / 1.7) * np.cos(y / 2.3) + 40 * np.sin(x / 6.5 + y / 7.0) + 40 * np.cos(x / 24.0)
    return np.repeat(base[..., None], 3, axis=2).astype(np.uint8)


def test_low_res_identity_size_rule_and_constant() -> None:
    image = _texture()
    assert np.array_equal(low_res.low_res(image, 1.0), image)
    assert reduced_size(640, 480, 0.02) == (13, 10) and reduced_size(640, 480, 0.001) == (1, 1)
    flat = np.full((60, 80, 3), 77, np.uint8)
    assert np.array_equal(low_res.low_res(flat, 0.13), flat)  # a constant image stays constant
    one = low_res.low_res(image, 0.001)
    assert one.shape == image.shape and (one == one[0, 0]).all()  # one pixel: the mean colour
    assert abs(int(one[0, 0, 0]) - float(image[..., 0].mean())) <= 1


def test_low_res_severity_is_monotone_and_deterministic() -> None:
    image = _texture()
    distances = []
    for level in ("1", "2", "3", "4", "5"):
        p = low_res.SPEC.sample_params(level, np.random.default_rng(0))
        out = low_res.SPEC.apply(image, p, np.random.default_rng(1))
        assert np.array_equal(out, low_res.SPEC.apply(image, p, np.random.default_rng(2)))
        distances.append(float(np.abs(out.astype(float) - image).mean()))
    assert distances == sorted(distances) and distances[0] > 0


def test_low_res_bad_input() -> None:
    with pytest.raises(InvalidDataError, match="uint8"):
        low_res.low_res(np.zeros((4, 4, 3), np.float32), 0.5)
    with pytest.raises(ParameterError, match="outside its hard limits"):
        low_res.SPEC.apply(_texture(), {"scale": 0.0}, np.random.default_rng(0))


def test_the_compiled_haze_is_numpys_koschmieder_bit_for_bit() -> None:
    """:func:`~spacedg.plugins.degradations.haze.haze` (one compiled pass) gives the bytes of the numpy
    expression it replaced, on float32 and float64 depth, alpha with NaN, ±inf and values outside [0, 1], no
    surface (0, NaN, inf), HDR colour, either normalisation depth."""
    from spacedg.plugins.degradations.common import surface_far_depth
    from spacedg.plugins.degradations.haze import haze

    def numpy_haze(rgb, depth, alpha, density, airlight, depth_ref, far_depth):
        far_depth = surface_far_depth(depth, alpha) if far_depth is None else far_depth
        far = float(far_depth) if far_depth and np.isfinite(far_depth) and far_depth > 0 else (depth_ref or 1.0)
        beta = np.float32(density / (depth_ref if depth_ref > 0 else far))
        far = depth_ref if depth_ref > 0 else far
        cover = np.clip(np.nan_to_num(alpha, nan=0.0), 0.0, 1.0).astype(np.float32)
        d = np.where((depth > 0) & np.isfinite(depth), np.minimum(depth, 1e12), far).astype(np.float32)
        t = np.exp(-beta * d)
        air = cover * (1.0 - t) + (1.0 - cover) * (1.0 - np.float32(np.exp(-float(beta) * far)))
        return (rgb * t[:, :, None] + np.float32(airlight) * air[:, :, None]).astype(np.float32, copy=False)

    for seed in range(12):
        rng = np.random.default_rng(700 + seed)
        h, w = (int(v) for v in rng.integers(1, 60, 2))
        rgb = (rng.random((h, w, 3)) * rng.choice([1.0, 5.0, 1e6])).astype(np.float32)
        depth = (rng.random((h, w)) * rng.choice([3.0, 100.0, 1e15])).astype(rng.choice([np.float32, np.float64]))
        for value, share in ((0.0, 0.1), (np.nan, 0.05), (np.inf, 0.05)):
            depth[rng.random((h, w)) < share] = value
        alpha = (rng.random((h, w)) * 1.4 - 0.2).astype(rng.choice([np.float32, np.float64]))
        alpha[rng.random((h, w)) < 0.05] = np.nan
        alpha[rng.random((h, w)) < 0.02] = np.inf
        args = (rgb, depth, alpha, float(rng.random() * 8), float(rng.random()), float(rng.choice([0.0, 12.5])),
                None if seed % 2 else float(rng.random() * 5))
        assert haze(*args).tobytes() == numpy_haze(*args).tobytes(), seed

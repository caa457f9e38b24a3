"""Built-in ``jpeg_compression`` degradation (display stage, OpenCV libjpeg)."""

from __future__ import annotations

import numpy as np
import pytest

from spacedg.errors import InvalidDataError, ParameterError
from spacedg.plugins import Category, Stage
from spacedg.plugins.degradations.jpeg_compression import SPEC, jpeg_compress


def _textured(height: int = 96, width: int = 128) -> np.ndarray:
    """A deterministic natural-ish image: smooth gradients, a sinusoidal texture, edges, mild noise."""
    y, x = np.mgrid[0:height, 0:width].astype(np.float64)
    base = np.stack([x / width, y / height, 0.5 + 0.25 * np.sin((x + y) / 17.0)], axis=-1)
    texture = 0.12 * (np.sin(x / 2.3) * np.cos(y / 3.1))[..., None]
    edges = 0.2 * ((x // 24 + y // 24) % 2)[..., None]
    noise = np.random.default_rng(0).normal(0.0, 0.01, size=(height, width, 3))
    return np.clip(255.0 * (0.15 + 0.6 * base + texture + edges + noise), 0, 255).round().astype(np.uint8)


def _psnr(a: np.ndarray, b: np.ndarray) -> float:
    mse = float(np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2))
    return float("inf") if mse == 0 else 10.0 * np.log10(255.0**2 / mse)


def _apply(image: np.ndarray, quality: int, seed: int = 0) -> np.ndarray:
    return SPEC.apply(image, {"quality": quality}, np.random.default_rng(seed))


def test_spec_declaration() -> None:
    assert SPEC.name == "jpeg_compression" and SPEC.stage is Stage.DISPLAY and SPEC.category is Category.DIGITAL
    (quality,) = SPEC.params
    assert (quality.name, quality.unit, quality.low, quality.high, quality.integer) == ("quality", "1", 1, 100, True)
    assert SPEC.presets["bench"]["quality"].to_list() == [2, 5]
    assert SPEC.needs == frozenset()


def test_quality_100_is_near_identity() -> None:
    image = _textured()
    assert _psnr(_apply(image, 100), image) > 40.0


def test_distance_rises_with_severity() -> None:
    image = _textured()
    distances = []
    for level in ("1", "2", "3", "4", "5"):
        r = SPEC.presets[level]["quality"]
        q = int(round((r.low + r.high) / 2))
        distances.append(float(np.mean(np.abs(_apply(image, q).astype(np.float64) - image))))
    assert all(a < b for a, b in zip(distances, distances[1:])), distances
    # and monotone in q itself over a wide sweep
    sweep = [float(np.mean(np.abs(_apply(image, q).astype(np.float64) - image))) for q in (95, 75, 50, 25, 10, 5)]
    assert sweep == sorted(sweep), sweep


def test_deterministic_and_rng_independent() -> None:
    image = _textured()
    first = _apply(image, 7, seed=0)
    assert np.array_equal(first, _apply(image, 7, seed=123))
    assert np.array_equal(first, jpeg_compress(image, 7))
    assert first.tobytes() == _apply(image.copy(), 7).tobytes()


@pytest.mark.parametrize("shape", [(96, 128, 3), (17, 23, 3), (1, 1, 3)])
def test_dtype_and_shape(shape: tuple[int, int, int]) -> None:
    image = np.random.default_rng(1).integers(0, 256, size=shape, dtype=np.uint8)
    before = image.copy()
    out = _apply(image, 30)
    assert out.dtype == np.uint8 and out.shape == shape
    assert np.array_equal(image, before), "input modified"
    strided = _textured()[:, ::2]  # non-contiguous view
    assert _apply(strided, 50).shape == strided.shape


@pytest.mark.parametrize(
    ("image", "pattern"),
    [
        (np.zeros((8, 8, 3), np.float32), "must be uint8.*got dtype float32.*silently cast"),
        (np.zeros((8, 8, 3), np.float64), "must be uint8"),
        (np.zeros((8, 8), np.uint8), r"shape \(H, W, 3\)"),
        (np.zeros((8, 8, 4), np.uint8), r"shape \(H, W, 3\)"),
        (np.zeros((0, 8, 3), np.uint8), r"shape \(H, W, 3\)"),
        ([[0, 0, 0]], "numpy array"),
    ],
)
def test_bad_images_rejected(image: object, pattern: str) -> None:
    with pytest.raises(InvalidDataError, match=pattern):
        _apply(image, 50)  # type: ignore[arg-type]


@pytest.mark.parametrize(("params", "pattern"), [
    ({"quality": 0}, r"outside its hard limits \[1, 100\]"),
    ({"quality": 101}, r"outside its hard limits \[1, 100\]"),
    ({"quality": 50.5}, "must be an integer"),
    ({"qualty": 50}, "Did you mean 'quality'"),
    ({}, r"missing parameter\(s\) \['quality'\]"),
])
def test_bad_params_rejected(params: dict, pattern: str) -> None:
    with pytest.raises(ParameterError, match=pattern):
        SPEC.apply(_textured(16, 16), params, np.random.default_rng(0))


def test_pure_red_stays_red() -> None:
    red = np.zeros((32, 48, 3), np.uint8)
    red[..., 0] = 255
    for q in (95, 50, 5):
        out = _apply(red, q)
        assert out[..., 0].min() >= 240 and out[..., 1:].max() <= 15, (q, out[0, 0])


def test_harsh_end_saturates() -> None:
    # libjpeg scales its tables by 5000/q below q = 50 and clamps entries at 255: at q <= 2
    # nearly all entries are saturated, so q = 1 and q = 2 give almost the same image, while
    # q = 2 → 5 still changes it (q = 2 and q = 3 are *not* identical with libjpeg-turbo 3.x).
    image = _textured()
    q1, q2, q5 = (_apply(image, q).astype(np.float64) for q in (1, 2, 5))
    assert np.mean(np.abs(q1 - q2)) < 0.25 * np.mean(np.abs(q2 - q5))


def test_sampled_presets_are_valid_integers() -> None:
    rng = np.random.default_rng(3)
    for preset in SPEC.preset_names:
        r = SPEC.presets[preset]["quality"]
        for _ in range(20):
            q = SPEC.sample_params(preset, rng)["quality"]
            assert isinstance(q, int) and r.low <= q <= r.high

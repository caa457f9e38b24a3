"""The photosites' one-pass kernel (:mod:`spacedg.plugins.degradations._photosite_kernel`) against OpenCV and the sensor:
the same bytes as ``cv2.resize`` (INTER_AREA) onto the grid, ``sensor_capture`` there and ``cv2.resize`` back."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from spacedg.errors import InvalidDataError
from spacedg.plugins.degradations import _photosite_kernel, _photosites
from spacedg.plugins.degradations._sensor import READ_GAUSSIAN, READ_TUKEY, sensor_capture

#: (image width, height) → (grid columns, rows): the dataset's 4:3 views, a 3:2 one, odd and tiny sizes, a
#: grid only just larger than the image, ratios of 2.43, 3.0 along one axis only, 19.3.
SIZES = [((64, 48), (156, 117)), ((58, 39), (175, 117)), ((37, 23), (101, 67)), ((9, 7), (174, 135)), ((50, 40), (51, 41)), ((20, 30), (60, 71))]
SENSOR = {"k": 1e-4, "sigma_read": 2.5e-4}


def _through_opencv(signal: np.ndarray, grid: tuple[int, int], key: int, **sensor: float) -> np.ndarray:
    """The two-resample path the kernel replaces."""
    sites = cv2.resize(signal, grid, interpolation=cv2.INTER_AREA)
    noise = sensor_capture(sites, exposure=1.0, key=key, noise=True, **sensor)  # type: ignore[arg-type]
    return cv2.resize(noise, signal.shape[1::-1], interpolation=cv2.INTER_AREA)


#: The bit-for-bit comparisons with OpenCV hold where its resamples are the kernel's float32 operations (an
#: unfused build, as the pinned wheels); elsewhere the photosites keep OpenCV's own resamples (tested below).
needs_agreeing_opencv = pytest.mark.skipif(not _photosite_kernel.opencv_agrees(), reason="this OpenCV fuses its resize steps")


@needs_agreeing_opencv
@pytest.mark.parametrize(("size", "grid"), SIZES)
def test_the_tables_are_opencvs_area_resampling_both_ways(size: tuple[int, int], grid: tuple[int, int]) -> None:
    rng = np.random.default_rng(46)
    image = (rng.random((size[1], size[0], 3)) * 4 - 1).astype(np.float32)
    assert _photosite_kernel.enlarge_reference(image, *grid).tobytes() == cv2.resize(image, grid, interpolation=cv2.INTER_AREA).tobytes()
    big = rng.standard_normal((grid[1], grid[0], 3)).astype(np.float32)
    assert _photosite_kernel.shrink_reference(big, *size).tobytes() == cv2.resize(big, size, interpolation=cv2.INTER_AREA).tobytes()


@needs_agreeing_opencv
@pytest.mark.parametrize(("size", "grid"), SIZES)
@pytest.mark.parametrize(("read_model", "brightness"), [(READ_GAUSSIAN, 0.004), (READ_GAUSSIAN, 0.6), (READ_TUKEY, 0.01)])
def test_binned_noise_is_the_opencv_path_bit_for_bit(size: tuple[int, int], grid: tuple[int, int], read_model: int, brightness: float) -> None:
    """Dark (table draws), bright (PTRS and the normal approximation: rates up to 6000 electrons) and Tukey read
    noise (every value by the scalar path); the same bytes whatever the chunks of rows."""
    signal = (np.random.default_rng(48).random((size[1], size[0], 3)) ** 2 * brightness).astype(np.float32)
    sensor = {**SENSOR, "read_model": read_model, "read_lambda": -0.2 if read_model == READ_TUKEY else 0.14}
    expected = _through_opencv(signal, grid, 77, **sensor)
    assert _photosite_kernel.binned_noise(signal, grid, key=77, **sensor).tobytes() == expected.tobytes()
    for chunks in (1, 3, size[1]):
        assert _photosite_kernel.binned_noise(signal, grid, key=77, chunks=chunks, **sensor).tobytes() == expected.tobytes()


@needs_agreeing_opencv
def test_the_capture_takes_the_kernel_where_it_fits_with_the_same_bytes(monkeypatch: pytest.MonkeyPatch) -> None:
    """``binned_capture`` at the presets' pitch for 64 × 48 (sites smaller than pixels) goes through the kernel and gives
    what the two resamples give; where OpenCV takes other paths the kernel is not used."""
    rgb = (np.random.default_rng(54).random((48, 64, 3)) * 0.8).astype(np.float32)
    pitch = 48 / 1168
    grid = _photosites.photosite_grid(64, 48, pitch)
    assert _photosite_kernel.fits(64, 48, grid)
    # OpenCV's other paths: a grid not larger along both axes, an integer ratio along both (its fast area sums)
    assert not _photosite_kernel.fits(64, 48, (64, 100)) and not _photosite_kernel.fits(64, 48, (32, 24))
    assert not _photosite_kernel.fits(64, 48, (128, 96)) and not _photosite_kernel.fits(64, 48, (192, 144))
    assert _photosite_kernel.fits(64, 48, (128, 97))
    calls: list[tuple[int, int]] = []
    original = _photosite_kernel.binned_noise

    def counted(signal: np.ndarray, grid: tuple[int, int], **kwargs: object) -> np.ndarray:
        calls.append(grid)
        return original(signal, grid, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(_photosite_kernel, "binned_noise", counted)
    fused = _photosites.binned_capture(rgb, pitch=pitch, exposure=0.004, clip=False, key=5, **SENSOR)
    assert calls == [grid]
    monkeypatch.setattr(_photosite_kernel, "fits", lambda *args: False)
    assert _photosites.binned_capture(rgb, pitch=pitch, exposure=0.004, clip=False, key=5, **SENSOR).tobytes() == fused.tobytes()
    assert calls == [grid]


def test_an_opencv_that_computes_otherwise_keeps_its_own_resamples(monkeypatch: pytest.MonkeyPatch) -> None:
    """Where this process's OpenCV does not give the kernel's bytes (a fused build), nothing fits: the photosites take
    the two ``cv2.resize`` calls."""
    grid = _photosites.photosite_grid(64, 48, 48 / 1168)
    monkeypatch.setattr(_photosite_kernel, "opencv_agrees", lambda: False)
    assert not _photosite_kernel.fits(64, 48, grid)
    called: list[object] = []
    monkeypatch.setattr(_photosite_kernel, "binned_noise", lambda *args, **kwargs: called.append(args))
    rgb = (np.random.default_rng(12).random((48, 64, 3)) * 0.8).astype(np.float32)
    out = _photosites.binned_capture(rgb, pitch=48 / 1168, exposure=0.004, clip=False, key=5, **SENSOR)
    assert not called and np.isfinite(out).all()


@needs_agreeing_opencv
def test_binned_noise_refuses_what_it_does_not_reproduce() -> None:
    signal = np.zeros((48, 64, 3), np.float32)
    with pytest.raises(InvalidDataError, match="larger than it along both axes"):
        _photosite_kernel.binned_noise(signal, (128, 96), key=1, **SENSOR)
    with pytest.raises(InvalidDataError, match="float32"):
        _photosite_kernel.binned_noise(signal.astype(np.float64), (150, 117), key=1, **SENSOR)
    for bad in ({"k": -1e-4}, {"sigma_read": math.nan}, {"read_model": 2}, {"key": 2**64}):
        with pytest.raises(InvalidDataError, match="k must|sigma_read must|read_model must|key must"):
            _photosite_kernel.binned_noise(signal, (150, 117), **{"key": 1, **SENSOR, **bad})  # type: ignore[arg-type]
    for out in (np.empty((48, 63, 3), np.float32), np.empty((48, 64, 3), np.float64), signal):
        with pytest.raises(InvalidDataError, match="out must be a writeable C-contiguous float32 array"):
            _photosite_kernel.binned_noise(signal, (150, 117), key=1, out=out, **SENSOR)

"""The sensor's noise drawn per photosite of a fixed pitch, then averaged over each pixel (not a plugin).

Why: photon shot noise and read noise belong to the sensor's photosites, not to the pixels of
whatever size the image is rendered at. The photometric presets describe a sensor with one
photosite per pixel of the reference image (:data:`~spacedg.plugins.specs.REFERENCE_IMAGE_SIZE`,
1752 × 1168): its ``pitch`` parameter is the photosite side in output pixels, 1 px at the
reference and scaled with the image (``ParamRange(per_size=True)``). A 640 × 360 image then
sees each pixel average ≈ 10.5 photosites (noise std ÷ 3.2, as binning would give), and a
1920 × 1080 image area-downsampled to 640 × 360 carries the *same* noise as a 640 × 360 image
rendered directly: both draw it on the same photosite grid with the same counter-based keys.

Model (``pitch ≠ 1``), with ``s = e·x`` the exposed linear light of the output (NaN → 0, ±inf
and beyond ±:data:`~._sensor.SIGNAL_CAP` clamped, as in :mod:`._sensor`):

1. the photosite grid has ``round(side / pitch)`` sites per side of the image's
   :func:`~.common.snapped_size` (a side within a pixel of a common aspect is taken at that
   aspect), so the sizes of one view share one grid whatever their rounding;
2. each site's signal ``s_g`` is ``s`` area-resampled onto the grid (:func:`cv2.resize`,
   ``INTER_AREA``: the box average where sites are larger than pixels, the overlapping pixel's
   value where they are smaller);
3. each site is captured by :func:`~._sensor.sensor_capture` (exact Poisson photons, read
   noise; the key's counters run over the grid's values), giving its noise ``n_g = y_g − s_g``;
4. the output is ``s + A(n)`` with ``A`` the area resampling back to (W, H), then the clip to
   [0, 1] when the degradation clips (over-exposure): the signal itself is never resampled.

Cost: the sensor draws every photosite (over-exposure: every one a pixel that may not saturate
reads, see below), about the reference's 2–3 M (× 3 channels) whatever the output size below
it: at 640 × 360 about 10 × the pixels, so about 10 × the sensor's time of a per-pixel draw
(at 640 × 480, 1557 × 1168 sites × 3, about 23–31 ms a view on two threads at low light's bench
preset, more than a clean render; ``benchmarks/dataset.py`` shows it per sample); at or above the
reference, about the pixel count. Over-exposure's presets draw per pixel instead (``per_pixel``
below; :mod:`.over_exposure` says why). Where sites are smaller than pixels and nothing is skipped
(low light), steps 2–4 run in one pass per row of sites (:mod:`._photosite_kernel`, the same bytes as
the two ``cv2.resize`` calls and the draw): the grid's signal and noise never exist as arrays, which
saved ~6 ms of a 640 × 480 view's ~50 (two threads; 11 of ~76 on one).

Skipped work (the same bytes): with the clip (over-exposure) and sites no larger than pixels, a
pixel whose signal stays ≥ 1 after the largest drop any draw of the sites around it can give
(:func:`~._sensor.largest_drop` of the highest signal within 2 px) is 1.0 whatever is drawn. Sites
that only such pixels read (none within 2 px of a pixel that might not saturate) are not drawn:
about half the sites of the built-in rooms at the bench preset.

One draw per pixel instead (``per_pixel = 1``, :func:`pixel_binning`; over-exposure's presets): where sites
are smaller than pixels, the sensor at gain ``k·q`` and read noise ``σ·√q``, ``q`` the mean share of
one site's noise variance that a pixel's area weights keep. Each pixel's noise then has the
photosites' mean and variance (tested on flat patches within 2 %), its photon count that of the
``1/q`` sites it bins, at one draw per value (about 10 × fewer at 640 × 360). Given up: the same
noise at every output size of the view, and the correlation of neighbouring pixels that share a
site. Where sites are no smaller than pixels it is the photosites, bit for bit.

Approximations, stated: the signal-dependence of the noise is taken at the site's average light
(within a pixel the light is constant, so this is exact whenever sites are smaller than pixels);
saturation is applied to the binned value, not per site. ``pitch = 1`` is
:func:`~._sensor.sensor_capture` itself, bit for bit (the reference size, and every plain call).
"""

from __future__ import annotations

import functools
import math
import threading
from collections.abc import Mapping
from typing import Any

import numba
import numpy as np

from spacedg.errors import ParameterError
from spacedg.plugins.degradations._sensor import SIGNAL_CAP, largest_drop, sensor_capture
from spacedg.plugins.degradations.common import snapped_size
from spacedg.render import kernel_cache
from spacedg.render.threads import fork_safe

__all__ = ["MAX_PHOTOSITES", "photosite_grid", "binned_capture", "pixel_binning", "pixel_sensor"]

#: Most photosites one capture may draw (a far smaller pitch than any preset gives is refused).
MAX_PHOTOSITES = 64_000_000


def photosite_grid(width: int, height: int, pitch: float) -> tuple[int, int]:
    """``(columns, rows)`` of photosites of side ``pitch`` output pixels over a ``width × height``
    image: ``round(side / pitch)`` of each side as :func:`~.common.snapped_size` has it (so every size
    of one view shares one grid; an exact aspect keeps the image's own sides). A grid of more than
    :data:`MAX_PHOTOSITES` sites is refused: it is drawn."""
    grid = _grid_shape(width, height, pitch)
    if grid[0] * grid[1] > MAX_PHOTOSITES:
        raise ParameterError(
            f"sensor: pitch {pitch:g} px on a {width}×{height} image needs {grid[0]}×{grid[1]} photosites, more than "
            f"{MAX_PHOTOSITES:.0e}; use a larger pitch (the presets give 1 px at 1752×1168, scaled with the image)"
        )
    return grid


def _grid_shape(width: int, height: int, pitch: float) -> tuple[int, int]:
    """:func:`photosite_grid`'s ``(columns, rows)`` without its limit (a grid that is only measured)."""
    if not (math.isfinite(pitch) and pitch > 0):
        raise ParameterError(f"sensor: pitch must be a finite number of pixels > 0, got {pitch!r}")
    snapped_w, snapped_h = snapped_size(width, height)
    return max(1, int(round(snapped_w / pitch))), max(1, int(round(snapped_h / pitch)))


@functools.lru_cache(maxsize=64)
def pixel_binning(width: int, height: int, pitch: float) -> float | None:
    """``q``, the photosite model's noise variance per pixel as a fraction of one photosite's, where a
    per-pixel draw can stand in for the photosites (``per_pixel = 1``): sites smaller than pixels on
    both axes (``None`` otherwise, also for ``pitch = 1``'s exact pixel grid).

    The photosite model's noise at a pixel is ``Σⱼ wⱼ nⱼ`` over the sites ``j`` it overlaps (``wⱼ`` the
    share of the pixel's area, OpenCV's area weights, separable), so its variance is
    ``Σⱼ wⱼ² · v`` for a site variance ``v`` (``k·s + σ²`` at signal ``s``). ``q`` is the mean of
    ``Σⱼ wⱼ²`` over the image's pixels (the product of the two axes' means): about ``pitch²`` (the
    share of one whole site), less where a pixel's edge cuts a site (a 640 × 480 image on the
    1752 × 1314 grid: 0.103 against ``pitch²`` = 0.133; the same as OpenCV's own weights, tested).
    No site is drawn, so a grid past :data:`MAX_PHOTOSITES` is measured too. Kept for the last 64 (size, pitch)
    (every view of a size asks the same).
    """
    grid = _grid_shape(width, height, pitch)
    if grid == (width, height) or grid[0] < width or grid[1] < height:
        return None
    return _axis_binning(grid[0], width) * _axis_binning(grid[1], height)


def _axis_binning(sites: int, pixels: int) -> float:
    """Mean over ``pixels`` equal pixels on ``sites ≥ pixels`` equal sites of one axis of ``Σⱼ wⱼ²``,
    ``wⱼ`` the share of the pixel that site ``j`` covers (its overlap ÷ the pixel's length)."""
    span = sites / pixels  # sites per pixel, ≥ 1
    start = np.arange(pixels, dtype=np.float64) * span
    end = start + span
    first, last = np.ceil(start), np.floor(end)  # the whole sites inside: [first, last)
    squares = np.where(first <= last, (last - first) + (first - start) ** 2 + (end - last) ** 2, (end - start) ** 2)
    return float(squares.mean() / (span * span))


def binned_capture(
    rgb: np.ndarray, *, pitch: float, exposure: float, clip: bool, key: int, skip_saturated: bool = True, per_pixel: bool = False,
    **sensor: float | int,
) -> np.ndarray:
    """Expose ``rgb`` (float32 (H, W, 3) linear light) by ``exposure`` with the noise of photosites
    of side ``pitch`` px (module docstring); ``sensor`` = ``k, sigma_read, read_model, read_lambda``.
    ``skip_saturated=False`` draws every site even where the clip makes it irrelevant (the same
    bytes; for tests and benchmarks).

    ``per_pixel``: where sites are smaller than pixels (:func:`pixel_binning`), draw the noise once
    per pixel with the photosites' statistics instead: the sensor at gain ``k·q`` and read noise
    ``σ·√q`` (the mean and variance per pixel of the photosite model, its photon count that of the
    ``1/q`` sites a pixel bins), one draw per value instead of about ``1/pitch²``. Not the same
    realisation: another output size of the view gets other noise. Elsewhere the photosites.

    Returns a new float32 array, always finite.
    """
    if pitch == 1.0:
        return sensor_capture(rgb, exposure=exposure, key=key, clip=clip, **sensor)  # type: ignore[arg-type]
    height, width = rgb.shape[:2]
    per_pixel_sensor = pixel_sensor(sensor, width, height, pitch) if per_pixel else None
    if per_pixel_sensor is not None:
        return sensor_capture(rgb, exposure=exposure, key=key, clip=clip, **per_pixel_sensor)  # type: ignore[arg-type]
    import cv2  # here: importing the plugin stays light (the entry point's import is timed)

    from spacedg.plugins.degradations import _photosite_kernel

    grid = photosite_grid(width, height, pitch)
    signal = np.empty(rgb.shape, np.float32)  # worked on in place below
    _exposed(kernel_cache.read_only(np.ascontiguousarray(rgb, dtype=np.float32)).reshape(-1), np.float32(exposure), signal.reshape(-1))
    resampled = grid != (width, height)
    unread = None
    if clip and skip_saturated and grid[0] >= width and grid[1] >= height:
        unread = _sites_of_saturated_pixels(signal, grid, sensor)
    if unread is None and _photosite_kernel.fits(width, height, grid):
        # the two resamples and the draw in one pass per row of sites, without the grid's arrays: the same bytes
        noise = _photosite_kernel.binned_noise(signal, grid, key=key, out=_workspace("binned", signal.shape), **sensor)  # type: ignore[arg-type]
    else:
        sites = cv2.resize(signal, grid, dst=_workspace("sites", (grid[1], grid[0], 3)), interpolation=cv2.INTER_AREA) if resampled else signal
        noise = sensor_capture(
            sites, exposure=1.0, key=key, skip=unread, noise=True, out=_workspace("noise", sites.shape), **sensor,  # type: ignore[arg-type]
        )
        if resampled:
            noise = cv2.resize(noise, (width, height), dst=_workspace("binned", signal.shape), interpolation=cv2.INTER_AREA)
    signal += noise.reshape(signal.shape)
    if clip:
        np.clip(signal, 0.0, 1.0, out=signal)
    return signal


_WORKSPACES = threading.local()


def _workspace(name: str, shape: tuple[int, ...]) -> np.ndarray:
    """A float32 scratch array of ``shape`` kept per thread under ``name`` and reused while the shape stays
    (its contents are whatever the last use left): the photosite grid's signal and noise (~22 MB each at
    640 × 480) and the binned noise. Fresh arrays of that size cost more in page faults than in
    arithmetic: a low-light sample spent ~20 % of its time in the kernel's first touch of them
    (``getrusage``: 4,100 minor faults and 28 ms of system time a sample against 2,200 and 6 ms clean;
    with them 2,100 and 8 ms). Kept until the thread ends or another shape replaces it: the binned noise (3.7 MB at
    640 × 480), and ~44 MB more a thread that took the two resamples (grid signal and noise, 1557 × 1168 × 3
    float32 each; not low light's one-pass kernel).
    Never returned: the capture's result is a new array."""
    arrays = getattr(_WORKSPACES, "arrays", None)
    if arrays is None:
        arrays = _WORKSPACES.arrays = {}
    array = arrays.get(name)
    if array is None or array.shape != shape:
        array = arrays[name] = np.empty(shape, np.float32)
    return array


#: :data:`~._sensor.SIGNAL_CAP` in float32 (what numpy compares a float32 array with).
_CAP32 = np.float32(SIGNAL_CAP)


@fork_safe
@numba.njit(parallel=True, cache=True, fastmath=False)
def _exposed(rgb: np.ndarray, exposure: np.float32, out: np.ndarray) -> None:  # pragma: no cover - compiled
    """``out = clip(nan_to_num(rgb, nan=0, ±inf → ±cap) · exposure, −cap, cap)`` over flat float32 arrays,
    ``cap`` = :data:`_CAP32`: the float32 operations of those numpy steps (a NaN is 0, ±inf the cap, one
    float32 product, the clamp), in one pass instead of four and their temporaries."""
    for i in numba.prange(rgb.shape[0]):
        v = rgb[i]
        v = np.float32(0.0) if v != v else v
        v = _CAP32 if v == np.inf else (-_CAP32 if v == -np.inf else v)
        out[i] = min(max(v * exposure, -_CAP32), _CAP32)


def pixel_sensor(sensor: Mapping[str, Any], width: int, height: int, pitch: float) -> dict[str, Any] | None:
    """``sensor`` (any mapping with ``k`` and ``sigma_read``) for one draw per pixel of a ``width × height``
    image standing in for photosites of side ``pitch`` px (``per_pixel = 1``): ``k·q`` and ``σ·√q``,
    ``q`` = :func:`pixel_binning`; ``None`` where ``per_pixel`` changes nothing (``pitch = 1``, or
    sites no smaller than pixels: the photosites are drawn)."""
    binning = None if pitch == 1.0 else pixel_binning(width, height, pitch)
    if binning is None:
        return None
    return {**sensor, "k": float(sensor["k"]) * binning, "sigma_read": float(sensor["sigma_read"]) * math.sqrt(binning)}


#: Relative and absolute slack of the saturation test: far above float32 rounding of the resampling sums.
_SATURATION_SLACK = (1e-5, 1e-4)


def _sites_of_saturated_pixels(signal: np.ndarray, grid: tuple[int, int], sensor: dict[str, float | int]) -> np.ndarray | None:
    """uint8 (rows, columns, 3) over the photosite grid, 1 where only pixels that saturate whatever is
    drawn read the site (or ``None`` when no site is skipped). Sites are no larger than pixels here.

    A pixel ``p`` reads the sites overlapping it; each site's signal is a convex mix of the pixels
    next to the one holding its corner (OpenCV's area resampling both ways: the corner's pixel and
    the next), so within 2 px of ``p``. Its noise is at least ``−largest_drop(M)`` with ``M`` the
    highest signal within 2 px (5 × 5 maximum; float32 rounding of a site's capture and noise adds
    at most 2⁻²³·M), and the area average of the noise at least the same, so
    ``s − largest_drop(M) − 2⁻²²·M > 1`` (with slack) clips to 1.0. A site overlaps the pixel its
    corner maps to and the next one: it is skipped when every pixel within 2 px of that one
    saturates (a pixel of margin against the resamplers' rounding, both ways).
    """
    import cv2

    relative, absolute = _SATURATION_SLACK
    bar = np.float32(1.0 + absolute)
    top = float(signal.max()) if signal.size else 0.0
    if top * (1.0 - relative) <= bar + float(largest_drop(np.float32(0.0), **sensor)):  # type: ignore[arg-type]
        return None  # no pixel is bright enough to be sure (a dark view: low light, most of over-exposure's range)
    box = np.ones((5, 5), np.uint8)
    highest = cv2.dilate(signal, box, borderType=cv2.BORDER_REPLICATE)
    floor = largest_drop(highest, **sensor)  # type: ignore[arg-type]
    highest *= np.float32(2.0**-22)  # the captures' float32 rounding, at the brightest neighbour's scale
    floor += highest
    floor += bar
    sure = (signal * np.float32(1.0 - relative) > floor).view(np.uint8)
    if not sure.any():
        return None
    all_sure = cv2.erode(sure, box, borderType=cv2.BORDER_REPLICATE)  # every pixel within 2 px saturates
    return cv2.resize(all_sure, grid, interpolation=cv2.INTER_NEAREST) if all_sure.any() else None

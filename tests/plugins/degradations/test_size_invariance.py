"""Presets independent of the image size, and inside the paper's parameter table.

Pixel parameters are stated at the reference image size (1752 × 1168, a ScanNet++ DSLR frame)
and scale with the output (``ParamRange(per_size=...)``); random fields are drawn in normalised
coordinates. So degrading a 128 × 96 image and area-downsampling it to 64 × 48 gives what
degrading its 64 × 48 area-downsample gives (benchmarks/resolution.py: 1920 × 1080 vs 640 × 360).
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import cv2
import numpy as np
import pytest

from spacedg.data.chain import BENCH_DEGRADATIONS, Chain, ResolvedDegradation
from spacedg.data.pipeline import degrade_image
from spacedg.errors import ParameterError, PluginError
from spacedg.plugins import DegradationSpec, ParamRange, ParamSpec, get_degradation
from spacedg.plugins.degradations._photosites import photosite_grid, pixel_binning
from spacedg.plugins.degradations._sensor import K_DEFAULT, SIGMA_READ_DEFAULT
from spacedg.plugins.degradations.common import view_aspect
from spacedg.plugins.degradations.low_light import low_light
from spacedg.plugins.degradations.over_exposure import over_expose
from spacedg.plugins.degradations.paper_table import PAPER_PARAMETER_TABLE, outside_paper_table
from spacedg.plugins.specs import REFERENCE_DEPTH_M, REFERENCE_IMAGE_SIZE, image_scale, scale_pixels

PAPER_TABLE_TEX = Path(__file__).parent / "data" / "paper_param_table.tex"


def _read_paper_table(text: str) -> dict[str, dict[str, tuple[float, float]]]:
    """The rows of the paper's LaTeX table: ``name & p $\\in [a,\\,b]$, q $= v$ \\\\``."""
    table: dict[str, dict[str, tuple[float, float]]] = {}
    body = text.split(r"\midrule", 1)[1].split(r"\bottomrule", 1)[0]
    for row in body.split(r"\\"):
        if "&" not in row:
            continue
        name, ranges = (part.strip() for part in row.split("&", 1))
        params = {}
        for param, low, high, fixed in re.findall(r"([a-z_\\0-9]+) \$(?:\\in \[([-0-9.]+),\\,([-0-9.]+)\]|= ([-0-9.]+))\$", ranges):
            params[param.replace("\\_", "_")] = (float(fixed), float(fixed)) if fixed else (float(low), float(high))
        table[name.replace("\\_", "_")] = params
    return table


def test_the_encoded_table_is_the_papers() -> None:
    published = _read_paper_table(PAPER_TABLE_TEX.read_text())
    assert set(published) == set(BENCH_DEGRADATIONS)
    assert published == {name: dict(params) for name, params in PAPER_PARAMETER_TABLE.items()}


@pytest.mark.parametrize("name", BENCH_DEGRADATIONS)
def test_bench_presets_stay_inside_the_paper_table(name: str) -> None:
    spec = get_degradation(name)
    assert outside_paper_table(spec) == []
    for seed in range(5):  # at the reference depth and size the scale-aware ranges are the written ones
        drawn = spec.sample_params("bench", np.random.default_rng(seed), REFERENCE_DEPTH_M, REFERENCE_IMAGE_SIZE)
        assert drawn == spec.sample_params("bench", np.random.default_rng(seed))
        for param, (low, high) in PAPER_PARAMETER_TABLE[name].items():
            assert low <= drawn[param] <= high


def test_a_preset_outside_the_table_is_reported() -> None:
    spec = get_degradation("water_droplets")
    wide = DegradationSpec(
        name="water_droplets", category=spec.category, stage=spec.stage, params=spec.params, apply=spec.apply,
        presets={**spec.presets, "bench": {**spec.presets["bench"], "blur_sigma": ParamRange(2.0, 3.0)}},
    )
    assert outside_paper_table(wide) == ["water_droplets.blur_sigma: 'bench' gives [2, 3], outside the paper's [2, 2.5]"]


def test_image_scale_and_pixel_scaling() -> None:
    assert REFERENCE_IMAGE_SIZE == (1752, 1168) and image_scale(1752, 1168) == 1.0
    assert image_scale(1920, 1080) == pytest.approx(3 * image_scale(640, 360)) and image_scale(480, 640) == 480 / 1168
    assert scale_pixels(2.0, 0.5) == 1.0 and scale_pixels(0.02, 0.5, power=-1) == 0.04
    assert [scale_pixels(9, s, integer=True) for s in (1.0, 0.925, 0.308, 0.05, 2.0)] == [9, 9, 3, 1, 17]  # odd stays odd
    with pytest.raises(PluginError, match="only a parameter in pixels"):
        DegradationSpec(
            name="bad_size", category="digital", stage="display", params=(ParamSpec("q", "1", "quality", low=0, high=100),),
            presets={p: {"q": ParamRange(1, 2, per_size=True)} for p in ("bench", "1", "2", "3", "4", "5")},
            apply=lambda image, params, rng: image,
        )


def test_provenance_records_the_pixels_used_and_the_size() -> None:
    chain = Chain.parse("water_droplets+low_light+low_res+haze")
    at_ref = {p["name"]: p for p in chain.provenance(4, image_size=REFERENCE_IMAGE_SIZE)}
    small = {p["name"]: p for p in chain.provenance(4, image_size=(640, 360))}
    s = 360 / 1168
    assert "image_size" not in small["haze"] and small["low_light"]["image_size"] == [640, 360]
    assert small["water_droplets"]["params"]["blur_sigma"] == pytest.approx(at_ref["water_droplets"]["params"]["blur_sigma"] * s)
    assert (at_ref["water_droplets"]["params"]["blur_kernel"], small["water_droplets"]["params"]["blur_kernel"]) == (9, 3)
    assert small["low_light"]["params"]["pitch"] == pytest.approx(s) and at_ref["low_light"]["params"]["pitch"] == 1.0
    assert small["low_res"]["params"]["scale"] == pytest.approx(at_ref["low_res"]["params"]["scale"] / s)
    assert ResolvedDegradation.from_provenance(small["low_light"]).provenance() == small["low_light"]
    old = {k: v for k, v in small["low_light"].items() if k != "image_size"}  # recorded before pitch existed
    old["params"] = {k: v for k, v in old["params"].items() if k != "pitch"}
    assert ResolvedDegradation.from_provenance(old).params["pitch"] == 1.0
    explicit = {p["name"]: p for p in Chain.parse("water_droplets:bench(blur_sigma=2.0)").provenance(4, image_size=(640, 360))}
    assert explicit["water_droplets"]["params"]["blur_sigma"] == 2.0  # explicit pixels are the output's


def test_sensor_noise_is_drawn_on_photosites() -> None:
    flat = np.full((48, 64, 3), 0.25, np.float32)
    per_pixel = low_light(flat, 0.5, key=9)
    binned = low_light(flat, 0.5, key=9, pitch=0.5)  # 2 × 2 photosites per pixel: variance / 4
    assert photosite_grid(64, 48, 0.5) == (128, 96)
    assert binned.mean() == pytest.approx(per_pixel.mean(), rel=0.01)
    assert binned.var() == pytest.approx(per_pixel.var() / 4, rel=0.15)
    big = np.full((96, 128, 3), 0.25, np.float32)
    down = cv2.resize(low_light(big, 0.5, key=9, pitch=1.0), (64, 48), interpolation=cv2.INTER_AREA)
    assert np.abs(down - binned).max() < 1e-6  # the same photosites at both sizes: the same noise


def _area_weights(sites: int, pixels: int) -> np.ndarray:
    """(sites, pixels) float64: OpenCV's INTER_AREA weight of each site in each pixel (the resampling the photosites use)."""
    return cv2.resize(np.eye(sites, dtype=np.float32), (pixels, sites), interpolation=cv2.INTER_AREA).astype(np.float64)


def test_pixel_binning_is_the_variance_share_of_opencvs_area_weights() -> None:
    for width, height in ((640, 480), (584, 389), (700, 360), (97, 61)):
        pitch = min(width / 1752, height / 1168)
        columns, rows = photosite_grid(width, height, pitch)
        shares = []
        for sites, pixels in ((columns, width), (rows, height)):
            weights = _area_weights(sites, pixels)
            np.testing.assert_allclose(weights.sum(axis=0), 1.0, atol=1e-5)  # a pixel's weights are its area shares
            shares.append((weights**2).sum(axis=0).mean())
        assert pixel_binning(width, height, pitch) == pytest.approx(shares[0] * shares[1], rel=1e-6), (width, height)
        assert pixel_binning(width, height, pitch) < pitch**2  # a pixel edge that cuts a site spreads its noise
    assert pixel_binning(64, 48, 0.5) == pytest.approx(0.25)  # 2 × 2 whole sites a pixel: a quarter
    assert pixel_binning(64, 48, 1.0) is None and pixel_binning(64, 48, 1.5) is None  # sites no smaller than pixels


@pytest.mark.parametrize("name", ["low_light", "over_exposure"])
def test_per_pixel_noise_has_the_photosites_mean_and_variance(name: str) -> None:
    """One draw per pixel (``per_pixel = 1``) against the photosites it stands in for, on a flat patch
    (sites not aligned with pixels): the same mean, and the variance both have, ``q·(k·s + σ²)``."""
    flat = np.full((150, 200, 3), 0.3, np.float32)
    pitch = 0.3  # a 667 × 500 grid: 3.3 sites a pixel per side
    capture, exposure, gain = (low_light, 0.004, 25.0) if name == "low_light" else (over_expose, 1.6, 1.0)
    extra = {"gain": gain} if name == "low_light" else {}
    sites = capture(flat, exposure, key=21, pitch=pitch, **extra)
    pixels = capture(flat, exposure, key=21, pitch=pitch, per_pixel=1, **extra)
    signal = 0.3 * exposure
    expected = pixel_binning(200, 150, pitch) * (K_DEFAULT * signal + SIGMA_READ_DEFAULT**2) * gain**2
    for out in (sites, pixels):
        assert np.isfinite(out).all()
        assert out.mean() == pytest.approx(signal * gain, rel=0.005)
        assert out.var() == pytest.approx(expected, rel=0.02)
    assert pixels.var() == pytest.approx(sites.var(), rel=0.02)
    assert not np.array_equal(sites, pixels)


def test_per_pixel_changes_nothing_where_sites_are_no_smaller_than_pixels() -> None:
    image = np.random.default_rng(4).uniform(0.0, 1.0, (48, 64, 3)).astype(np.float32)
    for pitch in (1.0, 1.5):
        assert low_light(image, 0.01, key=3, pitch=pitch, per_pixel=1).tobytes() == low_light(image, 0.01, key=3, pitch=pitch).tobytes()
    with pytest.raises(ParameterError, match="per_pixel"):
        low_light(image, 0.01, key=3, pitch=0.5, per_pixel=2)


def test_a_grid_too_large_to_draw_is_refused_but_per_pixel_only_measures_it() -> None:
    """A pitch whose photosite grid passes MAX_PHOTOSITES is refused by name with what to do; ``per_pixel = 1``
    draws no site, so it only measures that grid and captures (finite, the per-pixel statistics)."""
    from spacedg.plugins.degradations._photosites import MAX_PHOTOSITES

    flat = np.full((48, 64, 3), 0.3, np.float32)
    pitch = 0.005  # 12800 × 9600 sites: 1.2e8 > MAX_PHOTOSITES
    assert 12800 * 9600 > MAX_PHOTOSITES
    with pytest.raises(ParameterError, match=r"pitch 0\.005 px on a 64×48 image needs 12800×9600 photosites.*use a larger pitch"):
        low_light(flat, 0.004, key=7, pitch=pitch)
    assert pixel_binning(64, 48, pitch) == pytest.approx(pitch**2, rel=1e-9)  # 200 whole sites a pixel per side
    out = low_light(flat, 0.004, key=7, pitch=pitch, per_pixel=1, gain=25.0)
    assert np.isfinite(out).all() and out.mean() == pytest.approx(0.3 * 0.004 * 25.0, rel=0.005)
    expected = pitch**2 * (K_DEFAULT * 0.3 * 0.004 + SIGMA_READ_DEFAULT**2) * 25.0**2
    assert out.var() == pytest.approx(expected, rel=0.05)


def test_every_size_of_one_view_shares_one_photosite_grid() -> None:
    # a 3:2 view (the reference 1752 × 1168) fitted to other sizes is 3:2 up to a pixel of rounding:
    # its grid is the reference's, so the same sites (and noise) land on every size
    for width, height in ((1752, 1168), (584, 389), (640, 427), (876, 584), (1168, 779)):
        assert photosite_grid(width, height, height / 1168) == (1752, 1168), (width, height)
    assert photosite_grid(389, 584, 389 / 1168) == (1168, 1752)  # portrait
    assert photosite_grid(640, 360, 360 / 1168) == photosite_grid(1920, 1080, 1080 / 1168) == (2076, 1168)
    assert photosite_grid(700, 360, 360 / 1168) == (2271, 1168)  # no common ratio within a pixel: its own
    assert photosite_grid(1752, 1168, 2.5) == (701, 467)  # an exact aspect keeps its own side at any pitch
    assert view_aspect(16, 10) == 1.6 and view_aspect(5, 4) == 1.25  # the nearest ratio, an exact one itself


def test_every_size_of_one_view_draws_the_same_drops() -> None:
    from spacedg.plugins.degradations.water_droplets import _draw_drops

    big = _draw_drops((1168, 1752), 3.0, 0.5, np.random.default_rng(4))
    small = _draw_drops((389, 584), 3.0, 0.5, np.random.default_rng(4))
    for layer in range(3):
        assert (big[1][layer], big[2][layer]) == (small[1][layer], small[2][layer])  # columns and rows of cells
    np.testing.assert_allclose(small[6] / 389, big[6] / 1168, rtol=1e-9)  # radii, as fractions of the short side
    np.testing.assert_allclose(small[4] / 584, big[4] / 1752, rtol=1e-3)  # centres, as fractions of the image (the jitter
    np.testing.assert_allclose(small[5] / 389, big[5] / 1168, rtol=1e-9)  # keeps radii in short-side pixels: 0.09 % in x)


def _textured(width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """A smooth sRGB picture and a depth ramp (metres), defined in normalised coordinates."""
    y, x = np.mgrid[0:height, 0:width] / float(height)
    rgb = np.stack([0.5 + 0.4 * np.sin(6 * x + 1), 0.5 + 0.4 * np.cos(5 * y), 0.5 + 0.3 * np.sin(4 * (x + y))], -1)
    return np.round(255 * rgb).astype(np.uint8), (1.0 + 2.0 * x + 0.5 * y).astype(np.float32)


def _psnr(a: np.ndarray, b: np.ndarray) -> float:
    mse = float(np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2))
    return math.inf if mse == 0 else 10 * math.log10(255**2 / mse)


#: Lowest PSNR (dB) at 128 × 96 → 64 × 48 over severities and seeds. Drops: their rims, highlights
#: and the refracted scene behind them are point-sampled per pixel, and a drop is ~3 px wide at
#: 64 × 48 (measured 24.7 dB); at 1920 × 1080 → 640 × 360 they hold 41–44 dB (benchmarks/resolution.py).
_FLOOR_DB = {"haze": 45.0, "low_light": 45.0, "over_exposure": 45.0, "low_res": 45.0, "water_droplets": 23.0}


@pytest.mark.parametrize("name", sorted(_FLOOR_DB))
def test_post_render_degradations_do_not_depend_on_the_image_size(name: str) -> None:
    high, depth_high = _textured(128, 96)
    low, depth_low = (cv2.resize(a, (64, 48), interpolation=cv2.INTER_AREA) for a in (high, depth_high))
    worst = math.inf
    cases = (("bench", 0),) if name in ("low_light", "over_exposure") else (("bench", 0), ("1", 1), ("3", 2))  # a sensor call draws ~5M photosites
    for severity, seed in cases:
        a, _ = degrade_image(high, f"{name}:{severity}", seed, depth=depth_high)
        b, _ = degrade_image(low, f"{name}:{severity}", seed, depth=depth_low)
        worst = min(worst, _psnr(cv2.resize(a, (64, 48), interpolation=cv2.INTER_AREA), b))
    assert worst >= _FLOOR_DB[name]

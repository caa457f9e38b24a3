"""Built-in ``low_light`` and ``over_exposure`` degradations and their shared sensor model."""

from __future__ import annotations

import math

import numba
import numpy as np
import pytest

from spacedg.errors import InvalidDataError, ParameterError
from spacedg.plugins import Category, Stage
from spacedg.plugins.degradations import low_light as low_light_module
from spacedg.plugins.degradations import over_exposure as over_exposure_module
from spacedg.plugins.degradations.common import stream_key
from spacedg.plugins.degradations import _sensor
from spacedg.plugins.degradations._sensor import READ_TUKEY, SIGNAL_CAP, sensor_capture, tukey_lambda_std
from spacedg.plugins.degradations.low_light import SPEC as LOW_LIGHT
from spacedg.plugins.degradations.low_light import low_light
from spacedg.plugins.degradations.over_exposure import SPEC as OVER_EXPOSURE
from spacedg.plugins.degradations.over_exposure import over_expose
from spacedg.render import kernel_cache
from spacedg.render.colour import linear_to_srgb

SPECS = [LOW_LIGHT, OVER_EXPOSURE]
K, SIGMA = 1e-4, 2.5e-4  # the default sensor


def _textured(height: int = 64, width: int = 96) -> np.ndarray:
    """Deterministic linear-light image with gradients, texture and a few HDR highlights (> 1)."""
    y, x = np.mgrid[0:height, 0:width].astype(np.float64)
    base = np.stack([x / width, y / height, 0.5 + 0.4 * np.sin((x + y) / 9.0)], axis=-1)
    image = 0.05 + 0.6 * base**2.2 + 0.1 * (np.sin(x / 2.3) * np.cos(y / 3.1))[..., None] ** 2
    image[:8, :8] = 3.0
    return image.astype(np.float32)


def _params(spec, exposure: float, **sensor: float) -> dict[str, float]:
    return {"exposure": exposure, "k": K, "sigma_read": SIGMA, "read_model": 0, "read_lambda": 0.14, **sensor}


def _apply(spec, rgb: np.ndarray, seed: int = 0, **params: float) -> np.ndarray:
    return spec.apply(rgb, {}, _params(spec, **params), np.random.default_rng(seed))


def _flat(value: float, size: int = 300) -> np.ndarray:
    return np.full((size, size, 3), value, np.float32)


def _encode_u8(linear: np.ndarray) -> np.ndarray:
    """What the pipeline does after the linear stage: clip, sRGB encode, 8 bits."""
    return np.round(255.0 * linear_to_srgb(np.clip(linear.astype(np.float64), 0.0, 1.0))).astype(np.uint8)


# ------------------------------------------------------------------ declarations
@pytest.mark.parametrize("spec", SPECS, ids=lambda s: s.name)
def test_spec_declaration(spec) -> None:
    assert spec.category is Category.PHOTOMETRIC and spec.stage is Stage.LINEAR
    assert spec.order == 30.0 and spec.needs == frozenset()
    gain = ["gain"] if spec is LOW_LIGHT else []  # the camera's gain after a dark exposure (low light only)
    # per_pixel last: every earlier parameter keeps its draw of the preset's generator
    assert [p.name for p in spec.params] == ["exposure", "k", "sigma_read", "read_model", "read_lambda", "pitch", *gain, "per_pixel"]
    for preset in spec.preset_names:
        ranges = spec.presets[preset]
        assert (ranges["k"].to_list(), ranges["sigma_read"].to_list(), ranges["read_model"].to_list()) == ([K, K], [SIGMA, SIGMA], [0, 0])
        assert ranges["pitch"].to_list() == [1.0, 1.0] and ranges["pitch"].per_size  # one photosite per reference pixel
        # low light draws per photosite (its noise is the picture: the same at every size); over-exposure,
        # whose noise is ≤ 1 % of full scale beside the clip, once per pixel with the photosites' statistics
        assert ranges["per_pixel"].to_list() == ([0, 0] if spec is LOW_LIGHT else [1, 1])
    registered: list = []
    module = low_light_module if spec is LOW_LIGHT else over_exposure_module
    module.spacedg_register_degradations(registered.append)
    assert registered == [spec]


def test_bench_presets_are_the_papers() -> None:
    assert LOW_LIGHT.presets["bench"]["exposure"].to_list() == [0.003, 0.005]
    assert OVER_EXPOSURE.presets["bench"]["exposure"].to_list() == [7.0, 10.0]
    assert LOW_LIGHT.param_map["exposure"].harsher == "lower" and OVER_EXPOSURE.param_map["exposure"].harsher == "higher"


# ----------------------------------------------------------- contract behaviour
def test_identity_at_zero_strength_is_bit_exact() -> None:
    hdr = _textured()
    hdr[0, -1] = -0.25  # negative and > 1 values pass through low_light unchanged
    assert np.array_equal(_apply(LOW_LIGHT, hdr, exposure=1.0, k=0.0, sigma_read=0.0), hdr)
    ldr = np.clip(_textured(), 0.0, 1.0)
    assert np.array_equal(_apply(OVER_EXPOSURE, ldr, exposure=1.0, k=0.0, sigma_read=0.0), ldr)


@pytest.mark.parametrize(("spec", "exposure"), [(LOW_LIGHT, 0.004), (OVER_EXPOSURE, 8.0)], ids=["low_light", "over_exposure"])
def test_deterministic_per_seed_and_one_rng_draw(spec, exposure: float) -> None:
    image = _textured()
    first = _apply(spec, image, seed=3, exposure=exposure)
    assert first.tobytes() == _apply(spec, image.copy(), seed=3, exposure=exposure).tobytes()
    assert not np.array_equal(first, _apply(spec, image, seed=4, exposure=exposure))
    rng, reference = np.random.default_rng(5), np.random.default_rng(5)
    spec.apply(image, {}, _params(spec, exposure), rng)
    stream_key(reference)
    assert rng.random() == reference.random(), "apply must consume exactly one stream_key draw"


@pytest.mark.parametrize(("spec", "exposure"), [(LOW_LIGHT, 0.004), (OVER_EXPOSURE, 8.0)], ids=["low_light", "over_exposure"])
def test_same_bytes_whatever_the_thread_count(spec, exposure: float) -> None:
    image = _textured(97, 131)
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = _apply(spec, image, seed=11, exposure=exposure, read_model=READ_TUKEY, read_lambda=-0.1)
        numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
        two = _apply(spec, image, seed=11, exposure=exposure, read_model=READ_TUKEY, read_lambda=-0.1)
    finally:
        numba.set_num_threads(before)
    assert one.tobytes() == two.tobytes()


@pytest.mark.parametrize(("spec", "exposure"), [(LOW_LIGHT, 0.004), (OVER_EXPOSURE, 8.0)], ids=["low_light", "over_exposure"])
def test_shape_dtype_finite_and_input_untouched(spec, exposure: float) -> None:
    image = _textured()[:, ::2]  # a non-contiguous view
    before = image.copy()
    out = _apply(spec, image, exposure=exposure)
    assert out.dtype == np.float32 and out.shape == image.shape and np.isfinite(out).all()
    assert np.array_equal(image, before), "input modified"
    if spec is OVER_EXPOSURE:
        assert out.min() >= 0.0 and out.max() <= 1.0 and (out == 1.0).mean() > 0.3


def test_low_light_output_is_dark_and_unclipped() -> None:
    out = _apply(LOW_LIGHT, _textured(), exposure=0.004)
    assert abs(out.mean() - 0.004 * _textured().mean()) < 2e-5
    assert out.min() < 0.0, "read noise is not clipped by low_light (the pipeline clips)"
    assert _encode_u8(out).mean() < 8.0


# ------------------------------------------------------------ the sensor model
@pytest.mark.parametrize("exposure", [1e-3, 0.004, 0.05, 1.0])  # 5, 20, 250 and 5000 photo-electrons
def test_photon_transfer_variance(exposure: float) -> None:
    signal = exposure * 0.5
    out = _apply(LOW_LIGHT, _flat(0.5), seed=1, exposure=exposure).astype(np.float64)
    expected_var = K * signal + SIGMA**2
    assert abs(out.mean() - signal) < 5.0 * np.sqrt(expected_var / out.size)
    assert out.var() == pytest.approx(expected_var, rel=0.02)


@pytest.mark.parametrize("rate", [0.3, 0.0625, 3.0, 9.99, 10.0, 47.0, 63.99, 64.0, 999.0, 1e3, 2.5e4, 1e7])
def test_poisson_mean_and_variance_equal_the_rate(rate: float) -> None:
    # k = 1, exposure 1: y = Poisson(x); table (< 64), PTRS and (from 1e3) the normal approximation
    out = _apply(LOW_LIGHT, _flat(rate), seed=2, exposure=1.0, k=1.0, sigma_read=0.0).astype(np.float64)
    assert abs(out.mean() - rate) < 5.0 * np.sqrt(rate / out.size)
    assert out.var() == pytest.approx(rate, rel=0.02)
    if rate < 1e3:
        assert np.array_equal(out, np.round(out)) and out.min() >= 0.0


@pytest.mark.parametrize("rate", [0.0301, 0.0625, 3.7, 17.93, 63.99])
def test_table_sampler_matches_the_poisson_pmf(rate: float) -> None:
    # 1.2e6 draws of Poisson(rate) (k = 1, exposure 1, no read noise) against the exact pmf
    draws = sensor_capture(np.full(1_200_000, rate, np.float32), exposure=1.0, k=1.0, sigma_read=0.0, key=77)
    counts = np.bincount(draws.astype(np.int64))
    n = np.arange(counts.size + 20, dtype=np.float64)
    lam = float(np.float32(rate))
    log_factorial = np.array([math.lgamma(v + 1.0) for v in n])
    pmf = np.exp(n * math.log(lam) - lam - log_factorial)
    expected = draws.size * pmf
    observed = np.concatenate([counts, np.zeros(20)])
    # every count within 5 standard deviations (+1 for the tiniest cells) of its expectation
    assert (np.abs(observed - expected) <= 5.0 * np.sqrt(expected) + 1.0).all()
    # chi-square over the cells with ≥ 5 expected, the rest pooled
    big = expected >= 5.0
    obs = np.append(observed[big], observed[~big].sum())
    exp = np.append(expected[big], expected[~big].sum())
    keep = exp > 0
    chi2, dof = float((((obs - exp) ** 2)[keep] / exp[keep]).sum()), int(keep.sum()) - 1
    assert chi2 < dof + 5.0 * math.sqrt(2.0 * max(dof, 1)), (chi2, dof)


def test_poisson_tables_are_the_exact_cdf() -> None:
    thresholds, row_start, guide = _sensor._POISSON_THRESHOLDS, _sensor._POISSON_ROW_START, _sensor._POISSON_GUIDE
    # the kernels' forms of them: the guide's bytes as words (each entry shifted out of its word as the
    # compiled loops do, for every row and bin, whatever the uniform's lower bits), two full-scale entries past
    # the last row
    assert _sensor._GUIDE_WORDS.astype("<u4").view(np.uint8).tobytes() == guide.tobytes()
    assert thresholds.size == row_start[-1] + 2 and (thresholds[-2:] == 2**32 - 1).all()

    @numba.njit
    def entries(low_bits):
        out = np.empty((1024, 256), np.uint8)
        for g in range(1024):
            for j in range(256):
                out[g, j] = _sensor._guide_entry(np.uint64(g), (np.uint64(j) << np.uint64(24)) | low_bits[(g + j) % low_bits.size])
        return out

    low = np.array([0, 1, 2**23, 2**24 - 1, 0x5A5A5A], np.uint64)
    assert np.array_equal(entries(low), guide)
    for g in (0, 1, 37, 512, 1023):
        row = thresholds[row_start[g] : row_start[g + 1]].astype(np.float64)
        lam = g / 16.0
        n = np.arange(row.size, dtype=np.float64)
        cdf = np.cumsum(np.exp(n * math.log(lam) - lam - np.array([math.lgamma(v + 1.0) for v in n]))) if g else np.ones(1)
        assert row[-1] == 2.0**32 - 1 and np.all(np.diff(row) >= 0)
        if row.size > 1:  # T_n = ceil(F(n)·2³²) − 1
            assert np.abs((row[:-1] + 1.0) / 2.0**32 - cdf[:-1]).max() <= 2.0**-32
        assert cdf[-1] > 1.0 - 2.0**-32
        for j in range(_sensor._TABLE_GUIDE):  # guide: first n with T_n ≥ j·2²⁴
            first = int(np.argmax(row >= j * 2.0**24))
            assert guide[g, j] == first


def test_normal_quantile_table_is_accurate_in_the_centre_and_the_tails() -> None:
    @numba.njit
    def worst(bits):
        out = 0.0
        for b in bits:
            u = (np.float64(np.int64(b >> np.uint64(12))) + 0.5) * 2.0**-52
            out = max(out, abs(_sensor._normal(b) - _sensor._normal_quantile(u)))
        return out

    rng = np.random.default_rng(3)
    uniform_bits = rng.integers(0, 2**63, size=500_000, dtype=np.uint64) * np.uint64(2)
    octave = rng.integers(0, 51, 500_000)
    m = np.minimum(np.floor(2.0**octave * (1.0 + rng.random(500_000))), 2.0**52 - 1).astype(np.uint64)
    tails = np.concatenate([m, np.uint64(2**52 - 1) - m, np.array([0, 1, 63, 64, 2**51 - 1, 2**51, 2**52 - 1], np.uint64)])
    assert worst(uniform_bits) < 1e-9
    assert worst(tails << np.uint64(12)) < 1e-9


@pytest.mark.parametrize(("k", "sigma_read", "read_model"), [(1e-4, 2.5e-4, 0), (1e-4, 0.0, 0), (0.0, 2.5e-4, 0), (1e-2, 0.1, READ_TUKEY)])
def test_saturation_shortcut_gives_the_same_bytes(k: float, sigma_read: float, read_model: int) -> None:
    image = np.ascontiguousarray(_textured(97, 131).reshape(-1) * np.float32(3.0))
    shortcut = sensor_capture(image, exposure=8.5, k=k, sigma_read=sigma_read, key=5, read_model=read_model, read_lambda=-0.2, clip=True)
    read_scale = sigma_read / (tukey_lambda_std(-0.2) if read_model == READ_TUKEY else 1.0)
    full = np.empty_like(image)
    _sensor._sensor_kernel(  # read-only input and flags: the signature sensor_capture calls, compiled by `spacedg kernels`
        kernel_cache.read_only(image), full, 8.5, k, read_scale, read_model, -0.2, True, math.inf, np.uint64(5), _sensor._NO_SKIP, False,
    )
    assert shortcut.tobytes() == full.tobytes()
    assert (full == 1.0).mean() > 0.3


def _value_by_value(x, exposure, k, read_scale, read_model, read_lambda, clip, saturated, key, skip, noise):
    """The sensor kernel's bytes the scalar way: :func:`_sensor._value` of every value (through
    :func:`_sensor._scalar_block` with every value flagged: compiled by ``spacedg kernels``, where a loop of its own
    here compiled for ~10 s in every test run), skipped ones as the kernel writes them."""
    keys, key_mix = _sensor._stream_keys(np.uint64(key))
    key_mix = np.uint64(key_mix)  # back from numba as a Python int, which numba would type int64 (uint64 + int64 is float64)
    inv_k = 1.0 / k if k > 0.0 else 0.0
    out = np.empty_like(x)
    flags = np.ones(-(-x.size // 8) * 8, np.uint8)  # read as 64-bit words
    _sensor._scalar_block(kernel_cache.read_only(x), 0, out, flags, float(exposure), float(k), inv_k, float(read_scale), int(read_model),
                          float(read_lambda), bool(clip), float(saturated), keys, key_mix, bool(noise))
    if skip.size:
        hit = skip.astype(bool)
        with np.errstate(invalid="ignore", over="ignore"):
            s = np.clip(np.nan_to_num(exposure * x[hit].astype(np.float64), nan=0.0, posinf=_sensor.SIGNAL_CAP, neginf=-_sensor.SIGNAL_CAP),
                        -_sensor.SIGNAL_CAP, _sensor.SIGNAL_CAP)
        out[hit] = 0.0 if noise else (np.clip(s, 0.0, 1.0) if clip else s).astype(np.float32)
    return out


@pytest.mark.parametrize(("k", "sigma_read", "read_model", "exposure"), [
    (1e-4, 2.5e-4, 0, 0.004), (1e-4, 2.5e-4, 0, 1.0), (1e-4, 2.5e-4, 0, 8.5),  # dark, mixed and bright blocks
    (1e-4, 0.0, 0, 1.0), (0.0, 2.5e-4, 0, 1.0), (3e-3, 2.5e-4, 0, 8.5), (1e-4, 2.5e-4, READ_TUKEY, 1.0),
    (1e-310, 2.5e-4, 0, 1.0),  # 1/k overflows: rate = 0·inf = NaN at a zero signal (no table row may be read from it)
])
def test_vector_loop_gives_every_value_the_scalar_bytes(k: float, sigma_read: float, read_model: int, exposure: float) -> None:
    """The kernel's vector loop (blocks in the table's, the normal approximation's and mixed regimes, a
    remainder count, PTRS and odd values left to the scalar loop) equals the value-by-value capture."""
    rng = np.random.default_rng(21)
    block = _sensor._BLOCK
    parts = [
        np.repeat(rng.random(8) * 0.6, block),  # flat blocks (one regime each at most exposures)
        rng.random(4 * block) * 0.01, rng.random(4 * block) * 2.0,  # dark; mixed
        10.0 ** rng.uniform(-9, 4, 6 * block), rng.standard_normal(2 * block) * 3.0,  # every rate; negatives
        np.full(block, 3e38),  # past the cap
        rng.random(block) * 0.3,  # every value skipped below
        rng.random(37) * 0.3,  # a short last block
    ]
    x = np.concatenate(parts).astype(np.float32)
    all_skipped = slice(x.size - 37 - block, x.size - 37)
    x[::97], x[::101], x[::103], x[::107], x[::109] = np.nan, np.inf, -np.inf, 0.0, -0.0
    read_scale, read_bound = _sensor._read_noise(sigma_read, read_model, -0.2)
    for clip, noise in ((False, False), (True, False), (False, True)):
        saturated = _sensor._saturation_signal(k, read_bound) if clip else math.inf
        some = (rng.random(x.size) < 0.2).astype(np.uint8)
        some[all_skipped] = 1
        for skip in (_sensor._NO_SKIP, kernel_cache.read_only(some)):  # read-only, as sensor_capture passes them
            args = (exposure, k, read_scale, read_model, -0.2, clip, saturated, np.uint64(77), skip, noise)
            fast = np.empty_like(x)
            _sensor._sensor_kernel(kernel_cache.read_only(x), fast, *args)
            assert fast.tobytes() == _value_by_value(x, *args).tobytes(), (clip, noise, skip.size)


@pytest.mark.parametrize("exposure", [1.0, 8.5, 40.0])
def test_bright_blocks_take_their_own_loops_with_the_scalar_bytes(exposure: float) -> None:
    """Blocks whose every value saturates (with the clip: written 1.0, nothing drawn) or whose every rate is in the
    normal approximation's range (that approximation alone) give every value the value-by-value bytes; next to them
    blocks one value short of either (a darker value, a NaN, a zero, a negative one) take the general loop."""
    rng = np.random.default_rng(22)
    block = _sensor._BLOCK
    bright = [rng.uniform(low, high, block) for low, high in ((0.05, 0.1), (0.2, 0.6), (1.0, 3.0), (3e30, 3e38))]
    spoiled = []
    for odd in (1e-6, np.nan, 0.0, -0.5):
        part = rng.uniform(0.2, 0.6, block)
        part[rng.integers(block)] = odd
        spoiled.append(part)
    x = np.concatenate([*bright, *spoiled, rng.uniform(0.2, 0.6, 41)]).astype(np.float32)
    for k, sigma_read in ((1e-4, 2.5e-4), (1e-4, 0.0), (3e-3, 2.5e-4)):
        read_scale, read_bound = _sensor._read_noise(sigma_read, 0, 0.14)
        for clip, noise in ((False, False), (True, False), (False, True)):
            saturated = _sensor._saturation_signal(k, read_bound) if clip else math.inf
            args = (exposure, k, read_scale, 0, 0.14, clip, saturated, np.uint64(31), _sensor._NO_SKIP, noise)
            fast = np.empty_like(x)
            _sensor._sensor_kernel(kernel_cache.read_only(x), fast, *args)
            assert fast.tobytes() == _value_by_value(x, *args).tobytes(), (k, clip, noise)
            if clip and exposure >= 8.5:
                assert (fast[2 * block : 4 * block] == 1.0).all()


@pytest.mark.parametrize("lam", [-0.2, -1e-7, 0.0, 1e-7, 0.14, 0.5, 1.0])
def test_tukey_lambda_read_noise_has_unit_variance(lam: float) -> None:
    out = _apply(LOW_LIGHT, _flat(0.0), seed=4, exposure=1.0, k=0.0, sigma_read=1.0, read_model=READ_TUKEY, read_lambda=lam)
    assert np.isfinite(out).all()
    assert out.astype(np.float64).var() == pytest.approx(1.0, rel=0.05 if lam < 0 else 0.02)


def test_tukey_lambda_is_continuous_at_zero() -> None:
    logistic, near = (
        _apply(LOW_LIGHT, _flat(0.0, 64), seed=4, exposure=1.0, k=0.0, sigma_read=1.0, read_model=READ_TUKEY, read_lambda=lam)
        for lam in (0.0, 1.5e-6)
    )
    # just past the logistic branch (|λ| < 1e-6) the quantile moves by O(λ·log²p), no jump
    assert np.abs(logistic - near).max() < 100 * 1.5e-6
    assert tukey_lambda_std(0.0) == pytest.approx(np.pi / np.sqrt(3.0))
    for lam in (1.5e-6, 1e-5, -1e-5):
        assert tukey_lambda_std(lam) == pytest.approx(np.pi / np.sqrt(3.0), rel=1e-4)
    assert tukey_lambda_std(1.0) == pytest.approx(np.sqrt(1.0 / 3.0))  # λ = 1: uniform on [-1, 1]


def test_gaussian_read_noise_is_normal() -> None:
    out = _apply(LOW_LIGHT, _flat(0.0), seed=6, exposure=1.0, k=0.0, sigma_read=1.0).astype(np.float64)
    assert abs(out.mean()) < 0.01 and out.var() == pytest.approx(1.0, rel=0.02)
    assert np.mean(out**4) == pytest.approx(3.0, rel=0.05)  # normal kurtosis
    assert np.mean(np.abs(out) < 1.0) == pytest.approx(0.6827, abs=0.005)


# ------------------------------------------------------------ severity, extremes
@pytest.mark.parametrize("spec", SPECS, ids=lambda s: s.name)
def test_distance_rises_with_severity(spec) -> None:
    image = _textured()
    clean = _encode_u8(image).astype(np.float64)
    distances = []
    for level in ("1", "2", "3", "4", "5"):
        r = spec.presets[level]["exposure"]
        degraded = _encode_u8(_apply(spec, image, seed=7, exposure=(r.low + r.high) / 2.0))
        distances.append(float(np.mean(np.abs(degraded - clean))))
    assert all(a < b for a, b in zip(distances, distances[1:])), distances


@pytest.mark.parametrize(("spec", "exposure"), [(LOW_LIGHT, 1e-6), (LOW_LIGHT, 1.0), (OVER_EXPOSURE, 1e4), (OVER_EXPOSURE, 1e6)])
def test_extreme_values_stay_finite(spec, exposure: float) -> None:
    special = np.array([0.0, 1e30, -1.0, np.inf, np.nan, -np.inf, 1e-30, 3.0e38], np.float32)
    image = np.resize(special, (4, 6, 3)).astype(np.float32)
    for sensor in ({}, {"k": 1.0, "sigma_read": 1.0}, {"k": 1e-12, "read_model": READ_TUKEY, "read_lambda": -0.45}):
        out = _apply(spec, image, exposure=exposure, **sensor)
        assert np.isfinite(out).all(), (exposure, sensor, out)
        assert np.abs(out).max() <= 2.0 * SIGNAL_CAP
        if spec is OVER_EXPOSURE:
            assert out.min() >= 0.0 and out.max() <= 1.0
            assert out.reshape(-1)[3] == 1.0  # +inf saturates
    nan_and_inf = _apply(LOW_LIGHT, image, exposure=1.0, k=0.0, sigma_read=0.0).reshape(-1)
    assert nan_and_inf[4] == 0.0 and nan_and_inf[3] == SIGNAL_CAP and nan_and_inf[5] == -SIGNAL_CAP


def test_plain_functions_match_apply() -> None:
    image = _textured()
    key = stream_key(np.random.default_rng(9))
    assert np.array_equal(low_light(image, 0.004, key), _apply(LOW_LIGHT, image, seed=9, exposure=0.004))
    assert np.array_equal(over_expose(image, 8.0, key), _apply(OVER_EXPOSURE, image, seed=9, exposure=8.0))


@pytest.mark.parametrize(
    ("spec", "params", "pattern"),
    [
        (LOW_LIGHT, {"exposre": 0.1}, "unknown parameter 'exposre'. Did you mean 'exposure'"),
        (LOW_LIGHT, {"exposure": 1.5}, r"'exposure' = 1.5 is outside its hard limits \[0, 1\]"),
        (OVER_EXPOSURE, {"exposure": 0.5}, r"'exposure' = 0.5 is outside its hard limits \[1, 1e\+06\]"),
        (LOW_LIGHT, {"k": -1e-4}, r"'k' = -0.0001 is outside its hard limits \[0, 1\]"),
        (OVER_EXPOSURE, {"read_lambda": -0.5}, r"'read_lambda' = -0.5 is outside its hard limits \[-0.45, 1\]"),
        (LOW_LIGHT, {"read_model": 2}, r"'read_model' = 2 is outside its hard limits \[0, 1\]"),
        (LOW_LIGHT, {"read_model": 0.5}, "'read_model' must be an integer"),
        (OVER_EXPOSURE, {"sigma_read": float("nan")}, "'sigma_read' must be a finite number"),
    ],
)
def test_bad_params_rejected(spec, params: dict, pattern: str) -> None:
    with pytest.raises(ParameterError, match=pattern):
        spec.validate_params(params, partial=True)
    with pytest.raises(ParameterError, match=pattern):
        spec.apply(_textured(8, 8), {}, {**_params(spec, 1.0), **params}, np.random.default_rng(0))


@pytest.mark.parametrize(("k", "sigma_read", "read_model", "read_lambda"), [
    (1e-4, 2.5e-4, 0, 0.14), (0.0, 2.5e-4, 0, 0.14), (1e-4, 0.0, 0, 0.14), (1e-2, 0.05, READ_TUKEY, -0.2), (1e-4, 2.5e-4, READ_TUKEY, 0.14),
])
def test_saturated_sites_are_skipped_without_changing_a_byte(k: float, sigma_read: float, read_model: int, read_lambda: float) -> None:
    """Over-exposure on photosites (sites smaller than pixels) does not draw the sites that only
    pixels sure to clip to 1.0 read: the bytes equal drawing every site, at exposures that put
    many pixels right at the edge of saturating; and the skip does happen."""
    from spacedg.plugins.degradations import _photosites

    image = _textured(61, 83) * np.float32(1.3)
    image[5:9, 40:50] = np.nan
    sensor = {"k": k, "sigma_read": sigma_read, "read_model": read_model, "read_lambda": read_lambda}
    skipped = []
    for pitch in (0.31, 0.5, 0.77):
        for exposure in (1.05, 1.6, 2.5, 8.5):
            edge = image.copy()  # flat patches just above full scale: they clip unless the noise pulls them under
            edge[20:45, 5:35] = np.float32(1.003 / exposure)
            edge[45:60, 50:80] = np.float32(1.05 / exposure)
            edge[30, 35] = edge[52, 49] = np.float32(400.0 / exposure)  # hot pixels beside the patches
            args = {"pitch": pitch, "exposure": exposure, "clip": True, "key": 11, **sensor}
            assert _photosites.binned_capture(edge, **args).tobytes() == _photosites.binned_capture(edge, skip_saturated=False, **args).tobytes()
            signal = np.nan_to_num(edge) * np.float32(exposure)
            unread = _photosites._sites_of_saturated_pixels(signal, _photosites.photosite_grid(83, 61, pitch), sensor)
            skipped.append(0.0 if unread is None else unread.mean())
    if read_lambda < 0:  # Tukey λ = -0.2: read noise tails reach tens of full scales, so no pixel is sure to clip
        assert max(skipped) == 0.0
    else:
        assert max(skipped) > 0.3


def test_the_largest_drop_bounds_every_draw() -> None:
    signals = np.geomspace(1e-6, 30.0, 4000).astype(np.float32)
    for k, sigma_read, model in ((1e-4, 2.5e-4, 0), (1e-2, 0.05, READ_TUKEY), (0.0, 1e-3, 0)):
        drop = _sensor.largest_drop(signals, k=k, sigma_read=sigma_read, read_model=model, read_lambda=-0.2)
        assert drop.dtype == np.float32 and (np.diff(drop) >= 0).all()  # grows with the signal
        lowest = np.full(signals.size, np.inf)
        for key in range(40):
            lowest = np.minimum(lowest, sensor_capture(signals, exposure=1.0, k=k, sigma_read=sigma_read, key=key, read_model=model, read_lambda=-0.2) - signals)
        assert (lowest >= -drop).all()
        if model != READ_TUKEY:  # (the Tukey clamp's tail is far beyond 40 draws)
            assert (lowest < -0.1 * drop).any()  # not a vacuous bound


def test_the_noise_of_a_capture_and_its_skipped_values() -> None:
    image = _textured() * np.float32(0.2)
    image[0, :5, 0] = [np.nan, np.inf, -np.inf, -1.0, 2e12]
    for exposure in (1.0, 0.37):
        full = sensor_capture(image, exposure=exposure, k=1e-4, sigma_read=2.5e-4, key=3)
        signal = np.clip(np.nan_to_num(image.astype(np.float64) * exposure, nan=0.0), -SIGNAL_CAP, SIGNAL_CAP).astype(np.float32)
        noise = sensor_capture(image, exposure=exposure, k=1e-4, sigma_read=2.5e-4, key=3, noise=True)
        assert noise.tobytes() == (full - signal).tobytes()
        skip = np.zeros(image.shape, bool)
        skip[::3, ::2] = True
        partly = sensor_capture(image, exposure=exposure, k=1e-4, sigma_read=2.5e-4, key=3, skip=skip)
        assert partly[~skip].tobytes() == full[~skip].tobytes() and partly[skip].tobytes() == signal[skip].tobytes()
        assert not sensor_capture(image, exposure=exposure, k=1e-4, sigma_read=2.5e-4, key=3, skip=skip, noise=True)[skip].any()
        clipped = sensor_capture(image * np.float32(9.0), exposure=exposure, k=1e-4, sigma_read=2.5e-4, key=3, skip=skip, clip=True)
        assert clipped.min() >= 0.0 and clipped.max() <= 1.0  # skipped values are clipped like drawn ones
    with pytest.raises(InvalidDataError, match="noise=True .* clip=True"):
        sensor_capture(image, exposure=1.0, k=1e-4, sigma_read=2.5e-4, key=3, noise=True, clip=True)
    with pytest.raises(InvalidDataError, match="skip must have the image's shape"):
        sensor_capture(image, exposure=1.0, k=1e-4, sigma_read=2.5e-4, key=3, skip=np.zeros(5, bool))


def test_a_capture_into_a_given_array_and_the_photosites_reused_workspaces() -> None:
    """``sensor_capture(out=...)`` writes the same bytes into the caller's array (and refuses one of the wrong
    size, type or layout, or the input's own memory); the photosite capture's per-thread workspaces, reused from one call to the next
    (other keys, exposures, sizes, and back), leave every result as a fresh capture has it."""
    from spacedg.plugins.degradations import _photosites

    image = _textured() * np.float32(0.2)
    fresh = sensor_capture(image, exposure=0.5, k=K, sigma_read=SIGMA, key=11)
    given = np.full(image.shape, np.nan, np.float32)
    assert sensor_capture(image, exposure=0.5, k=K, sigma_read=SIGMA, key=11, out=given) is not None
    assert given.tobytes() == fresh.tobytes()
    for bad in (np.empty(image.size - 1, np.float32), np.empty(image.shape, np.float64), np.empty(image.shape[::-1], np.float32).T, image):
        with pytest.raises(InvalidDataError, match="out must be a writeable C-contiguous float32 array"):
            sensor_capture(image, exposure=0.5, k=K, sigma_read=SIGMA, key=11, out=bad)
    calls = [(image, 0.004, 5, 0.3), (image[:40, :50], 0.01, 6, 0.3), (image, 0.004, 5, 0.3), (image, 0.2, 7, 0.45)]
    kept = [_photosites.binned_capture(rgb, pitch=p, exposure=e, clip=False, key=key, k=K, sigma_read=SIGMA) for rgb, e, key, p in calls]
    first = [array.tobytes() for array in kept]  # read after every call: a result that were a workspace would have changed
    _photosites._WORKSPACES.arrays = {}  # as a new thread finds them
    alone = [_photosites.binned_capture(rgb, pitch=p, exposure=e, clip=False, key=key, k=K, sigma_read=SIGMA).tobytes() for rgb, e, key, p in calls[::-1]]
    assert first == alone[::-1] and first[0] == first[2] and first[0] != first[3]

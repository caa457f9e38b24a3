"""Shared sensor model of the photometric degradations (not a plugin: no entry point).

Model, per channel value ``x`` of linear light (normalised so that 1 is the sensor's full
scale at unit exposure):

    s = e·x                                   (exposure gain e)
    y = k · Poisson(max(s, 0) / k) + σ_read · R

``k`` is the system gain in normalised units per photo-electron (``1 / k`` electrons fill the
full scale), so ``s / k`` is the expected photo-electron count; ``R`` is unit-variance read
noise: standard Gaussian (the paper's formula) or, as the ELD refinement (Wei et al., CVPR
2020), a Tukey-lambda variate scaled to unit variance. The photon-transfer invariant holds:
``Var(y) = k·E(y) + σ_read²`` on a flat patch.

Defaults (photon-transfer / ELD literature, a mid-size CMOS pixel at base ISO): full-well
equivalent ≈ 10⁴ e⁻ → ``k = 1e-4``; read noise ≈ 2.5 e⁻ → ``σ_read = 2.5e-4``. Tukey λ
defaults to 0.14, the value whose distribution is closest to a normal; λ < 0 gives the
heavy tails ELD measured on dark frames.

Sampling (compiled numba kernel, parallel over values):

- Poisson, exact below 10³ electrons: inversion for λ < 10, Hörmann's transformed rejection
  with squeeze (PTRS, 1993) for 10 ≤ λ < 10³; normal approximation ``s + √(k·s)·Z`` above
  (relative error of the approximation < 10⁻³ there; numpy raises on NaN rates and
  ``torch.poisson`` returns garbage at 1e19, hence the own sampler).
- Rates: a negative signal gives 0 electrons (a sensor counts no negative photons).
- Non-finite input: NaN is treated as 0 (documented choice: ``check_linear_rgb`` does not scan
  for NaN, and a NaN would spread through every later stage); ±inf and values beyond
  ±:data:`SIGNAL_CAP` (after the gain) are clamped to ±:data:`SIGNAL_CAP`, so the output is
  always finite.
- Randomness is counter-based: value ``i`` (flat index into the C-ordered (H, W, 3) array)
  seeds a splitmix64 stream from ``(key, i)``; draw 0 is the read noise, draws 1, 2, … the
  shot noise. The output bytes depend only on ``(input, parameters, key)``, not on the
  number of threads, and the read noise of a pixel is the same at every exposure (common
  random numbers: severity levels differ only by the model).

Identity: ``e = 1, k = 0, σ_read = 0`` returns the input bit for bit (finite values within
the cap, NaN → 0); ``k = 0`` disables shot noise (``y = e·x``), ``σ_read = 0`` read noise.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from spacedg.errors import InvalidDataError
from spacedg.plugins.specs import ParamRange, ParamSpec

__all__ = [
    "K_DEFAULT",
    "SIGMA_READ_DEFAULT",
    "READ_LAMBDA_DEFAULT",
    "READ_GAUSSIAN",
    "READ_TUKEY",
    "SIGNAL_CAP",
    "SENSOR_PARAMS",
    "SENSOR_PRESET",
    "tukey_lambda_std",
    "sensor_capture",
]

#: System gain: normalised full scale per photo-electron (full well ≈ 10⁴ e⁻).
K_DEFAULT = 1e-4
#: Read-noise std in normalised linear units (≈ 2.5 e⁻ at K_DEFAULT).
SIGMA_READ_DEFAULT = 2.5e-4
#: Tukey λ closest to a normal distribution (λ ≈ 0.14).
READ_LAMBDA_DEFAULT = 0.14
#: ``read_model`` values.
READ_GAUSSIAN = 0
READ_TUKEY = 1
#: Largest |e·x| (normalised linear units) the sensor sees; beyond, and ±inf, is clamped.
SIGNAL_CAP = 1e12

_INVERSION_MAX_RATE = 10.0  # below: Poisson by inversion
_INVERSION_MAX_COUNT = 100  # P(Poisson(10) > 100) < 1e-60: the inversion search stops there
_RECIPROCALS = 1.0 / np.maximum(np.arange(_INVERSION_MAX_COUNT + 1, dtype=np.float64), 1.0)
_NORMAL_MIN_RATE = 1e3  # from here: normal approximation
_TUKEY_P_MIN = 1e-12  # p clamp of the Tukey-lambda inverse CDF (infinite at 0 and 1 for λ < 0)
_TUKEY_LOGISTIC = 1e-6  # |λ| below: the logistic limit log(p / (1 - p))
_TUKEY_SERIES = 1e-3  # |λ| below: Taylor series of the Tukey-lambda variance
_TUKEY_VAR_SERIES = (math.pi**2 / 3.0, -11.387963880031283, 27.646382311762686, -59.826680284056636)

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)
_S30, _S27, _S31, _S11 = np.uint64(30), np.uint64(27), np.uint64(31), np.uint64(11)
_TWO_M53 = 2.0**-53

SENSOR_PARAMS: tuple[ParamSpec, ...] = (
    ParamSpec("k", "1/e-", "System gain: normalised full-scale signal per photo-electron (1/k electrons fill the full scale); 0 disables shot noise.", low=0.0, high=1.0, harsher="higher"),
    ParamSpec("sigma_read", "1", "Read-noise standard deviation in normalised linear units (full scale = 1); 0 disables read noise.", low=0.0, high=1.0, harsher="higher"),
    ParamSpec("read_model", "1", "Read-noise shape: 0 = Gaussian (the paper's formula), 1 = Tukey lambda scaled to unit variance (ELD).", low=READ_GAUSSIAN, high=READ_TUKEY, integer=True),
    ParamSpec("read_lambda", "1", "Tukey-lambda shape of the read noise (read_model = 1): 0.14 ≈ normal, < 0 heavy-tailed, 0 logistic.", low=-0.45, high=1.0),
)

#: Fixed sensor ranges every preset of the photometric degradations uses.
SENSOR_PRESET: dict[str, ParamRange] = {
    "k": ParamRange(K_DEFAULT, K_DEFAULT),
    "sigma_read": ParamRange(SIGMA_READ_DEFAULT, SIGMA_READ_DEFAULT),
    "read_model": ParamRange(READ_GAUSSIAN, READ_GAUSSIAN),
    "read_lambda": ParamRange(READ_LAMBDA_DEFAULT, READ_LAMBDA_DEFAULT),
}


# ------------------------------------------------------------ random numbers
@numba.njit(cache=True, inline="always")
def _mix(z: np.uint64) -> np.uint64:
    """splitmix64 finaliser: a bijective 64-bit avalanche."""
    z = (z ^ (z >> _S30)) * _MIX1
    z = (z ^ (z >> _S27)) * _MIX2
    return z ^ (z >> _S31)


@numba.njit(cache=True, inline="always")
def _uniform(base: np.uint64, draw: int) -> float:
    """Draw number ``draw`` of the stream seeded by ``base``: uniform in the open interval (0, 1)."""
    z = _mix(base + np.uint64(draw + 1) * _GOLDEN)
    return (np.float64(np.int64(z >> _S11)) + 0.5) * _TWO_M53


@numba.njit(cache=True, inline="always")
def _normal_quantile(p: float) -> float:
    """Standard normal inverse CDF, Wichura's AS241 (PPND16, relative error ~1e-16), 0 < p < 1."""
    q = p - 0.5
    if abs(q) <= 0.425:
        r = 0.180625 - q * q
        num = (((((((2509.0809287301226727 * r + 33430.575583588128105) * r + 67265.770927008700853) * r
                   + 45921.953931549871457) * r + 13731.693765509461125) * r + 1971.5909503065514427) * r
                 + 133.14166789178437745) * r + 3.387132872796366608)
        den = (((((((5226.495278852545925 * r + 28729.085735721942674) * r + 39307.89580009271061) * r
                   + 21213.794301586595867) * r + 5394.1960214247511077) * r + 687.1870074920579083) * r
                 + 42.313330701600911252) * r + 1.0)
        return q * num / den
    r = p if q < 0.0 else 1.0 - p
    r = math.sqrt(-math.log(r))
    if r <= 5.0:
        r -= 1.6
        num = (((((((7.7454501427834140764e-4 * r + 0.0227238449892691845833) * r + 0.24178072517745061177) * r
                   + 1.27045825245236838258) * r + 3.64784832476320460504) * r + 5.7694972214606914055) * r
                 + 4.6303378461565452959) * r + 1.42343711074968357734)
        den = (((((((1.05075007164441684324e-9 * r + 5.475938084995344946e-4) * r + 0.0151986665636164571966) * r
                   + 0.14810397642748007459) * r + 0.68976733498510000455) * r + 1.6763848301838038494) * r
                 + 2.05319162663775882187) * r + 1.0)
    else:
        r -= 5.0
        num = (((((((2.01033439929228813265e-7 * r + 2.71155556874348757815e-5) * r + 0.0012426609473880784386) * r
                   + 0.026532189526576123093) * r + 0.29656057182850489123) * r + 1.7848265399172913358) * r
                 + 5.4637849111641143699) * r + 6.6579046435011037772)
        den = (((((((2.04426310338993978564e-15 * r + 1.4215117583164458887e-7) * r + 1.8463183175100546818e-5) * r
                   + 7.868691311456132591e-4) * r + 0.0148753612908506148525) * r + 0.13692988092273580531) * r
                 + 0.59983220655588793769) * r + 1.0)
    z = num / den
    return -z if q < 0.0 else z


@numba.njit(cache=True, inline="always")
def _tukey_quantile(p: float, lam: float) -> float:
    """Tukey-lambda inverse CDF in float64, p clamped into [1e-12, 1 - 1e-12]."""
    p = min(max(p, _TUKEY_P_MIN), 1.0 - _TUKEY_P_MIN)
    if abs(lam) < _TUKEY_LOGISTIC:
        return math.log(p / (1.0 - p))
    # (p^λ − (1−p)^λ) / λ written with expm1: no cancellation as λ → 0
    return (math.expm1(lam * math.log(p)) - math.expm1(lam * math.log1p(-p))) / lam


@numba.njit(cache=True, inline="always")
def _poisson(rate: float, base: np.uint64) -> float:
    """Exact Poisson(rate) for 0 ≤ rate < 10³ from draws 1, 2, … of the stream ``base``."""
    if rate < _INVERSION_MAX_RATE:
        u = _uniform(base, 1)
        p = math.exp(-rate)
        cdf = p
        n = 0
        while u > cdf and n < _INVERSION_MAX_COUNT:
            n += 1
            p *= rate * _RECIPROCALS[n]
            cdf += p
        return float(n)
    # Hörmann (1993), PTRS: transformed rejection with squeeze
    b = 0.931 + 2.53 * math.sqrt(rate)
    a = -0.059 + 0.02483 * b
    inv_alpha = 1.1239 + 1.1328 / (b - 3.4)
    v_r = 0.9277 - 3.6224 / (b - 2.0)
    draw = 1
    while True:
        u = _uniform(base, draw) - 0.5
        v = _uniform(base, draw + 1)
        draw += 2
        us = 0.5 - abs(u)
        n = math.floor((2.0 * a / us + b) * u + rate + 0.43)
        if us >= 0.07 and v <= v_r:
            return n
        if n < 0.0 or (us < 0.013 and v > us):
            continue
        if math.log(v) + math.log(inv_alpha) - math.log(a / (us * us) + b) <= -rate + n * math.log(rate) - math.lgamma(n + 1.0):
            return n


@numba.njit(parallel=True, cache=True, fastmath=False)
def _sensor_kernel(
    x: np.ndarray,
    out: np.ndarray,
    exposure: float,
    k: float,
    read_scale: float,
    read_model: int,
    read_lambda: float,
    clip: bool,
    key: np.uint64,
) -> None:
    """``out[i] = k·Poisson(e·x[i]/k) + read_scale·R`` over flat float32 arrays (see the module docstring)."""
    key_mix = _mix(key)
    for i in numba.prange(x.size):
        s = exposure * np.float64(x[i])
        if s != s:
            s = 0.0
        s = min(max(s, -SIGNAL_CAP), SIGNAL_CAP)
        base = _mix(key_mix + np.uint64(i) * _GOLDEN)
        if k > 0.0:
            if s <= 0.0:
                s = 0.0
            elif s < _NORMAL_MIN_RATE * k:
                s = k * _poisson(s / k, base)
            else:
                s = max(s + math.sqrt(k * s) * _normal_quantile(_uniform(base, 1)), 0.0)
        if read_scale > 0.0:
            u = _uniform(base, 0)
            r = _normal_quantile(u) if read_model == READ_GAUSSIAN else _tukey_quantile(u, read_lambda)
            s += read_scale * r
        if clip:
            s = min(max(s, 0.0), 1.0)
        out[i] = s


# ------------------------------------------------------------------ host side
def tukey_lambda_std(lam: float) -> float:
    """Standard deviation of the Tukey-lambda distribution with shape ``lam`` (> −1/2).

    ``Var = 2/λ² · (1/(1 + 2λ) − Γ(λ + 1)² / Γ(2λ + 2))`` (π²/3, logistic, at λ = 0), evaluated
    with ``expm1``; for |λ| < 1e-3, where that still cancels, its Taylor series to λ³ (from
    the ζ(n) series of log Γ(1 + x)); both agree to ~1e-9 at the switch.
    """
    if not lam > -0.5:
        raise InvalidDataError(f"Tukey-lambda read noise: λ = {lam!r} has infinite variance; use λ > -0.5")
    if abs(lam) < _TUKEY_SERIES:
        c0, c1, c2, c3 = _TUKEY_VAR_SERIES
        return math.sqrt(c0 + lam * (c1 + lam * (c2 + lam * c3)))
    log_ratio = 2.0 * math.lgamma(lam + 1.0) - math.lgamma(2.0 * lam + 2.0) + math.log1p(2.0 * lam)
    return math.sqrt(-2.0 / lam**2 * math.expm1(log_ratio) / (1.0 + 2.0 * lam))


def sensor_capture(
    rgb: np.ndarray,
    *,
    exposure: float,
    k: float,
    sigma_read: float,
    key: int,
    read_model: int = READ_GAUSSIAN,
    read_lambda: float = READ_LAMBDA_DEFAULT,
    clip: bool = False,
) -> np.ndarray:
    """Expose linear light by ``exposure`` and add shot and read noise (see the module docstring).

    Args:
        rgb: float32 array (any shape; the photometric plugins pass (H, W, 3)), linear light.
            Not modified.
        exposure: gain e ≥ 0 on linear light.
        k: normalised full scale per photo-electron, ≥ 0 (0: no shot noise).
        sigma_read: read-noise std in normalised linear units, ≥ 0 (0: no read noise).
        key: 63-bit stream key (:func:`~spacedg.plugins.degradations._common.stream_key`).
        read_model: :data:`READ_GAUSSIAN` or :data:`READ_TUKEY`.
        read_lambda: Tukey λ (> −0.5), used when ``read_model == READ_TUKEY``.
        clip: clip the result to [0, 1] (saturation).

    Returns:
        A new float32 array of ``rgb``'s shape, always finite.
    """
    for name, value in (("exposure", exposure), ("k", k), ("sigma_read", sigma_read)):
        if not (math.isfinite(value) and value >= 0.0):
            raise InvalidDataError(f"sensor model: {name} must be a finite number ≥ 0, got {value!r}")
    if read_model not in (READ_GAUSSIAN, READ_TUKEY):
        raise InvalidDataError(f"sensor model: read_model must be {READ_GAUSSIAN} (Gaussian) or {READ_TUKEY} (Tukey lambda), got {read_model!r}")
    if not 0 <= key < 2**64:
        raise InvalidDataError(f"sensor model: key must be an integer in [0, 2**64), got {key!r}; draw it with stream_key(rng)")
    read_scale = float(sigma_read)
    if read_model == READ_TUKEY and sigma_read > 0.0:
        read_scale /= tukey_lambda_std(float(read_lambda))
    flat = np.ascontiguousarray(rgb, dtype=np.float32).reshape(-1)
    out = np.empty(flat.size, dtype=np.float32)
    _sensor_kernel(
        flat, out, float(exposure), float(k), read_scale, int(read_model), float(read_lambda), bool(clip), np.uint64(key)
    )
    return out.reshape(rgb.shape)

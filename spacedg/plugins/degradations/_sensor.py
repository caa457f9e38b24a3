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

Sampling (compiled numba kernel, parallel over blocks of values, each block's common case in one
SIMD loop over the tables and the rest value by value, the same bytes: :func:`_sensor_kernel`), by
the expected electron count
``λ = s / k`` (computed as ``s·(1/k)``):

- ``λ < 64``: **exact** Poisson by table. ``Poisson(λ) = Poisson(λ_g) + Poisson(δ)`` (independent
  draws), ``λ_g = ⌊16·λ⌋/16``, ``δ < 1/16``. One 64-bit draw: its high 32 bits ``U`` give
  ``Poisson(λ_g)`` as ``min{n : U ≤ T_n}`` with ``T_n = ⌈F(n)·2³²⌉ − 1`` tabulated at import for the
  1024 grid rates (``F`` the float64 CDF), started from a 256-bin guide table (≈ 1 comparison);
  its low 32 bits give ``Poisson(δ)`` by inversion from 0 (``u < 1 − δ ≤ e^{−δ}`` decides 0
  without an ``exp``, a fraction ``1 − δ`` ≥ 15/16 of draws). Each pmf value is reproduced to within 2⁻³² ≈ 2.3e-10
  (the resolution of the uniforms; the tail beyond ``F > 1 − 2⁻³²`` is folded into the last
  table entry); no approximation otherwise.
- ``64 ≤ λ < 10³``: exact Poisson by Hörmann's transformed rejection with squeeze (PTRS, 1993),
  52-bit uniforms.
- ``λ ≥ 10³``: normal approximation ``s + √(k·s)·Z`` (relative error of the approximation
  < 10⁻³ there; numpy raises on NaN rates and ``torch.poisson`` returns garbage at 1e19, hence
  the own sampler).
- ``Z`` (that approximation and the Gaussian read noise): Φ⁻¹ of a 52-bit uniform through a
  branch-free table of 3008 cubic pieces (octave and 6 mantissa bits of ``min(u, 1 − u)``;
  Hermite interpolation of AS241 and its derivative). Its largest deviation from Φ⁻¹
  (AS241) is 3.8e-10 over 7e6 test inputs covering both tails down to ``u = 2⁻⁵³``
  (``|Z| ≤ 8.21``); tests check < 1e-9. Tukey-lambda read noise: its inverse CDF in float64.
- With ``clip`` (over-exposure), a signal so large that the output is 1.0 for every possible
  draw (``s − 8.5·√(k·s) − max|σ·R| > 1`` in the normal regime) is written as 1.0: the
  value-by-value path draws nothing for it, nor does a block of the vector loop whose every value
  saturates; in a block with others the branch-free vector loop draws and discards (the same bytes).
- Rates: a negative signal gives 0 electrons (a sensor counts no negative photons).
- Non-finite input: NaN is treated as 0 (documented choice: ``check_linear_rgb`` does not scan
  for NaN, and a NaN would spread through every later stage); ±inf and values beyond
  ±:data:`SIGNAL_CAP` (after the gain) are clamped to ±:data:`SIGNAL_CAP`, so the output is
  always finite.
- Randomness is counter-based: draw ``d`` of value ``i`` (flat index into the C-ordered
  (H, W, 3) array) is ``mix(K_d + i·γ)`` (splitmix64 finaliser ``mix``, golden gamma ``γ``,
  ``K_d = mix(mix(key) + (d + 1)·γ)``); draw 0 is the read noise, draws 1, 2, … the shot noise
  (the table sampler uses draw 1 only, PTRS draws 1, 2, …). The output bytes depend only on ``(input, parameters, key)``, not on the
  number of threads, and the read noise of a pixel is the same at every exposure (common
  random numbers: severity levels differ only by the model).

Identity: ``e = 1, k = 0, σ_read = 0`` returns the input bit for bit (finite values within
the cap, NaN → 0); ``k = 0`` disables shot noise (``y = e·x``), ``σ_read = 0`` read noise.
"""

from __future__ import annotations

import math
from statistics import NormalDist

import llvmlite.ir
import numba
import numba.core.types
import numba.extending
import numpy as np

from spacedg.render import kernel_cache  # numba's cache entries checked before any kernel here compiles
from spacedg.render.cpu_target import vectorise_table_lookups
from spacedg.render.threads import fork_safe

try:  # LLVM ctlz: used to find the octave of a uniform in the normal-quantile table
    from numba.cpython.unsafe.numbers import leading_zeros as _leading_zeros
except ImportError:  # pragma: no cover - older/newer numba without the intrinsic

    @numba.njit(cache=True, inline="always")
    def _leading_zeros(v):  # type: ignore[no-redef]
        n = 0
        while n < 64 and not (v >> np.uint64(63 - n)) & np.uint64(1):
            n += 1
        return n

from spacedg.errors import InvalidDataError

__all__ = [
    "K_DEFAULT",
    "SIGMA_READ_DEFAULT",
    "READ_LAMBDA_DEFAULT",
    "READ_GAUSSIAN",
    "READ_TUKEY",
    "SIGNAL_CAP",
    "tukey_lambda_std",
    "sensor_capture",
    "check_sensor_parameters",
    "largest_drop",
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

_TABLE_MAX_RATE = 64.0  # below: Poisson from the table (grid step 1/16) plus a small remainder
_TABLE_STEPS = 16  # grid points per electron: λ_g = floor(16·λ) / 16
_TABLE_GUIDE = 256  # guide-table bins per row (indexed by the top 8 bits of a 32-bit uniform)
_REMAINDER_MAX_COUNT = 30  # P(Poisson(1/16) > 30) < 1e-70: the remainder search stops there
_REMAINDER_RECIPROCALS = 1.0 / np.maximum(np.arange(_REMAINDER_MAX_COUNT + 1, dtype=np.float64), 1.0)
_NORMAL_MIN_RATE = 1e3  # from here: normal approximation
_NORMAL_BOUND = 8.5  # |Z| < 8.3 for every 52-bit uniform (Φ⁻¹(2⁻⁵³) = −8.21)
_TUKEY_P_MIN = 1e-12  # p clamp of the Tukey-lambda inverse CDF (infinite at 0 and 1 for λ < 0)
_TUKEY_LOGISTIC = 1e-6  # |λ| below: the logistic limit log(p / (1 - p))
_TUKEY_SERIES = 1e-3  # |λ| below: Taylor series of the Tukey-lambda variance
_TUKEY_VAR_SERIES = (math.pi**2 / 3.0, -11.387963880031283, 27.646382311762686, -59.826680284056636)

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)
_S30, _S27, _S31, _S12, _S32, _S24 = (np.uint64(n) for n in (30, 27, 31, 12, 32, 24))
_LOW32 = np.uint64(0xFFFFFFFF)
_TWO_M52 = 2.0**-52
_TWO_M32 = 2.0**-32
_HALF52 = np.uint64(1 << 51)
_TOP52 = np.uint64((1 << 52) - 1)
_POW2_NEG = 2.0 ** -np.arange(64, dtype=np.float64)  # the device twin's table (:mod:`.device`); the CPU kernels build 2^-shift from its exponent bits instead
_INF_BITS = np.int32(0x7F800000)  # +inf's float32 bits as int32: a larger int32 is a NaN
_DRAW_KEYS = 64  # stream seeds of draws 0 … 63 computed once per call (later PTRS draws: on the fly)


def _poisson_tables() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Inversion tables of Poisson(λ_g), λ_g = g/16 for g = 0 … 1023 (see the module docstring).

    Returns ``(thresholds, row_start, guide)``: row ``g`` is ``thresholds[row_start[g]:row_start[g + 1]]``
    with ``T_n = ⌈F_g(n)·2³²⌉ − 1`` (``F_g`` the CDF of Poisson(λ_g), float64 sums of the pmf from
    ``exp(n·log λ − λ − lgamma(n + 1))``), its last entry forced to 2³² − 1 where ``F_g > 1 − 2⁻³²``;
    ``guide[g, j]`` is the first ``n`` with ``T_n ≥ j·2²⁴``. A 32-bit uniform integer ``U`` maps to
    ``min{n : U ≤ T_n}``, which has probability ``(T_n − T_{n−1}) / 2³²``: the pmf to within 2⁻³².
    """
    rows = int(_TABLE_MAX_RATE) * _TABLE_STEPS
    width = 160  # > 121, the longest row (λ_g = 63.9375)
    n = np.arange(width, dtype=np.float64)
    log_factorial = np.array([math.lgamma(v + 1.0) for v in n])
    lam = np.arange(1, rows, dtype=np.float64)[:, None] / _TABLE_STEPS
    pmf = np.exp(n * np.log(lam) - lam - log_factorial)
    cdf = np.vstack([np.ones((1, width)), np.cumsum(pmf, axis=1)])  # row 0: Poisson(0) = 0
    scaled = np.minimum(np.ceil(cdf * 2.0**32) - 1.0, 2.0**32 - 1.0)
    lengths = np.argmax(scaled >= 2.0**32 - 1.0, axis=1) + 1
    assert (scaled[np.arange(rows), lengths - 1] == 2.0**32 - 1.0).all() and lengths.max() < min(width, 256)
    row_start = np.zeros(rows + 1, dtype=np.int64)
    row_start[1:] = np.cumsum(lengths)
    thresholds = np.concatenate([scaled[g, : lengths[g]] for g in range(rows)]).astype(np.uint32)
    bins = np.arange(_TABLE_GUIDE, dtype=np.float64) * (2.0**32 / _TABLE_GUIDE)
    guide = np.stack([np.searchsorted(scaled[g, : lengths[g]], bins, side="left") for g in range(rows)]).astype(np.uint8)
    return thresholds, row_start, guide


def _normal_table() -> np.ndarray:
    """Per-bin cubic coefficients ``(c0, c1, c2, c3)`` of Φ⁻¹ on ``p = v·2⁻⁵³``, ``v`` odd in [1, 2⁵²).

    Rows 0 … 63: ``v < 64`` exactly (``c0 = Φ⁻¹(v·2⁻⁵³)``, the other coefficients 0). Rows
    ``64·(e − 5) + s`` for octaves ``e = 6 … 51`` (``2^e ≤ v < 2^(e+1)``) and sub-bins ``s = 0 … 63``
    (the next 6 bits of ``v``): the cubic Hermite interpolant, in the position ``t ∈ [0, 1)``
    within the sub-bin, of Φ⁻¹ and its derivative ``1/φ(z)`` at the two ends
    (``statistics.NormalDist.inv_cdf``, Wichura's AS241, relative error ~1e-16).
    """
    nd = NormalDist()
    rows = np.zeros((64 + 64 * 46, 4), dtype=np.float64)
    rows[1:64, 0] = [nd.inv_cdf(v * 2.0**-53) for v in range(1, 64)]
    for e in range(6, 52):
        width = 2.0 ** (e - 6 - 53)
        p = (64.0 + np.arange(65)) * width
        z = np.array([nd.inv_cdf(float(v)) if v < 0.5 else 0.0 for v in p])
        slope = np.sqrt(2.0 * math.pi) * np.exp(0.5 * z * z) * width  # dz/dt
        z0, z1, d0, d1 = z[:-1], z[1:], slope[:-1], slope[1:]
        block = slice(64 * (e - 5), 64 * (e - 4))
        rows[block] = np.stack([z0, d0, 3.0 * (z1 - z0) - 2.0 * d0 - d1, 2.0 * (z0 - z1) + d0 + d1], axis=1)
    return rows


_POISSON_THRESHOLDS, _POISSON_ROW_START, _POISSON_GUIDE = _poisson_tables()
_NORMAL_COEFFICIENTS = _normal_table()
# The kernels read these as module constants (numba freezes a global array into the compiled code):
# LLVM then knows no store of the kernel can alias them, and vectorises its table reads as gathers.
# The guide table's bytes read as little-endian 32-bit words (entry e is byte e & 3 of word e >> 2,
# :func:`_guide_entry`): the vector loop gathers words and shifts the byte out, where a byte table had LLVM
# read the eight lanes one at a time (x86 has no byte gather). With :func:`_block_lanes`' contiguous loads
# and carried offsets and :func:`_lane`'s independent threshold reads: low light's 5.46 M photosite values
# of a 640 × 480 view 42–49 → 35–36 ms on two threads, the same bytes (docs/degradations-physics.md).
# 256 KiB, as the byte table (the int32 table tried in stop 55 was 1 MiB: numba would not cache its kernel).
# Native uint32 (numba refuses a non-native byte order) with the little-endian words' values.
_GUIDE_WORDS = _POISSON_GUIDE.reshape(-1).view("<u4").astype(np.uint32)
# Two entries past the last row: the vector loop reads T[n + 1] and T[n + 2] whatever n is, and uses them
# only within the row (whose last entry, 2³² − 1, no uniform exceeds).
_POISSON_THRESHOLDS = np.concatenate([_POISSON_THRESHOLDS, np.full(2, 2**32 - 1, np.uint32)])
_NORMAL_FLAT = _NORMAL_COEFFICIENTS.reshape(-1)


# ------------------------------------------------------------ random numbers
@numba.njit(cache=True, inline="always")
def _mix(z: np.uint64) -> np.uint64:
    """splitmix64 finaliser: a bijective 64-bit avalanche."""
    z = (z ^ (z >> _S30)) * _MIX1
    z = (z ^ (z >> _S27)) * _MIX2
    return z ^ (z >> _S31)


@numba.njit(cache=True, inline="always")
def _draw_key(key_mix: np.uint64, draw: int) -> np.uint64:
    """Seed of the splitmix64 stream that gives draw ``draw`` of every value."""
    return _mix(key_mix + np.uint64(draw + 1) * _GOLDEN)


@numba.njit(cache=True, inline="always")
def _stream_keys(key: np.uint64) -> tuple[np.ndarray, np.uint64]:
    """``(keys, key_mix)`` of a capture: the seeds of draws 0 … :data:`_DRAW_KEYS` − 1 (:func:`_draw_key`) and ``mix(key)``."""
    key_mix = _mix(key)
    keys = np.empty(_DRAW_KEYS, dtype=np.uint64)
    for draw in range(_DRAW_KEYS):
        keys[draw] = _draw_key(key_mix, draw)
    return keys, key_mix


@numba.njit(cache=True, inline="always")
def _bits(keys: np.ndarray, key_mix: np.uint64, offset: np.uint64, draw: int) -> np.uint64:
    """Draw ``draw`` of the value at ``offset = i·golden`` as 64 random bits: ``mix(K_draw + offset)``."""
    seed = keys[draw] if draw < _DRAW_KEYS else _draw_key(key_mix, draw)
    return _mix(seed + offset)


@numba.njit(cache=True, inline="always")
def _uniform(keys: np.ndarray, key_mix: np.uint64, offset: np.uint64, draw: int) -> float:
    """Draw ``draw`` of a value as a uniform on the 2⁵² points ``(m + ½)·2⁻⁵²``.

    The values lie in the open interval (0, 1) and are exact doubles (53 bits would round the
    top point to 1.0, where the quantiles are infinite).
    """
    return (np.float64(np.int64(_bits(keys, key_mix, offset, draw) >> _S12)) + 0.5) * _TWO_M52


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


def _bitcast_intrinsic(width: int):  # type: ignore[no-untyped-def]
    """A numba intrinsic: the float of ``width`` (32 or 64) bits whose IEEE bits are the integer of that
    width it is given (an LLVM bitcast: no memory round trip, so it vectorises)."""
    llvm_float = llvmlite.ir.FloatType() if width == 32 else llvmlite.ir.DoubleType()
    numba_float = numba.core.types.float32 if width == 32 else numba.core.types.float64

    def typer(typingctx, bits):  # type: ignore[no-untyped-def]
        if not isinstance(bits, numba.core.types.Integer) or bits.bitwidth != width:
            return None

        def codegen(context, builder, signature, args):  # type: ignore[no-untyped-def]
            return builder.bitcast(args[0], llvm_float)

        return numba_float(bits), codegen

    typer.__name__ = f"_as_float{width}"
    return numba.extending.intrinsic(typer)


_as_float64 = _bitcast_intrinsic(64)
_as_float32 = _bitcast_intrinsic(32)


@numba.njit(cache=True, inline="always")
def _normal(bits: np.uint64) -> float:
    """Standard normal Φ⁻¹(u) of the 52-bit uniform ``u = (m + ½)·2⁻⁵²``, ``m = bits >> 12``, without branches.

    By symmetry ``u' = min(u, 1 − u) = v·2⁻⁵³`` with ``v`` odd; the octave of ``v`` and its next 6
    bits select a cubic of :func:`_normal_table` (3008 pieces, exact values for ``v < 64``). Its
    largest deviation from Φ⁻¹ over all 2⁵² inputs is below 1e-9 (see the module docstring).
    Unsigned arithmetic, the table a module constant and ``2^-shift`` built from its exponent
    bits: LLVM vectorises it (gathers) in the kernel's vector loop.
    """
    m = bits >> _S12
    upper = m >= _HALF52
    m = (_TOP52 - m) if upper else m
    v = m + m + np.uint64(1)
    octave = np.uint64(63) - np.uint64(_leading_zeros(v))
    shift = octave - np.uint64(6) if octave > np.uint64(6) else np.uint64(0)
    row = (v >> shift) + np.uint64(64) * shift  # = 64·(octave − 5) + s, or v below 64
    t = np.float64(np.int64(v & ((np.uint64(1) << shift) - np.uint64(1)))) * _as_float64((np.uint64(1023) - shift) << np.uint64(52))
    at = row * np.uint64(4)
    z = _NORMAL_FLAT[at] + t * (_NORMAL_FLAT[at + np.uint64(1)] + t * (_NORMAL_FLAT[at + np.uint64(2)] + t * _NORMAL_FLAT[at + np.uint64(3)]))
    return -z if upper else z


@numba.njit(cache=True, inline="always")
def _guide_entry(row: np.uint64, high: np.uint64) -> np.uint64:
    """The guide table's first candidate count for table row ``row`` and the 32-bit uniform ``high`` (its top 8 bits)."""
    entry = row * np.uint64(_TABLE_GUIDE) + (high >> _S24)
    return (np.uint64(_GUIDE_WORDS[entry >> np.uint64(2)]) >> ((entry & np.uint64(3)) * np.uint64(8))) & np.uint64(255)


@numba.njit(cache=True, inline="always")
def _poisson_small(rate: float, bits: np.uint64) -> float:
    """Exact Poisson(rate), 0 ≤ rate < 64, as Poisson(λ_g) + Poisson(δ) from one 64-bit draw.

    ``λ_g = ⌊16·rate⌋ / 16`` (exact), ``δ = rate − λ_g ∈ [0, 1/16)``. The high 32 bits pick
    Poisson(λ_g) from its table row through the guide table (≈ 1 comparison); the low 32 bits
    give Poisson(δ) by inversion from 0, skipped without an ``exp`` when ``u < 1 − δ ≤ e^{−δ}``.
    """
    g = int(rate * _TABLE_STEPS)
    delta = rate - g * (1.0 / _TABLE_STEPS)
    high = bits >> _S32
    start = _POISSON_ROW_START[g]
    n = np.int64(_guide_entry(np.uint64(g), high))
    n += np.int64(np.uint64(_POISSON_THRESHOLDS[start + n]) < high)  # the usual single step, without a branch
    while np.uint64(_POISSON_THRESHOLDS[start + n]) < high:
        n += 1
    u = (np.float64(np.int64(bits & _LOW32)) + 0.5) * _TWO_M32
    if u >= 1.0 - delta:  # probability δ < 1/16 (a count > 0: ≈ δ): the exact inversion of Poisson(δ)
        p = math.exp(-delta)
        cdf = p
        m = 0
        while u > cdf and m < _REMAINDER_MAX_COUNT:
            m += 1
            p *= delta * _REMAINDER_RECIPROCALS[m]
            cdf += p
        n += m
    return float(n)


@numba.njit(cache=True, inline="always")
def _poisson_ptrs(rate: float, keys: np.ndarray, key_mix: np.uint64, offset: np.uint64) -> float:
    """Exact Poisson(rate) for rate ≥ 10 by Hörmann's PTRS (1993), from draws 1, 2, … of the value at ``offset``."""
    b = 0.931 + 2.53 * math.sqrt(rate)
    a = -0.059 + 0.02483 * b
    inv_alpha = 1.1239 + 1.1328 / (b - 3.4)
    v_r = 0.9277 - 3.6224 / (b - 2.0)
    draw = 1
    while True:
        u = _uniform(keys, key_mix, offset, draw) - 0.5
        v = _uniform(keys, key_mix, offset, draw + 1)
        draw += 2
        us = 0.5 - abs(u)
        n = math.floor((2.0 * a / us + b) * u + rate + 0.43)
        if us >= 0.07 and v <= v_r:
            return n
        if n < 0.0 or (us < 0.013 and v > us):
            continue
        if math.log(v) + math.log(inv_alpha) - math.log(a / (us * us) + b) <= -rate + n * math.log(rate) - math.lgamma(n + 1.0):
            return n


#: Values per block of :func:`_sensor_kernel`: its vector loop runs over a block, then the scalar loop
#: over the block's few values the vector loop left (the threads take blocks).
_BLOCK = 1024
#: Rate the vector loop clamps its table row to (row 1023: every rate in [63.9375, 64) reads it; lanes
#: outside the table's range read a valid row and discard it).
_TABLE_ROW_RATE = 63.99
#: Margin of the vector loop's decisions on the remainder Poisson(δ) against ``u`` (its ``e^{−δ}`` is a
#: polynomial within ~1e-15 of ``math.exp``'s): a uniform this close to a decision point is left to the
#: scalar loop (never, in practice: the uniforms are 2⁻³² apart).
_REMAINDER_MARGIN = 1e-13


@numba.njit(cache=True, inline="always")
def _signal(x: np.float32, exposure: float) -> float:
    """The exposed signal ``e·x`` of one value in float64: NaN → 0, clamped to ±:data:`SIGNAL_CAP`."""
    s = exposure * np.float64(x)
    s = 0.0 if s != s else s
    return min(max(s, -SIGNAL_CAP), SIGNAL_CAP)


@numba.njit(cache=True, inline="always")
def _value(
    x: np.float32, i: int, exposure: float, k: float, inv_k: float, read_scale: float, read_model: int, read_lambda: float, clip: bool,
    saturated: float, keys: np.ndarray, key_mix: np.uint64, noise: bool,
) -> np.float32:
    """One value's capture (the module docstring's model; the kernel's scalar loop), ``x`` float32 linear light, ``i`` its index."""
    s = _signal(x, exposure)
    signal = np.float32(s)
    if s >= saturated:
        return np.float32(1.0)  # k·Poisson + read noise ≥ 1 for every possible draw: clip gives 1.0
    offset = np.uint64(i) * _GOLDEN
    if k > 0.0:
        rate = s * inv_k  # expected photo-electrons
        if s <= 0.0:
            s = 0.0
        elif rate < _TABLE_MAX_RATE:
            s = k * _poisson_small(rate, _bits(keys, key_mix, offset, 1))
        elif rate < _NORMAL_MIN_RATE:
            s = k * _poisson_ptrs(rate, keys, key_mix, offset)
        else:
            s = max(s + math.sqrt(k * s) * _normal(_bits(keys, key_mix, offset, 1)), 0.0)
    if read_scale > 0.0:
        bits = _bits(keys, key_mix, offset, 0)
        if read_model == READ_GAUSSIAN:
            r = _normal(bits)
        else:
            r = _tukey_quantile((np.float64(np.int64(bits >> _S12)) + 0.5) * _TWO_M52, read_lambda)
        s += read_scale * r
    if clip:
        s = min(max(s, 0.0), 1.0)
    return np.float32(s) - signal if noise else np.float32(s)


@numba.njit(cache=True, inline="always")
def _exp_minus(delta: float) -> float:
    """``e^{−δ}`` for ``0 ≤ δ < 1/16`` by its Taylor polynomial to δ⁸ (truncation < 4e-17; a few ulp of
    rounding): the vector loop's stand-in for ``math.exp``, whose decisions keep a margin against it."""
    d = -delta
    return 1.0 + d * (1.0 + d * (0.5 + d * (1.0 / 6.0 + d * (1.0 / 24.0 + d * (1.0 / 120.0 + d * (1.0 / 720.0 + d * (1.0 / 5040.0 + d * (1.0 / 40320.0))))))))


@numba.njit(cache=True, inline="always")
def _with_read_noise(
    shot: float, signal: np.float32, offset: np.uint64, read_key: np.uint64, read_scale: float, clip: bool, noise: bool,
) -> np.float32:
    """The vector loops' end of :func:`_value` for a value whose shot-noise draw is ``shot`` (float64) and whose signal
    rounded to float32 is ``signal``: Gaussian read noise (draw 0's stream ``read_key``) added, clipped to [0, 1] with
    ``clip``, rounded to float32, less ``signal`` with ``noise``. The scalar's operations in its order."""
    y = shot + read_scale * _normal(_mix(read_key + offset)) if read_scale > 0.0 else shot
    y = min(max(y, 0.0), 1.0) if clip else y
    return np.float32(y) - signal if noise else np.float32(y)


@numba.njit(cache=True, inline="always")
def _lane(
    x: np.float32, offset: np.uint64, exposure: float, k: float, inv_k: float, read_key: np.uint64, shot_key: np.uint64, read_scale: float,
    clip: bool, saturated: float, noise: bool, use_normal: bool,
) -> tuple[np.float32, np.uint8]:
    """:func:`_value` of one Gaussian-read-noise value without branches (the kernel's vector loop), and 1 where
    it cannot say (``offset`` is the value's counter offset ``i·γ``): a rate in PTRS's range, or ≥ 10³ without ``use_normal`` (the normal approximation
    computed too: blocks with such rates), a table search past two steps, a remainder Poisson(δ) above 1 or
    within :data:`_REMAINDER_MARGIN` of a decision (Tukey read noise never comes here). Where the flag is 0 the value is
    :func:`_value`'s, bit for bit: the same float64 operations in the same order, table reads the
    scalar search would make (two steps of it; read side by side, each used only where the step before it was
    taken), ``e^{−δ}``'s comparisons kept apart by their margin."""
    s = _signal(x, exposure)
    signal = np.float32(s)
    rate = s * inv_k
    bits1 = _mix(shot_key + offset)
    in_table = rate < _TABLE_MAX_RATE
    in_normal = rate >= _NORMAL_MIN_RATE
    g = np.int64(min(rate if rate > 0.0 else 0.0, _TABLE_ROW_RATE) * _TABLE_STEPS)  # NaN (0·inf at a k whose 1/k overflows) → row 0
    delta = rate - g * (1.0 / _TABLE_STEPS)
    high = bits1 >> _S32
    row = np.uint64(g)
    start = np.uint64(_POISSON_ROW_START[row])
    n = _guide_entry(row, high)
    first = np.int64(np.uint64(_POISSON_THRESHOLDS[start + n]) < high)
    second = first & np.int64(np.uint64(_POISSON_THRESHOLDS[start + n + np.uint64(1)]) < high)
    unsure = second & np.int64(np.uint64(_POISSON_THRESHOLDS[start + n + np.uint64(2)]) < high)
    n = np.int64(n) + first + second
    u = (np.float64(np.int64(bits1 & _LOW32)) + 0.5) * _TWO_M32
    p0 = _exp_minus(delta)
    cdf1 = p0 + p0 * delta  # the scalar loop's p0 + p0·(δ·1)
    remainder = u >= 1.0 - delta
    at_least_one = u > p0 + _REMAINDER_MARGIN  # the remainder is at least 1 …
    unsure |= np.int64(remainder) & ((np.int64(u >= p0 - _REMAINDER_MARGIN) & np.int64(not at_least_one)) | (np.int64(at_least_one) & np.int64(u >= cdf1 - _REMAINDER_MARGIN)))
    table = k * np.float64(n + (np.int64(remainder) & np.int64(at_least_one)))  # … and exactly 1 where not unsure
    approx = max(s + math.sqrt(max(k * s, 0.0)) * _normal(bits1), 0.0) if use_normal else 0.0
    shot = (0.0 if s <= 0.0 else (table if in_table else approx)) if k > 0.0 else s
    unhandled = (np.int64(in_table) & unsure) | (np.int64(not in_table) & np.int64(not in_normal)) | (np.int64(in_normal) & np.int64(not use_normal))
    drawn = np.int64(s > 0.0) & np.int64(k > 0.0)
    result = _with_read_noise(shot, signal, offset, read_key, read_scale, clip, noise)
    saturates = s >= saturated
    return (np.float32(1.0) if saturates else result), np.uint8(drawn & unhandled & np.int64(not saturates))


@numba.njit(cache=True)
def _scalar_block(
    values: np.ndarray, first: int, out: np.ndarray, to_scalar: np.ndarray, exposure: float, k: float, inv_k: float, read_scale: float,
    read_model: int, read_lambda: float, clip: bool, saturated: float, keys: np.ndarray, key_mix: np.uint64, noise: bool,
) -> None:
    """:func:`_value` into ``out[j]`` for the values ``values[j]`` (of flat index ``first + j``: their counters) whose
    ``to_scalar[j]`` flag is set; eight flags are read as a word, most words being 0. Shared by the kernel, its serial
    twin and :mod:`._photosite_kernel`."""
    count = values.shape[0]
    words = to_scalar.view(np.uint64)
    for w in range(words.size):
        if words[w] == 0:
            continue
        for j in range(8 * w, min(8 * w + 8, count)):
            if to_scalar[j]:
                out[j] = _value(values[j], first + j, exposure, k, inv_k, read_scale, read_model, read_lambda, clip, saturated, keys, key_mix, noise)


@numba.njit(cache=True, inline="always")
def _block_lanes(
    values: np.ndarray, first: int, staged: np.ndarray, to_scalar: np.ndarray, exposure: float, k: float, inv_k: float, read_key: np.uint64,
    shot_key: np.uint64, read_scale: float, clip: bool, saturated: float, noise: bool, use_normal: bool,
) -> None:
    """:func:`_lane` over ``values`` (flat indices ``first`` on) into ``staged`` and ``to_scalar`` (from 0): the loop of
    :func:`_table_block` and :func:`_mixed_block`, inlined into each with ``use_normal`` a constant. It runs from 0 over a
    slice and carries the counter offset by addition: indexed from the block's start, numba's negative-index check kept
    LLVM from proving the loads contiguous (it gathered them), and ``i·γ`` cost a 64-bit vector multiply a value."""
    offset = np.uint64(first) * _GOLDEN  # value i's counter offset i·γ (mod 2⁶⁴), carried by addition
    for j in range(values.shape[0]):
        staged[j], to_scalar[j] = _lane(values[j], offset, exposure, k, inv_k, read_key, shot_key, read_scale, clip, saturated, noise, use_normal)
        offset += _GOLDEN


@numba.njit(cache=True)
def _table_block(
    values: np.ndarray, first: int, staged: np.ndarray, to_scalar: np.ndarray, exposure: float, k: float, inv_k: float, read_key: np.uint64,
    shot_key: np.uint64, read_scale: float, clip: bool, saturated: float, noise: bool,
) -> None:
    """:func:`_block_lanes` for rates below 64 only (the others flagged). Its own compiled function, not inlined:
    the parallel kernel, its serial twin and :mod:`._photosite_kernel` share it (compiled once)."""
    vectorise_table_lookups()  # the loop's table reads gathered on hosts that price them so (Zen 3)
    _block_lanes(values, first, staged, to_scalar, exposure, k, inv_k, read_key, shot_key, read_scale, clip, saturated, noise, False)


@numba.njit(cache=True)
def _mixed_block(
    values: np.ndarray, first: int, staged: np.ndarray, to_scalar: np.ndarray, exposure: float, k: float, inv_k: float, read_key: np.uint64,
    shot_key: np.uint64, read_scale: float, clip: bool, saturated: float, noise: bool,
) -> None:
    """:func:`_table_block` with the normal approximation too (rates ≥ 10³)."""
    vectorise_table_lookups()  # the loop's table reads gathered on hosts that price them so (Zen 3)
    _block_lanes(values, first, staged, to_scalar, exposure, k, inv_k, read_key, shot_key, read_scale, clip, saturated, noise, True)


@numba.njit(cache=True, inline="always")
def _signal_range(bits: np.ndarray, exposure: float, inv_k: float) -> tuple[float, float]:
    """One pass over a block of float32 values given as their bits (int32; float32 and int32 order agree for positive
    values, +inf included; a NaN reads as 0, as :func:`_signal` has it): ``(lowest, top_rate)``. ``lowest``: the exposed
    signal of the smallest value when every one is a positive number, else −1 (:func:`_signal` grows with the value,
    so every value's signal is at least it). ``top_rate``: the expected electron count of the largest value, 0 where
    none is positive."""
    lowest_bits = np.int32(2**31 - 1)
    largest_bits = np.int32(-(2**31))
    for j in range(bits.shape[0]):
        value = bits[j]
        value = value if value <= _INF_BITS else np.int32(0)
        lowest_bits = min(lowest_bits, value)
        largest_bits = max(largest_bits, value)
    lowest = _signal(_as_float32(lowest_bits), exposure) if lowest_bits > 0 else -1.0
    return lowest, (_signal(_as_float32(largest_bits), exposure) * inv_k if largest_bits > 0 else 0.0)


@numba.njit(cache=True, inline="always")
def _normal_lane(
    x: np.float32, offset: np.uint64, exposure: float, k: float, read_key: np.uint64, shot_key: np.uint64, read_scale: float, clip: bool,
    saturated: float, noise: bool,
) -> np.float32:
    """:func:`_lane` of a value whose rate is at least 10³ (a positive signal, ``k > 0``): its normal approximation alone,
    the same float64 operations (the table's lookups and the remainder's polynomial, which it would compute and
    discard, left out); never flagged."""
    s = _signal(x, exposure)
    signal = np.float32(s)
    shot = max(s + math.sqrt(max(k * s, 0.0)) * _normal(_mix(shot_key + offset)), 0.0)
    result = _with_read_noise(shot, signal, offset, read_key, read_scale, clip, noise)
    return np.float32(1.0) if s >= saturated else result


@numba.njit(cache=True)
def _normal_block(
    values: np.ndarray, first: int, staged: np.ndarray, exposure: float, k: float, read_key: np.uint64, shot_key: np.uint64, read_scale: float,
    clip: bool, saturated: float, noise: bool,
) -> None:
    """:func:`_normal_lane` over ``values`` (flat indices ``first`` on) into ``staged``: a block whose every rate is at least 10³."""
    vectorise_table_lookups()
    offset = np.uint64(first) * _GOLDEN
    for j in range(values.shape[0]):
        staged[j] = _normal_lane(values[j], offset, exposure, k, read_key, shot_key, read_scale, clip, saturated, noise)
        offset += _GOLDEN


@numba.njit(cache=True, inline="always")
def _vector_block(
    values: np.ndarray, bits: np.ndarray, first: int, staged: np.ndarray, to_scalar: np.ndarray, out: np.ndarray, gaussian: bool,
    exposure: float, k: float, inv_k: float, read_key: np.uint64, shot_key: np.uint64, read_scale: float, clip: bool, saturated: float,
    noise: bool,
) -> None:
    """One block's vector loop: ``values`` (flat indices ``first`` on; ``bits`` the same values as int32) into ``out`` through
    ``staged``, with the table alone where the block's largest rate is below 64 and with the normal approximation too
    elsewhere, ``to_scalar`` flagging what it leaves to :func:`_scalar_block`; with Tukey read noise (not ``gaussian``)
    every value is flagged. The vector loop writes a block-sized buffer, copied to ``out`` after it: writing ``out``
    directly ran 3.5x slower for some placements of ``out`` against the input (a reused zeroed array: 82 against 23 ms
    for 5.5 M values, the same bytes), likely the store buffer's 4 KiB address aliasing of the streams."""
    count = values.shape[0]
    if not gaussian:
        to_scalar[:count] = np.uint8(1)
        return
    lowest, top_rate = _signal_range(bits, exposure, inv_k)
    if lowest >= saturated:  # every value saturates (over-exposure's bright regions): 1.0 whatever is drawn
        out[:count] = np.float32(1.0)
        to_scalar[:count] = np.uint8(0)
        return
    if lowest * inv_k >= _NORMAL_MIN_RATE:  # every rate in the normal approximation's range
        _normal_block(values, first, staged, exposure, k, read_key, shot_key, read_scale, clip, saturated, noise)
        to_scalar[:count] = np.uint8(0)
    elif top_rate < _TABLE_MAX_RATE:
        _table_block(values, first, staged, to_scalar, exposure, k, inv_k, read_key, shot_key, read_scale, clip, saturated, noise)
    else:
        _mixed_block(values, first, staged, to_scalar, exposure, k, inv_k, read_key, shot_key, read_scale, clip, saturated, noise)
    out[:count] = staged[:count]


@fork_safe
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
    saturated: float,
    key: np.uint64,
    skip: np.ndarray,
    noise: bool,
) -> None:
    """``out[i] = k·Poisson(e·x[i]/k) + read_scale·R`` over flat float32 arrays (see the module docstring).

    ``saturated`` (with ``clip``): a signal ``s`` at or above it gives 1.0 whatever the draws
    (``∞`` without ``clip``; see :func:`_saturation_signal`). ``skip``: empty, or one uint8 per
    value; where it is non-zero ``out[i]`` is its signal ``s`` (float32; clipped with ``clip``)
    and nothing is drawn for it. ``noise``: ``out[i]`` is the capture less the signal instead, both
    rounded to float32 first (numpy's ``capture − float32(s)``, ``s`` clamped to ±SIGNAL_CAP as
    above); 0 where skipped.

    Per block of :data:`_BLOCK` values (:func:`_vector_block`): nothing drawn where every value saturates
    (1.0), the normal approximation alone where every rate is at least 10³ (:func:`_normal_block`), else
    a vector loop (:func:`_lane`, SIMD gathers from the constant tables) with the table alone where the
    block's largest rate is below 64 (float32 order is that of the bits as int32 for positive values) and
    with the normal approximation too elsewhere (a NaN counts as 0, as :func:`_signal` reads it), then
    :func:`_value` for the values it leaves (PTRS, a long table search, a remainder above 1): ~0.3 % of a
    dark view's. With Tukey read noise every value is :func:`_value`'s (no vector loop).
    The bytes are :func:`_value`'s for every value (tested against it), on any thread count. The block
    loops are compiled functions of their own (:func:`_table_block`, :func:`_mixed_block`,
    :func:`_normal_block`, :func:`_scalar_block`) that this kernel, its serial twin and
    :mod:`._photosite_kernel` share: inlined, the kernel took 17 s to compile and its twin as much again.
    """
    keys, key_mix = _stream_keys(key)
    read_key, shot_key = keys[0], keys[1]
    inv_k = 1.0 / k if k > 0.0 else 0.0
    skipping = skip.size > 0
    gaussian = read_model == READ_GAUSSIAN
    bits32 = x.view(np.int32)
    size = x.size
    blocks = (size + _BLOCK - 1) // _BLOCK
    flags = np.zeros(blocks * _BLOCK, np.uint8)  # 1: the scalar loop's (one allocation; ``staged`` is one of 4 KiB a block)
    for block in numba.prange(blocks):
        lo = block * _BLOCK
        hi = min(lo + _BLOCK, size)
        to_scalar = flags[lo : lo + _BLOCK]
        # the block's loops run from 0 over slices: indexed from ``lo``, numba's negative-index check kept LLVM
        # from seeing contiguous loads (it gathered the words and read the skip flags one byte at a time)
        block_x, block_out = x[lo:hi], out[lo:hi]
        every_skipped = skipping
        if skipping:
            block_skip = skip[lo:hi]
            fewest = np.uint8(255)
            for j in range(hi - lo):
                fewest = min(fewest, block_skip[j])
            every_skipped = fewest != 0
        if not every_skipped:  # a block whose every value is skipped (over-exposure's saturated regions) draws nothing
            staged = np.empty(_BLOCK, np.float32)
            _vector_block(block_x, bits32[lo:hi], lo, staged, to_scalar, block_out, gaussian, exposure, k, inv_k, read_key, shot_key,
                          read_scale, clip, saturated, noise)
        if skipping:
            block_skip = skip[lo:hi]
            for j in range(hi - lo):
                s = _signal(block_x[j], exposure)
                unread = np.float32(0.0) if noise else (np.float32(min(max(s, 0.0), 1.0)) if clip else np.float32(s))
                hit = block_skip[j] != 0
                block_out[j] = unread if hit else block_out[j]
                to_scalar[j] = np.uint8(0) if hit else to_scalar[j]
        _scalar_block(block_x, lo, block_out, to_scalar, exposure, k, inv_k, read_scale, read_model, read_lambda, clip, saturated, keys, key_mix, noise)


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


def check_sensor_parameters(what: str, *, k: float, sigma_read: float, read_model: int, key: int, exposure: float = 1.0) -> None:
    """One clear error (``InvalidDataError``, prefixed ``what``) for a sensor parameter no capture can take: ``exposure``,
    ``k`` and ``sigma_read`` finite and ≥ 0, ``read_model`` one of the two, ``key`` in [0, 2⁶⁴)."""
    for name, value in (("exposure", exposure), ("k", k), ("sigma_read", sigma_read)):
        if not (math.isfinite(value) and value >= 0.0):
            raise InvalidDataError(f"{what}: {name} must be a finite number ≥ 0, got {value!r}")
    if read_model not in (READ_GAUSSIAN, READ_TUKEY):
        raise InvalidDataError(f"{what}: read_model must be {READ_GAUSSIAN} (Gaussian) or {READ_TUKEY} (Tukey lambda), got {read_model!r}")
    if not 0 <= key < 2**64:
        raise InvalidDataError(f"{what}: key must be an integer in [0, 2**64), got {key!r}; draw it with stream_key(rng)")


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
    skip: np.ndarray | None = None,
    noise: bool = False,
    out: np.ndarray | None = None,
) -> np.ndarray:
    """Expose linear light by ``exposure`` and add shot and read noise (see the module docstring).

    Args:
        rgb: float32 array (any shape; the photometric plugins pass (H, W, 3)), linear light.
            Not modified.
        exposure: gain e ≥ 0 on linear light.
        k: normalised full scale per photo-electron, ≥ 0 (0: no shot noise).
        sigma_read: read-noise std in normalised linear units, ≥ 0 (0: no read noise).
        key: 63-bit stream key (:func:`~spacedg.plugins.degradations.common.stream_key`).
        read_model: :data:`READ_GAUSSIAN` or :data:`READ_TUKEY`.
        read_lambda: Tukey λ (> −0.5), used when ``read_model == READ_TUKEY``.
        clip: clip the result to [0, 1] (saturation).
        skip: optional array of ``rgb``'s shape, non-zero at values the caller will not use. They are
            not drawn and come back as their exposed signal (NaN → 0, clamped as above, float32;
            clipped with ``clip``); every other value is the same bytes as without ``skip`` (the
            draws are counter-based).
        noise: return the capture less the exposed signal (``y − float32(e·x)`` in float32, x as
            treated above: the bytes of subtracting them in numpy), 0 where skipped; not with ``clip``.
        out: a writeable C-contiguous float32 array of ``rgb``'s size to write into (a workspace the caller
            reuses), apart from ``rgb``; default a new one.

    Returns:
        A float32 array of ``rgb``'s shape (a view of ``out`` when given, else new), always finite.
    """
    check_sensor_parameters("sensor model", k=k, sigma_read=sigma_read, read_model=read_model, key=key, exposure=exposure)
    if noise and clip:
        raise InvalidDataError("sensor model: noise=True returns the unclipped noise; it cannot be combined with clip=True")
    read_scale, read_bound = _read_noise(float(sigma_read), int(read_model), float(read_lambda))
    saturated = _saturation_signal(float(k), read_bound) if clip else math.inf
    flat = kernel_cache.read_only(np.ascontiguousarray(rgb, dtype=np.float32).reshape(-1))
    if out is None:
        out = np.empty(flat.size, dtype=np.float32)
    elif out.dtype != np.float32 or out.size != flat.size or not out.flags.c_contiguous or not out.flags.writeable or np.may_share_memory(out, flat):
        raise InvalidDataError(
            f"sensor model: out must be a writeable C-contiguous float32 array of {flat.size} values apart from the input, "
            f"got {out.dtype} {out.shape}"
        )
    out = out.reshape(-1)
    if skip is None:
        skip_flags = _NO_SKIP
    elif skip.shape != rgb.shape:
        raise InvalidDataError(f"sensor model: skip must have the image's shape {rgb.shape}, got {skip.shape}")
    else:
        flags = skip if skip.dtype in (np.bool_, np.uint8) else skip != 0
        skip_flags = kernel_cache.read_only(np.ascontiguousarray(flags).reshape(-1).view(np.uint8))
    _sensor_kernel(
        flat,
        out,
        float(exposure),
        float(k),
        read_scale,
        int(read_model),
        float(read_lambda),
        bool(clip),
        saturated,
        np.uint64(key),
        skip_flags,
        bool(noise),
    )
    return out.reshape(rgb.shape)


#: ``skip`` of a capture that draws every value.
_NO_SKIP = kernel_cache.read_only(np.zeros(0, np.uint8))


def largest_drop(
    signal_max: np.ndarray, *, k: float, sigma_read: float, read_model: int = READ_GAUSSIAN, read_lambda: float = READ_LAMBDA_DEFAULT,
) -> np.ndarray:
    """The most a capture can fall below its signal: ``s − y ≤ largest_drop(m)`` for every signal
    ``s ≤ m`` (exposed, normalised linear units) and every possible draw; ≥ 0, in ``signal_max``'s
    float dtype (float32 rounds to ~1e-7 relative: callers leave slack).

    Shot noise: a Poisson count can be 0 (``y ≥ 0``, so at most ``s``), and in the normal regime
    (``s ≥ 10³·k``) ``y ≥ s − 8.5·√(k·s)`` (|Z| < 8.3 for every 52-bit uniform), so at most
    ``F(s) = min(s, max(10³·k, 8.5·√(k·s)))``, which grows with ``s``; read noise adds at most its
    largest magnitude (:data:`_NORMAL_BOUND` σ, or the Tukey clamp's quantile). Used to find
    values that saturate (clip to 1.0) whatever is drawn.
    """
    top = np.array(signal_max, ndmin=1)  # a copy, worked on in place (ufuncs return scalars for 0-d arrays)
    if not np.issubdtype(top.dtype, np.floating):
        top = top.astype(np.float64)
    np.maximum(top, top.dtype.type(0.0), out=top)
    if k > 0.0:
        drop = np.sqrt(top * top.dtype.type(k))
        drop *= top.dtype.type(_NORMAL_BOUND)
        np.maximum(drop, top.dtype.type(_NORMAL_MIN_RATE * k), out=drop)
        np.minimum(drop, top, out=drop)
    else:
        drop = np.zeros_like(top)
    drop += top.dtype.type(_read_noise(float(sigma_read), int(read_model), float(read_lambda))[1])
    return drop.reshape(np.shape(signal_max))


def _read_noise(sigma_read: float, read_model: int, read_lambda: float) -> tuple[float, float]:
    """``(scale, bound)`` of the read noise: the factor on the unit-variance variate ``R`` (σ, or σ
    over the Tukey-lambda standard deviation) and the largest ``|scale·R|`` any draw gives
    (:data:`_NORMAL_BOUND` scales, or the Tukey quantile at its clamp)."""
    if read_model == READ_TUKEY and sigma_read > 0.0:
        scale = sigma_read / tukey_lambda_std(read_lambda)
        return scale, scale * _tukey_bound(read_lambda)
    return sigma_read, sigma_read * _NORMAL_BOUND


def _saturation_signal(k: float, read_bound: float) -> float:
    """Smallest signal ``s`` from which the clipped output is 1.0 for every possible draw.

    The read noise is at most ``read_bound``; with shot noise, ``s`` must be in the normal
    regime (``s ≥ 10³·k``; the Poisson samplers can return 0), where ``s + √(k·s)·Z ≥
    s − 8.5·√(k·s)`` (|Z| < 8.3 for every 52-bit uniform). So ``s − 8.5·√(k·s) − read_bound > 1``,
    with margins (10⁻⁹ absolute, 10⁻⁹ relative, 0.1 % on the read bound) far above rounding.
    """
    floor = 1.0 + 1e-9 + 1.001 * read_bound
    if k == 0.0:
        return floor
    root = 0.5 * (_NORMAL_BOUND * math.sqrt(k) + math.sqrt(_NORMAL_BOUND**2 * k + 4.0 * floor))  # √s at equality
    return max(_NORMAL_MIN_RATE * k * (1.0 + 1e-9), root * root * (1.0 + 1e-9) + 1e-9)


def _tukey_bound(lam: float) -> float:
    """Largest |R| of the Tukey-lambda read noise: |Q(p)| at the clamp p = 1e-12 (Q is odd about ½)."""
    p = _TUKEY_P_MIN
    if abs(lam) < _TUKEY_LOGISTIC:
        return abs(math.log(p / (1.0 - p)))
    return abs((math.expm1(lam * math.log(p)) - math.expm1(lam * math.log1p(-p))) / lam)

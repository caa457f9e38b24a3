"""Many numpy generators from integer seeds at once: each exactly ``numpy.random.default_rng(seed)``.

``default_rng(seed)`` spends about 8 µs of its 9 in Python-level set-up, most of it in
:class:`numpy.random.SeedSequence` hashing one seed (``generate_state``). A question family that
gives every candidate its own generator (:func:`~spacedg.plugins.questions.records.child_rngs`)
makes thousands per scene. :func:`pcg64_states` runs the same SeedSequence algorithm (numpy's
documented, version-stable hash: ``mix_entropy`` over a pool of four 32-bit words, then
``generate_state``; all arithmetic modulo 2**32) on a whole array of seeds in a few numpy
passes, and :func:`generator_from_state` makes the generator from its state in under 1 µs:
``PCG64`` seeded by a :class:`_FixedSeedSequence` that hands over the precomputed words. The
draws are bit for bit those of ``default_rng(seed)`` (checked against numpy for seeds of every
word length by the tests), so nothing seeded changes.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.random import PCG64, Generator
from numpy.random.bit_generator import ISeedSequence, SeedSequence

__all__ = ["generator_from_state", "pcg64_states"]

# numpy.random.bit_generator's SeedSequence constants (pool of 4 words, 32-bit hash)
_POOL = 4
_INIT_A, _MULT_A = 0x43B0D7E5, 0x931E8875
_INIT_B, _MULT_B = 0x8B51F9DD, 0x58F38DED
_MIX_L, _MIX_R = 0xCA01F9DD, 0x4973F715
_MASK = 0xFFFFFFFF


class _HashConstants:
    """The running hash constant of ``mix_entropy`` (one sequence for every seed: it depends only on the call count)."""

    def __init__(self, start: int, mult: int) -> None:
        self.value, self.mult = start, mult

    def next(self) -> np.uint32:
        """The constant for this call (then advanced, as ``hashmix`` does)."""
        current = self.value
        self.value = (self.value * self.mult) & _MASK
        return np.uint32(current)


def _hashmix(value: np.ndarray, consts: _HashConstants) -> np.ndarray:
    """SeedSequence's ``hashmix`` on uint32 arrays."""
    const = consts.next()
    value = value ^ const
    value = value * np.uint32((int(const) * _MULT_A) & _MASK)
    return value ^ (value >> np.uint32(16))


def _mix(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """SeedSequence's ``mix`` on uint32 arrays."""
    result = x * np.uint32(_MIX_L) - y * np.uint32(_MIX_R)
    return result ^ (result >> np.uint32(16))


def _pool_words(words: np.ndarray) -> np.ndarray:
    """SeedSequence's ``mix_entropy``: the (n, 4) uint32 pools of seeds whose entropy is ``words`` ((n, k) uint32)."""
    consts = _HashConstants(_INIT_A, _MULT_A)
    zeros = np.zeros(len(words), np.uint32)
    pool = [_hashmix(words[:, i] if i < words.shape[1] else zeros, consts) for i in range(_POOL)]
    for src in range(_POOL):
        for dst in range(_POOL):
            if src != dst:
                pool[dst] = _mix(pool[dst], _hashmix(pool[src], consts))
    for src in range(_POOL, words.shape[1]):
        for dst in range(_POOL):
            pool[dst] = _mix(pool[dst], _hashmix(words[:, src], consts))
    return np.stack(pool, axis=1)


def _entropy_words(seeds: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each seed as SeedSequence coerces an int: its little-endian 32-bit words (one word for a seed below 2**32)."""
    low = (seeds & _MASK).astype(np.uint32)
    high = (seeds >> 32).astype(np.uint32)
    return low, high


def pcg64_states(seeds: Any) -> np.ndarray:
    """(n, 4) uint64: ``SeedSequence(seed).generate_state(4, np.uint64)`` for every seed of ``seeds``
    (integers in [0, 2**63)), i.e. the words ``PCG64(seed)`` is seeded from."""
    seeds = np.asarray(seeds, dtype=np.int64).reshape(-1)
    if seeds.size and int(seeds.min()) < 0:
        raise ValueError("pcg64_states: seeds must be non-negative integers below 2**63")
    low, high = _entropy_words(seeds)
    pools = np.empty((len(seeds), _POOL), np.uint32)
    two = high != 0
    if (~two).any():
        pools[~two] = _pool_words(low[~two, None])
    if two.any():
        pools[two] = _pool_words(np.stack([low[two], high[two]], axis=1))
    consts = _HashConstants(_INIT_B, _MULT_B)
    out = np.empty((len(seeds), 2 * _POOL), np.uint32)
    for i in range(2 * _POOL):  # generate_state(4, uint64): 8 words, the pool read cyclically
        const = consts.next()
        value = pools[:, i % _POOL] ^ const
        value = value * np.uint32((int(const) * _MULT_B) & _MASK)
        out[:, i] = value ^ (value >> np.uint32(16))
    return out.view("<u8").astype(np.uint64).reshape(len(seeds), _POOL)


class _FixedSeedSequence(ISeedSequence):
    """A seed sequence that hands ``PCG64`` the words :func:`pcg64_states` computed (and, if ever asked
    for anything else, delegates to the real ``SeedSequence(seed)``)."""

    __slots__ = ("words", "seed")

    def __init__(self, words: np.ndarray, seed: int) -> None:
        self.words, self.seed = words, seed

    def generate_state(self, n_words: int, dtype: Any = np.uint32) -> np.ndarray:
        if n_words == _POOL and np.dtype(dtype) == np.uint64:
            return self.words
        return SeedSequence(self.seed).generate_state(n_words, dtype)


def generator_from_state(words: np.ndarray, seed: int) -> Generator:
    """``numpy.random.default_rng(seed)``, made from ``words`` = ``pcg64_states([seed])[0]``."""
    return Generator(PCG64(_FixedSeedSequence(np.ascontiguousarray(words, dtype=np.uint64), int(seed))))

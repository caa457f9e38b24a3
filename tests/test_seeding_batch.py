"""Generators made from batched PCG64 states (:func:`spacedg.seeding.pcg64_states`) are ``default_rng(seed)`` bit for bit."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.random import SeedSequence

from spacedg.plugins.questions.records import ChildGenerators, child_rngs
from spacedg.seeding import generator_from_state, pcg64_states

#: Seeds of every entropy length SeedSequence distinguishes (one 32-bit word, two words) and the edges.
EDGES = [0, 1, 2, 2**31, 2**32 - 1, 2**32, 2**32 + 1, 2**62, 2**63 - 1]


def _seeds() -> list[int]:
    gen = np.random.default_rng(7)
    return EDGES + gen.integers(0, 2**63 - 1, 300).tolist() + gen.integers(0, 2**32, 100).tolist()


def test_states_equal_seed_sequence_for_every_word_length() -> None:
    seeds = _seeds()
    states = pcg64_states(seeds)
    assert states.shape == (len(seeds), 4) and states.dtype == np.uint64
    for seed, words in zip(seeds, states):
        assert words.tolist() == SeedSequence(seed).generate_state(4, np.uint64).tolist(), seed


@pytest.mark.parametrize("seed", EDGES[:5] + [123456789012345678])
def test_generator_from_state_draws_as_default_rng(seed: int) -> None:
    fast, plain = generator_from_state(pcg64_states([seed])[0], seed), np.random.default_rng(seed)
    assert fast.bit_generator.state == plain.bit_generator.state
    assert fast.permutation(9).tolist() == plain.permutation(9).tolist()
    assert fast.integers(0, 2**40, 20).tolist() == plain.integers(0, 2**40, 20).tolist()
    assert fast.random(5).tolist() == plain.random(5).tolist()
    # anything but PCG64's own request goes to the real SeedSequence of the seed
    assert fast.bit_generator.seed_seq.generate_state(3).tolist() == SeedSequence(seed).generate_state(3).tolist()


def test_states_refuse_negative_seeds_and_take_an_empty_batch() -> None:
    with pytest.raises(ValueError, match="non-negative"):
        pcg64_states([5, -1])
    assert pcg64_states([]).shape == (0, 4)


def test_child_generators_past_the_one_by_one_ones_are_the_same_generators() -> None:
    children = child_rngs(np.random.default_rng(3), 3 * ChildGenerators.ONE_BY_ONE)
    seeds = np.random.default_rng(3).integers(0, 2**63 - 1, size=len(children), dtype=np.int64).tolist()
    order = np.random.default_rng(0).permutation(len(children)).tolist()  # any access order
    for k in order:
        assert children[k].bit_generator.state == np.random.default_rng(seeds[k]).bit_generator.state
        assert children[k] is children[k]
    assert children._states is not None  # the batched path did run


def test_a_batched_generator_spawns_and_reports_as_default_rng() -> None:
    seed = 2**40 + 17
    fast, plain = generator_from_state(pcg64_states([seed])[0], seed), np.random.default_rng(seed)
    assert fast.bit_generator.seed_seq.entropy == plain.bit_generator.seed_seq.entropy == seed
    assert fast.bit_generator.seed_seq.n_children_spawned == 0
    for _ in range(2):  # children counted as numpy counts them: the second spawn gives new children
        kids_fast, kids_plain = fast.spawn(2), plain.spawn(2)
        assert [k.random() for k in kids_fast] == [k.random() for k in kids_plain]
    assert fast.bit_generator.seed_seq.n_children_spawned == 4


def test_a_batched_generator_pickles_copies_and_reads_as_default_rng() -> None:
    import copy
    import pickle

    seed = 987654321987
    fast, plain = generator_from_state(pcg64_states([seed])[0], seed), np.random.default_rng(seed)
    fast.random(3), plain.random(3)
    for clone in (pickle.loads(pickle.dumps(fast)), copy.deepcopy(fast)):
        assert clone.bit_generator.state == plain.bit_generator.state
    assert repr(fast.bit_generator.seed_seq) == repr(plain.bit_generator.seed_seq)
    assert fast.random(4).tolist() == plain.random(4).tolist()


def test_shuffled_takes_the_draws_of_permutation() -> None:
    """``shuffled(items, rng)`` is ``[items[i] for i in rng.permutation(len(items))]`` with the generator
    left in the same state, for every length the question families shuffle (and longer), from lists,
    tuples and ranges: the question indexes rely on it byte for byte."""
    from spacedg.seeding import shuffled

    for seed in range(25):
        ours, theirs = np.random.default_rng(seed), np.random.default_rng(seed)
        for n in [*range(0, 41), 255, 256, 257, 1000, 4321]:
            items = [f"item{k}" for k in range(n)]
            for source in (items, tuple(items)):
                assert shuffled(source, ours) == [items[i] for i in theirs.permutation(n)]
            assert shuffled(range(n), ours) == theirs.permutation(n).tolist()
        assert ours.bit_generator.state == theirs.bit_generator.state

"""The pair-family factory: a two-view object question family made from one record stream per view pair.

Four built-in families ask about objects found in two images (``inter_object_distance``,
``cross_view_cardinal_direction``, ``object_proxy_cardinal_direction``,
``object_size_comparison``). Each writes only what is its own: a **pair stream**
``stream(scene, index, pair, rules, rng)`` yielding the pair's records in a seeded order
(:data:`~spacedg.plugins.questions.records.PairStream`). The rest is the same for all of them
and lives here:

- :func:`pair_records`, the family's ``generate``: the
  :class:`~spacedg.plugins.questions.view_sampling.VisibilityIndex` of the scene under
  ``thresholds``, the pairs of :func:`~spacedg.plugins.questions.view_sampling.sample_pairs`
  (``pair_rules``, ``rng``), visited round-robin, one record of each pair's stream per round
  (:func:`~spacedg.plugins.questions.records.round_robin_pairs`). Lazy: nothing is drawn or
  built before the first ``next``; every stream draws from the one ``rng``, so the same seed
  gives the same records in the same order.
- :func:`pair_family`, the family's declaration (a
  :class:`~spacedg.plugins.question_family.FamilyFactory`): two views, needs
  :data:`PAIR_NEEDS` (per-view visibility and view covisibility), ``generate`` =
  :func:`pair_records` of the stream; its options are the visibility ``thresholds`` and the
  ``pair_rules`` (default :data:`~spacedg.plugins.questions.view_sampling.OBJECT_PAIRS`:
  covisibility > 0.25, baseline >= 0.2 m).
- :func:`view_and_pair_family`: the declaration of a family that asks in one image and in two
  (``camera_object_distance_estimation``, ``camera_object_relative_direction``): its own
  ``generate`` interleaves a single-view sub type with two-view ones
  (:func:`~spacedg.plugins.questions.records.round_robin_sub_types`); one or two views, needs
  :data:`PAIR_NEEDS`.
- :func:`object_pairs`: the candidates of the families that name object 1 in image A and
  object 2 in image B (both :func:`~spacedg.plugins.questions.records.referable` there),
  in a lazily drawn seeded order.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np

from spacedg.plugins.qa_record import QARecord
from spacedg.plugins.question_family import FamilyFactory
from spacedg.plugins.questions.records import PairStream, lazy_permutation, referable_ids, round_robin_pairs
from spacedg.plugins.questions.view_sampling import OBJECT_PAIRS, PairRules, ViewPair, VisibilityIndex
from spacedg.scene.model import Instance, Scene
from spacedg.scene.visibility_classes import DEFAULT_THRESHOLDS, VisibilityThresholds

__all__ = ["PAIR_NEEDS", "object_pairs", "pair_family", "pair_records", "view_and_pair_family"]

#: What a pair family reads from the scene: per-view instance visibility and view covisibility.
PAIR_NEEDS: frozenset[str] = frozenset({"visibility", "covisibility"})


def pair_records(
    scene: Scene,
    rng: np.random.Generator,
    thresholds: VisibilityThresholds = DEFAULT_THRESHOLDS,
    pair_rules: PairRules = OBJECT_PAIRS,
    *,
    stream: PairStream,
) -> Iterator[QARecord]:
    """Every record of ``stream`` over the view pairs of ``scene``, lazily, one per pair per round (module docstring)."""
    yield from round_robin_pairs(scene, VisibilityIndex(scene, thresholds), pair_rules, rng, stream)


def pair_family(stream: PairStream, **declaration: Any) -> FamilyFactory:
    """The factory of the two-view family whose ``generate`` is :func:`pair_records` of ``stream``.

    ``declaration``: ``name``, ``task_group``, ``answer_types``, ``sub_question_types`` and
    ``description``, as :class:`~spacedg.plugins.question_family.FamilyFactory`. Num views
    ``(2,)``, needs :data:`PAIR_NEEDS`; the options are :func:`pair_records`' ``thresholds`` and
    ``pair_rules``: ``make_family = pair_family(...)``, ``FAMILY = make_family()`` (the
    defaults), ``make_family(thresholds, pair_rules)``.
    """
    return FamilyFactory(functools.partial(pair_records, stream=stream), num_views=(2,), needs=PAIR_NEEDS, **declaration)


def view_and_pair_family(generate: Callable[..., Iterator[QARecord]], **declaration: Any) -> FamilyFactory:
    """The factory of the family whose ``generate`` asks in one image and in two (:func:`~spacedg.plugins.questions.records.round_robin_sub_types`).

    ``declaration`` as :func:`pair_family`'s. Num views ``(1, 2)``, needs :data:`PAIR_NEEDS`; the
    options are ``generate``'s own (its visibility thresholds and the rules of each two-view sub
    type): ``make_family = view_and_pair_family(generate, ...)``, ``FAMILY = make_family()`` (the
    defaults).
    """
    return FamilyFactory(generate, num_views=(1, 2), needs=PAIR_NEEDS, **declaration)


def object_pairs(index: VisibilityIndex, pair: ViewPair, rng: np.random.Generator) -> Iterator[tuple[Instance, Instance]]:
    """``(object 1, object 2)``: object 1 referable in image A, object 2 in image B, distinct instances.

    The candidates are the ``len(ones) · len(twos)`` combinations of
    :func:`~spacedg.plugins.questions.records.referable_ids` of A (``ones``) and of B
    (``twos``), candidate ``k`` = ``(ones[k // len(twos)], twos[k % len(twos)])``, walked in the
    order of :func:`~spacedg.plugins.questions.records.lazy_permutation` of their number and
    ``rng``: its draws are taken only as the caller asks for more, so a caller drawing from
    ``rng`` between candidates interleaves with it the same way on every run. The same instance
    twice is skipped. Either object may also be seen in the other image; nothing is required there.
    """
    ones, twos = referable_ids(index, pair.a), referable_ids(index, pair.b)
    for k in lazy_permutation(len(ones) * len(twos), rng):
        i, j = divmod(k, len(twos))
        if ones[i] != twos[j]:
            yield index.instance(ones[i]), index.instance(twos[j])

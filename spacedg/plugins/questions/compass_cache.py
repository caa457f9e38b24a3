"""Compass questions of one pair stream with their frames memoised (the same numbers, fewer operations).

A pair stream of a compass family (``cross_view_cardinal_direction``, ``object_proxy_cardinal_direction``)
asks :func:`~spacedg.plugins.questions.records.compass_question` about every pair of a
reference leg and a query leg, and the same reference leg recurs with many queries (object 1
in image A with every object 2 in image B). :class:`CompassQuestions` gives exactly what
``compass_question(reference, query, up, rng)`` gives, with the same draws in the same order,
but computes the compass frame (:func:`~spacedg.plugins.questions.geometry.compass_frame`) and
its ground axes (:func:`~spacedg.plugins.questions.geometry.ground_axes`) once per
(reference, assumed cardinal) from the reference's :func:`~spacedg.plugins.questions.geometry.compass_basis`
(once per reference), each query's ground projection once, and the angle
(:func:`~spacedg.plugins.questions.geometry.angle_on_ground` of the memoised parts, the same
operations :func:`~spacedg.plugins.questions.geometry.ground_angle` performs) and its sector once
per (reference, assumed cardinal, query): a triplet recurs in many view pairs.
"""

from __future__ import annotations

from collections.abc import Hashable, Sequence
from typing import Any

import numpy as np

from spacedg.plugins.questions.geometry import (
    CARDINALS,
    COMPASS_SECTORS,
    SectorHit,
    angle_on_ground,
    build_mcq,
    compass_basis,
    compass_turn,
    ground_axes,
    horizontal,
    on_compass_boundary,
)
from spacedg.plugins.questions.records import compass_entries, index_memo
from spacedg.plugins.questions.view_sampling import VisibilityIndex
from spacedg.seeding import draw_index

__all__ = ["CompassQuestions", "compass_questions"]


class CompassQuestions:
    """``compass_question`` for one stream; legs are named by hashable keys unique within it (module docstring)."""

    def __init__(self, up: np.ndarray) -> None:
        self.up = np.asarray(up, dtype=np.float64)
        self._frames: dict[tuple[Hashable, str], tuple[np.ndarray, np.ndarray, tuple[np.ndarray, np.ndarray]]] = {}
        self._bases: dict[Hashable, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        self._flats: dict[Hashable, np.ndarray] = {}
        self._answers: dict[tuple[Hashable, str, Hashable], tuple[float, SectorHit]] = {}  # the angle and sector of a (frame, query)

    def ask(
        self, reference_key: Hashable, reference: Sequence[float], query_key: Hashable, query: Sequence[float], rng: np.random.Generator,
    ) -> tuple[str, tuple[str, ...], str, dict[str, Any]] | None:
        """``(assumed_dir, options, letter, block)``, or ``None``: what
        ``compass_question(np.asarray(reference), np.asarray(query), up, rng)`` returns (the same draws)."""
        assumed = CARDINALS[draw_index(rng, len(CARDINALS))]
        frame = self._frames.get((reference_key, assumed))
        if frame is None:
            basis = self._bases.get(reference_key)
            if basis is None:
                basis = self._bases[reference_key] = compass_basis(np.asarray(reference), self.up)
            north, east = compass_turn(basis, assumed)  # = compass_frame(reference, assumed, up)
            frame = self._frames[(reference_key, assumed)] = (north, east, ground_axes(north, self.up))
        north, east, axes = frame
        answer = self._answers.get((reference_key, assumed, query_key))
        if answer is None:
            flat = self._flats.get(query_key)
            if flat is None:
                flat = self._flats[query_key] = horizontal(np.asarray(query), self.up)
            angle = angle_on_ground(axes, flat)
            answer = self._answers[(reference_key, assumed, query_key)] = (angle, COMPASS_SECTORS.classify(angle))
        angle, hit = answer
        if on_compass_boundary(hit):
            return None
        label = COMPASS_SECTORS.labels[hit.index]
        block = compass_entries(assumed, label, angle, hit, north, east)
        options, letter = build_mcq(label, COMPASS_SECTORS.distractors(hit, rng), rng)
        return assumed, options, letter, block


def compass_questions(index: VisibilityIndex, up: np.ndarray) -> CompassQuestions:
    """The scene's :class:`CompassQuestions` (one per index and ``up``, memoised on the index:
    legs recur across view pairs, so the keys must name what fixes a leg, e.g. ``("camera", view, id)``)."""
    memo = index_memo(index, "compass_questions")
    key = tuple(float(v) for v in np.asarray(up, dtype=np.float64))
    if key not in memo:
        memo[key] = CompassQuestions(up)
    return memo[key]

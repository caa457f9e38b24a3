"""Inter-object distance (``question_type = "inter_object_distance"``; object-centric, 2 views, NA).

Sub type ``two_view`` (SPEC-QA, type 6; paper appendix "Object-Object Distance"). Object 1 is
clearly visible in image A, object 2 clearly visible in image B; the answer is the Euclidean
distance between their oriented-box centres, ``|c_1 − c_2|`` in **metres**, rounded to
:data:`DECIMALS` = 3 decimals (invariant under any rigid motion of the scene; ``Scene.up`` plays
no part).

Objects (decisions in brackets):

- pairs of views from :func:`~spacedg.plugins.questions.view_sampling.sample_pairs` with
  :data:`~spacedg.plugins.questions.view_sampling.OBJECT_PAIRS` (covisibility > 0.25, baseline ≥ 0.2 m);
- object 1 clearly visible in A and object 2 clearly visible in B, each without a description
  clash in that view (:func:`~spacedg.plugins.questions.view_sampling.description_clash`; together
  :func:`~spacedg.plugins.questions.records.referable`); either may also be seen in the other
  image (nothing required there);
- distinct instances with different labels (:func:`~spacedg.plugins.questions.view_sampling.label_key`);
- [skipped when the centres are closer than :data:`MIN_DISTANCE_M` = 0.05 m: such boxes
  practically coincide (duplicate or nested annotations), and a relative-accuracy score on a
  distance of a few centimetres measures annotation noise; a rounded answer of 0 would also
  make the relative error undefined.]

Question: the two marker sentences, then the paper's wording on its own lines::

    In image A, find the red lamp. In image B, find the wooden chair.
    Estimate the 3D metric distance (in meters) between the centers of these two physical objects.
    Return only one number in meters (e.g., 1.2).

(The paper's last line "Output format: <answer>NUMBER</answer>" is left out: the evaluation
system prompt asks for the tags, as in ``camera_object_distance_estimation``.)

Order: pairs in ``sample_pairs`` order, visited round-robin (one record per pair per round;
the family is made by :func:`~spacedg.plugins.questions.pairs.pair_family`); each pair's
(object 1, object 2) candidates in a lazily drawn seeded permutation
(:func:`~spacedg.plugins.questions.pairs.object_pairs`). Same seed, same records in the same
order; everything is lazy.

Geometry block (JSON): ``up``; ``cameras`` (view → 4×4 ``cam_to_world``); ``objects`` (id,
label, description, box ``center``/``extents``/``rotation``); ``refs`` (``[{"id", "label",
"description", "view"}]``); ``visibility``; ``visibility_thresholds``; ``vector`` (``c_2 − c_1``,
metres); ``distance_m`` (unrounded); ``decimals``; ``thresholds`` (``min_distance_m``);
``template`` (always 0); ``pair``; ``pair_rules``; ``selection`` (subject = the unordered
object pair: the question index asks a pair once per scene, whatever the views).
"""

from __future__ import annotations

import functools
from collections.abc import Iterator
from typing import Any

import numpy as np

from spacedg.plugins.qa_record import QARecord
from spacedg.plugins.candidates import PASSED_OVER, Candidate, admitted, offer
from spacedg.scene.model import Instance, Scene
from spacedg.plugins.questions.view_sampling import (
    PairRules,
    ViewPair,
    VisibilityIndex,
    label_key,
)
from spacedg.plugins.hookspecs import registering
from spacedg.plugins.questions.language import find_in_image
from spacedg.plugins.questions.pairs import object_pairs, pair_family
from spacedg.plugins.questions.records import index_memo, make_record, objects_block, phrase, selection_entry
from spacedg.plugins.specs import AnswerType, TaskGroup

__all__ = ["DECIMALS", "FAMILY", "MIN_DISTANCE_M", "NAME", "SUB_QUESTION_TYPE", "TEMPLATE", "make_family", "render_question"]

NAME = "inter_object_distance"
SUB_QUESTION_TYPE = "two_view"
#: The paper's wording after the markers.
TEMPLATE = (
    "Estimate the 3D metric distance (in meters) between the centers of these two physical objects.\n"
    "Return only one number in meters (e.g., 1.2)."
)
#: Answers are metres rounded to this many decimals.
DECIMALS = 3
#: Centres closer than this (metres) are skipped.
MIN_DISTANCE_M = 0.05


def render_question(phrase1: str, phrase2: str) -> str:
    """Markers for object 1 in image A and object 2 in image B, then the paper's question."""
    return f"{find_in_image(phrase1, 0)} {find_in_image(phrase2, 1)}\n{TEMPLATE}"


def _record(
    scene: Scene, index: VisibilityIndex, pair: ViewPair, rules: PairRules, one: Instance, two: Instance, vector: np.ndarray, distance: float,
) -> QARecord:
    """The record of one candidate (``vector``: centre 1 → centre 2, ``distance`` its length, metres)."""
    views = (pair.a, pair.b)
    geometry = {
        **objects_block(scene, index, views, [one, two], [(one, pair.a), (two, pair.b)]),
        "vector": vector.tolist(),
        "distance_m": distance,
        "decimals": DECIMALS,
        "thresholds": {"min_distance_m": MIN_DISTANCE_M},
        "template": 0,
        "pair": pair.to_dict(),
        "pair_rules": rules.to_dict(),
        "selection": _selection(one, two),
    }
    return make_record(
        scene, NAME, SUB_QUESTION_TYPE, TaskGroup.OBJECT_CENTRIC, AnswerType.NA, views, {"objects": [one.id, two.id]},
        question=render_question(phrase(one), phrase(two)), answer=round(distance, DECIMALS), geometry=geometry,
    )


def _subject(one: Instance, two: Instance) -> str:
    """The selection subject: the unordered object pair."""
    return f"objects:{min(one.id, two.id)}|{max(one.id, two.id)}"


def _selection(one: Instance, two: Instance) -> dict[str, Any]:
    """The selection entry: the subject only (a metric answer)."""
    return selection_entry(_subject(one, two))


def _pair_stream(scene: Scene, index: VisibilityIndex, pair: ViewPair, rules: PairRules, rng: np.random.Generator) -> Iterator[QARecord | Candidate]:
    views = (pair.a, pair.b)
    memo = index_memo(index, "centre_distance")  # (id 1, id 2) → (vector, distance): a pair recurs in many view pairs
    for one, two in object_pairs(index, pair, rng):
        if label_key(one.label) == label_key(two.label):
            continue
        key = (one.id, two.id)
        hit = memo.get(key)
        if hit is None or hit[0] is not one or hit[1] is not two:
            vector = two.box.center - one.box.center
            hit = memo[key] = (one, two, vector, float(np.linalg.norm(vector)))
        vector, distance = hit[2], hit[3]
        if distance < MIN_DISTANCE_M:
            continue
        subject, named = _subject(one, two), (one.id, two.id)
        if not admitted(SUB_QUESTION_TYPE, views, subject, named):
            yield PASSED_OVER  # the caller passes it over
            continue
        yield offer(
            SUB_QUESTION_TYPE, views, subject, named, functools.partial(_selection, one, two),
            functools.partial(_record, scene, index, pair, rules, one, two, vector, distance),
        )


#: ``make_family(thresholds, pair_rules)``: this family with other visibility thresholds / pair rules
#: (:func:`~spacedg.plugins.questions.pairs.pair_family`); :data:`FAMILY`, the registered one, uses the defaults.
make_family = pair_family(
    _pair_stream, name=NAME, task_group=TaskGroup.OBJECT_CENTRIC, answer_types={AnswerType.NA}, sub_question_types=(SUB_QUESTION_TYPE,),
    description="Metric distance between the centres of an object seen in image A and a differently labelled one seen in image B.",
    metric_only=True,
)
FAMILY = make_family()
spacedg_register_question_families = registering(FAMILY)

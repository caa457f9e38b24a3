"""Which of four named objects is closest to the camera (an example third-party question family).

``question_type = "nearest_object"``, sub type ``closest_of_four``; camera-object, 1 view, MCQ.
Written only against the public authoring API (:mod:`spacedg.plugins.authoring`).

The question names four objects seen in one image; the answer is the one whose box centre is
nearest to the camera centre (:func:`~spacedg.plugins.authoring.camera_distance`: Euclidean,
world metres, the measure of ``camera_object_distance_estimation``). Rules:

- every named object is *referable* in the view (clearly visible, no same-label instance with
  the same description in the image), and the four phrases differ;
- the closest object is at least :data:`MIN_MARGIN_M` nearer than each of the other three, so
  box sizes and annotation noise cannot flip the answer.

A candidate is a (view, closest object) pair; its three distractors are drawn from the
objects that are far enough, and :func:`~spacedg.plugins.authoring.build_mcq` deals the options
(the correct letter is uniform over A–D across a generation). Views are visited round-robin in
a seeded order, each view's closest-object candidates in a seeded order; every draw comes
from ``rng``, so a seed gives the same records.

Geometry block: :func:`~spacedg.plugins.authoring.objects_block` of the four objects **in
option order** (``up``, ``cameras``, ``objects``, ``refs``, ``visibility``,
``visibility_thresholds``), plus ``view``, ``distances_m`` (camera centre → box centre of each
option's object, metres) and ``min_margin_m``. The answer is re-derivable from it alone: the
letter of the smallest distance from ``cameras[view]``'s translation to ``objects[k].center``.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator

import numpy as np

from spacedg.plugins.authoring import (
    AnswerType,
    Instance,
    QARecord,
    QuestionFamily,
    Scene,
    TaskGroup,
    VisibilityIndex,
    build_mcq,
    camera_distance,
    hookimpl,
    make_record,
    objects_block,
    phrase,
    phrase_key,
    referable_ids,
    round_robin_views,
    seeded_order,
)

__all__ = ["FAMILY", "MIN_MARGIN_M", "NAME", "QUESTION", "SUB_QUESTION_TYPE", "distance_m", "generate", "namable"]

NAME = "nearest_object"
SUB_QUESTION_TYPE = "closest_of_four"
#: The closest object is at least this much nearer to the camera than each distractor, metres.
MIN_MARGIN_M = 0.25
QUESTION = "Which of these objects is closest to the camera that took this image, measured to the centre of each object?"


def distance_m(scene: Scene, view: str, inst: Instance) -> float:
    """Distance from the centre of ``view``'s camera to the centre of ``inst``'s box, metres."""
    return camera_distance(scene.views[view], inst.box.center)


def namable(index: VisibilityIndex, view: str) -> list[Instance]:
    """The objects a question may name in ``view``: referable, with a phrase no other referable object shares."""
    objects = [index.instance(i) for i in referable_ids(index, view)]
    keys = [phrase_key(inst) for inst in objects]
    return [inst for inst, key in zip(objects, keys) if keys.count(key) == 1]


def _record(scene: Scene, index: VisibilityIndex, view: str, closest: Instance, others: list[Instance], rng: np.random.Generator) -> QARecord:
    options, letter = build_mcq(phrase(closest), [phrase(inst) for inst in others], rng)
    by_phrase = {phrase(inst): inst for inst in (closest, *others)}
    in_order = [by_phrase[option[3:]] for option in options]  # "A. text" → the object it names
    geometry = {
        **objects_block(scene, index, (view,), in_order, [(inst, view) for inst in in_order]),
        "view": view,
        "distances_m": [distance_m(scene, view, inst) for inst in in_order],
        "min_margin_m": MIN_MARGIN_M,
    }
    key = {"closest": closest.id, "others": sorted(inst.id for inst in others)}
    return make_record(
        scene, NAME, SUB_QUESTION_TYPE, TaskGroup.CAMERA_OBJECT, AnswerType.MCQ, (view,), key,
        question=QUESTION, answer=letter, geometry=geometry, options=options,
    )


def _view_records(scene: Scene, index: VisibilityIndex, view: str, rng: np.random.Generator) -> Iterator[QARecord]:
    """Every question of one view: each object that has three far-enough distractors, in a seeded order."""
    objects = namable(index, view)
    distance = {inst.id: distance_m(scene, view, inst) for inst in objects}
    for closest in seeded_order(objects, rng):
        farther = [inst for inst in objects if distance[inst.id] >= distance[closest.id] + MIN_MARGIN_M]
        if len(farther) < 3:
            continue
        others = [farther[int(k)] for k in rng.choice(len(farther), size=3, replace=False)]
        yield _record(scene, index, view, closest, others, rng)


def generate(scene: Scene, rng: np.random.Generator) -> Iterator[QARecord]:
    """Every valid question of ``scene``: views round-robin in a seeded order (see the module docstring)."""
    yield from round_robin_views(scene, VisibilityIndex(scene), rng, _view_records)


FAMILY = QuestionFamily(
    name=NAME,
    task_group=TaskGroup.CAMERA_OBJECT,
    answer_types=frozenset({AnswerType.MCQ}),
    sub_question_types=(SUB_QUESTION_TYPE,),
    num_views=(1,),
    generate=generate,
    needs=frozenset({"visibility"}),
    description=f"Which of four named objects is closest to the camera (by at least {MIN_MARGIN_M} m, box centres).",
)


@hookimpl
def spacedg_register_question_families(register: Callable[[QuestionFamily], None]) -> None:
    """Register :data:`FAMILY`."""
    register(FAMILY)

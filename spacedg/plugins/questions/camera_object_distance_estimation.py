"""Camera–object distance (``question_type = "camera_object_distance_estimation"``; camera-object, NA).

Answer: the straight-line distance in **metres** from a camera centre (the translation of
``Camera.cam_to_world``) to an object's centre (its oriented box centre), rounded to
:data:`DECIMALS` = 3 decimals. Distances are invariant under a rigid motion of the scene.

Sub types (SPEC-QA, type 3):

``single_view`` (1 view)
    The object is clearly visible in the view (:class:`~spacedg.plugins.questions.view_sampling.VisibilityIndex`
    ``visible``) and no other same-label instance with the same description is seen there
    (:func:`~spacedg.plugins.questions.view_sampling.description_clash`; together
    :func:`~spacedg.plugins.questions.records.referable`). The object is named by
    :func:`~spacedg.plugins.questions.language.object_phrase`. The four paper templates
    (:data:`TEMPLATES`, drawn by ``rng``) are kept, with one **deviation**: each states the
    unit and that the distance is measured to the object's centre (the paper's templates 1–3
    give no unit, and none says which point of the object is meant; the answer is in metres
    to the box centre, so the question says so).
``bbox_center_distance`` (2 views, :data:`~spacedg.plugins.questions.view_sampling.OBJECT_PAIRS`:
    covisibility > 0.25, baseline >= 0.2 m)
    The object is clearly visible in image A **and** in image B, and has no description clash
    in either (decision: B is checked too, since the model must find "the same physical
    object" there). The question is the marker ``find_in_image(phrase, 0)`` followed by the
    paper's two-view wording (:data:`TWO_VIEW_TEMPLATE`), which names the object by its label
    in quotes and — **deviation** — says "(to its center point)" where the paper says "(to the
    object surface/center point)", because the answer is the centre distance. The paper's
    "Output format: <answer>NUMBER</answer>" line is left out: the evaluation system prompt
    (``spacedg.eval.scoring``) asks for the tags. The answer is the distance from camera B's
    centre.

Skipped (decision, not in the spec): a camera centre inside the object's box (a distance "to
the object" is then meaningless, e.g. a room-sized instance).

Geometry block (JSON): ``up``; ``cameras`` (view → 4×4 ``cam_to_world``); ``objects`` (id,
label, description, box ``center``/``extents``/``rotation``); ``refs`` (``[{"id", "label",
"description", "view"}]``: where the text says to find the object); ``visibility`` (per view
and object: pixels, fraction, class); ``visibility_thresholds``; ``camera_center`` (of the
measuring camera, world metres); ``distance_m`` (unrounded); ``decimals``; ``template``; for
two views ``pair`` (covisibility, translation_m, rotation_deg) and ``pair_rules``; ``selection``
(subject = the measuring view and the object).

Order (decision): ``generate`` splits ``rng`` into one child generator per sub type and
interleaves the sub types round-robin, so a caller taking the first ``n`` records gets both
kinds (:func:`~spacedg.plugins.questions.records.round_robin_sub_types`). Within ``single_view`` the views are visited round-robin in a seeded order, each view's
objects in a seeded order; within ``bbox_center_distance`` the pairs of
:func:`~spacedg.plugins.questions.view_sampling.sample_pairs` (its seeded anchor round-robin) are visited
round-robin, each pair's objects in a seeded order. Everything is lazy: a caller that stops
early pays only for what it took. Same seed → same records in the same order.

The record-building helpers (seeded orders, round robins, geometry-block entries, the
"referable object" rule) come from :mod:`~spacedg.plugins.questions.records`.
"""

from __future__ import annotations

import functools
from collections.abc import Iterator
from typing import Any

import numpy as np

from spacedg.plugins.candidates import PASSED_OVER, admission, admitted, offer
from spacedg.plugins.qa_record import QARecord
from spacedg.scene.model import Instance, Scene
from spacedg.plugins.questions.view_sampling import (
    OBJECT_PAIRS,
    PairRules,
    ViewPair,
    VisibilityIndex,
)
from spacedg.scene.visibility_classes import DEFAULT_THRESHOLDS, VisibilityThresholds
from spacedg.plugins.hookspecs import registering
from spacedg.plugins.questions.geometry import camera_center, camera_distance
from spacedg.plugins.questions.language import find_in_image, label_text
from spacedg.plugins.questions.records import (
    camera_inside,
    index_memo,
    make_record,
    objects_block,
    phrase,
    referable,
    round_robin_sub_types,
    seeded_order,
    selection_entry,
)
from spacedg.plugins.questions.pairs import view_and_pair_family
from spacedg.plugins.specs import AnswerType, TaskGroup
from spacedg.seeding import draw_index

__all__ = [
    "BBOX_CENTER_DISTANCE", "DECIMALS", "FAMILY", "NAME", "SINGLE_VIEW", "SUB_QUESTION_TYPES", "TEMPLATES", "TWO_VIEW_TEMPLATE",
    "generate", "make_family",
]

NAME = "camera_object_distance_estimation"
SINGLE_VIEW = "single_view"
BBOX_CENTER_DISTANCE = "bbox_center_distance"
SUB_QUESTION_TYPES: tuple[str, ...] = (SINGLE_VIEW, BBOX_CENTER_DISTANCE)
#: Answers are metres rounded to this many decimals.
DECIMALS = 3

#: Single-view templates (paper order); ``{obj}``: the object phrase.
TEMPLATES: tuple[str, ...] = (
    "What is the straight-line distance to the {obj} from the camera in meters? Measure to the object's center.",
    "How far is the {obj} from the current viewpoint? Answer in meters, measured to the object's center.",
    "Estimate the physical distance between the camera and the {obj}. Answer in meters, measured to the object's center.",
    "Can you estimate the straight-line distance to the {obj} from the current viewpoint? Answer in meters, measured to the object's center.",
)
#: Two-view wording after the image-A marker; ``{label}``: the label as written.
TWO_VIEW_TEMPLATE = (
    "Locate the same physical object in image B. Estimate the 3D metric distance (in meters) from the camera "
    "position of image B (camera center) to the \"{label}\" (to its center point).\n"
    "This is NOT pixel distance. Return only one number in meters (e.g., 0.7)."
)


# ------------------------------------------------------------------ records
def _distance(index: VisibilityIndex, view: str, inst: Instance) -> float | None:
    """Camera centre → box centre in metres, or ``None`` when the camera is inside the box
    (:func:`~spacedg.plugins.questions.records.camera_inside`): memoised per (view, object) on the
    index, as a camera B and an object recur with every view A."""
    memo = index_memo(index, "camera_distances")
    key = (view, inst.id)
    if key not in memo:
        memo[key] = None if camera_inside(index, view, inst) else camera_distance(index.scene.views[view], inst.box.center)
    return memo[key]


def _record(
    scene: Scene, index: VisibilityIndex, sub: str, views: tuple[str, ...], inst: Instance, distance: float,
    question: str, template: int, extra: dict[str, Any],
) -> QARecord:
    measuring = views[-1]
    geometry = {
        **objects_block(scene, index, views, [inst], [(inst, views[0])]),
        "measured_from_view": measuring,
        "camera_center": camera_center(scene.views[measuring]).tolist(),
        "distance_m": distance,
        "decimals": DECIMALS,
        "template": template,
        **extra,
    }
    return make_record(
        scene, NAME, sub, TaskGroup.CAMERA_OBJECT, AnswerType.NA, views, {"object": inst.id, "template": template},
        question=question, answer=round(distance, DECIMALS), geometry=geometry,
    )


def _single_view_stream(scene: Scene, index: VisibilityIndex, view: str, rng: np.random.Generator) -> Iterator[QARecord]:
    for iid in seeded_order(index.visible[view], rng):
        inst = index.instance(iid)
        if not referable(index, view, iid):
            continue
        distance = _distance(index, view, inst)
        if distance is None:
            continue
        subject = f"view:{view}|object:{inst.id}"
        if not admitted(SINGLE_VIEW, (view,), subject, (inst.id,)):
            yield PASSED_OVER  # the caller passes it over: no draws
            continue
        template = draw_index(rng, len(TEMPLATES))
        yield offer(
            SINGLE_VIEW, (view,), subject, (inst.id,), functools.partial(selection_entry, subject),
            functools.partial(_single_view_record, scene, index, view, inst, distance, template),
        )


def _single_view_record(scene: Scene, index: VisibilityIndex, view: str, inst: Instance, distance: float, template: int) -> QARecord:
    """The single-view record of ``inst`` at ``distance`` metres from ``view``'s camera, in wording ``template``."""
    question = TEMPLATES[template].format(obj=phrase(inst))
    return _record(scene, index, SINGLE_VIEW, (view,), inst, distance, question, template, {"selection": selection_entry(f"view:{view}|object:{inst.id}")})


def _pair_stream(scene: Scene, index: VisibilityIndex, pair: ViewPair, rules: PairRules, rng: np.random.Generator) -> Iterator[QARecord]:
    both = sorted(index.visible_set(pair.a) & index.visible_set(pair.b))
    admit = admission()
    for iid in seeded_order(both, rng):
        inst = index.instance(iid)
        if not (referable(index, pair.a, iid) and referable(index, pair.b, iid)):
            continue
        distance = _distance(index, pair.b, inst)
        if distance is None:
            continue
        subject = f"view:{pair.b}|object:{inst.id}"
        if not admit(BBOX_CENTER_DISTANCE, (pair.a, pair.b), subject, (inst.id,)):
            yield PASSED_OVER  # the caller passes it over
            continue
        yield offer(
            BBOX_CENTER_DISTANCE, (pair.a, pair.b), subject, (inst.id,), functools.partial(selection_entry, subject),
            functools.partial(_pair_record, scene, index, pair, rules, inst, distance),
        )


def _pair_record(scene: Scene, index: VisibilityIndex, pair: ViewPair, rules: PairRules, inst: Instance, distance: float) -> QARecord:
    """The two-view record of ``inst`` at ``distance`` metres from camera B of ``pair``."""
    question = find_in_image(phrase(inst), 0) + "\n" + TWO_VIEW_TEMPLATE.format(label=label_text(inst.label))
    extra = {"pair": pair.to_dict(), "pair_rules": rules.to_dict(), "selection": selection_entry(f"view:{pair.b}|object:{inst.id}")}
    return _record(scene, index, BBOX_CENTER_DISTANCE, (pair.a, pair.b), inst, distance, question, 0, extra)


def generate(
    scene: Scene, rng: np.random.Generator, thresholds: VisibilityThresholds = DEFAULT_THRESHOLDS, pair_rules: PairRules = OBJECT_PAIRS,
) -> Iterator[QARecord]:
    """Every valid camera–object distance question of ``scene``, lazily, in a seeded order.

    See the module docstring for the rules, the geometry block and the order.
    """
    # a generator function: nothing runs (not even pair sampling) before the first ``next``
    yield from round_robin_sub_types(scene, VisibilityIndex(scene, thresholds), rng, _single_view_stream, (pair_rules, _pair_stream))


#: ``make_family(thresholds, pair_rules)``: this family with other visibility thresholds / pair rules
#: (:func:`~spacedg.plugins.questions.pairs.view_and_pair_family`); :data:`FAMILY`, the registered one, uses the defaults.
make_family = view_and_pair_family(
    generate, name=NAME, task_group=TaskGroup.CAMERA_OBJECT, answer_types={AnswerType.NA}, sub_question_types=SUB_QUESTION_TYPES,
    description="Metric distance from a camera centre to an object's box centre (single view, or camera B of a pair).",
    metric_only=True,
)
FAMILY = make_family()
spacedg_register_question_families = registering(FAMILY)

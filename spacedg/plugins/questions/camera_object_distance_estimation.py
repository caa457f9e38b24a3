"""Camera–object distance (``question_type = "camera_object_distance_estimation"``; camera-object, NA).

Answer: the straight-line distance in **metres** from a camera centre (the translation of
``Camera.cam_to_world``) to an object's centre (its oriented box centre), rounded to
:data:`DECIMALS` = 3 decimals. Distances are invariant under a rigid motion of the scene.

Sub types (SPEC-QA, type 3):

``single_view`` (1 view)
    The object is clearly visible in the view (:class:`~spacedg.data.view_sampling.VisibilityIndex`
    ``visible``) and no other same-label instance with the same description is seen there
    (:func:`~spacedg.data.view_sampling.description_clash`). The object is named by
    :func:`~spacedg.plugins.questions.language.object_phrase`. The four paper templates
    (:data:`TEMPLATES`, drawn by ``rng``) are kept, with one **deviation**: each states the
    unit and that the distance is measured to the object's centre (the paper's templates 1–3
    give no unit, and none says which point of the object is meant; the answer is in metres
    to the box centre, so the question says so).
``bbox_center_distance`` (2 views, :data:`~spacedg.data.view_sampling.OBJECT_PAIRS`:
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
two views ``pair`` (covisibility, translation_m, rotation_deg) and ``pair_rules``.

Order (decision): ``generate`` splits ``rng`` into one child generator per sub type and
interleaves the sub types round-robin (so a caller taking the first ``n`` records gets both
kinds). Within ``single_view`` the views are visited round-robin in a seeded order, each view's
objects in a seeded order; within ``bbox_center_distance`` the pairs of
:func:`~spacedg.data.view_sampling.sample_pairs` (its seeded anchor round-robin) are visited
round-robin, each pair's objects in a seeded order. Everything is lazy: a caller that stops
early pays only for what it took. Same seed → same records in the same order.

Helpers that several camera-object families share (:func:`round_robin`, :func:`child_rngs`,
:func:`seeded_order`, :func:`object_entry`, :func:`ref_entry`, :func:`camera_entry`,
:func:`visibility_entry`, :func:`visibility_thresholds`)
live here because ``geometry.py`` has none of them; ``camera_object_relative_direction``
imports them.
"""

from __future__ import annotations

import functools
from collections import deque
from collections.abc import Iterable, Iterator, Sequence
from typing import Any, TypeVar

import numpy as np

from spacedg.data.qa import QARecord, make_record_id
from spacedg.data.scene import Instance, Scene
from spacedg.data.view_sampling import (
    OBJECT_PAIRS,
    PairRules,
    ViewPair,
    VisibilityIndex,
    description_clash,
    sample_pairs,
)
from spacedg.data.visibility import DEFAULT_THRESHOLDS, VisibilityThresholds
from spacedg.plugins.hookspecs import hookimpl
from spacedg.plugins.questions.geometry import camera_center
from spacedg.plugins.questions.language import find_in_image, label_text, object_phrase
from spacedg.plugins.specs import AnswerType, QuestionFamily, TaskGroup

__all__ = [
    "BBOX_CENTER_DISTANCE",
    "DECIMALS",
    "FAMILY",
    "NAME",
    "SINGLE_VIEW",
    "SUB_QUESTION_TYPES",
    "TEMPLATES",
    "TWO_VIEW_TEMPLATE",
    "camera_entry",
    "child_rngs",
    "generate",
    "make_family",
    "object_entry",
    "ref_entry",
    "round_robin",
    "seeded_order",
    "visibility_entry",
    "visibility_thresholds",
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

T = TypeVar("T")


# ------------------------------------------------------------ shared helpers
def round_robin(streams: Iterable[Iterator[T]]) -> Iterator[T]:
    """One item from each stream in turn until all are exhausted (streams are started lazily)."""
    queue = deque(streams)
    while queue:
        stream = queue.popleft()
        try:
            item = next(stream)
        except StopIteration:
            continue
        yield item
        queue.append(stream)


def child_rngs(rng: np.random.Generator, n: int) -> list[np.random.Generator]:
    """``n`` independent generators seeded from ``rng`` (one draw of ``n`` integers)."""
    seeds = rng.integers(0, 2**63 - 1, size=n, dtype=np.int64)
    return [np.random.default_rng(int(s)) for s in seeds]


def seeded_order(items: Sequence[T], rng: np.random.Generator) -> Iterator[T]:
    """``items`` in the order of ``rng.permutation(len(items))`` (drawn on the first ``next``)."""
    for i in rng.permutation(len(items)):
        yield items[int(i)]


def object_entry(inst: Instance) -> dict[str, Any]:
    """An object's identity and oriented box (world metres) for a geometry block."""
    return {
        "id": inst.id, "label": inst.label, "description": inst.description,
        "center": inst.box.center.tolist(), "extents": inst.box.extents.tolist(), "rotation": inst.box.rotation.tolist(),
    }


def ref_entry(inst: Instance, view: str) -> dict[str, Any]:
    """``{"id", "label", "description", "view"}``: an object named in the question and the view it is found in."""
    return {"id": inst.id, "label": inst.label, "description": inst.description, "view": view}


def camera_entry(scene: Scene, views: Sequence[str]) -> dict[str, list[list[float]]]:
    """View → 4×4 ``cam_to_world`` (OpenCV axes, metres) of the views a question uses."""
    return {v: np.asarray(scene.views[v].cam_to_world, dtype=np.float64).tolist() for v in views}


def visibility_entry(index: VisibilityIndex, views: Sequence[str], ids: Sequence[int]) -> list[dict[str, Any]]:
    """Visibility (pixels, fraction, class) of every object in every view of the question."""
    return [{"view": v, "id": i, **index.vis_entry(v, i)} for v in views for i in ids]


def visibility_thresholds(scene: Scene, index: VisibilityIndex, views: Sequence[str]) -> dict[str, Any]:
    """The "clearly visible" thresholds scaled to each view's image size."""
    out: dict[str, Any] = {"min_fraction": float(index.thresholds.min_fraction), "min_pixels": {}}
    for v in views:
        cam = scene.views[v]
        out["min_pixels"][v] = index.thresholds.pixels_for(cam.width * cam.height)
    return out


# ------------------------------------------------------------------ records
def _distance(scene: Scene, view: str, inst: Instance) -> float | None:
    """Camera centre → box centre in metres, or ``None`` when the camera is inside the box."""
    centre = camera_center(scene.views[view])
    if bool(inst.box.contains(centre[None, :])[0]):
        return None
    return float(np.linalg.norm(inst.box.center - centre))


def _record(
    scene: Scene, index: VisibilityIndex, sub: str, views: tuple[str, ...], inst: Instance, distance: float,
    question: str, template: int, extra: dict[str, Any],
) -> QARecord:
    measuring = views[-1]
    geometry = {
        "up": scene.up.tolist(),
        "cameras": camera_entry(scene, views),
        "objects": [object_entry(inst)],
        "refs": [ref_entry(inst, views[0])],
        "visibility": visibility_entry(index, views, [inst.id]),
        "visibility_thresholds": visibility_thresholds(scene, index, views),
        "measured_from_view": measuring,
        "camera_center": camera_center(scene.views[measuring]).tolist(),
        "distance_m": distance,
        "decimals": DECIMALS,
        "template": template,
        **extra,
    }
    return QARecord(
        id=make_record_id(scene.id, NAME, sub, views, {"object": inst.id, "template": template}),
        scene_id=scene.id,
        question_type=NAME,
        sub_question_type=sub,
        task_group=TaskGroup.CAMERA_OBJECT,
        answer_type=AnswerType.NA,
        views=views,
        question=question,
        options=(),
        answer=round(distance, DECIMALS),
        geometry=geometry,
    )


def _single_view_stream(scene: Scene, index: VisibilityIndex, view: str, rng: np.random.Generator) -> Iterator[QARecord]:
    for iid in seeded_order(index.visible[view], rng):
        inst = index.instance(iid)
        if description_clash(index, view, inst):
            continue
        distance = _distance(scene, view, inst)
        if distance is None:
            continue
        template = int(rng.integers(len(TEMPLATES)))
        question = TEMPLATES[template].format(obj=object_phrase(inst.label, inst.description))
        yield _record(scene, index, SINGLE_VIEW, (view,), inst, distance, question, template, {})


def _pair_stream(scene: Scene, index: VisibilityIndex, pair: ViewPair, rules: PairRules, rng: np.random.Generator) -> Iterator[QARecord]:
    both = sorted(set(index.visible[pair.a]) & set(index.visible[pair.b]))
    for iid in seeded_order(both, rng):
        inst = index.instance(iid)
        if description_clash(index, pair.a, inst) or description_clash(index, pair.b, inst):
            continue
        distance = _distance(scene, pair.b, inst)
        if distance is None:
            continue
        question = find_in_image(object_phrase(inst.label, inst.description), 0) + "\n" + TWO_VIEW_TEMPLATE.format(label=label_text(inst.label))
        extra = {"pair": pair.to_dict(), "pair_rules": rules.to_dict()}
        yield _record(scene, index, BBOX_CENTER_DISTANCE, (pair.a, pair.b), inst, distance, question, 0, extra)


def _single_view_records(scene: Scene, index: VisibilityIndex, rng: np.random.Generator) -> Iterator[QARecord]:
    views = list(scene.views)
    order = [views[int(i)] for i in rng.permutation(len(views))]
    yield from round_robin(_single_view_stream(scene, index, v, rng) for v in order)


def _two_view_records(scene: Scene, index: VisibilityIndex, rng: np.random.Generator, rules: PairRules) -> Iterator[QARecord]:
    pairs = sample_pairs(scene, rules, rng)
    yield from round_robin([_pair_stream(scene, index, p, rules, rng) for p in pairs])


def generate(
    scene: Scene, rng: np.random.Generator, thresholds: VisibilityThresholds = DEFAULT_THRESHOLDS, pair_rules: PairRules = OBJECT_PAIRS,
) -> Iterator[QARecord]:
    """Every valid camera–object distance question of ``scene``, lazily, in a seeded order.

    See the module docstring for the rules, the geometry block and the order.
    """
    index = VisibilityIndex(scene, thresholds)
    rng_single, rng_pair = child_rngs(rng, 2)
    # generator functions: nothing runs (not even pair sampling) before the first ``next``
    yield from round_robin([_single_view_records(scene, index, rng_single), _two_view_records(scene, index, rng_pair, pair_rules)])


def make_family(thresholds: VisibilityThresholds = DEFAULT_THRESHOLDS, pair_rules: PairRules = OBJECT_PAIRS) -> QuestionFamily:
    """The family with custom visibility thresholds / pair rules (the registered one uses the defaults)."""
    return QuestionFamily(
        name=NAME,
        task_group=TaskGroup.CAMERA_OBJECT,
        answer_types=frozenset({AnswerType.NA}),
        sub_question_types=SUB_QUESTION_TYPES,
        num_views=(1, 2),
        generate=functools.partial(generate, thresholds=thresholds, pair_rules=pair_rules),
        needs=frozenset({"visibility", "covisibility"}),
        description="Metric distance from a camera centre to an object's box centre (single view, or camera B of a pair).",
    )


FAMILY = make_family()


@hookimpl
def spacedg_register_question_families(register: Any) -> None:
    """Register :data:`FAMILY`."""
    register(FAMILY)

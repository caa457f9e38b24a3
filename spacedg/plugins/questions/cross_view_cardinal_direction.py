"""Cross-view cardinal direction (``question_type = "cross_view_cardinal_direction"``; camera-object, 2 views, MCQ).

Sub type ``assumed_direction`` (SPEC-QA, type 5; paper appendix "Camera-Object Cardinal
Direction"). Object 1 is clearly visible in image A, object 2 clearly visible in image B; the
question tells the compass direction of object 1 as seen from where image A was taken and asks
the compass direction of object 2 as seen from where image B was taken.

Frame (exact definition; every vector in world metres, ``up = Scene.up``):

- ground plane: the plane orthogonal to ``up``; ``horizontal(v) = v − (v·up) up``;
- **reference** (defines north): origin = camera A's centre ``t_A`` (translation of A's
  ``cam_to_world``), vector ``u = c_1 − t_A`` to object 1's box centre. The assumed direction
  ``d`` is drawn by ``rng`` from :data:`~spacedg.plugins.questions.geometry.CARDINALS`
  (north, east, south, west at 0°, 90°, 180°, 270° clockwise seen from above); **north** is the
  unit ground vector such that ``horizontal(u)`` lies at angle ``angle(d)`` from north, i.e.
  north = ``horizontal(u)`` turned by ``−angle(d)`` about ``up``
  (:func:`~spacedg.plugins.questions.geometry.compass_frame`);
  **east = north × up** (right-handed world, up against gravity: with z up and north = +x,
  east = −y). Camera A's orientation plays no part (the reference pipeline used camera A's
  x–z plane; we use the ground plane, so the answer survives any camera tilt or roll);
- **query**: origin = camera B's centre ``t_B``, vector ``v = c_2 − t_B`` to object 2's box
  centre; ``angle = ground_angle(north, v, up)`` in [0, 360), clockwise from north towards
  east seen from above. The truth is ``COMPASS_SECTORS.classify(angle)``: by the 0.5774 rule
  on the (north, east) components a cardinal label covers ±30° around its axis and a diagonal
  label the 30° between (north [330, 30), northeast [30, 60), east [60, 120), …).

Skipped (:func:`~spacedg.plugins.questions.geometry.ground_leg`): ``|horizontal(u)|`` or
``|horizontal(v)|`` below :data:`~spacedg.plugins.questions.geometry.MIN_HORIZONTAL_M` = 0.25 m,
or ``u`` or ``v`` vertical-dominant (vertical ≥
:data:`~spacedg.plugins.questions.geometry.VERTICAL_FACTOR` = 1.2 × horizontal).

Options: the truth and three of the seven other compass labels
(``COMPASS_SECTORS.distractors``: seeded order; when ``angle`` is within
:data:`~spacedg.plugins.questions.geometry.BOUNDARY_GUARD_DEG` = 3° of a sector boundary the
label across that boundary is never offered), letters by
:func:`~spacedg.plugins.questions.geometry.build_mcq`. An angle within
:data:`~spacedg.plugins.questions.geometry.COMPASS_RULE_BAND_DEG` (0.01°) of a boundary is not
asked: there the ±30° and the 0.5774 readings of the rule disagree.

Objects (decisions): pairs of views from :func:`~spacedg.plugins.questions.view_sampling.sample_pairs` with
:data:`~spacedg.plugins.questions.view_sampling.OBJECT_PAIRS` (covisibility > 0.25, baseline ≥ 0.2 m; no
rotation minimum: camera B's orientation does not enter the answer). Object 1 is clearly
visible in A and object 2 clearly visible in B, each without a description clash in that view
(:func:`~spacedg.plugins.questions.view_sampling.description_clash`; together
:func:`~spacedg.plugins.questions.records.referable`); they are distinct instances and their
phrases (:func:`~spacedg.plugins.questions.language.object_phrase`) differ case-insensitively
(the same phrase twice would read as the same object). Either object may also be seen in the
other image; nothing is required there.

Question (the paper's wording, objects named by their phrases, the same as in the markers;
**deviation**: the paper's template has no article before the object, which reads badly with
descriptions, so "the" is added)::

    In image A, find the red lamp. In image B, find the wooden chair.
    The direction of the red lamp relative to image A is north. What is the direction of the wooden chair relative to image B?

Order: pairs in ``sample_pairs`` order, visited round-robin (one record per pair per round;
the family is made by :func:`~spacedg.plugins.questions.pairs.pair_family`); each pair's
(object 1, object 2) candidates in a lazily drawn seeded permutation
(:func:`~spacedg.plugins.questions.pairs.object_pairs`); for each accepted candidate
``rng`` draws the assumed direction, then the distractor order and the letter
(:func:`~spacedg.plugins.questions.records.compass_question`). All draws come from the one
``rng``: same seed, same records in the same order; everything is lazy.

Geometry block (JSON): ``up``; ``cameras`` (view → 4×4 ``cam_to_world``); ``objects`` (id,
label, description, box ``center``/``extents``/``rotation``); ``refs`` (``[{"id", "label",
"description", "view"}]`` in question order); ``visibility``; ``visibility_thresholds``;
``reference`` and ``query`` (``origin_view``, ``origin``, ``object``, ``vector``,
``horizontal``, ``horizontal_m``, ``vertical_m``); ``assumed_dir``; ``assumed_angle_deg``;
``north``; ``east``; ``angle_deg``; ``sector_index``; ``sector_label``; ``sector_labels``;
``sector_starts_deg``; ``boundary_distance_deg``; ``neighbour_index``; ``banned_labels``;
``thresholds`` (``min_horizontal_m``, ``vertical_factor``, ``boundary_guard_deg``,
``cardinal_ratio``); ``template`` (always 0); ``pair``; ``pair_rules``; ``selection`` (cell = the
assumed direction, roles = the eight compass labels: the answer was the assumed direction
itself half the time, since the two cameras are close; the question index balances the eight
answers per assumed direction; subject = the ordered object pair, asked once per scene).

The compass frame (:func:`~spacedg.plugins.questions.geometry.compass_frame`,
:func:`~spacedg.plugins.questions.geometry.compass_answer`,
:func:`~spacedg.plugins.questions.geometry.ground_leg`) lives in ``geometry.py``; the compass
part of the block (:func:`~spacedg.plugins.questions.records.compass_block`) and the other
record-building helpers in ``records.py``, shared with ``object_proxy_cardinal_direction`` and
``inter_object_distance``.
"""

from __future__ import annotations

import functools
from collections.abc import Iterator
from typing import Any

import numpy as np

from spacedg.plugins.qa_record import QARecord
from spacedg.plugins.candidates import PASSED_OVER, Candidate, admission, offer
from spacedg.scene.model import Instance, Scene
from spacedg.plugins.questions.view_sampling import (
    PairRules,
    ViewPair,
    VisibilityIndex,
)
from spacedg.plugins.hookspecs import registering
from spacedg.plugins.questions.geometry import (
    ground_leg,
)
from spacedg.plugins.questions.language import find_in_image
from spacedg.plugins.questions.pairs import pair_family
from spacedg.plugins.questions.geometry import COMPASS_SECTORS
from spacedg.plugins.questions.compass_cache import compass_questions
from spacedg.plugins.questions.records import (
    index_memo,
    compass_distractors,
    lazy_permutation,
    make_record,
    objects_block,
    phrase,
    phrase_key,
    referable_ids,
    selection_entry,
    view_centre,
)
from spacedg.plugins.specs import AnswerType, TaskGroup

__all__ = [
    "FAMILY",
    "NAME",
    "SUB_QUESTION_TYPE",
    "TEMPLATE",
    "make_family",
    "render_question",
]

NAME = "cross_view_cardinal_direction"
SUB_QUESTION_TYPE = "assumed_direction"
#: The paper's wording after the markers, with "the" before each object; ``{obj1}``, ``{obj2}``:
#: phrases; ``{assumed}``: a cardinal.
TEMPLATE = (
    "The direction of the {obj1} relative to image A is {assumed}. "
    "What is the direction of the {obj2} relative to image B?"
)


# ------------------------------------------------------------------ records
def render_question(phrase1: str, phrase2: str, assumed_dir: str) -> str:
    """Markers for object 1 in image A and object 2 in image B, then the paper's question."""
    markers = f"{find_in_image(phrase1, 0)} {find_in_image(phrase2, 1)}"
    return markers + "\n" + TEMPLATE.format(obj1=phrase1, obj2=phrase2, assumed=assumed_dir)


def _record(
    scene: Scene, index: VisibilityIndex, pair: ViewPair, rules: PairRules, one: Instance, two: Instance,
    legs: tuple[dict[str, Any], dict[str, Any]], origins: tuple[np.ndarray, np.ndarray], drawn: tuple[str, tuple[str, ...], str, dict[str, Any]],
) -> QARecord:
    """The record of one candidate: ``legs`` (reference, query: :func:`~spacedg.plugins.questions.geometry.ground_leg`),
    the camera centres ``origins`` and what :func:`~spacedg.plugins.questions.records.compass_question` drew."""
    views = (pair.a, pair.b)
    (ref, query), (origin_a, origin_b), (assumed, options, letter, compass) = legs, origins, drawn
    geometry = {
        **objects_block(scene, index, views, [one, two], [(one, pair.a), (two, pair.b)]),
        "reference": {"origin_view": pair.a, "origin": origin_a.tolist(), "object": one.id, **ref},
        "query": {"origin_view": pair.b, "origin": origin_b.tolist(), "object": two.id, **query},
        **compass,
        "template": 0,
        "pair": pair.to_dict(),
        "pair_rules": rules.to_dict(),
        "selection": _selection(one, two, drawn),
    }
    return make_record(
        scene, NAME, SUB_QUESTION_TYPE, TaskGroup.CAMERA_OBJECT, AnswerType.MCQ, views,
        {"objects": [one.id, two.id], "assumed_dir": assumed},
        question=render_question(phrase(one), phrase(two), assumed), answer=letter, geometry=geometry, options=options,
    )


def _subject(one: Instance, two: Instance) -> str:
    """The selection subject: the ordered object pair."""
    return f"objects:{one.id}|{two.id}"


def _selection(one: Instance, two: Instance, drawn: tuple[str, tuple[str, ...], str, dict[str, Any]]) -> dict[str, Any]:
    """The selection entry (module docstring) of the question about ``one`` and ``two`` that ``drawn`` describes."""
    assumed, compass = drawn[0], drawn[3]
    return selection_entry(
        _subject(one, two), f"assumed:{assumed}", compass["sector_label"], COMPASS_SECTORS.labels, distractors=compass_distractors(compass),
    )


def _side(
    index: VisibilityIndex, legs: dict[Any, Any], view: str, origin: np.ndarray, iid: int, up: np.ndarray,
) -> tuple[Instance, str, dict[str, Any] | None]:
    """An object of one side of a pair: its instance, :func:`~spacedg.plugins.questions.records.phrase_key`
    and the ground leg from the view's camera centre ``origin`` to its box centre (memoised per (view, id) in ``legs``)."""
    inst = index.instance(iid)
    key = (view, iid)
    if key not in legs:
        legs[key] = ground_leg(inst.box.center - origin, up)
    return inst, phrase_key(inst), legs[key]


def _view_side(index: VisibilityIndex, view: str, up: np.ndarray) -> tuple[np.ndarray, tuple[int, ...], tuple[tuple[Instance, str, dict[str, Any] | None], ...]]:
    """A view as one side of its pairs: its camera centre, its :func:`~spacedg.plugins.questions.records.referable_ids`
    and each one's :func:`_side` (in that order: object_pairs' candidates), memoised per view on the index (``up``: the scene's)."""
    memo = index_memo(index, "cross_view_sides")
    side = memo.get(view)
    if side is None:
        origin = view_centre(index, view)
        legs = index_memo(index, "camera_legs")  # (view, object id) → the leg camera → object
        ids = tuple(referable_ids(index, view))
        side = memo[view] = (origin, ids, tuple(_side(index, legs, view, origin, iid, up) for iid in ids))
    return side


def _pair_stream(scene: Scene, index: VisibilityIndex, pair: ViewPair, rules: PairRules, rng: np.random.Generator) -> Iterator[QARecord | Candidate]:
    up = np.asarray(scene.up, dtype=np.float64)
    views = (pair.a, pair.b)
    admit = admission()
    compass = compass_questions(index, up)
    (origin_a, ones, side_a), (origin_b, twos, side_b) = _view_side(index, pair.a, up), _view_side(index, pair.b, up)
    origins = origin_a, origin_b
    n_twos = len(twos)
    for k in lazy_permutation(len(ones) * n_twos, rng):  # = object_pairs(index, pair, rng), the same draws
        i, j = divmod(k, n_twos)
        if ones[i] == twos[j]:
            continue
        (one, key_one, ref), (two, key_two, query) = side_a[i], side_b[j]
        if key_one == key_two or ref is None or query is None:
            continue
        subject, named = _subject(one, two), (one.id, two.id)
        if not admit(SUB_QUESTION_TYPE, views, subject, named):
            yield PASSED_OVER  # the caller passes it over: no draws
            continue
        drawn = compass.ask(("camera", pair.a, one.id), ref["vector"], ("camera", pair.b, two.id), query["vector"], rng)  # = compass_question(ref, query, up, rng)
        if drawn is None:
            continue  # on a sector boundary: the label depends on the reading of the rule
        yield offer(
            SUB_QUESTION_TYPE, views, subject, named, functools.partial(_selection, one, two, drawn),
            functools.partial(_record, scene, index, pair, rules, one, two, (ref, query), origins, drawn),
        )


#: ``make_family(thresholds, pair_rules)``: this family with other visibility thresholds / pair rules
#: (:func:`~spacedg.plugins.questions.pairs.pair_family`); :data:`FAMILY`, the registered one, uses the defaults.
make_family = pair_family(
    _pair_stream, name=NAME, task_group=TaskGroup.CAMERA_OBJECT, answer_types={AnswerType.MCQ}, sub_question_types=(SUB_QUESTION_TYPE,),
    plain_rounds=True, description="Given the compass direction of an object seen from image A, the compass direction of another seen from image B.",
)
FAMILY = make_family()
spacedg_register_question_families = registering(FAMILY)

"""Object bounding-box size (``question_type = "object_bounding_size_estimation"``; object-centric, 1 view, SIZE_LIST).

For one view and one object the answer is the object's oriented-box extents (full side
lengths, metres) sorted ascending and rounded to 2 decimals:
``[shortest, middle, longest]`` (:class:`~spacedg.plugins.qa_record.QARecord` SIZE_LIST). Sorting happens
before rounding; rounding is monotone, so the rounded list stays sorted.

Object rule: the object is **clearly visible** in the view and
:func:`~spacedg.plugins.questions.view_sampling.description_clash` is False there (no same-label instance
with the same description is seen in that image;
:func:`~spacedg.plugins.questions.records.referable`). Decision: an object whose shortest side
rounds to 0.00 m (a flat annotation, < 5 mm) is skipped, because relative-error scoring of a
zero target is undefined. Every other (view, object) pair is a candidate, so an object seen
clearly in several views yields one candidate per view; the answer is the same in every view,
so the question index asks an object once per scene (the ``selection`` entry's subject is the
object).

Templates (the paper's appendix, bounding-box size), chosen per record by the seeded ``rng``;
``{target_obj}`` is :func:`~spacedg.plugins.questions.language.object_phrase` (description,
else label):

0. ``What are the 3D physical dimensions of the <obj>? Please answer in the format [shortest edge, middle edge, longest edge] in meters (e.g. [0.10, 0.20, 0.30]).``
1. ``Estimate the physical size of the <obj> in meters, and respond as [shortest edge, middle edge, longest edge] (e.g. [0.10, 0.20, 0.30]).``
2. ``Could you provide the three edge lengths of the <obj> in the format [shortest, middle, longest] (meters, e.g. [0.10, 0.20, 0.30])?``
3. ``What is the bounding box extent of the <obj>? Reply as [shortest edge, middle edge, longest edge] in meters (e.g. [0.10, 0.20, 0.30]).``

``sub_question_type`` is ``"extent_list"``.

Order: every (view, object) candidate is built first (views in scene order, objects in id
order), then shuffled with ``rng.permutation``; each candidate then draws its template with
``rng.integers`` (as :mod:`object_counting`), and records are built lazily.

Geometry block (JSON): ``view``, ``up``, ``object`` (``id``, ``label``, ``description``, box
``center`` / ``extents`` / ``rotation``: :func:`~spacedg.plugins.questions.records.object_entry`), ``sorted_extents`` (unrounded, metres),
``rounding_decimals`` (2), ``visibility`` (:meth:`VisibilityIndex.vis_entry`), ``template``,
``refs`` (the object with its view) and ``selection`` (subject = the object). The answer depends on the extents only, so it is
invariant under any rigid motion of the scene.
"""

from __future__ import annotations

import functools
from collections.abc import Iterator

import numpy as np

from spacedg.plugins.candidates import Candidate, offer_if_admitted
from spacedg.plugins.qa_record import QARecord
from spacedg.scene.model import Instance, Scene
from spacedg.plugins.questions.view_sampling import VisibilityIndex
from spacedg.scene.visibility_classes import DEFAULT_THRESHOLDS, VisibilityThresholds
from spacedg.plugins.hookspecs import registering
from spacedg.plugins.questions.records import (
    make_record,
    object_entry,
    phrase,
    ref_entry,
    referable_ids,
    selection_entry,
)
from spacedg.plugins.question_family import FamilyFactory
from spacedg.plugins.specs import AnswerType, TaskGroup

__all__ = ["DECIMALS", "FAMILY", "NAME", "SUB_QUESTION_TYPE", "TEMPLATES", "generate", "make_family", "render_question", "size_list"]

NAME = "object_bounding_size_estimation"
SUB_QUESTION_TYPE = "extent_list"
#: Decimals of the answer, metres.
DECIMALS = 2

#: ``{target_obj}``: the object's phrase.
TEMPLATES: tuple[str, ...] = (
    (
        "What are the 3D physical dimensions of the {target_obj}? Please answer in the format "
        "[shortest edge, middle edge, longest edge] in meters (e.g. [0.10, 0.20, 0.30])."
    ),
    (
        "Estimate the physical size of the {target_obj} in meters, and respond as "
        "[shortest edge, middle edge, longest edge] (e.g. [0.10, 0.20, 0.30])."
    ),
    (
        "Could you provide the three edge lengths of the {target_obj} in the format "
        "[shortest, middle, longest] (meters, e.g. [0.10, 0.20, 0.30])?"
    ),
    (
        "What is the bounding box extent of the {target_obj}? Reply as "
        "[shortest edge, middle edge, longest edge] in meters (e.g. [0.10, 0.20, 0.30])."
    ),
)


def size_list(inst: Instance) -> tuple[float, float, float]:
    """The box extents sorted ascending, then rounded to :data:`DECIMALS` decimals (metres)."""
    a, b, c = (round(float(v), DECIMALS) for v in sorted(float(e) for e in inst.box.extents))
    return a, b, c


def render_question(template: int, inst: Instance) -> str:
    """The question text of template index ``template`` for ``inst``."""
    return TEMPLATES[template].format(target_obj=phrase(inst))


def _offer(scene: Scene, index: VisibilityIndex, view: str, inst: Instance, template: int) -> QARecord | Candidate:
    """What the stream yields for ``inst`` in ``view`` (its template drawn up front): :data:`~spacedg.plugins.candidates.PASSED_OVER`
    when the pool refuses it, else :func:`~spacedg.plugins.candidates.offer` of its record."""
    subject = f"object:{inst.id}"
    return offer_if_admitted(  # type: ignore[return-value]
        SUB_QUESTION_TYPE, (view,), subject, (inst.id,), functools.partial(selection_entry, subject),
        functools.partial(_record, scene, index, view, inst, template),
    )


def _record(scene: Scene, index: VisibilityIndex, view: str, inst: Instance, template: int) -> QARecord:
    answer = size_list(inst)
    geometry = {
        "view": view,
        "up": np.asarray(scene.up, dtype=np.float64).tolist(),
        "object": object_entry(inst),
        "sorted_extents": sorted(float(e) for e in inst.box.extents),
        "rounding_decimals": DECIMALS,
        "visibility": index.vis_entry(view, inst.id),
        "template": template,
        "refs": [ref_entry(inst, view)],
        "selection": selection_entry(f"object:{inst.id}"),
    }
    views = (view,)
    return make_record(
        scene, NAME, SUB_QUESTION_TYPE, TaskGroup.OBJECT_CENTRIC, AnswerType.SIZE_LIST, views, {"object": inst.id, "template": template},
        question=render_question(template, inst), answer=answer, geometry=geometry,
    )


def generate(scene: Scene, rng: np.random.Generator, thresholds: VisibilityThresholds = DEFAULT_THRESHOLDS) -> Iterator[QARecord]:
    """Every valid bounding-size question of ``scene``, in an order shuffled by ``rng`` (module docstring)."""
    index = VisibilityIndex(scene, thresholds)
    candidates = [
        (view, inst) for view in scene.views for inst in map(index.instance, referable_ids(index, view)) if size_list(inst)[0] > 0.0
    ]
    order = rng.permutation(len(candidates))
    templates = rng.integers(0, len(TEMPLATES), size=len(candidates))
    for idx in order:
        view, inst = candidates[idx]
        yield _offer(scene, index, view, inst, int(templates[idx]))


#: ``make_family(thresholds)``: this family with other visibility thresholds
#: (:class:`~spacedg.plugins.question_family.FamilyFactory`); :data:`FAMILY`, the registered one, uses the defaults.
make_family = FamilyFactory(
    generate, name=NAME, task_group=TaskGroup.OBJECT_CENTRIC, answer_types={AnswerType.SIZE_LIST}, sub_question_types=(SUB_QUESTION_TYPE,),
    num_views=(1,), needs={"visibility"}, description="The three edge lengths [shortest, middle, longest] of a clearly visible object's box, in metres.",
    metric_only=True,
)
FAMILY = make_family()
spacedg_register_question_families = registering(FAMILY)

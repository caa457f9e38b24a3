"""Object counting (``question_type = "object_counting"``; object-centric, single view, COUNT).

Rule (SPEC-QA, type 11): for one view and one label, the answer is the number of instances of
that label that are **clearly visible** in the view (:func:`spacedg.scene.visibility.classify`
→ ``VISIBLE``). The (view, label) pair is skipped when any instance of the label is in the
grey zone (``PARTIAL``) there, since a viewer could reasonably count it or not; instances with
no visible pixel (``HIDDEN``) are simply not counted. The pair is also skipped when the view
shows (any pixel) an instance of a *confusable* label, one with the same head noun
(:func:`~spacedg.plugins.questions.view_sampling.confusable`: counting "lamp" next to a "floor lamp"). Only counts ≥ 1 are asked (a count of 0
would be an existence question about an absent label).

Labels are grouped case- and underscore-insensitively (``"Chair"``, ``"chair"`` and
``"chair "`` are one label); the question uses the first spelling in id order.

Templates (the paper's appendix "Question Templates", object counting), chosen per record by
the seeded ``rng``:

0. ``How many <label>s are visible in this image?``
1. ``Count the number of <label> objects in this image.`` — **deviation**: the paper says "in
   the scene", but the answer counts what this one image shows, not the whole scene.
2. ``What is the total count of <label>s shown?``
3. ``Tell me how many <label>s exist in the current view.``

``<label>s`` is a proper English plural (:func:`~spacedg.plugins.questions.language.plural`:
boxes, shelves, people). The answer is an ``int`` (``QARecord.answer``, JSON integer);
``sub_question_type`` is ``"count"``.

Geometry block: ``view``, ``label``, ``image_size`` ``[width, height]`` px, ``counted`` (one
entry per counted instance: ``id``, ``visible_pixels``, ``visible_fraction``), ``not_counted``
(the label's other instances with their ``class``, ``"hidden"``, and their visibility or
``null`` when the view has no record), ``thresholds`` (``min_pixels`` scaled to this image,
``min_fraction``) and ``template`` (index into :data:`TEMPLATES`).

Order: every (view, label) candidate is built first, then shuffled with ``rng``
(``rng.permutation``) and each candidate draws its template (``rng.integers``), so the same
seed gives the same records in the same order, and a caller may stop after any number.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

from spacedg.plugins.qa_record import QARecord
from spacedg.scene.model import Instance, Scene
from spacedg.plugins.questions.view_sampling import confusable
from spacedg.scene.visibility_classes import DEFAULT_THRESHOLDS, VisibilityClass, VisibilityThresholds, classify
from spacedg.plugins.hookspecs import registering
from spacedg.plugins.questions.language import label_text, plural
from spacedg.plugins.questions.records import make_record
from spacedg.plugins.question_family import FamilyFactory
from spacedg.plugins.specs import AnswerType, TaskGroup

__all__ = ["NAME", "SUB_QUESTION_TYPE", "TEMPLATES", "FAMILY", "make_family", "generate", "render_question"]

NAME = "object_counting"
SUB_QUESTION_TYPE = "count"

#: ``{plural}``: the label's plural; ``{label}``: the label as written.
TEMPLATES: tuple[str, ...] = (
    "How many {plural} are visible in this image?",
    "Count the number of {label} objects in this image.",
    "What is the total count of {plural} shown?",
    "Tell me how many {plural} exist in the current view.",
)


def render_question(template: int, label: str) -> str:
    """The question text of template index ``template`` for ``label``."""
    return TEMPLATES[template].format(label=label_text(label), plural=plural(label))


@dataclass(frozen=True)
class _Candidate:
    view: str
    label: str
    counted: tuple[Instance, ...]
    hidden: tuple[Instance, ...]
    image_size: tuple[int, int]
    min_pixels: float


def _label_key(label: str) -> str:
    return label_text(label).lower()


def _candidates(scene: Scene, thresholds: VisibilityThresholds) -> list[_Candidate]:
    groups: dict[str, list[Instance]] = {}
    for inst in sorted(scene.instances, key=lambda i: i.id):
        groups.setdefault(_label_key(inst.label), []).append(inst)
    out: list[_Candidate] = []
    for view, cam in scene.views.items():
        area = cam.width * cam.height
        for key in sorted(groups):
            members = groups[key]
            classes = [classify(inst.visibility.get(view), thresholds, area) for inst in members]
            if VisibilityClass.PARTIAL in classes:
                continue  # grey zone: the count is ambiguous
            counted = tuple(inst for inst, c in zip(members, classes) if c is VisibilityClass.VISIBLE)
            if not counted:
                continue
            if any(
                confusable(other.label, members[0].label) and inst_vis_pixels(other, view) > 0
                for other in scene.instances
            ):
                continue  # e.g. counting "lamp" while a "floor lamp" is in view: ambiguous
            hidden = tuple(inst for inst, c in zip(members, classes) if c is VisibilityClass.HIDDEN)
            out.append(_Candidate(view, members[0].label, counted, hidden, (cam.width, cam.height), thresholds.pixels_for(area)))
    return out


def inst_vis_pixels(inst: Instance, view: str) -> int:
    """Visible pixels of ``inst`` in ``view`` (0 without a record)."""
    vis = inst.visibility.get(view)
    return 0 if vis is None else vis.visible_pixels


def _vis_entry(inst: Instance, view: str) -> dict[str, Any]:
    vis = inst.visibility.get(view)
    return {
        "id": inst.id,
        "visible_pixels": None if vis is None else vis.visible_pixels,
        "visible_fraction": None if vis is None else vis.visible_fraction,
    }


def _record(scene: Scene, cand: _Candidate, template: int, thresholds: VisibilityThresholds) -> QARecord:
    counted_ids = [inst.id for inst in cand.counted]
    geometry = {
        "view": cand.view,
        "label": cand.label,
        "image_size": list(cand.image_size),
        "counted": [_vis_entry(inst, cand.view) for inst in cand.counted],
        "not_counted": [{**_vis_entry(inst, cand.view), "class": VisibilityClass.HIDDEN.value} for inst in cand.hidden],
        "thresholds": {"min_pixels": cand.min_pixels, "min_fraction": float(thresholds.min_fraction)},
        "template": template,
    }
    views = (cand.view,)
    return make_record(
        scene, NAME, SUB_QUESTION_TYPE, TaskGroup.OBJECT_CENTRIC, AnswerType.COUNT, views,
        {"label": _label_key(cand.label), "counted": counted_ids, "template": template},
        question=render_question(template, cand.label), answer=len(cand.counted), geometry=geometry,
    )


def generate(scene: Scene, rng: np.random.Generator, thresholds: VisibilityThresholds = DEFAULT_THRESHOLDS) -> Iterator[QARecord]:
    """Every valid counting question of ``scene``, in an order shuffled by ``rng``.

    Reads ``Instance.visibility[view]``; see the module docstring for the rule.
    """
    candidates = _candidates(scene, thresholds)
    order = rng.permutation(len(candidates))
    templates = rng.integers(0, len(TEMPLATES), size=len(candidates))
    for idx in order:
        yield _record(scene, candidates[idx], int(templates[idx]), thresholds)


#: ``make_family(thresholds)``: this family with other visibility thresholds
#: (:class:`~spacedg.plugins.question_family.FamilyFactory`); :data:`FAMILY`, the registered one, uses the defaults.
make_family = FamilyFactory(
    generate, name=NAME, task_group=TaskGroup.OBJECT_CENTRIC, answer_types={AnswerType.COUNT}, sub_question_types=(SUB_QUESTION_TYPE,),
    num_views=(1,), needs={"visibility"}, description="How many clearly visible instances of a label one image shows (grey-zone views skipped).",
)
FAMILY = make_family()
spacedg_register_question_families = registering(FAMILY)

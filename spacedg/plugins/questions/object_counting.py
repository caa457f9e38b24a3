"""Object counting (``question_type = "object_counting"``; object-centric, single view, COUNT).

Rule (SPEC-QA, type 11): for one view and one label, the answer is the number of instances of
that label that are **clearly visible** in the view (:func:`spacedg.scene.visibility.classify`
→ ``VISIBLE``) under :data:`COUNT_THRESHOLDS`. The (view, label) pair is skipped when any
instance of the label is in the grey zone (``PARTIAL``) there, since a viewer could reasonably
count it or not; instances with no visible pixel (``HIDDEN``) are simply not counted.

**Counting as people count** (:data:`COUNT_THRESHOLDS`: ``min_pixels`` 400 at 640×480, as
everywhere, but ``min_fraction`` **0.25**, not the 0.5 of :data:`DEFAULT_THRESHOLDS`): a person
counts the chairs around a table though the table hides their seats, and a chair half out of
frame. With 0.5 every view of a group had one such instance in the grey zone and was skipped,
so no view with several instances was ever asked. An instance is counted when at least 400 px
(scaled) and a quarter of its own projection show; one with fewer pixels or less of it showing
is the grey zone (the view is skipped); the ambiguity rules below still hold. The pair is also skipped when the view
shows (any pixel) an instance that makes the label ambiguous
(:func:`~spacedg.plugins.questions.view_sampling.label_ambiguous`, the scene lexicon
:mod:`spacedg.scene.lexicon`): a related label (counting "chair" beside an armchair, "lamp"
beside a floor lamp, "table" beside a desk) or an object that shows the label without its own
annotation (counting "book" beside a bookshelf full of books). A count of **0** is asked too
(no instance of the label has a visible pixel, and nothing ambiguous is in view), for the
scene's labels and its vocabulary.

Balance (**debiasing**: a blind model that knows the label must not know the count): views
showing several instances are asked (counts 0 to :data:`MAX_COUNT` = 10, :data:`COUNTS`), and
each label is asked equally often in each count **bin** of :data:`COUNT_BINS` (``"0"``, ``"1"``,
``"2+"``: the bin is the record's selection role): a label is asked only when the scene has a
view for every bin, in whole rounds (one view per bin). So neither "always 1" nor a per-label
prior beats a third: a blind model's best exact answer is right at most once per round. Within
the ``"2+"`` bin the views are taken round-robin over their counts, highest first
(:func:`_spread`), so a scene with six chairs in a view asks to count six of them rather than
always two. After the balanced rounds come the other candidates with a count in ``counts``, in a seeded order, with a selection cell
``label:<label>|unbalanced`` that never completes a round: the question index takes them
only when its quota per sub type is smaller than a round (``per_sub_type`` 1 or 2), so a tiny
index is not empty. ``counts=None`` yields every valid candidate instead (any count ≥ 0),
unbalanced.

Labels are grouped case- and underscore-insensitively (``"Chair"``, ``"chair"`` and
``"chair "`` are one label); the question uses the first spelling in id order (the labels are
:func:`~spacedg.plugins.questions.view_sampling.scene_labels`, as for existence).

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
``min_fraction``), ``template`` (index into :data:`TEMPLATES`) and ``selection``
(:func:`~spacedg.plugins.questions.records.selection_entry`: subject = view and label, cell =
the label and the template, roles = the bins of :data:`COUNT_BINS`, role = the count's bin).

Order: every (view, label) candidate is built first (views in scene order, labels in key
order). Balanced: the labels with a view for every bin are visited in the order of one
``rng.permutation``; each label's candidates of each bin are shuffled (``rng.permutation``,
bins in order, as :func:`~spacedg.plugins.questions.records.role_rounds`; the last bin's
then spread over its counts by :func:`_spread`: :func:`_count_rounds`); the stream goes round-robin over the labels, one
round (one view per bin, bins in the order of an ``rng.permutation`` per round) per visit. Each round draws one template (``rng.integers``,
before its permutation) for all its records, so its questions read word for word the same.
Unbalanced (``counts=None``): all candidates in the order of one ``rng.permutation`` with
templates drawn up front. The same seed gives the same records in the same order, and a caller
may stop after any number.
"""

from __future__ import annotations

import functools
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

from spacedg.plugins.candidates import Candidate, offer_if_admitted
from spacedg.plugins.qa_record import QARecord
from spacedg.scene.model import Instance, Scene
from spacedg.plugins.questions.view_sampling import VisibilityIndex, label_ambiguous, scene_labels
from spacedg.scene.visibility_classes import DEFAULT_THRESHOLDS, VisibilityClass, VisibilityThresholds
from spacedg.plugins.hookspecs import registering
from spacedg.plugins.questions.language import label_text, plural
from spacedg.plugins.questions.records import make_record, round_robin, selection_entry
from spacedg.plugins.question_family import FamilyFactory
from spacedg.plugins.specs import AnswerType, TaskGroup

__all__ = ["COUNTS", "COUNT_BINS", "COUNT_THRESHOLDS", "MAX_COUNT", "NAME", "bin_floor", "count_bin", "SUB_QUESTION_TYPE", "TEMPLATES", "FAMILY", "make_family", "generate", "render_question"]

NAME = "object_counting"
SUB_QUESTION_TYPE = "count"
#: The largest count asked (a view showing more instances of a label is not asked).
MAX_COUNT = 10
#: The counts asked (see the module docstring).
COUNTS: tuple[int, ...] = tuple(range(MAX_COUNT + 1))
#: The balance bins, by their smallest count: a label is asked equally often in each (the last
#: bin holds every larger count): ``"0"``, ``"1"``, ``"2+"``.
COUNT_BINS: tuple[int, ...] = (0, 1, 2)


#: The visibility thresholds of counting (module docstring): recognisable = 400 px at 640×480 and a quarter of the object.
COUNT_THRESHOLDS = VisibilityThresholds(min_pixels=DEFAULT_THRESHOLDS.min_pixels, min_fraction=0.25)


def bin_floor(count: int, bins: tuple[int, ...] = COUNT_BINS) -> int:
    """The smallest count of ``count``'s bin (:data:`COUNT_BINS`): 0, 1 or 2."""
    return max(low for low in bins if count >= low)


def count_bin(count: int, bins: tuple[int, ...] = COUNT_BINS) -> str:
    """The bin role of ``count``: ``"0"``, ``"1"``, …, ``"<last>+"`` (:data:`COUNT_BINS`)."""
    low = bin_floor(count, bins)
    return f"{low}+" if low == bins[-1] else str(low)


@functools.lru_cache(maxsize=64)
def _bin_roles(bins: tuple[int, ...] = COUNT_BINS) -> tuple[str, ...]:
    """The count bins' role texts, in bin order (one tuple per ``bins``: every candidate's selection entry reads it)."""
    return tuple(count_bin(low, bins) for low in bins)

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
    key: str
    label: str
    counted: tuple[Instance, ...]
    hidden: tuple[Instance, ...]
    image_size: tuple[int, int]
    min_pixels: float


def _candidates(scene: Scene, index: VisibilityIndex) -> list[_Candidate]:
    labels = scene_labels(scene)
    out: list[_Candidate] = []
    for view, cam in scene.views.items():
        area = cam.width * cam.height
        for label in labels:
            classes = [index.cls(view, inst.id) for inst in label.members]
            if VisibilityClass.PARTIAL in classes:
                continue  # grey zone: the count is ambiguous
            if label_ambiguous(index, view, label.text):
                continue  # counting "chair" beside an armchair, "book" beside a full bookshelf: ambiguous
            counted = tuple(inst for inst, c in zip(label.members, classes) if c is VisibilityClass.VISIBLE)
            hidden = tuple(inst for inst, c in zip(label.members, classes) if c is VisibilityClass.HIDDEN)
            out.append(_Candidate(view, label.key, label.text, counted, hidden, (cam.width, cam.height), index.thresholds.pixels_for(area)))
    return out


def _vis_entry(inst: Instance, view: str) -> dict[str, Any]:
    vis = inst.visibility.get(view)
    return {
        "id": inst.id,
        "visible_pixels": None if vis is None else vis.visible_pixels,
        "visible_fraction": None if vis is None else vis.visible_fraction,
    }


def _subject(cand: _Candidate) -> str:
    """The selection subject of a count: the view and the label."""
    return f"view:{cand.view}|label:{cand.key}"


def _selection(cand: _Candidate, template: int, counts: tuple[int, ...] | None, unbalanced: bool) -> dict[str, Any]:
    """The selection entry of a count (module docstring): subject only when ``counts`` is ``None``."""
    if counts is None:
        return selection_entry(_subject(cand))
    cell = f"label:{cand.key}|unbalanced" if unbalanced else f"label:{cand.key}|template:{template}"
    return selection_entry(_subject(cand), cell, count_bin(len(cand.counted)), _bin_roles())


def _offer(
    scene: Scene, cand: _Candidate, template: int, thresholds: VisibilityThresholds, counts: tuple[int, ...] | None,
    unbalanced: bool = False,
) -> QARecord | Candidate:
    """What the stream yields for ``cand`` (its draws already made): :data:`~spacedg.plugins.candidates.PASSED_OVER`
    when the pool refuses it, else :func:`~spacedg.plugins.candidates.offer` of its record (named objects: none)."""
    return offer_if_admitted(  # type: ignore[return-value]
        SUB_QUESTION_TYPE, (cand.view,), _subject(cand), (), functools.partial(_selection, cand, template, counts, unbalanced),
        functools.partial(_record, scene, cand, template, thresholds, counts, unbalanced),
    )


def _record(
    scene: Scene, cand: _Candidate, template: int, thresholds: VisibilityThresholds, counts: tuple[int, ...] | None,
    unbalanced: bool = False,
) -> QARecord:
    counted_ids = [inst.id for inst in cand.counted]
    count = len(cand.counted)
    geometry: dict[str, Any] = {
        "view": cand.view,
        "label": cand.label,
        "image_size": list(cand.image_size),
        "counted": [_vis_entry(inst, cand.view) for inst in cand.counted],
        "not_counted": [{**_vis_entry(inst, cand.view), "class": VisibilityClass.HIDDEN.value} for inst in cand.hidden],
        "thresholds": {"min_pixels": cand.min_pixels, "min_fraction": float(thresholds.min_fraction)},
        "template": template,
        "selection": _selection(cand, template, counts, unbalanced),
    }
    views = (cand.view,)
    return make_record(
        scene, NAME, SUB_QUESTION_TYPE, TaskGroup.OBJECT_CENTRIC, AnswerType.COUNT, views,
        {"label": cand.key, "counted": counted_ids, "template": template},
        question=render_question(template, cand.label), answer=count, geometry=geometry,
    )


def _spread(group: list[_Candidate]) -> list[_Candidate]:
    """The last bin's candidates (``"2+"``: several counts) round-robin over their counts, highest
    count first (each count's candidates keep their shuffled order), so the rounds a scene can
    afford count the most instances it shows, then the next count, and so on."""
    by_count: dict[int, list[_Candidate]] = {}
    for cand in group:
        by_count.setdefault(len(cand.counted), []).append(cand)
    return list(round_robin(iter(by_count[c]) for c in sorted(by_count, reverse=True)))


def _count_rounds(by_key: dict[str, list[list[_Candidate]]], rng: np.random.Generator) -> list[list[tuple[_Candidate, ...]]]:
    """:func:`~spacedg.plugins.questions.records.role_rounds` (same draws) with each key's last
    bin :func:`_spread` before its rounds are formed."""
    keys = sorted(key for key, groups in by_key.items() if all(groups))
    out: list[list[tuple[_Candidate, ...]]] = []
    for i in rng.permutation(len(keys)):
        shuffled = [[group[int(j)] for j in rng.permutation(len(group))] for group in by_key[keys[int(i)]]]
        out.append(list(zip(*shuffled[:-1], _spread(shuffled[-1]))))
    return out


def generate(
    scene: Scene, rng: np.random.Generator, thresholds: VisibilityThresholds = COUNT_THRESHOLDS,
    counts: tuple[int, ...] | None = COUNTS,
) -> Iterator[QARecord]:
    """Counting questions of ``scene`` in a seeded order: balanced over ``counts`` per label, or
    every valid one when ``counts`` is ``None``.

    Reads ``Instance.visibility[view]``; see the module docstring for the rule and the order.
    """
    index = VisibilityIndex(scene, thresholds)
    candidates = _candidates(scene, index)
    if counts is None:
        order = rng.permutation(len(candidates))
        templates = rng.integers(0, len(TEMPLATES), size=len(candidates))
        for idx in order:
            yield _offer(scene, candidates[idx], int(templates[idx]), thresholds, None)
        return
    counts = tuple(sorted({int(c) for c in counts}))
    roles = _bin_roles()
    by_key: dict[str, list[list[_Candidate]]] = {}
    for cand in candidates:
        by_key.setdefault(cand.key, [[] for _ in roles])
        if len(cand.counted) in counts:
            by_key[cand.key][roles.index(count_bin(len(cand.counted)))].append(cand)
    used: set[int] = set()
    for round_ in round_robin([iter(rounds) for rounds in _count_rounds(by_key, rng)]):
        template = int(rng.integers(0, len(TEMPLATES)))  # one wording per round: the text tells nothing
        for k in rng.permutation(len(roles)):
            used.add(id(round_[int(k)]))
            yield _offer(scene, round_[int(k)], template, thresholds, counts)
    # then the other candidates with an asked count, in a seeded order: their cell never completes
    # a round, so the question index takes them only to fill a quota too small for any round
    rest = [c for c in candidates if id(c) not in used and len(c.counted) in counts]
    for k in rng.permutation(len(rest)):
        yield _offer(scene, rest[int(k)], int(rng.integers(0, len(TEMPLATES))), thresholds, counts, unbalanced=True)


#: ``make_family(thresholds, counts)``: this family with other visibility thresholds or counts
#: (:class:`~spacedg.plugins.question_family.FamilyFactory`); :data:`FAMILY`, the registered one, uses the defaults.
make_family = FamilyFactory(
    generate, name=NAME, task_group=TaskGroup.OBJECT_CENTRIC, answer_types={AnswerType.COUNT}, sub_question_types=(SUB_QUESTION_TYPE,),
    num_views=(1,), needs={"visibility"},
    description="How many recognisable instances (400 px at 640×480 and a quarter of the object) of a label one image shows (0 to 10, balanced per label over 0 / 1 / 2+; grey-zone and ambiguous views skipped).",
)
FAMILY = make_family()
spacedg_register_question_families = registering(FAMILY)

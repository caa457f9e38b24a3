"""Object existence (``question_type = "object_existence_estimation"``; object-centric, 1 view, YN).

For one view and one label the answer is (SPEC-QA, type 10; classes from
:func:`spacedg.scene.visibility.classify` via :class:`~spacedg.plugins.questions.view_sampling.VisibilityIndex`):

- ``"yes"`` when at least one instance of the label is **clearly visible** (``VISIBLE``) in the
  view (other instances of the label may be partial or hidden: there still is one);
- ``"no"`` when **no** instance of the label has a single visible pixel there (all
  ``HIDDEN``, or the label has no instance in the scene at all);
- skipped (grey zone) when none is clearly visible but some instance is ``PARTIAL``, and a
  "no" is skipped when the view shows (any pixel) an instance that makes the label ambiguous
  (:func:`~spacedg.plugins.questions.view_sampling.label_ambiguous`, the scene lexicon
  :mod:`spacedg.scene.lexicon`): a related label ("Is there a chair?" beside an armchair, "a
  monitor?" beside a TV, "a table?" beside a coffee table) or an object that shows the label
  without its own annotation ("a book?" beside a bookshelf full of books).

Labels are grouped by :func:`~spacedg.plugins.questions.view_sampling.label_key` (case, space and
underscore insensitive). Candidate labels are the scene's instance labels (question text: the
first spelling in instance-id order; ``label_source = "scene"``) plus the labels of
``Scene.vocabulary`` that no instance carries (first spelling in vocabulary order;
``label_source = "vocabulary"``; together
:func:`~spacedg.plugins.questions.view_sampling.scene_labels`). So negatives use labels present
elsewhere in the scene or in the scene's category vocabulary; positives are always scene labels. Limitation: a vocabulary
word that names an unannotated or differently-labelled object ("couch" for an annotated
"sofa") cannot be detected here; the vocabulary must use the annotation's label words.

The question names the **label only**, never a description (a description of a specific
instance would leak that it exists). Templates (the paper's appendix, existence), chosen per
record by the seeded ``rng``:

0. ``Is there a <label> visible in this image?``
1. ``Can you find a <label> in the current view?``
2. ``Does the image contain a <label>?``
3. ``Check if a <label> is present in this picture.``

**Deviation**: templates 1–3 of the paper say "the <label>"; a definite article presupposes
that the object exists, so every template uses the indefinite article (``a`` / ``an`` by
:func:`indefinite_article`). ``sub_question_type`` is ``"existence"``.

Balance (exact 50/50 **per label**, so the label tells a blind model nothing): all positive
and negative (view, label) candidates are listed (views in scene order, labels in key order)
and grouped by label; only labels with both a "yes" and a "no" view are asked. The labels
are visited in the order of one ``rng.permutation``; each label's positives and then its
negatives are shuffled by ``rng.permutation`` (in that label order;
:func:`~spacedg.plugins.questions.records.role_rounds`); a fair coin
``rng.random() < 0.5`` chooses whether each label's pair starts with "yes" or "no". The stream
then goes round-robin over the labels, one (yes, no) pair of the label per visit, until a
label runs out of either. It yields ``2 · Σ_label min(#yes, #no)`` records, and **every
prefix** a caller takes is balanced within ±1 overall and per label. Each pair draws one
template (``rng.integers``) for both its records, so a "yes" and a "no" read word for word the
same.

Geometry block (JSON): ``view``, ``label`` (as written in the question), ``label_key``,
``label_source`` (``"scene"`` / ``"vocabulary"``), ``instances`` (every instance of the label:
``id`` with :meth:`VisibilityIndex.vis_entry` — ``visible_pixels``, ``visible_fraction``,
``class``), ``image_size`` ``[width, height]`` px, ``thresholds`` (``min_pixels`` scaled to the
image, ``min_fraction``), ``up``, ``template``, ``refs = []`` (no object is named) and
``selection`` (:func:`~spacedg.plugins.questions.records.selection_entry`: subject = view and
label, cell = the label and the template, roles yes / no). The
answer is independent of geometry, hence invariant under a rigid motion of the scene.
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
from spacedg.plugins.questions.language import indefinite_article, label_text
from spacedg.plugins.questions.records import make_record, role_rounds, round_robin, selection_entry
from spacedg.plugins.question_family import FamilyFactory
from spacedg.plugins.specs import AnswerType, TaskGroup

__all__ = [
    "FAMILY",
    "NAME",
    "SUB_QUESTION_TYPE",
    "TEMPLATES",
    "candidates",
    "generate",
    "make_family",
    "render_question",
]

NAME = "object_existence_estimation"
SUB_QUESTION_TYPE = "existence"

#: ``{article}``: "a" / "an"; ``{label}``: the label text.
TEMPLATES: tuple[str, ...] = (
    "Is there {article} {label} visible in this image?",
    "Can you find {article} {label} in the current view?",
    "Does the image contain {article} {label}?",
    "Check if {article} {label} is present in this picture.",
)


def render_question(template: int, label: str) -> str:
    """The question text of template index ``template`` for ``label``."""
    return TEMPLATES[template].format(article=indefinite_article(label), label=label_text(label))


@dataclass(frozen=True)
class _Candidate:
    view: str
    key: str
    label: str
    source: str
    members: tuple[Instance, ...]
    answer: str


def candidates(scene: Scene, index: VisibilityIndex) -> tuple[list[_Candidate], list[_Candidate]]:
    """``(positives, negatives)`` in a fixed order (views in scene order, labels in key order); grey zone dropped."""
    labels = [label for label in scene_labels(scene) if label.key]
    pos: list[_Candidate] = []
    neg: list[_Candidate] = []
    for view in scene.views:
        for label in labels:
            classes = [index.cls(view, inst.id) for inst in label.members]
            if VisibilityClass.VISIBLE in classes:
                pos.append(_Candidate(view, label.key, label.text, label.source, label.members, "yes"))
            elif all(c is VisibilityClass.HIDDEN for c in classes):
                if label_ambiguous(index, view, label.text):
                    continue  # "no chair" beside an armchair, "no book" beside a full bookshelf: ambiguous
                neg.append(_Candidate(view, label.key, label.text, label.source, label.members, "no"))
            # else: grey zone (some partial, none clearly visible) → skipped
    return pos, neg


def _subject(cand: _Candidate) -> str:
    """The selection subject: the view and the label."""
    return f"view:{cand.view}|label:{cand.key}"


def _selection(cand: _Candidate, template: int) -> dict[str, Any]:
    """The selection entry (module docstring): cell = the label and the template, role = the answer."""
    return selection_entry(_subject(cand), f"label:{cand.key}|template:{template}", cand.answer, ("yes", "no"))


def _offer(scene: Scene, index: VisibilityIndex, cand: _Candidate, template: int) -> QARecord | Candidate:
    """What the stream yields for ``cand`` (its draws already made): :data:`~spacedg.plugins.candidates.PASSED_OVER`
    when the pool refuses it, else :func:`~spacedg.plugins.candidates.offer` of its record (named objects: none)."""
    return offer_if_admitted(  # type: ignore[return-value]
        SUB_QUESTION_TYPE, (cand.view,), _subject(cand), (), functools.partial(_selection, cand, template),
        functools.partial(_record, scene, index, cand, template),
    )


def _record(scene: Scene, index: VisibilityIndex, cand: _Candidate, template: int) -> QARecord:
    cam = scene.views[cand.view]
    area = cam.width * cam.height
    geometry = {
        "view": cand.view,
        "label": cand.label,
        "label_key": cand.key,
        "label_source": cand.source,
        "instances": [{"id": inst.id, **index.vis_entry(cand.view, inst.id)} for inst in cand.members],
        "image_size": [cam.width, cam.height],
        "thresholds": {"min_pixels": index.thresholds.pixels_for(area), "min_fraction": float(index.thresholds.min_fraction)},
        "up": np.asarray(scene.up, dtype=np.float64).tolist(),
        "template": template,
        "refs": [],
        "selection": _selection(cand, template),
    }
    views = (cand.view,)
    return make_record(
        scene, NAME, SUB_QUESTION_TYPE, TaskGroup.OBJECT_CENTRIC, AnswerType.YN, views, {"label": cand.key, "template": template},
        question=render_question(template, cand.label), answer=cand.answer, geometry=geometry,
    )


def generate(scene: Scene, rng: np.random.Generator, thresholds: VisibilityThresholds = DEFAULT_THRESHOLDS) -> Iterator[QARecord]:
    """Existence questions of ``scene``, yes/no balanced per label, round-robin over labels in a seeded order (module docstring)."""
    index = VisibilityIndex(scene, thresholds)
    pos, neg = candidates(scene, index)
    by_key: dict[str, tuple[list[_Candidate], list[_Candidate]]] = {}
    for answer, group in enumerate((pos, neg)):
        for cand in group:
            by_key.setdefault(cand.key, ([], []))[answer].append(cand)
    queues = role_rounds(by_key, rng)
    if not queues:
        return
    yes_first = rng.random() < 0.5
    for yes, no in round_robin([iter(rounds) for rounds in queues]):
        a, b = (yes, no) if yes_first else (no, yes)
        template = int(rng.integers(0, len(TEMPLATES)))  # one wording for both: the text tells nothing
        yield _offer(scene, index, a, template)
        yield _offer(scene, index, b, template)


#: ``make_family(thresholds)``: this family with other visibility thresholds
#: (:class:`~spacedg.plugins.question_family.FamilyFactory`); :data:`FAMILY`, the registered one, uses the defaults.
make_family = FamilyFactory(
    generate, name=NAME, task_group=TaskGroup.OBJECT_CENTRIC, answer_types={AnswerType.YN}, sub_question_types=(SUB_QUESTION_TYPE,),
    num_views=(1,), needs={"visibility"}, plain_rounds=True, description="Whether an object of a label is visible in one image (yes/no balanced 50/50 per label; grey zone and related labels skipped).",
)
FAMILY = make_family()
spacedg_register_question_families = registering(FAMILY)

"""The public SpaceDG bench format: the one place where our records meet the public evaluator's names.

The authors' evaluator (``Visionary-Laboratory/SpaceDG``, ``EASI/VLMEvalKit/vlmeval/dataset/spacedg_bench.py``,
class ``SpaceDGBench``; run by VLMEvalKit as ``--data spacedg_bench``) decides how to score a row
from its ``question_type`` and ``sub_question_type`` alone (its ``infer_eval_task``). Read from its
code (not copied), the rule is:

1. an **empty** ``sub_question_type`` (blank or NaN) routes by ``question_type``
   (:data:`PUBLIC_EMPTY_SUB_ROUTES`): single-view camera-object distance → NA, existence → **MCQ**,
   counting → COUNT, bounding size → SIZE_LIST; any other question type with an empty sub type is
   an error there;
2. otherwise ``distance_threshold`` → YN; ``distance_exact``, ``bbox_center_distance``,
   ``inter_object_distance`` → NA (:data:`PUBLIC_NA_SUB_TYPES`);
3. every other sub type → MCQ.

Names are compared exactly (after stripping spaces), case-sensitively.

Our records keep finer internal sub types (``single_view``, ``count``, ``extent_list``,
``existence``, ``two_view``: used by the question index, stats and debiasing). An export maps them
to the public names here (:func:`to_public`), and :func:`from_public` maps them back, so both
directions are written once. Existence is a yes/no question in substance (the family and its
balance stay); the public evaluator scores it as multiple choice, so it is **rendered** as a
two-option question (:func:`existence_options`): options ``yes`` and ``no`` under the letters
A and B, their order a seeded coin per record id (so the correct letter is A about half the time,
independently of the answer, and the same question reads the same in every export), the answer
the letter. :func:`public_fields` gives every field of an exported row (TSV, chat JSONL, rows of
``spacedg predict`` over a dataset) from a record or a dataset item, so everything a model sees
and every answer it is scored against come from one function.

:func:`public_answer_type` is the public routing rule above, used by the compatibility tests and by
:func:`route`, which routes an exported row exactly as the public evaluator does (and still reads
older exports that carry our internal names); :func:`row_answer_type` is the answer type of a
bench table row (its ``answer_type`` cell, else :func:`route`). The table's own format (columns,
cells, reading and writing) is :mod:`spacedg.data.bench_table`'s.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from spacedg.data.bench_table import cell_text
from spacedg.errors import FileFormatError, InvalidDataError
from spacedg.plugins.answers import answer_text
from spacedg.plugins.specs import AnswerType
from spacedg.seeding import derive_seed

__all__ = [
    "EXISTENCE_OPTION_TEXTS",
    "INTERNAL_ANSWER_TYPES",
    "PUBLIC_BENCH_NAME",
    "PUBLIC_EMPTY_SUB_ROUTES",
    "PUBLIC_NA_SUB_TYPES",
    "PUBLIC_SUB_TYPES",
    "PUBLIC_YN_SUB_TYPES",
    "existence_options",
    "format_question",
    "from_public",
    "internal_answer_type",
    "public_answer_type",
    "public_fields",
    "public_mismatch",
    "route",
    "row_answer_type",
    "to_public",
]

#: The dataset name VLMEvalKit knows the public bench by (``--data spacedg_bench``); the class reads
#: ``$LMUData/spacedg_bench.tsv`` and resolves ``image_path`` entries under ``$LMUData``.
PUBLIC_BENCH_NAME = "spacedg_bench"

#: Public rule 1: the answer type of a row whose ``sub_question_type`` is empty, by ``question_type``
#: (``_QT_WHEN_EMPTY_SQT`` of the public evaluator, including its short aliases).
PUBLIC_EMPTY_SUB_ROUTES: Mapping[str, AnswerType] = {
    "distance_estimation": AnswerType.NA,
    "camera_object_distance_estimation": AnswerType.NA,
    "existence_estimation": AnswerType.MCQ,
    "object_existence_estimation": AnswerType.MCQ,
    "object_counting": AnswerType.COUNT,
    "size_estimation": AnswerType.SIZE_LIST,
    "object_bounding_size_estimation": AnswerType.SIZE_LIST,
}
#: Public rule 2: the only yes/no sub type.
PUBLIC_YN_SUB_TYPES: frozenset[str] = frozenset({"distance_threshold"})
#: Public rule 2: the numerical-answer sub types (``_NA_SUB_QUESTION_TYPES``).
PUBLIC_NA_SUB_TYPES: frozenset[str] = frozenset({"distance_exact", "bbox_center_distance", "inter_object_distance"})

#: ``(question_type, internal sub type) → public sub type`` for every built-in name that differs;
#: every other pair is exported unchanged (and routes the same under both rules).
PUBLIC_SUB_TYPES: Mapping[tuple[str, str], str] = {
    ("camera_object_distance_estimation", "single_view"): "",
    ("object_counting", "count"): "",
    ("object_bounding_size_estimation", "extent_list"): "",
    ("object_existence_estimation", "existence"): "",
    ("inter_object_distance", "two_view"): "inter_object_distance",
}
_FROM_PUBLIC: dict[tuple[str, str], str] = {(q, pub): sub for (q, sub), pub in PUBLIC_SUB_TYPES.items()}

#: The answer type of each internal name in :data:`PUBLIC_SUB_TYPES` (what a record, or an older
#: export that still carries the internal names, holds). Existence is YN here and MCQ once exported.
INTERNAL_ANSWER_TYPES: Mapping[tuple[str, str], AnswerType] = {
    ("camera_object_distance_estimation", "single_view"): AnswerType.NA,
    ("object_counting", "count"): AnswerType.COUNT,
    ("object_bounding_size_estimation", "extent_list"): AnswerType.SIZE_LIST,
    ("object_existence_estimation", "existence"): AnswerType.YN,
    ("inter_object_distance", "two_view"): AnswerType.NA,
}

#: Option texts of an exported existence question (the record's yes/no answers, lower case).
EXISTENCE_OPTION_TEXTS: tuple[str, str] = ("yes", "no")
_EXISTENCE = "object_existence_estimation"


def format_question(question: str, options: Sequence[str]) -> str:
    """The question text with its option lines (MCQ), as a model sees it."""
    return question if not options else question + "\n" + "\n".join(options)


def to_public(question_type: str, sub_question_type: str) -> tuple[str, str]:
    """``(question_type, sub_question_type)`` as the public bench names them (see :data:`PUBLIC_SUB_TYPES`)."""
    qtype, sub = cell_text(question_type), cell_text(sub_question_type)
    return qtype, PUBLIC_SUB_TYPES.get((qtype, sub), sub)


def from_public(question_type: str, sub_question_type: str) -> tuple[str, str]:
    """The inverse of :func:`to_public`: public names back to our internal ones (internal names,
    and names of neither kind, are returned unchanged)."""
    qtype, sub = cell_text(question_type), cell_text(sub_question_type)
    return qtype, _FROM_PUBLIC.get((qtype, sub), sub)


def public_answer_type(question_type: Any, sub_question_type: Any) -> AnswerType:
    """The answer type the public evaluator scores a row with (its ``infer_eval_task``; module docstring).

    Names are compared exactly after stripping; an empty sub type is blank, ``None`` or NaN.

    Raises:
        InvalidDataError: an empty sub type with a question type the public table does not know
            (the public evaluator raises too).
    """
    qtype, sub = cell_text(question_type), cell_text(sub_question_type)
    if not sub:
        if qtype not in PUBLIC_EMPTY_SUB_ROUTES:
            raise InvalidDataError(
                f"sub_question_type is empty but question_type {qtype!r} has no default answer type "
                f"(the public SpaceDG evaluator routes an empty sub type only for {', '.join(sorted(PUBLIC_EMPTY_SUB_ROUTES))}); "
                "give the row its sub_question_type or an answer_type"
            )
        return PUBLIC_EMPTY_SUB_ROUTES[qtype]
    if sub in PUBLIC_YN_SUB_TYPES:
        return AnswerType.YN
    if sub in PUBLIC_NA_SUB_TYPES:
        return AnswerType.NA
    return AnswerType.MCQ


def internal_answer_type(question_type: Any, sub_question_type: Any) -> AnswerType | None:
    """The answer type of one of our internal names that the public bench renames (``None`` for
    any other pair: those route the same under both rules)."""
    return INTERNAL_ANSWER_TYPES.get((cell_text(question_type), cell_text(sub_question_type)))


def route(question_type: str | None, sub_question_type: str | None = None) -> AnswerType:
    """The answer type of a question, routed exactly as the public SpaceDG evaluator routes it.

    The rule (:func:`public_answer_type`, read from the public evaluator's ``infer_eval_task``):

    ==============================================================  ===========
    empty ``sub_question_type``, by ``question_type``:
    ``camera_object_distance_estimation`` (``distance_estimation``)  NA
    ``object_existence_estimation`` (``existence_estimation``)      MCQ
    ``object_counting``                                             COUNT
    ``object_bounding_size_estimation`` (``size_estimation``)       SIZE_LIST
    ``sub_question_type == "distance_threshold"``                   YN
    ``sub_question_type`` in ``distance_exact``,
    ``bbox_center_distance``, ``inter_object_distance``             NA
    any other ``sub_question_type``                                 MCQ
    ==============================================================  ===========

    Our internal names, which records and exports made before the public format carry
    (:data:`INTERNAL_ANSWER_TYPES`: ``single_view`` distance → NA, ``count`` → COUNT,
    ``extent_list`` → SIZE_LIST, ``existence`` → YN, ``two_view`` → NA), route to their own answer
    type first, so those files keep scoring as they were written.

    Names are compared lower-cased and stripped (the public evaluator compares them exactly; every
    exported name is lower case). An empty sub type with a question type outside the table above
    raises :class:`~spacedg.errors.InvalidDataError`, as the public evaluator raises.
    """
    qtype, sub = cell_text(question_type).lower(), cell_text(sub_question_type).lower()
    internal = internal_answer_type(qtype, sub)
    return internal if internal is not None else public_answer_type(qtype, sub)


def row_answer_type(fields: Mapping[str, Any], where: str) -> AnswerType:
    """The answer type of a bench table row: its ``answer_type`` cell (any case), or :func:`route`
    by its names when the cell is blank (pandas writes the answer type ``"NA"`` back as ``NaN``).

    Raises:
        FileFormatError: the cell holds another value (``where`` names the row).
        InvalidDataError: a blank cell whose names :func:`route` cannot route.
    """
    kind = cell_text(fields.get("answer_type")).upper()
    if kind in ("", "NAN", "NONE"):
        return route(fields.get("question_type"), fields.get("sub_question_type"))
    try:
        return AnswerType(kind)
    except ValueError:
        allowed = ", ".join(a.value for a in AnswerType)
        raise FileFormatError(f"{where}: answer_type {kind!r} is not one of {allowed}") from None


def existence_options(record_id: str, answer: str) -> tuple[tuple[str, str], str]:
    """The lettered options and the correct letter of an existence question exported as MCQ.

    ``(("A. yes", "B. no"), "A")`` for a "yes" record whose coin put "yes" first, and so on. The
    order is ``derive_seed(0, "existence_options", record_id)`` modulo 2: fixed per record (the
    question reads the same in every export and under every degradation), independent of the
    answer, so over a set of records the correct letter is A for about half of each answer.
    """
    if answer not in EXISTENCE_OPTION_TEXTS:
        raise InvalidDataError(f"existence record {record_id}: the answer must be 'yes' or 'no', got {answer!r}")
    yes_first = derive_seed(0, "existence_options", record_id) % 2 == 0
    texts = EXISTENCE_OPTION_TEXTS if yes_first else EXISTENCE_OPTION_TEXTS[::-1]
    options = (f"A. {texts[0]}", f"B. {texts[1]}")
    return options, "AB"[texts.index(answer)]


def _get(source: Any, name: str) -> Any:
    return source.get(name) if isinstance(source, Mapping) else getattr(source, name)


def public_fields(source: Any) -> dict[str, Any]:
    """The fields of an exported row, as the public bench carries them, from a
    :class:`~spacedg.plugins.qa_record.QARecord` or a :class:`~spacedg.data.dataset.SpaceDGDataset` item.

    Returns ``{"question", "options", "answer", "answer_type", "question_type", "sub_question_type"}``:
    ``question`` with its option lines (what the model sees), ``options`` the ``"A. text"`` lines,
    ``answer`` the text a model should answer (:func:`~spacedg.plugins.answers.answer_text`; the
    letter for MCQ), ``answer_type`` the value (``"MCQ"``…) the row is scored with, and the public
    names (:func:`to_public`). Existence records become two-option MCQs (:func:`existence_options`).
    """
    record_id = _get(source, "record_id") if isinstance(source, Mapping) else source.id
    kind = AnswerType(str(_get(source, "answer_type")))
    qtype, sub = to_public(_get(source, "question_type"), _get(source, "sub_question_type"))
    question, options, answer = str(_get(source, "question")), list(_get(source, "options") or ()), _get(source, "answer")
    if qtype == _EXISTENCE and kind is AnswerType.YN:
        lines, answer = existence_options(str(record_id), str(answer))
        options, kind = list(lines), AnswerType.MCQ
    return {
        "question": format_question(question, options), "options": options, "answer": answer_text(answer),
        "answer_type": kind.value, "question_type": qtype, "sub_question_type": sub,
    }


def public_mismatch(fields: Mapping[str, Any]) -> str | None:
    """Why the public evaluator would score a row (:func:`public_fields`) with another answer type
    than ours, or ``None`` when the two agree. Only rows of third-party families whose names the
    public table does not know can disagree."""
    try:
        public = public_answer_type(fields["question_type"], fields["sub_question_type"])
    except InvalidDataError as err:
        return str(err)
    if public.value != str(fields["answer_type"]):
        return f"scored as {public.value} by the public evaluator, as {fields['answer_type']} here"
    return None

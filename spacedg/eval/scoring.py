"""Scoring model outputs against SpaceDG answers (SPEC-QA "Scoring"; the paper's evaluation).

The parsers live in :mod:`spacedg.eval.parsing`; this module routes, scores and summarises.

Pipeline for one prediction
---------------------------

1. :func:`extract_answer_text`: the content of the first ``<answer>…</answer>`` (tags
   case-insensitive, content may span lines), else the whole text; stripped. ``None`` → ``""``.
2. The answer type: the record's ``answer_type``, or :func:`~spacedg.data.public_format.route` from
   ``(question_type, sub_question_type)`` when a plain mapping has none (the public evaluator's
   routing rule: an exported row is scored as the same answer type by both).
3. A type-specific parser (each one runs step 1 itself, so raw model text may be passed):
   :func:`parse_mcq`, :func:`parse_yes_no`, :func:`parse_number`, :func:`parse_count`,
   :func:`parse_size_list`. A parser returns ``None`` when it cannot find an unambiguous answer.
4. The score in ``[0, 1]``: MCQ / YN / COUNT exact match (1 or 0); NA
   :func:`mean_relative_accuracy`; SIZE_LIST the mean of the per-edge MRA.
   **An unparseable prediction always scores 0**.

:func:`summarize` averages :class:`ScoreResult` s over **every** answer type and per answer type.

Deliberate deviations from the public evaluator
-----------------------------------------------

Every difference from the public SpaceDG evaluator (VLMEvalKit ``SpaceDGBench`` with its EASI
helpers) is listed in ``docs/scoring.md``, one line each with an example, both scores and the
reason: existence scored as yes/no on records (lettered on exported rows), internal names of
older exports, unparseable truths never a hit, option text → letter, a final letter / yes-no
answer after a correction, hedges, units converted, decimal comma, thousands, number words,
uncertainties and ranges, exact MRA thresholds, truth 0, fractional counts refused, sorted size
lists, extra numbers in size lists, and NA / size lists in the overall figure.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from decimal import Decimal, localcontext
from typing import Any

from spacedg.data.chat import ANSWER_FORMATS, ANSWER_PROMPT  # noqa: F401  (re-exported: the prompt the scorer's answers follow)
from spacedg.data.bench_table import cell_text
from spacedg.data.public_format import route
from spacedg.eval.parsing import (
    parse_count,
    parse_mcq,
    parse_number,
    parse_size_list,
    parse_yes_no,
)
from spacedg.plugins.answers import MCQ_LETTERS
from spacedg.plugins.specs import AnswerType

__all__ = [
    "ANSWER_FORMATS",
    "ANSWER_PROMPT",
    "MRA_THRESHOLDS",
    "SCORER",
    "ScoreResult",
    "route",
    "mean_relative_accuracy",
    "score",
    "summarize",
]

#: Which scorer a report comes from (written into ``summary.json`` and ``report.md`` of ``spacedg eval``).
SCORER: str = (
    "spacedg.eval.scoring: rows routed exactly as the public SpaceDG evaluator (VLMEvalKit SpaceDGBench) routes "
    "them; answers parsed and scored by spacedg's rules, which differ from the public evaluator only as listed in "
    "docs/scoring.md"
)
#: MRA confidence thresholds θ in hundredths: 0.50, 0.55, …, 0.95 (10 values, as in the paper).
MRA_THRESHOLDS: tuple[Decimal, ...] = tuple(Decimal(50 + 5 * k) / 100 for k in range(10))


# ------------------------------------------------------------------ result type
@dataclass(frozen=True)
class ScoreResult:
    """The score of one prediction.

    Attributes:
        score: in ``[0, 1]``; 1/0 for MCQ, YN and COUNT, MRA for NA and SIZE_LIST.
        parsed: what the parser read: an option letter, ``"yes"``/``"no"``, an ``int``, a
            ``float``, a tuple of 3 floats (as compared, i.e. sorted), or ``None``.
        answer_type: the answer type the prediction was scored as.
        parse_ok: whether the parser found an answer (``parsed is not None``).
    """

    score: float
    parsed: str | int | float | tuple[float, ...] | None
    answer_type: AnswerType
    parse_ok: bool


# ------------------------------------------------------------------ MRA
def _exact(value: float) -> Decimal:
    """The shortest decimal that round-trips to ``value`` (what was written: 2.1 → 2.1)."""
    return Decimal(repr(float(value)))


def mean_relative_accuracy(pred: float | None, truth: float) -> float:
    """Mean Relative Accuracy (VSI-Bench / SpaceDG) of one numeric prediction.

    ``e = |pred − truth| / |truth|`` and ``MRA = mean over θ ∈ {0.50, 0.55, …, 0.95} of
    [e ≤ 1 − θ]`` — 10 thresholds, so MRA is a multiple of 0.1: 1.0 for e ≤ 0.05, 0.6 for
    e = 0.25, 0 for e > 0.5.

    Exactness: both numbers are taken as their shortest round-trip decimal strings (``2.1``
    is 2.1, not the binary 2.1000000000000000888…) and compared in exact decimal arithmetic as
    ``|p − t| ≤ (1 − θ)·|t|``, so boundary cases count (truth 2.0, pred 2.1: e = 0.05 exactly
    → counts at θ = 0.95 → MRA 1.0). The public code uses the same 10 thresholds (its
    ``int((0.95 - 0.5) / 0.05 + 2)`` is 10 in floating point) but compares in floating point,
    which drops some boundary hits (truth 0.1, pred 0.08: e = 0.2 exactly, 0.6 there, 0.7 here);
    the paper's definition is followed here.

    Edge cases: ``pred`` ``None`` or non-finite → 0.0. ``truth == 0``: relative error is
    undefined, so MRA is 1.0 when ``pred == 0`` and 0.0 otherwise. A non-finite ``truth``
    raises ``ValueError``. A negative truth uses ``|truth|``.
    """
    try:
        truth_f = float(truth)
    except (TypeError, ValueError):
        raise ValueError(f"mean_relative_accuracy: truth must be a finite number, got {truth!r}") from None
    if not math.isfinite(truth_f):
        raise ValueError(f"mean_relative_accuracy: truth must be a finite number, got {truth!r}")
    if pred is None or isinstance(pred, bool):
        return 0.0
    try:
        pred_f = float(pred)
    except (TypeError, ValueError):
        return 0.0
    if not math.isfinite(pred_f):
        return 0.0
    p, t = _exact(pred_f), _exact(truth_f)
    if t == 0:
        return 1.0 if p == 0 else 0.0
    with localcontext() as ctx:
        ctx.prec = 80
        diff = abs(p - t)
        hits = sum(1 for theta in MRA_THRESHOLDS if diff <= (1 - theta) * abs(t))
    return hits / len(MRA_THRESHOLDS)


# ------------------------------------------------------------------ score
def _field(source: Any, name: str, default: Any = None) -> Any:
    if isinstance(source, Mapping):
        return source.get(name, default)
    return getattr(source, name, default)


def _answer_type_of(source: Any) -> AnswerType:
    kind = _field(source, "answer_type")
    # pandas reads the answer type "NA" (and an empty cell) as NaN: route those by name
    if isinstance(kind, AnswerType) or cell_text(kind).upper() not in ("", "NAN", "NONE"):
        try:
            return AnswerType(kind if isinstance(kind, AnswerType) else str(kind).strip().upper())
        except ValueError:
            raise ValueError(
                f"score: answer_type {kind!r} is not one of {', '.join(a.value for a in AnswerType)}"
            ) from None
    qtype, sub = _field(source, "question_type"), _field(source, "sub_question_type")
    if qtype is None and sub is None:
        raise ValueError("score: give answer_type, or question_type (+ sub_question_type) to route by")
    return route(qtype, sub)


def _options_of(source: Any) -> Sequence[str] | Mapping[str, Any] | None:
    options = _field(source, "options")
    if isinstance(options, str):
        try:
            options = json.loads(options)
        except json.JSONDecodeError:
            options = [line for line in options.splitlines() if line.strip()]
    if options:
        return options
    if isinstance(source, Mapping):  # VLMEvalKit TSV rows carry options as columns A…D
        columns = {k: source[k] for k in MCQ_LETTERS if k in source and cell_text(source[k])}
        return columns or None
    return None


def _truth_number(answer: Any) -> float:
    if isinstance(answer, (int, float)) and not isinstance(answer, bool):
        return float(answer)
    value = parse_number(str(answer), convert_units=False)
    if value is None:
        raise ValueError(f"score: cannot read a numeric ground truth from {answer!r}")
    return value


def _truth_sizes(answer: Any) -> list[float]:
    if isinstance(answer, str):
        values = parse_size_list(answer, convert_units=False)
        if values is None:
            raise ValueError(f"score: cannot read a [shortest, middle, longest] ground truth from {answer!r}")
        return values
    values = [float(v) for v in answer]
    if len(values) != 3:
        raise ValueError(f"score: a SIZE_LIST ground truth has 3 values, got {answer!r}")
    return values


def score(prediction: str | None, record_or_fields: Any, *, sort_sizes: bool = False) -> ScoreResult:
    """Score one model output against a :class:`~spacedg.plugins.qa_record.QARecord` or a mapping.

    ``record_or_fields`` is a ``QARecord`` or any mapping / object with ``answer`` and either
    ``answer_type`` or ``question_type`` (+ ``sub_question_type``) for :func:`route`; MCQ may
    carry ``options`` (``["A. text", …]``, ``{"A": text}``, a JSON string) or, as VLMEvalKit
    TSV rows do, columns ``A``…``D``. Ground truths given as text (TSV) are read leniently:
    ``" b "`` → ``"B"``, ``"Yes"`` → ``"yes"``, ``"2.5"``, ``"[0.1, 0.2, 0.3]"``.

    Rules by answer type:

    * MCQ: :func:`parse_mcq` (with the options); 1 iff the letter equals the truth letter.
      Unparseable → 0 (fixes the reference's unparseable-vs-unparseable hit).
    * YN: :func:`parse_yes_no`; exact match.
    * COUNT: :func:`parse_count`; exact integer match.
    * NA: :func:`parse_number`; :func:`mean_relative_accuracy`.
    * SIZE_LIST: :func:`parse_size_list`; the three predicted edges are compared
      **positionally** with ``[shortest, middle, longest]``, as the public evaluator does and the
      paper decides ("we require the model to output answers in ascending order"; the prompt asks
      for that order). ``sort_sizes=True`` sorts the prediction first (a lenient reading that
      scores the three lengths whatever their order). Score = mean of the 3 MRAs.
    """
    kind = _answer_type_of(record_or_fields)
    truth = _field(record_or_fields, "answer")
    if truth is None:
        raise ValueError("score: the record has no answer")
    parsed: Any
    value = 0.0
    if kind is AnswerType.MCQ:
        parsed = parse_mcq(prediction, _options_of(record_or_fields))
        value = float(parsed is not None and parsed == str(truth).strip().strip(".").upper())
    elif kind is AnswerType.YN:
        parsed = parse_yes_no(prediction)
        value = float(parsed is not None and parsed == str(truth).strip().lower())
    elif kind is AnswerType.COUNT:
        parsed = parse_count(prediction)
        value = float(parsed is not None and parsed == _truth_number(truth))
    elif kind is AnswerType.NA:
        parsed = parse_number(prediction)
        value = mean_relative_accuracy(parsed, _truth_number(truth))
    else:
        sizes = parse_size_list(prediction)
        truth_sizes = _truth_sizes(truth)
        parsed = None
        if sizes is not None:
            parsed = tuple(sorted(sizes)) if sort_sizes else tuple(sizes)
            value = sum(mean_relative_accuracy(p, t) for p, t in zip(parsed, truth_sizes)) / 3
    return ScoreResult(score=value, parsed=parsed, answer_type=kind, parse_ok=parsed is not None)


# ------------------------------------------------------------------ summary
def _group_stats(results: Sequence[ScoreResult]) -> dict[str, Any]:
    n = len(results)
    return {
        "n": n,
        "score": (sum(r.score for r in results) / n) if n else None,
        "parse_rate": (sum(r.parse_ok for r in results) / n) if n else None,
    }


def summarize(
    results: Iterable[ScoreResult],
    groups: Mapping[str, Sequence[Any]] | None = None,
) -> dict[str, Any]:
    """Mean scores of ``results``: overall over **every** answer type, and per answer type.

    Returns a JSON-ready dict::

        {"overall": {"n", "score", "parse_rate"},
         "by_answer_type": {"MCQ": {...}, "YN": {...}, "NA": {...}, ...},   # types present
         "by_<name>": {label: {...}}}                                      # for each group

    ``score`` is the mean of the per-question scores (accuracy for MCQ/YN/COUNT, mean MRA for
    NA/SIZE_LIST); ``overall`` weights every question equally whatever its type (the public
    evaluator left NA and SIZE_LIST out of its overall figure; fixed). ``parse_rate`` is the
    share of predictions the parser could read. ``score`` and ``parse_rate`` are ``None`` for
    an empty set. ``groups`` maps a name (e.g. ``"degradation_type"``, ``"question_type"``)
    to one label per result, in the same order.
    """
    items = list(results)
    summary: dict[str, Any] = {"overall": _group_stats(items)}
    by_type: dict[str, list[ScoreResult]] = {}
    for r in items:
        by_type.setdefault(AnswerType(r.answer_type).value, []).append(r)
    order = [a.value for a in AnswerType if a.value in by_type]
    summary["by_answer_type"] = {k: _group_stats(by_type[k]) for k in order}
    for name, labels in (groups or {}).items():
        labels = list(labels)
        if len(labels) != len(items):
            raise ValueError(f"summarize: group {name!r} has {len(labels)} labels for {len(items)} results")
        buckets: dict[str, list[ScoreResult]] = {}
        for label, r in zip(labels, items):
            buckets.setdefault(str(label), []).append(r)
        summary[f"by_{name}"] = {k: _group_stats(v) for k, v in sorted(buckets.items())}
    return summary

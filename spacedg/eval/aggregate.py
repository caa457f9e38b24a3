"""Scoring prediction sets against a bench and averaging the scores into the paper's slices.

Conventions (the paper's Table 1):

* A **condition** is a ``degradation_type``: ``"ori"`` (clean) or a degradation (chain) name.
* The score of a set of items is the mean of the per-item scores (accuracy for MCQ/YN/COUNT,
  MRA for NA/SIZE_LIST), every answer type counted (see :func:`spacedg.eval.scoring.summarize`).
* **Avg.** is the mean of the per-degradation scores (clean excluded), each degradation
  weighted equally, as in the paper (GPT-5.4's row: the mean of its nine degradation columns is
  its Avg. 46.2). On a bench with the same items under every degradation this equals the mean
  over all degraded items.
* **Answer format** (the paper's Figure 5b): MCA = MCQ and yes/no; NA = numbers, counts and
  size lists.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

from spacedg.data.public_format import from_public
from spacedg.errors import InvalidDataError
from spacedg.eval.bench import CLEAN, BenchRow
from spacedg.eval.predictions import PredictionSet
from spacedg.eval.scoring import score
from spacedg.plugins.specs import AnswerType

__all__ = [
    "AVG",
    "SLICE_KINDS",
    "MISSING_POLICIES",
    "ItemScore",
    "answer_format",
    "condition_order",
    "mean",
    "score_set",
    "slice_table",
]

#: Column key of the average over degradations.
AVG = "avg"
#: Slice kinds the report breaks scores down by, with their display names.
SLICE_KINDS: dict[str, str] = {
    "task_group": "Task group",
    "question_type": "Question type",
    "sub_question_type": "Sub type",
    "answer_type": "Answer type",
    "answer_format": "Answer format",
}


def answer_format(answer_type: str) -> str:
    """``"MCA"`` for multiple choice and yes/no, ``"NA"`` for numeric answers (number, count, size list)."""
    return "MCA" if answer_type in (AnswerType.MCQ.value, AnswerType.YN.value) else "NA"


@dataclass(frozen=True)
class ItemScore:
    """The score of one prediction, with the row's labels.

    ``parsed`` is what the parser read (``None`` when unreadable); ``missing`` marks an item
    the prediction file has no answer for (scored 0, only with ``missing="wrong"``).
    """

    index: int
    record_id: str
    degradation_type: str
    question_type: str
    sub_question_type: str
    task_group: str
    answer_type: str
    answer: str
    prediction: str
    parsed: object
    score: float
    parse_ok: bool
    missing: bool = False

    def label(self, kind: str) -> str:
        """This item's slice under ``kind`` (a key of :data:`SLICE_KINDS`, or ``"all"``)."""
        if kind == "all":
            return "all"
        if kind == "answer_format":
            return answer_format(self.answer_type)
        return getattr(self, kind) or "unknown"


def _same_answer(a: str, b: str) -> bool:
    """Answers equal as text, or as numbers (a spreadsheet turns ``"2.50"`` into ``2.5``)."""
    if a.strip().lower() == b.strip().lower():
        return True
    try:
        return float(a) == float(b)
    except ValueError:
        return False


def _truth_rows(pred: PredictionSet, bench_rows: Mapping[int, BenchRow] | None) -> Mapping[int, BenchRow]:
    if bench_rows is None:
        lacking = [i for i in pred.predictions if i not in pred.rows]
        if lacking:
            raise InvalidDataError(
                f"{pred.path}: {len(lacking)} prediction(s) (first index {lacking[0]}) do not carry their question and answer; "
                "pass the bench they were made on with --bench DIR"
            )
        return pred.rows
    unknown = sorted(set(pred.predictions) - set(bench_rows))
    if unknown:
        raise InvalidDataError(
            f"{pred.path}: {len(unknown)} prediction(s) refer to indices not in the bench (first {unknown[0]}); "
            "were they made on another bench?"
        )
    for index, own in pred.rows.items():
        truth = bench_rows[index]
        if own.question.strip() != truth.question.strip() or not _same_answer(own.answer, truth.answer):
            raise InvalidDataError(
                f"{pred.path}: index {index} carries another question or answer than the bench "
                f"({own.record_id or own.question[:40]!r} vs {truth.record_id or truth.question[:40]!r}); "
                "the predictions were made on another bench"
            )
    return bench_rows


#: What :func:`score_set` does with a bench item that has no prediction.
MISSING_POLICIES = ("error", "wrong", "skip")


def score_set(pred: PredictionSet, bench_rows: Mapping[int, BenchRow] | None = None, *, missing: str = "error") -> list[ItemScore]:
    """Score every item of the bench (or, without one, every item the file carries).

    A bench item without a prediction is, by ``missing``: ``"error"`` (default) an error naming
    how many are missing; ``"wrong"`` scored 0 and marked ``missing`` (the report counts them);
    ``"skip"`` left out, so only the answered items are scored (a subset evaluation, such as the
    paper's human study on part of the bench).
    """
    if missing not in MISSING_POLICIES:
        raise ValueError(f"missing must be one of {', '.join(MISSING_POLICIES)}, got {missing!r}")
    rows = _truth_rows(pred, bench_rows)
    absent = [i for i in rows if i not in pred.predictions]
    if absent and missing == "error":
        raise InvalidDataError(
            f"{pred.path}: {len(absent)} of {len(rows)} bench items have no prediction (first index {min(absent)}); "
            "finish the run (spacedg predict resumes), or pass --missing wrong to score them as wrong, "
            "or --missing skip to score only the answered items"
        )
    out = []
    for index in sorted(rows):
        if missing == "skip" and index not in pred.predictions:
            continue
        row = rows[index]
        text = pred.predictions.get(index)
        result = score(text, row.scoring_fields())
        out.append(ItemScore(
            index=index, record_id=row.record_id, degradation_type=row.degradation_type,
            question_type=row.question_type, task_group=row.task_group,
            # our finer sub type names (the public bench leaves single-view types blank): labels stay the same
            # for exports in the public format and older ones
            sub_question_type=from_public(row.question_type, row.sub_question_type)[1],
            answer_type=result.answer_type.value, answer=row.answer, prediction=text or "",
            parsed=result.parsed, score=result.score, parse_ok=result.parse_ok, missing=text is None,
        ))
    return out


def mean(values: Iterable[float]) -> float:
    """Mean of finite values; NaN when there are none."""
    kept = [v for v in values if v is not None and math.isfinite(v)]
    return math.fsum(kept) / len(kept) if kept else math.nan


def condition_order(conditions: Iterable[str], known: Sequence[str]) -> list[str]:
    """Clean first, then the ``known`` degradations in their order, then any other chains sorted."""
    present = set(conditions)
    ordered = [CLEAN] if CLEAN in present else []
    ordered += [name for name in known if name in present]
    ordered += sorted(present - set(ordered))
    return ordered


@dataclass(frozen=True)
class Cell:
    """Mean score and item count of one (slice, condition)."""

    score: float
    n: int
    parse_rate: float


def slice_table(items: Sequence[ItemScore], kind: str, conditions: Sequence[str]) -> dict[str, dict[str, Cell]]:
    """``slice → condition → Cell`` for ``kind`` (``"all"`` or a key of :data:`SLICE_KINDS`),
    plus ``AVG`` per slice: the mean of its degradation cells (NaN when it has none)."""
    buckets: dict[str, dict[str, list[ItemScore]]] = {}
    for item in items:
        buckets.setdefault(item.label(kind), {}).setdefault(item.degradation_type, []).append(item)
    table: dict[str, dict[str, Cell]] = {}
    for label in sorted(buckets):
        row: dict[str, Cell] = {}
        for condition in conditions:
            group = buckets[label].get(condition, [])
            if group:
                row[condition] = Cell(mean(i.score for i in group), len(group), mean(float(i.parse_ok) for i in group))
        degraded = [c for k, c in row.items() if k != CLEAN]
        row[AVG] = Cell(
            mean(c.score for c in degraded), sum(c.n for c in degraded),
            mean(c.parse_rate for c in degraded),
        )
        table[label] = row
    return table

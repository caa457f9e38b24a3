"""Dealing the options of the selected MCQ records again: distractors, then correct letters.

After :func:`~spacedg.qa.selection.select_records` has kept a family's records, the
sector-label questions get their distractors dealt so every text is offered about equally
often (:func:`deal_distractors`), then the correct letters are dealt from shuffled A–D blocks
(:func:`deal_letters`), so letters are uniform per sub type. Both are seeded by the caller
(:mod:`spacedg.qa.build`).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence

import numpy as np

from spacedg.plugins.answers import MCQ_LETTERS
from spacedg.plugins.qa_record import QARecord
from spacedg.plugins.specs import AnswerType
from spacedg.qa.selection import selection_of, truth_key

__all__ = ["with_letter", "deal_distractors", "deal_letters"]


def with_letter(record: QARecord, slot: int) -> QARecord:
    """``record`` (MCQ) with its correct option moved to letter ``slot`` (0 … options − 1), the other options
    keeping their order: the same question and answer text, another letter."""

    texts = [line[3:] for line in record.options]
    k = MCQ_LETTERS.index(str(record.answer))
    others = texts[:k] + texts[k + 1:]
    texts = others[:slot] + [texts[k]] + others[slot:]
    return record.with_changes(options=tuple(f"{MCQ_LETTERS[i]}. {t}" for i, t in enumerate(texts)), answer=MCQ_LETTERS[slot])


def _with_distractors(record: QARecord, picked: Sequence[str]) -> QARecord:
    """``record`` with ``picked`` (three texts, in order) around its truth, which keeps its letter."""
    slot = MCQ_LETTERS.index(str(record.answer))
    texts = [*picked[:slot], str(truth_key(record)), *picked[slot:]]
    return record.with_changes(options=tuple(f"{MCQ_LETTERS[i]}. {t}" for i, t in enumerate(texts)))


def _deal_sub_type(out: list[QARecord], ks: Sequence[int], rng: np.random.Generator) -> None:
    """Deal the distractors of the records ``out[k]`` for ``k`` in ``ks`` (one sub type), in place."""
    offered: Counter[str] = Counter(truth_key(out[k]) for k in ks)
    for j in rng.permutation(len(ks)):
        r = out[ks[int(j)]]
        truth = str(truth_key(r))
        allowed = sorted({str(t) for t in selection_of(r)["distractors"]} - {truth})  # type: ignore[index]
        if len(allowed) < 3:
            continue
        ties = rng.random(len(allowed))
        picked = [allowed[i] for i in sorted(range(len(allowed)), key=lambda i: (offered[allowed[i]], ties[i]))[:3]]
        picked = [picked[i] for i in rng.permutation(3)]
        offered.update(picked)
        out[ks[int(j)]] = _with_distractors(r, picked)


def deal_distractors(records: Sequence[QARecord], rng: np.random.Generator) -> list[QARecord]:
    """The MCQ ``records`` whose selection entry lists ``distractors`` (the texts that may be one)
    with their three distractors dealt again, per sub type: the truths stay, and the
    distractors of each record (visited in an order drawn from ``rng``) are the allowed texts
    offered least often so far in the sub type (ties broken by ``rng``), in an ``rng`` order. So
    every text is offered about equally often, and, the truths being balanced by the rounds,
    is right about as often as any other when offered (a text offered more often than the others
    would be right less often, which a blind model learns). The correct option keeps its letter
    (:func:`deal_letters` deals the letters afterwards); other records are returned unchanged."""

    out = list(records)
    by_sub: dict[str, list[int]] = {}
    for k, r in enumerate(out):
        sel = selection_of(r)
        if r.answer_type is AnswerType.MCQ and sel is not None and isinstance(sel.get("distractors"), list):
            by_sub.setdefault(r.sub_question_type, []).append(k)
    for sub in sorted(by_sub):
        _deal_sub_type(out, by_sub[sub], rng)
    return out


def deal_letters(records: Sequence[QARecord], rng: np.random.Generator) -> list[QARecord]:
    """The MCQ ``records`` with their correct letters dealt again, per sub type in the given
    order, from shuffled A–D blocks of ``rng``: the letters of each sub type of a scene's index
    are uniform to within one block (the selection keeps a subset of a family's records, whose
    letters were balanced over the whole generation only). Only records with a ``selection``
    entry are re-lettered: their geometry never refers to option positions (families without
    one keep their letters)."""
    decks: dict[tuple[str, int], list[int]] = {}
    out = []
    for r in records:
        if r.answer_type is not AnswerType.MCQ or selection_of(r) is None:
            out.append(r)  # a family without selection entries may tie its geometry to the option order
            continue
        n = len(r.options)
        deck = decks.setdefault((r.sub_question_type, n), [])
        if not deck:
            deck.extend(int(v) for v in rng.permutation(n))
        out.append(with_letter(r, deck.pop()))
    return out

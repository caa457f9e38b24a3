"""The count-based blind predictors of the stress test, fitted per question type on training records.

``letter``
    the most frequent correct letter (MCQ).
``majority``
    the most frequent correct answer text (MCQ option text, yes/no, count) per question
    *template* (:func:`~spacedg.qa.audit_text.template_signature`); e.g. always "1" for counts.
``option_text``
    MCQ: each option's training rate of being correct given its text (object phrases read as
    their label), the highest wins.
``label``
    per-label priors: existence → the majority answer per label; counting → the majority
    count per label; size comparison → the mean measured value per label and the object with
    the larger mean; other MCQ → the majority answer per (template, labels); metric answers →
    the geometric mean answer per label(s).
"""

from __future__ import annotations

from collections import Counter, defaultdict
from collections.abc import Sequence
from typing import Any

import numpy as np

from spacedg.plugins.answers import MCQ_LETTERS
from spacedg.plugins.qa_record import QARecord
from spacedg.plugins.questions.language import object_phrase
from spacedg.plugins.specs import AnswerType
from spacedg.qa.audit_text import option_role, record_labels, template_signature, truth_text
from spacedg.qa.stats import option_text

__all__ = ["Priors"]


def _majority(counter: Counter[str] | None) -> str | None:
    if not counter:
        return None
    return sorted(counter.items(), key=lambda kv: (-kv[1], kv[0]))[0][0]


def _best_option(record: QARecord, *counters: Counter[str] | None) -> str:
    """The option whose role was correct most often in the first counter that knows any of the
    record's options (later counters break ties and fill in); ties → the earlier letter."""
    letters = MCQ_LETTERS[:len(record.options)]
    roles = [option_role(record, option_text(record, k)) for k in letters]
    keys = []
    for k, role in enumerate(roles):
        keys.append((tuple((c or {}).get(role, 0) for c in counters), -k))
    return letters[max(range(len(letters)), key=lambda k: keys[k])]


def _size_values(record: QARecord) -> list[tuple[str, float]]:
    g = record.geometry
    objs, values = g.get("objects") or [], g.get("values") or []
    return [(str(o.get("label", "")).lower(), float(v)) for o, v in zip(objs, values)]


def _log_answer(record: QARecord) -> np.ndarray:
    return np.log(np.maximum(np.atleast_1d(np.asarray(record.answer, dtype=np.float64)), 1e-3))


class Priors:
    """The count-based predictors of one question type, fitted on training records
    (``frequent``: the question type's template words); :meth:`predict` answers by name."""

    def __init__(self, train: Sequence[QARecord], frequent: frozenset[str]) -> None:
        self.frequent = frequent
        self.letters: Counter[str] = Counter()
        self.by_sig: dict[str, Counter[str]] = defaultdict(Counter)
        self.overall: Counter[str] = Counter()
        self.text_hits: Counter[str] = Counter()
        self.text_seen: Counter[str] = Counter()
        self.by_labels: dict[tuple[str, ...], Counter[str]] = defaultdict(Counter)
        self.size_sum: dict[tuple[str, str], list[float]] = defaultdict(lambda: [0.0, 0.0])
        self.metric: dict[tuple[str, ...], list[np.ndarray]] = defaultdict(list)
        self.metric_all: list[np.ndarray] = []
        for r in train:
            sig = template_signature(r, frequent)
            if r.answer_type is AnswerType.MCQ:
                self._add_mcq(r, sig)
            elif r.answer_type in (AnswerType.YN, AnswerType.COUNT):
                self.by_sig[sig][str(r.answer)] += 1
                self.overall[str(r.answer)] += 1
                self.by_labels[(sig, *record_labels(r))][str(r.answer)] += 1
                self.by_labels[record_labels(r)][str(r.answer)] += 1
            else:
                value = _log_answer(r)
                self.metric[record_labels(r)].append(value)
                self.metric_all.append(value)

    def _add_mcq(self, r: QARecord, sig: str) -> None:
        self.letters[str(r.answer)] += 1
        truth = option_role(r, truth_text(r))
        for k in MCQ_LETTERS[:len(r.options)]:
            self.text_seen[option_role(r, option_text(r, k))] += 1
        self.text_hits[truth] += 1
        self.by_sig[sig][truth] += 1
        self.overall[truth] += 1
        self.by_labels[(sig, *record_labels(r))][truth] += 1
        for label, value in _size_values(r):
            acc = self.size_sum[(sig, label)]
            acc[0] += value
            acc[1] += 1

    def predict(self, name: str, record: QARecord) -> Any:
        """Predictor ``name``'s answer to ``record`` (a letter, an answer text, a value), or ``None``."""
        sig = template_signature(record, self.frequent)
        kind = record.answer_type
        if kind in (AnswerType.NA, AnswerType.SIZE_LIST):
            return self._metric(name, record)
        if name == "letter":
            return _majority(self.letters) if kind is AnswerType.MCQ else None
        if name == "majority":
            if kind is AnswerType.MCQ:
                return _best_option(record, self.by_sig.get(sig), self.overall)
            return _majority(self.by_sig.get(sig)) or _majority(self.overall)
        if name == "option_text":
            return self._option_text(record) if kind is AnswerType.MCQ else None
        if name == "label":
            return self._label(record, sig)
        return None

    def _metric(self, name: str, record: QARecord) -> Any:
        """``majority`` / ``label`` for metric answers: the geometric mean (per label(s))."""
        if name == "majority":
            values = self.metric_all
        elif name == "label":
            values = self.metric.get(record_labels(record)) or self.metric_all
        else:
            return None
        if not values:
            return None
        mean = np.exp(np.mean(values, axis=0))
        return float(mean[0]) if record.answer_type is AnswerType.NA else tuple(float(v) for v in np.sort(mean))

    def _option_text(self, record: QARecord) -> str:
        rates = []
        for k in MCQ_LETTERS[:len(record.options)]:
            role = option_role(record, option_text(record, k))
            rates.append(((self.text_hits[role] + 0.5) / (self.text_seen[role] + 2.0), -MCQ_LETTERS.index(k), k))
        return max(rates)[2]

    def _larger_by_label(self, record: QARecord, sig: str) -> str | None:
        """Size comparison: the letter of the object whose label has the larger mean measured value."""
        sizes = _size_values(record)
        if len(sizes) != 2 or not all(self.size_sum.get((sig, lab), (0, 0))[1] for lab, _ in sizes):
            return None
        means = [self.size_sum[(sig, lab)][0] / self.size_sum[(sig, lab)][1] for lab, _ in sizes]
        which = 0 if means[0] >= means[1] else 1
        phrase = (record.geometry.get("objects") or [])[which]
        wanted = object_phrase(str(phrase.get("label", "")), str(phrase.get("description", "")))
        for k in MCQ_LETTERS:
            if " ".join(option_text(record, k).lower().split()) == " ".join(wanted.lower().split()):
                return k
        return None

    def _label(self, record: QARecord, sig: str) -> str | None:
        labels = record_labels(record)
        if record.answer_type is AnswerType.MCQ:
            larger = self._larger_by_label(record, sig)
            if larger is not None:
                return larger
            return _best_option(record, self.by_labels.get((sig, *labels)), self.by_sig.get(sig), self.overall)
        guess = _majority(self.by_labels.get((sig, *labels))) or _majority(self.by_labels.get(labels))
        return guess or _majority(self.by_sig.get(sig)) or _majority(self.overall)

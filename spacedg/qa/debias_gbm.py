"""A small gradient-boosted blind predictor: trees on the audit's text features, softmax over candidates.

The bench-level pruning (:mod:`spacedg.qa.debias`) probes a bench with the blind stress test's
predictors (:mod:`spacedg.qa.audit`) and with this stronger, still cheap one. It reads exactly what
the audit's learned model reads (:func:`~spacedg.qa.audit_model.record_features`,
:func:`~spacedg.qa.audit_model.option_features`: question words, number bins, labels, template,
option words and roles) and nothing else (no images, no geometry, no sub type).

Every question is a choice among *candidates*, each a row of binary features:

- MCQ: its four options (the option's features plus the record's, so trees can cross them);
- YN / COUNT: the answers seen in training (``c:<answer>`` plus the record's features).

Depth-limited regression trees on the rows are boosted on the softmax loss over a question's
candidates (Newton steps: leaf value ``-lr · G / (H + l2)``, diagonal Hessian ``p (1 - p)``),
from zero scores. Features: the ``max_features`` most frequent among those seen at least twice
in training (ties by name), as a dense 0/1 matrix. Plain numpy, deterministic (no sampling; ties
go to the lower feature column).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from typing import Any

import numpy as np

from spacedg.plugins.answers import MCQ_LETTERS
from spacedg.plugins.qa_record import QARecord
from spacedg.plugins.specs import AnswerType
from spacedg.qa.audit_model import option_features, record_features
from spacedg.qa.audit_text import template_signature
from spacedg.qa.stats import option_text

__all__ = ["BoostedChoice", "candidate_rows"]

_Tree = Any  # ("leaf", value) or ("split", column, left tree, right tree)


def candidate_rows(record: QARecord, frequent: frozenset[str], classes: Sequence[str]) -> list[list[str]]:
    """The feature rows of ``record``'s candidates: its four options (MCQ) or ``classes`` (YN, COUNT)."""
    base = record_features(record, frequent)
    if record.answer_type is AnswerType.MCQ:
        sig = template_signature(record, frequent)
        return [option_features(record, option_text(record, k), sig) + base for k in MCQ_LETTERS]
    return [[f"c:{c}"] + [f"{f}|c:{c}" for f in base[:2]] + base for c in classes]


def _softmax_rows(scores: np.ndarray) -> np.ndarray:
    z = scores - scores.max(axis=1, keepdims=True)
    e = np.exp(z)
    return e / e.sum(axis=1, keepdims=True)


class BoostedChoice:
    """Boosted trees scoring a question's candidates; :meth:`predict_many` returns each record's best
    candidate's answer (a letter, ``"yes"``/``"no"`` or a count as text).

    Args:
        train: records of one question type and one answer type (MCQ, YN or COUNT).
        frequent: the question type's template words (:func:`~spacedg.qa.audit_text.frequent_words`).
        trees / depth / lr / l2: boosting rounds, tree depth, shrinkage, leaf L2.
        max_features: columns kept (most frequent features).
    """

    def __init__(self, train: Sequence[QARecord], frequent: frozenset[str], *, trees: int = 30, depth: int = 3,
                 lr: float = 0.3, l2: float = 1.0, max_features: int = 256) -> None:
        self.frequent = frequent
        self.kind = train[0].answer_type if train else AnswerType.MCQ
        self.classes = sorted({str(r.answer) for r in train}) if self.kind is not AnswerType.MCQ else list(MCQ_LETTERS)
        self.depth, self.lr, self.l2 = depth, lr, l2
        self.trees: list[_Tree] = []
        if not train or len(self.classes) < 1:
            self.columns: dict[str, int] = {}
            return
        docs = [candidate_rows(r, frequent, self.classes) for r in train]
        counts: Counter[str] = Counter(f for doc in docs for row in doc for f in set(row))
        kept = sorted((f for f, c in counts.items() if c >= 2), key=lambda f: (-counts[f], f))[:max_features]
        self.columns = {f: i for i, f in enumerate(kept)}
        x = self._matrix(docs)
        y = np.array([self._truth_index(r) for r in train])
        self._boost(x, y, trees)

    def _truth_index(self, record: QARecord) -> int:
        answer = str(record.answer)
        return self.classes.index(answer) if answer in self.classes else -1

    def _matrix(self, docs: Sequence[Sequence[Sequence[str]]]) -> np.ndarray:
        """Rows (records × candidates) × columns, 0/1 float32."""
        k = len(self.classes)
        x = np.zeros((len(docs) * k, len(self.columns)), dtype=np.float32)
        for i, doc in enumerate(docs):
            for j, row in enumerate(doc):
                cols = [self.columns[f] for f in row if f in self.columns]
                x[i * k + j, cols] = 1.0
        return x

    def _boost(self, x: np.ndarray, y: np.ndarray, trees: int) -> None:
        k = len(self.classes)
        target = np.zeros((len(y), k))
        known = y >= 0
        target[np.flatnonzero(known), y[known]] = 1.0
        scores = np.zeros(len(y) * k)
        for _ in range(trees):
            p = _softmax_rows(scores.reshape(-1, k))
            g = (p - target).ravel()
            h = np.maximum((p * (1.0 - p)).ravel(), 1e-6)
            tree = self._grow(x, g, h, np.arange(len(g)), self.depth)
            self.trees.append(tree)
            scores += _apply(tree, x)

    def _grow(self, x: np.ndarray, g: np.ndarray, h: np.ndarray, idx: np.ndarray, depth: int) -> _Tree:
        big_g, big_h = float(g[idx].sum()), float(h[idx].sum())
        leaf = ("leaf", -self.lr * big_g / (big_h + self.l2))
        if depth == 0 or len(idx) < 8 or x.shape[1] == 0:
            return leaf
        sub = x[idx]
        gl, hl = sub.T @ g[idx], sub.T @ h[idx]
        gr, hr = big_g - gl, big_h - hl
        gain = gl**2 / (hl + self.l2) + gr**2 / (hr + self.l2) - big_g**2 / (big_h + self.l2)
        gain[(hl < 0.5) | (hr < 0.5)] = -np.inf
        col = int(np.argmax(gain))
        if not np.isfinite(gain[col]) or gain[col] <= 1e-9:
            return leaf
        on = sub[:, col] > 0.5
        return ("split", col, self._grow(x, g, h, idx[~on], depth - 1), self._grow(x, g, h, idx[on], depth - 1))

    def scores(self, records: Sequence[QARecord]) -> np.ndarray:
        """Candidate scores, records × candidates (:attr:`classes` order)."""
        x = self._matrix([candidate_rows(r, self.frequent, self.classes) for r in records])
        total = np.zeros(x.shape[0])
        for tree in self.trees:
            total += _apply(tree, x)
        return total.reshape(len(records), len(self.classes))

    def predict_many(self, records: Sequence[QARecord]) -> tuple[list[str], np.ndarray]:
        """Each record's highest-scoring answer (ties: the first candidate) and the softmax probability
        of its true answer (0 when the truth is no candidate)."""
        if not records or not self.classes:
            return [""] * len(records), np.zeros(len(records))
        probs = _softmax_rows(self.scores(records))
        answers = [self.classes[int(k)] for k in np.argmax(probs, axis=1)]
        truth = np.array([probs[i, t] if t >= 0 else 0.0 for i, t in enumerate(self._truth_index(r) for r in records)])
        return answers, truth


def _apply(tree: _Tree, x: np.ndarray) -> np.ndarray:
    """The tree's value on every row of ``x``."""
    if tree[0] == "leaf":
        return np.full(x.shape[0], tree[1])
    _, col, left, right = tree
    out = np.empty(x.shape[0])
    on = x[:, col] > 0.5
    if on.any():
        out[on] = _apply(right, x[on])
    if (~on).any():
        out[~on] = _apply(left, x[~on])
    return out

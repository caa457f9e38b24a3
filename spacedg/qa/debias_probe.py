"""The pooled blind probe of a bench: k-fold by scene, every text-only predictor, chance over options shown.

:func:`probe` pools a set of question records (one bench, many scenes), deals the scenes into
``folds`` groups (:func:`scene_folds`: a seeded order, dealt round-robin, so a fold is a set of
whole scenes: leave-scenes-out), and for each fold fits on the others and scores its records with

- the blind stress test's predictors (:data:`spacedg.qa.audit.PREDICTORS`: majority letter,
  majority answer per template, option-text prior, per-label priors, the logistic model), via
  :func:`spacedg.qa.audit.held_out_scores` with the folds as its "scenes";
- ``boosted``: gradient-boosted trees on the same text features
  (:class:`spacedg.qa.debias_gbm.BoostedChoice`), per question type and answer type.

Only discrete answers are probed (MCQ, YN, COUNT). **Chance** is what a benchmark user's uniform
guess gets: MCQ ``1 / options shown`` (not over the options that can be correct, which is the
audit's), YN ``1/2``, COUNT ``1 / answer bins`` of the question type (0, 1, 2+: :func:`~spacedg.qa.audit.count_chances`, as the audit's;
passed in, so that pruning never raises chance by removing a bin). A sub type's **best** is the best predictor's
held-out accuracy (chosen on those scores: an upper bound on these blind models), its
**excess** best − chance in points; ``ALL`` pools the sub types with each one's best predictor.
"""

from __future__ import annotations

import hashlib
from collections import defaultdict
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from spacedg.plugins.qa_record import QARecord
from spacedg.plugins.specs import AnswerType
from spacedg.qa.audit import DISCRETE, PREDICTORS, count_chances, held_out_scores
from spacedg.qa.audit_text import frequent_words
from spacedg.qa.debias_gbm import BoostedChoice

__all__ = [
    "DISCRETE", "PROBES", "SubTypeBlind", "Probe", "blind_rows", "probe", "repeat_seeds",
    "half_split_plans", "scene_folds", "shown_chance", "stable_hash",
]

#: Predictor names of the probe, in report order.
PROBES: tuple[str, ...] = (*PREDICTORS, "boosted")


def stable_hash(seed: int, *parts: Any) -> int:
    """A seeded 64-bit hash of ``parts`` (the same in every process and Python version)."""
    text = ":".join([str(seed), *map(str, parts)])
    return int.from_bytes(hashlib.sha256(text.encode("utf-8")).digest()[:8], "big")


def scene_folds(scene_ids: Sequence[str], folds: int, seed: int) -> list[list[str]]:
    """The scenes dealt into ``min(folds, scenes)`` groups: ordered by :func:`stable_hash`, dealt round-robin."""
    ordered = sorted(set(scene_ids), key=lambda s: (stable_hash(seed, "fold", s), s))
    k = max(1, min(folds, len(ordered)))
    return [ordered[i::k] for i in range(k)]


def shown_chance(record: QARecord, counts: Mapping[str, float]) -> float:
    """A uniform guess's accuracy on ``record``: 1 / options shown (MCQ), 1/2 (YN), ``counts`` (COUNT)."""
    if record.answer_type is AnswerType.MCQ:
        return 1.0 / max(1, sum(1 for o in record.options if str(o).strip()))
    if record.answer_type is AnswerType.YN:
        return 0.5
    return counts.get(record.question_type, 1.0)


@dataclass
class SubTypeBlind:
    """One sub type's blind figures, percent."""

    question_type: str
    sub_question_type: str
    answer_type: str
    n: int
    best: str
    best_score: float
    chance: float

    @property
    def key(self) -> tuple[str, str]:
        return self.question_type, self.sub_question_type

    @property
    def excess(self) -> float:
        return self.best_score - self.chance

    def to_dict(self) -> dict[str, Any]:
        return {"question_type": self.question_type, "sub_question_type": self.sub_question_type, "answer_type": self.answer_type,
                "n": self.n, "best": self.best, "best_score": self.best_score, "chance": self.chance, "excess": self.excess}


@dataclass
class Probe:
    """:func:`probe`'s result: per record each predictor's 0/1, the boosted model's probability of
    the truth, the rows per sub type and the pooled ``overall`` (n, best, chance, excess)."""

    correct: dict[str, dict[str, float]]
    truth_probability: dict[str, float]
    rows: list[SubTypeBlind]
    overall: dict[str, float] = field(default_factory=dict)

    def row(self, key: tuple[str, str]) -> SubTypeBlind | None:
        return next((r for r in self.rows if r.key == key), None)


def _boosted_scores(train: Sequence[QARecord], tests: Sequence[QARecord]) -> tuple[dict[str, float], dict[str, float]]:
    """``boosted``'s 0/1 and truth probability on ``tests``, fitted on ``train`` per (question type, answer type)."""
    correct: dict[str, float] = {}
    prob: dict[str, float] = {}
    groups: dict[tuple[str, AnswerType], list[QARecord]] = defaultdict(list)
    for r in train:
        groups[(r.question_type, r.answer_type)].append(r)
    test_groups: dict[tuple[str, AnswerType], list[QARecord]] = defaultdict(list)
    for r in tests:
        test_groups[(r.question_type, r.answer_type)].append(r)
    frequent = {q: frequent_words([r for r in train if r.question_type == q]) for q in {q for q, _ in test_groups}}
    for key, rs in test_groups.items():
        model = BoostedChoice(groups.get(key, []), frequent[key[0]])
        answers, truth = model.predict_many(rs)
        for r, a, p in zip(rs, answers, truth):
            correct[r.id] = float(a == str(r.answer))
            prob[r.id] = float(p)
    return correct, prob


def _held_out(records: Sequence[QARecord], folds: list[list[str]], learned: bool) -> tuple[dict[str, dict[str, float]], dict[str, float]]:
    """Per record the held-out 0/1 of every probe, and ``boosted``'s probability of the truth."""
    fold_of = {s: k for k, group in enumerate(folds) for s in group}
    by_fold: dict[str, list[QARecord]] = defaultdict(list)
    for r in records:
        by_fold[f"fold{fold_of[r.scene_id]}"].append(r)
    names = sorted(by_fold)
    prob: dict[str, float] = {}
    if len(names) < 2:
        return {}, prob
    correct = held_out_scores(by_fold, names, learned)
    for held in names:
        train = [r for name in names if name != held for r in by_fold[name]]
        hits, probs = _boosted_scores(train, by_fold[held])
        for rid, hit in hits.items():
            correct.setdefault(rid, {})["boosted"] = hit
        prob.update(probs)
    return correct, prob


def blind_rows(records: Sequence[QARecord], correct: Mapping[str, Mapping[str, float]], counts: Mapping[str, float],
               names: Sequence[str] = PROBES) -> tuple[list[SubTypeBlind], dict[str, float]]:
    """The rows per sub type and the pooled figures of ``records`` from their held-out 0/1
    ``correct``, the best chosen among the predictors ``names``."""
    groups: dict[tuple[str, str, str], list[QARecord]] = defaultdict(list)
    for r in records:
        if r.id in correct:
            groups[(r.question_type, r.sub_question_type, r.answer_type.value)].append(r)
    rows = []
    hits = chance_sum = 0.0
    for key in sorted(groups):
        rs = groups[key]
        usable = [p for p in names if all(p in correct[r.id] for r in rs)]
        scores = {p: 100.0 * float(np.mean([correct[r.id][p] for r in rs])) for p in usable}
        best = max(usable, key=lambda p: (scores[p], -PROBES.index(p))) if usable else ""
        chance = 100.0 * float(np.mean([shown_chance(r, counts) for r in rs]))
        rows.append(SubTypeBlind(*key, len(rs), best, scores.get(best, 0.0), chance))
        hits += scores.get(best, 0.0) * len(rs)
        chance_sum += chance * len(rs)
    n = sum(r.n for r in rows)
    overall = {"n": float(n), "best": hits / n if n else 0.0, "chance": chance_sum / n if n else 0.0}
    overall["excess"] = overall["best"] - overall["chance"]
    return rows, overall


def repeat_seeds(seed: int, repeats: int) -> list[int]:
    """The fold seeds of ``repeats`` probes: ``seed`` itself, then seeded derivations of it."""
    return [seed] + [stable_hash(seed, "repeat", i) % (2**31) for i in range(1, repeats)]


def half_split_plans(scene_ids: Sequence[str], seed: int, half_splits: int) -> list[tuple[int, int]]:
    """``(folds, fold seed)`` of :func:`probe`'s ``half_splits`` extra splits: half as many folds
    as ``scene_ids`` has scenes (at least 2), on fold seeds of their own derived from ``seed``."""
    half = max(2, len(set(scene_ids)) // 2)
    return [(half, s) for s in repeat_seeds(stable_hash(seed, "half") % (2**31), half_splits)]


def _split_key(groups: Sequence[Sequence[str]]) -> object:
    """What a split's held-out fits depend on: the groups in order (training records are taken
    fold by fold), or, with two groups, the unordered pair (each fold trains on the other alone)."""
    parts = tuple(frozenset(g) for g in groups)
    return frozenset(parts) if len(parts) == 2 else parts


def probe(records: Sequence[QARecord], *, folds: int = 5, seed: int = 0, learned: bool = True,
          counts: Mapping[str, float] | None = None, repeats: int = 1, reuse: Probe | None = None,
          changed: set[str] | None = None, half_splits: int = 0) -> Probe:
    """Probe the discrete ``records`` (pooled over their scenes) k-fold by scene (module docstring).

    ``counts``: COUNT chance per question type (default: :func:`~spacedg.qa.audit.count_chances` of ``records``).
    ``repeats``: probes with different fold seeds (:func:`repeat_seeds`); a record's 0/1 per
    predictor and the boosted probability become their **means** over the repeats, so a record
    that one fold split happens to solve weighs less than one every split solves.
    ``half_splits``: that many more probes, each on half as many folds of whole scenes (at least
    two) on fold seeds of their own, averaged in alike: predictors trained on other subsets of the
    scenes, so that what is pruned is what blind models learn whatever the split, not what one
    split's fits happen to hit (pruning by leave-one-scene-out alone was measured on 4 unseen
    rooms to leave `relpos_A_facing_B` at + 3.0 there and + 6.0 on average over ten 2-fold splits).
    ``reuse`` / ``changed``: every predictor is fitted per question type, so after records of
    the question types ``changed`` were removed, the others' held-out scores are ``reuse``'s
    (the same numbers a full probe gives: their training records are the same) and only the
    changed ones are fitted again (the folds are dealt over all the records' scenes as before).
    Fewer than two scenes: nothing is held out and the probe is empty.
    """
    discrete = [r for r in records if r.answer_type in DISCRETE]
    counts = count_chances(discrete) if counts is None else counts
    correct: dict[str, dict[str, float]] = defaultdict(dict)
    prob: dict[str, float] = defaultdict(float)
    fitted = discrete
    if reuse is not None and changed is not None:
        fitted = [r for r in discrete if r.question_type in changed]
        for r in discrete:
            if r.question_type not in changed and r.id in reuse.correct:
                correct[r.id] = dict(reuse.correct[r.id])
                prob[r.id] = reuse.truth_probability.get(r.id, 0.0)
    scene_ids = [r.scene_id for r in discrete]
    plans = [(folds, s) for s in repeat_seeds(seed, repeats)]
    if half_splits:
        plans += half_split_plans(scene_ids, seed, half_splits)
    fits: dict[object, tuple[dict[str, dict[str, float]], dict[str, float]]] = {}  # a split dealt twice is fitted once
    for plan_folds, fold_seed in plans:
        groups = scene_folds(scene_ids, plan_folds, fold_seed)
        key = _split_key(groups)
        if key not in fits:
            fits[key] = _held_out(fitted, groups, learned)
        hits, probs = fits[key]
        for rid, per in hits.items():
            for name, value in per.items():
                correct[rid][name] = correct[rid].get(name, 0.0) + value / len(plans)
        for rid, p in probs.items():
            prob[rid] += p / len(plans)
    rows, overall = blind_rows(discrete, correct, counts)
    return Probe(dict(correct), dict(prob), rows, overall)

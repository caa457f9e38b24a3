"""The blind stress test: what a model gets from the question text alone, per sub type.

A robustness bench whose items can be answered without the images measures priors, not
vision. :func:`blind_audit` trains **text-only** predictors on some scenes and scores them on a
held-out scene (leave-one-scene-out: every scene is held out once), so a predictor can only
use what generalises across scenes, the way a blind model trained on a bench's other scenes
would.

What a blind predictor sees (and nothing else): the question text, the option texts, and the
object labels the question names (read from the record's ``refs`` / ``label`` entries: the
question states them verbatim, so this is text, not geometry). It never sees the
``sub_question_type`` (not part of the prompt; a dual ``camera_rotation`` sub type names the
dominant axis first) nor the images. Predictors are trained per ``question_type`` (the
wording identifies it) and reported per ``(question_type, sub_question_type)``.

Predictors (all fitted on the training scenes only; the count-based ones are
:mod:`spacedg.qa.audit_priors`, the learned one :mod:`spacedg.qa.audit_model`, what they read
:mod:`spacedg.qa.audit_text`):

``letter``
    the most frequent correct letter (MCQ).
``majority``
    the most frequent correct answer text (MCQ option text, yes/no, count) per question
    *template* (:func:`template_signature`: the words common to the question type, so camera
    rotation questions are split by the axes they name and the mode); e.g. always "1" for counts.
``option_text``
    MCQ: each option's training rate of being correct given its text (object phrases read as
    their label), the highest wins: catches "forward" or "about the same" being favoured.
``label``
    per-label priors: existence → the majority answer per label; counting → the majority
    count per label; size comparison → the **mean measured value per label** (longest side,
    top height) and the object with the larger mean; other MCQ → the majority answer per
    (template, labels); metric answers → the geometric mean answer per label(s).
``learned``
    a small L2-regularised logistic model on bag-of-words features (question words, option
    words, numbers binned by magnitude, labels, the template and its crossings with option
    words and labels): a conditional logit over the four options (MCQ), a multinomial logit
    (yes/no, counts) or ridge regression on log values (metric answers). Plain numpy on sparse
    binary features, 200 Adam steps from zero (deterministic): seconds per 10k records
    (:mod:`spacedg.qa.audit_model`).

Scores: accuracy (MCQ, YN, COUNT) or mean relative accuracy (NA, SIZE_LIST: MRA over
θ ∈ {0.50, …, 0.95}, the bench's metric). ``chance`` is what uniform guessing gets: MCQ 1 / the
number of the record's options that can be correct (*live* options: an option whose text, or
role "an object the question names", is the truth of at least one record of the same
question type and wording (the question without the objects, labels and numbers it names)
across all audited scenes; index version 5 offers only such options, so live options are the
options shown, but older indexes offered "cannot be determined" in size comparisons and "Up"
in direction questions, which never are), YN 1/2, COUNT 1 / the number of
answer **bins** of the question type (``0``, ``1``, ``2+``: :func:`count_chances`, as the bench's
debiasing reads it). The counting family balances each label's counts over those bins, the
``2+`` bin spread over every larger count a scene shows, so a blind model's best answer ("always
1") is right a third of the time whatever counts the scenes reach; ``1 / distinct counts`` put such
an index 13 points over chance on held-out rooms whose views show three or four of a label.
``best`` is the best predictor per sub type (chosen on the
held-out scores themselves: an upper bound on what these blind models reach); the ``ALL`` row
pools MCQ, YN and COUNT records with each sub type's best predictor.

A record is **solved** when its sub type's best predictor answers it correctly while that
predictor beats chance on the sub type; :attr:`AuditReport.solved` lists those ids.

**Null band** (:func:`null_audit`, ``spacedg qa audit --null RUNS``): ``best`` is chosen on
the held-out scores, so it beats chance even when the text says nothing about the truth, by
more the fewer records a sub type has (at 20 records, typically 5–10 points). The null audit
runs the same audit on the same records with every discrete truth drawn again independently
of the text (uniformly among the live options, yes/no, the question type's count bins and then
the counts seen in the drawn bin), ``RUNS``
times, and reports per sub type the mean and 95th percentile of that excess: an excess inside
the band is what chance alone gives at that ``n``; one above its 95th percentile is a bias the
text carries. (The draws are independent, not balanced per cell as the index's rounds are, so
the band is if anything wide.)
"""

from __future__ import annotations

from collections import Counter, defaultdict
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from spacedg.plugins.answers import MCQ_LETTERS
from spacedg.plugins.qa_record import QARecord
from spacedg.plugins.questions.object_counting import count_bin
from spacedg.plugins.specs import AnswerType
from spacedg.qa.audit_model import fit_learned
from spacedg.qa.audit_priors import Priors
from spacedg.qa.audit_text import NUMBER, frequent_words, option_role, record_labels, template_signature, template_words, truth_text
from spacedg.qa.stats import option_text

__all__ = [
    "PREDICTORS",
    "AuditRow",
    "AuditReport",
    "blind_audit",
    "held_out_scores",
    "null_audit",
    "with_null",
    "mra",
    "record_labels",
    "template_signature",
    "format_audit",
    "DISCRETE",
    "answer_class",
    "count_chances",
]

#: Predictor names, in report order.
PREDICTORS: tuple[str, ...] = ("letter", "majority", "option_text", "label", "learned")
#: The answer types scored against chance (and pruned by the bench's debiasing).
DISCRETE = (AnswerType.MCQ, AnswerType.YN, AnswerType.COUNT)


def mra(prediction: float, truth: float) -> float:
    """Mean relative accuracy over θ ∈ {0.50, 0.55, …, 0.95} (the bench's metric)."""
    if truth == 0:
        return float(prediction == 0)
    err = abs(float(prediction) - float(truth)) / abs(float(truth))
    return float(np.mean([err <= 1.0 - t for t in np.arange(0.5, 0.951, 0.05)]))


def _score(record: QARecord, prediction: Any) -> float:
    if prediction is None:
        return 0.0
    if record.answer_type is AnswerType.NA:
        return mra(float(prediction), float(record.answer))
    if record.answer_type is AnswerType.SIZE_LIST:
        return float(np.mean([mra(p, t) for p, t in zip(prediction, record.answer)]))
    return float(str(prediction) == str(record.answer))


# ------------------------------------------------------------------ the audit
@dataclass
class AuditRow:
    """One sub type's blind figures (accuracy or MRA in percent)."""

    question_type: str
    sub_question_type: str
    answer_type: str
    n: int
    chance: float | None
    scores: dict[str, float]
    best: str
    best_score: float
    solved: int
    null_mean: float | None = None
    null_p95: float | None = None

    @property
    def excess(self) -> float | None:
        """Best blind score minus chance, points (``None`` for metric answers)."""
        return None if self.chance is None else self.best_score - self.chance

    def to_dict(self) -> dict[str, Any]:
        return {
            "question_type": self.question_type, "sub_question_type": self.sub_question_type, "answer_type": self.answer_type,
            "n": self.n, "chance": self.chance, **self.scores, "best": self.best, "best_score": self.best_score,
            "excess": self.excess, "solved": self.solved,
            **({"null_mean": self.null_mean, "null_p95": self.null_p95} if self.null_p95 is not None else {}),
        }


@dataclass
class AuditReport:
    """:func:`blind_audit`'s result."""

    rows: list[AuditRow]
    overall: dict[str, Any]
    solved: list[str] = field(default_factory=list)
    per_record: dict[str, dict[str, float]] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {"rows": [r.to_dict() for r in self.rows], "overall": self.overall, "solved": list(self.solved)}


def _wording(record: QARecord) -> tuple[str, str]:
    """The question type and its wording without the objects, labels and numbers it names."""
    return record.question_type, " ".join(sorted(w for w in template_words(record) if not NUMBER.match(w)))


def _role_kind(role: str) -> str:
    """An option role with every named object as one kind (``"object"``)."""
    return "object" if role.startswith("object:") else role


def _live_roles(records: Sequence[QARecord]) -> dict[tuple[str, str], set[str]]:
    live: dict[tuple[str, str], set[str]] = defaultdict(set)
    for r in records:
        if r.answer_type is AnswerType.MCQ:
            live[_wording(r)].add(_role_kind(option_role(r, truth_text(r))))
    return live


def _live_letters(record: QARecord, live: Mapping[tuple[str, str], set[str]]) -> list[str]:
    """The letters of the MCQ ``record`` whose options can be correct (:func:`_live_roles`)."""
    allowed = live[_wording(record)]
    return [k for k in MCQ_LETTERS[:len(record.options)] if _role_kind(option_role(record, option_text(record, k))) in allowed]


def answer_class(record: QARecord) -> str:
    """What answer balance is kept over: the correct letter (MCQ), ``yes``/``no``, a count's **bin**
    (``"0"``, ``"1"``, ``"2+"``: :func:`~spacedg.plugins.questions.object_counting.count_bin`)."""
    if record.answer_type is AnswerType.COUNT:
        return count_bin(int(record.answer))
    return str(record.answer)


def count_chances(records: Sequence[QARecord]) -> dict[str, float]:
    """Per question type with COUNT answers, ``1 / answer bins`` among ``records``: the selection
    balances a label's counts over the bins 0, 1, 2+ (the last spread over its counts), so the
    best answer a blind model can give is right a third of the time whatever counts the scenes
    reach; ``1 / distinct counts`` would put a bin-balanced design at +8 points (four counts)
    and grow with every larger count the scenes offer."""
    seen: dict[str, set[str]] = defaultdict(set)
    for r in records:
        if r.answer_type is AnswerType.COUNT:
            seen[r.question_type].add(answer_class(r))
    return {q: 1.0 / len(v) for q, v in seen.items()}


def _chance(record: QARecord, live: Mapping[tuple[str, str], set[str]], counts: Mapping[str, float]) -> float | None:
    if record.answer_type is AnswerType.MCQ:
        return 1.0 / max(1, len(_live_letters(record, live)))
    if record.answer_type is AnswerType.YN:
        return 0.5
    if record.answer_type is AnswerType.COUNT:
        return counts.get(record.question_type, 1.0)
    return None



# ------------------------------------------------------------------ held-out scores
def _record_scores(record: QARecord, priors: Priors, models: Mapping[AnswerType, Any]) -> dict[str, float]:
    """Each predictor's score on ``record`` (1/0, or MRA); a predictor with no answer for its
    kind is left out (``majority`` and ``label`` score 0 instead)."""
    scores: dict[str, float] = {}
    for name in PREDICTORS:
        if name == "learned":
            model = models.get(record.answer_type)
            if model is None:
                continue
            scores[name] = _score(record, model.predict(record))
        else:
            pred = priors.predict(name, record)
            if pred is None and not (name in ("majority", "label")):
                continue
            scores[name] = _score(record, pred)
    return scores


def _score_question_type(train: Sequence[QARecord], tests: Sequence[QARecord], learned: bool) -> dict[str, dict[str, float]]:
    """Record id → predictor scores for the held-out ``tests`` of one question type, the
    predictors fitted on ``train`` (the same question type in the other scenes)."""
    frequent = frequent_words(train)
    priors = Priors(train, frequent)
    models: dict[AnswerType, Any] = {}
    for kind in {r.answer_type for r in tests}:
        kind_train = [r for r in train if r.answer_type is kind]
        if learned and kind_train:
            models[kind] = fit_learned(kind, kind_train, frequent)
    return {r.id: _record_scores(r, priors, models) for r in tests}


def held_out_scores(
    records_by_scene: Mapping[str, Sequence[QARecord]], scenes: Sequence[str], learned: bool,
) -> dict[str, dict[str, float]]:
    """Record id → predictor scores, every scene held out once (leave-one-scene-out). Keys may be
    groups of scenes (folds): then each fold is held out once, trained on the others (k-fold by
    scene, as :mod:`spacedg.qa.debias` probes a pooled bench)."""
    per_record: dict[str, dict[str, float]] = {}
    for held in scenes:
        train_by_type: dict[str, list[QARecord]] = defaultdict(list)
        for s in scenes:
            if s != held:
                for r in records_by_scene[s]:
                    train_by_type[r.question_type].append(r)
        test_by_type: dict[str, list[QARecord]] = defaultdict(list)
        for r in records_by_scene[held]:
            test_by_type[r.question_type].append(r)
        for qtype, tests in test_by_type.items():
            per_record.update(_score_question_type(train_by_type.get(qtype, []), tests, learned))
    return per_record


# ------------------------------------------------------------------ the report
def _row(
    key: tuple[str, str, str], rs: Sequence[QARecord], per_record: Mapping[str, Mapping[str, float]],
    live: Mapping[tuple[str, str], set[str]], counts: Mapping[str, float],
) -> tuple[AuditRow, list[str], list[float | None]]:
    """One sub type's row, the ids its best predictor solves, and each record's chance."""
    kind = rs[0].answer_type
    names = [p for p in PREDICTORS if all(p in per_record[r.id] for r in rs)]
    scores = {p: 100.0 * float(np.mean([per_record[r.id][p] for r in rs])) for p in names}
    chances = [_chance(r, live, counts) for r in rs]
    chance = None if chances[0] is None else 100.0 * float(np.mean(chances))
    best = max(names, key=lambda p: (scores[p], -PREDICTORS.index(p))) if names else ""
    best_score = scores.get(best, 0.0)
    solved: list[str] = []
    if best and kind in DISCRETE and chance is not None and best_score > chance:
        solved = [r.id for r in rs if per_record[r.id][best] >= 1.0]
    return AuditRow(key[0], key[1], key[2], len(rs), chance, scores, best, best_score, len(solved)), solved, chances


def _report(
    every: Sequence[QARecord], per_record: dict[str, dict[str, float]], live: Mapping[tuple[str, str], set[str]],
    counts: Mapping[str, float], n_scenes: int,
) -> AuditReport:
    """The rows per sub type (sorted) and the ``ALL`` figures pooled over discrete sub types."""
    groups: dict[tuple[str, str, str], list[QARecord]] = defaultdict(list)
    for r in every:
        if r.id in per_record:
            groups[(r.question_type, r.sub_question_type, r.answer_type.value)].append(r)
    rows: list[AuditRow] = []
    solved: list[str] = []
    pooled_n = 0
    pooled_hits = 0.0
    pooled_chance = 0.0
    for key in sorted(groups):
        rs = groups[key]
        row, ids, chances = _row(key, rs, per_record, live, counts)
        rows.append(row)
        solved.extend(ids)
        if rs[0].answer_type in DISCRETE and row.best:
            pooled_n += len(rs)
            pooled_hits += sum(per_record[r.id][row.best] for r in rs)
            pooled_chance += sum(chances)  # type: ignore[arg-type]
    overall = {
        "n": pooled_n,
        "chance": 100.0 * pooled_chance / pooled_n if pooled_n else None,
        "best_per_sub_type": 100.0 * pooled_hits / pooled_n if pooled_n else None,
        "scenes": n_scenes,
    }
    if overall["chance"] is not None:
        overall["excess"] = overall["best_per_sub_type"] - overall["chance"]
    return AuditReport(rows, overall, solved, per_record)


def blind_audit(records_by_scene: Mapping[str, Sequence[QARecord]], *, learned: bool = True) -> AuditReport:
    """Leave-one-scene-out blind predictors over ``records_by_scene`` (see the module docstring).

    Needs at least two scenes (with one, nothing is held out and the report is empty).
    ``learned=False`` skips the logistic models (the count-based priors only).
    """
    scenes = [s for s in records_by_scene if records_by_scene[s]]
    every = [r for s in scenes for r in records_by_scene[s]]
    per_record = held_out_scores(records_by_scene, scenes, learned) if len(scenes) >= 2 else {}
    return _report(every, per_record, _live_roles(every), count_chances(every), len(scenes))


def _null_records(records_by_scene: Mapping[str, Sequence[QARecord]], rng: np.random.Generator) -> dict[str, list[QARecord]]:
    """The records with every discrete truth drawn again, independently of the text: an MCQ's
    uniformly among its live options (:func:`_chance`'s), a yes/no among the answers of its
    question type in these records, a count uniformly among its question type's answer bins
    (:func:`answer_class`) and then among the counts of that bin in these records (so a blind
    guess gets :func:`count_chances`' chance at best, as from the index's balanced rounds)."""
    every = [r for rs in records_by_scene.values() for r in rs]
    live = _live_roles(every)
    answers: dict[tuple[str, AnswerType], dict[str, set[str]]] = defaultdict(lambda: defaultdict(set))
    for r in every:
        if r.answer_type in (AnswerType.YN, AnswerType.COUNT):  # a yes/no answer is its own class
            answers[(r.question_type, r.answer_type)][answer_class(r)].add(str(r.answer))
    pools = {k: [sorted(classes[c]) for c in sorted(classes)] for k, classes in answers.items()}
    out: dict[str, list[QARecord]] = {}
    for scene, rs in records_by_scene.items():
        drawn = []
        for r in rs:
            if r.answer_type is AnswerType.MCQ:
                letters = _live_letters(r, live)
                r = replace(r, answer=letters[int(rng.integers(len(letters)))]) if letters else r
            elif r.answer_type in (AnswerType.YN, AnswerType.COUNT):
                classes = pools[(r.question_type, r.answer_type)]
                pool = classes[int(rng.integers(len(classes)))]
                # a class of one value (yes, no, a count bin of one count) takes no second draw
                value = pool[int(rng.integers(len(pool)))] if len(pool) > 1 else pool[0]
                r = replace(r, answer=int(value) if r.answer_type is AnswerType.COUNT else value)
            drawn.append(r)
        out[scene] = drawn
    return out


def null_audit(
    records_by_scene: Mapping[str, Sequence[QARecord]], runs: int = 20, seed: int = 0, *, learned: bool = True,
) -> dict[tuple[str, str], tuple[float, float]]:
    """What the blind stress test reports when nothing can be learnt: :func:`blind_audit` on
    the same records (questions, options, labels, sub types and scenes) with their truths drawn
    independently of the text (:func:`_null_records`), ``runs`` times; per discrete
    ``(question_type, sub_question_type)`` the mean and the 95th percentile of the best
    predictor's excess over chance, in points. The best of five predictors chosen on the
    held-out scores is biased upwards, the more so the fewer the records: an excess inside this
    band is what chance alone gives at that ``n``, an excess above its 95th percentile is a
    bias the text carries. Seeded by ``seed``."""
    if runs < 1:
        raise ValueError(f"null_audit: runs must be at least 1, got {runs}")
    # chance as the real audit states it (the draws are uniform over exactly those options; a
    # run's own chance would count an option no draw happened to pick as never correct)
    every = [r for rs in records_by_scene.values() for r in rs]
    live = _live_roles(every)
    counts = count_chances(every)
    chances: dict[tuple[str, str], list[float]] = defaultdict(list)
    for r in every:
        c = _chance(r, live, counts)
        if c is not None:
            chances[(r.question_type, r.sub_question_type)].append(100.0 * c)
    rng = np.random.default_rng(seed)
    excess: dict[tuple[str, str], list[float]] = defaultdict(list)
    for _ in range(runs):
        for row in blind_audit(_null_records(records_by_scene, rng), learned=learned).rows:
            key = (row.question_type, row.sub_question_type)
            if row.excess is not None and key in chances:
                excess[key].append(row.best_score - float(np.mean(chances[key])))
    return {k: (float(np.mean(v)), float(np.percentile(v, 95))) for k, v in excess.items()}


def with_null(report: AuditReport, null: Mapping[tuple[str, str], tuple[float, float]]) -> AuditReport:
    """``report`` with each row's ``null_mean`` / ``null_p95`` from :func:`null_audit`."""
    rows = [replace(r, null_mean=null[(r.question_type, r.sub_question_type)][0], null_p95=null[(r.question_type, r.sub_question_type)][1])
            if (r.question_type, r.sub_question_type) in null else r for r in report.rows]
    return replace(report, rows=rows)


def format_audit(report: AuditReport) -> str:
    """The report as a Markdown table (one row per sub type, then ``ALL``)."""
    nulls = any(r.null_p95 is not None for r in report.rows)
    cols = ["question_type", "sub_question_type", "type", "n", "chance", *PREDICTORS, "best", "excess", "solved"]
    cols += ["null excess (mean / p95)"] if nulls else []
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]

    def cell(v: Any) -> str:
        if v is None:
            return ""
        return f"{v:.1f}" if isinstance(v, float) else str(v)

    for row in report.rows:
        values = [row.question_type, row.sub_question_type, row.answer_type, row.n, row.chance,
                  *(row.scores.get(p) for p in PREDICTORS), f"{row.best} {row.best_score:.1f}", row.excess, row.solved]
        if nulls:
            values.append(f"{row.null_mean:.1f} / {row.null_p95:.1f}" if row.null_p95 is not None and row.null_mean is not None else None)
        lines.append("| " + " | ".join(cell(v) for v in values) + " |")
    o = report.overall
    if o.get("n"):
        values = ["ALL (MCQ+YN+COUNT)", "", "", o["n"], o["chance"], *([None] * len(PREDICTORS)),
                  f"best/sub type {o['best_per_sub_type']:.1f}", o.get("excess"), len(report.solved), *([None] if nulls else [])]
        lines.append("| " + " | ".join(cell(v) for v in values) + " |")
    return "\n".join(lines)

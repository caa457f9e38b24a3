"""The blind stress test: what a model gets from the question text alone, per sub type.

A robustness bench whose items can be answered without the images measures priors, not
vision. :func:`blind_audit` trains **text-only** predictors on some scenes and scores them on a
held-out scene (leave-one-scene-out: every scene is held out once), so a predictor can only
use what generalises across scenes, the way a blind model trained on a bench's other scenes
would.

What a blind predictor sees (and nothing else): the question text, the option texts, and the
object labels the question names (read from the record's ``refs`` / ``label`` entries: the
question states them verbatim, so this is text, not geometry). It never sees the
``sub_question_type`` (not part of the prompt; for ``camera_rotation`` it names the dominant
axis, i.e. the answer) nor the images. Predictors are trained per ``question_type`` (the
wording identifies it) and reported per ``(question_type, sub_question_type)``.

Predictors (all fitted on the training scenes only):

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
    binary features, 200 Adam steps from zero (deterministic): seconds per 10k records.

Scores: accuracy (MCQ, YN, COUNT) or mean relative accuracy (NA, SIZE_LIST: MRA over
θ ∈ {0.50, …, 0.95}, the bench's metric). ``chance`` is what uniform guessing gets: MCQ 1 / the
number of the record's options that can be correct (*live* options: an option whose text, or
role "an object the question names", is the truth of at least one record of the same
question type and wording (the question without the objects, labels and numbers it names)
across all audited scenes: the size-comparison option "cannot be determined" is never correct,
so those questions have three live options; "Up" is never where an object lies from a camera
at eye height, so a direction question offering it has three), YN 1/2, COUNT 1 / the number of
distinct counts of the question type. ``best`` is the best predictor per sub type (chosen on the
held-out scores themselves: an upper bound on what these blind models reach); the ``ALL`` row
pools MCQ, YN and COUNT records with each sub type's best predictor.

A record is **solved** when its sub type's best predictor answers it correctly while that
predictor beats chance on the sub type; :attr:`AuditReport.solved` lists those ids.

**Null band** (:func:`null_audit`, ``spacedg qa audit --null RUNS``): ``best`` is chosen on
the held-out scores, so it beats chance even when the text says nothing about the truth, by
more the fewer records a sub type has (at 20 records, typically 5–10 points). The null audit
runs the same audit on the same records with every discrete truth drawn again independently
of the text (uniformly among the live options, yes/no, the question type's counts), ``RUNS``
times, and reports per sub type the mean and 95th percentile of that excess: an excess inside
the band is what chance alone gives at that ``n``; one above its 95th percentile is a bias the
text carries. (The draws are independent, not balanced per cell as the index's rounds are, so
the band is if anything wide.)
"""

from __future__ import annotations

import math
import re
from collections import Counter, defaultdict
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from spacedg.data.qa_stats import option_text
from spacedg.plugins.answers import MCQ_LETTERS
from spacedg.plugins.qa_record import QARecord
from spacedg.plugins.questions.language import object_phrase, plural
from spacedg.plugins.specs import AnswerType
from spacedg.scene.lexicon import label_key

__all__ = [
    "PREDICTORS",
    "AuditRow",
    "AuditReport",
    "blind_audit",
    "null_audit",
    "with_null",
    "mra",
    "record_labels",
    "template_signature",
    "format_audit",
]

#: Predictor names, in report order.
PREDICTORS: tuple[str, ...] = ("letter", "majority", "option_text", "label", "learned")
_DISCRETE = (AnswerType.MCQ, AnswerType.YN, AnswerType.COUNT)
_WORD = re.compile(r"[a-z]+|\d+(?:\.\d+)?")
_NUMBER = re.compile(r"^\d+(?:\.\d+)?$")
#: A word is a template word of a question type when at least this share of its questions use it.
TEMPLATE_DF = 0.2


# ------------------------------------------------------------------ text helpers
def _words(text: str) -> list[str]:
    return _WORD.findall(str(text).lower())


def _number_bin(token: str) -> str:
    value = float(token)
    return "n:0" if value <= 0 else f"n:{round(2 * math.log2(value))}"


def _tokens(text: str) -> list[str]:
    """Words of ``text``; numbers become magnitude bins (half-octaves)."""
    return [_number_bin(w) if _NUMBER.match(w) else w for w in _words(text)]


def truth_text(record: QARecord) -> str:
    """The correct answer as text: the correct option's text (MCQ) or ``str(answer)``."""
    if record.answer_type is AnswerType.MCQ:
        return option_text(record, str(record.answer))
    return str(record.answer)


def record_labels(record: QARecord) -> tuple[str, ...]:
    """The labels the question names, in question order: the ``refs`` of its geometry block, else
    its ``label`` (existence, counting) or ``object`` (size); lower case. The question text
    states them, so a text-only model knows them too."""
    g = record.geometry
    refs = g.get("refs") or []
    if refs:
        return tuple(label_key(r.get("label", "")) for r in refs)
    found = []
    for value in (g.get("label"), (g.get("object") or {}).get("label") if isinstance(g.get("object"), Mapping) else None):
        if isinstance(value, str):
            label = label_key(value)
            if label and label in record.question.lower():  # only a label the question states
                found.append(label)
    return tuple(found[:1])


def _named_objects(record: QARecord) -> dict[str, str]:
    """Phrase (lower case) → label of every object the question names."""
    out: dict[str, str] = {}
    for ref in record.geometry.get("refs") or []:
        phrase = object_phrase(str(ref.get("label", "")), str(ref.get("description", ""))).lower()
        out.setdefault(" ".join(phrase.split()), str(ref.get("label", "")).lower())
    return out


def option_role(record: QARecord, text: str) -> str:
    """How an option reads to a blind model: ``"object:<label>"`` when it names an object of the
    question, else its text (lower case)."""
    key = " ".join(text.lower().split())
    label = _named_objects(record).get(key)
    return f"object:{label}" if label is not None else key


def _template_words(record: QARecord) -> set[str]:
    """The question's words without the objects and labels it names (and their plurals)."""
    text = " ".join(record.question.lower().split())
    for phrase in sorted(_named_objects(record), key=len, reverse=True):
        text = text.replace(phrase, " ")
    named: set[str] = set()
    for label in record_labels(record):
        named.update(_words(label))
        named.update(_words(plural(label)))
    return {w for w in _words(text) if w not in named}


def template_signature(record: QARecord, frequent: frozenset[str]) -> str:
    """The question's template words: its words (objects and labels it names left out) that
    are in ``frequent`` (used by at least :data:`TEMPLATE_DF` of the question type's training
    questions), sorted."""
    return " ".join(sorted(w for w in _template_words(record) if w in frequent))


def _frequent_words(records: Sequence[QARecord]) -> frozenset[str]:
    df: Counter[str] = Counter()
    for r in records:
        df.update(_template_words(r))
    n = max(1, len(records))
    return frozenset(w for w, c in df.items() if c / n >= TEMPLATE_DF and not _NUMBER.match(w))


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


# ------------------------------------------------------------------ learned models
def _record_features(record: QARecord, frequent: frozenset[str]) -> list[str]:
    sig = template_signature(record, frequent)
    labels = record_labels(record)
    feats = ["bias", f"s:{sig}"]
    feats += [f"q:{t}" for t in set(_tokens(record.question))]
    feats += [f"l:{lab}" for lab in labels]
    feats += [f"s:{sig}|l{k}:{lab}" for k, lab in enumerate(labels)]
    if len(labels) > 1:
        feats.append(f"s:{sig}|ls:{'|'.join(labels)}")
    return feats


def _option_features(record: QARecord, text: str, sig: str) -> list[str]:
    """Features of one option of ``record``, whose template signature is ``sig``."""
    role = option_role(record, text)
    feats = [f"o:{role}", f"s:{sig}|o:{role}"]
    feats += [f"ow:{t}" for t in set(_tokens(text))]
    feats += [f"s:{sig}|ow:{t}" for t in set(_tokens(text))]
    key = " ".join(text.lower().split())
    question = " ".join(record.question.lower().split())
    pos = question.find(key) if key else -1
    if pos >= 0:
        order = sorted(question.find(k) for k in _named_objects(record) if question.find(k) >= 0)
        rank = order.index(pos) if pos in order else 0
        feats += ["r:named", f"s:{sig}|r:mention{rank}"]
    for lab in record_labels(record):
        feats.append(f"l:{lab}|o:{role}")
    return feats


class _Vocab:
    """Feature name → column, for features seen at least ``min_count`` times (at most ``cap``)."""

    def __init__(self, docs: Sequence[Sequence[str]], min_count: int = 2, cap: int = 4000) -> None:
        counts: Counter[str] = Counter(f for doc in docs for f in set(doc))
        kept = [f for f, c in counts.most_common() if c >= min_count][:cap]
        self.index = {f: i for i, f in enumerate(sorted(kept))}

    def matrix(self, docs: Sequence[Sequence[str]]) -> _Sparse:
        return _Sparse([[self.index[f] for f in set(doc) if f in self.index] for doc in docs], len(self.index))


class _Sparse:
    """A binary sparse matrix (rows of active columns): ``X @ w`` and ``X.T @ c`` in O(non-zeros)."""

    def __init__(self, rows: Sequence[Sequence[int]], width: int) -> None:
        self.n, self.width = len(rows), width
        self.cols = np.fromiter((c for r in rows for c in r), dtype=np.int64)
        self.rows = np.repeat(np.arange(len(rows)), [len(r) for r in rows])

    def dot(self, w: np.ndarray) -> np.ndarray:
        """``X @ w`` for ``w`` of shape (F,) or (F, C)."""
        if w.ndim == 1:
            return np.bincount(self.rows, weights=w[self.cols], minlength=self.n)
        return np.stack([np.bincount(self.rows, weights=w[self.cols, c], minlength=self.n) for c in range(w.shape[1])], axis=1)

    def tdot(self, c: np.ndarray) -> np.ndarray:
        """``X.T @ c`` for ``c`` of shape (n,) or (n, C)."""
        if c.ndim == 1:
            return np.bincount(self.cols, weights=c[self.rows], minlength=self.width)
        return np.stack([np.bincount(self.cols, weights=c[self.rows, k], minlength=self.width) for k in range(c.shape[1])], axis=1)


def _adam(grad_fn: Any, w: np.ndarray, steps: int = 200, lr: float = 0.1) -> np.ndarray:
    m = np.zeros_like(w)
    v = np.zeros_like(w)
    for t in range(1, steps + 1):
        g = grad_fn(w)
        m = 0.9 * m + 0.1 * g
        v = 0.999 * v + 0.001 * g * g
        w = w - lr * (m / (1 - 0.9**t)) / (np.sqrt(v / (1 - 0.999**t)) + 1e-8)
    return w


def _softmax(z: np.ndarray) -> np.ndarray:
    z = z - z.max(axis=1, keepdims=True)
    e = np.exp(z)
    return e / e.sum(axis=1, keepdims=True)


class _ConditionalLogit:
    """Scores each option ``w · f(option)``; softmax over the four options; L2 ``l2``."""

    def __init__(self, train: Sequence[QARecord], frequent: frozenset[str], l2: float = 1e-2) -> None:
        self.frequent = frequent
        docs = [doc for r in train for doc in self._docs(r)]  # 4 rows per record
        self.vocab = _Vocab(docs)
        x = self.vocab.matrix(docs)
        y = np.array([MCQ_LETTERS.index(str(r.answer)) for r in train])
        n = max(1, len(train))

        def grad(w: np.ndarray) -> np.ndarray:
            p = _softmax(x.dot(w).reshape(-1, 4))
            p[np.arange(len(y)), y] -= 1.0
            return x.tdot(p.ravel()) / n + l2 * w

        self.w = _adam(grad, np.zeros(len(self.vocab.index))) if len(train) else np.zeros(0)

    def _docs(self, record: QARecord) -> list[list[str]]:
        sig = template_signature(record, self.frequent)
        return [_option_features(record, option_text(record, k), sig) for k in MCQ_LETTERS]

    def predict(self, record: QARecord) -> str:
        scores = self.vocab.matrix(self._docs(record)).dot(self.w)
        return MCQ_LETTERS[int(np.argmax(scores))]


class _MultinomialLogit:
    """Multinomial logistic regression over the training answers (yes/no, counts)."""

    def __init__(self, train: Sequence[QARecord], frequent: frozenset[str], l2: float = 1e-2) -> None:
        self.frequent = frequent
        self.classes = sorted({str(r.answer) for r in train})
        docs = [_record_features(r, frequent) for r in train]
        self.vocab = _Vocab(docs)
        x = self.vocab.matrix(docs)
        y = np.array([self.classes.index(str(r.answer)) for r in train])
        n = max(1, len(train))
        shape = (len(self.vocab.index), max(1, len(self.classes)))

        def grad(w: np.ndarray) -> np.ndarray:
            p = _softmax(x.dot(w))
            p[np.arange(len(y)), y] -= 1.0
            return x.tdot(p) / n + l2 * w

        self.w = _adam(grad, np.zeros(shape)) if len(train) else None

    def predict(self, record: QARecord) -> str | None:
        if self.w is None:
            return None
        scores = self.vocab.matrix([_record_features(record, self.frequent)]).dot(self.w)
        return self.classes[int(np.argmax(scores[0]))]


class _Ridge:
    """Ridge regression of log answers (one output per answer element), by gradient steps."""

    def __init__(self, train: Sequence[QARecord], frequent: frozenset[str], l2: float = 1e-3) -> None:
        self.frequent = frequent
        docs = [_record_features(r, frequent) for r in train]
        self.vocab = _Vocab(docs)
        x = self.vocab.matrix(docs)
        y = np.log(np.maximum(np.array([np.atleast_1d(np.asarray(r.answer, dtype=np.float64)) for r in train]), 1e-3))
        self.mean = y.mean(axis=0) if len(train) else np.zeros(1)
        n = max(1, len(train))
        centred = y - self.mean

        def grad(w: np.ndarray) -> np.ndarray:
            return x.tdot(x.dot(w) - centred) / n + l2 * w

        self.w = _adam(grad, np.zeros((len(self.vocab.index), y.shape[1] if y.ndim == 2 else 1)), lr=0.05)

    def predict(self, record: QARecord) -> Any:
        x = self.vocab.matrix([_record_features(record, self.frequent)])
        pred = np.exp(x.dot(self.w)[0] + self.mean)
        return float(pred[0]) if pred.size == 1 else tuple(float(v) for v in np.sort(pred))


# ------------------------------------------------------------------ count-based predictors
def _majority(counter: Counter[str] | None) -> str | None:
    if not counter:
        return None
    return sorted(counter.items(), key=lambda kv: (-kv[1], kv[0]))[0][0]


def _best_option(record: QARecord, *counters: Counter[str] | None) -> str:
    """The option whose role was correct most often in the first counter that knows any of the
    record's options (later counters break ties and fill in); ties → the earlier letter."""
    roles = [option_role(record, option_text(record, k)) for k in MCQ_LETTERS]
    keys = []
    for k, role in enumerate(roles):
        keys.append((tuple((c or {}).get(role, 0) for c in counters), -k))
    return MCQ_LETTERS[max(range(4), key=lambda k: keys[k])]


def _size_values(record: QARecord) -> list[tuple[str, float]]:
    g = record.geometry
    objs, values = g.get("objects") or [], g.get("values") or []
    return [(str(o.get("label", "")).lower(), float(v)) for o, v in zip(objs, values)]


class _Priors:
    """The count-based predictors of one question type, fitted on training records."""

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
                self.letters[str(r.answer)] += 1
                truth = option_role(r, truth_text(r))
                for k in MCQ_LETTERS:
                    self.text_seen[option_role(r, option_text(r, k))] += 1
                self.text_hits[truth] += 1
                self.by_sig[sig][truth] += 1
                self.overall[truth] += 1
                self.by_labels[(sig, *record_labels(r))][truth] += 1
                for label, value in _size_values(r):
                    acc = self.size_sum[(sig, label)]
                    acc[0] += value
                    acc[1] += 1
            elif r.answer_type in (AnswerType.YN, AnswerType.COUNT):
                self.by_sig[sig][str(r.answer)] += 1
                self.overall[str(r.answer)] += 1
                self.by_labels[(sig, *record_labels(r))][str(r.answer)] += 1
                self.by_labels[record_labels(r)][str(r.answer)] += 1
            else:
                value = np.log(np.maximum(np.atleast_1d(np.asarray(r.answer, dtype=np.float64)), 1e-3))
                self.metric[record_labels(r)].append(value)
                self.metric_all.append(value)

    def predict(self, name: str, record: QARecord) -> Any:
        sig = template_signature(record, self.frequent)
        kind = record.answer_type
        if kind in (AnswerType.NA, AnswerType.SIZE_LIST):
            if name == "majority":
                values = self.metric_all
            elif name == "label":
                values = self.metric.get(record_labels(record)) or self.metric_all
            else:
                return None
            if not values:
                return None
            mean = np.exp(np.mean(values, axis=0))
            return float(mean[0]) if kind is AnswerType.NA else tuple(float(v) for v in np.sort(mean))
        if name == "letter":
            return _majority(self.letters) if kind is AnswerType.MCQ else None
        if name == "majority":
            if kind is AnswerType.MCQ:
                return _best_option(record, self.by_sig.get(sig), self.overall)
            return _majority(self.by_sig.get(sig)) or _majority(self.overall)
        if name == "option_text":
            if kind is not AnswerType.MCQ:
                return None
            rates = []
            for k in MCQ_LETTERS:
                role = option_role(record, option_text(record, k))
                rates.append(((self.text_hits[role] + 0.5) / (self.text_seen[role] + 2.0), -MCQ_LETTERS.index(k), k))
            return max(rates)[2]
        if name == "label":
            if kind is AnswerType.MCQ:
                sizes = _size_values(record)
                if len(sizes) == 2 and all(self.size_sum.get((sig, lab), (0, 0))[1] for lab, _ in sizes):
                    means = [self.size_sum[(sig, lab)][0] / self.size_sum[(sig, lab)][1] for lab, _ in sizes]
                    which = 0 if means[0] >= means[1] else 1
                    phrase = (record.geometry.get("objects") or [])[which]
                    wanted = object_phrase(str(phrase.get("label", "")), str(phrase.get("description", "")))
                    for k in MCQ_LETTERS:
                        if " ".join(option_text(record, k).lower().split()) == " ".join(wanted.lower().split()):
                            return k
                return _best_option(record, self.by_labels.get((sig, *record_labels(record))), self.by_sig.get(sig), self.overall)
            guess = _majority(self.by_labels.get((sig, *record_labels(record)))) or _majority(self.by_labels.get(record_labels(record)))
            return guess or _majority(self.by_sig.get(sig)) or _majority(self.overall)
        return None


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
    return record.question_type, " ".join(sorted(w for w in _template_words(record) if not _NUMBER.match(w)))


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
    return [k for k in MCQ_LETTERS if _role_kind(option_role(record, option_text(record, k))) in allowed]


def _distinct_counts(records: Sequence[QARecord]) -> dict[str, int]:
    """Per question type, how many distinct counts its COUNT records answer."""
    return {
        q: len({str(r.answer) for r in records if r.question_type == q and r.answer_type is AnswerType.COUNT})
        for q in {r.question_type for r in records}
    }


def _chance(record: QARecord, live: Mapping[tuple[str, str], set[str]], counts: Mapping[str, int]) -> float | None:
    if record.answer_type is AnswerType.MCQ:
        return 1.0 / max(1, len(_live_letters(record, live)))
    if record.answer_type is AnswerType.YN:
        return 0.5
    if record.answer_type is AnswerType.COUNT:
        return 1.0 / max(1, counts.get(record.question_type, 1))
    return None


def blind_audit(records_by_scene: Mapping[str, Sequence[QARecord]], *, learned: bool = True) -> AuditReport:
    """Leave-one-scene-out blind predictors over ``records_by_scene`` (see the module docstring).

    Needs at least two scenes (with one, nothing is held out and the report is empty).
    ``learned=False`` skips the logistic models (the count-based priors only).
    """
    scenes = [s for s in records_by_scene if records_by_scene[s]]
    every = [r for s in scenes for r in records_by_scene[s]]
    live = _live_roles(every)
    distinct_counts = _distinct_counts(every)
    per_record: dict[str, dict[str, float]] = {}
    if len(scenes) >= 2:
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
                train = train_by_type.get(qtype, [])
                frequent = _frequent_words(train)
                priors = _Priors(train, frequent)
                models: dict[AnswerType, Any] = {}
                for kind in {r.answer_type for r in tests}:
                    kind_train = [r for r in train if r.answer_type is kind]
                    if not learned or not kind_train:
                        continue
                    if kind is AnswerType.MCQ:
                        models[kind] = _ConditionalLogit(kind_train, frequent)
                    elif kind in (AnswerType.YN, AnswerType.COUNT):
                        models[kind] = _MultinomialLogit(kind_train, frequent)
                    else:
                        models[kind] = _Ridge(kind_train, frequent)
                for r in tests:
                    scores: dict[str, float] = {}
                    for name in PREDICTORS:
                        if name == "learned":
                            model = models.get(r.answer_type)
                            if model is None:
                                continue
                            scores[name] = _score(r, model.predict(r))
                        else:
                            pred = priors.predict(name, r)
                            if pred is None and not (name in ("majority", "label")):
                                continue
                            scores[name] = _score(r, pred)
                    per_record[r.id] = scores
    groups: dict[tuple[str, str, str], list[QARecord]] = defaultdict(list)
    for r in every:
        if r.id in per_record:
            groups[(r.question_type, r.sub_question_type, r.answer_type.value)].append(r)
    rows: list[AuditRow] = []
    solved: list[str] = []
    pooled_n = 0
    pooled_hits = 0.0
    pooled_chance = 0.0
    pooled_by_predictor: Counter[str] = Counter()
    for key in sorted(groups):
        rs = groups[key]
        kind = rs[0].answer_type
        names = [p for p in PREDICTORS if all(p in per_record[r.id] for r in rs)]
        scores = {p: 100.0 * float(np.mean([per_record[r.id][p] for r in rs])) for p in names}
        chances = [_chance(r, live, distinct_counts) for r in rs]
        chance = None if chances[0] is None else 100.0 * float(np.mean(chances))
        best = max(names, key=lambda p: (scores[p], -PREDICTORS.index(p))) if names else ""
        best_score = scores.get(best, 0.0)
        n_solved = 0
        if best and kind in _DISCRETE and chance is not None and best_score > chance:
            for r in rs:
                if per_record[r.id][best] >= 1.0:
                    solved.append(r.id)
                    n_solved += 1
        rows.append(AuditRow(key[0], key[1], key[2], len(rs), chance, scores, best, best_score, n_solved))
        if kind in _DISCRETE and best:
            pooled_n += len(rs)
            pooled_hits += sum(per_record[r.id][best] for r in rs)
            pooled_chance += sum(chances)  # type: ignore[arg-type]
            for p in names:
                pooled_by_predictor[p] += sum(per_record[r.id][p] for r in rs)
    overall = {
        "n": pooled_n,
        "chance": 100.0 * pooled_chance / pooled_n if pooled_n else None,
        "best_per_sub_type": 100.0 * pooled_hits / pooled_n if pooled_n else None,
        "scenes": len(scenes),
    }
    if overall["chance"] is not None:
        overall["excess"] = overall["best_per_sub_type"] - overall["chance"]
    return AuditReport(rows, overall, solved, per_record)


def _null_records(records_by_scene: Mapping[str, Sequence[QARecord]], rng: np.random.Generator) -> dict[str, list[QARecord]]:
    """The records with every discrete truth drawn again, independently of the text: an MCQ's
    uniformly among its live options (:func:`_chance`'s), a yes/no or count among the answers of
    its question type in these records."""
    every = [r for rs in records_by_scene.values() for r in rs]
    live = _live_roles(every)
    answers: dict[tuple[str, AnswerType], list[str]] = defaultdict(list)
    for r in every:
        if r.answer_type in (AnswerType.YN, AnswerType.COUNT):
            answers[(r.question_type, r.answer_type)].append(str(r.answer))
    pools = {k: sorted(set(v)) for k, v in answers.items()}
    out: dict[str, list[QARecord]] = {}
    for scene, rs in records_by_scene.items():
        drawn = []
        for r in rs:
            if r.answer_type is AnswerType.MCQ:
                letters = _live_letters(r, live)
                r = replace(r, answer=letters[int(rng.integers(len(letters)))]) if letters else r
            elif r.answer_type in (AnswerType.YN, AnswerType.COUNT):
                pool = pools[(r.question_type, r.answer_type)]
                value = pool[int(rng.integers(len(pool)))]
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
    counts = _distinct_counts(every)
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

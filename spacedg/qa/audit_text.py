"""What a blind model reads in a question record: words, number bins, named labels, option roles, templates.

The blind stress test (:mod:`spacedg.qa.audit`) gives its predictors only the question text,
the option texts and the object labels the question names (read from the record's ``refs`` /
``label`` entries: the question states them verbatim, so this is text, not geometry). This
module turns a record into those pieces; nothing here looks at the images, the geometry's
numbers or the ``sub_question_type``.
"""

from __future__ import annotations

import math
import re
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from typing import TypeVar

from spacedg.plugins.qa_record import QARecord
from spacedg.plugins.questions.language import object_phrase, plural
from spacedg.plugins.specs import AnswerType
from spacedg.qa.stats import option_text
from spacedg.scene.lexicon import label_key

__all__ = [
    "TEMPLATE_DF", "NUMBER", "words", "tokens", "truth_text", "record_labels", "named_objects", "option_role",
    "template_words", "template_signature", "frequent_words",
]

_WORD = re.compile(r"[a-z]+|\d+(?:\.\d+)?")
NUMBER = re.compile(r"^\d+(?:\.\d+)?$")
#: A word is a template word of a question type when at least this share of its questions use it.
TEMPLATE_DF = 0.2


_T = TypeVar("_T")
#: Attribute of a record that holds its text features once computed (:func:`_kept`).
_KEPT = "_audit_text"


def _kept(record: QARecord, name: str, compute: Callable[[QARecord], _T]) -> _T:
    """``compute(record)``, computed once per record object and kept on it.

    A record is frozen, so its text never changes; the blind probes read the same records' features in every
    fold, split and pruning round (``export --debias`` on the session rooms: ~60,000 calls for ~1,000
    records). The values kept are immutable and picklable (tuples, frozensets); a record made from
    another (``dataclasses.replace``) is a new object and computes its own. Not a field: equality,
    ``to_dict`` and the index files do not see it; a pickle or copy of the record carries it (the same values
    its copy would compute). Two threads may both compute a value: the same value, one kept."""
    kept = record.__dict__.get(_KEPT)
    if kept is None:
        kept = {}
        object.__setattr__(record, _KEPT, kept)  # the record is a frozen dataclass
    if name not in kept:
        kept[name] = compute(record)
    return kept[name]


def words(text: str) -> list[str]:
    """Lower-case words and numbers of ``text``."""
    return _WORD.findall(str(text).lower())


def number_bin(token: str) -> str:
    """A number's magnitude bin: ``n:<round(2 log2 value)>`` (half-octaves), ``n:0`` for zero or less."""
    value = float(token)
    return "n:0" if value <= 0 else f"n:{round(2 * math.log2(value))}"


def tokens(text: str) -> list[str]:
    """Words of ``text``; numbers become magnitude bins (half-octaves)."""
    return [number_bin(w) if NUMBER.match(w) else w for w in words(text)]


def truth_text(record: QARecord) -> str:
    """The correct answer as text: the correct option's text (MCQ) or ``str(answer)``."""
    if record.answer_type is AnswerType.MCQ:
        return option_text(record, str(record.answer))
    return str(record.answer)


def record_labels(record: QARecord) -> tuple[str, ...]:
    """The labels the question names, in question order: the ``refs`` of its geometry block, else
    its ``label`` (existence, counting) or ``object`` (size); lower case. The question text
    states them, so a text-only model knows them too."""
    return _kept(record, "labels", _record_labels)


def _record_labels(record: QARecord) -> tuple[str, ...]:
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


def named_objects(record: QARecord) -> dict[str, str]:
    """Phrase (lower case) → label of every object the question names (a new dict each call)."""
    return dict(_kept(record, "named", _named_objects))


def _named_objects(record: QARecord) -> tuple[tuple[str, str], ...]:
    out: dict[str, str] = {}
    for ref in record.geometry.get("refs") or []:
        phrase = object_phrase(str(ref.get("label", "")), str(ref.get("description", ""))).lower()
        out.setdefault(" ".join(phrase.split()), str(ref.get("label", "")).lower())
    return tuple(out.items())


def option_role(record: QARecord, text: str) -> str:
    """How an option reads to a blind model: ``"object:<label>"`` when it names an object of the
    question, else its text (lower case)."""
    key = " ".join(text.lower().split())
    label = named_objects(record).get(key)
    return f"object:{label}" if label is not None else key


def template_words(record: QARecord) -> frozenset[str]:
    """The question's words without the objects and labels it names (and their plurals)."""
    return _kept(record, "template", _template_words)


def _template_words(record: QARecord) -> frozenset[str]:
    text = " ".join(record.question.lower().split())
    for phrase in sorted(named_objects(record), key=len, reverse=True):
        text = text.replace(phrase, " ")
    named: set[str] = set()
    for label in record_labels(record):
        named.update(words(label))
        named.update(words(plural(label)))
    return frozenset(w for w in words(text) if w not in named)


def template_signature(record: QARecord, frequent: frozenset[str]) -> str:
    """The question's template words: its words (objects and labels it names left out) that
    are in ``frequent`` (used by at least :data:`TEMPLATE_DF` of the question type's training
    questions), sorted."""
    return " ".join(sorted(w for w in template_words(record) if w in frequent))


def frequent_words(records: Sequence[QARecord]) -> frozenset[str]:
    """The template words of ``records`` (one question type): words used by at least
    :data:`TEMPLATE_DF` of them, numbers left out."""
    df: Counter[str] = Counter()
    for r in records:
        df.update(template_words(r))
    n = max(1, len(records))
    return frozenset(w for w, c in df.items() if c / n >= TEMPLATE_DF and not NUMBER.match(w))

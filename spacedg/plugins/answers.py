"""Answers, one module: how each :class:`~spacedg.plugins.specs.AnswerType` is held, written and read.

=============  ==========================================  =====================================
answer type    value (``QARecord.answer``, JSON)           text (``<answer>…</answer>``, TSV)
=============  ==========================================  =====================================
``MCQ``        option letter ``"A"`` … ``"D"``             ``B``
``YN``         ``"yes"`` or ``"no"`` (lower case)          ``yes``
``NA``         finite ``float``, the question's unit (m)   ``2.35`` (``str(float)``)
``COUNT``      ``int >= 0``                                ``3``
``SIZE_LIST``  ``(shortest, middle, longest)`` floats, m   ``[0.31, 0.90, 1.11]`` (2 decimals)
=============  ==========================================  =====================================

- :func:`validate_answer` checks and normalises a value (what :class:`~spacedg.plugins.qa_record.QARecord`
  stores); :class:`~spacedg.errors.InvalidDataError` otherwise.
- :func:`answer_text` writes a value as a model should write it (what exports and chat samples carry).
- :func:`answer_from_text` reads a typed-in answer (a reviewer's edit, a bench cell) back to the
  text stored for it, refusing anything that is not a valid answer of its type with a message
  that says what a valid one looks like.

Scoring a model's free-form output (tags, number words, hedges) is :mod:`spacedg.eval.parsing`.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from spacedg.errors import InvalidDataError
from spacedg.plugins.specs import AnswerType

__all__ = ["MCQ_LETTERS", "MCQ_OPTION_COUNTS", "Answer", "validate_answer", "answer_text", "answer_from_text"]

#: Option letters of a multiple-choice question, in order.
MCQ_LETTERS: tuple[str, ...] = ("A", "B", "C", "D")
#: How many options an MCQ may have: 4, or 3 where only three answers are possible (a size
#: comparison: object 1, object 2, about the same); never an option that cannot be the answer.
MCQ_OPTION_COUNTS: tuple[int, ...] = (3, 4)

#: A record's answer value (see the module docstring).
Answer = str | int | float | tuple[float, ...]

_NUMBER = re.compile(r"^[+-]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?$")
_COUNT = re.compile(r"^\d+$")


def _is_number(value: object) -> bool:
    return not isinstance(value, (bool, np.bool_)) and isinstance(value, (int, float, np.integer, np.floating))


def validate_answer(kind: AnswerType, answer: Any, where: str) -> Answer:
    """``answer`` normalised for ``kind`` (``int`` counts, ``float`` numbers, a size tuple), or
    :class:`InvalidDataError` prefixed with ``where`` saying what a valid answer is."""
    if kind is AnswerType.MCQ:
        if answer not in MCQ_LETTERS:
            raise InvalidDataError(f"{where}: an MCQ answer is the option letter 'A'–'D', got {answer!r}")
        return answer
    if kind is AnswerType.YN:
        if answer not in ("yes", "no"):
            raise InvalidDataError(f"{where}: a YN answer is 'yes' or 'no' (lower case), got {answer!r}")
        return answer
    if kind is AnswerType.COUNT:
        if not _is_number(answer) or not isinstance(answer, (int, np.integer)) or answer < 0:
            raise InvalidDataError(f"{where}: a COUNT answer is an integer >= 0, got {answer!r}")
        return int(answer)
    if kind is AnswerType.NA:
        if not _is_number(answer) or not math.isfinite(float(answer)):
            raise InvalidDataError(f"{where}: an NA answer is a finite number, got {answer!r}")
        return float(answer)
    # SIZE_LIST
    if isinstance(answer, (str, bytes)) or not isinstance(answer, (Sequence, np.ndarray)) or len(answer) != 3:
        raise InvalidDataError(f"{where}: a SIZE_LIST answer is [shortest, middle, longest] in metres, got {answer!r}")
    values = []
    for v in answer:
        if not _is_number(v) or not math.isfinite(float(v)) or v < 0:
            raise InvalidDataError(f"{where}: SIZE_LIST entries must be finite lengths >= 0 metres, got {list(answer)!r}")
        values.append(float(v))
    if values != sorted(values):
        raise InvalidDataError(f"{where}: a SIZE_LIST answer must be sorted [shortest, middle, longest], got {values}")
    return tuple(values)


def answer_text(answer: Any) -> str:
    """An answer value as the model should write it inside ``<answer>…</answer>`` (and as exports
    write it): a size list as ``[0.31, 0.90, 1.11]`` (metres, 2 decimals), anything else ``str()``."""
    if isinstance(answer, (list, tuple)):
        return "[" + ", ".join(f"{float(v):.2f}" for v in answer) + "]"
    return str(answer)


def _finite_number(text: str) -> float | None:
    if not _NUMBER.match(text):
        return None
    value = float(text)
    return value if math.isfinite(value) else None


def _size_list(text: str) -> list[float] | None:
    if not (text.startswith("[") and text.endswith("]")):
        return None
    parts = [p.strip() for p in text[1:-1].split(",")]
    if len(parts) != 3:
        return None
    values = [_finite_number(p) for p in parts]
    if any(v is None or v < 0 for v in values):
        return None
    return values  # type: ignore[return-value]


def answer_from_text(kind: AnswerType, text: str, options: Mapping[str, str] | None = None) -> str:
    """A typed-in answer of ``kind`` as it is stored (trimmed; MCQ letters upper case, yes/no lower
    case), or :class:`InvalidDataError` saying what a valid one looks like.

    ``options`` (letter → option text) is required for MCQ: the letter must name a non-empty option.
    """
    text = text.strip()
    if "\n" in text or "\t" in text:
        raise InvalidDataError("answer must be one line")
    if kind is AnswerType.MCQ:
        letter = text.upper()
        if letter not in MCQ_LETTERS:
            raise InvalidDataError(f"answer {text!r} is not an option letter; an MCQ answer is one of A, B, C, D")
        options = options or {}
        if not options.get(letter, "").strip():
            present = ", ".join(k for k in MCQ_LETTERS if options.get(k, "").strip()) or "none"
            raise InvalidDataError(f"answer {letter} has no option text (options present: {present})")
        return letter
    if kind is AnswerType.YN:
        if text.lower() not in ("yes", "no"):
            raise InvalidDataError(f"answer {text!r} is not yes or no (a yes/no question)")
        return text.lower()
    if kind is AnswerType.COUNT:
        if not _COUNT.match(text):
            raise InvalidDataError(f"answer {text!r} is not a non-negative integer (a counting question)")
        return text
    if kind is AnswerType.NA:
        if _finite_number(text) is None:
            raise InvalidDataError(f"answer {text!r} is not a finite number (a numerical question, e.g. 2.35)")
        return text
    if _size_list(text) is None:
        raise InvalidDataError(f"answer {text!r} is not a size list: three finite non-negative numbers like [0.10, 0.20, 0.30]")
    return text

"""One answer module: validate values, write them as text, read typed-in text back."""

from __future__ import annotations

import numpy as np
import pytest

from spacedg.errors import InvalidDataError
from spacedg.plugins.answers import answer_from_text, answer_text, validate_answer
from spacedg.plugins.specs import AnswerType as A


@pytest.mark.parametrize(
    ("kind", "value", "normalised", "text"),
    [
        (A.MCQ, "B", "B", "B"),
        (A.YN, "no", "no", "no"),
        (A.NA, np.float32(2.5), 2.5, "2.5"),
        (A.NA, 3, 3.0, "3.0"),
        (A.COUNT, np.int64(4), 4, "4"),
        (A.SIZE_LIST, [0.314, 0.9, 1.111], (0.314, 0.9, 1.111), "[0.31, 0.90, 1.11]"),
    ],
)
def test_validate_and_write(kind, value, normalised, text: str) -> None:
    out = validate_answer(kind, value, "here")
    assert out == normalised and type(out) is type(normalised)
    assert answer_text(out) == text
    assert answer_from_text(kind, text, {"B": "left"}) == (text if kind is not A.MCQ else "B")


@pytest.mark.parametrize(
    ("kind", "value", "pattern"),
    [
        (A.MCQ, "E", "option letter"),
        (A.YN, "Yes", "'yes' or 'no'"),
        (A.NA, float("nan"), "finite number"),
        (A.NA, True, "finite number"),
        (A.COUNT, 2.0, "integer >= 0"),
        (A.COUNT, -1, "integer >= 0"),
        (A.SIZE_LIST, [3, 2, 1], "sorted"),
        (A.SIZE_LIST, "[1, 2, 3]", "SIZE_LIST answer"),
    ],
)
def test_invalid_values_name_the_rule(kind, value, pattern: str) -> None:
    with pytest.raises(InvalidDataError, match=pattern):
        validate_answer(kind, value, "record x")


@pytest.mark.parametrize(
    ("kind", "text", "options", "pattern"),
    [
        (A.MCQ, "C", {"A": "x", "B": "y"}, "no option text"),
        (A.MCQ, "up", {}, "not an option letter"),
        (A.YN, "maybe", None, "not yes or no"),
        (A.COUNT, "2.5", None, "non-negative integer"),
        (A.NA, "inf", None, "finite number"),
        (A.SIZE_LIST, "[1, 2]", None, "three finite non-negative numbers"),
        (A.NA, "1\n2", None, "one line"),
    ],
)
def test_typed_in_answers_are_refused_with_the_fix(kind, text: str, options, pattern: str) -> None:
    with pytest.raises(InvalidDataError, match=pattern):
        answer_from_text(kind, text, options)
    assert answer_from_text(A.MCQ, " b ", {"B": "x"}) == "B" and answer_from_text(A.YN, "YES") == "yes"

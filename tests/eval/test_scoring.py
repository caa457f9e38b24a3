"""Scoring: answer extraction, routing, parsers, MRA, score() and summarize() (no models)."""

from __future__ import annotations

import json
import math
from typing import Any

import pytest

from spacedg.plugins.qa_record import QARecord
from spacedg.eval import (
    ANSWER_PROMPT,
    MRA_THRESHOLDS,
    ScoreResult,
    extract_answer_text,
    mean_relative_accuracy,
    parse_count,
    parse_mcq,
    parse_number,
    parse_size_list,
    parse_yes_no,
    route,
    score,
    summarize,
)
from spacedg.errors import InvalidDataError
from spacedg.plugins import AnswerType, TaskGroup
from tests.qa_records import MCQ_OPTIONS as OPTIONS
from tests.qa_records import qa_record


def _record(answer_type: AnswerType, answer: Any, **changes: Any) -> QARecord:
    """A record of ``answer_type`` answering ``answer`` (four options for an MCQ, none otherwise)."""
    return qa_record(answer_type=answer_type, answer=answer, options=OPTIONS if answer_type is AnswerType.MCQ else (), **changes)


# ------------------------------------------------------------------ prompt / extraction
def test_prompt_asks_for_answer_tags() -> None:
    assert "<answer>" in ANSWER_PROMPT and "</answer>" in ANSWER_PROMPT


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("<answer>B</answer>", "B"),
        ("<ANSWER> c </Answer>", "c"),
        ("reasoning…\n<answer>\n 2.5 m\n</answer> trailing", "2.5 m"),
        ("<answer>1</answer><answer>2</answer>", "1"),
        ("no tags at all  ", "no tags at all"),
        ("<answer>unclosed", "<answer>unclosed"),
        ("", ""),
        ("   \n\t ", ""),
        (None, ""),
    ],
)
def test_extract_answer_text(text: str | None, expected: str) -> None:
    assert extract_answer_text(text) == expected


# ------------------------------------------------------------------ routing
#: The public evaluator's routing (an empty sub type routes by question type; only distance_threshold
#: is YN; three NA sub types; anything else MCQ), plus our internal names (records, older exports).
ROUTES = [
    # public names, as every export carries them
    ("camera_translation", "main_dir", AnswerType.MCQ),
    ("camera_translation", "distance_exact", AnswerType.NA),
    ("camera_translation", "distance_threshold", AnswerType.YN),
    ("camera_rotation", "yaw+pitch_dual", AnswerType.MCQ),
    ("camera_rotation", "roll+yaw_single", AnswerType.MCQ),
    ("camera_object_distance_estimation", "", AnswerType.NA),
    ("camera_object_distance_estimation", "bbox_center_distance", AnswerType.NA),
    ("camera_object_relative_direction", "single_view", AnswerType.MCQ),
    ("camera_object_relative_direction", "bbox_center_direction", AnswerType.MCQ),
    ("camera_object_relative_direction", "relpos_A_facing_B", AnswerType.MCQ),
    ("cross_view_cardinal_direction", "assumed_direction", AnswerType.MCQ),
    ("inter_object_distance", "inter_object_distance", AnswerType.NA),
    ("object_proxy_cardinal_direction", "proxy_frame", AnswerType.MCQ),
    ("object_size_comparison", "longest_side_compare", AnswerType.MCQ),
    ("object_size_comparison", "top_height_compare", AnswerType.MCQ),
    ("object_bounding_size_estimation", "", AnswerType.SIZE_LIST),
    ("object_existence_estimation", "", AnswerType.MCQ),  # lettered options, as the public bench scores it
    ("object_counting", None, AnswerType.COUNT),
    ("distance_estimation", "", AnswerType.NA),  # the public table's short aliases
    ("existence_estimation", "", AnswerType.MCQ),
    ("size_estimation", "", AnswerType.SIZE_LIST),
    # our internal names (records; exports made before the public format)
    ("camera_object_distance_estimation", "single_view", AnswerType.NA),
    ("inter_object_distance", "two_view", AnswerType.NA),
    ("object_bounding_size_estimation", "extent_list", AnswerType.SIZE_LIST),
    ("object_existence_estimation", "existence", AnswerType.YN),
    ("object_counting", "count", AnswerType.COUNT),
    # names of neither kind: the public rule (a non-empty unknown sub type is MCQ)
    ("some_future_family", "whatever", AnswerType.MCQ),
    ("inter_object_distance", "center_distance", AnswerType.MCQ),
    ("object_counting", "object_counting", AnswerType.MCQ),
    ("Camera_Translation ", " DISTANCE_THRESHOLD", AnswerType.YN),
    (None, "distance_exact", AnswerType.NA),
]


@pytest.mark.parametrize(("qtype", "sub", "expected"), ROUTES)
def test_route_table(qtype: str | None, sub: str | None, expected: AnswerType) -> None:
    assert route(qtype, sub) is expected


@pytest.mark.parametrize("qtype", ["camera_translation", "some_future_family", ""])
def test_route_refuses_an_empty_sub_type_the_public_table_lacks(qtype: str) -> None:
    with pytest.raises(InvalidDataError, match="sub_question_type is empty"):
        route(qtype, "")


# ------------------------------------------------------------------ MCQ
@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("The answer is B.", "B"),
        ("<answer> c </answer>", "C"),
        ("<ANSWER>b</ANSWER> but maybe A", "B"),
        ("Answer: A", "A"),
        ("Answer: C", "C"),
        ("answer - d", "D"),
        ("B", "B"),
        ("a", "A"),
        ("(b)", "B"),
        ("**D**", "D"),
        ("Option C", "C"),
        ("B. right", "B"),
        ("(C) forward", "C"),
        ("The camera moved to the right, so B.", "B"),
        ("I pick C because it fits.", "C"),
        ("A is correct", "A"),
        ("The correct option is (d)", "D"),
        ("The answer is B. Option A is wrong.", "B"),
        ("The answer is not A, it is B", "B"),
        ("so the answer is a", "A"),
        # unparseable / ambiguous
        ("I think a chair is left", None),
        ("A chair is to the left.", None),
        ("the answer is a chair", None),
        ("The answer is A. Actually, the answer is C.", None),
        ("A, B, C or D", None),
        ("(A/B/C/D)", None),
        ("A or B", None),  # two options offered: a hedge, not B
        ("Either A or C", None),
        ("It happened at 10 a.m.", None),
        ("In 3D space it is left", None),
        ("Answer", None),
        ("E", None),
        ("", None),
        ("   ", None),
        ("<answer></answer> B", None),
    ],
)
def test_parse_mcq(text: str, expected: str | None) -> None:
    assert parse_mcq(text) == expected


def test_parse_mcq_option_text_fallback() -> None:
    assert parse_mcq("right", OPTIONS) == "B"
    assert parse_mcq("<answer>Forward.</answer>", {"A": "left", "B": "right", "C": "forward", "D": "backward"}) == "C"
    assert parse_mcq("forward-left", OPTIONS) is None  # only an exact option text maps
    assert parse_mcq("right", None) is None


# ------------------------------------------------------------------ yes / no
@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("yes", "yes"),
        ("<answer>No</answer>", "no"),
        ("YES.", "yes"),
        ("No, there is none.", "no"),
        ("Yes, but also no", None),
        ("<answer>yes</answer> or no", "yes"),
        ("Nothing notable", None),
        ("maybe", None),
        ("", None),
        # both words: the final answer decides (statement, else the last line), a hedge is ambiguous
        ("At first I'd say no, but the answer is yes", "yes"),
        ("There is no chair at first glance. Final answer: **No**", "no"),
        ("There is no lamp on the left, so yes", "yes"),
        ("No, wait: yes.", "yes"),
        ("Is it yes or no? Looking closer, I see it.\nYes.", "yes"),
        ("Is it yes or no? Looking closer, I see it: yes.", "yes"),
        ("Yes, and no other lamp is visible.", "yes"),
        ("I first thought yes.\nNo, there is none.", "no"),
        ("<answer>I said no before, but the answer is yes</answer>", "yes"),
        ("the answer is yes or no", None),
        ("maybe yes, maybe no", None),
        ("yes/no", None),
        ("Yes or no, I cannot tell.", None),
        ("I cannot tell: yes and no.", None),
        ("There is no chair but yes a table in the corner", None),  # neither a statement nor a final word
    ],
)
def test_parse_yes_no(text: str, expected: str | None) -> None:
    assert parse_yes_no(text) == expected


# ------------------------------------------------------------------ numbers
@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("2.5", 2.5),
        ("<answer>1.25</answer> (I measured 3 m before)", 1.25),
        ("1,234 m", 1234.0),
        ("1,234,567", 1234567.0),
        ("1,234.5", 1234.5),
        ("1,5", 1.5),  # a lone decimal-comma number
        ("2,75 m", 2.75),
        ("1,2,3", 3.0),  # commas separating numbers: the last one
        ("There are 3 chairs... final: 4", 4.0),
        ("-2.5", -2.5),
        ("−2", -2.0),
        (".5 m", 0.5),
        ("1e-3", 0.001),
        ("2.5E2 m", 250.0),
        ("2.5 m", 2.5),
        ("2 meters", 2.0),
        ("30cm", 0.3),
        ("30 centimetres", 0.3),
        ("1500 mm", 1.5),
        ("5 ft", 1.524),
        ("3-4 m", 4.0),
        ("In 3D the distance is 2.5 m", 2.5),
        ("2.5 m in 3D", 2.5),
        ("view2 is about 1.5", 1.5),
        ("Distance: 3.2m (±0.5m)", 3.2),
        ("3.2 +/- 0.4", 3.2),
        ("twenty-one", 21.0),
        ("twenty one chairs", 21.0),
        ("one hundred and five", 105.0),
        ("a dozen", 12.0),
        ("zero", 0.0),
        ("three, no wait, four", 4.0),
        ("about 2 (two) meters", 2.0),  # digits take precedence over words
        ("no idea", None),
        ("", None),
        ("   ", None),
        ("1e999", None),
    ],
)
def test_parse_number(text: str, expected: float | None) -> None:
    got = parse_number(text)
    if expected is None:
        assert got is None
    else:
        assert got == pytest.approx(expected, rel=1e-12, abs=1e-12)


def test_parse_number_without_unit_conversion() -> None:
    assert parse_number("30 cm", convert_units=False) == 30.0


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("3", 3),
        ("<answer>4</answer>", 4),
        ("3.0", 3),
        ("three", 3),
        ("twenty one chairs", 21),
        ("There are 3 chairs... final: 4", 4),
        ("1,234", 1234),
        ("2.5", None),
        ("-1", None),
        ("none", None),
        ("", None),
    ],
)
def test_parse_count(text: str, expected: int | None) -> None:
    got = parse_count(text)
    assert got == expected and (got is None or isinstance(got, int))


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("[0.5, 1.2, 2.0]", [0.5, 1.2, 2.0]),
        ("<answer>[0.10, 0.20, 0.30]</answer>", [0.1, 0.2, 0.3]),
        ("Dimensions: 0.5 x 1.2 x 2 m", [0.5, 1.2, 2.0]),
        ("0.5×1.2×2", [0.5, 1.2, 2.0]),
        ("50 x 120 x 200 cm", [0.5, 1.2, 2.0]),
        ("[50, 120, 200] cm", [0.5, 1.2, 2.0]),
        ("The 2 chairs are about [2.0, 0.5, 1.2] meters", [2.0, 0.5, 1.2]),
        ("[1,2,3]", [1.0, 2.0, 3.0]),
        ("shortest 0.4, middle 0.6 and longest 1.0", [0.4, 0.6, 1.0]),
        ("0.5 by 1.2", None),
        ("", None),
        # numbered lists: the labels are not values
        ("1. 0.31\n2. 0.9\n3. 1.11", [0.31, 0.9, 1.11]),
        ("<answer>1. 0.31\n2. 0.9\n3. 1.11</answer>", [0.31, 0.9, 1.11]),
        ("1) 31 cm 2) 90 cm 3) 111 cm", [0.31, 0.9, 1.11]),
        ("(1) 0.31 (2) 0.9 (3) 1.11", [0.31, 0.9, 1.11]),
        ("Edge 1: 0.31 m\nEdge 2: 0.9 m\nEdge 3: 1.11 m", [0.31, 0.9, 1.11]),
        ("1. The shortest edge is 0.31 m\n2. The middle one 0.9 m\n3. The longest 1.11 m", [0.31, 0.9, 1.11]),
        ("I see 2. The edges are 0.3, 0.5, 1.2", [0.3, 0.5, 1.2]),  # a lone "2." is not a list label
        # extra numbers: the last run of exactly three listed numbers, else refused
        ("The 3 edges are 0.31, 0.9 and 1.11 m", [0.31, 0.9, 1.11]),
        ("0.31, 0.9, 1.11 (about 2 ft)", [0.31, 0.9, 1.11]),
        ("0.3, 0.8, 1.0, no: 0.31, 0.9, 1.11", [0.31, 0.9, 1.11]),
        ("0.31, 0.9, 1.11, 2.0", None),
        ("[0.31, 0.9, 1.11, 2.0]", None),
        ("Shortest 0.31 m, middle 0.9 m, longest 1.11 m, volume 0.31 m3", None),
    ],
)
def test_parse_size_list(text: str, expected: list[float] | None) -> None:
    got = parse_size_list(text)
    if expected is None:
        assert got is None
    else:
        assert got == pytest.approx(expected)


# ------------------------------------------------------------------ MRA
def test_mra_thresholds_are_the_papers_ten() -> None:
    assert [float(t) for t in MRA_THRESHOLDS] == pytest.approx([0.5 + 0.05 * k for k in range(10)])


@pytest.mark.parametrize(
    ("pred", "truth", "expected"),
    [
        (2.0, 2.0, 1.0),
        (2.1, 2.0, 1.0),  # e = 0.05 exactly: counts at θ = 0.95
        (1.9, 2.0, 1.0),
        (2.11, 2.0, 0.9),  # e = 0.055: fails only θ = 0.95
        (2.5, 2.0, 0.6),  # e = 0.25: θ ∈ {0.50 … 0.75}
        (3.0, 2.0, 0.1),  # e = 0.5: only θ = 0.50
        (3.01, 2.0, 0.0),
        (1.0, 2.0, 0.1),
        (0.3, 0.2, 0.1),  # e = 0.5 exactly with inexact binary floats
        (-2.0, 2.0, 0.0),
        (-2.1, -2.0, 1.0),  # |truth| in the denominator
        (0.0, 0.0, 1.0),  # truth 0: exact match only
        (0.01, 0.0, 0.0),
        (math.nan, 1.0, 0.0),
        (math.inf, 1.0, 0.0),
        (None, 1.0, 0.0),
    ],
)
def test_mean_relative_accuracy(pred: float | None, truth: float, expected: float) -> None:
    assert mean_relative_accuracy(pred, truth) == pytest.approx(expected)


def test_mra_rejects_non_finite_truth() -> None:
    with pytest.raises(ValueError):
        mean_relative_accuracy(1.0, math.nan)


# ------------------------------------------------------------------ score
def test_score_mcq_record() -> None:
    rec = _record(AnswerType.MCQ, "B")
    assert score("The answer is B.", rec) == ScoreResult(1.0, "B", AnswerType.MCQ, True)
    assert score("<answer>A</answer>", rec).score == 0.0
    assert score("right", rec).score == 1.0  # exact option text


@pytest.mark.parametrize("prediction", ["", "   ", "I think a chair is left", "A/B/C/D", None])
def test_score_mcq_unparseable_is_a_miss(prediction: str | None) -> None:
    result = score(prediction, _record(AnswerType.MCQ, "A"))
    assert result.score == 0.0 and result.parsed is None and not result.parse_ok


def test_score_yes_no_and_count() -> None:
    yn = _record(AnswerType.YN, "no", sub_question_type="distance_threshold")
    assert score("<answer>No</answer>", yn).score == 1.0
    assert score("yes", yn).score == 0.0
    assert score("yes or no", yn) == ScoreResult(0.0, None, AnswerType.YN, False)
    count = _record(
        AnswerType.COUNT, 21, question_type="object_counting", sub_question_type="count",
        task_group=TaskGroup.OBJECT_CENTRIC, views=("v0",),
    )
    assert score("twenty one chairs", count) == ScoreResult(1.0, 21, AnswerType.COUNT, True)
    assert score("There are 3 chairs... final: 20", count).score == 0.0
    assert score("21.5", count).parse_ok is False


def test_score_numeric_answer() -> None:
    rec = _record(AnswerType.NA, 2.0, sub_question_type="distance_exact")
    assert score("<answer>2.1</answer>", rec).score == pytest.approx(1.0)
    assert score("2.5 m", rec).score == pytest.approx(0.6)
    assert score("250 cm", rec).score == pytest.approx(0.6)
    assert score("I can't tell", rec) == ScoreResult(0.0, None, AnswerType.NA, False)


def test_score_size_list_sorted_and_positional() -> None:
    rec = _record(
        AnswerType.SIZE_LIST, (0.5, 1.0, 2.0), question_type="object_bounding_size_estimation",
        sub_question_type="size", task_group=TaskGroup.OBJECT_CENTRIC, views=("v0",),
    )
    ok = score("[0.5, 1.0, 2.0]", rec)
    assert ok.score == pytest.approx(1.0) and ok.parsed == (0.5, 1.0, 2.0)
    shuffled = score("Dimensions: 2 x 0.5 x 1 m", rec, sort_sizes=True)  # the lenient reading
    assert shuffled.score == pytest.approx(1.0) and shuffled.parsed == (0.5, 1.0, 2.0)
    # positional by default (the paper requires ascending order): 2 vs 0.5 → 0, 0.5 vs 1.0 → e = 0.5 → 0.1, 1 vs 2 → 0.1
    assert score("2, 0.5, 1", rec).score == pytest.approx(0.2 / 3)
    # per-element MRA averaged: e = 0.05 (1.0), e = 0.25 (0.6), e = 0 (1.0)
    assert score("[0.525, 1.25, 2.0]", rec).score == pytest.approx(2.6 / 3)
    assert score("0.5 and 1.0", rec).parse_ok is False


def test_score_from_tsv_like_mapping() -> None:
    row = {"question_type": "camera_translation", "sub_question_type": "main_dir", "answer": " b ",
           "A": "left", "B": "right", "C": "forward", "D": "backward"}
    assert score("right", row).score == 1.0
    assert score("<answer>B</answer>", row).answer_type is AnswerType.MCQ
    na_row = {"question_type": "inter_object_distance", "sub_question_type": "inter_object_distance", "answer": "2.0"}
    assert score("2.5", na_row).score == pytest.approx(0.6)
    yn_row = {"question_type": "camera_translation", "sub_question_type": "distance_threshold", "answer": "Yes"}
    assert score("yes", yn_row).score == 1.0
    old_existence = {"question_type": "object_existence_estimation", "sub_question_type": "existence", "answer": "no"}
    assert score("<answer>no</answer>", old_existence).answer_type is AnswerType.YN  # an export with our internal names
    existence = {"question_type": "object_existence_estimation", "sub_question_type": float("nan"), "answer": "B",
                 "A": "yes", "B": "no", "C": float("nan"), "D": float("nan")}  # as pandas reads the public format
    assert score("<answer>B</answer>", existence).score == 1.0 and score("no", existence).score == 1.0
    assert score("yes", existence).score == 0.0 and score("<answer>no</answer>", existence).answer_type is AnswerType.MCQ
    size_row = {"answer_type": "SIZE_LIST", "answer": "[0.1, 0.2, 0.3]"}
    assert score("[0.1, 0.2, 0.3]", size_row).score == pytest.approx(1.0)
    mcq_json_options = {"answer_type": "MCQ", "answer": "C", "options": json.dumps(list(OPTIONS))}
    assert score("forward", mcq_json_options).score == 1.0
    with pytest.raises(ValueError):
        score("A", {"answer": "A"})


# ------------------------------------------------------------------ summarize
def test_summarize_counts_every_answer_type() -> None:
    results = [
        ScoreResult(1.0, "B", AnswerType.MCQ, True),
        ScoreResult(0.0, None, AnswerType.MCQ, False),
        ScoreResult(1.0, "yes", AnswerType.YN, True),
        ScoreResult(0.6, 2.5, AnswerType.NA, True),
        ScoreResult(0.2, (1.0, 2.0, 3.0), AnswerType.SIZE_LIST, True),
        ScoreResult(1.0, 3, AnswerType.COUNT, True),
    ]
    summary = summarize(results, groups={"degradation_type": ["ori", "haze", "ori", "haze", "ori", "ori"]})
    assert summary["overall"]["n"] == 6
    assert summary["overall"]["score"] == pytest.approx(3.8 / 6)
    assert summary["overall"]["parse_rate"] == pytest.approx(5 / 6)
    by_type = summary["by_answer_type"]
    assert list(by_type) == ["MCQ", "YN", "NA", "COUNT", "SIZE_LIST"]
    assert by_type["MCQ"] == {"n": 2, "score": 0.5, "parse_rate": 0.5}
    assert by_type["NA"]["score"] == pytest.approx(0.6)
    assert by_type["SIZE_LIST"]["score"] == pytest.approx(0.2)
    assert summary["by_degradation_type"]["haze"]["score"] == pytest.approx(0.3)
    assert summary["by_degradation_type"]["ori"]["n"] == 4
    json.dumps(summary)


def test_summarize_empty_and_bad_groups() -> None:
    assert summarize([]) == {"overall": {"n": 0, "score": None, "parse_rate": None}, "by_answer_type": {}}
    with pytest.raises(ValueError):
        summarize([ScoreResult(1.0, "A", AnswerType.MCQ, True)], groups={"g": []})

"""QARecord: validation by answer type, JSON round trip, deterministic ids."""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import pytest

from spacedg.plugins.qa_record import QARecord, json_ready, make_record_id
from spacedg.errors import InvalidDataError
from spacedg.plugins import AnswerType
from tests.qa_records import MCQ_OPTIONS
from tests.qa_records import qa_record as _record

VALID = {
    "MCQ": {},
    "YN": {"answer_type": "YN", "options": (), "answer": "yes", "sub_question_type": "distance_threshold"},
    "NA": {"answer_type": AnswerType.NA, "options": (), "answer": 1.25, "sub_question_type": "distance_exact"},
    "COUNT": {"answer_type": AnswerType.COUNT, "options": (), "answer": 3, "task_group": "object_centric",
              "question_type": "object_counting", "sub_question_type": "count", "views": ("v0",)},
    "SIZE_LIST": {"answer_type": AnswerType.SIZE_LIST, "options": (), "answer": [0.2, 0.5, 1.1], "views": ("v0",)},
    "rotation_subtype": {"sub_question_type": "yaw+pitch_dual"},
}


@pytest.mark.parametrize("case", sorted(VALID))
def test_valid_records_round_trip(case: str) -> None:
    record = _record(**VALID[case])
    data = record.to_dict()
    text = json.dumps(data)
    assert json.loads(text) == data
    clone = QARecord.from_dict(json.loads(text))
    assert clone == record and clone.to_dict() == data
    assert QARecord.from_json(record.to_json()) == record
    assert hash(clone) == hash(record)


def test_normalised_types() -> None:
    r = _record(**VALID["SIZE_LIST"])
    assert r.answer == (0.2, 0.5, 1.1) and r.to_dict()["answer"] == [0.2, 0.5, 1.1]
    c = _record(**{**VALID["COUNT"], "answer": np.int64(4)})
    assert c.answer == 4 and type(c.answer) is int
    n = _record(**{**VALID["NA"], "answer": 2})
    assert n.answer == 2.0 and type(n.answer) is float
    assert _record(task_group="camera_centric", answer_type="MCQ", views=["v0", "v1"]).views == ("v0", "v1")
    assert _record(views="v0").views == ("v0",)


def test_geometry_becomes_plain_json() -> None:
    r = _record(geometry={"t": (np.float32(0.5), np.int64(2)), "m": np.eye(2), "ok": np.bool_(True), "nested": {"ids": (1, 2)}})
    assert r.geometry == {"t": [0.5, 2], "m": [[1.0, 0.0], [0.0, 1.0]], "ok": True, "nested": {"ids": [1, 2]}}
    assert QARecord.from_dict(json.loads(json.dumps(r.to_dict()))) == r
    external = {"a": [1]}
    r2 = _record(geometry=external)
    external["a"].append(2)
    assert r2.geometry == {"a": [1]}, "geometry must be copied"
    r2.to_dict()["geometry"]["a"].append(3)
    assert r2.geometry == {"a": [1]}, "to_dict must return a copy"


@pytest.mark.parametrize(
    ("changes", "pattern"),
    [
        ({"options": MCQ_OPTIONS[:2]}, "needs 4 options"),
        ({"options": MCQ_OPTIONS[:3], "answer": "D"}, "names no option"),
        ({"options": ("A. x", "B. y", "D. z", "C. w")}, "option C must read 'C. <text>'"),
        ({"options": ("A) x", "B. y", "C. z", "D. w")}, "option A must read"),
        ({"options": ("A. x", "B. x", "C. z", "D. w")}, "repeat a text"),
        ({"options": "A. x"}, "not one string"),
        ({"answer": "E"}, "MCQ answer is the option letter"),
        ({"answer": "b"}, "MCQ answer is the option letter"),
        ({"answer_type": "YN", "answer": "yes"}, "only MCQ records have options"),
        ({"answer_type": "YN", "options": (), "answer": "Yes"}, "'yes' or 'no'"),
        ({"answer_type": "COUNT", "options": (), "answer": -1}, "integer >= 0"),
        ({"answer_type": "COUNT", "options": (), "answer": 2.0}, "integer >= 0"),
        ({"answer_type": "COUNT", "options": (), "answer": True}, "integer >= 0"),
        ({"answer_type": "COUNT", "options": (), "answer": "3"}, "integer >= 0"),
        ({"answer_type": "NA", "options": (), "answer": float("nan")}, "finite number"),
        ({"answer_type": "NA", "options": (), "answer": "1.5"}, "finite number"),
        ({"answer_type": "SIZE_LIST", "options": (), "answer": [1.0, 0.5, 2.0]}, "must be sorted"),
        ({"answer_type": "SIZE_LIST", "options": (), "answer": [0.5, 1.0]}, r"\[shortest, middle, longest\]"),
        ({"answer_type": "SIZE_LIST", "options": (), "answer": [-0.1, 0.5, 1.0]}, "finite lengths >= 0"),
        ({"answer_type": "MAYBE"}, "answer_type 'MAYBE' is not one of MCQ, YN, NA, COUNT, SIZE_LIST"),
        ({"task_group": "objects"}, "task_group 'objects' is not one of"),
        ({"views": ()}, "views must be one or more"),
        ({"views": ("v0", "v0")}, "repeat a view"),
        ({"question": "  "}, "question must be a non-empty string"),
        ({"id": ""}, "id must be a non-empty string"),
        ({"question_type": "Camera Translation"}, r"question_type .* must match"),
        ({"sub_question_type": "Main-Dir"}, "sub_question_type 'Main-Dir'"),
        ({"geometry": {"d": float("inf")}}, r"geometry\.d is inf"),
        ({"geometry": {"p": [0.0, float("nan")]}}, r"geometry\.p\[1\] is nan"),
        ({"geometry": {1: "x"}}, "JSON keys must be strings"),
        ({"geometry": {"o": object()}}, r"geometry\.o is a object"),
        ({"geometry": [1, 2]}, "geometry must be a dict"),
    ],
)
def test_invalid_records(changes: dict[str, Any], pattern: str) -> None:
    with pytest.raises(InvalidDataError, match=pattern):
        _record(**changes)


def test_from_dict_rejects_missing_and_unknown_keys() -> None:
    data = _record().to_dict()
    with pytest.raises(InvalidDataError, match=r"missing key\(s\) \['answer'\]"):
        QARecord.from_dict({k: v for k, v in data.items() if k != "answer"})
    with pytest.raises(InvalidDataError, match=r"unknown key\(s\) \['extra'\]"):
        QARecord.from_dict({**data, "extra": 1})
    with pytest.raises(InvalidDataError, match="expected a JSON object"):
        QARecord.from_dict([data])  # type: ignore[arg-type]
    with pytest.raises(InvalidDataError, match="not valid JSON"):
        QARecord.from_json("{")


def test_record_is_frozen() -> None:
    r = _record()
    with pytest.raises(AttributeError):
        r.answer = "C"  # type: ignore[misc]


def test_make_record_id() -> None:
    a = make_record_id("room", "object_counting", "count", ["v0"], {"ids": [1, 2], "template": 0})
    assert a == make_record_id("room", "object_counting", "count", ("v0",), {"template": 0, "ids": (1, 2)})
    assert a.startswith("room/object_counting/count/") and len(a.rsplit("/", 1)[1]) == 12
    assert a != make_record_id("room", "object_counting", "count", ["v1"], {"ids": [1, 2], "template": 0})
    assert a != make_record_id("room", "object_counting", "count", ["v0"], {"ids": [1, 2], "template": 1})
    # stable across processes and versions: a fixed value
    assert make_record_id("s", "q", "t", ["v"], 1) == "s/q/t/" + __import__("hashlib").sha1(b'{"key":1,"views":["v"]}').hexdigest()[:12]


def test_json_ready_rejects_with_path() -> None:
    with pytest.raises(InvalidDataError, match=r"key\.a\[0\] is nan"):
        json_ready({"a": [float("nan")]}, "key")


def test_json_ready_fast_path_equals_the_full_walk() -> None:
    """The plain-types fast path gives exactly the full walk's result (values and types), and
    anything it cannot take (numpy, subclasses, NaN, bad keys) still goes through the walk."""
    import enum
    import json

    import numpy as np

    from spacedg.plugins import qa_record

    class Level(enum.IntEnum):
        HIGH = 2

    rng = np.random.default_rng(0)
    leaves = [None, True, 0, -7, 1.5, "a", np.float32(0.25), np.int64(3), np.bool_(False), Level.HIGH,
              np.arange(3), (1, 2.0)]
    for _ in range(200):
        value = {f"k{i}": [leaves[int(j)] for j in rng.integers(0, len(leaves), 3)] for i in range(3)}
        fast = qa_record.json_ready(value)
        walked = qa_record._json_ready_walk(value, "geometry")
        assert fast == walked and json.dumps(fast) == json.dumps(walked)
        assert [type(x) for row in fast.values() for x in row] == [type(x) for row in walked.values() for x in row]
    for bad, where in (({"a": [1.0, float("nan")]}, r"geometry\.a\[1\] is nan"), ({"a": {3: 1}}, "has key 3")):
        with pytest.raises(InvalidDataError, match=where):
            qa_record.json_ready(bad)

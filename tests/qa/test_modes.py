"""Selection modes (strict bench, dense train), no twins, and only answerable options: on
hand-made records and on the session rooms' records (``room_records``, built once)."""

from __future__ import annotations

from collections import defaultdict

import pytest

from spacedg.errors import ParameterError
from spacedg.plugins.answers import MCQ_LETTERS
from spacedg.plugins.qa_record import QARecord
from spacedg.plugins.questions.language import object_phrase
from spacedg.plugins.questions.records import selection_entry
from spacedg.plugins.questions.view_sampling import VisibilityIndex
from spacedg.plugins.specs import AnswerType, TaskGroup
from spacedg.qa.index import QABuildConfig, index_paths
from spacedg.qa.mode_stats import count_distribution, mode_row, object_reasks
from spacedg.qa.modes import TRAIN_QUOTA_FACTOR, quota, subject_key
from spacedg.qa.selection import select_records
from spacedg.qa.stats import option_text
from spacedg.qa.twins import TwinCheck, has_twin, named_ids


def _distance(k: int, view: str, obj: int) -> QARecord:
    return QARecord(
        id=f"r{k}", scene_id="s", question_type="camera_object_distance_estimation", sub_question_type="single_view",
        task_group=TaskGroup.CAMERA_OBJECT, answer_type=AnswerType.NA, views=(view,), question=f"How far is object {obj}?",
        answer=1.0 + k, geometry={"refs": [{"id": obj, "view": view}], "selection": selection_entry(f"view:{view}|object:{obj}")},
    )


def test_subject_key_per_mode() -> None:
    assert subject_key("view:f3|object:12", ("f3",)) == "object:12"
    assert subject_key("view:f3|objects:1|2", ("f3",), "bench") == "objects:1|2"
    assert subject_key("view:f3|label:chair", ("f3",), "bench") == "view:f3|label:chair"  # a view and a label: kept
    assert subject_key("views:a|b", ("a", "b"), "bench") == "views:a|b"
    assert subject_key("object:12", ("f1", "f3"), "train") == "object:12|views:f1,f3"
    assert quota(25) == 25 and quota(25, "train") == 25 * TRAIN_QUOTA_FACTOR


def test_mode_config_and_files() -> None:
    assert QABuildConfig().mode == "bench" and QABuildConfig.from_dict({**QABuildConfig().to_dict(), "mode": "train"}).mode == "train"
    old = {k: v for k, v in QABuildConfig().to_dict().items() if k != "mode"}
    assert QABuildConfig.from_dict(old).mode == "bench"  # a meta file written before modes
    with pytest.raises(ParameterError, match="mode must be one of.*'dense'"):
        QABuildConfig(mode="dense")
    assert index_paths("r", "/x", mode="train")[0].name == "r.qa-train.jsonl"
    assert index_paths("r", "/x", ("a",), mode="train")[1].name == "r.qa-train.a.meta.json"
    assert index_paths("r", "/x")[0].name == "r.qa.jsonl"


def test_bench_asks_an_object_once_train_from_every_view() -> None:
    records = [_distance(k, f"v{k % 3}", obj=k // 3) for k in range(9)]  # objects 0, 1, 2 from views v0, v1, v2
    bench = select_records(records, 25, mode="bench")
    train = select_records(records, 25, mode="train")
    assert sorted(named_ids(r)[0] for r in bench) == [0, 1, 2]
    assert len(train) == 9
    assert object_reasks({"s": bench})[-1]["reasks"] == 0
    assert object_reasks({"s": train})[-1] == {"question_type": "ALL", "sub_question_type": "", "n": 9, "reasks": 6, "max_per_object": 3}
    assert mode_row("train", {"s": train})["per_scene"] == 9.0


def test_rooms_bench_has_no_reasks_no_twins_and_counts_beyond_one(room_records) -> None:
    by_scene = {scene.id: records for scene, records in room_records}
    assert object_reasks(by_scene)[-1]["reasks"] == 0
    for scene, records in room_records:
        check = TwinCheck(VisibilityIndex(scene))
        assert not any(check.has_twin(r) for r in records), scene.id
    dist = count_distribution(r for _, rs in room_records for r in rs)
    assert {0, 1, 2} <= set(dist) and len({dist[0], dist[1], sum(v for k, v in dist.items() if k >= 2)}) == 1  # bins 0 / 1 / 2+ even


def test_twin_in_the_other_image_is_found(room_records) -> None:
    """A record naming an object is a twin case iff one of its views shows a same-description
    same-label instance; checked against a brute force over the rooms' instances."""
    scene, records = room_records[0]
    index = VisibilityIndex(scene)
    for r in records[:200]:
        brute = any(
            o != i and index.instance(o).label.lower() == index.instance(i).label.lower()
            and (not index.instance(i).description or index.instance(o).description.lower() == index.instance(i).description.lower())
            for i in named_ids(r) for v in r.views for o in index.seen[v]
        )
        assert has_twin(r, index) == brute


def _option_key(record: QARecord, text: str) -> str:
    """An option's text, or ``<object>`` when it is the phrase of an object the question names (size comparisons)."""
    names = {object_phrase(str(o["label"]), str(o.get("description", ""))) for o in record.geometry.get("objects", []) if isinstance(o, dict)}
    return "<object>" if text in names else text


def _wording(record: QARecord) -> str:
    """What a model sees of the question's kind: its sub type, except camera rotation, whose
    dual sub types (dominant axis first) share one wording per axis pair (the selection cell);
    for rotation the cell is the wording (a single's sub type already is)."""
    if record.question_type == "camera_rotation":
        return f"camera_rotation|{record.geometry['selection']['cell']}"
    return record.sub_question_type


def test_every_offered_option_is_the_answer_somewhere(room_records) -> None:
    """Per MCQ sub type over the four rooms: every option text offered is the correct answer of
    some record of that sub type (no option that is never correct); size comparisons offer 3."""
    offered: dict[str, set[str]] = defaultdict(set)
    correct: dict[str, set[str]] = defaultdict(set)
    for _, records in room_records:
        for r in records:
            if r.answer_type is not AnswerType.MCQ:
                continue
            letters = MCQ_LETTERS[:len(r.options)]
            offered[_wording(r)] |= {_option_key(r, option_text(r, k)) for k in letters}
            correct[_wording(r)].add(_option_key(r, option_text(r, str(r.answer))))
            if r.question_type == "object_size_comparison":
                assert len(r.options) == 3 and "cannot be determined" not in {o[3:] for o in r.options}
    assert "bbox_center_direction" in offered and "longest_side_compare" in offered
    never = {sub: sorted(offered[sub] - correct[sub]) for sub in offered if offered[sub] - correct[sub]}
    assert not never, never

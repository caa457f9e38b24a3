"""ReviewStore: edits validated by answer type, an append-only log, a new reviewed TSV, replay."""

from __future__ import annotations

import csv
import json
import threading
from pathlib import Path

import pytest

from spacedg.errors import FileFormatError, InvalidDataError, ParameterError
from spacedg.plugins import AnswerType, TaskGroup
from spacedg.data.bench_table import read_table
from spacedg.eval.bench import load_bench
from spacedg.review import ReviewError, ReviewStore
from tests.eval_fixtures import write_bench
from tests.qa_records import qa_record

# index = 5 · condition + question; questions: 0 MCQ, 1 YN, 2 NA, 3 COUNT, 4 SIZE_LIST
MCQ, YN, NA, COUNT, SIZE = 0, 1, 2, 3, 4


@pytest.fixture()
def bench(tmp_path: Path) -> Path:
    return write_bench(tmp_path / "bench")


def _log_lines(store: ReviewStore) -> list[dict]:
    if not store.log.exists():
        return []
    return [json.loads(line) for line in store.log.read_text(encoding="utf-8").splitlines() if line.strip()]


def _reviewed(store: ReviewStore) -> dict[int, dict[str, str]]:
    return {int(r["index"]): r for r in read_table(store.out)}


def test_defaults_and_first_write(bench: Path) -> None:
    original = (bench / "bench.tsv").read_bytes()
    store = ReviewStore(bench)
    assert store.table == bench / "bench.tsv"
    assert store.out == bench / "bench.reviewed.tsv"
    assert store.log == bench / "bench.reviewed.log.jsonl"
    assert len(store) == 15
    assert store.header[:4] == ["index", "question", "answer", "image_path"]
    assert store.out.is_file() and not store.log.exists()
    assert list(_reviewed(store)) == list(range(15))
    assert (bench / "bench.tsv").read_bytes() == original
    summaries = store.summaries()
    assert [s["index"] for s in summaries] == list(range(15))
    assert summaries[0]["title"] == "Where did the camera move?"
    assert summaries[0]["answer_type"] == "MCQ" and summaries[7]["degradation_type"] == "haze"
    assert not any(s["dropped"] or s["edited"] for s in summaries)


def test_item_fields(bench: Path) -> None:
    store = ReviewStore(bench)
    item = store.item(5 + MCQ)
    assert item["options"] == {"A": "left", "B": "right", "C": "forward", "D": "backward"}
    assert item["image_paths"] == ["images/0000005_0.png"]
    assert item["answer"] == "B" and item["answer_type"] == "MCQ"
    assert item["clean_index"] == MCQ and store.item(MCQ)["clean_index"] == MCQ
    assert item["history"] == [] and item["geometry"] is None
    assert store.item(YN)["options"] == {}
    assert set(store.header) <= set(item)


def test_blank_answer_type_is_routed(tmp_path: Path) -> None:
    folder = write_bench(tmp_path / "b")
    rows = read_table(folder / "bench.tsv")
    for row in rows:
        row["answer_type"] = ""
    with (folder / "bench.tsv").open("w", newline="", encoding="utf-8") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]), delimiter="\t", lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
    store = ReviewStore(folder)
    assert [store.item(i)["answer_type"] for i in range(5)] == ["MCQ", "YN", "NA", "COUNT", "SIZE_LIST"]
    with pytest.raises(ReviewError, match="yes or no"):
        store.edit(YN, {"answer": "maybe"}, "ana")


def test_edit_mcq_answer_writes_new_tsv_and_log(bench: Path) -> None:
    original = (bench / "bench.tsv").read_bytes()
    store = ReviewStore(bench)
    item = store.edit(MCQ, {"answer": " c "}, "ana")
    assert item["answer"] == "C" and item["edited"]
    assert _reviewed(store)[MCQ]["answer"] == "C"
    assert _reviewed(store)[5]["answer"] == "B"  # other conditions untouched
    assert (bench / "bench.tsv").read_bytes() == original
    [entry] = _log_lines(store)
    assert entry["action"] == "edit" and entry["reviewer"] == "ana" and entry["index"] == MCQ
    assert entry["record_id"] == "room/camera_translation/main_dir/0"
    assert entry["before"] == {"answer": "B"} and entry["after"] == {"answer": "C"}
    assert entry["time"].endswith("+00:00") and "T" in entry["time"]
    assert item["history"] == [entry]
    assert store.summaries()[MCQ]["edited"]


def test_option_edit_rewrites_question_line(bench: Path) -> None:
    store = ReviewStore(bench)
    item = store.edit(MCQ, {"C": "straight ahead"}, "ana")
    assert item["C"] == "straight ahead" and item["options"]["C"] == "straight ahead"
    assert item["question"] == "Where did the camera move?\nA. left\nB. right\nC. straight ahead\nD. backward"
    [entry] = _log_lines(store)
    assert entry["before"] == {"question": "Where did the camera move?\nA. left\nB. right\nC. forward\nD. backward",
                               "C": "forward"}
    assert entry["after"]["C"] == "straight ahead"
    row = load_bench(store.out).by_index[MCQ]
    assert row.options == ("left", "right", "straight ahead", "backward")
    assert row.question.endswith("C. straight ahead\nD. backward")
    # question and option edited together: the option line is rewritten in the new question
    item = store.edit(MCQ, {"question": "Which way?\nA. left\nB. right\nC. straight ahead\nD. backward", "D": "back"}, "bo")
    assert item["question"] == "Which way?\nA. left\nB. right\nC. straight ahead\nD. back"


def test_valid_edits_per_type(bench: Path) -> None:
    store = ReviewStore(bench)
    assert store.edit(YN, {"answer": "NO"}, "ana")["answer"] == "no"
    assert store.edit(NA, {"answer": " 2.35 "}, "ana")["answer"] == "2.35"
    assert store.edit(COUNT, {"answer": "0"}, "ana")["answer"] == "0"
    assert store.edit(SIZE, {"answer": "[0.1, 0.2, 0.4]"}, "ana")["answer"] == "[0.1, 0.2, 0.4]"
    assert len(_log_lines(store)) == 4
    rows = _reviewed(store)
    assert [rows[i]["answer"] for i in (YN, NA, COUNT, SIZE)] == ["no", "2.35", "0", "[0.1, 0.2, 0.4]"]


@pytest.mark.parametrize(("index", "changes", "message"), [
    (MCQ, {"answer": "E"}, "not an option letter"),
    (YN, {"answer": "maybe"}, "not yes or no"),
    (COUNT, {"answer": "-1"}, "non-negative integer"),
    (COUNT, {"answer": "2.5"}, "non-negative integer"),
    (NA, {"answer": "abc"}, "finite number"),
    (NA, {"answer": "nan"}, "finite number"),
    (NA, {"answer": "inf"}, "finite number"),
    (SIZE, {"answer": "[1,2]"}, "size list"),
    (SIZE, {"answer": "[1, 2, -3]"}, "size list"),
    (MCQ, {"question": "   "}, "question cannot be empty"),
    (MCQ, {"C": ""}, "option C cannot be empty"),
    (MCQ, {"B": "two\nlines"}, "one line"),
    (YN, {"A": "x"}, "MCQ only"),
    (MCQ, {"scene_id": "other"}, "'scene_id' cannot be edited"),
    (MCQ, {}, "no changes"),
])
def test_invalid_edits_refused(bench: Path, index: int, changes: dict, message: str) -> None:
    store = ReviewStore(bench)
    before = store.out.read_bytes()
    with pytest.raises(ReviewError, match=message):
        store.edit(index, changes, "ana")
    assert store.out.read_bytes() == before and not store.log.exists()
    assert not store.item(index)["edited"] and store.item(index)["history"] == []


def test_answer_to_empty_option_refused(tmp_path: Path) -> None:
    folder = write_bench(tmp_path / "b")
    rows = read_table(folder / "bench.tsv")
    rows[0]["D"] = ""
    rows[0]["question"] = "Where did the camera move?\nA. left\nB. right\nC. forward"
    with (folder / "bench.tsv").open("w", newline="", encoding="utf-8") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]), delimiter="\t", lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
    store = ReviewStore(folder)
    with pytest.raises(ReviewError, match="answer D has no option text"):
        store.edit(MCQ, {"answer": "D"}, "ana")
    with pytest.raises(ReviewError, match="option D is not part of this question"):
        store.edit(MCQ, {"D": "up"}, "ana")
    assert not store.log.exists()


def test_unknown_index_reviewer_and_noop(bench: Path) -> None:
    store = ReviewStore(bench)
    with pytest.raises(ReviewError, match="no item with index 99"):
        store.edit(99, {"answer": "A"}, "ana")
    with pytest.raises(ReviewError, match="no item with index 99"):
        store.item(99)
    with pytest.raises(ReviewError, match="no item with index 99"):
        store.set_dropped(99, True, "ana")
    with pytest.raises(ReviewError, match="reviewer"):
        store.edit(MCQ, {"answer": "A"}, " ")
    before = store.out.read_bytes()
    item = store.edit(MCQ, {"answer": "B", "A": "left"}, "ana")  # same values
    assert item["answer"] == "B" and not item["edited"]
    assert not store.log.exists() and store.out.read_bytes() == before


def test_drop_and_restore(bench: Path) -> None:
    store = ReviewStore(bench)
    item = store.set_dropped(5 + COUNT, True, "ana")
    assert item["dropped"]
    assert 5 + COUNT not in _reviewed(store) and len(_reviewed(store)) == 14
    assert store.summaries()[5 + COUNT]["dropped"]
    assert store.set_dropped(5 + COUNT, True, "ana")["dropped"]  # no-op: not logged
    entries = _log_lines(store)
    assert [e["action"] for e in entries] == ["drop"]
    assert entries[0]["before"] == {"dropped": False} and entries[0]["after"] == {"dropped": True}
    store.set_dropped(5 + COUNT, False, "bo")
    assert 5 + COUNT in _reviewed(store) and len(_reviewed(store)) == 15
    assert [e["action"] for e in _log_lines(store)] == ["drop", "restore"]
    assert len(store.item(5 + COUNT)["history"]) == 2


def test_restart_replays_log(bench: Path) -> None:
    store = ReviewStore(bench)
    store.edit(MCQ, {"answer": "A", "A": "to the left"}, "ana")
    store.edit(YN, {"answer": "no"}, "ana")
    store.set_dropped(10 + NA, True, "bo")
    store.edit(YN, {"answer": "yes"}, "bo")
    out_bytes = store.out.read_bytes()
    summaries, item = store.summaries(), store.item(MCQ)
    store.out.unlink()

    again = ReviewStore(bench)
    assert again.summaries() == summaries
    assert again.item(MCQ) == item
    assert again.item(YN)["answer"] == "yes" and not again.item(YN)["edited"]
    assert len(again.item(YN)["history"]) == 2
    assert again.out.read_bytes() == out_bytes
    again.edit(COUNT, {"answer": "4"}, "cy")
    assert len(_log_lines(again)) == 5


def test_log_of_another_bench_refused(bench: Path) -> None:
    store = ReviewStore(bench)
    store.edit(MCQ, {"answer": "A"}, "ana")
    entries = _log_lines(store)
    entries[0]["record_id"] = "other/record"
    store.log.write_text(json.dumps(entries[0]) + "\n", encoding="utf-8")
    with pytest.raises(InvalidDataError, match="record_id .* belongs to another bench"):
        ReviewStore(bench)
    entries[0].update(record_id="room/camera_translation/main_dir/0", index=999)
    store.log.write_text(json.dumps(entries[0]) + "\n", encoding="utf-8")
    with pytest.raises(InvalidDataError, match="index 999 is not in"):
        ReviewStore(bench)
    store.log.write_text("{not json\n", encoding="utf-8")
    with pytest.raises(InvalidDataError, match=r"log\.jsonl:1: not a JSON log entry"):
        ReviewStore(bench)


def test_out_paths(bench: Path, tmp_path: Path) -> None:
    with pytest.raises(ParameterError, match="original table"):
        ReviewStore(bench, out=bench / "bench.tsv")
    with pytest.raises(ParameterError, match="original table"):
        ReviewStore(bench / "bench.tsv", out=bench / "." / "bench.tsv")
    store = ReviewStore(bench / "bench.tsv", out=bench / "mine.tsv")
    assert store.out == bench / "mine.tsv" and store.log == bench / "mine.log.jsonl"
    store.edit(COUNT, {"answer": "5"}, "ana")
    assert store.log.is_file() and not (bench / "bench.reviewed.tsv").exists()


def test_geometry_from_scene_index(bench: Path, tmp_path: Path) -> None:
    scenes = tmp_path / "scenes"
    (scenes / "room").mkdir(parents=True)
    geometry = {"distance": 2.0, "camera": [0, 0, 0]}
    records = [  # read with the project's record loader: whole records, as `spacedg qa build` writes them
        qa_record(id="room/camera_object_distance_estimation/distance_exact/2", question_type="camera_object_distance_estimation",
                  sub_question_type="distance_exact", task_group=TaskGroup.CAMERA_OBJECT, answer_type=AnswerType.NA,
                  views=("v0",), question="How far is the chair?", options=(), answer=2.0, geometry=geometry),
        qa_record(id="room/camera_translation/main_dir/9", geometry={"a": 1}),
    ]
    (scenes / "room" / "room.qa.jsonl").write_text("".join(r.to_json() + "\n" for r in records), encoding="utf-8")
    for roots in ([scenes], [scenes / "room"]):
        store = ReviewStore(bench, scenes=roots)
        assert store.item(NA)["geometry"] == geometry
        assert store.item(10 + NA)["geometry"] == geometry  # same record under low_light
        assert store.item(MCQ)["geometry"] is None


def test_geometry_from_a_malformed_scene_index_names_the_line(bench: Path, tmp_path: Path) -> None:
    scenes = tmp_path / "scenes"
    (scenes / "room").mkdir(parents=True)
    (scenes / "room" / "room.qa.jsonl").write_text(qa_record().to_json() + "\n{not json\n", encoding="utf-8")
    store = ReviewStore(bench, scenes=[scenes])
    with pytest.raises(FileFormatError, match=r"room\.qa\.jsonl:2: not a question record"):
        store.item(NA)


def test_geometry_from_bench_jsonl(bench: Path) -> None:
    (bench / "bench.jsonl").write_text(json.dumps({"index": 3, "geometry": {"count": 3}}) + "\n", encoding="utf-8")
    store = ReviewStore(bench)
    assert store.item(COUNT)["geometry"] == {"count": 3}
    assert store.item(MCQ)["geometry"] is None


def test_reviewed_tsv_readers(bench: Path) -> None:
    pandas = pytest.importorskip("pandas")
    store = ReviewStore(bench)
    store.edit(MCQ, {"question": "Where did the camera move?\n\"quoted\"\tand tabbed\nA. left\nB. right\nC. forward\nD. backward"}, "ana")
    store.set_dropped(14, True, "ana")
    loaded = load_bench(store.out)
    assert len(loaded) == 14 and loaded.by_index[MCQ].question.startswith("Where did the camera move?\n\"quoted\"\tand")
    assert loaded.by_index[MCQ].options == ("left", "right", "forward", "backward")
    assert [r.answer_type.value for r in loaded.rows[:5]] == ["MCQ", "YN", "NA", "COUNT", "SIZE_LIST"]
    frame = pandas.read_csv(store.out, sep="\t")
    assert list(frame.columns) == store.header and len(frame) == 14
    assert frame.loc[frame["index"] == MCQ, "question"].item() == loaded.by_index[MCQ].question


def test_concurrent_edits_are_serialised(bench: Path) -> None:
    store = ReviewStore(bench)
    errors: list[BaseException] = []

    def work(i: int) -> None:
        try:
            store.edit(3 + 5 * (i % 3), {"answer": str(i)}, f"r{i}")
        except BaseException as err:  # noqa: BLE001
            errors.append(err)

    threads = [threading.Thread(target=work, args=(i,)) for i in range(12)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors
    entries = _log_lines(store)
    assert len(entries) == 12
    again = ReviewStore(bench)  # replay checks every before value in order
    assert [again.item(i)["answer"] for i in (3, 8, 13)] == [store.item(i)["answer"] for i in (3, 8, 13)]

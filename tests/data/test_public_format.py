"""The exported bench in the public SpaceDG bench's format, checked against the public evaluator's rules.

The public evaluator (``Visionary-Laboratory/SpaceDG``, ``EASI/VLMEvalKit/vlmeval/dataset/spacedg_bench.py``)
is not installable from a package registry, so its rules are transcribed below **from reading its
code** (``infer_eval_task``, ``_QT_WHEN_EMPTY_SQT``, ``_NA_SUB_QUESTION_TYPES``, the ground-truth
readers of each answer type, ``load_data`` and ``dump_image``), independently of
``spacedg.data.public_format``, and every row of a real export of all eleven families is held
against them: each row must route to the same answer type under the public rule as under ours.
"""

from __future__ import annotations

import ast
import json
import os
import shutil
from collections import Counter
from pathlib import Path

import pandas as pd
import pytest

from spacedg.data.dataset import SpaceDGDataset
from spacedg.data.export import export_bench
from spacedg.data.public_format import (
    INTERNAL_ANSWER_TYPES,
    PUBLIC_SUB_TYPES,
    existence_options,
    from_public,
    public_answer_type,
    public_fields,
    to_public,
)
from spacedg.qa.index import QABuildConfig
from spacedg.errors import InvalidDataError
from spacedg.eval import load_bench, route, score
from spacedg.plugins import list_question_families
from spacedg.plugins.specs import AnswerType
from tests.conftest import private_copies

# ------------------------------------------------------------------ the public rules, as read
#: ``_QT_WHEN_EMPTY_SQT``: an empty sub type routes by question type (any other type raises there).
PUBLIC_WHEN_EMPTY = {
    "distance_estimation": "NA", "camera_object_distance_estimation": "NA", "existence_estimation": "MCQ",
    "object_existence_estimation": "MCQ", "object_counting": "COUNT", "size_estimation": "SIZE_LIST",
    "object_bounding_size_estimation": "SIZE_LIST",
}
#: ``_NA_SUB_QUESTION_TYPES``.
PUBLIC_NA_SUBS = {"distance_exact", "bbox_center_distance", "inter_object_distance"}
#: the columns ``load_data`` requires.
PUBLIC_REQUIRED = {"index", "question", "answer", "image_path", "question_type", "sub_question_type", "task_group", "degradation_type"}


def public_eval_task(row: pd.Series) -> str:
    """``infer_eval_task`` as read: the row as pandas loaded it (empty cells are NaN)."""
    qt = str(row["question_type"]).strip()
    sqt = row["sub_question_type"]
    if pd.isna(sqt) or str(sqt).strip() == "":
        if qt not in PUBLIC_WHEN_EMPTY:
            raise ValueError(f"empty sub_question_type with question_type {qt!r}")
        return PUBLIC_WHEN_EMPTY[qt]
    sqt = str(sqt).strip()
    if sqt == "distance_threshold":
        return "YN"
    return "NA" if sqt in PUBLIC_NA_SUBS else "MCQ"


def public_truth_readable(task: str, answer: object) -> bool:
    """Whether the public scorer of ``task`` reads the ground truth ``answer`` (as pandas loaded it)."""
    text = str(answer).strip()
    if task == "MCQ":  # can_match_option(answer): one capital option letter
        return len(text) == 1 and text in "ABCDEF"
    if task == "YN":  # _normalize_yes_no
        return text.lower() in ("yes", "no")
    if task == "NA":  # _parse_gt_numeric: float() after dropping a trailing "m"/"meters"
        return _is_float(text)
    if task == "COUNT":  # _parse_gt_int: int(float(text))
        return _is_float(text) and float(text) == int(float(text))
    value = ast.literal_eval(text)  # SIZE_LIST: _parse_list_floats
    return isinstance(value, list) and len(value) == 3 and all(isinstance(v, (int, float)) for v in value)


def _is_float(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def public_image_file(lmu_data: Path, tsv_dir: Path, rel: str) -> Path | None:
    """``dump_image`` as read: a leading ``images/`` is dropped, then the path is tried under the TSV's
    folder, ``$LMUData``, ``$LMUData/images`` and ``$LMUData/images/spacedg_bench``."""
    rel = rel.replace("\\", "/").removeprefix("images/")
    for base in (tsv_dir, lmu_data, lmu_data / "images", lmu_data / "images" / "spacedg_bench"):
        if (base / rel).is_file():
            return base / rel
    return None


# ------------------------------------------------------------------ one export of every family
ALL = QABuildConfig(seed=3, per_sub_type=2)
SIZE = (32, 24)


@pytest.fixture(scope="module")
def exported(qa_room_dirs, tmp_path_factory):
    rooms = private_copies(qa_room_dirs, tmp_path_factory.mktemp("public_rooms"))
    dataset = SpaceDGDataset("bench", ["low_res"], scenes=rooms, image_size=SIZE, qa_config=ALL)
    out = tmp_path_factory.mktemp("public_bench")
    summary = export_bench(dataset, out, shard_size=64, progress=False)
    assert summary.merged
    return dataset, out, summary


def test_every_exported_row_routes_to_the_same_answer_type_under_the_public_rule(exported):
    dataset, out, summary = exported
    table = pd.read_csv(out / "spacedg_bench.tsv", sep="\t")  # what SpaceDGBench.load_data reads
    assert PUBLIC_REQUIRED <= set(table.columns)
    bench = load_bench(out)
    agree: Counter[str] = Counter()
    for row in table.itertuples(index=False):
        series = pd.Series(row._asdict())
        public = public_eval_task(series)
        ours = bench.by_index[int(row.index)].answer_type.value
        record = dataset.plan(int(row.index)).record
        assert public == ours == route(row.question_type, series["sub_question_type"]).value, (row.question_type, row.sub_question_type)
        assert public == public_answer_type(row.question_type, series["sub_question_type"]).value
        assert public_truth_readable(public, row.answer), (public, row.answer)
        # the record keeps its own type; only existence is rendered as another (YN → lettered options)
        expected = "MCQ" if record.question_type == "object_existence_estimation" else record.answer_type.value
        assert ours == expected
        agree[row.question_type] += 1
    assert sum(agree.values()) == len(table) == len(dataset)
    assert set(agree) == {f.name for f in list_question_families()}  # every family is in the export
    assert summary.merge.mismatches == {}
    assert json.loads((out / "summary.json").read_text())["public_evaluator_mismatches"] == {}


def test_single_view_types_carry_an_empty_sub_type_and_existence_is_lettered(exported):
    dataset, out, _ = exported
    table = pd.read_csv(out / "spacedg_bench.tsv", sep="\t")
    subs = {qt: set(group["sub_question_type"].fillna("")) for qt, group in table.groupby("question_type")}
    assert subs["object_counting"] == subs["object_bounding_size_estimation"] == subs["object_existence_estimation"] == {""}
    assert "" in subs["camera_object_distance_estimation"] and "single_view" not in subs["camera_object_distance_estimation"]
    assert subs["inter_object_distance"] == {"inter_object_distance"}
    existence = table[table["question_type"] == "object_existence_estimation"]
    assert len(existence) > 0
    for row in existence.itertuples():
        record = dataset.plan(row.index).record
        assert record.answer_type is AnswerType.YN  # the record stays yes/no in substance
        assert {row.A, row.B} == {"yes", "no"} and pd.isna(row.C) and pd.isna(row.D)
        assert getattr(row, row.answer) == record.answer  # the answer letter names the record's answer
        assert row.question == f"{record.question}\nA. {row.A}\nB. {row.B}" and row.answer_type == "MCQ"
    # the chat JSONL shows the model exactly the bench's text and answer
    chats = [json.loads(line) for line in (out / "bench.jsonl").read_text().splitlines()]
    for chat, row in zip(chats, table.itertuples()):
        user, assistant = chat["messages"]
        assert user["content"].endswith(row.question) and assistant["content"] == f"<answer>{row.answer}</answer>"
        assert (chat["sub_question_type"] or "") == ("" if pd.isna(row.sub_question_type) else row.sub_question_type)


def test_lmudata_layout_resolves_every_image_as_the_public_class_does(exported, tmp_path):
    _, out, _ = exported
    assert (out / "spacedg_bench.tsv").read_bytes() == (out / "bench.tsv").read_bytes()
    table = pd.read_csv(out / "spacedg_bench.tsv", sep="\t")
    for cell in table["image_path"]:
        paths = ast.literal_eval(cell)  # toliststr
        assert paths and all(public_image_file(out, out, p) == out / p for p in paths)
    # a shared LMUData folder (other benches' TSVs beside it) is read by spacedg eval too
    lmu = tmp_path / "LMUData"
    lmu.mkdir()
    shutil.copy(out / "spacedg_bench.tsv", lmu)
    (lmu / "MMBench_DEV_EN.tsv").write_text("index\tquestion\n0\tq\n")
    (lmu / "images").symlink_to(out / "images")
    assert len(load_bench(lmu)) == len(table)


def test_spacedg_eval_scores_the_true_answers_of_the_export_as_correct(exported):
    _, out, _ = exported
    for row in load_bench(out):
        fields = row.scoring_fields()
        assert score(f"<answer>{row.answer}</answer>", fields).score == 1.0, row.index
        if row.answer_type is AnswerType.MCQ:
            wrong = next(k for k in "AB" if k != row.answer)
            assert score(f"<answer>{wrong}</answer>", fields).score == 0.0


# ------------------------------------------------------------------ the mapping itself
def test_names_map_both_ways_and_routes_agree():
    for (qtype, sub), public in PUBLIC_SUB_TYPES.items():
        assert to_public(qtype, sub) == (qtype, public)
        assert from_public(qtype, public) == (qtype, sub)
        kind = INTERNAL_ANSWER_TYPES[(qtype, sub)]
        assert route(qtype, sub) is kind  # older exports with our internal names keep their answer types
        expected = AnswerType.MCQ if kind is AnswerType.YN else kind  # existence is lettered once exported
        assert route(qtype, public) is expected
        assert public_eval_task(pd.Series({"question_type": qtype, "sub_question_type": public or float("nan")})) == expected.value
    for qtype, sub in (("camera_translation", "main_dir"), ("camera_rotation", "yaw+roll_dual"), ("x", "y")):
        assert to_public(qtype, sub) == from_public(qtype, sub) == (qtype, sub)


@pytest.mark.parametrize(
    ("qtype", "sub"),
    [(q, s) for q in (*PUBLIC_WHEN_EMPTY, "camera_translation", "object_size_comparison", "unknown")
     for s in ("", "distance_threshold", "distance_exact", "bbox_center_distance", "inter_object_distance", "main_dir", "count")],
)
def test_public_answer_type_is_the_public_rule(qtype, sub):
    row = pd.Series({"question_type": qtype, "sub_question_type": sub or float("nan")})
    try:
        expected = public_eval_task(row)
    except ValueError:
        with pytest.raises(InvalidDataError):
            public_answer_type(qtype, sub)
        return
    assert public_answer_type(qtype, sub).value == expected


def test_existence_options_are_seeded_per_record_and_balanced():
    ids = [f"room-{k % 7}/object_existence_estimation/existence/{k:012x}" for k in range(4000)]
    letters = {answer: Counter(existence_options(i, answer)[1] for i in ids) for answer in ("yes", "no")}
    for answer, count in letters.items():
        assert 0.46 <= count["A"] / len(ids) <= 0.54, (answer, count)
    for i in ids[:50]:
        options, letter = existence_options(i, "yes")
        assert options in (("A. yes", "B. no"), ("A. no", "B. yes")) and options[ord(letter) - 65].endswith("yes")
        assert existence_options(i, "no") == (options, "B" if letter == "A" else "A")  # one order per record
    with pytest.raises(InvalidDataError):
        existence_options(ids[0], "maybe")


def test_public_fields_of_a_record_and_of_a_dataset_item_agree(exported):
    dataset, _, _ = exported
    for index in range(0, len(dataset), max(1, len(dataset) // 25)):
        record = dataset.plan(index).record
        item = {**{k: getattr(record, k) for k in ("question", "options", "answer", "question_type", "sub_question_type")},
                "answer_type": record.answer_type.value, "record_id": record.id}
        assert public_fields(record) == public_fields(item)


def test_an_old_format_export_folder_is_not_resumed(exported, tmp_path):
    dataset, out, _ = exported
    copy = tmp_path / "old"
    shutil.copytree(out, copy)
    manifest = json.loads((copy / "parts" / "manifest.json").read_text())
    (copy / "parts" / "manifest.json").write_text(json.dumps({**manifest, "version": 1}))
    with pytest.raises(Exception, match="format version 1"):
        export_bench(dataset, copy, shard_size=64, progress=False)
    assert os.path.exists(copy / "bench.tsv")


def test_rows_the_public_evaluator_would_route_differently_are_reported(exported, tmp_path):
    """A third-party family's names the public table does not know (e.g. a YN family with sub type
    "pair", as in the README's plugin example) are reported by the merge, not silently exported."""
    from spacedg.data.export import merge_parts
    from spacedg.data.public_format import public_mismatch

    assert public_mismatch({"question_type": "camera_closer", "sub_question_type": "pair", "answer_type": "YN"})
    assert public_mismatch({"question_type": "object_counting", "sub_question_type": "", "answer_type": "COUNT"}) is None
    assert "empty" in public_mismatch({"question_type": "camera_closer", "sub_question_type": "", "answer_type": "NA"})
    _, out, _ = exported
    copy = tmp_path / "edited"
    shutil.copytree(out, copy)
    part = copy / "parts" / "part-00000.jsonl"
    lines = [json.loads(line) for line in part.read_text().splitlines()]
    lines[0].update(question_type="camera_closer", sub_question_type="pair", answer_type="YN")
    part.write_text("".join(json.dumps(line) + "\n" for line in lines))
    result = merge_parts(copy)
    assert list(result.mismatches) == ["camera_closer/pair"] and "MCQ" in result.mismatches["camera_closer/pair"]
    assert json.loads((copy / "summary.json").read_text())["public_evaluator_mismatches"] == result.mismatches

"""`spacedg export`: images + VLMEvalKit TSV + chat JSONL, resumable, sharded, bad scenes named."""

from __future__ import annotations

import ast
import json
import shutil

import cv2
import pandas as pd
import pytest

from spacedg.cli import main
from spacedg.data.dataset import CLEAN, SpaceDGDataset
from spacedg.data.export import TSV_COLUMNS, chunk_ids, export_split, parse_shard
from spacedg.data.pipeline import BENCH_DEGRADATIONS
from spacedg.data.qa_index import QABuildConfig
from spacedg.errors import ParameterError

CONFIG = QABuildConfig(per_sub_type=1, families=("object_counting", "camera_translation", "object_size_comparison"))
SIZE = (64, 48)
REQUIRED = ["index", "question", "answer", "image_path", "question_type", "sub_question_type", "task_group", "degradation_type"]


@pytest.fixture(scope="module")
def rooms(qa_room_dirs, tmp_path_factory):
    root = tmp_path_factory.mktemp("export_rooms")
    for d in qa_room_dirs:
        shutil.copytree(d, root / d.name, ignore=shutil.ignore_patterns("*.qa.*"))
    return sorted(root.iterdir())


@pytest.fixture(scope="module")
def bench(rooms):
    return SpaceDGDataset("bench", scenes=rooms, image_size=SIZE, qa_config=CONFIG)


@pytest.fixture(scope="module")
def exported(bench, tmp_path_factory):
    out = tmp_path_factory.mktemp("bench_export")
    summary = export_split(bench, out, chunk_size=7, progress=False)
    return out, summary


def test_tsv_loads_with_pandas_and_matches_the_dataset(bench, exported):
    out, summary = exported
    assert summary.merged and summary.items_written == len(bench) == len(bench.records) * 10
    table = pd.read_csv(out / "bench.tsv", sep="\t", keep_default_na=False)
    assert list(table.columns) == list(TSV_COLUMNS) and set(REQUIRED) <= set(table.columns)
    assert len(table) == len(bench) and table["index"].tolist() == list(range(len(bench)))
    assert set(table["degradation_type"]) == {CLEAN, *BENCH_DEGRADATIONS}
    for row in table.itertuples():
        record, _, name = bench.plan(row.index)
        assert row.degradation_type == name and row.record_id == record.id and row.question_type == record.question_type
        expected = "[" + ", ".join(f"{v:.2f}" for v in record.answer) + "]" if isinstance(record.answer, tuple) else str(record.answer)
        assert str(row.answer) == expected or float(row.answer) == pytest.approx(float(expected))
        paths = ast.literal_eval(row.image_path)
        assert len(paths) == len(record.views)
        for p in paths:
            image = cv2.imread(str(out / p))
            assert image is not None and image.shape == (SIZE[1], SIZE[0], 3)
        if record.options:
            assert row.question.endswith("\n".join(record.options)) and row.A == record.options[0][3:]
    counts = json.loads((out / "summary.json").read_text())["counts"]
    assert sum(sum(row.values()) for row in counts.values()) == len(bench)


def test_exported_images_equal_the_dataset_items(bench, exported):
    out, _ = exported
    for index in (0, 5, len(bench) - 1):
        item = bench[index]
        for v, image in enumerate(item["images"]):
            saved = cv2.imread(str(out / f"images/{index:07d}_{v}.png"))[:, :, ::-1]
            assert (saved == image.permute(1, 2, 0).numpy()).all()


def test_chat_jsonl(bench, exported):
    out, _ = exported
    rows = [json.loads(line) for line in (out / "bench.jsonl").read_text().splitlines()]
    assert len(rows) == len(bench)
    for row in rows[:30]:
        user, assistant = row["messages"]
        assert user["content"].count("<image>") == len(row["images"]) and user["role"] == "user"
        assert assistant["content"].startswith("<answer>") and assistant["content"].endswith("</answer>")
        assert "<answer>" in row["system"]


def test_shards_are_disjoint_complete_and_resumable(bench, exported, tmp_path):
    out = tmp_path / "sharded"
    first = export_split(bench, out, shard=(0, 2), chunk_size=7, progress=False)
    assert not first.merged and not (out / "bench.tsv").exists()
    second = export_split(bench, out, shard=(1, 2), chunk_size=7, progress=False)
    assert second.merged and set(first.chunks_written).isdisjoint(second.chunks_written)
    assert sorted(first.chunks_written + second.chunks_written) == list(range(first.chunks_total))
    assert (out / "bench.tsv").read_bytes() == (exported[0] / "bench.tsv").read_bytes()
    # an interrupted run: a chunk's parts are missing → only that chunk is redone, no duplicates
    (out / "parts" / "part-00002.tsv").unlink()
    again = export_split(bench, out, chunk_size=7, progress=False)
    assert again.chunks_written == [2] and again.merged
    table = pd.read_csv(out / "bench.tsv", sep="\t")
    assert table["index"].is_unique and len(table) == len(bench)
    assert chunk_ids(20, 7, (1, 2)) == [1] and chunk_ids(20, 7) == [0, 1, 2]


@pytest.mark.parametrize("text", ["2/2", "x", "1/0", "-1/3", "1"])
def test_bad_shard(text):
    with pytest.raises(ParameterError, match="shard"):
        parse_shard(text)


def test_cli_export_and_bad_scene(rooms, tmp_path, capsys):
    out = tmp_path / "cli"
    argv = ["export", "--split", "bench", "--out", str(out), "--scenes", *map(str, rooms), "--image-size", "64x48",
            "--per-sub-type", "1", "--question-types", "object_counting", "--chunk-size", "50"]
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "bench.tsv" in text and "| object_counting |" in text
    assert main(argv) == 0 and "skipped 1 finished" in capsys.readouterr().out  # a rerun does nothing
    assert main([*argv[:4], str(tmp_path / "x"), "--shard", "3/2"]) == 2
    assert "shard" in capsys.readouterr().err
    # a corrupted scene is named; with --skip-bad-scenes the others still export
    broken = tmp_path / "broken_rooms"
    shutil.copytree(rooms[0].parent, broken)
    bad = sorted(broken.iterdir())[1]
    (bad / "scene.json").write_text("{ not json")
    argv_broken = ["export", "--split", "train", "--out", str(tmp_path / "b"), "--scenes", str(broken), "--image-size", "64x48",
                   "--per-sub-type", "1", "--question-types", "object_counting", "--clean-prob", "1"]
    assert main(argv_broken) == 2
    assert str(bad) in capsys.readouterr().err
    with pytest.warns(UserWarning, match=str(bad)):
        assert main([*argv_broken, "--skip-bad-scenes"]) == 0
    assert f"skipped scene {bad}" in capsys.readouterr().out
    assert len(pd.read_csv(tmp_path / "b" / "train.tsv", sep="\t")) > 0


def test_max_questions_spreads_over_types(rooms):
    full = SpaceDGDataset("train", scenes=rooms, image_size=SIZE, qa_config=CONFIG)
    small = SpaceDGDataset("train", scenes=rooms, image_size=SIZE, qa_config=CONFIG, max_questions=6)
    assert len(small) == 6 and {r.question_type for r in small.records} == {r.question_type for r in full.records}
    assert [r.id for r in small.records] == [r.id for r in full.records if r in set(small.records)]  # original order
    with pytest.raises(ParameterError, match="max_questions"):
        SpaceDGDataset("train", scenes=rooms, image_size=SIZE, qa_config=CONFIG, max_questions=0)

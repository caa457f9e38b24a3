"""`spacedg export`: images + VLMEvalKit TSV + chat JSONL, resumable, sharded, bad scenes named."""

from __future__ import annotations

import ast
import io
import json
import shutil

import cv2
import pandas as pd
import pytest

import spacedg.data.export as export_module
from spacedg.cli import main
from spacedg.data.answerability import named_objects
from spacedg.data.chain import CLEAN
from spacedg.data.dataset import SpaceDGDataset
from spacedg.data.bench_table import TSV_COLUMNS, tsv_bytes
from spacedg.data.export import (
    chunk_ids,
    export_bench,
    merge_parts,
    parse_shard,
    shard_from_env,
)
from spacedg.data.chain import BENCH_DEGRADATIONS
from spacedg.data.public_format import to_public
from spacedg.qa.index import QABuildConfig, read_index
from spacedg.errors import InvalidDataError, ParameterError
from tests.conftest import private_copies

CONFIG = QABuildConfig(seed=0, per_sub_type=1, families=("object_counting", "camera_translation", "object_size_comparison"))
SIZE = (64, 48)
REQUIRED = ["index", "question", "answer", "image_path", "question_type", "sub_question_type", "task_group", "degradation_type"]


@pytest.fixture(scope="module")
def rooms(qa_room_dirs, tmp_path_factory):
    """A private copy of the four session rooms (this module's indexes do not touch the originals)."""
    return private_copies(qa_room_dirs, tmp_path_factory.mktemp("export_rooms"))


@pytest.fixture(scope="module")
def bench(rooms):
    return SpaceDGDataset("bench", scenes=rooms, image_size=SIZE, qa_config=CONFIG)


@pytest.fixture(scope="module")
def exported(bench, tmp_path_factory):
    out = tmp_path_factory.mktemp("bench_export")
    summary = export_bench(bench, out, shard_size=7, progress=False)
    return out, summary


def _tree(out):
    """Bytes of every exported file (temporary files of atomic writes would show up here too)."""
    return {p.relative_to(out).as_posix(): p.read_bytes() for p in sorted(out.rglob("*")) if p.is_file()}


# ------------------------------------------------------------------ formats
def test_tsv_loads_with_pandas_and_matches_the_dataset(bench, exported):
    out, summary = exported
    assert summary.merged and summary.items_written == len(bench) == len(bench.records) * 10
    assert summary.chunks_written == list(range(summary.chunks_total)) and not summary.chunks_skipped
    table = pd.read_csv(out / "bench.tsv", sep="\t")  # exactly what VLMEvalKit's load() does
    assert list(table.columns) == list(TSV_COLUMNS) and set(REQUIRED) <= set(table.columns)
    assert len(table) == len(bench) and table["index"].tolist() == list(range(len(bench)))
    assert table["index"].dtype.kind == "i"
    assert set(table["degradation_type"]) == {CLEAN, *BENCH_DEGRADATIONS}
    for row in table.itertuples():
        plan = bench.plan(row.index)
        record, name = plan.record, plan.degradation_type
        assert row.degradation_type == name and row.record_id == record.id and row.question_type == record.question_type
        public_sub = to_public(record.question_type, record.sub_question_type)[1]  # "" for counting: pandas reads NaN
        assert (pd.isna(row.sub_question_type) and public_sub == "") or row.sub_question_type == public_sub
        assert row.task_group == record.task_group.value
        expected = "[" + ", ".join(f"{v:.2f}" for v in record.answer) + "]" if isinstance(record.answer, tuple) else str(record.answer)
        assert str(row.answer) == expected or float(row.answer) == pytest.approx(float(expected))
        provenance = json.loads(row.degradation)  # the chain's steps, as JSON; [] for clean
        assert [step["name"] for step in provenance] == ([] if name == CLEAN else name.split("+"))
        paths = ast.literal_eval(row.image_path)
        assert len(paths) == len(record.views) and all(not p.startswith("/") for p in paths)
        for p in paths:
            image = cv2.imread(str(out / p), cv2.IMREAD_UNCHANGED)
            assert image is not None and image.shape == (SIZE[1], SIZE[0], 3) and image.dtype == "uint8"
        if record.options:
            assert row.question == record.question + "\n" + "\n".join(record.options)
            assert [row.A, row.B] == [record.options[0][3:], record.options[1][3:]]
        else:
            assert row.question == record.question and pd.isna(row.A)
    counts = json.loads((out / "summary.json").read_text())
    assert sum(sum(row.values()) for row in counts["counts"].values()) == len(bench) == counts["items"]
    assert counts["by_degradation"][CLEAN] == len(bench.records)
    assert "| total |" in summary.merge.table and CLEAN in summary.merge.table.splitlines()[0]


def test_summary_keeps_answerability_per_item(bench, exported):
    """summary.json: the share per degradation × severity and, per item, each named object's contrast."""
    out, summary = exported
    block = json.loads((out / "summary.json").read_text())["answerability"]
    assert block["criterion"] == {"weber_threshold": 0.02, "viewing_flare": 0.01, "rose_k": 5.0}
    assert set(block["by_condition"]) == {CLEAN, *BENCH_DEGRADATIONS} and set(block["by_condition"][CLEAN]) == {"-"}
    assert all(set(row) == {"bench"} for name, row in block["by_condition"].items() if name != CLEAN)
    assert len(block["items"]) == len(bench) and summary.merge.answerability == block["by_condition"]
    for index, item in block["items"].items():
        plan = bench.plan(int(index))
        named = {i for _, ids in named_objects(plan.record) for i in ids}
        assert item["degradation_type"] == plan.degradation_type and item["groups"] == len(named_objects(plan.record))
        assert {o["id"] for o in item["objects"]} == named
        assert item["answerable"] == all(any(o["discernible"] for o in item["objects"] if o["id"] in ids) for _, ids in named_objects(plan.record))
    assert "| ori |" in summary.merge.answerability_table


def test_tsv_quoting_survives_quotes_tabs_and_newlines():
    tricky = 'He said "3"\tthen\nleft; \'quoted\' and "a\r\nb"'
    row = dict.fromkeys(TSV_COLUMNS, "")
    row.update(index=7, question=tricky, answer="NA-like", image_path=repr(["images/0000007_0.png"]), A='"x"')
    table = pd.read_csv(io.BytesIO(tsv_bytes([row, {**row, "index": 8}], header=True)), sep="\t", keep_default_na=False)
    assert len(table) == 2 and table["question"].tolist() == [tricky, tricky] and table["A"][0] == '"x"'
    assert ast.literal_eval(table["image_path"][0]) == ["images/0000007_0.png"]


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
    assert len(rows) == len(bench) and [r["index"] for r in rows] == list(range(len(bench)))
    table = pd.read_csv(out / "bench.tsv", sep="\t")
    for row, tsv in zip(rows, table.itertuples()):
        user, assistant = row["messages"]
        assert user["role"] == "user" and assistant["role"] == "assistant"
        assert user["content"].count("<image>") == len(row["images"]) == len(ast.literal_eval(tsv.image_path))
        assert user["content"] == "<image>" * len(row["images"]) + tsv.question
        assert assistant["content"] == f"<answer>{tsv.answer}</answer>" or float(assistant["content"][8:-9]) == pytest.approx(float(tsv.answer))
        assert row["images"] == ast.literal_eval(tsv.image_path) and row["degradation_type"] == tsv.degradation_type
        assert "<answer>" in row["system"]
        assert row["geometry"] == bench.plan(row["index"]).record.geometry  # the audit block travels with the bench
    from spacedg.review import ReviewStore

    store = ReviewStore(out, out=out.parent / "reviewed.tsv")  # the review page shows it without --scenes
    assert store.item(0)["geometry"] == rows[0]["geometry"]


# ------------------------------------------------------------------ shards and resume
def test_shards_are_disjoint_complete_and_byte_identical(bench, exported, tmp_path):
    out = tmp_path / "sharded"
    first = export_bench(bench, out, shard=(0, 3), shard_size=7, progress=False)
    assert not first.merged and not (out / "bench.tsv").exists() and first.merge.missing
    second = export_bench(bench, out, shard=(2, 3), shard_size=7, progress=False)
    third = export_bench(bench, out, shard=(1, 3), shard_size=7, progress=False)
    written = [first.chunks_written, second.chunks_written, third.chunks_written]
    assert third.merged and sum(map(len, written)) == len(set().union(*written)) == first.chunks_total
    assert all(k % 3 == i for i, ks in zip((0, 2, 1), written) for k in ks)
    assert _tree(out) == _tree(exported[0])  # deterministic: sharded = one process, byte for byte
    assert chunk_ids(20, 7, (1, 2)) == [1] and chunk_ids(20, 7) == [0, 1, 2]
    for n in (1, 2, 5):
        parts = [chunk_ids(100, 9, (i, n)) for i in range(n)]
        assert sorted(k for p in parts for k in p) == list(range(12))


def test_interrupted_export_resumes_without_duplicates(bench, exported, tmp_path, monkeypatch):
    out = tmp_path / "interrupted"
    real, calls = export_module.write_png, []

    def crash_after_25(path, image, what, **kwargs):
        calls.append(path)
        if len(calls) > 25:
            raise KeyboardInterrupt("killed")
        real(path, image, what, **kwargs)

    monkeypatch.setattr(export_module, "write_png", crash_after_25)
    with pytest.raises(KeyboardInterrupt):
        export_bench(bench, out, shard_size=7, progress=False)
    monkeypatch.setattr(export_module, "write_png", real)
    done = sorted(p.name for p in (out / "parts").glob("part-*"))
    assert done and not (out / "bench.tsv").exists() and not list(out.rglob(".*.tmp"))
    resumed = export_bench(bench, out, shard_size=7, progress=False)
    assert resumed.merged and resumed.chunks_skipped == list(range(len(done) // 2))
    table = pd.read_csv(out / "bench.tsv", sep="\t")
    assert table["index"].is_unique and len(table) == len(bench)
    assert _tree(out) == _tree(exported[0])
    # a lost part: only its chunk is rebuilt
    (out / "parts" / "part-00002.tsv").unlink()
    again = export_bench(bench, out, shard_size=7, progress=False)
    assert again.chunks_written == [2] and again.merged and _tree(out) == _tree(exported[0])
    # nothing left: a rerun only merges
    assert export_bench(bench, out, shard_size=7, progress=False).items_written == 0


def test_a_killed_exports_temp_files_are_removed_by_the_rerun(bench, exported, tmp_path):
    """The finding: `images/.NNN.png.*.tmp` of a killed export stayed forever. A rerun removes
    the temporary files of each chunk it redoes (and only files of that exact pattern)."""
    out = tmp_path / "killed"
    shutil.copytree(exported[0], out)
    for part in (out / "parts").glob("part-00001.*"):  # chunk 1 (indices 7-13) was being written when killed
        part.unlink()
    stale = [out / "images" / ".0000008_0.png.k1ll3d_x.tmp", out / "parts" / ".part-00001.tsv.a8c_d2zz.tmp",
             out / "parts" / ".part-00001.jsonl.00000000.tmp"]
    kept = [out / "images" / ".0000008_0.png.tmp", out / "images" / "notes.tmp", out / "parts" / ".part-00001.tsv.NOTOURS.tmp"]
    for path in stale + kept:
        path.write_bytes(b"half")
    summary = export_bench(bench, out, shard_size=7, progress=False)
    assert summary.chunks_written == [1] and summary.merged
    assert not any(p.exists() for p in stale) and all(p.exists() for p in kept)
    for path in kept:
        path.unlink()
    assert _tree(out) == _tree(exported[0])


def test_other_settings_in_the_same_folder_are_refused(bench, rooms, exported, tmp_path):
    out = tmp_path / "mixed"
    export_bench(bench, out, shard=(0, 2), shard_size=7, progress=False)
    with pytest.raises(ParameterError, match="shard_size"):
        export_bench(bench, out, shard=(1, 2), shard_size=8, progress=False)
    other = SpaceDGDataset("bench", ["haze"], scenes=rooms, image_size=SIZE, qa_config=CONFIG)
    with pytest.raises(ParameterError, match="other settings"):
        export_bench(other, out, shard=(1, 2), shard_size=7, progress=False)
    assert not merge_parts(out) and merge_parts(out).missing
    with pytest.raises(ParameterError, match="manifest"):
        merge_parts(tmp_path / "nothing")


@pytest.mark.parametrize("text", ["2/2", "3/2", "x", "1/0", "-1/3", "1", "1/2/3", "a/b"])
def test_bad_shard(text):
    with pytest.raises(ParameterError, match="shard"):
        parse_shard(text)


def test_shard_from_launcher_environment():
    assert parse_shard("1/4") == (1, 4)
    assert shard_from_env({"RANK": "3", "WORLD_SIZE": "8"}) == (3, 8)
    assert shard_from_env({"SLURM_ARRAY_TASK_ID": "5", "SLURM_ARRAY_TASK_COUNT": "4", "SLURM_ARRAY_TASK_MIN": "2"}) == (3, 4)
    assert shard_from_env({"SLURM_PROCID": "0", "SLURM_NTASKS": "2"}) == (0, 2)
    with pytest.raises(ParameterError, match="RANK"):
        shard_from_env({})
    with pytest.raises(ParameterError, match="shard"):
        shard_from_env({"RANK": "8", "WORLD_SIZE": "8"})


def test_shard_from_a_launcher_half_configured_or_a_stepped_array():
    """A job array with a step (``--array=0-15:4``: ids 0, 4, 8, 12) is shards 0/4 … 3/4; one variable of a
    pair set alone names the other; a later launcher's whole pair still decides; an id off the steps, ids
    not evenly spaced (a resubmission of some tasks, which would otherwise read another split), a value that
    is not an integer and n < 1 are errors that say so."""
    array = {"SLURM_ARRAY_TASK_COUNT": "4", "SLURM_ARRAY_TASK_MIN": "0", "SLURM_ARRAY_TASK_STEP": "4"}
    assert [shard_from_env({**array, "SLURM_ARRAY_TASK_ID": str(t)}) for t in (0, 4, 8, 12)] == [(0, 4), (1, 4), (2, 4), (3, 4)]
    assert shard_from_env({"SLURM_ARRAY_TASK_ID": "7", "SLURM_ARRAY_TASK_COUNT": "3", "SLURM_ARRAY_TASK_MIN": "3",
                           "SLURM_ARRAY_TASK_STEP": "2"}) == (2, 3)
    with pytest.raises(ParameterError, match="not evenly spaced"):
        shard_from_env({**array, "SLURM_ARRAY_TASK_ID": "6"})
    resubmitted = {"SLURM_ARRAY_TASK_COUNT": "2", "SLURM_ARRAY_TASK_MIN": "5", "SLURM_ARRAY_TASK_MAX": "17"}  # --array=5,17
    for task in ("5", "17"):
        with pytest.raises(ParameterError, match=r"resubmission .*--shard \$\{SLURM_ARRAY_TASK_ID\}/32"):
            shard_from_env({**resubmitted, "SLURM_ARRAY_TASK_ID": task})
    assert shard_from_env({**array, "SLURM_ARRAY_TASK_MAX": "12", "SLURM_ARRAY_TASK_ID": "8"}) == (2, 4)
    with pytest.raises(ParameterError, match="RANK is set but WORLD_SIZE is not"):
        shard_from_env({"RANK": "1"})
    with pytest.raises(ParameterError, match="SLURM_ARRAY_TASK_ID is set but SLURM_ARRAY_TASK_COUNT is not"):
        shard_from_env({"SLURM_ARRAY_TASK_ID": "1"})
    assert shard_from_env({"RANK": "1", "SLURM_PROCID": "1", "SLURM_NTASKS": "3"}) == (1, 3)
    with pytest.raises(ParameterError, match="WORLD_SIZE='eight' is not an integer"):
        shard_from_env({"RANK": "1", "WORLD_SIZE": "eight"})
    with pytest.raises(ParameterError, match="at least 1"):
        parse_shard("0/0")


# ------------------------------------------------------------------ bad scenes
def test_a_scene_corrupted_after_indexing_is_named(bench, rooms, tmp_path):
    copy = tmp_path / "rooms"
    shutil.copytree(rooms[0].parent, copy)  # with the question indexes: nothing is rebuilt
    dataset = SpaceDGDataset("bench", scenes=[copy], image_size=SIZE, qa_config=CONFIG)
    folder = dataset.scene_dirs[dataset.records[0].scene_id]
    ply = folder / "gaussians.ply"
    ply.write_bytes(ply.read_bytes()[: ply.stat().st_size // 3])  # truncated
    with pytest.raises(InvalidDataError, match=str(folder)) as caught:
        export_bench(dataset, tmp_path / "out", shard_size=7, progress=False)
    assert "item 0" in str(caught.value) and "gaussians.ply" in str(caught.value)
    assert not list((tmp_path / "out" / "parts").glob("part-*"))


# ------------------------------------------------------------------ CLI
def test_cli_export_and_bad_scene(rooms, tmp_path, capsys, monkeypatch):
    out = tmp_path / "cli"
    argv = ["export", "--split", "bench", "--out", str(out), "--scenes", *map(str, rooms), "--image-size", "64x48",
            "--per-sub-type", "1", "--question-types", "object_counting", "--shard-size", "50", "--no-progress", "--no-debias"]
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "bench.tsv" in text and "| object_counting |" in text and "| total |" in text
    assert "answerability: share of items" in text and "| ori | " in text  # the bench split measures it by default
    assert len(pd.read_csv(out / "bench.tsv", sep="\t")) == sum(json.loads((out / "summary.json").read_text())["by_question_type"].values())
    assert main(argv) == 0 and "wrote 0 chunk(s)" in capsys.readouterr().out  # a rerun does nothing
    monkeypatch.setenv("RANK", "0")
    monkeypatch.setenv("WORLD_SIZE", "1")
    assert main([*argv, "--shard", "env"]) == 0 and "shard 0/1" in capsys.readouterr().out
    for bad in ("3/2", "x"):
        assert main([*argv[:4], str(tmp_path / "x"), "--shard", bad]) == 2
        assert "shard" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()  # refused before any work
    # a corrupted scene is named; with --skip-bad-scenes the others still export
    broken = tmp_path / "broken_rooms"
    shutil.copytree(rooms[0].parent, broken)
    bad = sorted(broken.iterdir())[1]
    (bad / "scene.json").write_text("{ not json")
    argv_broken = ["export", "--split", "train", "--out", str(tmp_path / "b"), "--scenes", str(broken), "--image-size", "64x48",
                   "--per-sub-type", "1", "--question-types", "object_counting", "--clean-prob", "1", "--no-progress"]
    assert main(argv_broken) == 2
    err = capsys.readouterr().err
    assert str(bad) in err and "skip" in err
    with pytest.warns(UserWarning, match=str(bad)):
        assert main([*argv_broken, "--skip-bad-scenes"]) == 0
    assert f"skipped scene {bad}" in capsys.readouterr().out
    table = pd.read_csv(tmp_path / "b" / "train.tsv", sep="\t")
    assert len(table) > 0 and set(table["degradation_type"]) == {CLEAN} and bad.name not in set(table["scene_id"])


def test_max_questions_spreads_over_types(rooms):
    full = SpaceDGDataset("train", scenes=rooms, image_size=SIZE, qa_config=CONFIG)
    small = SpaceDGDataset("train", scenes=rooms, image_size=SIZE, qa_config=CONFIG, max_questions=6)
    assert len(small) == 6 and {r.question_type for r in small.records} == {r.question_type for r in full.records}
    assert [r.id for r in small.records] == [r.id for r in full.records if r in set(small.records)]  # original order
    with pytest.raises(ParameterError, match="max_questions"):
        SpaceDGDataset("train", scenes=rooms, image_size=SIZE, qa_config=CONFIG, max_questions=0)


def test_cli_bench_debias_prunes_and_no_debias_skips_it(indexed_room_dirs, tmp_path, capsys):
    # --oversample 1: the candidates are indexes at per sub type 25 with partial rounds (<id>.qa-pooled.jsonl)
    rooms = private_copies(indexed_room_dirs, tmp_path / "rooms", indexes=True)
    common = ["export", "--split", "bench", "--all-bench", "--scenes", *map(str, rooms), "--image-size", "64x48",
              "--families", "camera_object_relative_direction,object_existence_estimation", "--degradations", "haze",
              "--max-questions", "40", "--shard-size", "64", "--no-progress"]
    assert main([*common, "--out", str(tmp_path / "plain"), "--no-debias"]) == 0
    assert "Blind pruning" not in capsys.readouterr().out and not (tmp_path / "plain" / "debias.json").exists()
    assert main([*common, "--out", str(tmp_path / "debiased"), "--oversample", "1"]) == 0  # on by default
    text = capsys.readouterr().out
    assert "Blind pruning" in text and "| object_existence_estimation | existence |" in text and "round 1" in text
    plain = pd.read_csv(tmp_path / "plain" / "bench.tsv", sep="\t")
    debiased = pd.read_csv(tmp_path / "debiased" / "bench.tsv", sep="\t")
    report = json.loads((tmp_path / "debiased" / "debias.json").read_text())
    # the candidates: the indexes at --per-sub-type x 1 with partial rounds, files of their own beside the strict bench
    # indexes (which stay as they were), all kept before the pruning trims to --max-questions
    assert all(len(list(room.glob("*.qa-pooled.jsonl"))) == 1 for room in rooms)
    assert all("partial_rounds" not in json.loads(next(room.glob("*.qa.meta.json")).read_text())["config"] for room in rooms)
    candidates = {r.id for room in rooms for path in room.glob("*.qa-pooled.jsonl") for r in read_index(path)}
    assert set(debiased["record_id"]) < candidates and 30 <= debiased["record_id"].nunique() <= 40 == plain["record_id"].nunique()
    assert report["kept"] == debiased["record_id"].nunique() and sum(report["removed"].values()) > 0
    assert "before the probe, roles balanced per cell across scenes" in text and sum(report["balanced"].values()) > 0
    for row in report["after"]["rows"]:
        name = f"{row['question_type']}/{row['sub_question_type']}"
        assert name not in report["eligible"] or row["excess"] <= row["allowed"] or row["n"] <= 0.5 * report["targets"][name] + 1
        assert row["allowed"] >= report["bound"]  # the bound, or the sub type's noise band where wider
    # every record keeps all its degradations: the degradation balance is untouched
    assert set(debiased.groupby("record_id").size()) == {2} and (tmp_path / "debiased" / "debias.md").is_file()
    assert main([*common, "--out", str(tmp_path / "debiased"), "--debias", "--oversample", "1"]) == 0  # deterministic: same manifest
    assert "wrote 0 chunk(s)" in capsys.readouterr().out
    assert main([*common, "--out", str(tmp_path / "x"), "--no-debias", "--oversample", "2"]) == 2
    assert "--oversample" in capsys.readouterr().err
    one = [a for a in common if a not in map(str, rooms[1:])]  # a bench of one scene: nothing to hold out, no pruning
    assert main([*one, "--out", str(tmp_path / "x"), "--oversample", "2"]) == 2
    assert "fewer than 2 scenes" in capsys.readouterr().err

"""`spacedg predict` end to end with real tiny transformers VLMs built in code.

The bench is a real export (`export_bench`) of small rooms; the models are real
Qwen2.5-VL / InternVL classes with tiny random weights, saved and reloaded from disk. Their
answers are noise, but batching, resuming, the prompt variants, the online dataset source
and scoring the output are all exercised for real.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from spacedg.cli import main
from spacedg.data.chat import chat_collate
from spacedg.data.dataset import SpaceDGDataset
from spacedg.data.export import export_bench
from spacedg.qa.index import QABuildConfig
from spacedg.errors import InvalidDataError, ParameterError
from spacedg.eval.bench import load_bench
from spacedg.eval.predict import bench_source, dataset_source, predict
from spacedg.eval.predictions import meta_path, read_predictions
from spacedg.eval.prompts import conversation, degradation_info, parse_degradation_guess
from spacedg.eval.report import build_report
from spacedg.vlm import encode_chats, load_vlm, save_tiny_vlm
from tests.conftest import private_copies

CONFIG = QABuildConfig(seed=0, per_sub_type=1, families=("object_counting", "camera_translation", "object_existence_estimation"))
SIZE = (64, 48)
DEGRADATIONS = ["haze", "low_res"]


@pytest.fixture(scope="module")
def rooms(qa_room_dirs, tmp_path_factory) -> list[Path]:
    return private_copies(qa_room_dirs, tmp_path_factory.mktemp("predict_rooms"))


def _dataset(rooms: list[Path]) -> SpaceDGDataset:
    return SpaceDGDataset("bench", DEGRADATIONS, scenes=rooms, image_size=SIZE, qa_config=CONFIG, max_questions=6)


@pytest.fixture(scope="module")
def bench_dir(rooms, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("predict_bench")
    export_bench(_dataset(rooms), out, progress=False)
    return out


@pytest.fixture(scope="module")
def model_dir(tmp_path_factory) -> Path:
    return save_tiny_vlm(tmp_path_factory.mktemp("tiny") / "tiny-qwen2.5-vl", "qwen2_5_vl")


@pytest.fixture(scope="module")
def vlm(model_dir):
    return load_vlm(model_dir)


def _lines(path: Path) -> list[dict]:
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


def test_predict_default_batched_equals_one_by_one(bench_dir, model_dir, vlm, tmp_path) -> None:
    bench = load_bench(bench_dir)
    n = len(bench)
    assert n == 3 * len({r.record_id for r in bench}) >= 12  # each question under clean, haze, low_res
    batched = predict(model_dir, bench_source(bench), tmp_path / "b.jsonl", batch_size=5, progress=False)
    single = predict(vlm, bench_source(bench), tmp_path / "s.jsonl", batch_size=1, progress=False, model_name="tiny-qwen2.5-vl")
    assert (batched.answered, batched.generated, single.answered) == (n, n, n)
    a, b = _lines(tmp_path / "b.jsonl"), _lines(tmp_path / "s.jsonl")
    assert [x["index"] for x in a] == [r.index for r in bench]
    assert [x["prediction"] for x in a] == [x["prediction"] for x in b]
    assert all(x["model"] == "tiny-qwen2.5-vl" and x["variant"] == "default" for x in a)
    meta = json.loads(meta_path(tmp_path / "b.jsonl").read_text())
    assert meta["bench_fingerprint"] == bench.fingerprint and meta["variant"] == "default"
    assert "<answer></answer>" in meta["prompts"]["answer_prompt"]
    # the file scores on its own (it carries the rows) and against the bench, to the same numbers
    alone = build_report([read_predictions(tmp_path / "b.jsonl")])
    against = build_report([read_predictions(tmp_path / "b.jsonl")], bench)
    assert alone.overall("tiny-qwen2.5-vl") == against.overall("tiny-qwen2.5-vl")
    assert against.conditions == ["ori", "haze", "low_res"]


def test_predict_resumes_and_survives_a_torn_line(bench_dir, vlm, tmp_path) -> None:
    source = bench_source(load_bench(bench_dir))
    n = len(source.indices)
    out = tmp_path / "p.jsonl"
    first = predict(vlm, source, out, batch_size=4, limit=7, progress=False)
    assert (first.answered, first.skipped) == (7, 0)
    with out.open("ab") as handle:
        handle.write(b'{"index": 99, "predic')  # a crash in the middle of a write
    second = predict(vlm, source, out, batch_size=4, progress=False)
    assert (second.skipped, second.answered) == (7, n - 7)
    third = predict(vlm, source, out, batch_size=4, progress=False)
    assert (third.answered, third.generated) == (0, 0)
    once = predict(vlm, source, tmp_path / "once.jsonl", batch_size=4, progress=False)
    assert once.answered == n
    resumed = {x["index"]: x["prediction"] for x in _lines(out)}
    assert resumed == {x["index"]: x["prediction"] for x in _lines(tmp_path / "once.jsonl")}
    with pytest.raises(InvalidDataError, match="another variant"):
        predict(vlm, source, out, variant="cot", progress=False)
    (tmp_path / "foreign.jsonl").write_text("{}\n")
    with pytest.raises(InvalidDataError, match="not written by spacedg predict"):
        predict(vlm, source, tmp_path / "foreign.jsonl", progress=False)


def test_no_image_baseline_shares_one_call_per_question(bench_dir, vlm, tmp_path) -> None:
    bench = load_bench(bench_dir)
    summary = predict(vlm, bench_source(bench), tmp_path / "n.jsonl", variant="no_image", batch_size=4, progress=False)
    questions = {r.question for r in bench}
    assert summary.answered == len(bench) and summary.generated == len(questions) == len(bench) // 3
    by_question: dict[str, set[str]] = {}
    for line in _lines(tmp_path / "n.jsonl"):
        by_question.setdefault(line["question"], set()).add(line["prediction"])
    assert all(len(answers) == 1 for answers in by_question.values())
    chat = conversation(bench.rows[0], "no_image")
    assert not any(part.get("type") == "image" for m in chat for part in m["content"])


def test_degradation_info_prompt(bench_dir, vlm, tmp_path) -> None:
    bench = load_bench(bench_dir)
    hazy = next(r for r in bench if r.degradation_type == "haze")
    clean = next(r for r in bench if r.degradation_type == "ori")
    text = degradation_info(hazy)
    assert text.startswith("The images are degraded by haze (severity given as the rendering parameter ranges: density in [3.5, 6]")
    assert degradation_info(clean) == ""
    user = conversation(hazy, "degradation_info")[1]["content"]
    assert sum(p["type"] == "image" for p in user) == len(hazy.image_paths)
    assert user[-1]["text"] == text + hazy.question
    low_res = next(r for r in bench if r.degradation_type == "low_res")
    assert "scale in [0.02, 0.05]" in degradation_info(low_res)
    summary = predict(vlm, bench_source(bench), tmp_path / "d.jsonl", variant="degradation_info", progress=False)
    assert summary.answered == len(bench)


def test_cot_is_two_stage(bench_dir, vlm, tmp_path) -> None:
    bench = load_bench(bench_dir)
    summary = predict(vlm, bench_source(bench), tmp_path / "c.jsonl", variant="cot", limit=4, max_new_tokens=8, progress=False)
    assert summary.answered == 4 and summary.generated == 8
    lines = _lines(tmp_path / "c.jsonl")
    assert all("stage1" in x and "degradation_guess" in x for x in lines)
    stage1 = conversation(bench.rows[0], "cot")
    assert "Choose exactly one of: clean (no degradation), defocus, distortion, haze" in stage1[1]["content"][-1]["text"]


def test_parse_degradation_guess() -> None:
    names = ["defocus", "haze", "low_light", "low_res", "motion_blur", "over_exposure", "water_droplets"]
    assert parse_degradation_guess("Degradation: haze. Description: a grey veil.", names) == "haze"
    assert parse_degradation_guess("Degradation: Low light. Description: dark, noisy.", names) == "low_light"
    assert parse_degradation_guess("I think this is motion blur, with streaks; not defocus.", names) == "motion_blur"
    assert parse_degradation_guess("Degradation: none", names) == "ori"
    assert parse_degradation_guess("Degradation: overexposed", names) == "over_exposure"
    assert parse_degradation_guess("no idea", names) is None


def test_predict_over_the_dataset_online_matches_the_export(rooms, bench_dir, vlm, tmp_path) -> None:
    source = dataset_source(_dataset(rooms))
    summary = predict(vlm, source, tmp_path / "o.jsonl", limit=6, batch_size=3, progress=False)
    assert summary.answered == 6
    exported = {x["index"]: x for x in _lines(tmp_path / "o.jsonl")}
    bench = load_bench(bench_dir)
    from_export = predict(vlm, bench_source(bench), tmp_path / "e.jsonl", limit=6, batch_size=3, progress=False)
    assert from_export.answered == 6
    for line in _lines(tmp_path / "e.jsonl"):
        online = exported[line["index"]]
        for key in ("question", "answer", "answer_type", "question_type", "degradation_type", "record_id", "prediction"):
            assert online[key] == line[key], key


def test_internvl_family_predicts(bench_dir, tmp_path) -> None:
    model_dir = save_tiny_vlm(tmp_path / "tiny-internvl", "internvl")
    summary = predict(model_dir, bench_source(load_bench(bench_dir)), tmp_path / "i.jsonl", batch_size=6, limit=6,
                      progress=False)
    assert summary.answered == 6


def test_chat_collate_with_a_real_processor(rooms, vlm) -> None:
    """The dataset's collate output goes through the real processor; the assistant mask holds the answer."""
    _, processor = vlm
    items = [_dataset(rooms)[i] for i in (0, 7)]
    batch = chat_collate(items)
    encoded = encode_chats(processor, batch["messages"], batch["images"], add_generation_prompt=False, return_assistant_mask=True)
    for row, answer in enumerate(batch["answers"]):
        ids = encoded["input_ids"][row][encoded["assistant_masks"][row].bool()]
        assert processor.tokenizer.decode(ids) == answer + "<|im_end|>"


def test_cli_predict(bench_dir, model_dir, tmp_path, capsys) -> None:
    out = tmp_path / "cli.jsonl"
    args = ["predict", "--model", str(model_dir), "--bench", str(bench_dir), "--out", str(out), "--no-image", "--no-progress"]
    assert main(args) == 0
    n = len(load_bench(bench_dir))
    assert f"{n} answered now ({n // 3} model calls" in capsys.readouterr().out
    assert read_predictions(out).variant == "no_image"
    assert main(["predict", "--model", str(tmp_path / "nothing"), "--bench", str(bench_dir), "--out", str(tmp_path / "x.jsonl")]) == 2
    assert "nothing" in capsys.readouterr().err
    with pytest.raises(ParameterError, match=r"\*.jsonl"):
        predict(model_dir, bench_source(load_bench(bench_dir)), tmp_path / "x.csv")


def test_shards_split_the_bench_and_eval_merges_them(bench_dir, model_dir, tmp_path, monkeypatch, capsys) -> None:
    out = tmp_path / "sharded.jsonl"
    base = ["predict", "--model", str(model_dir), "--bench", str(bench_dir), "--out", str(out), "--no-progress"]
    assert main([*base, "--shard", "0/2"]) == 0
    monkeypatch.setenv("RANK", "1")
    monkeypatch.setenv("WORLD_SIZE", "2")
    assert main([*base, "--shard", "env"]) == 0
    parts = [tmp_path / "sharded.shard0of2.jsonl", tmp_path / "sharded.shard1of2.jsonl"]
    first, second = ({x["index"] for x in _lines(p)} for p in parts)
    bench = load_bench(bench_dir)
    assert not first & second and first | second == {r.index for r in bench}
    assert len(first) == (len(bench) + 1) // 2
    whole = tmp_path / "whole.jsonl"
    assert main(["predict", "--model", str(model_dir), "--bench", str(bench_dir), "--out", str(whole), "--no-progress"]) == 0
    capsys.readouterr()
    merged = build_report([read_predictions(p) for p in parts], bench)
    once = build_report([read_predictions(whole)], bench)
    assert [s.label for s in merged.sets] == ["tiny-qwen2.5-vl"]
    assert merged.overall("tiny-qwen2.5-vl") == once.overall("tiny-qwen2.5-vl")
    assert main([*base, "--shard", "2/2"]) == 2
    assert "need 0 <= i < n" in capsys.readouterr().err


def test_a_mixture_predicted_online_records_every_part_with_its_parameters(rooms, vlm, tmp_path) -> None:
    dataset = SpaceDGDataset("bench", ["night_capture", "haze:3+low_res"], scenes=rooms, image_size=SIZE,
                             qa_config=CONFIG, max_questions=1)
    source = dataset_source(dataset)
    mixture = next(i for i in source.indices if dataset.plan(i).degradation_type == "night_capture")
    row = source.row(mixture)
    parts = {d["name"]: d for d in row.degradation}
    assert set(parts) == {"low_light", "motion_blur", "low_res"}
    assert parts["low_light"]["preset"] == "bench" and parts["motion_blur"]["preset"] == "2" == parts["low_res"]["preset"]
    assert all(d["params"] and isinstance(d["seed"], int) for d in row.degradation)
    assert [dict(d) for d in row.degradation] == dataset[mixture]["degradation"]  # what the render recorded
    info = degradation_info(row)  # before the fix: "degraded by night capture" with no ranges
    assert "low light (severity given as the rendering parameter ranges: exposure in [0.003, 0.005]" in info
    assert "motion blur (severity" in info and "low res (severity" in info and "night capture" not in info
    summary = predict(vlm, source, tmp_path / "mix.jsonl", variant="degradation_info", progress=False)
    assert summary.answered == len(dataset)
    line = next(x for x in _lines(tmp_path / "mix.jsonl") if x["index"] == mixture)
    assert [d["name"] for d in line["degradation"]] == [d["name"] for d in row.degradation]
    chained = next(i for i in source.indices if dataset.plan(i).degradation_type == "haze+low_res")
    assert {d["name"]: d["preset"] for d in source.row(chained).degradation} == {"haze": "3", "low_res": "bench"}

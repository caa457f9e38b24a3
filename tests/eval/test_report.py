"""`spacedg eval`: scores, tables and correlations checked against hand-computed values."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import pointbiserialr

from spacedg.cli import main
from spacedg.errors import FileFormatError, InvalidDataError, ParameterError
from spacedg.eval.aggregate import AVG
from spacedg.eval.bench import load_bench
from spacedg.eval.correlation import point_biserial
from spacedg.eval.predictions import read_predictions
from spacedg.eval.report import build_report, write_report
from tests.eval_fixtures import (
    CONDITIONS,
    ITEM_SCORES,
    condition_score,
    write_bench,
    write_jsonl,
    write_vlmevalkit_tsv,
    write_vlmevalkit_xlsx,
)

MODELS = ("good-model", "mid-model", "tsv-model")


@pytest.fixture()
def bench_dir(tmp_path: Path) -> Path:
    return write_bench(tmp_path / "bench")


@pytest.fixture()
def pred_files(tmp_path: Path) -> list[Path]:
    return [
        write_jsonl(tmp_path / "good-model.jsonl", "good-model"),
        write_vlmevalkit_xlsx(tmp_path / "mid-model_SpaceDG.xlsx", "mid-model"),
        write_vlmevalkit_tsv(tmp_path / "tsv-model_SpaceDG.tsv", "tsv-model"),
    ]


def _report(bench_dir: Path, files: list[Path], labels: tuple[str, ...] = MODELS):
    sets = [read_predictions(f"{label}={path}") for label, path in zip(labels, files)]
    return build_report(sets, load_bench(bench_dir))


def _hand_avg(model: str) -> float:
    return (condition_score(model, "haze") + condition_score(model, "low_light")) / 2


# ------------------------------------------------------------------ numbers
def test_condition_scores_match_hand_computed(bench_dir: Path, pred_files: list[Path]) -> None:
    report = _report(bench_dir, pred_files)
    assert report.conditions == list(CONDITIONS)
    for model in MODELS:
        scores = report.overall(model)
        for condition in CONDITIONS:
            assert scores[condition] == pytest.approx(condition_score(model, condition), abs=1e-12), (model, condition)
        assert scores[AVG] == pytest.approx(_hand_avg(model), abs=1e-12)
    # the three formats (.jsonl, .xlsx, quoted .tsv) agree item by item with the hand scores
    for model in MODELS:
        got = {(i.degradation_type, i.index % 5): i.score for i in report.items[model]}
        for condition in CONDITIONS:
            for q, expected in enumerate(ITEM_SCORES[model][condition]):
                assert got[(condition, q)] == pytest.approx(expected, abs=1e-12), (model, condition, q)


def test_main_table_markdown_is_the_papers_layout(bench_dir: Path, pred_files: list[Path]) -> None:
    table = _report(bench_dir, pred_files).out["main"]
    lines = table.markdown().splitlines()
    assert lines[2:7] == [
        "| Model | Clean | Haze | Low-light | Avg. |",
        "|---|---:|---:|---:|---:|",
        "| good-model | **100.0** | **72.0** | 63.3 | **67.7** |",
        "| mid-model | 74.0 | 42.0 | **78.0** | 60.0 |",
        "| tsv-model | **100.0** | 0.0 | 0.0 | 0.0 |",
    ]


def test_slice_tables(bench_dir: Path, pred_files: list[Path]) -> None:
    report = _report(bench_dir, pred_files)
    by_type = report.tables["good-model"]["answer_type"]
    assert by_type["MCQ"]["ori"].score == 1 and by_type["MCQ"]["haze"].score == 1 and by_type["MCQ"]["low_light"].score == 0
    assert by_type["MCQ"][AVG].score == pytest.approx(0.5)
    assert by_type["NA"][AVG].score == pytest.approx((0.6 + 0.5) / 2)
    assert by_type["SIZE_LIST"]["low_light"].score == pytest.approx(2 / 3)
    groups = report.tables["mid-model"]["task_group"]
    # object-centric = existence, counting, size: mid-model haze 1, 1, 0 → 2/3; clean 0, 1, 0.7 → 0.5667
    assert groups["object_centric"]["haze"].score == pytest.approx(2 / 3)
    assert groups["object_centric"]["ori"].score == pytest.approx(1.7 / 3)
    assert groups["object_centric"]["ori"].n == 3
    formats = report.tables["tsv-model"]["answer_format"]
    assert set(formats) == {"MCA", "NA"} and formats["MCA"]["ori"].n == 2
    rows = {(r[0], r[1]): r for r in report.out["by_question_type"].values}
    assert rows[("good-model", "camera_translation")][2:5] == [1.0, 1.0, 0.0]


def test_drop_table(bench_dir: Path, pred_files: list[Path]) -> None:
    table = _report(bench_dir, pred_files).out["drop"]
    good = table.values[0]
    assert good[0] == "good-model"
    assert good[3] == pytest.approx(1 - _hand_avg("good-model"))
    assert good[5] == "low_light"  # 1 − 0.633 > 1 − 0.72
    assert table.cells[0][3] == "+32.3"
    mid = table.values[1]
    assert mid[6 + 1] == pytest.approx(0.74 - 0.78)  # Δ low_light is negative: mid-model did better degraded


# ------------------------------------------------------------------ correlation
def test_correlation_matches_scipy(bench_dir: Path, pred_files: list[Path]) -> None:
    report = _report(bench_dir, pred_files)
    checked = 0
    for kind, panel in report.correlation.items():
        for slice_name, row in panel.items():
            for condition, (r, models) in row.items():
                clean = [report.tables[m][kind][slice_name]["ori"].score for m in MODELS]
                degraded = [report.tables[m][kind][slice_name][condition].score for m in MODELS]
                assert models == 3
                y = np.array(clean + degraded)
                if np.ptp(y) == 0:
                    assert math.isnan(r)
                    continue
                expected = pointbiserialr([0, 0, 0, 1, 1, 1], y).statistic
                assert r == pytest.approx(expected, abs=1e-12), (kind, slice_name, condition)
                checked += 1
    assert checked >= 20
    # the overall haze value, by hand: y = [1, .74, 1, .72, .42, 0]
    haze = report.correlation["all"]["all"]["haze"][0]
    y = np.array([1, 0.74, 1, 0.72, 0.42, 0.0])
    by_hand = (y[3:].mean() - y[:3].mean()) / y.std() * 0.5
    assert haze == pytest.approx(by_hand, abs=1e-12)


@pytest.mark.parametrize("seed", range(5))
def test_point_biserial_random_and_extreme(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = int(rng.integers(4, 60))
    x = np.array([0] * (n // 2) + [1] * (n - n // 2))
    for y in (rng.random(n), 1 - 1e-9 * rng.random(n), 1e12 + rng.random(n) * 1e3):
        expected = pointbiserialr(x, y).statistic
        assert point_biserial(x, y) == pytest.approx(expected, rel=1e-9, abs=1e-9)


def test_point_biserial_undefined_cases() -> None:
    assert math.isnan(point_biserial([0, 0, 1, 1], [0.5, 0.5, 0.5, 0.5]))  # constant scores
    assert math.isnan(point_biserial([1, 1, 1], [0.1, 0.2, 0.3]))  # no clean side
    assert math.isnan(point_biserial([0, 1], [0.1, float("nan")]))
    assert point_biserial([0, 1], [0.9, 0.1]) == -1.0
    with pytest.raises(ValueError, match="only 0 and 1"):
        point_biserial([0, 2], [0.1, 0.2])
    with pytest.raises(ValueError, match="equal length"):
        point_biserial([0, 1, 1], [0.1, 0.2])


def test_correlation_needs_two_models(bench_dir: Path, pred_files: list[Path]) -> None:
    report = _report(bench_dir, pred_files[:1], labels=MODELS[:1])
    r, models = report.correlation["all"]["all"]["haze"]
    assert math.isnan(r) and models == 1
    assert "at least 2 models" in report.out["correlation"].note


# ------------------------------------------------------------------ variants
def test_degradation_info_delta_and_non_image_rows(bench_dir: Path, tmp_path: Path) -> None:
    base = write_jsonl(tmp_path / "base.jsonl", "good-model")
    info = write_jsonl(tmp_path / "info.jsonl", "mid-model")
    blind = write_jsonl(tmp_path / "blind.jsonl", "tsv-model")
    sets = [read_predictions(f"M={base}"), read_predictions(f"M@degradation_info={info}"), read_predictions(f"M@no_image={blind}")]
    report = build_report(sets, load_bench(bench_dir))
    delta = report.out["degradation_info"]
    assert delta.header == ["Model", "Δ Haze", "Δ Low-light", "Δ Avg."]
    assert delta.values[0][1] == pytest.approx(0.42 - 0.72)
    assert delta.cells[0][1] == "-30.0"
    main_table = report.out["main"].markdown()
    assert "| *Base* |" in main_table and "| *Models* |" in main_table
    blind_avg = sum(sum(ITEM_SCORES["tsv-model"][c]) for c in CONDITIONS) / 15
    assert f"| Non-Image (M) | - | - | - | {100 * blind_avg:.1f} |" in main_table
    assert "| M@degradation_info |" in main_table


def test_cot_recognition_accuracy(bench_dir: Path, tmp_path: Path) -> None:
    path = tmp_path / "cot.jsonl"
    guesses = {"ori": "Degradation: none. Description: sharp.", "haze": "Degradation: fog. Description: grey veil.",
               "low_light": "Degradation: motion blur. Description: streaks."}
    with path.open("w") as handle:
        for index in range(15):
            condition = CONDITIONS[index // 5]
            handle.write(json.dumps({"index": index, "prediction": "<answer>B</answer>", "stage1": guesses[condition]}) + "\n")
    base = write_jsonl(tmp_path / "base.jsonl", "good-model")
    report = build_report([read_predictions(f"M={base}"), read_predictions(f"M@cot={path}")], load_bench(bench_dir))
    recognition = report.out["cot_recognition"].values[0]
    assert recognition == ["M", 1.0, 1.0, 0.0]
    cot = report.out["cot"].values
    assert [row[1] for row in cot] == ["w/o CoT", "with CoT"]


# ------------------------------------------------------------------ files
def test_write_report_tree_and_csv_round_trip(bench_dir: Path, pred_files: list[Path], tmp_path: Path) -> None:
    report = _report(bench_dir, pred_files)
    out = tmp_path / "report"
    written = write_report(report, out, with_plots=False)
    names = {p.relative_to(out).as_posix() for p in written}
    for stem in ("main", "by_task_group", "by_question_type", "by_answer_type", "drop", "correlation"):
        assert {f"{stem}.md", f"{stem}.csv"} <= names
    assert {"scores.csv", "items.csv", "summary.json", "report.md"} <= names
    rows = list(csv.DictReader((out / "main.csv").open()))
    assert [r["Model"] for r in rows] == list(MODELS)
    assert float(rows[1]["Low-light"]) == pytest.approx(0.78)
    items = list(csv.DictReader((out / "items.csv").open()))
    assert len(items) == 45
    summary = json.loads((out / "summary.json").read_text())
    assert summary["models"]["good-model"]["scores"]["haze"] == pytest.approx(0.72)
    assert "### Scores per degradation" in (out / "report.md").read_text()


def test_self_contained_predictions_need_no_bench(tmp_path: Path) -> None:
    path = write_jsonl(tmp_path / "p.jsonl", "good-model", with_rows=True)
    report = build_report([read_predictions(path)])
    assert report.overall("p")["haze"] == pytest.approx(0.72)


def test_cli_eval(bench_dir: Path, pred_files: list[Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    args = ["eval", *(f"{m}={p}" for m, p in zip(MODELS, pred_files)), "--bench", str(bench_dir), "--out", str(tmp_path / "r"), "--no-plots"]
    assert main(args) == 0
    out = capsys.readouterr().out
    assert "| good-model | **100.0** | **72.0** | 63.3 | **67.7** |" in out
    assert main(["eval", str(tmp_path / "nope.jsonl"), "--out", str(tmp_path / "r2")]) == 2
    assert "nope.jsonl does not exist" in capsys.readouterr().err


# ------------------------------------------------------------------ readers and errors
def test_model_names_from_vlmevalkit_layout(tmp_path: Path) -> None:
    run = tmp_path / "outputs" / "Qwen3-VL-8B" / "T20260101_Gabcdef"
    run.mkdir(parents=True)
    path = write_vlmevalkit_tsv(run / "Qwen3-VL-8B_SpaceDG_Bench.tsv", "good-model")
    assert read_predictions(path).model == "Qwen3-VL-8B"
    flat = write_vlmevalkit_tsv(tmp_path / "outputs" / "Qwen3-VL-8B" / "Qwen3-VL-8B_SpaceDG.tsv", "good-model")
    assert read_predictions(flat).model == "Qwen3-VL-8B"
    labelled = read_predictions(f"Mine@no_image={flat}")
    assert (labelled.model, labelled.variant, labelled.label) == ("Mine", "no_image", "Mine@no_image")


def test_missing_predictions(bench_dir: Path, tmp_path: Path) -> None:
    path = write_jsonl(tmp_path / "p.jsonl", "good-model")
    lines = path.read_text().splitlines()
    path.write_text("\n".join(lines[:-2]) + "\n")  # indices 13 and 14 unanswered
    with pytest.raises(InvalidDataError, match=r"2 of 15 bench items have no prediction \(first index 13\).*--missing wrong"):
        build_report([read_predictions(path)], load_bench(bench_dir))
    report = build_report([read_predictions(path)], load_bench(bench_dir), missing="wrong")
    items = report.items["p"]
    assert sum(i.missing for i in items) == 2 and all(i.score == 0 for i in items if i.missing)
    assert report.overall("p")["low_light"] == pytest.approx((0 + 1 + 0.5) / 5)
    subset = build_report([read_predictions(path)], load_bench(bench_dir), missing="skip")
    assert len(subset.items["p"]) == 13 and subset.tables["p"]["all"]["all"]["low_light"].n == 3
    assert subset.overall("p")["low_light"] == pytest.approx((0 + 1 + 0.5) / 3)


def test_bad_inputs_get_one_clear_error(bench_dir: Path, tmp_path: Path) -> None:
    bench = load_bench(bench_dir)
    other = tmp_path / "other.jsonl"
    other.write_text(json.dumps({"index": 99, "prediction": "B"}) + "\n")
    with pytest.raises(InvalidDataError, match="not in the bench"):
        build_report([read_predictions(other)], bench)
    with pytest.raises(InvalidDataError, match="pass the bench"):
        build_report([read_predictions(other)])
    torn = tmp_path / "torn.jsonl"
    torn.write_text('{"index": 0, "prediction": "B"}\n{"index": 1, "predic\n')
    with pytest.raises(FileFormatError, match=r"torn.jsonl:2: not JSON"):
        read_predictions(torn)
    twice = tmp_path / "twice.jsonl"
    twice.write_text('{"index": 0, "prediction": "B"}\n{"index": 0, "prediction": "C"}\n')
    with pytest.raises(FileFormatError, match="two different predictions"):
        read_predictions(twice)
    nocol = tmp_path / "nocol.tsv"
    nocol.write_text("index\tanswer\n0\tB\n")
    with pytest.raises(FileFormatError, match="needs 'index' and 'prediction'"):
        read_predictions(nocol)
    with pytest.raises(InvalidDataError, match="unknown prediction format '.txt'"):
        (tmp_path / "p.txt").write_text("x")
        read_predictions(tmp_path / "p.txt")
    with pytest.raises(ParameterError, match="prompt variant 'fancy'"):
        read_predictions(f"M@fancy={write_jsonl(tmp_path / 'q.jsonl', 'good-model')}")
    same = write_jsonl(tmp_path / "r.jsonl", "good-model")
    with pytest.raises(InvalidDataError, match="both 'M' and both answer item 0"):
        build_report([read_predictions(f"M={same}"), read_predictions(f"M={same}")], bench)
    (tmp_path / "bad.xlsx").write_bytes(b"not a zip")
    with pytest.raises(FileFormatError, match="not a readable .xlsx"):
        read_predictions(tmp_path / "bad.xlsx")


def test_load_bench_reads_na_as_text_and_routes_blank_types(bench_dir: Path, tmp_path: Path) -> None:
    bench = load_bench(bench_dir)
    assert bench.by_index[2].answer_type.value == "NA"  # pandas would read "NA" as missing
    assert bench.by_index[0].options == ("left", "right", "forward", "backward")
    text = (bench_dir / "bench.tsv").read_text().replace("\tNA\t", "\t\t")
    (tmp_path / "b2").mkdir()
    (tmp_path / "b2" / "bench.tsv").write_text(text)
    assert load_bench(tmp_path / "b2").by_index[2].answer_type.value == "NA"  # routed from the question type
    with pytest.raises(InvalidDataError, match="no .tsv"):
        load_bench(tmp_path)
    dup = tmp_path / "dup"
    dup.mkdir()
    lines = (bench_dir / "bench.tsv").read_text().splitlines()
    (dup / "bench.tsv").write_text("\n".join([*lines, lines[-1]]) + "\n")
    with pytest.raises(FileFormatError, match="index 14 appears twice"):
        load_bench(dup)

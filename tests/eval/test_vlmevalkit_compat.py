"""`spacedg eval` reads what VLMEvalKit writes for an exported bench, and still reads older exports.

VLMEvalKit cannot be installed from a package registry here, so its files are written the way its
code writes them (read from ``vlmeval/dataset/image_base.py``, ``vlmeval/inference.py`` and
``vlmeval/smp/file.py`` of the EASI VLMEvalKit, and ``SpaceDGBench.evaluate``): the bench TSV loaded
with ``pandas.read_csv(sep="\\t")``, ``index`` through ``str``/``int``, ``image_path`` through
``toliststr`` (one path → the path, several → a list), a ``prediction`` column added and the frame
written with ``DataFrame.to_excel(index=False)`` to ``{work_dir}/{model}/T…_G…/{model}_spacedg_bench.xlsx``.
(VLMEvalKit uses the xlsxwriter engine; pandas converts cells identically for openpyxl, used here.)
"""

from __future__ import annotations

import ast
import csv
import json
from pathlib import Path

import pandas as pd
import pytest

from spacedg.cli import main
from spacedg.data.dataset import SpaceDGDataset
from spacedg.data.bench_table import TSV_COLUMNS, tsv_bytes
from spacedg.data.export import export_bench
from spacedg.data.public_format import from_public
from spacedg.qa.index import QABuildConfig
from spacedg.eval import load_bench, read_predictions, score
from spacedg.eval.aggregate import score_set
from spacedg.plugins.specs import AnswerType
from tests.conftest import private_copies

CONFIG = QABuildConfig(seed=5, per_sub_type=1)


@pytest.fixture(scope="module")
def bench_dir(qa_room_dirs, tmp_path_factory) -> Path:
    """A real export of every built-in family (clean + one degradation, tiny images)."""
    rooms = private_copies(qa_room_dirs, tmp_path_factory.mktemp("compat_rooms"))
    dataset = SpaceDGDataset("bench", ["haze"], scenes=rooms, image_size=(32, 24), qa_config=CONFIG)
    out = tmp_path_factory.mktemp("compat_bench")
    assert export_bench(dataset, out, progress=False).merged
    return out


def _toliststr(cell: str) -> list[str]:
    return [str(x) for x in ast.literal_eval(cell)] if cell.startswith("[") and cell.endswith("]") else [cell]


def _predictions(row: pd.Series) -> str:
    """A varied, deterministic answer per row: right, wrong, tagged, wordy, unparseable."""
    index, answer = int(row["index"]), str(row["answer"])
    style = index % 5
    if style == 0:
        return f"<answer>{answer}</answer>"
    if style == 1:
        return "I cannot tell."
    if style == 2:
        return f"Let me think step by step.\n<answer>{answer}</answer>"
    if style == 3:
        return "<answer>B</answer>" if answer != "B" else "<answer>A</answer>"
    return f"The answer is {answer}"


def write_vlmevalkit_xlsx(bench: Path, work_dir: Path, model: str) -> tuple[Path, dict[int, str]]:
    data = pd.read_csv(bench / "spacedg_bench.tsv", sep="\t")  # SpaceDGBench.load_data
    data["index"] = [str(x) for x in data["index"]]  # ImageBaseDataset.__init__
    paths = [_toliststr(x) for x in data["image_path"]]
    data["image_path"] = [x[0] if len(x) == 1 else x for x in paths]
    data["index"] = [int(x) for x in data["index"]]
    data["prediction"] = [_predictions(row) for _, row in data.iterrows()]  # infer_data_job
    out = work_dir / model / "T20260101_G0a1b2c3" / f"{model}_spacedg_bench.xlsx"
    out.parent.mkdir(parents=True)
    data.to_excel(out, index=False)  # smp.file.dump → to_excel(index=False)
    return out, dict(zip(data["index"], data["prediction"]))


def test_spacedg_eval_reads_vlmevalkits_prediction_xlsx_of_an_exported_bench(bench_dir, tmp_path):
    xlsx, predictions = write_vlmevalkit_xlsx(bench_dir, tmp_path / "outputs", "Tiny-VLM")
    preds = read_predictions(xlsx)
    bench = load_bench(bench_dir)
    assert preds.model == "Tiny-VLM" and preds.predictions == predictions and len(preds.rows) == len(bench)
    for index, row in bench.by_index.items():
        from_xlsx = preds.rows[index]  # the row as VLMEvalKit's file repeats it (answer type "NA" lost to pandas)
        assert from_xlsx.answer_type is row.answer_type, (row.question_type, row.sub_question_type)
        assert (from_xlsx.question_type, from_xlsx.sub_question_type, from_xlsx.answer) == (row.question_type, row.sub_question_type, row.answer)
        assert from_xlsx.image_paths == row.image_paths
        expected = score(predictions[index], row.scoring_fields())
        assert score(predictions[index], from_xlsx.scoring_fields()) == expected
    items = score_set(preds, bench.by_index)
    assert {i.answer_type for i in items} == {r.answer_type.value for r in bench} == {a.value for a in AnswerType}
    tagged = [i for i in items if i.index % 5 == 0]
    assert tagged and all(i.score == 1.0 for i in tagged)
    assert all(i.score == 0.0 and not i.parse_ok for i in items if i.index % 5 == 1)


def test_spacedg_eval_cli_on_the_xlsx_and_the_report_names_its_scorer(bench_dir, tmp_path, capsys):
    xlsx, _ = write_vlmevalkit_xlsx(bench_dir, tmp_path / "outputs", "Tiny-VLM")
    assert main(["eval", str(xlsx), "--bench", str(bench_dir), "--out", str(tmp_path / "report"), "--no-plots"]) == 0
    summary = json.loads((tmp_path / "report" / "summary.json").read_text())
    assert "public SpaceDG evaluator" in summary["scorer"] and "docs/scoring.md" in summary["scorer"]
    assert "Tiny-VLM" in summary["models"] and summary["models"]["Tiny-VLM"]["items"] == len(load_bench(bench_dir))
    assert "Scorer: " in (tmp_path / "report" / "report.md").read_text()
    with (tmp_path / "report" / "items.csv").open() as handle:
        subs = {(r["question_type"], r["sub_question_type"]) for r in csv.DictReader(handle)}
    assert ("object_counting", "count") in subs  # our finer names label the tables


def test_the_evaluators_own_output_xlsx_is_readable_too(bench_dir, tmp_path):
    """``SpaceDGBench.evaluate`` writes its scored buckets (MCQ first, then NA, YN, …) with the
    extracted answers as ``prediction`` plus ``eval_task``, ``pred_extracted``, ``hit``, ``bucket``."""
    xlsx, predictions = write_vlmevalkit_xlsx(bench_dir, tmp_path / "outputs", "Tiny-VLM")
    data = pd.read_excel(xlsx)
    data = data.sort_values("question_type", kind="stable")
    data["eval_task"], data["pred_extracted"], data["hit"], data["bucket"] = "MCQ", "", 0.0, "mcq"
    scored = xlsx.with_name("Tiny-VLM_spacedg_bench_extract_matching.xlsx")
    data.to_excel(scored, index=False)
    preds = read_predictions(f"Tiny-VLM={scored}")
    assert set(preds.predictions) == set(predictions)


def _old_format(bench_dir: Path, out: Path) -> Path:
    """The bench as spacedg wrote it before the public format: our internal sub types, existence as yes/no."""
    rows = list(csv.DictReader((bench_dir / "bench.tsv").open(newline="", encoding="utf-8"), delimiter="\t"))
    old = []
    for row in rows:
        qtype, sub = from_public(row["question_type"], row["sub_question_type"])
        row = {**row, "sub_question_type": sub}
        if qtype == "object_existence_estimation":
            answer = row[row["answer"]]
            row.update(answer=answer, answer_type="YN", A="", B="", question=row["question"].split("\nA. ")[0])
        old.append(row)
    out.mkdir()
    (out / "bench.tsv").write_bytes(tsv_bytes(old, columns=TSV_COLUMNS))
    (out / "images").symlink_to(bench_dir / "images")
    return out


def test_older_exports_with_internal_names_still_score(bench_dir, tmp_path):
    old_dir = _old_format(bench_dir, tmp_path / "old")
    old, new = load_bench(old_dir), load_bench(bench_dir)
    subs = {(r.question_type, r.sub_question_type) for r in old}
    assert {("object_counting", "count"), ("object_existence_estimation", "existence"), ("inter_object_distance", "two_view")} <= subs
    for row in old:
        twin = new.by_index[row.index]
        if row.question_type == "object_existence_estimation":
            assert row.answer_type is AnswerType.YN and twin.answer_type is AnswerType.MCQ
            assert score(row.answer, row.scoring_fields()).score == 1.0
            assert score(twin.options[ord(twin.answer) - 65], twin.scoring_fields()).score == 1.0  # "yes" → its letter
        else:
            assert row.answer_type is twin.answer_type
        # a VLMEvalKit file of the old bench loses the answer type "NA": the internal names still route
        assert score(row.answer, {**row.scoring_fields(), "answer_type": float("nan")}).answer_type is row.answer_type

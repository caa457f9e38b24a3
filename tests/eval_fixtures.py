"""A fixed tiny bench and three models' fixed predictions, with hand-computed scores.

Five questions (MCQ, yes/no, distance, count, size list) under three conditions (clean,
haze, low_light): 15 rows, ``index = 5 · condition + question``. The expected scores below are
worked out by hand from the scoring rules (MCQ/YN/COUNT exact; MRA over θ = 0.50 … 0.95, i.e.
the share of the ten thresholds with ``e <= 1 − θ``), not by calling the scorer.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

CONDITIONS = ("ori", "haze", "low_light")
QUESTIONS = [
    # (question_type, sub_question_type, task_group, answer_type, answer, options, question)
    ("camera_translation", "main_dir", "camera_centric", "MCQ", "B", ["left", "right", "forward", "backward"],
     "Where did the camera move?\nA. left\nB. right\nC. forward\nD. backward"),
    ("object_existence_estimation", "existence", "object_centric", "YN", "yes", [],  # as older exports wrote it
     "Is there a chair in the image?"),
    ("camera_object_distance_estimation", "distance_exact", "camera_object", "NA", "2.0", [],
     "How far is the lamp from the camera, in meters?"),
    ("object_counting", "", "object_centric", "COUNT", "3", [], "How many cups are there?"),  # public names: empty sub type
    ("object_bounding_size_estimation", "", "object_centric", "SIZE_LIST",
     "[0.10, 0.20, 0.30]", [], "What are the dimensions of the box?"),
]

#: Raw predictions per model, per condition, per question (in QUESTIONS order).
PREDICTIONS: dict[str, dict[str, list[str]]] = {
    "good-model": {
        "ori": ["B", "yes", "2.0", "3", "[0.1, 0.2, 0.3]"],
        "haze": ["B", "no", "2.5", "3", "0.1 x 0.2 x 0.3 m"],
        "low_light": ["A", "yes", "2.6", "3", "[0.1, 0.2, 0.6]"],
    },
    "mid-model": {
        "ori": ["B", "no", "1.9", "3", "[0.1, 0.2, 0.45]"],
        "haze": ["garbage", "yes", "1.0", "3", "none"],
        "low_light": ["B", "yes", "2.2", "4", "[0.1, 0.2, 0.3]"],
    },
    "tsv-model": {
        "ori": ["<answer>B</answer>", "Yes.", "two meters", "3 objects", "[0.1, 0.2, 0.3]"],
        "haze": ["C", "no", "4.0", "1", "[1, 1, 1]"],
        "low_light": ["D", "no", "0", "0", "[0.2, 0.4, 0.6]"],
    },
}

# Per-item scores worked out by hand (MRA: e = |p − t| / t; hits = #θ with e <= 1 − θ; /10).
#   2.5 vs 2.0: e = 0.25 → θ ∈ {.50 … .75} → 0.6       2.6: e = 0.30 → 0.5     1.9: e = 0.05 → 1.0
#   1.0: e = 0.5 → θ = .50 only → 0.1                   2.2: e = 0.10 → 0.9     4.0: e = 1 → 0    0: e = 1 → 0
#   size [0.1,0.2,0.45] vs [.1,.2,.3]: 1, 1, e=.5 → .1 → 2.1/3 = 0.7; [0.1,0.2,0.6]: 1, 1, 0 → 2/3
#   [1,1,1]: e = 9, 4, 2.33 → 0; [0.2,0.4,0.6]: e = 1, 1, 1 → 0
ITEM_SCORES: dict[str, dict[str, list[float]]] = {
    "good-model": {"ori": [1, 1, 1.0, 1, 1.0], "haze": [1, 0, 0.6, 1, 1.0], "low_light": [0, 1, 0.5, 1, 2 / 3]},
    "mid-model": {"ori": [1, 0, 1.0, 1, 0.7], "haze": [0, 1, 0.1, 1, 0.0], "low_light": [1, 1, 0.9, 0, 1.0]},
    "tsv-model": {"ori": [1, 1, 1.0, 1, 1.0], "haze": [0, 0, 0.0, 0, 0.0], "low_light": [0, 0, 0.0, 0, 0.0]},
}
# "tsv-model" haze: C ≠ B, "no" ≠ "yes", 4.0 → 0, count 1 ≠ 3, sizes → 0.


def condition_score(model: str, condition: str) -> float:
    scores = ITEM_SCORES[model][condition]
    return sum(scores) / len(scores)


def bench_rows() -> list[dict[str, object]]:
    rows = []
    for c, condition in enumerate(CONDITIONS):
        for q, (qtype, sub, group, kind, answer, options, text) in enumerate(QUESTIONS):
            rows.append({
                "index": 5 * c + q, "question": text, "answer": answer, "image_path": f"['images/{5 * c + q:07d}_0.png']",
                "question_type": qtype, "sub_question_type": sub, "task_group": group, "degradation_type": condition,
                "answer_type": kind, **{k: (options[i] if options else "") for i, k in enumerate("ABCD")},
                "scene_id": "room", "record_id": f"room/{qtype}/{sub}/{q}",
                "degradation": "[]" if condition == "ori" else json.dumps([{"name": condition, "params": {}, "preset": "bench"}]),
            })
    return rows


def write_bench(folder: Path) -> Path:
    """Write ``bench.tsv`` the way the exporter does (pandas-readable, quoted multi-line fields)."""
    folder.mkdir(parents=True, exist_ok=True)
    rows = bench_rows()
    with (folder / "bench.tsv").open("w", newline="", encoding="utf-8") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]), delimiter="\t", lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
    return folder


def prediction_rows(model: str) -> list[dict[str, object]]:
    preds = PREDICTIONS[model]
    return [
        {**row, "prediction": preds[CONDITIONS[int(row["index"]) // 5]][int(row["index"]) % 5]}
        for row in bench_rows()
    ]


def write_jsonl(path: Path, model: str, *, with_rows: bool = False) -> Path:
    """Predictions as ``spacedg predict`` lines (``with_rows``: self-contained) without a sidecar."""
    with path.open("w", encoding="utf-8") as handle:
        for row in prediction_rows(model):
            line = row if with_rows else {"index": row["index"], "prediction": row["prediction"]}
            handle.write(json.dumps(line) + "\n")
    return path


def write_vlmevalkit_tsv(path: Path, model: str) -> Path:
    """VLMEvalKit's ``PRED_FORMAT=tsv`` output: every bench column plus ``prediction``, all quoted."""
    rows = prediction_rows(model)
    with path.open("w", newline="", encoding="utf-8") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]), delimiter="\t", quoting=csv.QUOTE_ALL)
        writer.writeheader()
        writer.writerows(rows)
    return path


def write_vlmevalkit_xlsx(path: Path, model: str) -> Path:
    """VLMEvalKit's default ``.xlsx`` output, written with openpyxl."""
    import openpyxl

    rows = prediction_rows(model)
    book = openpyxl.Workbook()
    sheet = book.active
    sheet.append(list(rows[0]))
    for row in rows:
        sheet.append([row[k] for k in rows[0]])
    book.save(path)
    return path


if __name__ == "__main__":  # python -m tests.eval_fixtures OUT: the fixed bench and predictions as files
    import sys

    root = Path(sys.argv[1] if len(sys.argv) > 1 else "runs/eval-fixtures")
    write_bench(root / "bench")
    write_jsonl(root / "good-model.jsonl", "good-model")
    write_vlmevalkit_xlsx(root / "mid-model_SpaceDG.xlsx", "mid-model")
    write_vlmevalkit_tsv(root / "tsv-model_SpaceDG.tsv", "tsv-model")
    print(f"wrote {root}/bench/bench.tsv and 3 prediction files (.jsonl, VLMEvalKit .xlsx and .tsv)")

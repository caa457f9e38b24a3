"""Export a split to files: PNG images, a VLMEvalKit TSV, and chat JSONL for training tools.

Layout of ``out_dir``::

    images/{index:07d}_{k}.png       view k of dataset item ``index`` (RGB PNG)
    parts/part-{chunk:05d}.tsv       rows of one chunk (header included), written after its images
    parts/part-{chunk:05d}.jsonl     the same chunk as chat JSONL
    bench.tsv, bench.jsonl           all chunks in index order (written once every chunk exists)
    summary.json                     counts per question_type × degradation_type

Work is split into **chunks** of ``chunk_size`` consecutive dataset indices; ``shard=(i, n)``
processes the chunks ``k`` with ``k % n == i``, so ``n`` processes or machines split the work
disjointly and together completely. A chunk whose two part files exist is skipped, so an
interrupted export resumes where it stopped; every file is written atomically (temporary
name, then rename), so a crash never leaves a half-written part. Items are deterministic, so
re-running a chunk anywhere writes the same bytes.

TSV columns (what the public SpaceDG evaluator and VLMEvalKit read): ``index``, ``question``
(with the option lines for MCQ), ``answer`` (letter, yes/no, number, ``[a, b, c]``),
``image_path`` (a Python list literal of relative paths), ``question_type``,
``sub_question_type``, ``task_group``, ``degradation_type`` (``ori`` for clean), then
``answer_type``, ``A``–``D`` (option texts, empty for non-MCQ), ``scene_id``, ``record_id`` and
``degradation`` (the provenance as JSON). Tabs and newlines inside fields are quoted (CSV
quoting, ``pandas.read_csv(path, sep="\\t")`` reads them back).

Chat JSONL (LLaMA-Factory / ShareGPT style): ``{"id", "images": [paths], "system":
ANSWER_PROMPT, "messages": [{"role": "user", "content": "<image>"×V + question}, {"role":
"assistant", "content": "<answer>…</answer>"}], ...metadata}``.
"""

from __future__ import annotations

import csv
import io
import json
import math
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from spacedg.data.dataset import SpaceDGDataset, answer_text, format_question
from spacedg.data.io._files import atomic_write_bytes
from spacedg.errors import ParameterError

__all__ = ["TSV_COLUMNS", "ExportSummary", "export_split", "merge_parts", "parse_shard", "chunk_ids"]

TSV_COLUMNS: tuple[str, ...] = (
    "index", "question", "answer", "image_path", "question_type", "sub_question_type", "task_group", "degradation_type",
    "answer_type", "A", "B", "C", "D", "scene_id", "record_id", "degradation",
)


@dataclass
class ExportSummary:
    """What one call did: chunks written and skipped, items written, and whether the merge ran."""

    chunks_total: int
    chunks_written: list[int] = field(default_factory=list)
    chunks_skipped: list[int] = field(default_factory=list)
    items_written: int = 0
    merged: bool = False
    counts: dict[str, dict[str, int]] = field(default_factory=dict)


def parse_shard(text: str) -> tuple[int, int]:
    """``"i/n"`` → ``(i, n)`` with ``0 <= i < n``; :class:`ParameterError` otherwise."""
    try:
        i_text, n_text = str(text).split("/")
        i, n = int(i_text), int(n_text)
    except ValueError:
        raise ParameterError(f"--shard must read i/n (e.g. 0/4), got {text!r}") from None
    if n < 1 or not 0 <= i < n:
        raise ParameterError(f"--shard {text}: need 0 <= i < n, e.g. 0/{max(n, 1)} … {max(n, 1) - 1}/{max(n, 1)}")
    return i, n


def chunk_ids(total_items: int, chunk_size: int, shard: tuple[int, int] = (0, 1)) -> list[int]:
    """The chunks of a dataset of ``total_items`` that ``shard`` owns."""
    if chunk_size < 1:
        raise ParameterError(f"chunk_size must be >= 1, got {chunk_size}")
    i, n = shard
    return [k for k in range(math.ceil(total_items / chunk_size)) if k % n == i]


def _part_paths(out_dir: Path, chunk: int) -> tuple[Path, Path]:
    return out_dir / "parts" / f"part-{chunk:05d}.tsv", out_dir / "parts" / f"part-{chunk:05d}.jsonl"


def _tsv(rows: list[dict[str, Any]], header: bool) -> bytes:
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=TSV_COLUMNS, delimiter="\t", lineterminator="\n", quoting=csv.QUOTE_MINIMAL)
    if header:
        writer.writeheader()
    writer.writerows(rows)
    return buffer.getvalue().encode("utf-8")


def _rows(item: dict[str, Any], paths: list[str]) -> tuple[dict[str, Any], dict[str, Any]]:
    options = {line[0]: line[3:] for line in item["options"]}
    answer = answer_text(item["answer"])
    question = format_question(item["question"], item["options"])
    tsv = {
        "index": item["index"], "question": question, "answer": answer, "image_path": repr(paths),
        "question_type": item["question_type"], "sub_question_type": item["sub_question_type"],
        "task_group": item["task_group"], "degradation_type": item["degradation_type"], "answer_type": item["answer_type"],
        **{k: options.get(k, "") for k in "ABCD"}, "scene_id": item["scene_id"], "record_id": item["record_id"],
        "degradation": json.dumps(item["degradation"], separators=(",", ":")),
    }
    chat = {
        "id": f"{item['index']:07d}", "images": paths,
        "system": None,
        "messages": [
            {"role": "user", "content": "<image>" * len(paths) + question},
            {"role": "assistant", "content": f"<answer>{answer}</answer>"},
        ],
        **{k: tsv[k] for k in ("question_type", "sub_question_type", "task_group", "degradation_type", "answer_type", "scene_id", "record_id")},
    }
    return tsv, chat


def _write_png(path: Path, image: np.ndarray) -> None:
    ok, data = cv2.imencode(".png", np.ascontiguousarray(image[:, :, ::-1]))
    if not ok:  # pragma: no cover - OpenCV encodes any uint8 image
        raise OSError(f"could not encode {path}")
    atomic_write_bytes(path, data.tobytes())


def export_split(
    dataset: SpaceDGDataset,
    out_dir: str | Path,
    *,
    shard: tuple[int, int] = (0, 1),
    chunk_size: int = 256,
    progress: bool = True,
) -> ExportSummary:
    """Export the chunks of ``dataset`` that ``shard`` owns (see the module docstring), then merge
    if every chunk of the dataset is present."""
    from tqdm import tqdm

    from spacedg.eval.scoring import ANSWER_PROMPT

    out = Path(out_dir)
    (out / "images").mkdir(parents=True, exist_ok=True)
    (out / "parts").mkdir(parents=True, exist_ok=True)
    mine = chunk_ids(len(dataset), chunk_size, shard)
    summary = ExportSummary(chunks_total=math.ceil(len(dataset) / chunk_size))
    todo = [k for k in mine if not all(p.is_file() for p in _part_paths(out, k))]
    summary.chunks_skipped = [k for k in mine if k not in todo]
    total = sum(min(chunk_size, len(dataset) - k * chunk_size) for k in todo)
    bar = tqdm(total=total, desc=f"export {dataset.split} shard {shard[0]}/{shard[1]}", unit="item", disable=not progress)
    for k in todo:
        tsv_rows, chat_rows = [], []
        for index in range(k * chunk_size, min(len(dataset), (k + 1) * chunk_size)):
            item = dataset[index]
            paths = []
            for v, image in enumerate(item["images"]):
                rel = f"images/{index:07d}_{v}.png"
                _write_png(out / rel, image.permute(1, 2, 0).numpy())
                paths.append(rel)
            tsv, chat = _rows(item, paths)
            chat["system"] = ANSWER_PROMPT
            tsv_rows.append(tsv)
            chat_rows.append(chat)
            bar.update(1)
        tsv_path, jsonl_path = _part_paths(out, k)
        atomic_write_bytes(jsonl_path, "".join(json.dumps(r, ensure_ascii=False) + "\n" for r in chat_rows).encode("utf-8"))
        atomic_write_bytes(tsv_path, _tsv(tsv_rows, header=True))  # the TSV last: it marks the chunk done
        summary.chunks_written.append(k)
        summary.items_written += len(tsv_rows)
    bar.close()
    summary.merged, summary.counts = merge_parts(out, summary.chunks_total, dataset.split)
    return summary


def merge_parts(out_dir: str | Path, chunks_total: int, split: str = "bench") -> tuple[bool, dict[str, dict[str, int]]]:
    """Write ``<split>.tsv``, ``<split>.jsonl`` and ``summary.json`` when all ``chunks_total`` parts
    exist; returns ``(merged, counts per question_type × degradation_type)``."""
    out = Path(out_dir)
    parts = [_part_paths(out, k) for k in range(chunks_total)]
    if not all(t.is_file() and j.is_file() for t, j in parts):
        return False, {}
    tsv_chunks, jsonl_chunks = [], []
    counts: dict[str, Counter[str]] = {}
    for k, (tsv_path, jsonl_path) in enumerate(parts):
        text = tsv_path.read_bytes()
        tsv_chunks.append(text if k == 0 else text.split(b"\n", 1)[1])
        jsonl = jsonl_path.read_bytes()
        jsonl_chunks.append(jsonl)
        for line in jsonl.decode("utf-8").splitlines():
            row = json.loads(line)
            counts.setdefault(row["question_type"], Counter())[row["degradation_type"]] += 1
    atomic_write_bytes(out / f"{split}.tsv", b"".join(tsv_chunks))
    atomic_write_bytes(out / f"{split}.jsonl", b"".join(jsonl_chunks))
    table = {q: dict(sorted(c.items())) for q, c in sorted(counts.items())}
    atomic_write_bytes(out / "summary.json", (json.dumps({"split": split, "counts": table}, indent=2) + "\n").encode("utf-8"))
    return True, table


def counts_table(counts: dict[str, dict[str, int]]) -> str:
    """A Markdown table of ``counts`` (question_type rows × degradation_type columns, with totals)."""
    columns = sorted({d for row in counts.values() for d in row}, key=lambda d: (d != "ori", d))
    lines = ["| question_type | " + " | ".join(columns) + " | total |", "|---|" + "---|" * (len(columns) + 1)]
    for q, row in counts.items():
        lines.append(f"| {q} | " + " | ".join(str(row.get(c, 0)) for c in columns) + f" | {sum(row.values())} |")
    totals = [sum(row.get(c, 0) for row in counts.values()) for c in columns]
    lines.append("| total | " + " | ".join(map(str, totals)) + f" | {sum(totals)} |")
    return "\n".join(lines)

"""Export a split to files: PNG images, a VLMEvalKit TSV, and chat JSONL for training tools.

Layout of ``out_dir`` (every path inside the exported rows is relative to it)::

    images/{index:07d}_{v}.png       view v of dataset item ``index`` (8-bit RGB PNG)
    parts/manifest.json              split, item count, shard size, fingerprint of the settings
    parts/part-{k:05d}.jsonl         chunk k as chat JSONL, written after its images
    parts/part-{k:05d}.tsv           chunk k as TSV rows (header included), written last
    <split>.tsv, <split>.jsonl       every chunk in index order (written once all chunks exist)
    spacedg_bench.tsv                the same bytes as bench.tsv (split ``bench`` only): the file the
                                     public evaluator reads, so the folder is VLMEvalKit's ``$LMUData``
    parts/answer-{k:05d}.jsonl       chunk k's answerability (one row per item, written before its parts)
    summary.json                     counts per question_type × degradation_type; ``answerability``:
                                     per degradation × severity the share of items whose named objects
                                     are discernible, and per item its objects' contrasts
                                     (:mod:`spacedg.data.answerability`)

**Chunks and shards.** Items are grouped into chunks of ``shard_size`` consecutive dataset
indices (chunk ``k`` = indices ``[k·shard_size, (k+1)·shard_size)``); ``shard=(i, n)``
processes the chunks with ``k % n == i``, so ``n`` processes or machines split the work
disjointly and together completely. A chunk whose two part files exist is skipped, so an
interrupted export resumes where it stopped. Every file is written atomically (temporary
sibling, then rename), so a crash never leaves a half-written file; an interrupted chunk just
has some images and no parts, and is redone, after its own leftover temporary files
(``images/.NNNNNNN_v.png.*.tmp``, ``parts/.part-KKKKK.*.tmp`` of that chunk only, so shards
working on other chunks are never disturbed) are removed. Items are a pure function of the dataset's
arguments, so re-running a chunk anywhere writes the same bytes. ``parts/manifest.json`` pins
the settings: a shard started with other arguments on the same folder fails instead of mixing
two exports.

**TSV** (what the public SpaceDG evaluator and VLMEvalKit read with
``pandas.read_csv(path, sep="\\t")``), in the public bench's format (names:
:mod:`spacedg.data.public_format`; columns and dialect: :mod:`spacedg.data.bench_table`):
``index`` (the dataset index, int), ``question`` (with the option lines for MCQ), ``answer``
(letter, yes/no, integer, number, ``[a, b, c]``), ``image_path`` (a Python list literal of
relative paths, ``"['images/0000000_0.png', ...]"``, which VLMEvalKit's ``toliststr`` evaluates;
the public class finds them under ``$LMUData``),
``question_type``, ``sub_question_type`` (the public names: **empty** for single-view distance,
counting, bounding size and existence, ``inter_object_distance`` for the inter-object distance),
``task_group``, ``degradation_type`` (``ori`` for clean): the eight columns the public loader
requires, then ``answer_type`` (how the row is scored: the public routing of its names),
``A``–``D`` (option texts, empty for non-MCQ, which pandas reads as NaN as VLMEvalKit expects),
``scene_id``, ``record_id`` (``scene/question_type/internal sub type/hash``) and ``degradation``
(the provenance as compact JSON), which the public loader carries along unused. Existence
questions are exported as two lettered options (``A. yes`` / ``B. no`` in a seeded order) with
the letter as the answer, as the public evaluator scores them. Fields holding tabs, newlines or
quotes are quoted CSV-style (``"..."`` with ``""`` for a quote), which is pandas' default
dialect, so multi-line questions read back unchanged.

**Chat JSONL** (LLaMA-Factory ShareGPT style, ``"messages"`` + ``"images"`` columns): ``{"id",
"index", "images": [paths], "system": ANSWER_PROMPT, "messages": [{"role": "user", "content":
"<image>"×V + question}, {"role": "assistant", "content": "<answer>…</answer>"}], ...metadata,
"geometry"}`` with exactly one ``<image>`` placeholder per image, in view order; the question,
answer and names are the TSV row's (the text the bench shows); ``geometry`` is the record's
geometry block (poses, boxes, visibility: what the answer was computed from).
"""

from __future__ import annotations

import hashlib
import json
import math
import time
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass, field
from os import PathLike
from pathlib import Path
from typing import Any

from spacedg._checks import check_bool, check_int, short_repr
from spacedg.data.answerability import (
    ROSE_K,
    VIEWING_FLARE,
    WEBER_THRESHOLD,
    answerability_table,
    condition_of,
    item_answerability,
    object_id_maps,
    share_by_condition,
)
from spacedg.data.bench_table import tsv_bytes
from spacedg.data.chain import CLEAN
from spacedg.data.chat import ANSWER_PROMPT
from spacedg.data.dataset import SpaceDGDataset
from spacedg.data.pipeline import ItemPlan, degrade_device
from spacedg.data.public_format import PUBLIC_BENCH_NAME, public_fields, public_mismatch
from spacedg.data.shards import chunk_ids, parse_shard, shard_from_env
from spacedg.errors import InvalidDataError, ParameterError, SpaceDGError
from spacedg.files import atomic_write_bytes, remove_stale_temps, write_png
from spacedg.plugins.answers import answer_text

__all__ = [
    "DEFAULT_SHARD_SIZE",
    "ExportSummary",
    "MergeResult",
    "chunk_ids",
    "counts_table",
    "dataset_fingerprint",
    "export_bench",
    "export_split",
    "merge_parts",
    "parse_shard",
    "shard_from_env",
]

#: Items per chunk (the unit of resuming and of sharding) unless told otherwise.
DEFAULT_SHARD_SIZE = 256
#: Version of the exported format (2: the public bench's names and existence as lettered options).
_MANIFEST_VERSION = 2


# ---------------------------------------------------------------- results
@dataclass
class MergeResult:
    """Outcome of :func:`merge_parts`. Truthy when the merged files were written.

    Attributes:
        complete: every chunk of the export exists and ``<split>.tsv``/``.jsonl`` were written.
        missing: chunk ids whose parts are absent (empty when complete).
        counts: ``question_type → degradation_type → items`` (empty when incomplete).
        table: :func:`counts_table` of ``counts`` (empty when incomplete).
        mismatches: ``"question_type/sub_question_type"`` → why the public evaluator would score
            those rows with another answer type than ours (empty for the built-in families; see
            :func:`~spacedg.data.public_format.public_mismatch`).
        answerability: ``degradation → severity → {items, with_objects, answerable, share}``
            (:func:`~spacedg.data.answerability.share_by_condition`; empty when the export measured none).
        answerability_table: the same as a Markdown table.
    """

    complete: bool
    missing: list[int] = field(default_factory=list)
    counts: dict[str, dict[str, int]] = field(default_factory=dict)
    table: str = ""
    mismatches: dict[str, str] = field(default_factory=dict)
    answerability: dict[str, Any] = field(default_factory=dict)
    answerability_table: str = ""

    def __bool__(self) -> bool:
        return self.complete


@dataclass
class ExportSummary:
    """What one :func:`export_bench` call did.

    Attributes:
        split: the dataset's split.
        items_total: ``len(dataset)``.
        shard_size: items per chunk.
        chunks_total: chunks of the whole export, ``ceil(items_total / shard_size)``.
        shard: ``(i, n)`` this call processed.
        chunks_written / chunks_skipped: this shard's chunks exported now / found finished.
        items_written: items exported now (rendered, images and rows written).
        seconds: wall time of the call, merge included.
        merge: the merge attempt at the end (complete or not).
    """

    split: str
    items_total: int
    shard_size: int
    chunks_total: int
    shard: tuple[int, int] = (0, 1)
    chunks_written: list[int] = field(default_factory=list)
    chunks_skipped: list[int] = field(default_factory=list)
    items_written: int = 0
    seconds: float = 0.0
    merge: MergeResult = field(default_factory=lambda: MergeResult(False))

    @property
    def merged(self) -> bool:
        """Whether the merged ``<split>.tsv`` / ``.jsonl`` exist after this call."""
        return self.merge.complete

    @property
    def counts(self) -> dict[str, dict[str, int]]:
        return self.merge.counts


# ---------------------------------------------------------------- sharding
# parse_shard, shard_from_env, chunk_ids: spacedg.data.shards (light: `qa build --shard` reads them too)


def _chunk_range(k: int, shard_size: int, total: int) -> range:
    return range(k * shard_size, min(total, (k + 1) * shard_size))


# ---------------------------------------------------------------- manifest
def dataset_fingerprint(dataset: SpaceDGDataset) -> str:
    """SHA-256 (16 hex) of what decides the exported content: split, chains, seeds, image size,
    severity, clean probability, and every question record (id, text, options, answer, views).
    The renderer backend is not part of it (backends agree to float precision); where the
    degradations run is, when they run on a torch device (its JPEG codec and its noise draws are
    not the CPU path's: shards of one export must not mix them), as ``"torch:<device type>"``."""

    digest = hashlib.sha256()
    settings: dict[str, Any] = {
        "split": dataset.split, "chains": [chain.text for chain in dataset.chains], "seed": dataset.seed, "severity": dataset.severity,
        "clean_prob": dataset.clean_prob, "epoch": dataset.epoch,
        "image_size": list(dataset.options.image_size) if dataset.options.image_size else None,
    }
    device = degrade_device(dataset.options)
    if device is not None:
        settings["degradations_on"] = f"torch:{device.type}"
    digest.update(json.dumps(settings, sort_keys=True).encode())
    for record in dataset.records:
        digest.update(json.dumps([record.id, record.question, list(record.options), answer_text(record.answer), list(record.views)]).encode())
    return digest.hexdigest()[:16]


def _manifest(dataset: SpaceDGDataset, shard_size: int) -> dict[str, Any]:
    return {
        "version": _MANIFEST_VERSION, "split": dataset.split, "items": len(dataset), "shard_size": shard_size,
        "chunks": math.ceil(len(dataset) / shard_size), "fingerprint": dataset_fingerprint(dataset),
    }


def _read_manifest(out: Path) -> dict[str, Any] | None:
    path = out / "parts" / "manifest.json"
    if not path.is_file():
        return None
    try:
        return dict(json.loads(path.read_text(encoding="utf-8")))
    except (ValueError, TypeError) as err:
        raise InvalidDataError(f"{path}: not a valid export manifest ({err}); delete it (and parts/) to start over") from None


def _claim_manifest(out: Path, manifest: dict[str, Any]) -> None:
    """Write ``parts/manifest.json``, or check that the one there describes the same export."""
    found = _read_manifest(out)
    if found is None:
        atomic_write_bytes(out / "parts" / "manifest.json", (json.dumps(manifest, indent=2) + "\n").encode())
        return
    if found.get("version") != manifest["version"]:
        raise ParameterError(
            f"{out} holds an export in format version {found.get('version')!r}, this spacedg writes version "
            f"{manifest['version']} (the public bench's names, existence as lettered options); its parts cannot be "
            "mixed: use a new --out folder (or delete this one) and export again"
        )
    differ = [k for k in ("split", "items", "shard_size", "fingerprint") if found.get(k) != manifest[k]]
    if differ:
        what = ", ".join(f"{k} {found.get(k)!r} there vs {manifest[k]!r} now" for k in differ)
        raise ParameterError(
            f"{out} holds an export made with other settings ({what}). Every shard must use the same arguments "
            "apart from --shard (same scenes, degradations, seed, image size, --shard-size); use a new --out folder "
            "to export different settings"
        )


# ---------------------------------------------------------------- rows
def _part_paths(out: Path, chunk: int) -> tuple[Path, Path]:
    """``(tsv, jsonl)`` part files of ``chunk``."""
    return out / "parts" / f"part-{chunk:05d}.tsv", out / "parts" / f"part-{chunk:05d}.jsonl"


def _chunk_done(out: Path, chunk: int) -> bool:
    return all(p.is_file() for p in _part_paths(out, chunk))


def _rows(item: dict[str, Any], paths: list[str], system: str) -> tuple[dict[str, Any], dict[str, Any]]:
    """The TSV row and the chat JSONL row of one dataset item whose images are at ``paths``, in the
    public bench's format (:func:`~spacedg.data.public_format.public_fields`: public names, existence
    as lettered options)."""
    public = public_fields(item)
    options = {line[0]: line[3:] for line in public["options"]}  # "A. text" → {"A": "text"}
    answer, question = public["answer"], public["question"]
    meta = {k: public[k] if k in public else item[k]
            for k in ("question_type", "sub_question_type", "task_group", "degradation_type", "answer_type", "scene_id", "record_id")}
    tsv = {
        "index": int(item["index"]), "question": question, "answer": answer, "image_path": repr(list(paths)), **meta,
        **{k: options.get(k, "") for k in "ABCD"},
        "degradation": json.dumps(item["degradation"], separators=(",", ":")),
    }
    chat = {
        "id": f"{item['index']:07d}", "index": int(item["index"]), "images": list(paths), "system": system,
        "messages": [
            {"role": "user", "content": "<image>" * len(paths) + question},
            {"role": "assistant", "content": f"<answer>{answer}</answer>"},
        ],
        **meta, "views": list(item["views"]),
    }
    return tsv, chat


def _item(dataset: SpaceDGDataset, plan: ItemPlan) -> dict[str, Any]:
    """The item of ``plan`` (``dataset[plan.index]``), with an error that names its scene folder if it fails."""
    try:
        return dataset.sample(plan)
    except (SpaceDGError, OSError) as err:
        record = plan.record
        folder = dataset.scene_dirs.get(record.scene_id, record.scene_id)
        raise InvalidDataError(f"item {plan.index} ({plan.degradation_type} of {record.id}) failed: scene {folder}: {err}") from err


def _remove_chunk_temps(out: Path, k: int, shard_size: int, total: int) -> None:
    """Remove the temporary files a killed export of chunk ``k`` left (its images' and parts')."""
    indices = _chunk_range(k, shard_size, total)

    def image_of_chunk(name: str) -> bool:
        stem, _, view = name.removesuffix(".png").partition("_")
        return name.endswith(".png") and len(stem) == 7 and stem.isdigit() and view.isdigit() and int(stem) in indices

    remove_stale_temps(out / "images", image_of_chunk)
    remove_stale_temps(out / "parts", [p.name for p in (*_part_paths(out, k), _answer_path(out, k))])


def _answer_path(out: Path, chunk: int) -> Path:
    return out / "parts" / f"answer-{chunk:05d}.jsonl"


def _answer_row(dataset: SpaceDGDataset, plan: ItemPlan, item: dict[str, Any], cache: dict[Any, Any]) -> dict[str, Any]:
    """The answerability row of one exported item (:mod:`spacedg.data.answerability`)."""
    scene = dataset.scene(plan.record.scene_id)
    images = item["images"].permute(0, 2, 3, 1).numpy()
    maps = object_id_maps(scene, plan.views, item["degradation"], dataset.options, cache)
    result = item_answerability(plan.record, images, maps)
    degradation, severity = condition_of(plan.degradation_type, item["degradation"])
    return {"index": plan.index, "degradation_type": degradation, "severity": severity, **result.to_dict()}


def _export_chunk(
    dataset: SpaceDGDataset, out: Path, k: int, shard_size: int, system: str, bar: Any, answerability: bool = False,
) -> int:
    """Render chunk ``k``, write its images, its answerability rows (if asked), then its JSONL part, then its
    TSV part; returns its item count."""
    _remove_chunk_temps(out, k, shard_size, len(dataset))
    tsv_rows, chat_rows, answer_rows = [], [], []
    cache: dict[Any, Any] = {}
    for index in _chunk_range(k, shard_size, len(dataset)):
        plan = dataset.plan(index)
        item = _item(dataset, plan)
        paths = []
        for v, image in enumerate(item["images"]):
            rel = f"images/{index:07d}_{v}.png"
            write_png(out / rel, image.permute(1, 2, 0).numpy(), "image")
            paths.append(rel)
        tsv, chat = _rows(item, paths, system)
        chat["geometry"] = plan.record.geometry  # what the answer was computed from (spacedg review shows it)
        tsv_rows.append(tsv)
        chat_rows.append(chat)
        if answerability:
            answer_rows.append(_answer_row(dataset, plan, item, cache))
        bar.update(1)
    tsv_path, jsonl_path = _part_paths(out, k)
    if answerability:
        atomic_write_bytes(_answer_path(out, k), "".join(json.dumps(r) + "\n" for r in answer_rows).encode("utf-8"))
    atomic_write_bytes(jsonl_path, "".join(json.dumps(r, ensure_ascii=False) + "\n" for r in chat_rows).encode("utf-8"))
    atomic_write_bytes(tsv_path, tsv_bytes(tsv_rows, header=True))
    return len(tsv_rows)


# ---------------------------------------------------------------- export
def export_bench(
    dataset: SpaceDGDataset,
    out_dir: str | Path,
    *,
    shard: tuple[int, int] = (0, 1),
    shard_size: int = DEFAULT_SHARD_SIZE,
    progress: bool = True,
    answerability: bool | None = None,
) -> ExportSummary:
    """Export the chunks of ``dataset`` that ``shard=(i, n)`` owns, then merge if every chunk exists.

    Works for any split (``bench``: each question × clean + each chain; ``train``/``val``: one
    item per question). See the module docstring for the layout, formats and resume rules.

    Args:
        dataset: the dataset to export (its items are rendered in index order).
        out_dir: output folder (created); shared by every shard of one export.
        shard: ``(i, n)``: process the chunks ``k`` with ``k % n == i``.
        shard_size: items per chunk (the unit of resuming); every shard must use the same.
        progress: show a tqdm bar over this shard's items.
        answerability: measure whether each item's named objects are discernible in its images
            (:mod:`spacedg.data.answerability`; one extra instance-id render per question and lens)
            and keep it in ``summary.json``; ``None`` = for the ``bench`` split only.

    Raises:
        ParameterError: a bad ``shard``/``shard_size``, or ``out_dir`` holds an export of other settings.
        InvalidDataError: an item cannot be rendered (the message names its scene folder).
    """
    from tqdm import tqdm

    started = time.perf_counter()
    out = _check_export_arguments(dataset, out_dir, shard, progress)
    measure = dataset.split == "bench" if answerability is None else check_bool(answerability, "export_bench: answerability")
    mine = chunk_ids(len(dataset), shard_size, shard)
    (out / "images").mkdir(parents=True, exist_ok=True)
    (out / "parts").mkdir(parents=True, exist_ok=True)
    _claim_manifest(out, _manifest(dataset, shard_size))
    summary = ExportSummary(dataset.split, len(dataset), shard_size, math.ceil(len(dataset) / shard_size), tuple(shard))
    todo = [k for k in mine if not _chunk_done(out, k)]
    summary.chunks_skipped = sorted(set(mine) - set(todo))
    total = sum(len(_chunk_range(k, shard_size, len(dataset))) for k in todo)
    with tqdm(total=total, desc=f"export {dataset.split} {shard[0]}/{shard[1]}", unit="item", disable=not progress) as bar:
        for k in todo:
            summary.items_written += _export_chunk(dataset, out, k, shard_size, ANSWER_PROMPT, bar, bool(measure))
            summary.chunks_written.append(k)
    summary.merge = merge_parts(out)
    summary.seconds = time.perf_counter() - started
    return summary


def _check_export_arguments(dataset: Any, out_dir: Any, shard: Any, progress: Any) -> Path:
    """``out_dir`` as a Path, after checking every argument of :func:`export_bench` (ParameterError naming it)."""
    if not isinstance(dataset, SpaceDGDataset):
        raise ParameterError(f"export_bench: dataset must be a SpaceDGDataset, got {short_repr(dataset)}")
    if not isinstance(out_dir, (str, PathLike)) or not str(out_dir).strip():
        raise ParameterError(f"export_bench: out_dir must be a folder path, got {short_repr(out_dir)}")
    if isinstance(shard, (str, bytes)) or not isinstance(shard, (tuple, list)) or len(shard) != 2:
        raise ParameterError(f"export_bench: shard must be (i, n) with 0 <= i < n, e.g. (0, 1); got {short_repr(shard)}")
    n = check_int(shard[1], "export_bench: shard n", minimum=1)
    check_int(shard[0], "export_bench: shard i", minimum=0, maximum=n - 1)
    check_bool(progress, "export_bench: progress")
    return Path(out_dir)


#: The same function; the name reads better for ``train``/``val`` exports.
export_split = export_bench


# ---------------------------------------------------------------- merge
def merge_parts(out_dir: str | Path, *, verbose: bool = False) -> MergeResult:
    """Concatenate every chunk's parts into ``<split>.tsv`` and ``<split>.jsonl`` (index order,
    one header) and write ``summary.json``, if every chunk named by ``parts/manifest.json``
    exists; otherwise write nothing and report the missing chunks.

    Safe to call from several processes at once (each file is replaced atomically with the
    same bytes). With ``verbose`` the counts table is printed.

    Raises:
        ParameterError: ``out_dir`` has no export manifest.
        InvalidDataError: a part holds other rows than its chunk's indices (a foreign or edited file).
    """
    out = Path(out_dir)
    manifest = _read_manifest(out)
    if manifest is None:
        raise ParameterError(f"{out}: no parts/manifest.json; not a spacedg export folder (run spacedg export first)")
    chunks, size, items, split = int(manifest["chunks"]), int(manifest["shard_size"]), int(manifest["items"]), str(manifest["split"])
    missing = [k for k in range(chunks) if not _chunk_done(out, k)]
    if missing:
        return MergeResult(False, missing)
    tsv_chunks, jsonl_chunks = [], []
    counts: dict[str, Counter[str]] = {}
    mismatches: dict[str, str] = {}
    for k in range(chunks):
        tsv_path, jsonl_path = _part_paths(out, k)
        part = tsv_path.read_bytes()
        tsv_chunks.append(part if k == 0 else part.split(b"\n", 1)[1])
        jsonl = jsonl_path.read_bytes()
        jsonl_chunks.append(jsonl)
        rows = [json.loads(line) for line in jsonl.decode("utf-8").splitlines()]
        if [r.get("index") for r in rows] != list(_chunk_range(k, size, items)):
            raise InvalidDataError(f"{jsonl_path}: rows are not the indices of chunk {k}; delete its two part files and rerun")
        for row in rows:
            counts.setdefault(row["question_type"], Counter())[row["degradation_type"]] += 1
            if "answer_type" in row:
                why = public_mismatch(row)
                if why:
                    mismatches.setdefault(f"{row['question_type']}/{row['sub_question_type']}", why)
    table = {q: dict(sorted(c.items(), key=lambda kv: (kv[0] != CLEAN, kv[0]))) for q, c in sorted(counts.items())}
    tsv = b"".join(tsv_chunks)
    atomic_write_bytes(out / f"{split}.tsv", tsv)
    if split == "bench":  # VLMEvalKit's SpaceDGBench reads $LMUData/spacedg_bench.tsv: this folder is its LMUData
        atomic_write_bytes(out / f"{PUBLIC_BENCH_NAME}.tsv", tsv)
    atomic_write_bytes(out / f"{split}.jsonl", b"".join(jsonl_chunks))
    by_degradation: Counter[str] = Counter()
    for row in table.values():
        by_degradation.update(row)
    summary = {
        "split": split, "items": items, "chunks": chunks, "shard_size": size, "fingerprint": manifest.get("fingerprint"),
        "counts": table, "by_degradation": dict(sorted(by_degradation.items(), key=lambda kv: (kv[0] != CLEAN, kv[0]))),
        "by_question_type": {q: sum(row.values()) for q, row in table.items()},
        "public_evaluator_mismatches": mismatches,
    }
    answers = _merge_answerability(out, chunks)
    if answers:
        summary["answerability"] = answers
    atomic_write_bytes(out / "summary.json", (json.dumps(summary, indent=2) + "\n").encode("utf-8"))
    text = counts_table(table)
    shares = answers.get("by_condition", {})
    answer_text_table = answerability_table(shares) if shares else ""
    if verbose:
        print(text)
        if answer_text_table:
            print(answer_text_table)
    return MergeResult(True, [], table, text, mismatches, shares, answer_text_table)


def _merge_answerability(out: Path, chunks: int) -> dict[str, Any]:
    """``summary.json``'s ``answerability`` block from every chunk's answer part; ``{}`` unless every chunk has one."""
    paths = [_answer_path(out, k) for k in range(chunks)]
    if not paths or not all(p.is_file() for p in paths):
        return {}
    rows = [json.loads(line) for p in paths for line in p.read_text(encoding="utf-8").splitlines() if line.strip()]
    return {
        "criterion": {"weber_threshold": WEBER_THRESHOLD, "viewing_flare": VIEWING_FLARE, "rose_k": ROSE_K},
        "by_condition": share_by_condition(rows),
        "items": {str(r["index"]): {k: v for k, v in r.items() if k != "index"} for r in rows},
    }


def counts_table(counts: Mapping[str, Mapping[str, int]]) -> str:
    """A Markdown table of ``counts``: question_type rows × degradation_type columns (``ori``
    first, then by name), with a total column and a total row."""
    columns = sorted({d for row in counts.values() for d in row}, key=lambda d: (d != CLEAN, d))
    lines = ["| question_type | " + " | ".join(columns) + " | total |", "|---|" + "---:|" * (len(columns) + 1)]
    for q, row in counts.items():
        lines.append(f"| {q} | " + " | ".join(str(row.get(c, 0)) for c in columns) + f" | {sum(row.values())} |")
    totals = [sum(row.get(c, 0) for row in counts.values()) for c in columns]
    lines.append("| total | " + " | ".join(map(str, totals)) + f" | {sum(totals)} |")
    return "\n".join(lines)

"""``spacedg predict``: run a local transformers VLM over a bench, batched and resumable.

Sources: an exported bench (:func:`~spacedg.eval.bench.load_bench`; images read from its PNGs)
or a :class:`~spacedg.data.dataset.SpaceDGDataset` (``split="bench"``; each pending item rendered
online, nothing written but the predictions).

Output: ``preds.jsonl``, one line per item, written after each batch: the bench row (so the
file is scorable on its own), ``prediction`` (the raw generated text), ``model``, ``variant``;
``cot`` adds ``stage1`` and ``degradation_guess``. The sidecar ``preds.jsonl.meta.json`` records
the model, the variant, the bench's fingerprint, the generation settings and every prompt text.

Resuming: an existing output is read, its answered indices are skipped and new lines are
appended. A sidecar that disagrees (another bench, model, variant, prompt or generation
setting) is an error, so one file never mixes two runs; an output with no prediction line yet
starts over whatever its sidecar says. A torn last line (a crash mid-write) is dropped and redone.

One writer per output: a run holds ``<out>.lock`` (``fcntl.flock``, freed when it ends, even by
``kill -9``), so a second ``predict`` on the same ``--out`` fails at once naming the first's pid
instead of appending the same items again. Every setting is checked before the sidecar is written.

Work that a sample does not need is skipped: ``no_image`` generates once per distinct question
(the same question under ten degradations is one prompt) and copies the answer; images are
loaded or rendered only for pending items.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from spacedg.data.chat import item_images
from spacedg.data.public_format import public_fields
from spacedg.errors import FileFormatError, InvalidDataError, ParameterError
from spacedg.eval.bench import Bench, BenchRow, row_from_mapping
from spacedg.eval.predictions import meta_path
from spacedg.eval.prompts import (
    VARIANTS,
    conversation,
    cot_followup,
    known_degradations,
    parse_degradation_guess,
    prompt_texts,
)
from spacedg.files import atomic_write_bytes, exclusive_lock, read_rgb

__all__ = ["PredictSummary", "Source", "bench_source", "dataset_source", "predict", "shard_path"]

#: Version of the prediction file layout (in the sidecar).
PREDICTIONS_VERSION = 1


@dataclass
class Source:
    """Rows to answer and a way to get their images.

    Attributes:
        name: where the rows come from (a bench path or a dataset description).
        fingerprint: identifies the rows' content (the bench TSV hash or the dataset fingerprint).
        indices: every item index, in order.
        row: index → :class:`BenchRow` (cheap; no image work).
        images: index → the row's images, uint8 H×W×3 RGB, in view order.
    """

    name: str
    fingerprint: str
    indices: list[int]
    row: Callable[[int], BenchRow]
    images: Callable[[int], list[np.ndarray]]


def bench_source(bench: Bench) -> Source:
    """A :class:`Source` over an exported bench; images are read from its PNG files."""

    def images(index: int) -> list[np.ndarray]:
        row = bench.by_index[index]
        out = []
        for view in range(len(row.image_paths)):
            path = bench.image_file(row, view)
            image = read_rgb(path)
            if image is None:
                raise InvalidDataError(f"{path}: missing or unreadable image of bench item {index}; re-export the bench")
            out.append(image)
        return out

    return Source(str(bench.path), bench.fingerprint, [r.index for r in bench.rows], bench.by_index.__getitem__, images)


def dataset_source(dataset: Any) -> Source:
    """A :class:`Source` over a :class:`~spacedg.data.dataset.SpaceDGDataset`: rows from its
    plan (no rendering), images rendered online for the items asked for."""
    from spacedg.data.export import dataset_fingerprint

    def row(index: int) -> BenchRow:
        plan = dataset.plan(index)
        record, name = plan.record, plan.degradation_type
        fields = {  # the row the export writes for this item (public names, existence as lettered options)
            "index": index, **public_fields(record), "task_group": record.task_group.value,
            "degradation_type": name, "scene_id": record.scene_id, "record_id": record.id,
            "degradation": dataset.provenance(index),
        }
        return row_from_mapping(fields, f"dataset item {index}")

    def images(index: int) -> list[np.ndarray]:
        item = dataset[index]
        return item_images(item)

    name = f"SpaceDGDataset(split={dataset.split!r}, items={len(dataset)})"
    # the rows are in the public bench's format (existence lettered): a run that answered the earlier
    # yes/no rows of the same dataset is another bench, not one to resume
    return Source(name, f"{dataset_fingerprint(dataset)}-public", list(range(len(dataset))), row, images)


@dataclass
class PredictSummary:
    """What one :func:`predict` call did: items in the source, found answered, answered now,
    model calls made (a ``cot`` item makes two; ``no_image`` shares calls), and wall seconds."""

    total: int
    skipped: int
    answered: int
    generated: int
    seconds: float
    out: Path


def shard_path(out: Path, shard: tuple[int, int]) -> Path:
    """The file shard ``(i, n)`` writes: ``preds.jsonl`` → ``preds.shard0of4.jsonl`` (``n = 1``: ``out``).
    ``spacedg eval`` merges the shards of one model and variant back into one run."""
    i, n = shard
    return out if n == 1 else out.with_name(f"{out.stem}.shard{i}of{n}{out.suffix}")


# ------------------------------------------------------------------ resume
def _existing(out: Path, meta: dict[str, Any]) -> set[int]:
    side = meta_path(out)
    if not out.exists() or not out.read_bytes().strip():
        return set()  # nothing answered yet: whatever a sidecar says, this run starts the file over
    if not side.exists():
        raise InvalidDataError(f"{out} exists but has no {side.name}; it was not written by spacedg predict. Choose another --out")
    try:
        old = json.loads(side.read_text(encoding="utf-8"))
    except json.JSONDecodeError as err:
        raise FileFormatError(f"{side}: not JSON ({err.msg}); delete it and {out.name} to start over") from None
    for key in ("bench_fingerprint", "model_path", "variant", "generation", "prompts", "version", "shard"):
        if old.get(key) != meta.get(key):
            raise InvalidDataError(
                f"{out} holds a run with another {key} ({old.get(key)!r}, now {meta.get(key)!r}); "
                "use another --out, or delete the file to start over"
            )
    data = out.read_bytes()
    lines = data.split(b"\n")
    keep, done = [], set()
    for number, line in enumerate(lines, 1):
        if not line.strip():
            continue
        try:
            value = json.loads(line)
            done.add(int(value["index"]))
            keep.append(line)
        except (ValueError, KeyError, TypeError):
            if number < len(lines) - 1:  # only the last line may be torn by a crash
                raise FileFormatError(f"{out}:{number}: not a prediction line; the file was edited or corrupted") from None
    if len(keep) != sum(1 for line in lines if line.strip()):
        atomic_write_bytes(out, b"".join(line + b"\n" for line in keep))
    return done


# ------------------------------------------------------------------ generation
def _work_units(source: Source, pending: Sequence[int], variant: str) -> list[list[int]]:
    """Pending indices grouped by prompt: one group per item, except ``no_image``, where every
    item asking the same question (the same record under each degradation) shares one call."""
    if variant != "no_image":
        return [[i] for i in pending]
    groups: dict[str, list[int]] = {}
    for index in pending:
        groups.setdefault(source.row(index).question, []).append(index)
    return list(groups.values())


def predict(
    model: str | Path | tuple[Any, Any],
    source: Source,
    out: str | Path,
    *,
    variant: str = "default",
    model_name: str | None = None,
    batch_size: int = 8,
    max_new_tokens: int | None = None,
    limit: int | None = None,
    shard: tuple[int, int] = (0, 1),
    device: str = "cpu",
    dtype: str = "auto",
    min_pixels: int | None = None,
    max_pixels: int | None = None,
    progress: bool = True,
) -> PredictSummary:
    """Answer every item of ``source`` with a VLM and append the answers to ``out``.

    Args:
        model: a model folder (loaded with :func:`spacedg.vlm.load_vlm`) or ``(model, processor)``.
        source: :func:`bench_source` or :func:`dataset_source`.
        out: the ``.jsonl`` to write (and resume).
        variant: one of :data:`~spacedg.eval.prompts.VARIANTS`.
        model_name: display name in reports (default: the folder's name).
        batch_size: conversations per ``generate`` call.
        max_new_tokens: generation budget (default 32; 512 for ``cot``, whose answers reason).
        limit: answer at most this many pending items (a smoke run).
        shard: ``(i, n)``: answer only the items at positions ``p`` with ``p % n == i`` (one
            process or GPU of ``n``; write each shard to its own file, see :func:`shard_path`).
        device / dtype / min_pixels / max_pixels: see :func:`spacedg.vlm.load_vlm`.
        progress: show a progress bar.
    """
    if variant not in VARIANTS:
        raise ParameterError(f"unknown prompt variant {variant!r}; choose one of {', '.join(VARIANTS)}")
    if batch_size < 1:
        raise ParameterError(f"--batch-size must be >= 1, got {batch_size}")
    out = Path(out)
    if out.suffix != ".jsonl":
        raise ParameterError(f"--out {out}: predictions are written as JSON lines; name the file *.jsonl")
    tokens = max_new_tokens if max_new_tokens is not None else (512 if variant == "cot" else 32)
    if isinstance(tokens, bool) or not isinstance(tokens, int) or tokens < 1:
        raise ParameterError(f"--max-new-tokens must be a whole number >= 1, got {max_new_tokens!r}")
    if limit is not None and limit < 1:
        raise ParameterError(f"--limit must be >= 1, got {limit}")
    if isinstance(model, tuple):
        vlm, processor = model
        model_path = str(getattr(vlm, "name_or_path", "") or "in-memory model")
    else:
        model_path = str(Path(model).resolve())
        vlm = processor = None
    name = model_name or Path(model_path).name
    meta = {
        "format": "spacedg-predictions", "version": PREDICTIONS_VERSION, "model": name, "model_path": model_path,
        "variant": variant, "bench": source.name, "bench_fingerprint": source.fingerprint,
        "generation": {"max_new_tokens": tokens, "do_sample": False}, "image_pixels": {"min": min_pixels, "max": max_pixels},
        "prompts": prompt_texts(), "shard": list(shard),
    }
    out.parent.mkdir(parents=True, exist_ok=True)
    with exclusive_lock(out.with_name(out.name + ".lock"), f"{out} is being written by another spacedg predict"):
        return _run(model, source, out, meta, name, variant, tokens, batch_size, limit, shard, device, dtype,
                    min_pixels, max_pixels, progress, vlm, processor)


def _run(model: Any, source: Source, out: Path, meta: dict[str, Any], name: str, variant: str, tokens: int, batch_size: int,
         limit: int | None, shard: tuple[int, int], device: str, dtype: str, min_pixels: int | None, max_pixels: int | None,
         progress: bool, vlm: Any, processor: Any) -> PredictSummary:
    """:func:`predict` once the output's lock is held."""
    from tqdm.auto import tqdm

    from spacedg.vlm import generate, load_vlm, pixel_budget

    done = _existing(out, meta)
    pending = [i for pos, i in enumerate(source.indices) if pos % shard[1] == shard[0] and i not in done]
    if limit is not None:
        pending = pending[:limit]
    start = time.perf_counter()
    owned = sum(1 for pos in range(len(source.indices)) if pos % shard[1] == shard[0])
    summary = PredictSummary(owned, len(done), 0, 0, 0.0, out)
    if not pending:
        return summary
    if vlm is None:
        vlm, processor = load_vlm(model, device=device, dtype=dtype, min_pixels=min_pixels, max_pixels=max_pixels)
    meta["image_pixels"] = pixel_budget(processor)  # the budget in force: the model's saved one unless overridden
    atomic_write_bytes(meta_path(out), json.dumps(meta, indent=2).encode() + b"\n")
    names = known_degradations()
    bar = tqdm(total=len(pending), desc=f"predict {name} [{variant}]", unit="item", disable=not progress)
    with out.open("ab") as handle:
        units = _work_units(source, pending, variant)
        for start_unit in range(0, len(units), batch_size):
            batch = units[start_unit:start_unit + batch_size]
            rows = {index: source.row(index) for unit in batch for index in unit}
            leaders = [rows[unit[0]] for unit in batch]
            images = [[] if variant == "no_image" else source.images(row.index) for row in leaders]
            chats = [conversation(row, variant, len(imgs)) for row, imgs in zip(leaders, images)]
            stage1: list[str] = []
            if variant == "cot":
                stage1 = generate(vlm, processor, chats, images, max_new_tokens=128)
                chats = [cot_followup(chat, text, row) for chat, text, row in zip(chats, stage1, leaders)]
                summary.generated += len(chats)
            answers = generate(vlm, processor, chats, images, max_new_tokens=tokens)
            summary.generated += len(chats)
            lines = []
            for k, unit in enumerate(batch):
                for index in unit:
                    line = {**rows[index].to_dict(), "prediction": answers[k], "model": name, "variant": variant}
                    if variant == "cot":
                        line["stage1"] = stage1[k]
                        line["degradation_guess"] = parse_degradation_guess(stage1[k], names)
                    lines.append(json.dumps(line, ensure_ascii=False).encode() + b"\n")
            handle.write(b"".join(lines))
            handle.flush()
            answered = sum(len(unit) for unit in batch)
            summary.answered += answered
            bar.update(answered)
        os.fsync(handle.fileno())
    bar.close()
    summary.seconds = time.perf_counter() - start
    return summary

"""Prediction files: ours (``spacedg predict``) and VLMEvalKit's, read into one form.

Accepted formats (by suffix):

* ``.jsonl``: one JSON object per line with ``index`` and ``prediction`` (what
  ``spacedg predict`` writes; its lines also repeat the bench row, so the file is scorable on
  its own). A sidecar ``<file>.meta.json`` names the model and the prompt variant.
* ``.xlsx`` (VLMEvalKit's default ``PRED_FORMAT``), ``.tsv`` (``PRED_FORMAT=tsv``, every field
  quoted), ``.csv``, ``.json`` (``PRED_FORMAT=json``: a list of row objects): the bench's columns
  plus ``prediction``, as VLMEvalKit's inference writes ``{model}_{dataset}.{ext}``.

The model's display name comes, in order, from ``LABEL=PATH`` on the command line, the sidecar's
``model``, VLMEvalKit's naming (``…/{model}/[T…_G…/]{model}_{dataset}.ext``), or the file's stem.
A label may carry the prompt variant after ``@`` (``"Qwen3-VL-8B@no_image"``).
"""

from __future__ import annotations

import json
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from spacedg.data.bench_table import cell_text, read_table
from spacedg.errors import (
    FileFormatError,
    InvalidDataError,
    ParameterError,
    SpaceDGWarning,
)
from spacedg.eval.bench import BenchRow, row_from_mapping
from spacedg.eval.prompts import VARIANTS

__all__ = ["PredictionSet", "merge_shards", "meta_path", "parse_source", "read_predictions"]


@dataclass
class PredictionSet:
    """The predictions of one model under one prompt variant.

    Attributes:
        model: display name (a row of the report's tables).
        variant: prompt variant (``default``, ``no_image``, ``degradation_info``, ``cot``).
        path: the file read.
        predictions: bench index → the model's raw output text.
        rows: bench index → the row the file carries (self-contained files; may be empty).
        extras: bench index → other fields of the line (e.g. ``degradation_guess`` of ``cot``).
        meta: the sidecar's content (empty for foreign files).
    """

    model: str
    variant: str
    path: Path
    predictions: dict[int, str]
    rows: dict[int, BenchRow] = field(default_factory=dict)
    extras: dict[int, dict[str, Any]] = field(default_factory=dict)
    meta: dict[str, Any] = field(default_factory=dict)

    @property
    def label(self) -> str:
        return self.model if self.variant == "default" else f"{self.model}@{self.variant}"


def merge_shards(sets: list[PredictionSet]) -> list[PredictionSet]:
    """Sets sharing a label (model and variant) merged into one, in first-seen order: the
    shards of one run (``spacedg predict --shard i/n``) or any files answering disjoint items.
    Two files of one label that answer the same item are an error naming both."""
    merged: dict[str, PredictionSet] = {}
    for s in sets:
        if s.label not in merged:
            merged[s.label] = PredictionSet(s.model, s.variant, s.path, dict(s.predictions), dict(s.rows), dict(s.extras),
                                            {**s.meta, "files": [str(s.path)]})
            continue
        into = merged[s.label]
        shared = sorted(set(into.predictions) & set(s.predictions))
        if shared:
            raise InvalidDataError(
                f"{s.path} and {into.path} are both {s.label!r} and both answer item {shared[0]} ({len(shared)} shared); "
                f"name them apart with LABEL=PATH (e.g. {s.model}-b={s.path}), or pass each shard once"
            )
        into.predictions.update(s.predictions)
        into.rows.update(s.rows)
        into.extras.update(s.extras)
        into.meta["files"].append(str(s.path))
    return list(merged.values())


def meta_path(path: Path) -> Path:
    """The sidecar of a prediction file: ``preds.jsonl`` → ``preds.jsonl.meta.json``."""
    return path.with_name(path.name + ".meta.json")


def parse_source(text: str) -> tuple[str | None, str | None, Path]:
    """``"[LABEL[@VARIANT]=]PATH"`` → ``(label, variant, path)``; a path containing ``=`` that
    exists is taken whole."""
    if "=" in text and not Path(text).exists():
        label, _, path = text.partition("=")
        model, _, variant = label.partition("@")
        if not model.strip():
            raise ParameterError(f"{text!r}: empty model label before '='; write NAME=PATH")
        return model.strip(), (variant.strip() or None), Path(path)
    return None, None, Path(text)


# ------------------------------------------------------------------ per format
def _records_jsonl(path: Path) -> list[dict[str, Any]]:
    records = []
    with path.open(encoding="utf-8") as handle:
        for number, line in enumerate(handle, 1):
            if not line.strip():
                continue
            try:
                value = json.loads(line)
            except json.JSONDecodeError as err:
                raise FileFormatError(f"{path}:{number}: not JSON ({err.msg}); a prediction line is one JSON object") from None
            if not isinstance(value, dict):
                raise FileFormatError(f"{path}:{number}: expected a JSON object with index and prediction")
            records.append(value)
    return records


def _records_json(path: Path) -> list[dict[str, Any]]:
    try:
        value = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as err:
        raise FileFormatError(f"{path}: not JSON ({err.msg} at line {err.lineno})") from None
    if isinstance(value, dict) and isinstance(value.get("columns"), list) and isinstance(value.get("data"), list):
        return [dict(zip(value["columns"], row)) for row in value["data"]]
    if isinstance(value, dict) and value and all(isinstance(v, list) for v in value.values()):
        keys = list(value)
        return [dict(zip(keys, row)) for row in zip(*value.values())]
    if isinstance(value, list) and all(isinstance(v, dict) for v in value):
        return value
    raise FileFormatError(f"{path}: expected a list of row objects (VLMEvalKit PRED_FORMAT=json)")


def _records_xlsx(path: Path) -> list[dict[str, Any]]:
    try:
        import openpyxl
    except ImportError:  # pragma: no cover - openpyxl is a dependency
        raise InvalidDataError(f"{path}: reading .xlsx needs openpyxl (pip install openpyxl), or rerun VLMEvalKit with PRED_FORMAT=tsv") from None
    try:
        book = openpyxl.load_workbook(path, read_only=True, data_only=True)
    except Exception as err:  # noqa: BLE001 - any failure to open means a bad file
        raise FileFormatError(f"{path}: not a readable .xlsx workbook ({err})") from None
    try:
        rows = book.worksheets[0].iter_rows(values_only=True)
        header = next(rows, None)
        if header is None:
            raise FileFormatError(f"{path}: empty sheet (expected a header row)")
        names = [str(h) if h is not None else "" for h in header]
        return [dict(zip(names, row)) for row in rows if any(v is not None for v in row)]
    finally:
        book.close()


_READERS = {".jsonl": _records_jsonl, ".json": _records_json, ".xlsx": _records_xlsx}


def _model_name(path: Path, meta: Mapping[str, Any]) -> str:
    if meta.get("model"):
        return str(meta["model"])
    stem = path.stem
    parents = [path.parent.name, path.parent.parent.name]
    if parents[0].startswith("T") and "_G" in parents[0]:  # VLMEvalKit's per-run folder T{date}_G{commit}
        parents.reverse()
    for candidate in parents:
        if candidate and stem.startswith(candidate + "_"):
            return candidate
    return stem


def read_predictions(source: str | Path, *, model: str | None = None, variant: str | None = None) -> PredictionSet:
    """Read one prediction file (any accepted format; see the module docstring).

    ``model`` / ``variant`` override what the file says. Errors name the file and line: a
    missing ``index`` or ``prediction`` column, a non-integer index, two different predictions
    for one index, an unknown variant. An index repeated with the same prediction (two runs
    appended to one file) is counted once and reported in one
    :class:`~spacedg.errors.SpaceDGWarning` giving how many lines repeated and the first index.
    """
    label, label_variant, path = parse_source(str(source))
    model = model or label
    variant = variant or label_variant
    if not path.is_file():
        raise InvalidDataError(f"prediction file {path} does not exist")
    meta: dict[str, Any] = {}
    if meta_path(path).is_file():
        try:
            meta = json.loads(meta_path(path).read_text(encoding="utf-8"))
        except json.JSONDecodeError as err:
            raise FileFormatError(f"{meta_path(path)}: not JSON ({err.msg})") from None
    suffix = path.suffix.lower()
    if suffix in (".tsv", ".csv"):
        records: list[dict[str, Any]] = read_table(path)  # type: ignore[assignment]
    elif suffix in _READERS:
        records = _READERS[suffix](path)
    else:
        raise InvalidDataError(f"{path}: unknown prediction format {suffix!r}; use .jsonl, .json, .tsv, .csv or .xlsx")
    variant = variant or str(meta.get("variant") or "default")
    if variant not in VARIANTS:
        raise ParameterError(f"{path}: prompt variant {variant!r} is not one of {', '.join(VARIANTS)}")
    out = PredictionSet(model=model or _model_name(path, meta), variant=variant, path=path, predictions={}, meta=meta)
    repeated: list[int] = []
    for number, fields in enumerate(records, 1):
        where = f"{path}:{number + (1 if suffix in ('.tsv', '.csv', '.xlsx') else 0)}"
        if "index" not in fields or "prediction" not in fields:
            raise FileFormatError(f"{where}: needs 'index' and 'prediction' fields (has {', '.join(map(str, fields)) or 'none'})")
        try:
            index = int(float(str(fields["index"]).strip()))
        except ValueError:
            raise FileFormatError(f"{where}: index {fields['index']!r} is not an integer") from None
        text = cell_text(fields["prediction"], strip=False)
        if index in out.predictions:
            if out.predictions[index] != text:
                raise FileFormatError(f"{where}: index {index} has two different predictions; keep one line per index")
            repeated.append(index)
        out.predictions[index] = text
        if "answer" in fields and "question_type" in fields:
            out.rows[index] = row_from_mapping(fields, where)
        extra = {k: v for k, v in fields.items() if k in ("degradation_guess", "stage1", "seconds")}
        if extra:
            out.extras[index] = extra
    if not out.predictions:
        raise InvalidDataError(f"{path}: no predictions")
    if repeated:
        warnings.warn(SpaceDGWarning(
            f"{path}: {len(repeated)} line(s) repeat an index already answered with the same prediction (first: index "
            f"{repeated[0]}); each index is scored once. Two runs appended to one file? Keep one line per index"
        ), stacklevel=2)
    return out

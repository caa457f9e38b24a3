"""The bench table: the one home of the exported TSV's format.

``spacedg export`` writes it (:mod:`spacedg.data.export`), :mod:`spacedg.eval.bench` reads it
and :mod:`spacedg.review.store` edits it; all three use this module for:

- the columns: :data:`PUBLIC_TSV_COLUMNS` (the eight the public loader requires), then the
  export's own (:data:`TSV_COLUMNS`), and :data:`SCORING_COLUMNS` (without which a row cannot be
  scored);
- the cells: :func:`cell_text` (a cell as text: ``None`` and pandas' NaN are ``""``, stripped
  unless asked not to) and :func:`list_cell` (a list cell such as ``image_path``, written as a
  Python list literal, ``"['images/0000000_0.png', ...]"``, JSON or one bare path);
- the dialect: :func:`tsv_bytes` writes rows (UTF-8, tab separated, ``\\n`` line ends, CSV
  quoting of fields with tabs, newlines or quotes: pandas' default, so multi-line questions read
  back unchanged); :func:`read_table` reads a table back, every field as text (pandas' default
  reader would turn the answer type ``"NA"`` and an answer ``"None"`` into missing values);
  :func:`table_header` gives its header row;
- the file: :func:`find_table` finds the table of a bench folder;
- the geometry of a row's question: :func:`index_geometry` reads a scene's question index
  ``<scene id>.qa.jsonl`` with the project's record loader.

How a row is *scored* (its answer type, the public names) is :mod:`spacedg.data.public_format`'s.
"""

from __future__ import annotations

import ast
import csv
import io
import json
import math
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from spacedg.errors import FileFormatError, InvalidDataError

__all__ = [
    "PUBLIC_TSV_COLUMNS",
    "SCORING_COLUMNS",
    "TSV_COLUMNS",
    "cell_text",
    "find_table",
    "index_geometry",
    "list_cell",
    "read_table",
    "table_header",
    "tsv_bytes",
]

#: Columns the public loader requires (it refuses a TSV without any of them; others are carried along).
PUBLIC_TSV_COLUMNS: tuple[str, ...] = (
    "index", "question", "answer", "image_path", "question_type", "sub_question_type", "task_group", "degradation_type",
)
#: Column order of the exported TSV: the evaluator's eight first, then options and provenance.
TSV_COLUMNS: tuple[str, ...] = PUBLIC_TSV_COLUMNS + (
    "answer_type", "A", "B", "C", "D", "scene_id", "record_id", "degradation",
)
#: Columns without which a row cannot be scored.
SCORING_COLUMNS: tuple[str, ...] = ("index", "question", "answer", "question_type")
#: Table names looked for in a bench folder, in this order (``spacedg_bench.tsv``: a VLMEvalKit ``LMUData`` folder).
_TABLE_NAMES = ("bench.tsv", "spacedg_bench.tsv", "val.tsv", "train.tsv")

csv.field_size_limit(min(sys.maxsize, 2**31 - 1))


# ------------------------------------------------------------------ cells
def cell_text(value: Any, *, strip: bool = True) -> str:
    """A table cell as text: ``None`` and NaN (pandas' empty cell) are ``""``; spaces stripped
    unless ``strip=False`` (free text such as a question or a model's answer keeps them)."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return ""
    return str(value).strip() if strip else str(value)


def list_cell(value: Any, what: str, where: str) -> list[Any]:
    """A list cell (``image_path``, ``degradation``) as a list: a list or tuple as is; text as JSON,
    else as a Python literal (what VLMEvalKit's ``toliststr`` evaluates), else as one bare item;
    empty → ``[]``.

    Raises:
        FileFormatError: the text parses to something other than a list or a string (``where``
            names the row, ``what`` the column).
    """
    if isinstance(value, (list, tuple)):
        return list(value)
    text = cell_text(value)
    if not text:
        return []
    try:
        parsed = json.loads(text)
    except json.JSONDecodeError:
        try:
            parsed = ast.literal_eval(text)
        except (ValueError, SyntaxError):
            parsed = text  # one bare path
    if isinstance(parsed, str):
        return [parsed]
    if not isinstance(parsed, (list, tuple)):
        raise FileFormatError(f"{where}: {what} must be a list, got {text[:80]!r}")
    return list(parsed)


# ------------------------------------------------------------------ the dialect
def tsv_bytes(rows: Sequence[Mapping[str, Any]], header: bool = True, columns: Sequence[str] = TSV_COLUMNS) -> bytes:
    """Rows as the bench's TSV dialect (UTF-8, ``\\n`` line ends, CSV quoting of fields with tabs,
    newlines or quotes) under ``columns`` (default: the export's); also used for reviewed benches."""
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=list(columns), delimiter="\t", lineterminator="\n", quoting=csv.QUOTE_MINIMAL)
    if header:
        writer.writeheader()
    writer.writerows(rows)
    return buffer.getvalue().encode("utf-8")


def _delimiter(path: Path) -> str:
    return "," if path.suffix.lower() == ".csv" else "\t"


def read_table(path: Path) -> list[dict[str, str]]:
    """Rows of a TSV (``.tsv``) or CSV (``.csv``) file as text dicts (quoted fields understood).

    Raises:
        FileFormatError: not UTF-8, malformed quoting, or no header row.
    """
    delimiter = _delimiter(path)
    try:
        with path.open(newline="", encoding="utf-8") as handle:
            reader = csv.DictReader(handle, delimiter=delimiter)
            rows = list(reader)
    except UnicodeDecodeError as err:
        raise FileFormatError(f"{path}: not UTF-8 text ({err.reason} at byte {err.start})") from None
    except csv.Error as err:
        raise FileFormatError(f"{path}: malformed {'CSV' if delimiter == ',' else 'TSV'} ({err})") from None
    if reader.fieldnames is None:
        raise FileFormatError(f"{path}: empty file (expected a header row)")
    return rows


def table_header(path: Path) -> list[str]:
    """The column names of a table :func:`read_table` has read (its first row; ``[]`` when empty)."""
    with path.open(newline="", encoding="utf-8") as handle:
        return list(next(csv.reader(handle, delimiter=_delimiter(path)), None) or [])


def find_table(path: Path) -> Path:
    """The TSV of a bench: ``path`` itself, or ``bench.tsv`` / ``spacedg_bench.tsv`` (a VLMEvalKit ``LMUData``
    folder) / ``val.tsv`` / ``train.tsv`` / the one ``.tsv`` in the folder.

    Raises:
        InvalidDataError: ``path`` does not exist, or the folder has no table or several.
    """
    if path.is_file():
        return path
    if not path.is_dir():
        raise InvalidDataError(f"bench {path} does not exist; pass the folder written by `spacedg export` (or its .tsv)")
    for name in _TABLE_NAMES:
        if (path / name).is_file():
            return path / name
    tables = sorted(path.glob("*.tsv"))
    if len(tables) == 1:
        return tables[0]
    if not tables:
        raise InvalidDataError(
            f"bench {path} has no .tsv; export one with `spacedg export --split bench --out {path}` "
            "(an interrupted export writes bench.tsv only once every chunk exists: rerun it to finish)"
        )
    raise InvalidDataError(f"bench {path} has several tables ({', '.join(t.name for t in tables)}); pass the .tsv to use")


# ------------------------------------------------------------------ question geometry
def index_geometry(path: Path) -> dict[str, Any]:
    """``record id → geometry`` of every record of a question index ``<scene id>.qa.jsonl``, read
    with the project's record loader (the numbers a row's answer came from: what a reviewer checks).

    Raises:
        FileFormatError: the file cannot be read, or a line is not a question record (file and line named).
    """
    from spacedg.qa.index import read_index  # the record loader (and its scene imports) only when asked

    return {record.id: record.geometry for record in read_index(path)}

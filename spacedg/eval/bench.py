"""Reading an exported benchmark (``spacedg export``) for prediction and scoring.

A bench folder holds ``<split>.tsv`` (VLMEvalKit columns; the table's format is
:mod:`spacedg.data.bench_table`'s) and ``images/``. :func:`load_bench` reads the TSV
(:func:`~spacedg.data.bench_table.read_table`), **every field as text**: pandas' default reader
turns the answer type ``"NA"`` (numerical answer) and an answer ``"None"`` into missing values,
which is why the answer type is also re-derived by :func:`~spacedg.data.public_format.route` when
a row lacks it (:func:`~spacedg.data.public_format.row_answer_type`).

Rows are :class:`BenchRow` s; their :meth:`BenchRow.scoring_fields` is what
:func:`~spacedg.eval.scoring.score` takes.
"""

from __future__ import annotations

import hashlib
import re
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from spacedg.data.bench_table import SCORING_COLUMNS, cell_text, find_table, list_cell, read_table
from spacedg.data.chain import CLEAN
from spacedg.data.public_format import row_answer_type
from spacedg.errors import FileFormatError, InvalidDataError
from spacedg.plugins.answers import MCQ_LETTERS
from spacedg.plugins.specs import AnswerType

__all__ = ["CLEAN", "Bench", "BenchRow", "load_bench", "row_from_mapping"]

#: ``"A. "`` … ``"D. "`` in front of an option written as a line.
_OPTION_PREFIX = re.compile(r"^\s*[A-D][.)]\s+")


@dataclass(frozen=True)
class BenchRow:
    """One benchmark item: a question about some views under one degradation condition.

    Attributes:
        index: the item's index in the bench (unique; the key predictions refer to).
        question: the question text, option lines included for MCQ (as the model sees it).
        answer: the ground truth as text (letter, yes/no, integer, number in metres, ``[a, b, c]``).
        answer_type: how the answer is scored.
        question_type / sub_question_type / task_group: the evaluator's names.
        degradation_type: ``"ori"`` for clean, else the chain name (``"haze"``, ``"haze+low_res"``).
        options: MCQ option texts in letter order (empty for other answer types).
        image_paths: image files relative to the bench folder, in view order.
        scene_id / record_id: provenance of the question.
        degradation: provenance of the degradation: ``[{"name", "params", "seed", "preset"}, …]``.
    """

    index: int
    question: str
    answer: str
    answer_type: AnswerType
    question_type: str
    sub_question_type: str = ""
    task_group: str = ""
    degradation_type: str = CLEAN
    options: tuple[str, ...] = ()
    image_paths: tuple[str, ...] = ()
    scene_id: str = ""
    record_id: str = ""
    degradation: tuple[Mapping[str, Any], ...] = field(default_factory=tuple)

    @property
    def is_clean(self) -> bool:
        return self.degradation_type == CLEAN

    def scoring_fields(self) -> dict[str, Any]:
        """The mapping :func:`spacedg.eval.scoring.score` reads."""
        fields: dict[str, Any] = {
            "answer": self.answer, "answer_type": self.answer_type.value,
            "question_type": self.question_type, "sub_question_type": self.sub_question_type,
        }
        if self.options:
            fields["options"] = {MCQ_LETTERS[i]: text for i, text in enumerate(self.options)}
        return fields

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready fields (what a prediction line repeats so that it is self-contained)."""
        return {
            "index": self.index, "question": self.question, "answer": self.answer,
            "answer_type": self.answer_type.value, "question_type": self.question_type,
            "sub_question_type": self.sub_question_type, "task_group": self.task_group,
            "degradation_type": self.degradation_type, "options": list(self.options),
            "image_paths": list(self.image_paths), "scene_id": self.scene_id, "record_id": self.record_id,
            "degradation": [dict(d) for d in self.degradation],
        }


@dataclass
class Bench:
    """An exported benchmark: its rows, in file order, and where its images are.

    Attributes:
        root: the bench folder (image paths are relative to it).
        path: the TSV read.
        rows: the items.
        fingerprint: SHA-256 (16 hex) of the TSV bytes; predictions record it so that a
            resumed or scored run can tell it is looking at the same bench.
    """

    root: Path
    path: Path
    rows: list[BenchRow]
    fingerprint: str

    def __post_init__(self) -> None:
        self.by_index: dict[int, BenchRow] = {}
        for row in self.rows:
            if row.index in self.by_index:
                raise FileFormatError(f"{self.path}: index {row.index} appears twice; every row needs its own index")
            self.by_index[row.index] = row

    def __len__(self) -> int:
        return len(self.rows)

    def __iter__(self) -> Iterator[BenchRow]:
        return iter(self.rows)

    def image_file(self, row: BenchRow, view: int) -> Path:
        return self.root / row.image_paths[view]


# ------------------------------------------------------------------ reading
def _options(fields: Mapping[str, Any]) -> tuple[str, ...]:
    given = fields.get("options")
    if isinstance(given, Mapping):
        return tuple(cell_text(given[k], strip=False) for k in MCQ_LETTERS if cell_text(given.get(k)))
    if isinstance(given, (list, tuple)) and given:
        return tuple(_OPTION_PREFIX.sub("", cell_text(o, strip=False), count=1) for o in given)
    texts = [cell_text(fields.get(k)) for k in MCQ_LETTERS]
    return tuple(t for t in texts if t)


def row_from_mapping(fields: Mapping[str, Any], where: str) -> BenchRow:
    """A :class:`BenchRow` from one TSV row / JSON object (columns as in the export).

    ``where`` names the row in errors (``"bench.tsv:12"``). Missing optional columns default
    to empty; ``answer_type`` falls back to routing by question type.
    """
    missing = [c for c in SCORING_COLUMNS if not cell_text(fields.get(c))]
    if missing:
        raise FileFormatError(f"{where}: missing {', '.join(missing)} (needed to score a row)")
    try:
        index = int(float(cell_text(fields["index"])))
    except ValueError:
        raise FileFormatError(f"{where}: index {fields['index']!r} is not an integer") from None
    answer = fields["answer"]
    if isinstance(answer, (list, tuple)):
        answer = "[" + ", ".join(str(v) for v in answer) + "]"
    degradation = [d for d in list_cell(fields.get("degradation"), "degradation", where) if isinstance(d, Mapping)]
    return BenchRow(
        index=index,
        question=cell_text(fields["question"], strip=False),
        answer=cell_text(answer),
        answer_type=row_answer_type(fields, where),
        question_type=cell_text(fields["question_type"]),
        sub_question_type=cell_text(fields.get("sub_question_type")),
        task_group=cell_text(fields.get("task_group")),
        degradation_type=cell_text(fields.get("degradation_type")) or CLEAN,
        options=_options(fields),
        image_paths=tuple(str(p) for p in list_cell(fields.get("image_path", fields.get("image_paths")), "image_path", where)),
        scene_id=cell_text(fields.get("scene_id"), strip=False),
        record_id=cell_text(fields.get("record_id"), strip=False),
        degradation=tuple(degradation),
    )


def load_bench(path: str | Path) -> Bench:
    """Read an exported bench: a folder with ``bench.tsv`` (or ``val.tsv``/``train.tsv``, or
    one ``.tsv``), or the TSV itself. Errors name the file and line."""
    table = find_table(Path(path))
    data = table.read_bytes()
    rows = [row_from_mapping(fields, f"{table}:{n + 2}") for n, fields in enumerate(read_table(table))]
    if not rows:
        raise InvalidDataError(f"{table}: no rows")
    return Bench(root=table.parent, path=table, rows=rows, fingerprint=hashlib.sha256(data).hexdigest()[:16])

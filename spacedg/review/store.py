"""The data side of the benchmark review page: a bench's rows, reviewers' edits, and their log.

A :class:`ReviewStore` opens an exported bench (``spacedg export``: ``bench.tsv`` and
``images/``) **read-only** and keeps the reviewed state in two new files next to the output:

``<table stem>.reviewed.tsv`` (default ``out``, beside the original so image paths stay valid)
    the original columns in the original order, every row's current (edited) values, dropped
    rows left out. Same dialect as the exporter (tab separated, ``\\n`` line ends, CSV quoting
    of fields with tabs, newlines or quotes), so :func:`spacedg.eval.bench.load_bench` and
    ``pandas.read_csv(out, sep="\\t")`` read it. Rewritten atomically after every change.
``<out stem>.log.jsonl``
    one JSON line per accepted change (the record of truth; the TSV is derived from it)::

        {"time": "2025-01-01T12:00:00.123456+00:00", "reviewer": "ana", "index": 3,
         "record_id": "room/…/0", "action": "edit" | "drop" | "restore",
         "before": {field: old}, "after": {field: new}}

    (``drop``/``restore`` log ``{"dropped": false}`` → ``{"dropped": true}`` and back.) On start
    an existing log is replayed in order, every entry checked against the bench (its index must
    exist with the same ``record_id``, and its ``before`` values must be the row's values at
    that point), so reviewing resumes where it stopped and a log of another bench is refused.

Crash safety. A change is committed in this order: the new TSV is written in full to a
temporary sibling and fsynced; the log line is appended; the temporary file is renamed over
the TSV; then the log and the folder are fsynced. A ``kill -9`` can only land between the
append and the rename (two system calls) for the TSV to lag the log by that one change, and
every start replays the log and rewrites the TSV (removing a killed writer's temporary files),
so after a restart the two always agree. A failed write (disk full) undoes all three and
raises. With ``lock=True`` (what ``spacedg review`` uses) the store holds ``<out>.lock`` so a
second review of the same output fails at once instead of interleaving two logs.

The bench must be complete: every row has every column of the header and the fields
:func:`~spacedg.eval.bench.load_bench` needs (the same check), and the file ends with a line
break, so a truncated copy is refused instead of being rewritten without its tail.

Edits (:meth:`ReviewStore.edit`) touch ``question``, ``answer`` and the option texts ``A``–``D``
only, and the row is validated **after** the change by its answer type (the ``answer_type``
column, or :func:`~spacedg.data.public_format.route` when blank):

========== ==========================================================================
MCQ        answer a letter whose option is present; the options present in the original row
           stay non-empty (no option can be added or removed); option texts are one line
YN         ``yes`` / ``no`` (any case, stored lower case)
COUNT      a non-negative integer (digits only)
NA         a finite number (stored as given, stripped)
SIZE_LIST  ``[a, b, c]``: three finite non-negative numbers (stored as given, stripped)
========== ==========================================================================

Changing an option's text rewrites its ``"X. old"`` line in the option block at the end of the
question, so the question a model sees and the option columns agree. A refused change raises
:class:`ReviewError` (its message is shown in the page) and writes nothing.

Geometry (the audit numbers an answer came from) is looked up, lazily and cached per scene,
in the scene question indexes ``<scene>/<scene_id>.qa.jsonl`` (and ``.qa-pooled.jsonl``, a pruned
bench's candidates, and ``.qa-train.jsonl``) under the ``scenes`` folders (read
with the project's record loader, :func:`spacedg.data.bench_table.index_geometry`: a malformed
index is an error naming its file and line), or taken from a ``"geometry"`` field of the bench's
chat JSONL (``<table stem>.jsonl``) when present.

Every public method holds one lock, so a threaded HTTP server may call it concurrently.
"""

from __future__ import annotations

import json
import os
import re
import threading
from collections.abc import Mapping, Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from spacedg.data.bench_table import (
    SCORING_COLUMNS,
    find_table,
    index_geometry,
    list_cell,
    read_table,
    table_header,
    tsv_bytes,
)
from spacedg.data.chain import CLEAN
from spacedg.data.public_format import row_answer_type
from spacedg.files import ExclusiveLock, exclusive_lock, remove_stale_temps, write_temp_sibling
from spacedg.errors import FileFormatError, InvalidDataError, ParameterError
from spacedg.eval.bench import row_from_mapping
from spacedg.plugins.answers import MCQ_LETTERS, answer_from_text
from spacedg.plugins.specs import AnswerType
from spacedg.qa.index import FILE_MODES, index_paths

__all__ = ["EDITABLE", "ReviewError", "ReviewStore"]

#: Fields a reviewer may change.
EDITABLE: tuple[str, ...] = ("question", "answer", "A", "B", "C", "D")
_TITLE_CHARS = 120
_OPTION_LINE = re.compile(r"^\s*([A-D])[.)]\s")


class ReviewError(InvalidDataError):
    """A refused review action (its message is meant for the reviewer)."""


# ------------------------------------------------------------------ validation helpers
def _normalise_answer(kind: AnswerType, answer: str, options: Mapping[str, str]) -> str:
    """The answer as stored, or :class:`ReviewError` saying what a valid one looks like."""
    try:
        return answer_from_text(kind, answer, options)
    except InvalidDataError as err:
        raise ReviewError(str(err)) from None


def _rewrite_option_line(question: str, letter: str, old: str, new: str) -> str:
    """``question`` with its ``"X. old"`` option line (the last one in the trailing option
    block, else the last matching line anywhere) set to ``"X. new"``."""
    lines = question.split("\n")
    start = len(lines)
    while start > 0 and _OPTION_LINE.match(lines[start - 1]):
        start -= 1
    exact = f"{letter}. {old}"
    candidates = [i for i in range(len(lines) - 1, start - 1, -1) if lines[i].strip() == exact.strip()]
    if not candidates:  # the block's line for this letter, whatever its text
        candidates = [i for i in range(len(lines) - 1, start - 1, -1)
                      if (m := _OPTION_LINE.match(lines[i])) and m.group(1) == letter]
    if not candidates:
        candidates = [i for i in range(len(lines) - 1, -1, -1) if lines[i].strip() == exact.strip()]
    if not candidates:
        return question
    i = candidates[0]
    prefix = _OPTION_LINE.match(lines[i])
    lines[i] = (prefix.group(0) if prefix else f"{letter}. ") + new
    return "\n".join(lines)


def _now() -> str:
    return datetime.now(UTC).isoformat()


def _fsync_folder(folder: Path) -> None:
    """Make a rename in ``folder`` durable (a no-op where folders cannot be opened)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


# ------------------------------------------------------------------ the store
class ReviewStore:
    """A bench under review: rows, their current values, dropped flags and the change log.

    Args:
        bench: the bench folder (``bench.tsv``, else ``val.tsv``/``train.tsv``/its one ``.tsv``)
            or the TSV itself; never written.
        out: the reviewed TSV (default ``<table stem>.reviewed.tsv`` beside the table); must
            not be the original table. The log is ``<out stem>.log.jsonl`` beside it.
        scenes: scene folders, or folders of them, whose ``<scene_id>.qa.jsonl`` indexes give
            each record's ``geometry``.
        lock: hold ``<out>.lock`` (one writer per output; :meth:`close` frees it) and remove the
            temporary files a killed writer of ``out`` left.
    """

    def __init__(self, bench: str | Path, *, out: str | Path | None = None,
                 scenes: Sequence[str | Path] | None = None, lock: bool = False) -> None:
        self._lock = threading.Lock()
        self._file_lock: ExclusiveLock | None = None
        self.table: Path = find_table(Path(bench))
        self.root: Path = self.table.parent
        self.out: Path = Path(out) if out is not None else self.table.with_name(f"{self.table.stem}.reviewed.tsv")
        if self.out.exists() and self.out.is_dir():
            raise ParameterError(f"review output {self.out} is a folder; pass the path of the reviewed .tsv to write")
        if self.out.resolve() == self.table.resolve():
            raise ParameterError(
                f"review output {self.out} is the original table; the original is never overwritten: "
                "pass another --out (default <table stem>.reviewed.tsv)"
            )
        self.log: Path = self.out.with_name(f"{self.out.stem}.log.jsonl")
        if self.log.resolve() == self.table.resolve():
            raise ParameterError(f"review log {self.log} would be the original table; pass another out")
        if isinstance(scenes, (str, Path)):
            scenes = [scenes]
        self._scene_roots = [Path(s) for s in (scenes or ())]
        self._scene_cache: dict[str, dict[str, Any]] = {}
        self._jsonl_geometry: dict[int, Any] | None = None
        if lock:
            if not self.out.parent.is_dir():
                raise ParameterError(f"review output {self.out}: folder {self.out.parent} does not exist; create it or pass another --out")
            self._file_lock = exclusive_lock(self.out.with_name(self.out.name + ".lock"),
                                             f"{self.out} is being reviewed by another spacedg review")
        try:
            self._open()
        except BaseException:
            self.close()
            raise

    def close(self) -> None:
        """Free ``<out>.lock`` (a store opened with ``lock=True``); the store stays readable."""
        if self._file_lock is not None:
            self._file_lock.release()

    def _open(self) -> None:
        if self._file_lock is not None:
            remove_stale_temps(self.out.parent, [self.out.name])
        raw_bytes = self.table.read_bytes()
        if raw_bytes and not raw_bytes.endswith(b"\n"):
            raise FileFormatError(
                f"{self.table}: does not end with a line break, so its last row may be cut off (an interrupted copy "
                "or export?); copy or export the bench again"
            )
        rows = read_table(self.table)
        self.header: list[str] = table_header(self.table)
        missing = [c for c in SCORING_COLUMNS if c not in self.header]
        if missing:
            raise InvalidDataError(f"{self.table}: missing column(s) {', '.join(missing)}; is this a `spacedg export` TSV?")
        if not rows:
            raise InvalidDataError(f"{self.table}: no rows")
        self._original: list[dict[str, str]] = []
        self._pos: dict[int, int] = {}
        for n, raw in enumerate(rows):
            if None in raw:
                raise InvalidDataError(f"{self.table}:{n + 2}: more fields than header columns")
            short = [k for k, v in raw.items() if v is None]
            if short:
                raise FileFormatError(
                    f"{self.table}:{n + 2}: {len(self.header) - len(short)} of {len(self.header)} fields (no "
                    f"{', '.join(short[:3])}{' …' if len(short) > 3 else ''}); the file looks truncated: copy or export it again"
                )
            row = dict(raw)  # every value is text: short rows were refused above
            try:
                index = int(float(row["index"].strip()))
            except (ValueError, OverflowError):
                raise InvalidDataError(f"{self.table}:{n + 2}: index {row['index']!r} is not an integer") from None
            row_from_mapping(raw, f"{self.table}:{n + 2}")  # what load_bench checks (it refuses such a bench too)
            if index in self._pos:
                raise InvalidDataError(f"{self.table}:{n + 2}: index {index} appears twice; every row needs its own index")
            self._pos[index] = n
            self._original.append(row)
        self._indexes: list[int] = [int(float(r["index"].strip())) for r in self._original]
        self._current: list[dict[str, str]] = [dict(r) for r in self._original]
        self._dropped: list[bool] = [False] * len(self._original)
        self._history: list[list[dict[str, Any]]] = [[] for _ in self._original]
        self._clean: dict[str, int] = {}
        for index, row in zip(self._indexes, self._original):
            rid = row.get("record_id", "")
            if rid and (row.get("degradation_type", "").strip() or CLEAN) == CLEAN:
                self._clean.setdefault(rid, index)

        if self.log.is_file():
            self._replay()
        self._write_tsv()

    # -------------------------------------------------------------- reading
    def __len__(self) -> int:
        return len(self._original)

    def referenced_images(self) -> list[str]:
        """Every image path the bench's rows name (``image_path``, relative to the bench folder),
        once each, in file order: what the review page may show."""
        seen: dict[str, None] = {}
        for row in self._original:
            for path in self._image_paths(row):
                seen.setdefault(path, None)
        return list(seen)

    def summaries(self) -> list[dict[str, Any]]:
        """One short dict per row, in file order (the page's list and filters)."""
        with self._lock:
            out = []
            for n, index in enumerate(self._indexes):
                row = self._current[n]
                first = row.get("question", "").strip().split("\n", 1)[0].strip()
                title = first if len(first) <= _TITLE_CHARS else first[: _TITLE_CHARS - 1] + "…"
                out.append({
                    "index": index,
                    "question_type": row.get("question_type", ""),
                    "sub_question_type": row.get("sub_question_type", ""),
                    "task_group": row.get("task_group", ""),
                    "degradation_type": row.get("degradation_type", "").strip() or CLEAN,
                    "answer_type": self._answer_type(row).value,
                    "title": title,
                    # what the page's keyword box searches: the whole question (options included), the answer, the scene
                    "text": " ".join((row.get("question", ""), row.get("answer", ""), row.get("scene_id", ""))),
                    "dropped": self._dropped[n],
                    "edited": self._edited(n),
                })
            return out

    def item(self, index: int) -> dict[str, Any]:
        """Every column's current value plus ``answer_type`` (resolved), ``options`` (non-empty
        texts by letter), ``image_paths`` (relative to the bench folder), ``dropped``,
        ``edited``, ``history`` (this row's log entries), ``clean_index`` and ``geometry``."""
        with self._lock:
            return self._item(self._position(index))

    # -------------------------------------------------------------- changing
    def edit(self, index: int, changes: Mapping[str, str], reviewer: str) -> dict[str, Any]:
        """Change ``question``/``answer``/``A``–``D`` of one row; the item after the change.

        Validated on the row after the change (see the module docstring); a refused change
        raises :class:`ReviewError` and writes nothing. A change to nothing new logs nothing.
        """
        with self._lock:
            n = self._position(index)
            before, after = self._plan_edit(n, changes)
            if not after:
                return self._item(n)
            entry = self._entry(n, "edit", before, after, reviewer)
            self._commit(n, entry)
            return self._item(n)

    def set_dropped(self, index: int, dropped: bool, reviewer: str) -> dict[str, Any]:
        """Drop a row from (``True``) or restore it to (``False``) the reviewed TSV."""
        with self._lock:
            n = self._position(index)
            if not isinstance(dropped, bool):
                raise ReviewError(f"dropped must be true or false, got {dropped!r}")
            if self._dropped[n] == dropped:
                return self._item(n)
            entry = self._entry(n, "drop" if dropped else "restore", {"dropped": not dropped}, {"dropped": dropped}, reviewer)
            self._commit(n, entry)
            return self._item(n)

    # -------------------------------------------------------------- internals
    def _position(self, index: Any) -> int:
        try:
            key = int(index)
        except (TypeError, ValueError):
            raise ReviewError(f"index {index!r} is not an integer") from None
        if isinstance(index, float) and index != key:
            raise ReviewError(f"index {index!r} is not an integer")
        if key not in self._pos:
            raise ReviewError(f"no item with index {key} in {self.table.name} ({len(self._original)} items)")
        return self._pos[key]

    def _answer_type(self, row: Mapping[str, str]) -> AnswerType:
        """The row's answer type (its ``answer_type`` cell, else routed by its names); every row
        passed :func:`~spacedg.eval.bench.row_from_mapping` on opening and edits never touch it."""
        return row_answer_type(row, f"{self.table}: index {row.get('index', '?')}")

    def _image_paths(self, row: Mapping[str, str]) -> list[str]:
        """The row's ``image_path`` list (relative to the bench folder)."""
        where = f"{self.table}: index {row.get('index', '?')}"
        return [str(p) for p in list_cell(row.get("image_path", ""), "image_path", where)]

    def _edited(self, n: int) -> bool:
        return any(self._current[n].get(f, "") != self._original[n].get(f, "") for f in EDITABLE)

    def _plan_edit(self, n: int, changes: Mapping[str, str]) -> tuple[dict[str, str], dict[str, str]]:
        """``(before, after)`` of the fields that change (option lines of the question
        included), validated; ``ReviewError`` otherwise. State is not touched."""
        if not isinstance(changes, Mapping) or not changes:
            raise ReviewError("no changes given; edit one of: " + ", ".join(EDITABLE))
        for name, value in changes.items():
            if name not in EDITABLE:
                raise ReviewError(f"field {name!r} cannot be edited; editable fields: {', '.join(EDITABLE)}")
            if name in MCQ_LETTERS and name not in self.header:
                raise ReviewError(f"field {name!r} is not a column of {self.table.name}")
            if not isinstance(value, str):
                raise ReviewError(f"{name} must be text, got {type(value).__name__}")
        current = self._current[n]
        original = self._original[n]
        kind = self._answer_type(current)
        row = dict(current)
        if "question" in changes:
            row["question"] = changes["question"].replace("\r\n", "\n").replace("\r", "\n")
        for letter in MCQ_LETTERS:
            if letter not in changes:
                continue
            new = changes[letter].strip()
            old = current.get(letter, "")
            if new == old:
                continue
            if kind is not AnswerType.MCQ:
                raise ReviewError(f"option {letter} cannot be set: this is a {kind.value} question, options belong to MCQ only")
            if not original.get(letter, "").strip():
                raise ReviewError(f"option {letter} is not part of this question (options cannot be added)")
            if not new:
                raise ReviewError(f"option {letter} cannot be empty (options cannot be removed; drop the sample instead)")
            if "\n" in new or "\t" in new:
                raise ReviewError(f"option {letter} must be one line")
            row[letter] = new
            row["question"] = _rewrite_option_line(row["question"], letter, old, new)
        if not row.get("question", "").strip():
            raise ReviewError("question cannot be empty")
        options = {k: row.get(k, "") for k in MCQ_LETTERS}
        if kind is AnswerType.MCQ:
            for letter in MCQ_LETTERS:
                if original.get(letter, "").strip() and not options[letter].strip():
                    raise ReviewError(f"option {letter} cannot be empty")
        if "answer" in changes:
            row["answer"] = _normalise_answer(kind, changes["answer"], options)
        elif row.get("answer", "") != current.get("answer", "") or any(k in changes for k in MCQ_LETTERS):
            # the answer must still point at a present option after option edits
            _normalise_answer(kind, row.get("answer", ""), options)
        fields = [f for f in EDITABLE if f in row and row.get(f, "") != current.get(f, "")]
        return {f: current.get(f, "") for f in fields}, {f: row[f] for f in fields}

    def _entry(self, n: int, action: str, before: dict[str, Any], after: dict[str, Any], reviewer: str) -> dict[str, Any]:
        name = (reviewer or "").strip() if isinstance(reviewer, str) else ""
        if not name:
            raise ReviewError("reviewer name is required (it is recorded in the log)")
        return {"time": _now(), "reviewer": name, "index": self._indexes[n],
                "record_id": self._original[n].get("record_id", ""), "action": action,
                "before": before, "after": after}

    def _set(self, n: int, entry: Mapping[str, Any], side: str) -> None:
        """Put row ``n`` in the state of ``entry[side]`` (``"after"``: apply, ``"before"``: undo)."""
        values = entry[side]
        if entry["action"] == "edit":
            self._current[n].update(values)
        else:
            self._dropped[n] = bool(values["dropped"])

    def _apply(self, n: int, entry: Mapping[str, Any]) -> None:
        self._set(n, entry, "after")
        self._history[n].append(dict(entry))

    def _unapply(self, n: int, entry: Mapping[str, Any]) -> None:
        self._set(n, entry, "before")
        self._history[n].pop()

    def _commit(self, n: int, entry: dict[str, Any]) -> None:
        """Apply ``entry``, write the new TSV to a temporary file, append the log line, rename the
        TSV into place, then fsync the log (see "Crash safety"); on failure undo all three."""
        line = (json.dumps(entry, ensure_ascii=False) + "\n").encode("utf-8")
        size = self.log.stat().st_size if self.log.exists() else None
        self._apply(n, entry)
        tmp: Path | None = None
        renamed = False
        try:
            tmp = self._prepare_tsv()
            with self.log.open("ab") as handle:
                handle.write(line)
                handle.flush()
                os.replace(tmp, self.out)  # the commit point; a kill between these two lines is repaired on start
                renamed = True
                os.fsync(handle.fileno())
            _fsync_folder(self.out.parent)
        except BaseException:
            self._unapply(n, entry)
            if tmp is not None and not renamed:
                tmp.unlink(missing_ok=True)
            try:
                if size is None:
                    self.log.unlink(missing_ok=True)
                else:
                    with self.log.open("r+b") as handle:
                        handle.truncate(size)
                if renamed:  # put the previous rows back
                    os.replace(self._prepare_tsv(), self.out)
            except OSError:
                pass
            raise

    def _tsv(self) -> bytes:
        rows = [{k: row.get(k, "") for k in self.header}
                for row, dropped in zip(self._current, self._dropped) if not dropped]
        return tsv_bytes(rows, columns=self.header)

    def _prepare_tsv(self) -> Path:
        """The current rows written in full (and fsynced) to a temporary sibling of ``out``."""
        data = self._tsv()

        def write(path: Path) -> None:
            with path.open("wb") as handle:
                handle.write(data)
                handle.flush()
                os.fsync(handle.fileno())

        return write_temp_sibling(self.out, write)

    def _write_tsv(self) -> None:
        os.replace(self._prepare_tsv(), self.out)
        _fsync_folder(self.out.parent)

    def _replay(self) -> None:
        try:
            lines = self.log.read_text(encoding="utf-8").split("\n")
        except (OSError, UnicodeDecodeError) as err:
            raise InvalidDataError(f"{self.log}: cannot read the review log ({err})") from err
        for number, line in enumerate(lines, 1):
            if not line.strip():
                continue
            where = f"{self.log}:{number}"
            try:
                entry = json.loads(line)
            except json.JSONDecodeError as err:
                raise InvalidDataError(f"{where}: not a JSON log entry ({err.msg}); fix or remove the line") from None
            if not isinstance(entry, dict) or entry.get("action") not in ("edit", "drop", "restore") \
                    or not isinstance(entry.get("before"), dict) or not isinstance(entry.get("after"), dict):
                raise InvalidDataError(f"{where}: not a review log entry (needs action edit/drop/restore, before, after)")
            try:
                index = int(entry.get("index"))
            except (TypeError, ValueError):
                raise InvalidDataError(f"{where}: index {entry.get('index')!r} is not an integer") from None
            if index not in self._pos:
                raise InvalidDataError(
                    f"{where}: index {index} is not in {self.table}; this log belongs to another bench "
                    f"(move {self.log.name} away or pass another --out)"
                )
            n = self._pos[index]
            expected = self._original[n].get("record_id", "")
            if str(entry.get("record_id", "")) != expected:
                raise InvalidDataError(
                    f"{where}: index {index} has record_id {expected!r} in {self.table.name} but "
                    f"{entry.get('record_id')!r} in the log; this log belongs to another bench "
                    f"(move {self.log.name} away or pass another --out)"
                )
            if entry["action"] == "edit":
                bad = [f for f in entry["after"] if f not in EDITABLE]
                if bad:
                    raise InvalidDataError(f"{where}: field(s) {', '.join(bad)} cannot be edited")
                stale = [f for f, v in entry["before"].items() if self._current[n].get(f, "") != v]
                if stale:
                    raise InvalidDataError(
                        f"{where}: the log's old value of {', '.join(stale)} for index {index} differs from the bench; "
                        f"this log belongs to another version of {self.table.name}"
                    )
                if not all(isinstance(v, str) for v in entry["after"].values()):
                    raise InvalidDataError(f"{where}: edited values must be text")
            else:
                if not isinstance(entry["after"].get("dropped"), bool):
                    raise InvalidDataError(f"{where}: a {entry['action']} entry needs after.dropped true/false")
            self._apply(n, entry)

    # -------------------------------------------------------------- item views
    def _item(self, n: int) -> dict[str, Any]:
        row = self._current[n]
        index = self._indexes[n]
        item: dict[str, Any] = {k: row.get(k, "") for k in self.header}
        item["index"] = index
        item["answer_type"] = self._answer_type(row).value
        item["options"] = {k: row[k] for k in MCQ_LETTERS if row.get(k, "").strip()}
        item["image_paths"] = self._image_paths(row)
        item["dropped"] = self._dropped[n]
        item["edited"] = self._edited(n)
        item["history"] = [dict(e) for e in self._history[n]]
        rid = self._original[n].get("record_id", "")
        item["clean_index"] = self._clean.get(rid) if rid else None
        item["geometry"] = self._geometry(n)
        return item

    def _geometry(self, n: int) -> dict[str, Any] | None:
        from_jsonl = self._bench_jsonl_geometry().get(self._indexes[n])
        if isinstance(from_jsonl, dict):
            return from_jsonl
        row = self._original[n]
        scene_id, rid = row.get("scene_id", "").strip(), row.get("record_id", "").strip()
        if not scene_id or not rid:
            return None
        geometry = self._scene_geometry(scene_id).get(rid)
        return geometry if isinstance(geometry, dict) else None

    def _bench_jsonl_geometry(self) -> dict[int, Any]:
        if self._jsonl_geometry is None:
            found: dict[int, Any] = {}
            path = self.table.with_suffix(".jsonl")
            if path.is_file():
                try:
                    with path.open(encoding="utf-8") as handle:
                        for line in handle:
                            if '"geometry"' not in line:
                                continue
                            try:
                                data = json.loads(line)
                                found[int(data["index"])] = data["geometry"]
                            except (ValueError, KeyError, TypeError):
                                continue
                except (OSError, UnicodeDecodeError):
                    pass
            self._jsonl_geometry = found
        return self._jsonl_geometry

    def _scene_geometry(self, scene_id: str) -> dict[str, Any]:
        """``record id → geometry`` of the scene's question indexes under the scene roots (each root
        itself, then its ``<scene_id>/`` folder): the first ``<scene_id>.qa.jsonl`` found, merged with
        the first ``<scene_id>.qa-pooled.jsonl`` (a pruned bench's candidates) and
        ``<scene_id>.qa-train.jsonl``; cached per scene."""
        if scene_id not in self._scene_cache:
            geometry: dict[str, Any] = {}
            for name in (index_paths(scene_id, ".", mode=mode)[0].name for mode in FILE_MODES):
                candidates = (c for root in self._scene_roots for c in (root / name, root / scene_id / name))
                path = next((c for c in candidates if c.is_file()), None)
                if path is not None:
                    geometry = {**index_geometry(path), **geometry}
            self._scene_cache[scene_id] = geometry
        return self._scene_cache[scene_id]

"""Question–answer records: :class:`QARecord`, JSON-serialisable, validated at construction.

Answer representation by :class:`~spacedg.plugins.specs.AnswerType` (JSON in brackets; checked
by :func:`spacedg.plugins.answers.validate_answer`, written by :func:`~spacedg.plugins.answers.answer_text`):

``MCQ``
    ``answer`` is the correct option letter, ``"A"`` … ``"D"`` (string); ``options`` holds
    4 lines ``"A. text"``, ``"B. text"``, ``"C. text"``, ``"D. text"``, in letter order
    (letters assigned after a seeded shuffle by the family), or 3 (``"A."`` – ``"C."``) where
    only three answers are possible (:data:`~spacedg.plugins.answers.MCQ_OPTION_COUNTS`); the
    answer is one of the letters shown.
``YN``
    ``"yes"`` or ``"no"`` (string, lower case).
``NA``
    a finite number (``float``), in the unit the question states (metres for distances).
``COUNT``
    a non-negative ``int`` (JSON integer); exports that need text use ``str(answer)``.
``SIZE_LIST``
    a tuple of 3 finite non-negative floats ``(shortest, middle, longest)`` in metres,
    non-decreasing (JSON list).

Every non-MCQ record has ``options == ()``. ``geometry`` is the audit block of the numbers
the answer came from; it is normalised to plain JSON types at construction (tuples → lists,
numpy scalars → Python numbers; NaN/Inf and non-string keys rejected), so
``QARecord.from_dict(record.to_dict()) == record`` and ``from_dict(d).to_dict() == d`` for any
``d`` produced by ``to_dict``.

The per-scene question index (build, reuse, JSONL files) is :mod:`spacedg.qa` (:mod:`spacedg.qa.build`, :mod:`spacedg.qa.index`).

Record ids are deterministic: :func:`make_record_id` gives
``"{scene_id}/{question_type}/{sub_question_type}/{hash}"`` with ``hash`` the first 12 hex
digits of the SHA-1 of the views and a family-chosen key (instances, template, …).
"""

from __future__ import annotations

import contextlib
import contextvars
import dataclasses
import hashlib
import json
import math
import re
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from spacedg.errors import InvalidDataError
from spacedg.plugins.answers import MCQ_LETTERS, MCQ_OPTION_COUNTS, Answer, validate_answer
from spacedg.plugins.specs import NAME_PATTERN, SUB_TYPE_PATTERN, AnswerType, TaskGroup, enum_member

__all__ = ["QARecord", "MCQ_LETTERS", "make_record_id", "json_ready", "deferred_geometry"]

_OPTION = re.compile(r"^([A-D])\. \S")
_FIELDS = (
    "id",
    "scene_id",
    "question_type",
    "sub_question_type",
    "task_group",
    "answer_type",
    "views",
    "question",
    "options",
    "answer",
    "geometry",
)


#: True inside :func:`deferred_geometry`: records keep their ``geometry`` as given (not converted).
_DEFER_GEOMETRY: contextvars.ContextVar[bool] = contextvars.ContextVar("spacedg_defer_geometry", default=False)
#: True while :meth:`QARecord.with_changes` copies a record whose geometry is already plain JSON.
_GEOMETRY_PLAIN: contextvars.ContextVar[bool] = contextvars.ContextVar("spacedg_geometry_plain", default=False)


@contextlib.contextmanager
def deferred_geometry() -> Iterator[None]:
    """Within this block, a new :class:`QARecord` keeps its ``geometry`` mapping as given: the
    conversion to plain JSON types (:func:`json_ready`, and its errors) waits for
    :meth:`QARecord.materialised`. For a caller that builds many candidates and keeps few (the
    question index pools thousands per family and keeps a few hundred); everything else about
    the record is checked as usual. The candidates must not be written or compared before they
    are materialised."""
    token = _DEFER_GEOMETRY.set(True)
    try:
        yield
    finally:
        _DEFER_GEOMETRY.reset(token)


class _NotPlain(Exception):
    """Raised by :func:`_plain` when a value needs :func:`json_ready`'s full conversion or its error."""


#: Exact scalar types :func:`_plain` returns as they are (a float only when finite).
_SCALARS = frozenset({int, str, bool, type(None)})
_NUMBERS = frozenset({float, int})


def _finite_sum(value: list[Any] | tuple[Any, ...]) -> bool:
    """Whether the sum of these numbers is finite (then every one is; False may be an overflow)."""
    try:
        return math.isfinite(sum(value))
    except OverflowError:
        return False


def _plain_list(value: list[Any] | tuple[Any, ...]) -> list[Any]:
    """:func:`_plain` of a list or tuple: one C-level pass over the element types for the common
    flat cases (all numbers: finite when their sum is; all other scalars), else element by element."""
    kinds = set(map(type, value))
    if kinds <= _NUMBERS:
        if float not in kinds or _finite_sum(value):
            return list(value)
        return [_plain(item) for item in value]  # a NaN/Inf (or an overflowing sum): the exact check
    if kinds <= _SCALARS:
        return list(value)
    return [_plain(item) for item in value]


def _plain(value: Any) -> Any:
    """Fast path of :func:`json_ready` for values made of exact built-in types only (no numpy, no
    subclasses): the same result, without building a location string per element. Anything else
    (numpy, NaN/Inf, a non-string key, an unsupported type) raises :class:`_NotPlain`."""
    kind = type(value)
    if kind is float:
        if math.isfinite(value):
            return value
        raise _NotPlain
    if kind in _SCALARS:
        return value
    if kind is list or kind is tuple:
        return _plain_list(value)
    if kind is dict:
        out: dict[str, Any] = {}
        for key, item in value.items():
            if type(key) is not str:
                raise _NotPlain
            kind = type(item)
            out[key] = item if kind in _SCALARS else _plain(item)
        return out
    raise _NotPlain


def json_ready(value: Any, path: str = "geometry") -> Any:
    """``value`` converted to plain JSON types (dict with str keys, list, str, int, float, bool, None).

    Tuples and numpy arrays become lists, numpy scalars Python numbers. Raises
    :class:`InvalidDataError` naming the path of a NaN/Inf, a non-string key or an
    unsupported type. Values of plain built-in types take a fast path (:func:`_plain`, the same
    result); the rest, and every error, the full walk below.
    """
    try:
        return _plain(value)
    except _NotPlain:
        return _json_ready_walk(value, path)


def _json_ready_walk(value: Any, path: str) -> Any:
    """:func:`json_ready`'s full conversion, naming the path of whatever cannot be converted."""
    if value is None or isinstance(value, (bool, str)):
        return value
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        number = float(value)
        if not math.isfinite(number):
            raise InvalidDataError(f"QARecord: {path} is {number}; geometry values must be finite (JSON has no NaN/Inf)")
        return number
    if isinstance(value, np.ndarray):
        return json_ready(value.tolist(), path)
    if isinstance(value, Mapping):
        out: dict[str, Any] = {}
        for key, item in value.items():
            if not isinstance(key, str):
                raise InvalidDataError(f"QARecord: {path} has key {key!r} of type {type(key).__name__}; JSON keys must be strings")
            out[key] = json_ready(item, f"{path}.{key}")
        return out
    if isinstance(value, (list, tuple)):
        return [json_ready(item, f"{path}[{i}]") for i, item in enumerate(value)]
    raise InvalidDataError(f"QARecord: {path} is a {type(value).__name__}, which is not JSON-serialisable; convert it to numbers, strings, lists or dicts")


def make_record_id(
    scene_id: str,
    question_type: str,
    sub_question_type: str,
    views: Sequence[str],
    key: Any,
) -> str:
    """Deterministic id ``"{scene_id}/{question_type}/{sub_question_type}/{12 hex}"``.

    ``key`` is any JSON-ready value that identifies the question within its family and views
    (instance ids, template index, threshold, …); the hash covers ``views`` and ``key``.
    """
    payload = json.dumps({"views": list(views), "key": json_ready(key, "key")}, sort_keys=True, separators=(",", ":"))
    digest = hashlib.sha1(payload.encode("utf-8")).hexdigest()[:12]
    return f"{scene_id}/{question_type}/{sub_question_type}/{digest}"


@dataclass(frozen=True)
class QARecord:
    """One spatial question with its ground-truth answer (see the module docstring).

    Attributes:
        id: unique, deterministic id (see :func:`make_record_id`).
        scene_id: the scene's id.
        question_type: the question family's name.
        sub_question_type: the family's sub type (``^[a-z][A-Za-z0-9_+]*$``: the evaluator's names such
            as ``relpos_A_facing_B`` keep their capitals; ``+`` appears in
            the rotation family's ``"{ax1}+{ax2}_{mode}"``).
        task_group: :class:`~spacedg.plugins.specs.TaskGroup`.
        answer_type: :class:`~spacedg.plugins.specs.AnswerType`; fixes ``answer`` and ``options``.
        views: names of the views (images) the question shows, in order (image 1, 2, …).
        question: the question text.
        options: 4 ``"A. text"`` lines for MCQ, else empty.
        answer: see the module docstring.
        geometry: the numbers the answer came from (JSON types).
    """

    id: str
    scene_id: str
    question_type: str
    sub_question_type: str
    task_group: TaskGroup
    answer_type: AnswerType
    views: tuple[str, ...]
    question: str
    options: tuple[str, ...] = ()
    answer: Answer = ""
    geometry: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        where = f"QARecord {self.id!r}"
        for name in ("id", "scene_id", "question"):
            value = getattr(self, name)
            if not isinstance(value, str) or not value.strip():
                raise InvalidDataError(f"{where}: {name} must be a non-empty string, got {value!r}")
        if not isinstance(self.question_type, str) or not NAME_PATTERN.match(self.question_type):
            raise InvalidDataError(f"{where}: question_type {self.question_type!r} must match ^[a-z][a-z0-9_]*$ (the family name)")
        if not isinstance(self.sub_question_type, str) or not SUB_TYPE_PATTERN.match(self.sub_question_type):
            raise InvalidDataError(f"{where}: sub_question_type {self.sub_question_type!r} must start with a lower-case letter, then letters, digits, '_' or '+' (e.g. 'relpos_A_facing_B')")
        object.__setattr__(self, "task_group", _coerce(TaskGroup, self.task_group, where, "task_group"))
        object.__setattr__(self, "answer_type", _coerce(AnswerType, self.answer_type, where, "answer_type"))
        views = (self.views,) if isinstance(self.views, str) else tuple(self.views)
        if not views or any(not isinstance(v, str) or not v for v in views):
            raise InvalidDataError(f"{where}: views must be one or more non-empty view names, got {self.views!r}")
        if len(set(views)) != len(views):
            raise InvalidDataError(f"{where}: views {list(views)} repeat a view; each image appears once")
        object.__setattr__(self, "views", views)
        object.__setattr__(self, "options", self._check_options(where))
        object.__setattr__(self, "answer", self._check_answer(where))
        if not isinstance(self.geometry, Mapping):
            raise InvalidDataError(f"{where}: geometry must be a dict of the numbers the answer came from, got {type(self.geometry).__name__}")
        if _DEFER_GEOMETRY.get():
            object.__setattr__(self, "_raw_geometry", True)
        elif not _GEOMETRY_PLAIN.get():
            object.__setattr__(self, "geometry", json_ready(self.geometry))

    def with_changes(self, **changes: Any) -> QARecord:
        """``dataclasses.replace(self, **changes)`` (every field checked again), without converting
        a geometry that is already plain JSON a second time: for changes of the text, options or
        answer of a record whose ``geometry`` stays (the copy shares that mapping)."""
        if "geometry" in changes or self.__dict__.get("_raw_geometry"):
            return dataclasses.replace(self, **changes)
        token = _GEOMETRY_PLAIN.set(True)
        try:
            return dataclasses.replace(self, **changes)
        finally:
            _GEOMETRY_PLAIN.reset(token)

    def materialised(self) -> QARecord:
        """This record with its ``geometry`` in plain JSON types: ``self`` unless it was made inside
        :func:`deferred_geometry`, else the converted copy (raising what construction would have)."""
        if not self.__dict__.get("_raw_geometry"):
            return self
        return dataclasses.replace(self)

    def _check_options(self, where: str) -> tuple[str, ...]:
        if isinstance(self.options, str):
            raise InvalidDataError(f"{where}: options must be a sequence of strings, not one string")
        options = tuple(self.options)
        if self.answer_type is not AnswerType.MCQ:
            if options:
                raise InvalidDataError(f"{where}: only MCQ records have options; a {self.answer_type.value} record must have options=()")
            return options
        if len(options) not in MCQ_OPTION_COUNTS:
            raise InvalidDataError(f"{where}: an MCQ needs 4 options 'A. …' to 'D. …' (or 3, 'A. …' to 'C. …'), got {len(options)}")
        for letter, option in zip(MCQ_LETTERS, options):
            match = _OPTION.match(option) if isinstance(option, str) else None
            if match is None or match.group(1) != letter:
                raise InvalidDataError(f"{where}: option {letter} must read '{letter}. <text>', got {option!r}")
        texts = [o[3:].strip() for o in options]
        if len(set(texts)) != len(options):
            raise InvalidDataError(f"{where}: MCQ options repeat a text: {list(options)}; the options must differ")
        if isinstance(self.answer, str) and self.answer in MCQ_LETTERS and MCQ_LETTERS.index(self.answer) >= len(options):
            raise InvalidDataError(f"{where}: the answer {self.answer!r} names no option; the options are {list(MCQ_LETTERS[:len(options)])}")
        return options

    def _check_answer(self, where: str) -> Answer:
        return validate_answer(self.answer_type, self.answer, where)

    def __hash__(self) -> int:
        return hash(self.id)

    # ------------------------------------------------------------- JSON
    def to_dict(self) -> dict[str, Any]:
        """Plain JSON types; ``json.dumps(record.to_dict())`` always works."""
        return {
            "id": self.id,
            "scene_id": self.scene_id,
            "question_type": self.question_type,
            "sub_question_type": self.sub_question_type,
            "task_group": self.task_group.value,
            "answer_type": self.answer_type.value,
            "views": list(self.views),
            "question": self.question,
            "options": list(self.options),
            "answer": list(self.answer) if isinstance(self.answer, tuple) else self.answer,
            "geometry": json.loads(json.dumps(self.geometry)),
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> QARecord:
        """Inverse of :meth:`to_dict`; rejects missing and unknown keys."""
        if not isinstance(data, Mapping):
            raise InvalidDataError(f"QARecord: expected a JSON object, got {type(data).__name__}")
        where = f"QARecord {data.get('id', '?')!r}"
        missing = [k for k in _FIELDS if k not in data and k not in ("options", "geometry")]
        if missing:
            raise InvalidDataError(f"{where}: missing key(s) {missing}")
        unknown = sorted(set(data) - set(_FIELDS))
        if unknown:
            raise InvalidDataError(f"{where}: unknown key(s) {unknown}; known keys: {list(_FIELDS)}")
        return cls(**{k: data[k] for k in _FIELDS if k in data})

    def to_json(self) -> str:
        """One line of JSON (keys in field order)."""
        return json.dumps(self.to_dict(), ensure_ascii=False, separators=(",", ":"))

    @classmethod
    def from_json(cls, text: str) -> QARecord:
        try:
            data = json.loads(text)
        except json.JSONDecodeError as err:
            raise InvalidDataError(f"QARecord: not valid JSON ({err})") from err
        return cls.from_dict(data)


def _coerce(enum_cls: Any, value: object, where: str, name: str) -> Any:
    member = enum_member(enum_cls, value)
    if member is None:
        raise InvalidDataError(f"{where}: {name} {value!r} is not one of {', '.join(m.value for m in enum_cls)}")
    return member


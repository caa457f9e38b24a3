"""Light candidates: a family's question before its record is built, for a caller that keeps few.

The question index (:func:`~spacedg.qa.build.generate_records`) scans up to ``max_scan``
candidates per family and pools a few thousand of them; most are passed over without being
read (their subject already has its alternates, or an object they name has a twin in one of
their images). Building a :class:`~spacedg.plugins.qa_record.QARecord` (question text, geometry
block, id) for those is most of generation's cost. Inside :func:`light_candidates` a family
that supports it yields a :class:`Candidate` instead: what the pool reads (sub type, views,
subject, the ids of the objects it names), a ``selection`` closure making the record's
``selection`` entry (what the debiased selection reads, :mod:`spacedg.qa.selection`) and a
``build`` closure making the record, called only for the few hundred records kept. Every
random draw a candidate needs is made **before** it is yielded (the closure draws nothing), so
the order of draws, and the records, are the same whichever way the stream is read. Outside
the block :func:`offer` builds the record at once: the family yields records as always.

A caller that pools candidates may also refuse one **before** the family draws for it:
inside :func:`gated`, a family asks :func:`admitted` with the candidate's sub type, views,
subject and named ids once the checks that draw nothing have passed, and when the caller does
not want it (a subject that already has its alternates, or a twin in one of its images) yields
:data:`PASSED_OVER` instead of the candidate and makes none of its draws. The marker keeps the
caller's count and a round-robin's turns as they were (one item per valid candidate), so only
the draws differ. Outside :func:`gated`, :func:`admitted` is always true, so a family's
``generate`` yields what it always yielded; inside, the draws of refused candidates are never
made, so the streams draw differently from an ungated run (each draw is still a fresh uniform
draw, so the candidates' questions follow the same distribution).

A :class:`Candidate`'s fields equal what its built record says: ``sub_question_type`` and
``views`` the record's, ``subject`` its ``geometry["selection"]["subject"]``, ``selection()`` its
``geometry["selection"]`` and ``named`` the ids of its ``geometry["refs"]`` (checked by the tests for every built-in family that offers them).
"""

from __future__ import annotations

import contextlib
import contextvars
from collections.abc import Callable, Iterator
from typing import Any, NamedTuple

from spacedg.plugins.qa_record import QARecord

__all__ = ["PASSED_OVER", "Candidate", "ScanGate", "admission", "admitted", "gate_active", "gated", "light_candidates", "offer", "offer_if_admitted"]

#: True inside :func:`light_candidates`: :func:`offer` hands out :class:`Candidate` objects.
_LIGHT: contextvars.ContextVar[bool] = contextvars.ContextVar("spacedg_light_candidates", default=False)

class _PassedOver:
    """The type of :data:`PASSED_OVER`."""

    __slots__ = ()

    def __repr__(self) -> str:
        return "PASSED_OVER"


#: What a family yields, inside :func:`gated`, for a valid candidate :func:`admitted` refused
#: (never outside it): the caller counts it as examined; it is no question.
PASSED_OVER = _PassedOver()

#: ``gate(sub_question_type, views, subject, named) -> bool``: whether the caller wants a candidate
#: (it may also raise to end the caller's scan); see :func:`gated`.
ScanGate = Callable[[str, tuple[str, ...], str, tuple[int, ...]], bool]
_GATE: contextvars.ContextVar[ScanGate | None] = contextvars.ContextVar("spacedg_scan_gate", default=None)


class Candidate(NamedTuple):
    """A question not built yet (module docstring).

    Attributes:
        sub_question_type: the record's sub type.
        views: the record's views, in order.
        subject: the record's selection subject (``geometry["selection"]["subject"]``).
        named: ids of the objects the question names (``geometry["refs"]``), in question order.
        selection: makes the record's ``geometry["selection"]`` entry (no random draws).
        build: makes the record (no random draws).
    """

    sub_question_type: str
    views: tuple[str, ...]
    subject: str
    named: tuple[int, ...]
    selection: Callable[[], dict[str, Any]]
    build: Callable[[], QARecord]


@contextlib.contextmanager
def light_candidates() -> Iterator[None]:
    """Within this block, families that support it yield :class:`Candidate` objects (:func:`offer`)."""
    token = _LIGHT.set(True)
    try:
        yield
    finally:
        _LIGHT.reset(token)


@contextlib.contextmanager
def gated(gate: ScanGate) -> Iterator[None]:
    """Within this block, :func:`admitted` asks ``gate`` (module docstring)."""
    token = _GATE.set(gate)
    try:
        yield
    finally:
        _GATE.reset(token)


def gate_active() -> bool:
    """Whether a :func:`gated` caller is listening (only then may a family yield :data:`PASSED_OVER`)."""
    return _GATE.get() is not None


def admitted(sub_question_type: str, views: tuple[str, ...], subject: str, named: tuple[int, ...]) -> bool:
    """Whether the candidate (sub type, views, subject, named ids, as it would be offered) is
    wanted: the :func:`gated` caller's answer, always ``True`` outside :func:`gated`. A family
    asks once the checks that draw nothing have passed and before any draw for the candidate;
    when refused it yields :data:`PASSED_OVER` and moves on (module docstring)."""
    gate = _GATE.get()
    return gate is None or gate(sub_question_type, views, subject, named)


def _admit_all(sub_question_type: str, views: tuple[str, ...], subject: str, named: tuple[int, ...]) -> bool:
    """The gate outside :func:`gated`: every candidate is wanted."""
    return True


def admission() -> ScanGate:
    """:func:`admitted` as a function looked up once, for a stream that asks about many candidates:
    the :func:`gated` caller's gate, or one that admits everything outside :func:`gated`. Take it
    when the stream starts (its first ``next``, inside the caller's scan); it holds for that scan."""
    gate = _GATE.get()
    return gate if gate is not None else _admit_all


def offer(
    sub_question_type: str, views: tuple[str, ...], subject: str, named: tuple[int, ...],
    selection: Callable[[], dict[str, Any]], build: Callable[[], QARecord],
) -> QARecord | Candidate:
    """What a family yields for one question: a :class:`Candidate` inside :func:`light_candidates`,
    else ``build()`` (the record)."""
    if _LIGHT.get():
        return Candidate(sub_question_type, views, subject, named, selection, build)
    return build()


def offer_if_admitted(
    sub_question_type: str, views: tuple[str, ...], subject: str, named: tuple[int, ...],
    selection: Callable[[], dict[str, Any]], build: Callable[[], QARecord],
) -> QARecord | Candidate | _PassedOver:
    """For a candidate whose random draws are all made already (drawn up front, or per round):
    :data:`PASSED_OVER` when :func:`admitted` refuses it, else :func:`offer` with the same values."""
    if not admitted(sub_question_type, views, subject, named):
        return PASSED_OVER
    return offer(sub_question_type, views, subject, named, selection, build)

"""A pooled candidate: what the debiased selection reads, the record built only when asked for.

The question index pools thousands of candidates per family and keeps a few hundred
(:mod:`spacedg.qa.build`). A :class:`Pooled` wraps a family's
:class:`~spacedg.plugins.candidates.Candidate` for :func:`~spacedg.qa.selection.select_records`:
it has the fields the selection reads (``question_type``, ``sub_question_type``, ``views`` and a
``geometry`` holding only the ``selection`` entry), and builds the
:class:`~spacedg.plugins.qa_record.QARecord` (checked against its family's declaration) the
first time its ``id`` or :meth:`Pooled.materialised` is asked for: for the records taken, or
the ones a judge is asked about.
"""

from __future__ import annotations

from typing import Any

from spacedg.errors import PluginError
from spacedg.plugins.candidates import Candidate
from spacedg.plugins.qa_record import QARecord

__all__ = ["Pooled"]


class Pooled:
    """A pooled candidate of ``family`` in scene ``scene_id`` (module docstring)."""

    __slots__ = ("candidate", "family", "scene_id", "question_type", "sub_question_type", "views", "geometry", "_record")

    def __init__(self, candidate: Candidate, family: Any, scene_id: str) -> None:
        self.candidate = candidate
        self.family = family
        self.scene_id = scene_id
        self.question_type: str = family.name
        self.sub_question_type: str = candidate.sub_question_type  # read often by the selection: plain attributes
        self.views: tuple[str, ...] = candidate.views
        self.geometry: dict[str, Any] = {"selection": candidate.selection()}
        self._record: QARecord | None = None

    def record(self) -> QARecord:
        """The record (built and checked once)."""
        if self._record is None:
            record = self.candidate.build()
            self.family.check_record(record, self.scene_id)
            if record.geometry.get("selection") != self.geometry["selection"]:
                raise PluginError(
                    f"question family {self.family.name!r}: record {record.id!r} has the selection entry "
                    f"{record.geometry.get('selection')!r}, but its candidate offered {self.geometry['selection']!r}"
                )
            self._record = record
        return self._record

    @property
    def id(self) -> str:
        return self.record().id

    def materialised(self) -> QARecord:
        """The record with its geometry in plain JSON types (:meth:`QARecord.materialised`)."""
        return self.record().materialised()

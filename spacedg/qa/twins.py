"""No twins: a question never names an object whose same-description twin shows in any of its images.

A family checks that the object it names has no same-label, same-description neighbour in the
view the question points to (:func:`~spacedg.plugins.questions.records.referable`). A two-view
question shows a second image, though, and "the green plastic chair" is ambiguous when image B
shows another green plastic chair. :func:`has_twin` applies the family rule
(:func:`~spacedg.plugins.questions.view_sampling.description_clash`: another instance of the
same label, any visible pixel, with the same description, or any same-label neighbour when the
object has no description) to **every** image of the record, for every object its ``geometry``
block's ``refs`` name. The question index drops such candidates before selection
(:func:`~spacedg.qa.build.generate_records`; the meta file counts them per family as ``twins``).
Records without ``refs`` (camera motion, counting, existence: they name labels or nothing) are kept.
"""

from __future__ import annotations

from collections.abc import Sequence

from spacedg.plugins.qa_record import QARecord
from spacedg.plugins.questions.view_sampling import VisibilityIndex, description_clash

__all__ = ["named_ids", "has_twin", "TwinCheck"]


def named_ids(record: QARecord) -> list[int]:
    """Ids of the objects ``record`` names (its geometry block's ``refs``), in question order."""
    refs = record.geometry.get("refs")
    if not isinstance(refs, list):
        return []
    return [int(ref["id"]) for ref in refs if isinstance(ref, dict) and "id" in ref]


def has_twin(record: QARecord, index: VisibilityIndex) -> bool:
    """Whether an object ``record`` names has a same-description twin shown in any of its views."""
    return TwinCheck(index).has_twin(record)


class TwinCheck:
    """:func:`has_twin` over many records of one scene, each (view, object) clash computed once."""

    def __init__(self, index: VisibilityIndex) -> None:
        self.index = index
        self._clash: dict[tuple[str, int], bool] = {}

    def clash(self, view: str, iid: int) -> bool:
        """Whether ``view`` shows a same-description twin of object ``iid`` (cached)."""
        key = (view, iid)
        if key not in self._clash:
            try:
                inst = self.index.instance(iid)
            except KeyError:  # not an instance of this scene: nothing to compare
                self._clash[key] = False
            else:
                self._clash[key] = view in self.index.seen and description_clash(self.index, view, inst)
        return self._clash[key]

    def has_twin(self, record: QARecord) -> bool:
        """Whether an object ``record`` names has a same-description twin shown in any of its views."""
        return self.has_twin_ids(record.views, named_ids(record))

    def has_twin_ids(self, views: Sequence[str], ids: Sequence[int]) -> bool:
        """Whether one of the objects ``ids`` has a same-description twin shown in one of ``views``."""
        clash = self._clash
        for iid in ids:
            for view in views:
                hit = clash.get((view, iid))
                if hit is None:
                    hit = self.clash(view, iid)
                if hit:
                    return True
        return False

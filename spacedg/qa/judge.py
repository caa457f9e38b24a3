"""Optional description judge: a VLM (or any callable) confirms that a description picks out one object.

The deterministic filter (:func:`spacedg.plugins.questions.view_sampling.description_clash`) already drops a
question when an image shows two same-label instances with the same description. When the
image shows same-label instances whose descriptions *differ*, the paper asks a VLM judge
whether the description still identifies exactly one instance; uncertain cases are dropped.

A judge is any callable ``judge(image, label, description) -> str``: ``image`` is the clean
view, uint8 (H, W, 3) sRGB; it answers with the keyword ``KEEP`` or ``DROP``.
:func:`parse_verdict` reads the reply: exactly one of the two keywords as a standalone word
(case-insensitive) decides; anything else (both, neither, empty) is **DROP**.
:data:`JUDGE_PROMPT` is the prompt a VLM-backed judge should send with the image.

:class:`DescriptionJudge` applies a judge to records: every ``geometry["refs"]`` entry whose
view shows a same-label neighbour is judged once per (view, instance) and cached; a record is
kept only if all its judged references are ``KEEP``.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from typing import Any

import numpy as np

from spacedg.plugins.qa_record import QARecord
from spacedg.plugins.questions.view_sampling import (
    VisibilityIndex,
    same_label_neighbours,
)
from spacedg.qa.views import render_clean_view
from spacedg.scene.model import Scene

__all__ = ["JUDGE_PROMPT", "Judge", "parse_verdict", "DescriptionJudge", "render_clean_view"]

Judge = Callable[[np.ndarray, str, str], str]

#: Prompt for a VLM judge (the paper's MLLM filter: clean image, category, description → KEEP/DROP).
JUDGE_PROMPT = (
    "You are checking a referring expression for a spatial question.\n"
    "Category: {label}\nDescription: {description}\n"
    "Look at the image. Several objects of this category may be visible. If the description "
    "identifies exactly one visible {label} without doubt, answer KEEP. If it could refer to more "
    "than one, or to none, or you are unsure, answer DROP.\n"
    "Answer with one word: KEEP or DROP."
)

_WORD = re.compile(r"\b(keep|drop)\b", re.IGNORECASE)


def parse_verdict(reply: object) -> bool:
    """True (keep) only when the reply contains ``KEEP`` and not ``DROP`` as standalone words."""
    if not isinstance(reply, str):
        return False
    words = {m.group(1).lower() for m in _WORD.finditer(reply)}
    return words == {"keep"}


class DescriptionJudge:
    """Applies a judge to records' object references (see the module docstring).

    Args:
        scene: the scene the records come from (with visibility).
        judge: ``judge(image, label, description) -> "KEEP" | "DROP"``.
        index: its visibility index (built from ``scene`` if omitted).
        image_for: ``image_for(scene, view) -> uint8 image``; default renders the clean view.
    """

    def __init__(
        self,
        scene: Scene,
        judge: Judge,
        index: VisibilityIndex | None = None,
        image_for: Callable[[Scene, str], np.ndarray] = render_clean_view,
    ) -> None:
        self.scene = scene
        self.judge = judge
        self.index = index or VisibilityIndex(scene)
        self.image_for = image_for
        self._images: dict[str, np.ndarray] = {}
        self._verdicts: dict[tuple[str, int], bool] = {}
        self.calls = 0

    def keep(self, record: QARecord) -> bool:
        """False if any reference of ``record`` is judged ambiguous."""
        refs: list[dict[str, Any]] = list(record.geometry.get("refs", []))
        return all(self._keep_ref(str(ref["view"]), int(ref["id"])) for ref in refs)

    def _keep_ref(self, view: str, instance_id: int) -> bool:
        key = (view, instance_id)
        if key not in self._verdicts:
            inst = self.index.instance(instance_id)
            if not same_label_neighbours(self.index, view, inst):
                self._verdicts[key] = True  # nothing to confuse it with
            else:
                if view not in self._images:
                    self._images[view] = self.image_for(self.scene, view)
                self.calls += 1
                try:
                    reply = self.judge(self._images[view], inst.label, inst.description)
                except Exception:  # noqa: BLE001 - a failing judge is an uncertain case: drop
                    reply = ""
                self._verdicts[key] = parse_verdict(reply)
        return self._verdicts[key]

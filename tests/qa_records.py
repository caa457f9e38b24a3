"""One valid :class:`QARecord` for tests that need a record but not a scene: a camera-translation MCQ."""

from __future__ import annotations

from typing import Any

from spacedg.plugins import AnswerType, TaskGroup
from spacedg.plugins.qa_record import QARecord

#: The record's four option lines.
MCQ_OPTIONS = ("A. left", "B. right", "C. forward", "D. backward")


def qa_record(**changes: Any) -> QARecord:
    """The camera-translation ``main_dir`` MCQ record (answer ``"B"``, views ``v0``, ``v1``), with ``changes`` applied."""
    kwargs: dict[str, Any] = dict(
        id="room/camera_translation/main_dir/abc",
        scene_id="room",
        question_type="camera_translation",
        sub_question_type="main_dir",
        task_group=TaskGroup.CAMERA_CENTRIC,
        answer_type=AnswerType.MCQ,
        views=("v0", "v1"),
        question="What is the primary camera motion direction from view A to view B?",
        options=MCQ_OPTIONS,
        answer="B",
        geometry={"translation_m": [0.5, 0.0, 0.1]},
    )
    kwargs.update(changes)
    return QARecord(**kwargs)

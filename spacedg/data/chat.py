"""Chat formatting: the one conversation layout of training samples, exports, prediction and evaluation.

- :data:`ANSWER_PROMPT`: the system text (answer only, in ``<answer>…</answer>`` tags), with
  :data:`ANSWER_FORMATS` saying how each answer type is written inside the tags.
- :func:`format_question`: the question with its option lines, as a model sees it (defined in
  :mod:`spacedg.data.public_format`, re-exported here).
- :func:`chat_messages`: system turn, user turn (one ``{"type": "image"}`` entry per view, then the
  question) and, when given, the assistant turn.
- :func:`chat_collate`: a DataLoader batch of :class:`~spacedg.data.dataset.SpaceDGDataset` items
  → conversations and images for ``processor.apply_chat_template``; :func:`item_images`.

Training samples, exports and predictions show a model the same thing: the public bench's form of
a record (:func:`spacedg.data.public_format.public_fields`: existence as lettered options, the
answer text of :func:`spacedg.plugins.answers.answer_text`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from spacedg._checks import check_bool, check_int, short_repr
from spacedg.data.public_format import format_question, public_fields
from spacedg.errors import ParameterError

__all__ = ["ANSWER_FORMATS", "ANSWER_PROMPT", "format_question", "chat_messages", "item_images", "chat_collate"]

#: How each answer type is written inside the tags (shared by every prompt variant).
ANSWER_FORMATS: str = (
    "for a multiple-choice question the option "
    "letter (e.g. <answer>B</answer>); for a yes/no question yes or no (e.g. "
    "<answer>no</answer>); for a count an integer (e.g. <answer>3</answer>); for a distance "
    "or size one number in meters (e.g. <answer>1.25</answer>); for object dimensions a list "
    "[shortest edge, middle edge, longest edge] in meters (e.g. <answer>[0.10, 0.20, 0.30]</answer>)."
)
#: System text given to the model: answer only, wrapped in ``<answer>…</answer>``.
ANSWER_PROMPT: str = (
    "Answer the question about the image(s). Output only the final answer, wrapped in "
    "<answer></answer> tags, with no other text: " + ANSWER_FORMATS
)


def chat_messages(question: str, n_images: int, *, system: str = ANSWER_PROMPT, answer: str | None = None) -> list[dict[str, Any]]:
    """A system turn, a user turn (``n_images`` image entries, then ``question``) and, when
    ``answer`` is given, the assistant turn: the one conversation layout of prediction,
    evaluation during training, and training samples."""
    if not isinstance(question, str):
        raise ParameterError(f"chat_messages: question must be a string, got {short_repr(question)}")
    check_int(n_images, "chat_messages: n_images", minimum=0)
    for name, value in (("system", system), ("answer", answer)):
        if value is not None and not isinstance(value, str):
            raise ParameterError(f"chat_messages: {name} must be a string, got {short_repr(value)}")
    user: list[dict[str, Any]] = [{"type": "image"} for _ in range(n_images)]
    user.append({"type": "text", "text": question})
    messages = [{"role": "system", "content": [{"type": "text", "text": system}]}, {"role": "user", "content": user}]
    if answer is not None:
        messages.append({"role": "assistant", "content": [{"type": "text", "text": answer}]})
    return messages


def item_images(item: dict[str, Any]) -> list[np.ndarray]:
    """The views of a dataset item as uint8 H×W×3 RGB arrays (contiguous), in view order
    (``item["images"]`` is a uint8 V×3×H×W tensor, or a list of H×W×3 arrays)."""
    # a torch tensor has .permute: told apart without importing torch
    return [np.ascontiguousarray(img.permute(1, 2, 0).numpy()) if hasattr(img, "permute") else np.asarray(img)
            for img in item["images"]]


def chat_collate(batch: Sequence[dict[str, Any]], *, system_prompt: str | None = None, with_answer: bool = True) -> dict[str, Any]:
    """A batch of items → chat messages for ``processor.apply_chat_template``.

    Returns ``{"messages": [...], "images": [[uint8 H×W×3 arrays] per sample], "answers": [...],
    "items": batch}``. Each conversation is a system turn (the SpaceDG answer prompt), a user turn
    with one ``{"type": "image"}`` entry per view followed by the question (options included),
    and with ``with_answer`` the assistant turn ``<answer>…</answer>``.
    """
    if isinstance(batch, dict) or not isinstance(batch, Sequence) or not all(isinstance(item, dict) for item in batch):
        raise ParameterError(f"chat_collate: batch must be a list of dataset items (dicts), got {short_repr(batch)}")
    check_bool(with_answer, "chat_collate: with_answer")
    if system_prompt is not None and not isinstance(system_prompt, str):
        raise ParameterError(f"chat_collate: system_prompt must be a string or None, got {short_repr(system_prompt)}")
    prompt = ANSWER_PROMPT if system_prompt is None else system_prompt
    messages, images, answers = [], [], []
    for item in batch:
        views = item_images(item)
        fields = public_fields(item)  # what the bench shows: public names, existence as lettered options
        answer = f"<answer>{fields['answer']}</answer>"
        question = fields["question"]
        messages.append(chat_messages(question, len(views), system=prompt, answer=answer if with_answer else None))
        images.append(views)
        answers.append(answer)
    return {"messages": messages, "images": images, "answers": answers, "items": list(batch)}

"""Training samples for SFT: online SpaceDG items or an exported chat JSONL, under a token budget.

Every sample becomes ``{"conversation": [system, user, assistant], "images": [uint8 H×W×3],
"degradation_type": str}``: the conversation ``spacedg predict`` sends (system
:data:`~spacedg.data.chat.ANSWER_PROMPT`, one image entry per view, the question with its
options) plus the assistant turn ``<answer>…</answer>``, so training and evaluation prompts agree.

**Token budget.** A sample longer than ``max_length`` tokens is dropped, never truncated
(truncation would cut through image tokens: "image features and image tokens do not match").
The length of a sample does not depend on its degradation: image tokens depend only on the
image size, so :func:`token_lengths` measures every question once, on blank images of the
rendered size, before training, and :class:`BudgetedDataset` keeps the ones that fit; the
count of dropped questions is reported (``data_stats.json``).
"""

from __future__ import annotations

import json
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from torch.utils.data import Dataset

from spacedg.files import read_rgb
from spacedg.errors import FileFormatError, InvalidDataError, ParameterError
from spacedg.data.chat import ANSWER_PROMPT, chat_messages, item_images
from spacedg.data.public_format import public_fields
from spacedg.vlm import encode_chats

__all__ = ["BudgetedDataset", "ChatJsonlDataset", "OnlineSFTDataset", "token_lengths"]

_IMAGE_TAG = re.compile(r"<image>")


class OnlineSFTDataset(Dataset):
    """SFT samples rendered online by a :class:`~spacedg.data.dataset.SpaceDGDataset`."""

    def __init__(self, dataset: Any) -> None:
        self.dataset = dataset

    def __len__(self) -> int:
        return len(self.dataset)

    def set_epoch(self, epoch: int) -> None:
        """Forwarded to the SpaceDG dataset: a new epoch draws new degradations."""
        self.dataset.set_epoch(epoch)

    def question(self, index: int) -> tuple[str, str, int, str]:
        """``(question, answer, views, key)`` of item ``index`` without rendering it."""
        record = self.dataset.plan(index).record
        fields = public_fields(record)  # the bench's form: existence as lettered options
        return fields["question"], f"<answer>{fields['answer']}</answer>", len(record.views), record.id

    def image_size(self) -> tuple[int, int] | None:
        """The requested size, a bounding box: views render at the largest size of their own
        aspect within it (:meth:`~spacedg.render.camera.Camera.fitted`), never larger."""
        return self.dataset.options.image_size

    def __getitem__(self, index: int) -> dict[str, Any]:
        item = self.dataset[index]
        images = item_images(item)
        fields = public_fields(item)
        answer = f"<answer>{fields['answer']}</answer>"
        return {"conversation": chat_messages(fields["question"], len(images), answer=answer), "images": images,
                "degradation_type": item["degradation_type"]}


@dataclass(frozen=True)
class _ChatLine:
    images: tuple[str, ...]
    system: str | None
    question: str
    answer: str
    degradation_type: str


class ChatJsonlDataset(Dataset):
    """SFT samples from a chat JSONL written by ``spacedg export`` (LLaMA-Factory / ShareGPT
    style: ``images`` paths relative to the file, ``messages`` user + assistant with one
    ``<image>`` placeholder per image, optional ``system``)."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        if not self.path.is_file():
            raise InvalidDataError(f"data.jsonl {self.path} does not exist; export one with `spacedg export --split train --out DIR`")
        self.lines: list[_ChatLine] = []
        with self.path.open(encoding="utf-8") as handle:
            for number, raw in enumerate(handle, 1):
                if raw.strip():
                    self.lines.append(self._parse(raw, f"{self.path}:{number}"))
        if not self.lines:
            raise InvalidDataError(f"{self.path}: no samples")

    @staticmethod
    def _parse(raw: str, where: str) -> _ChatLine:
        try:
            value = json.loads(raw)
            messages = value["messages"]
            user = next(m["content"] for m in messages if m["role"] == "user")
            answer = next(m["content"] for m in messages if m["role"] == "assistant")
            images = tuple(value.get("images", []))
        except (json.JSONDecodeError, KeyError, StopIteration, TypeError) as err:
            raise FileFormatError(f"{where}: not a chat line with messages (user + assistant) and images ({err})") from None
        placeholders = len(_IMAGE_TAG.findall(user))
        if placeholders != len(images):
            raise FileFormatError(f"{where}: {placeholders} <image> placeholders for {len(images)} images; they must match")
        return _ChatLine(images, value.get("system"), _IMAGE_TAG.sub("", user).strip(), answer, str(value.get("degradation_type", "ori")))

    def __len__(self) -> int:
        return len(self.lines)

    def set_epoch(self, epoch: int) -> None:
        """Nothing to redraw: exported samples are fixed."""

    def question(self, index: int) -> tuple[str, str, int, str]:
        line = self.lines[index]
        return line.question, line.answer, len(line.images), f"{line.question}\x00{len(line.images)}"

    def image_size(self) -> tuple[int, int] | None:
        first = self.lines[0]
        if not first.images:
            return None
        image = read_rgb(self.path.parent / first.images[0])
        return None if image is None else (image.shape[1], image.shape[0])

    def __getitem__(self, index: int) -> dict[str, Any]:
        line = self.lines[index]
        images = []
        for rel in line.images:
            image = read_rgb(self.path.parent / rel)
            if image is None:
                raise InvalidDataError(f"{self.path}: image {rel} of sample {index} is missing or unreadable")
            images.append(image)
        return {"conversation": chat_messages(line.question, len(images), system=ANSWER_PROMPT if line.system is None else line.system, answer=line.answer), "images": images,
                "degradation_type": line.degradation_type}


def token_lengths(dataset: OnlineSFTDataset | ChatJsonlDataset, processor: Any) -> list[int]:
    """Tokens of every sample (system + user with images + answer), measured once per distinct
    question on blank images of the dataset's image size (image tokens depend only on size; an
    online dataset's size is a bounding box its views fit in, so the count is an upper bound)."""
    size = dataset.image_size()
    width, height = size if size is not None else (640, 480)
    blank = np.zeros((height, width, 3), np.uint8)
    measured: dict[str, int] = {}
    lengths = []
    for index in range(len(dataset)):
        question, answer, views, key = dataset.question(index)
        if key not in measured:
            batch = encode_chats(processor, [chat_messages(question, views, answer=answer)], [[blank] * views], add_generation_prompt=False)
            measured[key] = int(batch["input_ids"].shape[1])
        lengths.append(measured[key])
    return lengths


class BudgetedDataset(Dataset):
    """The samples of ``dataset`` whose token length is at most ``max_length`` (others dropped).

    Attributes:
        kept: indices into ``dataset`` that fit.
        dropped: how many samples were too long.
        longest: the longest sample's token count (kept or not).
    """

    def __init__(self, dataset: OnlineSFTDataset | ChatJsonlDataset, lengths: Sequence[int], max_length: int) -> None:
        if max_length < 16:
            raise ParameterError(f"data.max_length must be >= 16 tokens, got {max_length}")
        self.dataset = dataset
        self.kept = [i for i, n in enumerate(lengths) if n <= max_length]
        self.dropped = len(lengths) - len(self.kept)
        self.longest = max(lengths, default=0)
        if not self.kept:
            raise InvalidDataError(
                f"every one of the {len(lengths)} samples is longer than data.max_length={max_length} tokens "
                f"(the shortest has {min(lengths, default=0)}); raise data.max_length or lower the image budget"
            )

    def __len__(self) -> int:
        return len(self.kept)

    def set_epoch(self, epoch: int) -> None:
        self.dataset.set_epoch(epoch)

    def __getitem__(self, index: int) -> dict[str, Any]:
        return self.dataset[self.kept[index]]

"""Batches for SFT: the processor's chat template, with loss on the assistant answer only.

``labels`` equal ``input_ids`` on the tokens the chat template marks as the assistant's
(``{% generation %}`` blocks: the answer and its end-of-turn token) and ``-100`` everywhere
else (system prompt, question, image tokens, padding).

**Over-long samples.** A sample longer than ``max_length`` tokens is dropped from its batch and
counted (:attr:`SFTCollator.dropped`), never truncated; :class:`~spacedg.sft.data.BudgetedDataset`
normally removes such samples before training (it measures every question on blank images of the
rendered size), so this is a guard for samples it could not foresee (views of another size). When
*no* sample of a batch fits (always the case at batch size 1), the batch becomes a **filler**: one
short conversation with one blank image and no supervised token (:attr:`SFTCollator.fillers`
counts them). It trains nothing (the loss of :mod:`spacedg.sft.loss` is a sum over supervised
tokens) but keeps every rank doing the same forward and backward, so DDP, FSDP and ZeRO never wait
on a rank that skipped a step (and the vision tower runs on every rank).

**Trimmed logits.** With ``trim_logits=True`` each batch also carries ``logits_to_keep``: the
number of final positions whose logits the loss needs (from the first supervised token on); the
model then never materialises ``T × vocab`` logits for the prompt and image tokens.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import torch

from spacedg.data.chat import chat_messages
from spacedg.errors import InvalidDataError
from spacedg.sft.loss import IGNORE_INDEX
from spacedg.vlm import encode_chats

__all__ = ["IGNORE_INDEX", "SFTCollator"]

#: Side of the blank image of a filler batch (56 × 56 = 3136 pixels, the Qwen-VL minimum: 4 tokens).
_FILLER_SIDE = 56


class SFTCollator:
    """``collate(samples) -> BatchFeature`` with ``input_ids``, ``attention_mask``, the pixel
    inputs and ``labels`` (and ``logits_to_keep`` with ``trim_logits``). ``samples`` are
    ``{"conversation", "images"}`` dicts (see :mod:`spacedg.sft.data`)."""

    def __init__(self, processor: Any, max_length: int, *, trim_logits: bool = False) -> None:
        self.processor = processor
        self.max_length = int(max_length)
        self.trim_logits = bool(trim_logits)
        self.dropped = 0
        self.fillers = 0

    def _encode(self, samples: Sequence[dict[str, Any]]) -> Any:
        return encode_chats(self.processor, [s["conversation"] for s in samples], [s["images"] for s in samples],
                            add_generation_prompt=False, return_assistant_mask=True)

    def _filler(self, lengths: list[int]) -> Any:
        blank = np.zeros((_FILLER_SIDE, _FILLER_SIDE, 3), np.uint8)
        batch = self._encode([{"conversation": chat_messages("", 1, answer=""), "images": [blank]}])
        if int(batch["attention_mask"].sum()) > self.max_length:
            raise InvalidDataError(
                f"every sample of this batch is longer than data.max_length={self.max_length} tokens "
                f"(lengths {lengths}), and so is a one-image filler; raise data.max_length"
            )
        batch.pop("assistant_masks")
        batch["labels"] = torch.full_like(batch["input_ids"], IGNORE_INDEX)
        if self.trim_logits:
            batch["logits_to_keep"] = 1
        self.fillers += 1
        return batch

    def __call__(self, samples: Sequence[dict[str, Any]]) -> Any:
        batch = self._encode(samples)
        lengths = batch["attention_mask"].sum(dim=1)
        if int(lengths.max()) > self.max_length:
            fits = [s for s, n in zip(samples, lengths.tolist()) if n <= self.max_length]
            self.dropped += len(samples) - len(fits)
            if not fits:
                return self._filler(lengths.tolist())
            batch = self._encode(fits)
        mask = batch.pop("assistant_masks")
        mask = torch.as_tensor(mask, dtype=torch.bool) & batch["attention_mask"].bool()
        if not bool(mask.any(dim=1).all()):
            raise InvalidDataError("a sample has no supervised tokens: its chat template lacks {% generation %} markers "
                                   "around the assistant answer (see spacedg.vlm.tiny for a template that has them)")
        batch["labels"] = torch.where(mask, batch["input_ids"], torch.full_like(batch["input_ids"], IGNORE_INDEX))
        if self.trim_logits:
            first = int(mask.to(torch.int8).argmax(dim=1).min())  # earliest supervised position of the batch
            batch["logits_to_keep"] = int(mask.shape[1] - first + 1)
        return batch

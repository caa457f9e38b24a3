"""Batches for SFT: the processor's chat template, with loss on the assistant answer only.

``labels`` equal ``input_ids`` on the tokens the chat template marks as the assistant's
(``{% generation %}`` blocks: the answer and its end-of-turn token) and ``-100`` everywhere
else (system prompt, question, image tokens, padding). A sample longer than ``max_length``
tokens is dropped from its batch and counted (:attr:`SFTCollator.dropped`), never truncated;
:class:`~spacedg.sft.data.BudgetedDataset` normally removes such samples before training, so
this is a guard.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import torch

from spacedg.errors import InvalidDataError
from spacedg.vlm import encode_chats

__all__ = ["IGNORE_INDEX", "SFTCollator"]

#: Label of tokens the loss ignores.
IGNORE_INDEX = -100


class SFTCollator:
    """``collate(samples) -> BatchFeature`` with ``input_ids``, ``attention_mask``, the pixel
    inputs and ``labels``. ``samples`` are ``{"conversation", "images"}`` dicts (see
    :mod:`spacedg.sft.data`)."""

    def __init__(self, processor: Any, max_length: int) -> None:
        self.processor = processor
        self.max_length = int(max_length)
        self.dropped = 0

    def _encode(self, samples: Sequence[dict[str, Any]]) -> Any:
        return encode_chats(self.processor, [s["conversation"] for s in samples], [s["images"] for s in samples],
                            add_generation_prompt=False, return_assistant_mask=True)

    def __call__(self, samples: Sequence[dict[str, Any]]) -> Any:
        batch = self._encode(samples)
        lengths = batch["attention_mask"].sum(dim=1)
        if int(lengths.max()) > self.max_length:
            fits = [s for s, n in zip(samples, lengths.tolist()) if n <= self.max_length]
            self.dropped += len(samples) - len(fits)
            if not fits:
                raise InvalidDataError(
                    f"every sample of this batch is longer than data.max_length={self.max_length} tokens "
                    f"(lengths {lengths.tolist()}); raise data.max_length or lower the image budget"
                )
            batch = self._encode(fits)
        mask = batch.pop("assistant_masks")
        mask = torch.as_tensor(mask, dtype=torch.bool) & batch["attention_mask"].bool()
        if not bool(mask.any(dim=1).all()):
            raise InvalidDataError("a sample has no supervised tokens: its chat template lacks {% generation %} markers "
                                   "around the assistant answer (see spacedg.vlm.tiny for a template that has them)")
        batch["labels"] = torch.where(mask, batch["input_ids"], torch.full_like(batch["input_ids"], IGNORE_INDEX))
        return batch

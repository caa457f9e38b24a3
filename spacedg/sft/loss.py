"""The SFT loss, normalised over the whole optimizer step: batch × accumulation × ranks is a pure
performance choice.

transformers marks the Qwen-VL classes ``accepts_loss_kwargs=False``, so the stock ``Trainer``
averages each micro-batch's loss over its own tokens and divides by the accumulation steps: with
batch 1 × accumulation 16 every sample weighs the same whatever its answer length, and batch 2 ×
accumulation 1 trains differently from batch 1 × accumulation 2 (measured on the tiny Qwen2.5-VL
and four samples with answers of 2 to 14 tokens: step-2 loss 5.9677 vs 5.9404; with this module's
loss 5.9677 both ways). Here the Trainer gets a ``compute_loss_func``:

* ``tokens`` (default): the sum of the token losses of a micro-batch divided by the number of
  supervised tokens of the whole optimizer step, counted over every micro-batch and every rank
  (``num_items_in_batch``); every supervised token weighs the same.
* ``samples``: each sample's mean token loss, summed and divided by the number of supervised
  samples of the whole step; every sample weighs the same whatever its answer length.

The Trainer counts the step's items (:func:`count_items`, through
:meth:`spacedg.sft.trainer.SFTTrainer._get_num_items_in_batch`), sums them over ranks and scales
the loss by the number of processes, because DDP / FSDP / DeepSpeed average gradients over ranks.

Logits may cover only the last ``K`` positions (``logits_to_keep``, set by
:class:`~spacedg.sft.collator.SFTCollator`: answers sit at the end, so the full ``T × vocab``
logits of a 7B are never materialised); the labels before them must all be ignored.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import torch
import torch.nn.functional as F

__all__ = ["IGNORE_INDEX", "LOSSES", "count_items", "loss_function", "sample_loss", "token_loss"]

#: Label of tokens the loss ignores.
IGNORE_INDEX = -100
#: The ``train.loss`` choices.
LOSSES = ("tokens", "samples")


def _aligned(logits: torch.Tensor, labels: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """``(logits[:, :-1], targets)``: each kept logit position with the label of the next token."""
    kept, length = logits.shape[1], labels.shape[1]
    if kept > length or kept < 1:
        raise ValueError(f"logits cover {kept} positions but the labels have {length}")
    if kept < length and bool((labels[:, 1:length - kept + 1] != IGNORE_INDEX).any()):
        raise ValueError(f"logits_to_keep={kept} drops supervised positions; keep at least "
                         f"length - first supervised position + 1")
    return logits[:, :-1], labels[:, length - kept + 1:]


def _token_losses(outputs: Any, labels: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """``(losses, mask)``: cross-entropy of every supervised target (float32) and where they are."""
    logits = outputs["logits"] if isinstance(outputs, dict) else outputs.logits
    logits, targets = _aligned(logits, labels.to(logits.device))
    mask = targets != IGNORE_INDEX
    losses = F.cross_entropy(logits[mask].float(), targets[mask], reduction="none")
    return losses, mask


def _divide(total: torch.Tensor, count: Any) -> torch.Tensor:
    count = torch.as_tensor(count, device=total.device, dtype=total.dtype)
    return total / count.clamp(min=1)


def token_loss(outputs: Any, labels: torch.Tensor, num_items_in_batch: Any = None) -> torch.Tensor:
    """Sum of the token losses / ``num_items_in_batch`` (the step's supervised tokens; default: this batch's)."""
    losses, mask = _token_losses(outputs, labels)
    return _divide(losses.sum(), mask.sum() if num_items_in_batch is None else num_items_in_batch)


def sample_loss(outputs: Any, labels: torch.Tensor, num_items_in_batch: Any = None) -> torch.Tensor:
    """Sum of the samples' mean token losses / ``num_items_in_batch`` (the step's supervised samples)."""
    losses, mask = _token_losses(outputs, labels)
    rows = mask.nonzero()[:, 0]
    per_row = torch.zeros(mask.shape[0], device=losses.device, dtype=losses.dtype).index_add_(0, rows, losses)
    counts = mask.sum(dim=1)
    supervised = counts > 0
    total = (per_row[supervised] / counts[supervised]).sum()
    return _divide(total, int(supervised.sum()) if num_items_in_batch is None else num_items_in_batch)


def count_items(labels: torch.Tensor, mode: str) -> torch.Tensor:
    """What ``mode`` normalises by in one micro-batch: supervised targets (``tokens``) or samples
    with at least one (``samples``)."""
    supervised = labels[:, 1:] != IGNORE_INDEX
    return supervised.sum() if mode == "tokens" else supervised.any(dim=1).sum()


def loss_function(mode: str) -> Callable[..., torch.Tensor]:
    """The ``compute_loss_func`` of ``mode`` (one of :data:`LOSSES`)."""
    if mode not in LOSSES:
        raise ValueError(f"train.loss must be one of {', '.join(LOSSES)}, got {mode!r}")
    return token_loss if mode == "tokens" else sample_loss

"""The HF ``Trainer`` with what SFT of SpaceDG VLMs needs and the stock one lacks.

* **Resume that restores the weights.** transformers 5.23 reloads a VLM checkpoint's hub-format
  keys with ``strict=False`` and silently trains on from the *initial* weights (measured: loss
  back from 5.64 to 5.98). :meth:`SFTTrainer._load_from_checkpoint` loads full checkpoints
  through ``from_pretrained`` (which maps the keys) and copies the weights in strictly, and
  LoRA checkpoints through peft; optimizer, scheduler and RNG state still come from the
  Trainer's own resume.
* **Evaluation by generation.** :meth:`SFTTrainer.evaluate` answers ``val`` items with greedy
  generation and scores them with :func:`spacedg.eval.scoring.score`, returning
  ``eval_score`` and ``eval_score_<degradation>`` (accuracy / MRA per condition). On several
  processes each rank answers its share and the scores are gathered. Not under FSDP (the
  sharded model cannot generate rank by rank): there, evaluate checkpoints with ``spacedg predict``.
* **Checkpoints ``spacedg predict`` loads.** :class:`SaveProcessorCallback` writes the
  processor (with its image pixel budget and chat template) into every checkpoint.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import torch
from peft import PeftModel, set_peft_model_state_dict
from safetensors.torch import load_file
from transformers import Trainer, TrainerCallback

from spacedg.eval.scoring import score
from spacedg.vlm import generate

__all__ = ["EpochCallback", "SFTTrainer", "SaveProcessorCallback", "ValItem", "latest_checkpoint"]

ValItem = dict  # {"conversation" (without the assistant turn), "images", "degradation_type", "truth": {...}}


class SaveProcessorCallback(TrainerCallback):
    """Save the processor (and run metadata) into each ``checkpoint-N`` folder, on the main process."""

    def __init__(self, processor: Any, extra_files: dict[str, str] | None = None) -> None:
        self.processor = processor
        self.extra_files = extra_files or {}

    def on_save(self, args: Any, state: Any, control: Any, **kwargs: Any) -> None:
        if not state.is_world_process_zero:
            return
        folder = Path(args.output_dir) / f"checkpoint-{state.global_step}"
        if folder.is_dir():
            self.processor.save_pretrained(folder)
            for name, text in self.extra_files.items():
                (folder / name).write_text(text)


class EpochCallback(TrainerCallback):
    """Tell the training data a new epoch began (online SpaceDG samples draw new degradations)."""

    def __init__(self, dataset: Any) -> None:
        self.dataset = dataset

    def on_epoch_begin(self, args: Any, state: Any, control: Any, **kwargs: Any) -> None:
        if hasattr(self.dataset, "set_epoch"):
            self.dataset.set_epoch(int(state.epoch or 0))


class SFTTrainer(Trainer):
    """``Trainer`` with strict resume and generation-based evaluation (see the module docstring).

    Args:
        val_items: evaluation items (may be empty: no evaluation).
        processor: the model's processor (for generation).
        val_max_new_tokens / val_batch_size: generation settings of the evaluation (``data.val``).
        Other arguments go to :class:`transformers.Trainer`.
    """

    def __init__(self, *args: Any, val_items: Sequence[ValItem], processor: Any, val_max_new_tokens: int,
                 val_batch_size: int, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.val_items = list(val_items)
        self.val_processor = processor
        self.val_max_new_tokens = int(val_max_new_tokens)
        self.val_batch_size = max(1, int(val_batch_size))

    # -------------------------------------------------------------- resume
    def _load_from_checkpoint(self, resume_from_checkpoint: str, model: Any = None) -> None:
        model = self.model if model is None else model
        folder = Path(resume_from_checkpoint)
        if isinstance(model, PeftModel):
            weights = folder / "adapter_model.safetensors"
            if not weights.is_file():
                raise FileNotFoundError(f"{folder}: no adapter_model.safetensors to resume the LoRA adapters from")
            result = set_peft_model_state_dict(model, load_file(str(weights)))
            missing = [k for k in getattr(result, "unexpected_keys", []) if "lora_" in k]
            if missing:
                raise RuntimeError(f"{folder}: adapter weights {missing[:3]} did not match the model")
            return
        if not (folder / "config.json").is_file():
            return super()._load_from_checkpoint(resume_from_checkpoint, model)
        loaded = type(model).from_pretrained(folder, dtype=next(model.parameters()).dtype)
        state = loaded.state_dict()
        model.load_state_dict(state, strict=True)
        del loaded, state

    # -------------------------------------------------------------- evaluation
    def evaluate(self, eval_dataset: Any = None, ignore_keys: Any = None, metric_key_prefix: str = "eval") -> dict[str, float]:
        if not self.val_items or self.is_fsdp_enabled:
            return {}
        rank, world = self.args.process_index, self.args.world_size
        mine = self.val_items[rank::world]
        model = self.accelerator.unwrap_model(self.model)
        was_training = model.training
        model.eval()
        results: list[tuple[str, float]] = []
        try:
            for start in range(0, len(mine), self.val_batch_size):
                batch = mine[start:start + self.val_batch_size]
                answers = generate(model, self.val_processor, [b["conversation"] for b in batch], [b["images"] for b in batch],
                                   max_new_tokens=self.val_max_new_tokens)
                results += [(b["degradation_type"], score(text, b["truth"]).score) for b, text in zip(batch, answers)]
        finally:
            model.train(was_training)
        if world > 1:
            gathered: list[Any] = [None] * world
            torch.distributed.all_gather_object(gathered, results)
            results = [r for part in gathered for r in part]
        metrics: dict[str, float] = {}
        if results:
            metrics[f"{metric_key_prefix}_score"] = sum(s for _, s in results) / len(results)
            for condition in sorted({c for c, _ in results}):
                values = [s for c, s in results if c == condition]
                metrics[f"{metric_key_prefix}_score_{condition}"] = sum(values) / len(values)
            metrics[f"{metric_key_prefix}_samples"] = float(len(results))
        self.log(metrics)
        self.control = self.callback_handler.on_evaluate(self.args, self.state, self.control, metrics)
        return metrics


def latest_checkpoint(output_dir: str | os.PathLike[str]) -> Path | None:
    """The ``checkpoint-N`` folder with the largest ``N`` in ``output_dir``, or ``None``."""
    folder = Path(output_dir)
    steps = [(int(p.name.split("-")[1]), p) for p in folder.glob("checkpoint-*") if p.name.split("-")[1].isdigit()]
    return max(steps)[1] if steps else None

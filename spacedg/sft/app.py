"""``python -m spacedg.sft +experiment=qwen``: supervised fine-tuning of a VLM on SpaceDG samples.

The Hydra app reads ``conf/sft.yaml`` (shipped in the package as ``spacedg.conf``) and instantiates
its ``data`` group into :class:`~spacedg.sft.sources.DataOptions` (degradation names checked before
anything is built) and its ``model`` group into :class:`~spacedg.sft.model.ModelOptions`
(:func:`spacedg.sft.config.build`: ``hydra.utils.instantiate`` with spacedg's errors). From those it
builds the model (:func:`~spacedg.sft.model.prepare_model`), the training data (online degraded
samples or an exported JSONL, under a token budget: :mod:`spacedg.sft.data`), the val items, the
collator (:mod:`spacedg.sft.collator`) and the trainer (:mod:`spacedg.sft.trainer`, with
``TrainingArguments`` from the ``train`` group), then trains. ``output_dir`` receives:

* ``checkpoint-N/``: weights (or LoRA adapters), optimizer state, the processor (with its image
  budget and chat template) and ``spacedg_sft.yaml``; ``spacedg predict --model`` loads it;
* ``final/``: the trained model (LoRA merged) with its processor: ``spacedg predict`` loads it;
* ``data_stats.json``: samples kept and dropped by the token budget; ``train_summary.json``:
  losses, steps and the last evaluation.

Under ``torchrun`` every process renders its own share of the samples (``DistributedSampler``);
set ``output_dir`` (or ``hydra.run.dir``) explicitly, since each rank evaluates ``${now:}``.
"""

from __future__ import annotations

import dataclasses
import json
import multiprocessing
import os
import random
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import hydra
import numpy as np
import torch
from omegaconf import DictConfig, OmegaConf
from transformers import TrainingArguments

from spacedg.errors import ParameterError, SpaceDGError
from spacedg.sft.collator import SFTCollator
from spacedg.sft.config import build
from spacedg.sft.data import BudgetedDataset, token_lengths
from spacedg.sft.model import ModelOptions, prepare_model, save_for_inference, trainable_summary
from spacedg.sft.sources import DataOptions
from spacedg.sft.template import ensure_generation_markers
from spacedg.sft.trainer import EpochCallback, SaveProcessorCallback, SFTTrainer, latest_checkpoint
from spacedg.vlm import save_tiny_vlm

__all__ = ["main", "run", "training_arguments"]


def _bf16(value: Any) -> bool:
    if value == "auto":
        return bool(torch.cuda.is_available() and torch.cuda.is_bf16_supported())
    return bool(value)


def training_arguments(train: Mapping[str, Any], output_dir: Path, seed: int, evaluate: bool) -> TrainingArguments:
    """``TrainingArguments`` from the ``train`` group (keys set to null are left to transformers'
    defaults; ``bf16: auto`` is on where the device supports it); an unknown key is one clear error."""
    options = {k: v for k, v in train.items() if v is not None}
    if "bf16" in options:
        options["bf16"] = _bf16(options["bf16"])
    if not torch.cuda.is_available():
        # Without this, accelerate treats a multi-process CPU launch (torchrun) as not distributed and
        # every rank would train its own copy; with it, DDP runs on gloo.
        options.setdefault("use_cpu", True)
    eval_steps = options.pop("eval_steps", None)
    if evaluate and eval_steps:
        options.update(eval_strategy="steps", eval_steps=eval_steps)
    else:
        options["eval_strategy"] = "no"
    try:
        return TrainingArguments(output_dir=str(output_dir), seed=seed, remove_unused_columns=False, **options)
    except TypeError as err:
        raise ParameterError(f"train: {err}; see transformers.TrainingArguments for the accepted keys") from None


def _resume_path(resume: Any, output_dir: Path) -> str | None:
    if resume in (None, False, "", "null"):
        return None
    if resume == "auto":
        found = latest_checkpoint(output_dir)
        return str(found) if found else None
    path = Path(str(resume))
    if not path.is_dir():
        raise ParameterError(f"resume={resume}: no such checkpoint folder; use a checkpoint-N folder, auto or null")
    return str(path)


def _model_options(node: DictConfig, output_dir: Path) -> ModelOptions:
    """The ``model`` group as :class:`ModelOptions`. A tiny model built in code is saved first (once, to
    ``output_dir/base-model``), so checkpoints (LoRA adapters included) name a real base folder; ranks
    other than the first build the same weights in memory (same seed) instead of racing on the folder."""
    options: ModelOptions = build(node, "model")
    if options.tiny_family is None or int(os.environ.get("LOCAL_RANK", "0")) != 0:
        return options
    folder = output_dir / "base-model"
    if not (folder / "config.json").is_file():
        save_tiny_vlm(folder, options.tiny_family)
    return dataclasses.replace(options, path=str(folder))


def _seed_everything(seed: int) -> None:
    random.seed(seed)
    np.random.seed(seed)
    torch.manual_seed(seed)


def run(cfg: DictConfig | Mapping[str, Any]) -> dict[str, Any]:
    """Train as ``cfg`` (the composed Hydra config, or a plain dict of the same shape) says;
    returns the summary also written to ``train_summary.json``."""
    cfg = cfg if isinstance(cfg, DictConfig) else OmegaConf.create(dict(cfg))
    config = OmegaConf.to_container(cfg, resolve=True)
    output_dir = Path(config["output_dir"])
    seed = config["seed"]
    _seed_everything(seed)
    data: DataOptions = build(cfg.data, "data")  # degradation names are checked here, before any model or index
    model, processor = prepare_model(_model_options(cfg.model, output_dir))
    replaced = ensure_generation_markers(processor)
    train_data = data.train_data()
    lengths = token_lengths(train_data, processor)
    budgeted = BudgetedDataset(train_data, lengths, data.max_length)
    val_items = data.val_items()
    args = training_arguments(config["train"], output_dir, seed, evaluate=bool(val_items))
    if args.dataloader_num_workers > 0:
        # The main process has rendered (val items): numba's OpenMP threads are not fork-safe, so workers start
        # from a fork server (the datasets pickle small).
        multiprocessing.set_start_method("forkserver", force=True)
    trainer = SFTTrainer(
        model=model, args=args, train_dataset=budgeted, eval_dataset=val_items or None,
        data_collator=SFTCollator(processor, data.max_length),
        val_items=val_items, processor=processor, val_max_new_tokens=data.val.max_new_tokens,
        val_batch_size=data.val.batch_size,
        callbacks=[SaveProcessorCallback(processor, {"spacedg_sft.yaml": OmegaConf.to_yaml(OmegaConf.create(config))}),
                   EpochCallback(train_data)],
    )
    stats = {"samples": len(lengths), "kept": len(budgeted), "dropped_over_budget": budgeted.dropped,
             "longest_tokens": budgeted.longest, "max_length": data.max_length,
             "chat_template_replaced": replaced, "parameters": trainable_summary(model)}
    if args.process_index == 0:
        output_dir.mkdir(parents=True, exist_ok=True)
        (output_dir / "data_stats.json").write_text(json.dumps(stats, indent=2) + "\n")
    result = trainer.train(resume_from_checkpoint=_resume_path(config["resume"], output_dir))
    losses = [entry["loss"] for entry in trainer.state.log_history if "loss" in entry]
    evaluations = [entry for entry in trainer.state.log_history if "eval_score" in entry]
    summary = {
        "global_step": trainer.state.global_step, "train_loss": result.training_loss, "losses": losses,
        "train_runtime_s": result.metrics.get("train_runtime"),
        "last_evaluation": evaluations[-1] if evaluations else None, "dropped_in_collator": trainer.data_collator.dropped,
        "data": stats,
        "distributed": {"world_size": args.world_size, "parallel_mode": str(args.parallel_mode.value),
                        "fsdp": bool(trainer.is_fsdp_enabled), "deepspeed": bool(trainer.is_deepspeed_enabled),
                        "model_class": type(trainer.model_wrapped).__name__},
    }
    if trainer.is_world_process_zero():
        final = save_for_inference(trainer.accelerator.unwrap_model(trainer.model), processor, output_dir / "final")
        summary["final_model"] = str(final)
        (output_dir / "train_summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    return summary


def main() -> None:
    """Console entry point (``spacedg-sft`` and ``python -m spacedg.sft``)."""

    @hydra.main(version_base="1.3", config_path="pkg://spacedg.conf", config_name="sft")
    def _app(cfg: Any) -> None:
        try:
            run(cfg)
        except SpaceDGError as err:  # one clear line, as the spacedg CLI prints it (Hydra would print a traceback)
            print(f"spacedg-sft: error: {err}", file=sys.stderr)
            raise SystemExit(2) from None

    os.environ.setdefault("TOKENIZERS_PARALLELISM", "false")
    _app()

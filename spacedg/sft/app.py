"""``python -m spacedg.sft +experiment=qwen``: supervised fine-tuning of a VLM on SpaceDG samples.

The Hydra app reads ``conf/sft.yaml`` (shipped in the package as ``spacedg.conf``), builds the
model (:mod:`spacedg.sft.model`), the training data (:mod:`spacedg.sft.data`: online degraded
samples or an exported JSONL, under a token budget), the collator (:mod:`spacedg.sft.collator`)
and the trainer (:mod:`spacedg.sft.trainer`), then trains. ``output_dir`` receives:

* ``checkpoint-N/``: weights (or LoRA adapters), optimizer state, the processor (with its image
  budget and chat template) and ``spacedg_sft.yaml``; ``spacedg predict --model`` loads it;
* ``final/``: the trained model (LoRA merged) with its processor: ``spacedg predict`` loads it;
* ``data_stats.json``: samples kept and dropped by the token budget; ``train_summary.json``:
  losses, steps and the last evaluation.

Under ``torchrun`` every process renders its own share of the samples (``DistributedSampler``);
set ``output_dir`` (or ``hydra.run.dir``) explicitly, since each rank evaluates ``${now:}``.
"""

from __future__ import annotations

import json
import os
import random
from pathlib import Path
from typing import Any

import numpy as np
import torch

from spacedg.errors import ParameterError

__all__ = ["build_val_items", "main", "run"]


def _plain(cfg: Any) -> dict[str, Any]:
    from omegaconf import OmegaConf

    return OmegaConf.to_container(cfg, resolve=True) if not isinstance(cfg, dict) else dict(cfg)


def _spacedg_dataset(data: dict[str, Any], split: str, degradations: Any, clean_prob: float) -> Any:
    from spacedg.data.dataset import SpaceDGDataset
    from spacedg.data.chain import BENCH_DEGRADATIONS

    size = data.get("image_size")
    if degradations is None:  # the config's null means the paper's nine (the dataset's own default is clean only)
        degradations = list(BENCH_DEGRADATIONS)
    return SpaceDGDataset(
        split, degradations, scenes=data.get("scenes"), question_types=data.get("question_types"),
        severity=data.get("severity", "random") if split != "bench" else "bench", clean_prob=clean_prob,
        image_size=tuple(size) if size else None, seed=int(data.get("seed", 0)),
        max_questions=data.get("max_questions") if split == "train" else None,
        builtin_rooms=int(data.get("builtin_rooms", 16)),
    )


def build_train_data(data: dict[str, Any]) -> Any:
    """The unbudgeted training samples of ``data`` (the ``data`` config group as a dict)."""
    from spacedg.sft.data import ChatJsonlDataset, OnlineSFTDataset

    source = data.get("source", "online")
    if source == "jsonl":
        if not data.get("jsonl"):
            raise ParameterError("data.source=jsonl needs data.jsonl=PATH (a chat .jsonl written by spacedg export)")
        return ChatJsonlDataset(data["jsonl"])
    if source != "online":
        raise ParameterError(f"data.source must be online or jsonl, got {source!r}")
    return OnlineSFTDataset(_spacedg_dataset(data, "train", data.get("degradations"), float(data.get("clean_prob", 0.1))))


def build_val_items(data: dict[str, Any]) -> list[dict[str, Any]]:
    """``data.val.samples`` items of the ``val`` split (a seeded spread), rendered once, each with
    its prompt (no answer), images, condition and the fields the scorer reads."""
    from spacedg.data.chat import chat_messages, format_question, item_images

    val = data.get("val") or {}
    count = int(val.get("samples", 0))
    if count <= 0 or data.get("source", "online") != "online":
        return []
    dataset = _spacedg_dataset(data, "val", val.get("degradations"), float(val.get("clean_prob", 0.1)))
    order = np.random.default_rng(int(data.get("seed", 0))).permutation(len(dataset))[:count]
    items = []
    for index in sorted(int(i) for i in order):
        item = dataset[index]
        images = item_images(item)
        conversation = chat_messages(format_question(item["question"], item["options"]), len(images))
        truth = {k: item[k] for k in ("answer", "answer_type", "question_type", "sub_question_type")}
        truth["options"] = {"ABCD"[i]: text for i, text in enumerate(item["options"])}
        items.append({"conversation": conversation, "images": images, "degradation_type": item["degradation_type"], "truth": truth})
    return items


def _bf16(value: Any) -> bool:
    if value == "auto":
        return bool(torch.cuda.is_available() and torch.cuda.is_bf16_supported())
    return bool(value)


def training_arguments(train: dict[str, Any], output_dir: Path, seed: int, evaluate: bool) -> Any:
    """``TrainingArguments`` from the ``train`` group; an unknown key is one clear error."""
    from transformers import TrainingArguments

    options = {k: v for k, v in train.items() if v is not None}
    options["bf16"] = _bf16(options.get("bf16", "auto"))
    if not torch.cuda.is_available():
        # Without this, accelerate treats a multi-process CPU launch (torchrun) as not distributed and
        # every rank would train its own copy; with it, DDP runs on gloo.
        options.setdefault("use_cpu", True)
    eval_steps = options.pop("eval_steps", None)
    options.setdefault("save_strategy", "steps")
    if evaluate and eval_steps:
        options.update(eval_strategy="steps", eval_steps=eval_steps)
    else:
        options["eval_strategy"] = "no"
    try:
        return TrainingArguments(output_dir=str(output_dir), seed=seed, remove_unused_columns=False, **options)
    except TypeError as err:
        raise ParameterError(f"train: {err}; see transformers.TrainingArguments for the accepted keys") from None


def _resume_path(resume: Any, output_dir: Path) -> str | None:
    from spacedg.sft.trainer import latest_checkpoint

    if resume in (None, False, "", "null"):
        return None
    if resume == "auto":
        found = latest_checkpoint(output_dir)
        return str(found) if found else None
    path = Path(str(resume))
    if not path.is_dir():
        raise ParameterError(f"resume={resume}: no such checkpoint folder; use a checkpoint-N folder, auto or null")
    return str(path)


def _tiny_base(path: str, folder: Path) -> Path:
    """``tiny:<family>`` saved to ``folder`` (once; reused when it exists)."""
    from spacedg.vlm import save_tiny_vlm

    if not (folder / "config.json").is_file():
        save_tiny_vlm(folder, path.split(":", 1)[1])
    return folder


def _seed_everything(seed: int) -> None:
    random.seed(seed)
    np.random.seed(seed)
    torch.manual_seed(seed)


def run(cfg: Any) -> dict[str, Any]:
    """Train as ``cfg`` (the composed Hydra config, or a plain dict of the same shape) says;
    returns the summary also written to ``train_summary.json``."""
    from spacedg.sft.collator import SFTCollator
    from spacedg.sft.data import BudgetedDataset, token_lengths
    from spacedg.sft.model import ModelOptions, prepare_model, save_for_inference, trainable_summary
    from spacedg.sft.template import ensure_generation_markers
    from spacedg.sft.trainer import EpochCallback, SaveProcessorCallback, SFTTrainer

    config = _plain(cfg)
    output_dir = Path(config["output_dir"])
    seed = int(config.get("seed", 0))
    _seed_everything(seed)
    data = dict(config["data"])
    model_config = dict(config["model"])
    if str(model_config["path"]).startswith("tiny:") and int(os.environ.get("LOCAL_RANK", "0")) == 0:
        # A tiny model built in code is saved first, so checkpoints (LoRA adapters included) name a real base folder.
        # Other ranks build the same weights in memory (same seed) instead of racing on the folder.
        model_config["path"] = str(_tiny_base(str(model_config["path"]), output_dir / "base-model"))
    try:
        options = ModelOptions(**model_config)
    except TypeError as err:
        raise ParameterError(f"model: {err}; the model group takes the fields of spacedg.sft.model.ModelOptions") from None
    model, processor = prepare_model(options)
    replaced = ensure_generation_markers(processor)
    train_data = build_train_data(data)
    lengths = token_lengths(train_data, processor)
    budgeted = BudgetedDataset(train_data, lengths, int(data.get("max_length", 4096)))
    val_items = build_val_items(data)
    if int(config["train"].get("dataloader_num_workers") or 0) > 0:
        # The main process has rendered (val items): numba's OpenMP threads are not fork-safe, so workers start
        # from a fork server (the datasets pickle small).
        import multiprocessing

        multiprocessing.set_start_method("forkserver", force=True)
    args = training_arguments(dict(config["train"]), output_dir, seed, evaluate=bool(val_items))
    val = data.get("val") or {}
    from omegaconf import OmegaConf

    trainer = SFTTrainer(
        model=model, args=args, train_dataset=budgeted, eval_dataset=val_items or None,
        data_collator=SFTCollator(processor, int(data.get("max_length", 4096))),
        val_items=val_items, processor=processor, val_max_new_tokens=int(val.get("max_new_tokens", 32)),
        val_batch_size=int(val.get("batch_size", 8)),
        callbacks=[SaveProcessorCallback(processor, {"spacedg_sft.yaml": OmegaConf.to_yaml(OmegaConf.create(config))}),
                   EpochCallback(train_data)],
    )
    stats = {"samples": len(lengths), "kept": len(budgeted), "dropped_over_budget": budgeted.dropped,
             "longest_tokens": budgeted.longest, "max_length": int(data.get("max_length", 4096)),
             "chat_template_replaced": replaced, "parameters": trainable_summary(model)}
    if args.process_index == 0:
        output_dir.mkdir(parents=True, exist_ok=True)
        (output_dir / "data_stats.json").write_text(json.dumps(stats, indent=2) + "\n")
    result = trainer.train(resume_from_checkpoint=_resume_path(config.get("resume"), output_dir))
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
    import hydra

    @hydra.main(version_base="1.3", config_path="pkg://spacedg.conf", config_name="sft")
    def _app(cfg: Any) -> None:
        run(cfg)

    os.environ.setdefault("TOKENIZERS_PARALLELISM", "false")
    _app()

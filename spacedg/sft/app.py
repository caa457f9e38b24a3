"""Supervised fine-tuning of a VLM on SpaceDG samples: what ``python -m spacedg.sft +experiment=qwen`` runs
(its entry point, :mod:`spacedg.sft.command`, imports this module only once a run starts).

The Hydra app reads ``conf/sft.yaml`` (shipped in the package as ``spacedg.conf``) and instantiates
its ``data`` group into :class:`~spacedg.sft.sources.DataOptions` (degradation names checked before
anything is built) and its ``model`` group into :class:`~spacedg.sft.model.ModelOptions`
(:func:`spacedg.sft.config.build`: ``hydra.utils.instantiate`` with spacedg's errors). It then
builds the ``TrainingArguments`` from the ``train`` group *before* the model: they start the
process group and fix the launch (:func:`spacedg.sft.distributed.launch_of`: one process, DDP,
FSDP 1/2, DeepSpeed ZeRO; presets ``train=fsdp``, ``fsdp1``, ``zero2``, ``zero3``), so the model is
loaded as the launch needs it (storage dtypes for the launch's mixed precision; FSDP ranks > 0 on
the meta device; ZeRO-3 partitioned). Then the model (:func:`~spacedg.sft.model.prepare_model`),
the training data (online degraded samples or an exported JSONL, under a token budget:
:mod:`spacedg.sft.data`), the val split (checked now; each rank renders its share of the val items at the
first evaluation), the collator (:mod:`spacedg.sft.collator`) and the
trainer (:mod:`spacedg.sft.trainer`, with the loss of :mod:`spacedg.sft.loss`), then it trains.
``output_dir`` receives:

* ``checkpoint-N/``: weights (or LoRA adapters; FSDP: sharded), optimizer state, the processor
  (with its image budget and chat template) and ``spacedg_sft.yaml``; ``spacedg predict --model``
  loads the unsharded ones;
* ``final/``: the trained model (LoRA merged; gathered from the shards under FSDP / ZeRO-3; bf16
  after bf16 training) with its processor: ``spacedg predict`` loads it;
* ``data_stats.json``: samples kept and dropped by the token budget; ``train_summary.json``:
  losses, steps, the last evaluation, the launch and the bytes each rank held.

Under ``torchrun`` every process renders its own share of the samples (``DistributedSampler``);
set ``output_dir`` (or ``hydra.run.dir``) explicitly, since each rank evaluates ``${now:}``.
"""

from __future__ import annotations

import dataclasses
import gc
import json
import logging
import multiprocessing
import os
import random
from collections.abc import Mapping
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
import torch
from omegaconf import DictConfig, OmegaConf
from transformers import TrainingArguments

from spacedg.data.workers import loader_plan
from spacedg.errors import ParameterError
from spacedg.sft.collator import SFTCollator
from spacedg.sft.config import build
from spacedg.sft.data import BudgetedDataset, token_lengths
from spacedg.sft.distributed import Launch, launch_of, wrap_classes
from spacedg.sft.loss import LOSSES
from spacedg.sft.memory import memory_for
from spacedg.sft.model import HALF_DTYPES, ModelOptions, prepare_model, trainable_summary
from spacedg.sft.sources import DataOptions
from spacedg.sft.template import ensure_generation_markers
from spacedg.sft.trainer import (
    EpochCallback, MemoryProbe, SaveProcessorCallback, SFTTrainer, ValShare, is_complete, latest_checkpoint,
)
from spacedg.vlm import save_tiny_vlm

__all__ = ["SPACEDG_TRAIN_KEYS", "run", "shut_down_process_group", "training_arguments"]

log = logging.getLogger(__name__)


def _bf16(value: Any) -> bool:
    if value == "auto":
        return bool(torch.cuda.is_available() and torch.cuda.is_bf16_supported())
    return bool(value)


#: Keys of the ``train`` group that are spacedg's, not ``TrainingArguments``'.
SPACEDG_TRAIN_KEYS = ("loss",)


def training_arguments(train: Mapping[str, Any], output_dir: Path, seed: int, evaluate: bool) -> TrainingArguments:
    """``TrainingArguments`` from the ``train`` group (keys set to null are left to transformers'
    defaults; ``bf16: auto`` is on where the device supports it; ``dataloader_num_workers: auto``
    is :func:`spacedg.data.workers.loader_plan`'s ``min(8, cores // 2)`` per process; spacedg's own keys,
    :data:`SPACEDG_TRAIN_KEYS`, are left out); an unknown key is one clear error. Under torchrun
    the process group is initialised here (before the model loads, so sharded launches can load it
    sharded)."""
    options = {k: v for k, v in train.items() if v is not None and k not in SPACEDG_TRAIN_KEYS}
    if options.get("dataloader_num_workers") == "auto":
        # rendering workers from this process's share of the node's cores (spacedg.data.workers)
        options["dataloader_num_workers"] = loader_plan().workers
    if "bf16" in options:
        options["bf16"] = _bf16(options["bf16"])
    cpu_deepspeed = not torch.cuda.is_available() and bool(options.get("deepspeed"))
    if cpu_deepspeed:
        _cpu_deepspeed_state(options)
    elif not torch.cuda.is_available():
        # Without this, accelerate treats a multi-process CPU launch (torchrun) as not distributed and
        # every rank would train its own copy; with it, DDP (or FSDP, see spacedg.sft.distributed) runs on gloo.
        options.setdefault("use_cpu", True)
    eval_steps = options.pop("eval_steps", None)
    if evaluate and eval_steps:
        options.update(eval_strategy="steps", eval_steps=eval_steps)
    else:
        options["eval_strategy"] = "no"
    # the loss of spacedg.sft.loss counts the step's items over all ranks
    options.setdefault("average_tokens_across_devices", True)
    try:
        args = TrainingArguments(output_dir=str(output_dir), seed=seed, remove_unused_columns=False, **options)
    except TypeError as err:
        raise ParameterError(f"train: {err}; see transformers.TrainingArguments for the accepted keys") from None
    _ = args.device  # sets up the process group under torchrun
    return args


def _cpu_deepspeed_state(options: dict[str, Any]) -> None:
    """DeepSpeed without CUDA (its CPU accelerator, gloo; used by the tests under torchrun): accelerate
    picks no backend for it and would count one process. Set up its process state first, on gloo,
    and let the training arguments use it."""
    from accelerate import PartialState

    if int(os.environ.get("WORLD_SIZE", "1")) < 2:
        raise ParameterError("DeepSpeed without CUDA runs only under torchrun (several processes, gloo)")
    os.environ["ACCELERATE_USE_DEEPSPEED"] = "true"
    try:
        PartialState(cpu=False, backend="gloo")
    finally:
        del os.environ["ACCELERATE_USE_DEEPSPEED"]
    options["accelerator_config"] = dict(options.get("accelerator_config") or {}, use_configured_state=True)


def _resume_path(resume: Any, output_dir: Path) -> str | None:
    if resume in (None, False, "", "null"):
        return None
    if resume == "auto":
        found = latest_checkpoint(output_dir)
        skipped = sorted(p.name for p in output_dir.glob("checkpoint-*") if p.is_dir() and not is_complete(p)
                         and (found is None or _step(p) > _step(found)))
        if skipped:
            log.warning("resume=auto: skipping %s (save interrupted: no trainer_state.json)", ", ".join(skipped))
        return str(found) if found else None
    path = Path(str(resume))
    if not path.is_dir():
        raise ParameterError(f"resume={resume}: no such checkpoint folder; use a checkpoint-N folder, auto or null")
    if not is_complete(path):
        raise ParameterError(f"resume={resume}: this checkpoint is incomplete (no trainer_state.json: its save was "
                             f"interrupted); resume from an earlier one, or use resume=auto")
    return str(path)


def _step(folder: Path) -> int:
    tail = folder.name.split("-")[-1]
    return int(tail) if tail.isdigit() else -1


def _barrier() -> None:
    if torch.distributed.is_available() and torch.distributed.is_initialized():
        torch.distributed.barrier()


def _save_tiny_base(options: ModelOptions, output_dir: Path) -> ModelOptions:
    """A tiny model built in code is saved first, to ``output_dir/base-model``, by the first process of
    each machine and before the process group (and DeepSpeed's ZeRO-3, whose ``save_pretrained``
    would wait on the other ranks) exists; every process then loads that folder (after
    :func:`_barrier`), so checkpoints (LoRA adapters included) name a real base folder and sharded
    launches load it as they would a real model."""
    if options.tiny_family is None:
        return options
    folder = output_dir / "base-model"
    if int(os.environ.get("LOCAL_RANK", "0")) == 0 and not (folder / "config.json").is_file():
        save_tiny_vlm(folder, options.tiny_family)
    return dataclasses.replace(options, path=str(folder))


def _for_launch(options: ModelOptions, launch: Launch, args: TrainingArguments) -> ModelOptions:
    """One activation checkpointing under FSDP: FSDP's own (``fsdp_config.activation_checkpointing``)
    switches the model's off (checkpointing twice recomputes twice); except with LoRA, where FSDP's
    is switched off and the model's kept (peft cannot save adapters through FSDP's checkpoint
    wrappers: its sharded adapter checkpoints came out empty)."""
    plugin = args.fsdp_plugin_args
    if launch.kind != "fsdp" or plugin is None or not plugin.get("activation_checkpointing"):
        return options
    if options.lora:
        plugin["activation_checkpointing"] = False
        args.fsdp_config["activation_checkpointing"] = False
        return options
    return dataclasses.replace(options, gradient_checkpointing=False)


def _fill_wrap_classes(args: TrainingArguments, model: Any) -> list[str] | None:
    """FSDP's ``transformer_layer_cls_to_wrap: auto`` (or unset): the model's decoder layer and vision
    block classes (:func:`spacedg.sft.distributed.wrap_classes`)."""
    plugin = args.fsdp_plugin_args
    if plugin is None or plugin.get("auto_wrap_policy") != "TRANSFORMER_BASED_WRAP":
        return None
    given = plugin.get("transformer_cls_names_to_wrap")
    if given not in (None, "auto", "null", "None"):
        return [name for name in str(given).split(",") if name]
    classes = wrap_classes(model)
    plugin["transformer_cls_names_to_wrap"] = ",".join(classes)
    args.fsdp_config["transformer_layer_cls_to_wrap"] = classes
    return classes


def _memory(probe: MemoryProbe, predicted: dict[int, dict[str, int]], world: int) -> dict[str, Any] | None:
    """Bytes measured on every rank (collective) next to :func:`spacedg.sft.memory.predict`'s."""
    measured: list[Any] = [probe.measured]
    if world > 1:
        measured = [None] * world
        torch.distributed.all_gather_object(measured, probe.measured)
    if not any(measured):
        return None
    return {"per_rank": [dict(m or {}, predicted=predicted.get(rank)) for rank, m in enumerate(measured)]}


def _seed_everything(seed: int) -> None:
    random.seed(seed)
    np.random.seed(seed)
    torch.manual_seed(seed)


def _val_share(data: DataOptions, rank: int, world: int) -> ValShare | None:
    """This rank's evaluation items (``None`` without evaluation): the ``val`` split built and checked now (a
    wrong scene or an empty split fails before training), its items rendered at the first evaluation, this
    rank's share only (none under FSDP or ZeRO-3, which do not evaluate)."""
    val = data.val_dataset()
    if val is None:
        return None
    if len(val) == 0:
        raise ParameterError(
            f"data.val: the val split of {data.scenes_description()} holds no questions to evaluate on (with these "
            "question types); set data.val.samples=0 to train without evaluation, or give scenes whose val split has questions"
        )
    return ValShare(partial(data.val_items, rank, world, val))


def run(cfg: DictConfig | Mapping[str, Any]) -> dict[str, Any]:
    """Train as ``cfg`` (the composed Hydra config, or a plain dict of the same shape) says;
    returns the summary also written to ``train_summary.json`` (on every rank; rank 0 writes it)."""
    cfg = cfg if isinstance(cfg, DictConfig) else OmegaConf.create(dict(cfg))
    config = OmegaConf.to_container(cfg, resolve=True)
    output_dir = Path(config["output_dir"])
    seed = config["seed"]
    _seed_everything(seed)
    data: DataOptions = build(cfg.data, "data")  # degradation names are checked here, before any model or index
    options: ModelOptions = build(cfg.model, "model")
    loss = config["train"].get("loss")
    if loss not in LOSSES:
        raise ParameterError(f"train.loss must be one of {', '.join(LOSSES)}, got {loss!r}")
    options = _save_tiny_base(options, output_dir)
    # the training arguments before the model: the process group, ZeRO-3's partitioned loading and the
    # storage dtypes all depend on the launch
    args = training_arguments(config["train"], output_dir, seed, evaluate=data.val.samples > 0)
    _barrier()
    launch = launch_of(args)
    options = _for_launch(options, launch, args)
    # FSDP with cpu_ram_efficient_loading: only rank 0 reads the weights; accelerate broadcasts them into
    # the other ranks' shards (transformers 5.23 would read them on every rank)
    rank0_reads = launch.kind == "fsdp" and bool((args.fsdp_plugin_args or {}).get("cpu_ram_efficient_loading"))
    empty = rank0_reads and args.process_index != 0
    model, processor = prepare_model(options, mixed_precision=launch.mixed_precision,
                                     shards_parameters=launch.shards_parameters, empty_weights=empty)
    wrapped = _fill_wrap_classes(args, model)
    predicted = {rank: memory_for(model, launch, rank=rank) for rank in range(args.world_size)}
    replaced = ensure_generation_markers(processor)
    train_data = data.train_data()
    lengths = token_lengths(train_data, processor)
    budgeted = BudgetedDataset(train_data, lengths, data.max_length)
    val_items = _val_share(data, args.process_index, args.world_size)
    if data.render_device not in (None, "cpu") and args.dataloader_num_workers > 0:
        raise ParameterError(
            f"data.render_device={data.render_device} renders on the GPU in the training process; DataLoader workers must not "
            f"touch CUDA: set train.dataloader_num_workers=0 (got {args.dataloader_num_workers})"
        )
    if args.dataloader_num_workers > 0:
        # The main process renders (the val items, at the first evaluation): numba's OpenMP threads are not
        # fork-safe, so workers start from a fork server (the datasets pickle small).
        multiprocessing.set_start_method("forkserver", force=True)
    probe = MemoryProbe()
    trainer = SFTTrainer(
        model=model, args=args, train_dataset=budgeted, eval_dataset=val_items,
        data_collator=SFTCollator(processor, data.max_length, trim_logits=True),
        val_items=val_items, processor=processor, val_max_new_tokens=data.val.max_new_tokens,
        val_batch_size=data.val.batch_size, loss=loss, model_options=options,
        callbacks=[SaveProcessorCallback(processor, {"spacedg_sft.yaml": OmegaConf.to_yaml(OmegaConf.create(config))}),
                   EpochCallback(train_data), probe],
    )
    stats = {"samples": len(lengths), "kept": len(budgeted), "dropped_over_budget": budgeted.dropped,
             "longest_tokens": budgeted.longest, "max_length": data.max_length,
             "chat_template_replaced": replaced, "parameters": trainable_summary(model)}
    if args.process_index == 0:
        output_dir.mkdir(parents=True, exist_ok=True)
        (output_dir / "data_stats.json").write_text(json.dumps(stats, indent=2) + "\n")
    result = trainer.train(resume_from_checkpoint=_resume_path(config["resume"], output_dir))
    final = trainer.export_final(output_dir / "final", save_dtype=HALF_DTYPES.get(launch.mixed_precision))
    losses = [entry["loss"] for entry in trainer.state.log_history if "loss" in entry]
    evaluations = [entry for entry in trainer.state.log_history if "eval_score" in entry]
    collator = trainer.data_collator
    summary = {
        "global_step": trainer.state.global_step, "train_loss": result.training_loss, "losses": losses,
        "train_runtime_s": result.metrics.get("train_runtime"),
        "last_evaluation": evaluations[-1] if evaluations else None,
        "evaluation": data.val_description(),
        "dropped_in_collator": collator.dropped, "filler_batches": collator.fillers,
        "data": stats, "loss": loss,
        "distributed": {"world_size": args.world_size, "parallel_mode": str(args.parallel_mode.value),
                        "launch": launch.name, "mixed_precision": launch.mixed_precision,
                        "fsdp": bool(trainer.is_fsdp_enabled), "deepspeed": bool(trainer.is_deepspeed_enabled),
                        "model_class": type(trainer.model_wrapped).__name__, "wrapped_classes": wrapped,
                        "weights_read_by": "rank 0" if rank0_reads else "every rank"},
        "memory": _memory(probe, predicted, args.world_size),
    }
    if trainer.is_world_process_zero():
        summary["final_model"] = str(final)
        (output_dir / "train_summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    return summary


def shut_down_process_group() -> None:
    """After a successful distributed run: free the model (FSDP modules hold process groups), wait for
    every rank and destroy the process group before the interpreter exits. Left to interpreter
    teardown, torch 2.13 with gloo aborts at exit ("terminate called without an active exception")
    in about half of the runs of a bare all_reduce script, and in some FSDP2 runs after they finished."""
    if not (torch.distributed.is_available() and torch.distributed.is_initialized()):
        return
    gc.collect()
    torch.distributed.barrier()
    torch.distributed.destroy_process_group()

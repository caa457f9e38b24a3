"""The HF ``Trainer`` with what SFT of SpaceDG VLMs needs and the stock one lacks.

* **Resume that restores the weights, under every launch.** transformers 5.23 reloads a VLM
  checkpoint's hub-format keys with ``strict=False`` and silently trains on from the *initial*
  weights (measured: loss back from 5.64 to 5.98). :meth:`SFTTrainer._load_from_checkpoint` loads
  full checkpoints of one process / DDP through ``from_pretrained`` (which maps the keys) and
  copies the weights in strictly, and LoRA checkpoints through peft. Under FSDP (1 and 2) the
  model is sharded: the checkpoint's FSDP state (``pytorch_model_fsdp*``, written by accelerate
  in the model's own names) is loaded into the shards, strictly. DeepSpeed loads its own
  ``global_step*`` state. Optimizer, scheduler and RNG state come from the Trainer's own resume.
* **Complete checkpoints.** Every rank has written its files before ``trainer_state.json``, the
  Trainer's last file, appears; :func:`latest_checkpoint` (``resume=auto``) skips folders without it
  (a save that was interrupted).
* **The loss of the whole run.** The checkpoint records the sum of the per-step losses so far, so
  after a resume ``train_loss`` is the mean over every step, not only the resumed ones.
* **A loss normalised over the optimizer step** (:mod:`spacedg.sft.loss`): the items of the step
  are counted over its micro-batches and ranks (:meth:`SFTTrainer._get_num_items_in_batch`).
* **FSDP on CPU** (:func:`spacedg.sft.distributed.enable_cpu_fsdp`), so the sharded path is tested
  with torchrun + gloo; under mixed precision FSDP reduces gradients in float32
  (:func:`spacedg.sft.distributed.reduce_in_fp32`).
* **``final/`` under every launch** (:meth:`SFTTrainer.export_final`, collective): sharded weights
  are gathered to rank 0, which rebuilds the model on the CPU and writes it (LoRA merged).
* **Evaluation by generation.** :meth:`SFTTrainer.evaluate` answers ``val`` items with greedy
  generation and scores them with :func:`spacedg.eval.scoring.score`, returning
  ``eval_score`` and ``eval_score_<degradation>`` (accuracy / MRA per condition). On several
  processes each rank answers its share and the scores are gathered. Not under FSDP or ZeRO-3 (the
  sharded model cannot generate rank by rank): there, evaluate checkpoints with ``spacedg predict``.
* **Checkpoints ``spacedg predict`` loads.** :class:`SaveProcessorCallback` writes the
  processor (with its image pixel budget and chat template) into every checkpoint.
* **What a rank holds.** :class:`MemoryProbe` measures the local bytes of parameters, gradients
  and optimizer states at the second optimizer step (:mod:`spacedg.sft.memory` predicts them).
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import torch
from peft import PeftModel, set_peft_model_state_dict
from safetensors.torch import load_file
from transformers import Trainer, TrainerCallback
from transformers.trainer import TRAINER_STATE_NAME
from transformers.trainer_utils import TrainOutput

from spacedg.eval.scoring import score
from spacedg.sft.distributed import enable_cpu_fsdp, full_state_dict, local_bytes, reduce_in_fp32, without_zero3
from spacedg.sft.loss import count_items, loss_function
from spacedg.sft.model import ModelOptions, rebuild_with_state, save_for_inference
from spacedg.vlm import generate

__all__ = ["EpochCallback", "MemoryProbe", "SFTTrainer", "SaveProcessorCallback", "ValItem", "ValShare", "is_complete",
           "latest_checkpoint"]

ValItem = dict  # {"conversation" (without the assistant turn), "images", "degradation_type", "truth": {...}}


class ValShare:
    """One process's share of the evaluation items, rendered on its first evaluation.

    ``render()`` returns the items this process answers (e.g. :meth:`DataOptions.val_items
    <spacedg.sft.sources.DataOptions.val_items>` with its rank and world): a launch that never
    evaluates (FSDP, ZeRO-3: :meth:`SFTTrainer.evaluate`) renders none, and on ``world`` processes
    each renders ``1/world`` of them, not all. Every process holds one (possibly empty) share, so
    all ranks reach the evaluation's gather together."""

    def __init__(self, render: Callable[[], list[ValItem]]) -> None:
        self._render = render
        self._items: list[ValItem] | None = None

    def __bool__(self) -> bool:
        """Always true, even for an empty share: an empty share is still this rank's part of the evaluation (its
        rank joins the gather; one that skipped it would leave the others waiting)."""
        return True

    def rendered(self) -> list[ValItem]:
        """This process's items (rendered on the first call, then kept)."""
        if self._items is None:
            self._items = list(self._render())
        return self._items

#: Key of spacedg's record in ``trainer_state.json``'s ``stateful_callbacks``.
STATE_KEY = "SpaceDGRun"


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


class MemoryProbe(TrainerCallback):
    """Local bytes of parameters, gradients and optimizer states, measured just before the
    optimizer step of global step ``at`` (1-based; the optimizer state exists from the second step),
    plus the CUDA peak at the end of training where there is one. Result: :attr:`measured`."""

    def __init__(self, at: int = 2) -> None:
        self.at = at
        self.measured: dict[str, Any] = {}

    def on_pre_optimizer_step(self, args: Any, state: Any, control: Any, model: Any = None, optimizer: Any = None,
                              **kwargs: Any) -> None:
        if state.global_step + 1 == self.at and model is not None:
            inner = getattr(optimizer, "optimizer", optimizer)
            self.measured.update(local_bytes(model.parameters(), inner), step=self.at)

    def on_train_end(self, args: Any, state: Any, control: Any, **kwargs: Any) -> None:
        if torch.cuda.is_available():
            self.measured["cuda_max_allocated"] = int(torch.cuda.max_memory_allocated())


class SFTTrainer(Trainer):
    """``Trainer`` with strict resume, a step-normalised loss, sharded export and generation-based
    evaluation (see the module docstring).

    Args:
        val_items: the evaluation items, all of them (each rank answers every ``world``-th from its rank;
            empty or ``None``: no evaluation), or a :class:`ValShare`: this rank's share alone, rendered when
            first evaluated.
        processor: the model's processor (for generation and ``final/``).
        val_max_new_tokens / val_batch_size: generation settings of the evaluation (``data.val``).
        loss: ``"tokens"`` or ``"samples"`` (:mod:`spacedg.sft.loss`); ``None`` keeps the model's own loss.
        model_options: how the model was built (to rebuild it for ``final/`` of a sharded launch).
        Other arguments go to :class:`transformers.Trainer`.
    """

    def __init__(self, *args: Any, val_items: Sequence[ValItem] | ValShare | None, processor: Any, val_max_new_tokens: int,
                 val_batch_size: int, loss: str | None, model_options: ModelOptions | None = None,
                 **kwargs: Any) -> None:
        if loss is not None:
            kwargs.setdefault("compute_loss_func", loss_function(loss))
        super().__init__(*args, **kwargs)
        self.loss_mode = loss
        self.model_options = model_options
        self.val_items: ValShare | None = val_items if isinstance(val_items, ValShare) else self._share_of(val_items)
        self.val_processor = processor
        self.val_max_new_tokens = int(val_max_new_tokens)
        self.val_batch_size = max(1, int(val_batch_size))
        self._loss_before = 0.0  # sum of the per-step losses before this train() call (a resumed run)
        self._step_before = 0

    # -------------------------------------------------------------- launch
    def create_accelerator_and_postprocess(self) -> None:
        super().create_accelerator_and_postprocess()
        if enable_cpu_fsdp(self.accelerator, self.args.fsdp_plugin_args):
            self.is_fsdp_enabled = True
        if self.is_fsdp_enabled:
            reduce_in_fp32(self.accelerator.state.fsdp_plugin)

    @property
    def shards_parameters(self) -> bool:
        """Whether each rank holds only a shard of the weights (FSDP, ZeRO-3)."""
        if self.is_fsdp_enabled:
            return True
        return bool(self.is_deepspeed_enabled and self.accelerator.state.deepspeed_plugin.zero_stage == 3)

    # -------------------------------------------------------------- loss
    def _get_num_items_in_batch(self, batch_samples: list, device: torch.device) -> Any:
        """The step's supervised tokens (or samples), summed over its micro-batches and all ranks."""
        if self.loss_mode is None:
            return super()._get_num_items_in_batch(batch_samples, device)
        if not batch_samples:
            return None
        count = sum(count_items(batch["labels"], self.loss_mode) for batch in batch_samples).to(device)
        if self.args.world_size > 1:
            count = self.accelerator.gather(count.reshape(1)).sum()
        return count

    # -------------------------------------------------------------- resume
    def _load_from_checkpoint(self, resume_from_checkpoint: str, model: Any = None) -> None:
        model = self.model if model is None else model
        folder = Path(resume_from_checkpoint)
        if self.is_fsdp_enabled:
            return self._load_fsdp_checkpoint(folder, model)
        if isinstance(model, PeftModel):
            weights = folder / "adapter_model.safetensors"
            if not weights.is_file():
                raise FileNotFoundError(f"{folder}: no adapter_model.safetensors to resume the LoRA adapters from")
            result = set_peft_model_state_dict(model, load_file(str(weights)))
            missing = [k for k in getattr(result, "unexpected_keys", []) if "lora_" in k]
            if missing:
                raise RuntimeError(f"{folder}: adapter weights {missing[:3]} did not match the model")
            return None
        if not (folder / "config.json").is_file():
            return super()._load_from_checkpoint(resume_from_checkpoint, model)
        # float32 holds every stored dtype exactly (trained weights in fp32, frozen ones maybe in bf16)
        loaded = type(model).from_pretrained(folder, dtype=torch.float32)
        state = loaded.state_dict()
        model.load_state_dict(state, strict=True)
        del loaded, state
        return None

    def _load_fsdp_checkpoint(self, folder: Path, model: Any) -> None:
        """accelerate's FSDP checkpoint (``pytorch_model_fsdp*``, the model's own names) into the shards.

        Full models load strictly (``set_model_state_dict``). Adapters load with ``strict=False``
        (the base weights are not in the checkpoint), so every trained parameter is checked to be in it.
        """
        from accelerate.utils import load_fsdp_model

        written = sorted(p.name for p in folder.iterdir() if p.name.startswith("pytorch_model_fsdp"))
        if not written:
            raise RuntimeError(f"{folder} was not written under FSDP (no pytorch_model_fsdp* in it); resume it "
                               f"with the launch that wrote it")
        plugin = self.accelerator.state.fsdp_plugin
        unwrapped = self.accelerator.unwrap_model(model)
        adapter_only = isinstance(unwrapped, PeftModel)
        if adapter_only:
            saved = _fsdp_checkpoint_keys(folder / written[0])
            trained = sum(1 for p in unwrapped.parameters() if p.requires_grad)
            if len(saved) != trained:
                raise RuntimeError(f"{folder}: the FSDP checkpoint holds {len(saved)} adapter weights, the model trains "
                                   f"{trained}; it does not belong to this model")
        result = load_fsdp_model(plugin, self.accelerator, model, str(folder), adapter_only=adapter_only)
        if not adapter_only and (getattr(result, "missing_keys", None) or getattr(result, "unexpected_keys", None)):
            raise RuntimeError(f"{folder}: the FSDP checkpoint does not match the model (missing "
                               f"{list(result.missing_keys)[:3]}, unexpected {list(result.unexpected_keys)[:3]})")

    def _save_rng_state(self, output_dir: str) -> None:
        super()._save_rng_state(output_dir)
        # trainer_state.json, written next by rank 0, marks the checkpoint complete: every rank is done here
        self.accelerator.wait_for_everyone()

    # -------------------------------------------------------------- the run's loss
    def _save_checkpoint(self, model: Any, trial: Any) -> None:
        pending = self._tr_loss.detach().reshape(1)
        if self.args.world_size > 1:
            pending = self.accelerator.gather(pending)
        total = self._loss_before + self._total_loss_scalar + float(pending.mean())
        self.state.stateful_callbacks[STATE_KEY] = {"loss_sum": total, "global_step": self.state.global_step}
        super()._save_checkpoint(model, trial)

    def train(self, resume_from_checkpoint: Any = None, **kwargs: Any) -> TrainOutput:
        self._loss_before, self._step_before = 0.0, 0
        if isinstance(resume_from_checkpoint, (str, os.PathLike)):
            self._loss_before, self._step_before = _loss_so_far(Path(resume_from_checkpoint))
        result = super().train(resume_from_checkpoint=resume_from_checkpoint, **kwargs)
        steps = self.state.global_step
        if not self._step_before or not steps:
            return result
        session = result.training_loss * (steps - self._step_before)
        loss = (self._loss_before + session) / steps
        metrics = dict(result.metrics, train_loss=loss)
        return TrainOutput(result.global_step, loss, metrics)

    # -------------------------------------------------------------- final/
    def export_final(self, out: str | os.PathLike[str], save_dtype: torch.dtype | None = None) -> Path | None:
        """Write the trained model (LoRA merged) and the processor to ``out`` for ``spacedg predict``.

        Collective: every rank must call it; rank 0 writes and returns the folder, the others
        return ``None`` once it is written. Sharded weights (FSDP, ZeRO-3) are gathered to rank 0,
        which rebuilds the model on the CPU from ``model_options`` and loads them strictly.
        ``save_dtype`` casts the saved weights (bf16 after mixed precision training).
        """
        state = full_state_dict(self)
        written: Path | None = None
        if self.is_world_process_zero():
            if state is None:
                written = save_for_inference(self.accelerator.unwrap_model(self.model), self.val_processor, out, save_dtype=save_dtype)
            else:
                if self.model_options is None:
                    raise RuntimeError("export_final of a sharded model needs the model_options it was built from")
                with without_zero3():
                    model = rebuild_with_state(self.model_options, state)
                del state
                written = save_for_inference(model, self.val_processor, out, save_dtype=save_dtype, in_place=True)
                del model
        self.accelerator.wait_for_everyone()
        return written

    # -------------------------------------------------------------- evaluation
    def _share_of(self, items: Sequence[ValItem] | None) -> ValShare | None:
        """This rank's share of all the evaluation ``items`` (every ``world``-th from its rank); ``None`` for none."""
        every = list(items or [])
        rank, world = self.args.process_index, self.args.world_size
        return ValShare(lambda: every[rank::world]) if every else None

    def evaluate(self, eval_dataset: Any = None, ignore_keys: Any = None, metric_key_prefix: str = "eval") -> dict[str, float]:
        if self.val_items is None or self.shards_parameters:  # an empty share still gathers the others' scores
            return {}
        world = self.args.world_size
        mine = self.val_items.rendered()
        model = self.accelerator.unwrap_model(self.model)
        was_training = model.training
        model.eval()
        results: list[tuple[str, float]] = []
        try:
            for start in range(0, len(mine), self.val_batch_size):
                batch = mine[start:start + self.val_batch_size]
                with self.accelerator.autocast():  # frozen bf16 and trained fp32 weights meet under autocast
                    answers = generate(model, self.val_processor, [b["conversation"] for b in batch],
                                       [b["images"] for b in batch], max_new_tokens=self.val_max_new_tokens)
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


def _fsdp_checkpoint_keys(path: Path) -> set[str]:
    """The weight names in accelerate's FSDP checkpoint: a DCP folder (sharded) or a ``.bin`` (full)."""
    if path.is_dir():
        import torch.distributed.checkpoint as dcp

        names = dcp.FileSystemReader(str(path)).read_metadata().state_dict_metadata
        return {name.split(".", 1)[1] for name in names if name.startswith("model.")}
    return set(torch.load(path, map_location="cpu", weights_only=True))


def _loss_so_far(folder: Path) -> tuple[float, int]:
    """``(sum of the per-step losses, global step)`` recorded in a checkpoint; from its logged
    losses when it predates the record (exact when checkpoints fall on logging steps)."""
    file = folder / TRAINER_STATE_NAME
    if not file.is_file():
        return 0.0, 0
    state = json.loads(file.read_text())
    step = int(state.get("global_step") or 0)
    record = (state.get("stateful_callbacks") or {}).get(STATE_KEY)
    if isinstance(record, dict) and int(record.get("global_step", -1)) == step:
        return float(record["loss_sum"]), step
    total, last = 0.0, 0
    for entry in state.get("log_history", []):
        if "loss" in entry and "step" in entry:
            total += float(entry["loss"]) * (int(entry["step"]) - last)
            last = int(entry["step"])
    return total, last


def is_complete(folder: str | os.PathLike[str]) -> bool:
    """Whether a ``checkpoint-N`` folder was completely written (the Trainer writes
    ``trainer_state.json`` last, after every rank's weights, optimizer and RNG files)."""
    return (Path(folder) / TRAINER_STATE_NAME).is_file()


def latest_checkpoint(output_dir: str | os.PathLike[str]) -> Path | None:
    """The complete ``checkpoint-N`` folder with the largest ``N`` in ``output_dir``, or ``None``
    (folders whose save was interrupted are skipped, see :func:`is_complete`)."""
    folder = Path(output_dir)
    steps = [(int(p.name.split("-")[1]), p) for p in folder.glob("checkpoint-*")
             if p.name.split("-")[1].isdigit() and is_complete(p)]
    return max(steps)[1] if steps else None

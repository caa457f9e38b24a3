"""What differs between launches (one process, DDP, FSDP 1 / 2, DeepSpeed ZeRO) for SFT, in one place.

* :func:`launch_of` reads the launch from the ``TrainingArguments`` (and the environment that
  ``accelerate launch`` sets): which wrapper shards what, and whether bf16 / fp16 mixed precision
  is on. The model's storage dtypes follow from it (:func:`spacedg.sft.model.storage_dtypes`).
* :func:`wrap_classes` names the decoder layer and vision block classes of a VLM: the units FSDP
  shards and all-gathers one at a time (``fsdp_config.transformer_layer_cls_to_wrap: auto``).
* :func:`enable_cpu_fsdp`: accelerate (1.15) turns FSDP on only for accelerator devices; on a
  multi-process CPU launch (torchrun + gloo) it would silently train DDP. This switches its state to
  FSDP, so the sharded path (sharding, checkpoints, resume, export) runs, and is tested, on CPU
  exactly as accelerate runs it on GPUs.
* :func:`reduce_in_fp32`: under FSDP mixed precision the gradients are averaged over the GPUs in
  float32 (accelerate's bf16 policy reduces in bf16); weights are still all-gathered in bf16.
* :func:`full_state_dict` is collective: every rank calls it and rank 0 receives the full,
  unsharded weights on the CPU (FSDP 1/2: ``torch.distributed.checkpoint.state_dict``;
  ZeRO-3: ``deepspeed.zero.GatheredParameters`` parameter by parameter, with the fp32 master
  weights where DeepSpeed keeps them); other ranks get ``{}``.
* :func:`local_bytes` measures what a rank holds: parameters, gradients and optimizer states
  (the local shards of DTensors), for the memory formulas of :mod:`spacedg.sft.memory`.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from typing import Any

import torch

__all__ = ["Launch", "enable_cpu_fsdp", "full_state_dict", "launch_of", "local_bytes", "reduce_in_fp32", "without_zero3",
           "wrap_classes"]

_KINDS = ("single", "ddp", "fsdp", "deepspeed")


@dataclass(frozen=True)
class Launch:
    """How a run is launched.

    ``kind``: ``"single"`` (one process), ``"ddp"``, ``"fsdp"`` or ``"deepspeed"``;
    ``world_size``: processes; ``mixed_precision``: ``"bf16"``, ``"fp16"`` or ``"no"``;
    ``fsdp_version``: 1 or 2 under FSDP; ``zero_stage``: 0–3 under DeepSpeed.
    """

    kind: str
    world_size: int = 1
    mixed_precision: str = "no"
    fsdp_version: int | None = None
    zero_stage: int | None = None

    def __post_init__(self) -> None:
        if self.kind not in _KINDS:
            raise ValueError(f"launch kind must be one of {_KINDS}, got {self.kind!r}")

    @property
    def shards_parameters(self) -> bool:
        """Whether each rank holds only a shard of the weights (FSDP, ZeRO-3)."""
        return self.kind == "fsdp" or (self.kind == "deepspeed" and (self.zero_stage or 0) >= 3)

    @property
    def name(self) -> str:
        """``"single"``, ``"ddp"``, ``"fsdp1"``, ``"fsdp2"`` or ``"zero<stage>"``."""
        if self.kind == "fsdp":
            return f"fsdp{self.fsdp_version}"
        if self.kind == "deepspeed":
            return f"zero{self.zero_stage}"
        return self.kind


def _env_flag(name: str) -> bool:
    return os.environ.get(name, "false").lower() in ("1", "true", "yes")


def launch_of(args: Any) -> Launch:
    """The :class:`Launch` that ``args`` (``transformers.TrainingArguments``) will train under.

    FSDP comes from ``args.fsdp`` or ``accelerate launch``'s ``ACCELERATE_USE_FSDP``; DeepSpeed
    from ``args.deepspeed`` (a JSON path or dict) or ``ACCELERATE_USE_DEEPSPEED``.
    """
    world = int(args.world_size)
    # transformers' resolution: train.bf16 / fp16, else accelerate launch's ACCELERATE_MIXED_PRECISION
    precision = str(getattr(args, "mixed_precision", None) or ("bf16" if args.bf16 else "fp16" if args.fp16 else "no"))
    if precision not in ("bf16", "fp16"):
        precision = "no"
    if args.deepspeed or _env_flag("ACCELERATE_USE_DEEPSPEED"):
        stage = None
        config = getattr(args, "hf_deepspeed_config", None)
        if config is not None:
            stage = config.get_value("zero_optimization.stage")
        if stage is None:
            stage = os.environ.get("ACCELERATE_DEEPSPEED_ZERO_STAGE")
        return Launch("deepspeed", world, precision, zero_stage=int(stage) if stage is not None else 0)
    plugin = getattr(args, "fsdp_plugin_args", None)
    if plugin is not None:
        return Launch("fsdp", world, precision, fsdp_version=int(plugin.get("fsdp_version", 2)))
    if _env_flag("ACCELERATE_USE_FSDP"):
        return Launch("fsdp", world, precision, fsdp_version=int(os.environ.get("FSDP_VERSION", "1")))
    return Launch("ddp" if world > 1 else "single", world, precision)


# ----------------------------------------------------------------------------------------------
# wrap policy


def _repeated_blocks(module: torch.nn.Module) -> list[torch.nn.ModuleList]:
    return [m for m in module.modules() if isinstance(m, torch.nn.ModuleList) and len(m) > 1
            and len({type(child) for child in m}) == 1]


def wrap_classes(model: torch.nn.Module) -> list[str]:
    """Class names of the decoder layers of the language model and of the blocks of the vision tower.

    Each is the class of the longest list of identical blocks in that part of the model
    (``model.language_model.layers``: ``Qwen2_5_VLDecoderLayer``; ``model.visual.blocks``:
    ``Qwen2_5_VLVisionBlock``; InternVL's ``model.vision_tower.encoder.layer``:
    ``InternVLVisionLayer``). A peft-wrapped model works too.
    """
    from spacedg.sft.model import module_groups

    groups = module_groups(model)
    modules = dict(model.named_modules())
    names: list[str] = []
    for group in ("language", "vision"):
        lists = [block for prefix in groups[group] if prefix in modules for block in _repeated_blocks(modules[prefix])]
        if lists:
            name = type(max(lists, key=len)[0]).__name__
            if name not in names:
                names.append(name)
    return names


# ----------------------------------------------------------------------------------------------
# FSDP on CPU


def enable_cpu_fsdp(accelerator: Any, plugin_args: dict[str, Any] | None) -> bool:
    """Turn accelerate's FSDP path on for a multi-process CPU run; returns whether it did.

    Does nothing unless FSDP was asked for (``plugin_args``, the ``TrainingArguments``'
    ``fsdp_plugin_args``) and accelerate chose plain multi-CPU data parallelism instead.
    The state is set on both accelerate state singletons, so later ``AcceleratorState()``
    constructions (which copy the partial state) keep it.
    """
    from accelerate.state import PartialState
    from accelerate.utils import DistributedType, FullyShardedDataParallelPlugin

    state = accelerator.state
    if plugin_args is None or state.distributed_type != DistributedType.MULTI_CPU:
        return False
    plugin = FullyShardedDataParallelPlugin(**plugin_args)
    if accelerator.mixed_precision != "no":
        plugin.set_mixed_precision(accelerator.mixed_precision)
    PartialState._shared_state["distributed_type"] = DistributedType.FSDP
    state.distributed_type = DistributedType.FSDP
    state.fsdp_plugin = plugin
    if plugin.fsdp_version == 1:  # FSDP1 compares its device_id with the parameters' device: "cpu", not "cpu:0"
        PartialState._shared_state["device"] = torch.device("cpu")
        state.device = torch.device("cpu")
    return True


def reduce_in_fp32(plugin: Any) -> bool:
    """Under FSDP mixed precision, reduce gradients in float32; returns whether the policy changed.

    accelerate's bf16 policy also reduces (averages over the GPUs) in bf16; the parameters
    (float32 shards: the master weights) are still all-gathered and computed in bf16.
    """
    policy = getattr(plugin, "mixed_precision_policy", None)
    half = getattr(policy, "param_dtype", None)
    if policy is None or half in (None, torch.float32) or getattr(policy, "reduce_dtype", None) == torch.float32:
        return False
    if plugin.fsdp_version == 2:
        from torch.distributed.fsdp import MixedPrecisionPolicy

        plugin.mixed_precision_policy = MixedPrecisionPolicy(param_dtype=half, reduce_dtype=torch.float32,
                                                             output_dtype=policy.output_dtype,
                                                             cast_forward_inputs=policy.cast_forward_inputs)
    else:
        from torch.distributed.fsdp import MixedPrecision

        plugin.mixed_precision_policy = MixedPrecision(param_dtype=half, reduce_dtype=torch.float32,
                                                       buffer_dtype=policy.buffer_dtype)
    return True


# ----------------------------------------------------------------------------------------------
# gathering


def _rank() -> int:
    return torch.distributed.get_rank() if torch.distributed.is_initialized() else 0


def _fsdp_full_state(model: torch.nn.Module, version: int) -> dict[str, torch.Tensor]:
    on_cpu = next(model.parameters()).device.type == "cpu"
    if version == 1:
        from torch.distributed.fsdp import FullStateDictConfig, StateDictType
        from torch.distributed.fsdp import FullyShardedDataParallel as FSDP

        # (offloading a CPU model "to the CPU" crashes FSDP1)
        config = FullStateDictConfig(offload_to_cpu=not on_cpu, rank0_only=True)
        with FSDP.state_dict_type(model, StateDictType.FULL_STATE_DICT, config):
            state = model.state_dict()
        prefix = "_fsdp_wrapped_module."
        state = {k.replace(prefix, ""): v for k, v in state.items()}
    else:
        from torch.distributed.checkpoint.state_dict import StateDictOptions, get_model_state_dict

        state = get_model_state_dict(model, options=StateDictOptions(full_state_dict=True, cpu_offload=True))
    # On a CPU device the "offloaded" tensors can share storage with FSDP's all-gather buffers: own them.
    return {k: v.detach().clone() for k, v in state.items()} if _rank() == 0 else {}


def _zero3_full_state(engine: Any) -> dict[str, torch.Tensor]:
    import deepspeed
    from deepspeed.utils import safe_get_full_fp32_param

    module = engine.module
    rank0 = _rank() == 0
    state: dict[str, torch.Tensor] = {}
    for name, param in module.named_parameters():
        # the fp32 master weights of a trained parameter (collective; None where DeepSpeed keeps none)
        full = safe_get_full_fp32_param(param) if param.requires_grad else None
        if full is None:  # the same on every rank, so every rank takes the same collective
            with deepspeed.zero.GatheredParameters([param], modifier_rank=None):
                if rank0:
                    state[name] = param.detach().cpu().clone()
        elif rank0:
            state[name] = full.detach().cpu().clone()
    if rank0:  # buffers are not partitioned; the persistent ones belong in the state dict
        for prefix, sub in module.named_modules():
            for name, buffer in sub.named_buffers(recurse=False):
                if buffer is not None and name not in sub._non_persistent_buffers_set:
                    state[f"{prefix}.{name}" if prefix else name] = buffer.detach().cpu().clone()
    return state


@contextlib.contextmanager
def without_zero3() -> Iterator[None]:
    """Models built inside are plain (not ZeRO-3 partitioned), e.g. rank 0's rebuild for ``final/``:
    transformers otherwise builds every model under ``deepspeed.zero.Init`` once a ZeRO-3 config
    exists, which waits on the other ranks."""
    from transformers.integrations import deepspeed as hf_deepspeed

    ref = hf_deepspeed._hf_deepspeed_config_weak_ref
    config = ref() if ref is not None else None
    if config is None:
        yield
        return
    hf_deepspeed.unset_hf_deepspeed_config()
    try:
        yield
    finally:
        hf_deepspeed.set_hf_deepspeed_config(config)


def full_state_dict(trainer: Any) -> dict[str, torch.Tensor] | None:
    """The full weights of ``trainer``'s model (an :class:`~spacedg.sft.trainer.SFTTrainer`), gathered
    to rank 0 (collective: call on every rank).

    ``None`` when the launch does not shard parameters (every rank holds the whole model: use it
    directly); else rank 0 gets ``{name: cpu tensor}`` in the unwrapped model's own names (a peft
    model's ``base_model.model.…`` names included) and the other ranks ``{}``.
    """
    if not trainer.shards_parameters:
        return None
    if trainer.is_fsdp_enabled:
        return _fsdp_full_state(trainer.model_wrapped, trainer.accelerator.state.fsdp_plugin.fsdp_version)
    return _zero3_full_state(trainer.model_wrapped)


# ----------------------------------------------------------------------------------------------
# measuring


def _local_numel(tensor: torch.Tensor) -> int:
    """Bytes of this rank's part: a DTensor's local shard, a ZeRO-3 parameter's partition."""
    local = tensor.to_local() if hasattr(tensor, "to_local") else getattr(tensor, "ds_tensor", tensor)
    return local.numel() * local.element_size()


def local_bytes(parameters: Iterable[torch.nn.Parameter], optimizer: Any = None) -> dict[str, int]:
    """Bytes this rank holds in ``parameters`` (their local shards), their gradients and the
    optimizer's per-parameter state tensors (AdamW: ``exp_avg``, ``exp_avg_sq``; scalar ``step``
    counters are left out). Under DeepSpeed the gradients live in its own buffers (not counted
    here) and the optimizer is its inner one (fp32 partitions)."""
    params = list(parameters)
    out = {"params": sum(_local_numel(p) for p in params),
           "trainable_params": sum(_local_numel(p) for p in params if p.requires_grad),
           "grads": sum(_local_numel(p.grad) for p in params if p.grad is not None),
           "optimizer": 0}
    if optimizer is not None:
        for state in getattr(optimizer, "state", {}).values():
            out["optimizer"] += sum(_local_numel(v) for v in state.values()
                                    if isinstance(v, torch.Tensor) and v.dim() > 0)
    return out

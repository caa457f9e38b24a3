"""Memory per GPU of the SFT launches, from parameter counts: weights, gradients, optimizer states.

Notation: ``P`` parameters, ``T`` trained ones, ``F = P - T`` frozen ones, ``N`` GPUs; AdamW keeps
two fp32 moments per trained parameter. With ``dtype: auto`` and bf16 mixed precision
(:func:`spacedg.sft.model.storage_dtypes`) the launches hold, per GPU:

=============  =====================  ===============  ==================
launch         weights                gradients        AdamW states
=============  =====================  ===============  ==================
single / DDP   ``4T + 2F``            ``4T``           ``8T``
FSDP (1, 2)    ``4P / N``             ``4T / N``       ``8T / N``
ZeRO-2         ``2P + 4T / N``        ``2T / N``       ``8T / N``
ZeRO-3         ``2P / N + 4T / N``    ``2T / N``       ``8T / N``
=============  =====================  ===============  ==================

(ZeRO keeps bf16 weights for compute and fp32 master weights beside the moments: the ZeRO paper's
``2 + 2 + 12`` bytes per parameter.) On top come the activations (with activation checkpointing,
the hidden state at each decoder layer boundary plus one layer being recomputed), FSDP's
all-gathered bf16 copy of the unit(s) in flight (``2 U`` bytes for a unit of ``U`` parameters,
about two at a time with prefetching), the logits of the supervised positions and the CUDA
context; :func:`table` lists the decoder-layer size ``U`` so these can be added.

:func:`predict` gives the exact bytes a rank holds for a launch from a model's real parameter
shapes (FSDP2 shards each parameter along dim 0 in ``ceil(d0 / N)`` rows), so the formulas are
checked against :func:`spacedg.sft.distributed.local_bytes` measured on the tiny models.
:func:`qwen2_5_vl_7b` builds Qwen2.5-VL-7B-Instruct from its published configuration on the
``meta`` device (no memory) and :func:`table` computes the documented table
(``python -m spacedg.sft.memory`` prints it).
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable
from typing import Any

import torch

from spacedg.sft.distributed import Launch

__all__ = ["QWEN2_5_VL_7B", "counts", "main", "markdown", "memory_for", "predict", "qwen2_5_vl_7b", "table"]

_GB = 1e9

#: Qwen/Qwen2.5-VL-7B-Instruct's config.json (the values that set parameter shapes).
QWEN2_5_VL_7B = {
    "text_config": {"hidden_size": 3584, "intermediate_size": 18944, "num_hidden_layers": 28, "num_attention_heads": 28,
                    "num_key_value_heads": 4, "vocab_size": 152064, "rms_norm_eps": 1e-6, "max_position_embeddings": 128000,
                    "rope_parameters": {"rope_type": "default", "rope_theta": 1000000.0, "mrope_section": [16, 24, 24]}},
    "vision_config": {"depth": 32, "hidden_size": 1280, "intermediate_size": 3420, "num_heads": 16, "out_hidden_size": 3584,
                      "patch_size": 14, "spatial_merge_size": 2, "temporal_patch_size": 2, "window_size": 112,
                      "fullatt_block_indexes": [7, 15, 23, 31], "in_channels": 3},
    "tie_word_embeddings": False, "image_token_id": 151655, "video_token_id": 151656,
    "vision_start_token_id": 151652, "vision_end_token_id": 151653,
}


def qwen2_5_vl_7b() -> torch.nn.Module:
    """Qwen2.5-VL-7B-Instruct's architecture with its published sizes, on the ``meta`` device."""
    from transformers import Qwen2_5_VLConfig, Qwen2_5_VLForConditionalGeneration

    config = Qwen2_5_VLConfig(**QWEN2_5_VL_7B)
    with torch.device("meta"):
        return Qwen2_5_VLForConditionalGeneration(config)


def counts(model: torch.nn.Module, *, lora_rank: int | None) -> dict[str, int]:
    """Parameter counts: ``vision``, ``merger``, ``language`` (:func:`spacedg.sft.model.module_groups`),
    ``unit`` (the largest decoder layer, FSDP's all-gather unit) and, with ``lora_rank``, ``lora``: the
    adapters of that rank on the default targets (the language model's attention and MLP
    projections: ``r × (in + out)`` each)."""
    from spacedg.sft.model import _group_of, default_lora_target, module_groups

    groups = module_groups(model)
    out = {g: 0 for g in groups}
    for name, param in model.named_parameters():
        out[_group_of(name, groups)] += param.numel()
    language = dict(model.named_modules())[groups["language"][0]]
    layers = [m for m in language.modules() if isinstance(m, torch.nn.ModuleList) and len(m) > 1]
    out["unit"] = max((sum(p.numel() for p in layer.parameters()) for block in layers for layer in block), default=0)
    if lora_rank is not None:
        regex = default_lora_target(model)
        out["lora"] = sum(lora_rank * (m.in_features + m.out_features) for n, m in model.named_modules()
                          if isinstance(m, torch.nn.Linear) and re.fullmatch(regex, n))
    return out


def _shard(numel: int, rows: int, world: int, rank: int) -> int:
    """Elements of an FSDP2 shard: dim 0 split in chunks of ``ceil(rows / world)``."""
    if world <= 1 or rows == 0:
        return numel
    chunk = math.ceil(rows / world)
    mine = max(0, min(chunk, rows - rank * chunk))
    return numel // rows * mine


def predict(parameters: Iterable[tuple[torch.Size, torch.dtype, bool]], launch: Launch, *, rank: int = 0,
            optimizer_state_size: int = 4) -> dict[str, int]:
    """Bytes rank ``rank`` holds under ``launch`` for parameters given as ``(shape, stored dtype,
    trained)``: ``params``, ``grads`` and ``optimizer`` (AdamW: two moments of
    ``optimizer_state_size`` bytes per trained parameter, the dtype of the master weights).

    One process / DDP: everything whole. FSDP2: every parameter sharded along dim 0 (exact shard
    sizes); FSDP1: ``numel / N``. DeepSpeed: the ZeRO paper's accounting (see the module doc).
    """
    world = launch.world_size
    out = {"params": 0, "grads": 0, "optimizer": 0}
    for shape, dtype, trained in parameters:
        numel = int(math.prod(shape)) if len(shape) else 1
        size = torch.empty((), dtype=dtype).element_size()
        if launch.kind == "deepspeed":
            stage = launch.zero_stage or 0
            half = 2 if launch.mixed_precision != "no" else size
            whole = numel if stage < 3 else numel / world
            out["params"] += half * whole + (4 * numel / world if trained and launch.mixed_precision != "no" else 0)
            if trained:
                out["grads"] += half * (numel / world if stage >= 2 else numel)
                out["optimizer"] += 2 * optimizer_state_size * numel / world
            continue
        if launch.kind == "fsdp":
            local = _shard(numel, shape[0] if len(shape) else 1, world, rank) if launch.fsdp_version == 2 else numel / world
        else:
            local = numel
        out["params"] += size * local
        if trained:
            out["grads"] += size * local
            out["optimizer"] += 2 * optimizer_state_size * local
    return {k: int(round(v)) for k, v in out.items()}


def memory_for(model: torch.nn.Module, launch: Launch, *, rank: int = 0) -> dict[str, int]:
    """:func:`predict` for ``model``'s own parameters as stored; call it before the launch wraps the model
    (FSDP1 flattens, ZeRO-3 partitions; FSDP2's DTensors and ZeRO-3's ``ds_shape`` keep full shapes)."""
    return predict(((getattr(p, "ds_shape", p.shape), p.dtype, p.requires_grad) for p in model.parameters()), launch,
                   rank=rank)


def _bytes(trained: int, frozen: int, launch: Launch) -> dict[str, float]:
    """The module doc's formulas (``dtype: auto``, bf16 mixed precision) for parameter counts."""
    n = launch.world_size
    total = trained + frozen
    if launch.kind == "fsdp":
        return {"weights": 4 * total / n, "grads": 4 * trained / n, "optimizer": 8 * trained / n}
    if launch.kind == "deepspeed":
        weights = (2 * total if (launch.zero_stage or 0) < 3 else 2 * total / n) + 4 * trained / n
        return {"weights": weights, "grads": 2 * trained / n, "optimizer": 8 * trained / n}
    return {"weights": 4 * trained + 2 * frozen, "grads": 4 * trained, "optimizer": 8 * trained}


def table(model: torch.nn.Module, *, world_size: int, lora_rank: int) -> list[dict[str, Any]]:
    """Rows of the memory table of ``model`` (e.g. :func:`qwen2_5_vl_7b`) on ``world_size`` GPUs:
    DDP + LoRA of rank ``lora_rank`` (adapters only), DDP full (for comparison), FSDP full, ZeRO-2
    and ZeRO-3 full (language model and merger trained, vision tower frozen), in GB (1e9 bytes)."""
    c = counts(model, lora_rank=lora_rank)
    full = c["language"] + c["merger"]
    everything = c["vision"] + c["merger"] + c["language"]
    rows = []
    for label, launch, trained, frozen in (
        (f"DDP + LoRA r={lora_rank}", Launch("ddp", world_size, "bf16"), c["lora"], everything),
        ("DDP, full", Launch("ddp", world_size, "bf16"), full, c["vision"]),
        ("FSDP2, full", Launch("fsdp", world_size, "bf16", fsdp_version=2), full, c["vision"]),
        ("ZeRO-2, full", Launch("deepspeed", world_size, "bf16", zero_stage=2), full, c["vision"]),
        ("ZeRO-3, full", Launch("deepspeed", world_size, "bf16", zero_stage=3), full, c["vision"]),
    ):
        parts = _bytes(trained, frozen, launch)
        rows.append({"launch": label, "trained": trained, "frozen": frozen,
                     **{k: v / _GB for k, v in parts.items()}, "total": sum(parts.values()) / _GB})
    return rows


def markdown(rows: list[dict[str, Any]]) -> str:
    """``rows`` of :func:`table` as a Markdown table."""
    lines = ["| launch | trained | frozen | weights GB | grads GB | AdamW GB | total GB / GPU |",
             "|---|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        lines.append(f"| {r['launch']} | {r['trained'] / 1e9:.2f} B | {r['frozen'] / 1e9:.2f} B | {r['weights']:.1f} "
                     f"| {r['grads']:.1f} | {r['optimizer']:.1f} | **{r['total']:.1f}** |")
    return "\n".join(lines)


def main() -> None:
    """``python -m spacedg.sft.memory``: the table for Qwen2.5-VL-7B on 8 GPUs, LoRA rank from ``conf/model/base.yaml``."""
    from hydra import compose, initialize_config_module

    with initialize_config_module(config_module="spacedg.conf", version_base="1.3"):
        rank = int(compose("sft").model.lora_r)
    meta = qwen2_5_vl_7b()
    c = counts(meta, lora_rank=rank)
    print("Qwen2.5-VL-7B-Instruct parameters:", {k: f"{v / 1e6:.1f}M" for k, v in c.items()})
    print(markdown(table(meta, world_size=8, lora_rank=rank)))


if __name__ == "__main__":
    main()

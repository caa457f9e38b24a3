"""The paper's two 8B models with their published sizes, on the ``meta`` device, and the memory per GPU
of the paper's run (``+experiment=paper``: FSDP2 on 8 GPUs, vision tower frozen, activation checkpointing).

``python -m spacedg.sft.paper_models`` prints the table of ``docs/training.md``. The parameter shapes
come from the models' ``config.json`` (Qwen/Qwen3-VL-8B-Instruct, OpenGVLab/InternVL3_5-8B-HF);
building them on ``meta`` allocates nothing, and :func:`spacedg.sft.memory.counts` counts them (the
totals are checked against the published 8.77 B and 8.5 B in the tests).

Activations with checkpointing (one micro-batch of ``T`` tokens, bf16, ``L`` decoder layers of width
``h`` and MLP width ``i``): the hidden state kept at every layer boundary, ``2 L T h`` bytes, plus
one layer being recomputed and back-propagated, about ``2 × 2 T (6 h + 3 i)`` bytes (q/k/v/o,
norms and residuals ~6h, gate/up/activation 3i per token, and their gradients). The frozen vision
tower keeps no activations (no gradient flows into it); the logits are computed at the supervised
positions only (``trim_logits``).
"""

from __future__ import annotations

from typing import Any

import torch

from spacedg.sft.distributed import Launch
from spacedg.sft.memory import _GB, _bytes, counts

__all__ = ["INTERNVL3_5_8B", "QWEN3_VL_8B", "activation_bytes", "internvl3_5_8b", "main", "paper_rows", "qwen3_vl_8b"]

_QWEN3_8B_TEXT = {"hidden_size": 4096, "intermediate_size": 12288, "num_hidden_layers": 36, "num_attention_heads": 32,
                  "num_key_value_heads": 8, "head_dim": 128, "vocab_size": 151936, "rms_norm_eps": 1e-6,
                  "max_position_embeddings": 40960, "tie_word_embeddings": False}

#: Qwen/Qwen3-VL-8B-Instruct's config.json (the values that set parameter shapes).
QWEN3_VL_8B: dict[str, Any] = {
    "text_config": {**_QWEN3_8B_TEXT, "max_position_embeddings": 262144,
                    "rope_parameters": {"rope_type": "default", "rope_theta": 5000000.0, "mrope_section": [24, 20, 20],
                                        "mrope_interleaved": True}},
    "vision_config": {"depth": 27, "hidden_size": 1152, "intermediate_size": 4304, "num_heads": 16, "out_hidden_size": 4096,
                      "patch_size": 16, "spatial_merge_size": 2, "temporal_patch_size": 2, "num_position_embeddings": 2304,
                      "deepstack_visual_indexes": [8, 16, 24], "in_channels": 3, "hidden_act": "gelu_pytorch_tanh"},
    "tie_word_embeddings": False, "image_token_id": 151655, "video_token_id": 151656,
    "vision_start_token_id": 151652, "vision_end_token_id": 151653,
}

#: OpenGVLab/InternVL3_5-8B-HF's config.json (InternViT-300M + Qwen3-8B, pixel-shuffle 0.5 projector).
INTERNVL3_5_8B: dict[str, Any] = {
    "text_config": {**_QWEN3_8B_TEXT, "model_type": "qwen3"},
    "vision_config": {"hidden_size": 1024, "intermediate_size": 4096, "num_hidden_layers": 24, "num_attention_heads": 16,
                      "image_size": [448, 448], "patch_size": [14, 14], "use_qk_norm": False, "norm_type": "layer_norm",
                      "layer_scale_init_value": 0.1, "use_mean_pooling": True},
    "downsample_ratio": 0.5, "projector_hidden_act": "gelu", "vision_feature_layer": -1,
    "image_token_id": 151671, "tie_word_embeddings": False,
}


def qwen3_vl_8b() -> torch.nn.Module:
    """Qwen3-VL-8B-Instruct's architecture with its published sizes, on the ``meta`` device."""
    from transformers import Qwen3VLConfig, Qwen3VLForConditionalGeneration

    with torch.device("meta"):
        return Qwen3VLForConditionalGeneration(Qwen3VLConfig(**QWEN3_VL_8B))


def internvl3_5_8b() -> torch.nn.Module:
    """InternVL3.5-8B's architecture (transformers format) with its published sizes, on the ``meta`` device."""
    from transformers import InternVLConfig, InternVLForConditionalGeneration

    with torch.device("meta"):
        return InternVLForConditionalGeneration(InternVLConfig(**INTERNVL3_5_8B))


def activation_bytes(tokens: int, layers: int, hidden: int, intermediate: int) -> int:
    """Activation bytes of one micro-batch of ``tokens`` tokens with activation checkpointing (module doc)."""
    return int(2 * layers * tokens * hidden + 2 * 2 * tokens * (6 * hidden + 3 * intermediate))


def paper_rows(model: torch.nn.Module, text: dict[str, Any], *, world_size: int = 8,
               tokens: tuple[int, ...] = (12_000, 32_768)) -> list[dict[str, Any]]:
    """The paper run's memory per GPU in GB (1e9 bytes) for ``model`` under FSDP2 on ``world_size`` GPUs:
    weights, gradients, AdamW states (language model and merger trained, vision tower frozen), FSDP's
    two bf16 all-gathered units in flight, and the activations of a micro-batch of each of ``tokens``."""
    c = counts(model, lora_rank=None)
    trained, frozen = c["language"] + c["merger"], c["vision"]
    parts = _bytes(trained, frozen, Launch("fsdp", world_size, "bf16", fsdp_version=2))
    state = {k: v / _GB for k, v in parts.items()}
    gathered = 2 * 2 * c["unit"] / _GB
    rows = []
    for t in tokens:
        act = activation_bytes(t, text["num_hidden_layers"], text["hidden_size"], text["intermediate_size"]) / _GB
        rows.append({"tokens": t, **state, "gathered": gathered, "activations": act,
                     "total": sum(state.values()) + gathered + act, "trained": trained, "frozen": frozen, "unit": c["unit"]})
    return rows


def main() -> None:
    """``python -m spacedg.sft.paper_models``: parameter counts and the memory table of the paper's run."""
    print("| model | micro-batch tokens | weights GB | grads GB | AdamW GB | gathered units GB | activations GB | total GB / GPU |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    for name, build, config in (("Qwen3-VL-8B-Instruct", qwen3_vl_8b, QWEN3_VL_8B), ("InternVL3.5-8B", internvl3_5_8b, INTERNVL3_5_8B)):
        model = build()
        c = counts(model, lora_rank=None)
        print(f"<!-- {name}: " + ", ".join(f"{k} {v / 1e6:.1f}M" for k, v in c.items()) + f", total {sum(c[k] for k in ('vision', 'merger', 'language')) / 1e9:.2f}B -->")
        for r in paper_rows(model, config["text_config"]):
            print(f"| {name} | {r['tokens']:,} | {r['weights']:.1f} | {r['grads']:.1f} | {r['optimizer']:.1f} | {r['gathered']:.1f} "
                  f"| {r['activations']:.1f} | **{r['total']:.1f}** |")


if __name__ == "__main__":
    main()

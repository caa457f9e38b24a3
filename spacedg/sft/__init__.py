"""Supervised fine-tuning of VLMs on SpaceDG samples (``python -m spacedg.sft +experiment=qwen``).

Modules: :mod:`~spacedg.sft.app` (the Hydra app), :mod:`~spacedg.sft.config` (config groups →
objects with ``hydra.utils.instantiate``), :mod:`~spacedg.sft.model` (model options, freezing, LoRA,
checkpoint export), :mod:`~spacedg.sft.sources` (data options: what trains and what evaluates),
:mod:`~spacedg.sft.data` (samples and the token budget),
:mod:`~spacedg.sft.collator` (assistant-only labels, trimmed logits, filler batches),
:mod:`~spacedg.sft.loss` (the loss normalised over the optimizer step), :mod:`~spacedg.sft.trainer`
(strict resume under every launch, ``final/`` export, generation-based evaluation),
:mod:`~spacedg.sft.distributed` (what differs between one process, DDP, FSDP and ZeRO),
:mod:`~spacedg.sft.memory` (memory per GPU from parameter counts), :mod:`~spacedg.sft.template`
(chat template with answer markers).
"""

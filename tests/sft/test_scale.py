"""SFT at scale, in one process: the step-normalised loss (gradient accumulation = a larger batch),
over-long batches, storage dtypes and mixed precision, the LoRA parameter sets, the wrap policy and
the memory formulas (checked against the bytes the tiny models really hold; the sharded launches
are checked under torchrun in test_distributed.py)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from transformers import TrainingArguments

from spacedg.data.chat import chat_messages
from spacedg.sft.collator import IGNORE_INDEX, SFTCollator
from spacedg.sft.distributed import Launch, local_bytes, wrap_classes
from spacedg.sft.loss import count_items, sample_loss, token_loss
from spacedg.sft.memory import counts, memory_for, qwen2_5_vl_7b, table
from spacedg.sft.model import module_groups, prepare_model, storage_dtypes
from spacedg.sft.trainer import SFTTrainer
from spacedg.vlm import TINY_FAMILIES, build_tiny_vlm
from tests.sft.configs import model_options

# answers of different lengths (an MCQ letter to a size list), so the weighting of samples matters
ANSWERS = ["<answer>A</answer>", "<answer>0.75, 1.5, 2.25, 3.0, 4.5</answer>", "<answer>no</answer>",
           "<answer>12 meters, about 3 chairs</answer>"]


def _samples(n: int = 4) -> list[dict]:
    rng = np.random.default_rng(0)
    return [{"conversation": chat_messages(f"Question {i}: how far is the chair?", 1, answer=ANSWERS[i % len(ANSWERS)]),
             "images": [rng.integers(0, 256, (48, 64, 3), dtype=np.uint8)], "degradation_type": "ori"} for i in range(n)]


def _train(tmp_path, batch: int, accumulation: int, loss: str | None) -> tuple[list[float], dict[str, torch.Tensor]]:
    """Two optimizer steps of the tiny Qwen2.5-VL through SFTTrainer; (logged losses, trained weights)."""
    torch.manual_seed(0)
    model, processor = prepare_model(model_options())
    args = TrainingArguments(output_dir=str(tmp_path / f"b{batch}g{accumulation}{loss}"), per_device_train_batch_size=batch,
                             gradient_accumulation_steps=accumulation, max_steps=2, learning_rate=1e-3, warmup_steps=0,
                             lr_scheduler_type="constant", weight_decay=0.0, logging_steps=1, save_strategy="no",
                             report_to="none", use_cpu=True, seed=0, remove_unused_columns=False, disable_tqdm=True)
    trainer = SFTTrainer(model=model, args=args, train_dataset=_samples(),
                         data_collator=SFTCollator(processor, 4096, trim_logits=loss is not None), val_items=[],
                         processor=processor, val_max_new_tokens=1, val_batch_size=1, loss=loss)
    trainer.train()
    losses = [e["loss"] for e in trainer.state.log_history if "loss" in e]
    return losses, {n: p.detach().clone() for n, p in model.named_parameters() if p.requires_grad}


def test_gradient_accumulation_equals_a_larger_batch(tmp_path) -> None:
    results = {(b, g, loss): _train(tmp_path, b, g, loss) for loss in ("tokens", "samples", None) for b, g in ((2, 1), (1, 2))}
    for loss in ("tokens", "samples"):
        (big_losses, big), (acc_losses, acc) = results[(2, 1, loss)], results[(1, 2, loss)]
        assert np.allclose(big_losses, acc_losses, rtol=0, atol=2e-5), (loss, big_losses, acc_losses)
        # float noise only: AdamW turns tiny gradient differences of near-zero entries into ~1e-6 steps
        assert max(float((big[n] - acc[n]).abs().max()) for n in big) < 1e-5, loss
    assert not np.allclose(results[(2, 1, "tokens")][0], results[(2, 1, "samples")][0], atol=1e-4)  # two weightings
    # the model's own loss (transformers' handling of these classes) is not invariant
    (stock_big, stock_big_w), (stock_acc, stock_acc_w) = results[(2, 1, None)], results[(1, 2, None)]
    assert abs(stock_big[1] - stock_acc[1]) > 1e-3
    assert max(float((stock_big_w[n] - stock_acc_w[n]).abs().max()) for n in stock_big_w) > 1e-4


def _logits(labels: torch.Tensor, vocab: int = 11, seed: int = 0) -> torch.Tensor:
    return torch.randn(*labels.shape, vocab, generator=torch.Generator().manual_seed(seed), requires_grad=True)


def test_losses_by_hand_trimmed_logits_and_empty_batches() -> None:
    labels = torch.full((2, 7), IGNORE_INDEX)
    labels[0, 5:7] = torch.tensor([3, 4])
    labels[1, 3:7] = torch.tensor([1, 2, 3, 4])
    logits = _logits(labels)
    per_token = torch.nn.functional.cross_entropy(logits[:, :-1].reshape(-1, 11), labels[:, 1:].reshape(-1), reduction="none")
    per_token = per_token.reshape(2, 6)
    assert torch.isclose(token_loss({"logits": logits}, labels), per_token.sum() / 6)
    assert torch.isclose(token_loss({"logits": logits}, labels, num_items_in_batch=12), per_token.sum() / 12)
    means = per_token[0, 4:].mean() + per_token[1, 2:].mean()
    assert torch.isclose(sample_loss({"logits": logits}, labels), means / 2)
    assert int(count_items(labels, "tokens")) == 6 and int(count_items(labels, "samples")) == 2
    # logits of the last K positions only (logits_to_keep): the same loss
    kept = logits[:, -5:]
    assert torch.isclose(token_loss({"logits": kept}, labels), per_token.sum() / 6)
    with pytest.raises(ValueError, match="drops supervised positions"):
        token_loss({"logits": logits[:, -3:]}, labels)
    # a batch without supervised tokens (a filler) trains nothing
    empty = torch.full((1, 5), IGNORE_INDEX)
    logits = _logits(empty)
    for fn in (token_loss, sample_loss):
        loss = fn({"logits": logits}, empty, num_items_in_batch=torch.tensor(0))
        loss.backward()
        assert float(loss.detach()) == 0.0 and float(logits.grad.abs().sum()) == 0.0


def test_an_over_long_batch_of_one_becomes_a_filler() -> None:
    model, processor = prepare_model(model_options())
    sample = _samples(1)[0]
    full = SFTCollator(processor, 4096, trim_logits=True)([sample])
    length = int(full["attention_mask"].sum())
    collator = SFTCollator(processor, length - 1, trim_logits=True)
    batch = collator([sample])  # batch size 1, over the budget: no error, a filler
    assert collator.dropped == 1 and collator.fillers == 1
    assert (batch["labels"] == IGNORE_INDEX).all() and "pixel_values" in batch  # the vision tower still runs
    inputs = {k: v for k, v in batch.items() if k != "labels"}
    loss = token_loss(model(**inputs), batch["labels"], num_items_in_batch=torch.tensor(0))
    loss.backward()
    assert float(loss.detach()) == 0.0
    assert all(p.grad is None or float(p.grad.abs().sum()) == 0.0 for p in model.parameters())
    # a fitting batch carries logits_to_keep covering every supervised position
    kept = full["logits_to_keep"]
    first = int((full["labels"][0] != IGNORE_INDEX).nonzero()[0])
    assert kept == full["input_ids"].shape[1] - first + 1
    out = model(**{k: v for k, v in full.items() if k != "labels"})
    reference = model(**{k: v for k, v in full.items() if k not in ("labels", "logits_to_keep")})
    assert out.logits.shape[1] == kept
    assert torch.allclose(token_loss(out, full["labels"]), token_loss(reference, full["labels"]), atol=1e-6)


# ------------------------------------------------------------------------------------------ what trains


def _trained(model) -> dict[str, set[str]]:
    """Trainable parameter kinds per group: "lora", "copy" (peft modules_to_save) or "full"."""
    groups = module_groups(model)
    out: dict[str, set[str]] = {}
    for name, param in model.named_parameters():
        if param.requires_grad:
            group = next(g for g, prefixes in groups.items() if any(name == p or name.startswith(p + ".") for p in prefixes))
            kind = "lora" if ".lora_" in name else "copy" if ".modules_to_save." in name else "full"
            out.setdefault(group, set()).add(kind)
    return out


@pytest.mark.parametrize(("flags", "expected"), [
    ({}, {"merger": {"full"}, "language": {"full"}}),
    ({"lora": True}, {"language": {"lora"}}),
    ({"lora": True, "freeze_merger": False}, {"language": {"lora"}, "merger": {"copy"}}),
    ({"lora": True, "freeze_vision": False}, {"language": {"lora"}, "vision": {"copy"}}),
    ({"lora": True, "freeze_merger": True}, {"language": {"lora"}}),
    ({"freeze_merger": True}, {"language": {"full"}}),
    ({"freeze_language": True}, {"merger": {"full"}}),
])
def test_lora_trains_what_its_flags_say(flags, expected) -> None:
    model, _ = prepare_model(model_options("tiny:qwen2_vl", **flags))
    assert _trained(model) == expected


def test_storage_dtypes_per_launch() -> None:
    f32, bf16 = torch.float32, torch.bfloat16
    assert storage_dtypes("auto") == (f32, f32)
    assert storage_dtypes("auto", "bf16") == (f32, bf16)            # one process / DDP: frozen weights in bf16
    assert storage_dtypes("auto", "bf16", shards_parameters=True) == (f32, f32)  # FSDP / ZeRO-3
    assert storage_dtypes("bfloat16", "bf16") == (bf16, bf16)
    model, _ = prepare_model(model_options(lora=True), mixed_precision="bf16")
    for name, param in model.named_parameters():
        assert param.dtype == (f32 if param.requires_grad else bf16), name
    model, _ = prepare_model(model_options(), mixed_precision="bf16", shards_parameters=True)
    assert {p.dtype for p in model.parameters()} == {f32}


def _changed_share(dtype: str) -> float:
    """Share of the trained values that moved in 4 AdamW steps at lr 1e-5 under bf16 autocast."""
    torch.manual_seed(0)
    model, processor = prepare_model(model_options(dtype=dtype), mixed_precision="bf16")
    batch = SFTCollator(processor, 4096, trim_logits=True)(_samples(2))
    labels = batch.pop("labels")
    params = [p for p in model.parameters() if p.requires_grad]
    before = [p.detach().clone() for p in params]
    optimizer = torch.optim.AdamW(params, lr=1e-5, weight_decay=0.0)
    for _ in range(4):
        with torch.autocast("cpu", dtype=torch.bfloat16):
            loss = token_loss(model(**batch), labels)
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
    changed = sum(int((p.detach() != b).sum()) for p, b in zip(params, before))
    return changed / sum(p.numel() for p in params)


def test_fp32_master_weights_keep_small_updates() -> None:
    master, pure = _changed_share("auto"), _changed_share("bfloat16")
    assert master > 0.8 and pure < 0.5 and master > 2 * pure, (master, pure)


@pytest.mark.parametrize("family", TINY_FAMILIES)
def test_wrap_classes_are_the_decoder_layers_and_vision_blocks(family) -> None:
    model, _ = build_tiny_vlm(family)
    classes = wrap_classes(model)
    assert set(classes) == set(model._no_split_modules) and len(classes) == 2
    lora, _ = prepare_model(model_options(f"tiny:{family}", lora=True))
    assert wrap_classes(lora) == classes


# ------------------------------------------------------------------------------------------ memory


def test_qwen2_5_vl_7b_memory_table() -> None:
    meta = qwen2_5_vl_7b()
    c = counts(meta, lora_rank=16)
    assert round(c["vision"] / 1e6, 1) == 632.0 and round(c["merger"] / 1e6, 1) == 44.6
    assert round(c["language"] / 1e6, 1) == 7615.6 and round(c["lora"] / 1e6, 1) == 40.4
    assert c["merger"] > c["lora"]  # the issue: the merger as modules_to_save outweighs the r=16 adapters
    rows = {r["launch"]: r for r in table(meta, world_size=8, lora_rank=16)}
    assert rows["DDP, full"]["total"] > 120  # does not fit on 80 GB: weights 32 + grads 31 + AdamW 61
    for launch in ("DDP + LoRA r=16", "FSDP2, full", "ZeRO-3, full"):
        assert rows[launch]["total"] < 40, rows[launch]
    assert abs(rows["FSDP2, full"]["total"] - 16 * (c["language"] + c["merger"]) / 8e9 - 4 * c["vision"] / 8e9) < 1e-6


@pytest.mark.parametrize(("options", "precision"), [({}, "no"), ({"lora": True, "freeze_merger": False}, "bf16")])
def test_memory_formulas_match_the_bytes_held(options, precision) -> None:
    model, processor = prepare_model(model_options(**options), mixed_precision=precision)
    launch = Launch("single", 1, precision)
    predicted = memory_for(model, launch)
    batch = SFTCollator(processor, 4096, trim_logits=True)(_samples(2))
    labels = batch.pop("labels")
    optimizer = torch.optim.AdamW([p for p in model.parameters() if p.requires_grad], lr=1e-4)
    with torch.autocast("cpu", dtype=torch.bfloat16, enabled=precision == "bf16"):
        loss = token_loss(model(**batch), labels)
    loss.backward()
    optimizer.step()
    measured = local_bytes(model.parameters(), optimizer)
    assert {k: measured[k] for k in predicted} == predicted
    trained = sum(p.numel() for p in model.parameters() if p.requires_grad)
    frozen = sum(p.numel() for p in model.parameters() if not p.requires_grad)
    half = 2 if precision == "bf16" else 4
    assert predicted == {"params": 4 * trained + half * frozen, "grads": 4 * trained, "optimizer": 8 * trained}


def test_bf16_export_of_a_mixed_precision_model(tmp_path) -> None:
    from safetensors.torch import load_file

    from spacedg.sft.model import save_for_inference

    for lora in (False, True):
        model, processor = prepare_model(model_options(lora=lora), mixed_precision="bf16")
        dtypes = {n: p.dtype for n, p in model.named_parameters()}
        out = save_for_inference(model, processor, tmp_path / f"final-{lora}", save_dtype=torch.bfloat16)
        assert {t.dtype for t in load_file(str(out / "model.safetensors")).values()} == {torch.bfloat16}
        assert '"dtype": "bfloat16"' in (out / "config.json").read_text()
        assert {n: p.dtype for n, p in model.named_parameters()} == dtypes  # the training model is untouched


def test_fsdp_reduces_gradients_in_fp32() -> None:
    from accelerate.utils import FullyShardedDataParallelPlugin

    from spacedg.sft.distributed import reduce_in_fp32

    plugin = FullyShardedDataParallelPlugin(fsdp_version=2)
    plugin.set_mixed_precision("bf16")
    assert plugin.mixed_precision_policy.reduce_dtype == torch.bfloat16  # accelerate's own
    assert reduce_in_fp32(plugin) and not reduce_in_fp32(plugin)
    policy = plugin.mixed_precision_policy
    assert (policy.param_dtype, policy.reduce_dtype) == (torch.bfloat16, torch.float32)
    assert not reduce_in_fp32(FullyShardedDataParallelPlugin(fsdp_version=2))  # no mixed precision: nothing to do


def test_the_launch_is_read_from_the_training_arguments(tmp_path) -> None:
    from spacedg.sft.distributed import launch_of

    def args(**kw):
        return TrainingArguments(output_dir=str(tmp_path), use_cpu=True, report_to="none", **kw)

    assert launch_of(args()) == Launch("single", 1, "no")
    assert launch_of(args(bf16=True)).mixed_precision == "bf16"
    fsdp = launch_of(args(fsdp=True, fsdp_config={"version": 2}))
    assert (fsdp.name, fsdp.shards_parameters) == ("fsdp2", True)
    assert launch_of(args(fsdp=True, fsdp_config={"version": 1})).name == "fsdp1"
    assert not Launch("deepspeed", 8, "bf16", zero_stage=2).shards_parameters
    assert Launch("deepspeed", 8, "bf16", zero_stage=3).shards_parameters

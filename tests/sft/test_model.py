"""spacedg.sft.model: parameter groups, freezing, LoRA on the language model only, checkpointing, saving."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from spacedg.errors import InvalidDataError, ParameterError
from spacedg.sft.model import (
    ModelOptions,
    drop_vision_input_grad_hooks,
    module_groups,
    prepare_model,
    save_for_inference,
    trainable_summary,
)
from spacedg.vlm import (
    TINY_FAMILIES,
    build_tiny_vlm,
    encode_chats,
    load_vlm,
    save_tiny_vlm,
)
from tests.sft.configs import model_options

IMAGE = np.random.default_rng(0).integers(0, 256, (64, 64, 3), dtype=np.uint8)
CHAT = [
    {"role": "user", "content": [{"type": "image"}, {"type": "text", "text": "Is the chair on the left?"}]},
    {"role": "assistant", "content": "<answer>yes</answer>"},
]


def _batch(processor) -> dict:
    """One conversation with one 64×64 image; labels = input_ids."""
    batch = dict(encode_chats(processor, [CHAT], [[IMAGE]], add_generation_prompt=False))
    batch["labels"] = batch["input_ids"].clone()
    return batch


def _group_of(name: str, groups: dict[str, list[str]]) -> list[str]:
    return [g for g, prefixes in groups.items() if any(name == p or name.startswith(p + ".") for p in prefixes)]


def _snapshot(model) -> dict[str, torch.Tensor]:
    return {n: p.detach().clone() for n, p in model.named_parameters()}


def _train(model, processor, steps: int = 3) -> None:
    batch = _batch(processor)
    params = [p for p in model.parameters() if p.requires_grad]
    optimizer = torch.optim.AdamW(params, lr=1e-2, weight_decay=0.0)
    model.train()
    for _ in range(steps):
        optimizer.zero_grad()
        loss = model(**batch).loss
        assert torch.isfinite(loss)
        loss.backward()
        optimizer.step()


def _logits(model, batch) -> torch.Tensor:
    model.eval()
    with torch.no_grad():
        return model(**{k: v for k, v in batch.items() if k != "labels"}).logits


def _lora_modules(model) -> list[str]:
    return [n for n, m in model.named_modules() if hasattr(m, "lora_A")]


# ------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("family", TINY_FAMILIES)
def test_groups_partition_the_parameters(family):
    model, _ = build_tiny_vlm(family)
    groups = module_groups(model)
    assert set(groups) == {"vision", "merger", "language"}
    counts = dict.fromkeys(groups, 0)
    for name, _ in model.named_parameters():
        owners = _group_of(name, groups)
        assert len(owners) == 1, (name, owners)
        counts[owners[0]] += 1
    assert all(counts.values()), counts
    merger = {"internvl": ["model.multi_modal_projector"],
              "qwen3_vl": ["model.visual.merger", "model.visual.deepstack_merger_list"]}.get(family, ["model.visual.merger"])
    assert groups["merger"] == merger
    assert groups["language"] == ["model.language_model", "lm_head"]
    assert not any("merger" in p or "projector" in p for p in groups["vision"])
    # the same partition on the peft-wrapped model (names under base_model.model.)
    lora_model, _ = prepare_model(model_options(f"tiny:{family}", lora=True))
    wrapped = module_groups(lora_model)
    assert all(len(_group_of(n, wrapped)) == 1 for n, _ in lora_model.named_parameters())


@pytest.mark.parametrize("family", TINY_FAMILIES)
def test_default_options_freeze_vision_and_train_merger_and_language(family):
    model, processor = prepare_model(model_options(f"tiny:{family}"))
    assert model.training
    groups = module_groups(model)
    before = _snapshot(model)
    for name, param in model.named_parameters():
        assert param.requires_grad == (_group_of(name, groups) != ["vision"]), name
    summary = trainable_summary(model)
    assert summary["vision"]["trainable"] == 0 and summary["vision"]["total"] > 0
    assert summary["merger"]["trainable"] == summary["merger"]["total"] > 0
    assert summary["language"]["trainable"] == summary["language"]["total"] > 0
    assert summary["all"]["total"] == sum(p.numel() for p in model.parameters())

    _train(model, processor)
    for name, param in model.named_parameters():
        if param.requires_grad:
            assert not torch.equal(param, before[name]), f"{name} did not change"
        else:
            assert param.grad is None and torch.equal(param, before[name]), f"{name} changed"


@pytest.mark.parametrize("family", TINY_FAMILIES)
def test_lora_wraps_only_the_language_model_and_keeps_base_weights(family):
    model, processor = prepare_model(model_options(f"tiny:{family}", lora=True, lora_dropout=0.0))
    from peft import PeftModel

    assert isinstance(model, PeftModel)
    groups = module_groups(model)
    wrapped = _lora_modules(model)
    # 2 layers × (q, k, v, o, gate, up, down); nothing in the vision tower or merger, no lm_head
    assert len(wrapped) == 14
    assert all(_group_of(n, groups) == ["language"] and ".layers." in n for n in wrapped)
    suffixes = {n.rsplit(".", 1)[-1] for n in wrapped}
    assert suffixes == {"q_proj", "k_proj", "v_proj", "o_proj", "gate_proj", "up_proj", "down_proj"}

    # trainable: the LoRA matrices only (freeze_merger: auto freezes the merger under LoRA); the
    # vision tower, the merger and the LM base are frozen
    trainable = [n for n, p in model.named_parameters() if p.requires_grad]
    assert any("lora_A" in n for n in trainable) and any("lora_B" in n for n in trainable)
    for name in trainable:
        assert (".lora_A." in name or ".lora_B." in name) and _group_of(name, groups) == ["language"], name
    summary = trainable_summary(model)
    assert summary["vision"]["trainable"] == 0
    assert 0 < summary["language"]["trainable"] < summary["language"]["total"] // 4

    before = _snapshot(model)
    _train(model, processor)
    after = dict(model.named_parameters())
    for name, param in after.items():
        if not param.requires_grad:
            assert torch.equal(param, before[name]), f"frozen {name} changed"
    assert all(not torch.equal(after[n], before[n]) for n in trainable if ".lora_B." in n)


def test_lora_trains_an_unfrozen_merger_and_vision_tower_as_copies():
    model, processor = prepare_model(model_options("tiny:qwen2_5_vl", lora=True, freeze_merger=False))
    groups = module_groups(model)
    merger = [n for n, p in model.named_parameters() if p.requires_grad and _group_of(n, groups) == ["merger"]]
    assert merger and all(".modules_to_save.default." in n for n in merger)
    model, processor = prepare_model(model_options("tiny:qwen2_5_vl", lora=True, freeze_vision=False))
    groups = module_groups(model)
    vision = [n for n, p in model.named_parameters() if p.requires_grad and _group_of(n, groups) == ["vision"]]
    assert vision and all(".modules_to_save.default." in n for n in vision)
    _train(model, processor, steps=1)


def test_custom_lora_target_must_stay_in_the_language_model():
    model, _ = prepare_model(model_options("tiny:internvl", lora=True, lora_target=r".*language_model.*\.(q_proj|v_proj)"))
    assert len(_lora_modules(model)) == 4
    # InternVL's vision tower has q_proj / k_proj / v_proj too: an unanchored list must be refused
    with pytest.raises(ParameterError, match="outside the language model"):
        prepare_model(model_options("tiny:internvl", lora=True, lora_target=r".*\.(q_proj|v_proj)"))
    with pytest.raises(ParameterError, match="matches no linear layer"):
        prepare_model(model_options("tiny:qwen2_vl", lora=True, lora_target=r"nothing\.here"))


def _grads(options: ModelOptions, lora_b: float | None = None) -> tuple[dict[str, torch.Tensor], object]:
    torch.manual_seed(0)
    model, processor = prepare_model(options)
    if lora_b is not None:  # non-zero lora_B so that lora_A gets a gradient too
        generator = torch.Generator().manual_seed(1)
        with torch.no_grad():
            for name, param in model.named_parameters():
                if ".lora_B." in name:
                    param.copy_(torch.randn(param.shape, generator=generator) * lora_b)
    model.train()
    loss = model(**_batch(processor)).loss
    loss.backward()
    return {n: p.grad.clone() for n, p in model.named_parameters() if p.requires_grad}, model


@pytest.mark.parametrize(("family", "options"), [
    ("qwen2_5_vl", {"lora": True, "lora_dropout": 0.0}),
    ("internvl", {"lora": True, "lora_dropout": 0.0}),
    ("qwen3_vl", {"freeze_language": True}),  # only the merger trains: grads must cross frozen embeddings + LM
])
def test_gradient_checkpointing_matches_plain_backward(family, options):
    plain, _ = _grads(model_options(f"tiny:{family}", **options), lora_b=0.1 if options.get("lora") else None)
    checkpointed, model = _grads(model_options(f"tiny:{family}", gradient_checkpointing=True, **options),
                                 lora_b=0.1 if options.get("lora") else None)
    base = model.get_base_model() if hasattr(model, "get_base_model") else model
    assert not any(p.requires_grad for p in base.get_input_embeddings().parameters())
    assert base.is_activation_checkpointing and base.config.use_cache is False
    assert base.config.get_text_config().use_cache is False
    assert plain.keys() == checkpointed.keys() and plain
    for name in plain:
        assert torch.allclose(plain[name], checkpointed[name], atol=1e-6, rtol=1e-5), name
    assert any(g.abs().sum() > 0 for g in checkpointed.values())


@pytest.mark.parametrize("family", TINY_FAMILIES)
@pytest.mark.parametrize("lora", [False, True])
def test_frozen_vision_tower_is_not_recorded_by_autograd(family, lora):
    # enable_input_require_grads (transformers, and peft again) also hooks the vision patch embedding
    model, processor = prepare_model(model_options(f"tiny:{family}", lora=lora, gradient_checkpointing=True))
    groups = module_groups(model)
    merger = dict(model.named_modules())[groups["merger"][0]]
    seen: list[bool] = []
    merger.register_forward_pre_hook(lambda module, args: seen.append(args[0].requires_grad))
    model(**_batch(processor)).loss.backward()
    assert seen == [False]
    # re-enabling checkpointing (as the HF Trainer does with activation_checkpointing=True) hooks it again
    base = model.get_base_model() if lora else model
    base.activation_checkpointing_enable(activation_checkpointing_kwargs={"use_reentrant": False})
    assert drop_vision_input_grad_hooks(model) == (0 if family == "qwen3_vl" else 1)


@pytest.mark.parametrize("family", ["qwen2_vl", "internvl"])
def test_save_for_inference_merges_a_copy(family, tmp_path):
    options = model_options(f"tiny:{family}", lora=True, lora_dropout=0.0, gradient_checkpointing=True,
                           min_pixels=28 * 28 * 4, max_pixels=28 * 28 * 4 * 4)
    model, processor = prepare_model(options)
    _train(model, processor, steps=2)
    batch = _batch(processor)
    expected = _logits(model, batch)
    state = _snapshot(model)
    out = save_for_inference(model, processor, tmp_path / "merged")
    assert (out / "config.json").is_file() and not (out / "adapter_config.json").exists()
    assert json.loads((out / "config.json").read_text()).get("text_config", {}).get("use_cache", True) is True

    loaded, loaded_processor = load_vlm(out)
    assert not _lora_modules(loaded) and type(loaded).__name__.endswith("ForConditionalGeneration")
    assert torch.allclose(_logits(loaded, batch), expected, atol=1e-5, rtol=1e-5)
    assert loaded_processor.image_processor.size == processor.image_processor.size
    if family != "internvl":
        assert dict(loaded_processor.image_processor.size) == {"shortest_edge": 28 * 28 * 4,
                                                                "longest_edge": 28 * 28 * 4 * 4}

    # the training model is untouched: still peft, adapters unmerged, same weights
    from peft import PeftModel

    assert isinstance(model, PeftModel)
    wrapped = dict(model.named_modules())
    assert _lora_modules(model) and not any(wrapped[n].merged for n in _lora_modules(model))
    after = dict(model.named_parameters())
    assert after.keys() == state.keys() and all(torch.equal(after[n], state[n]) for n in state)
    assert torch.allclose(_logits(model, batch), expected, atol=0, rtol=0)


def test_save_for_inference_of_a_fully_trained_model(tmp_path):
    model, processor = prepare_model(model_options("tiny:qwen3_vl", gradient_checkpointing=True))
    _train(model, processor, steps=1)
    batch = _batch(processor)
    expected = _logits(model, batch)
    loaded, _ = load_vlm(save_for_inference(model, processor, tmp_path / "full"))
    assert torch.allclose(_logits(loaded, batch), expected, atol=1e-5, rtol=1e-5)
    assert model.config.get_text_config().use_cache is False  # the training model's config is restored


def test_adapter_folder_loads_through_load_vlm(tmp_path):
    base = save_tiny_vlm(tmp_path / "base", "qwen2_5_vl")
    model, processor = prepare_model(model_options(str(base), lora=True, lora_dropout=0.0))
    _train(model, processor, steps=2)
    batch = _batch(processor)
    expected = _logits(model, batch)
    model.save_pretrained(tmp_path / "adapter")  # peft: adapter_config.json + adapter weights only
    assert not (tmp_path / "adapter" / "config.json").exists()
    loaded, loaded_processor = load_vlm(tmp_path / "adapter")
    assert not _lora_modules(loaded)
    assert torch.allclose(_logits(loaded, batch), expected, atol=1e-5, rtol=1e-5)
    assert loaded_processor.tokenizer.get_vocab() == processor.tokenizer.get_vocab()

    config = json.loads((tmp_path / "adapter" / "adapter_config.json").read_text())
    config["base_model_name_or_path"] = str(tmp_path / "gone")
    (tmp_path / "adapter" / "adapter_config.json").write_text(json.dumps(config))
    with pytest.raises(InvalidDataError, match="base model folder .*gone.* does not exist"):
        load_vlm(tmp_path / "adapter")


@pytest.mark.parametrize(("kwargs", "message"), [
    ({"freeze_vision": True, "freeze_merger": True, "freeze_language": True}, "nothing to train"),
    ({"path": "tiny:llava"}, "unknown tiny model"),
    ({"path": ""}, "model path is empty"),
    ({"dtype": "float64x"}, "unknown dtype"),
    ({"lora": True, "lora_r": 0}, "lora_r must be"),
    ({"lora": True, "lora_dropout": 1.0}, "lora_dropout must be"),
    ({"lora": True, "lora_alpha": -1}, "lora_alpha must be"),
    ({"lora_target": r".*q_proj"}, "lora_target is set .* but lora is false"),
    ({"lora": True, "lora_target": "(unclosed"}, "not a valid regex"),
    ({"min_pixels": 4096, "max_pixels": 1024}, "min_pixels"),
    ({"max_pixels": 0}, "max_pixels must be a positive"),
    ({"lora": "yes"}, "lora must be true or false"),
    ({"freeze_merger": "sometimes"}, "freeze_merger must be true, false or auto"),
])
def test_bad_options_are_refused(kwargs, message):
    kwargs = {"path": "tiny:qwen2_vl", **kwargs}
    with pytest.raises(ParameterError, match=message):
        model_options(**kwargs)


def test_lora_with_everything_frozen_is_fine():
    options = model_options("tiny:qwen2_vl", lora=True, freeze_vision=True, freeze_merger=True, freeze_language=True)
    model, _ = prepare_model(options)
    assert all(".lora_" in n for n, p in model.named_parameters() if p.requires_grad)


def test_hub_id_paths_go_through_snapshot_download(tmp_path, monkeypatch):
    import huggingface_hub

    folder = save_tiny_vlm(tmp_path / "snapshot", "qwen2_vl")
    calls: list[str] = []

    def fake_download(repo_id, **kwargs):
        calls.append(repo_id)
        if repo_id != "Org/Tiny-VL":
            raise OSError("repository not found")
        return str(folder)

    monkeypatch.setattr(huggingface_hub, "snapshot_download", fake_download)
    model, _ = prepare_model(model_options("Org/Tiny-VL"))
    assert calls == ["Org/Tiny-VL"] and type(model).__name__ == "Qwen2VLForConditionalGeneration"
    with pytest.raises(ParameterError, match="not a local folder and could not be fetched"):
        prepare_model(model_options("Org/Missing"))
    with pytest.raises(InvalidDataError, match="does not exist"):  # not hub-shaped: the local-folder error
        prepare_model(model_options(str(tmp_path / "no" / "such" / "folder")))
    assert calls == ["Org/Tiny-VL", "Org/Missing"]


@pytest.mark.filterwarnings("ignore:Could not find a config file in tiny:UserWarning")  # the base is rebuilt in code
def test_adapter_of_a_tiny_model_built_in_code_loads(tmp_path):
    model, processor = prepare_model(model_options("tiny:internvl", lora=True, lora_dropout=0.0))
    _train(model, processor, steps=2)
    batch = _batch(processor)
    expected = _logits(model, batch)
    model.save_pretrained(tmp_path / "adapter")
    assert json.loads((tmp_path / "adapter" / "adapter_config.json").read_text())["base_model_name_or_path"] == "tiny:internvl"
    loaded, loaded_processor = load_vlm(tmp_path / "adapter")
    assert torch.allclose(_logits(loaded, batch), expected, atol=1e-5, rtol=1e-5)
    assert loaded_processor.tokenizer.padding_side == "left"

"""spacedg.vlm: tiny real VLMs built offline, save/reload, chat encoding, batched generation."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from spacedg.errors import InvalidDataError, ParameterError
from spacedg.vlm import (
    TINY_FAMILIES,
    build_tiny_vlm,
    encode_chats,
    generate,
    load_processor,
    load_vlm,
    save_tiny_vlm,
    to_pil,
)

RNG = np.random.default_rng(0)
IMAGES = [RNG.integers(0, 256, (64, 64, 3), dtype=np.uint8) for _ in range(3)]


def _user(n_images: int, text: str) -> dict:
    return {"role": "user", "content": [*({"type": "image"} for _ in range(n_images)), {"type": "text", "text": text}]}


#: A batch mixing 2, 1 and 0 images, list and string content, with and without system messages.
CHATS = [
    [{"role": "system", "content": [{"type": "text", "text": "Answer briefly."}]}, _user(2, "Did the camera turn left?")],
    [_user(1, "Is the chair on the left? Answer yes or no.")],
    [{"role": "system", "content": "You are a helpful assistant."}, {"role": "user", "content": "How many chairs?"}],
]
CHAT_IMAGES = [IMAGES[:2], [IMAGES[2]], []]


@pytest.fixture(scope="module", params=TINY_FAMILIES)
def tiny(request, tmp_path_factory):
    """(family, built model, built processor, folder, reloaded model, reloaded processor)."""
    family = request.param
    model, processor = build_tiny_vlm(family, seed=0)
    folder = save_tiny_vlm(tmp_path_factory.mktemp(family) / "model", family, seed=0)
    loaded, loaded_processor = load_vlm(folder)
    return family, model, processor, folder, loaded, loaded_processor


def test_reload_gives_same_weights_and_processor(tiny):
    _family, model, processor, _, loaded, loaded_processor = tiny
    assert type(loaded) is type(model) and not loaded.training
    reference, state = model.state_dict(), loaded.state_dict()
    assert reference.keys() == state.keys()
    assert all(torch.equal(reference[k], state[k]) for k in reference)
    assert type(loaded_processor) is type(processor)
    assert loaded_processor.chat_template == processor.chat_template
    assert loaded_processor.tokenizer.get_vocab() == processor.tokenizer.get_vocab()
    assert loaded_processor.tokenizer.eos_token == "<|im_end|>" and loaded_processor.tokenizer.pad_token == "<|endoftext|>"
    a = encode_chats(processor, CHATS, CHAT_IMAGES)
    b = encode_chats(loaded_processor, CHATS, CHAT_IMAGES)
    assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)


def test_special_tokens_pinned_in_real_order(tiny):
    family, _, processor, *_ = tiny
    tok = processor.tokenizer
    ids = tok.convert_tokens_to_ids(["<|endoftext|>", "<|im_start|>", "<|im_end|>", "<|vision_start|>",
                                     "<|vision_end|>", "<|vision_pad|>", "<|image_pad|>", "<|video_pad|>"])
    assert ids == sorted(ids) and ids[1] == ids[0] + 1 and ids[2] == ids[0] + 2 and ids[-1] == ids[-2] + 1
    assert (tok.eos_token_id, tok.pad_token_id) == (ids[2], ids[0])
    if family == "internvl":
        assert tok.convert_tokens_to_ids(["<img>", "</img>", "<IMG_CONTEXT>", "<video>"]) == list(range(ids[-1] + 1, ids[-1] + 5))


def test_generate_mixed_batch_is_deterministic_and_equals_one_by_one(tiny):
    _, _, _, _, model, processor = tiny
    batched = generate(model, processor, CHATS, CHAT_IMAGES, max_new_tokens=6)
    assert len(batched) == 3 and all(isinstance(text, str) for text in batched)
    assert generate(model, processor, CHATS, CHAT_IMAGES, max_new_tokens=6) == batched
    singles = [generate(model, processor, [chat], [imgs], max_new_tokens=6)[0] for chat, imgs in zip(CHATS, CHAT_IMAGES)]
    assert singles == batched
    # Stronger than equal strings: the next-token logits of each left-padded row equal the
    # unpadded ones (padding, attention mask and (m)RoPE position ids are right).
    with torch.inference_mode():
        rows = model(**encode_chats(processor, CHATS, CHAT_IMAGES)).logits[:, -1]
        for k, (chat, imgs) in enumerate(zip(CHATS, CHAT_IMAGES)):
            alone = model(**encode_chats(processor, [chat], [imgs])).logits[0, -1]
            torch.testing.assert_close(rows[k], alone, atol=1e-4, rtol=1e-4)


def test_encode_chats_left_pads_and_counts_images(tiny):
    _, _, processor, *_ = tiny
    batch = encode_chats(processor, CHATS, CHAT_IMAGES)
    mask = batch["attention_mask"]
    assert mask[:, -1].all() and not mask[2, 0]  # the text-only row is the shortest: padded on the left
    assert (batch["input_ids"][mask == 0] == processor.tokenizer.pad_token_id).all()
    assert encode_chats(processor, CHATS[2:], [[]]).keys().isdisjoint({"pixel_values"})
    with pytest.raises(ParameterError, match="conversation 1 has 1 image entries but 0 images"):
        encode_chats(processor, CHATS, [CHAT_IMAGES[0], [], []])
    with pytest.raises(ParameterError, match="image lists"):
        encode_chats(processor, CHATS, CHAT_IMAGES[:2])


def test_assistant_mask_decodes_to_exactly_the_answers(tiny):
    _, _, processor, *_ = tiny
    answer = "<answer>left</answer>"
    chats = [
        [*CHATS[0], {"role": "assistant", "content": [{"type": "text", "text": answer}]}],
        [*CHATS[2], {"role": "assistant", "content": "There are 2 chairs."},
         {"role": "user", "content": [{"type": "text", "text": "And tables?"}]},
         {"role": "assistant", "content": [{"type": "text", "text": "no"}]}],
    ]
    batch = encode_chats(processor, chats, [CHAT_IMAGES[0], []], add_generation_prompt=False, return_assistant_mask=True)
    tok = processor.tokenizer
    masks = batch["assistant_masks"].bool()
    assert tok.decode(batch["input_ids"][0][masks[0]]) == answer + "<|im_end|>"
    assert tok.decode(batch["input_ids"][1][masks[1]]) == "There are 2 chairs.<|im_end|>no<|im_end|>"
    assert not (masks & (batch["attention_mask"] == 0)).any()
    # The mask path tokenizes exactly as the plain path (mixed 2, 1, 0 images included).
    plain = encode_chats(processor, CHATS, CHAT_IMAGES)
    masked = encode_chats(processor, CHATS, CHAT_IMAGES, return_assistant_mask=True)
    assert all(torch.equal(plain[k], masked[k]) for k in plain) and not masked["assistant_masks"].any()


def test_pixel_budget(tiny):
    family, _, _, folder, *_ = tiny
    small, large = load_processor(folder), load_processor(folder, min_pixels=100 * 100, max_pixels=200 * 200)
    count = {name: encode_chats(p, CHATS[1:2], CHAT_IMAGES[1:2])["input_ids"].shape[1] for name, p in
             (("small", small), ("large", large))}
    assert count["large"] > count["small"]
    if family == "internvl":
        assert (large.image_processor.min_patches, large.image_processor.max_patches) == (9, 39)
    else:
        assert dict(large.image_processor.size) == {"shortest_edge": 100 * 100, "longest_edge": 200 * 200}
    with pytest.raises(ParameterError, match="min_pixels"):
        load_processor(folder, min_pixels=10, max_pixels=5)


def test_build_is_deterministic_and_keeps_global_rng():
    torch.manual_seed(123)
    expected = torch.rand(3)
    torch.manual_seed(123)
    a, _ = build_tiny_vlm("qwen2_5_vl", seed=1)
    assert torch.equal(torch.rand(3), expected)
    b, processor = build_tiny_vlm("qwen2_5_vl", seed=1)
    assert processor.tokenizer.get_vocab() == build_tiny_vlm("qwen2_5_vl", seed=2)[1].tokenizer.get_vocab()
    c, _ = build_tiny_vlm("qwen2_5_vl", seed=2)
    name = "lm_head.weight"
    assert torch.equal(a.state_dict()[name], b.state_dict()[name])
    assert not torch.equal(a.state_dict()[name], c.state_dict()[name])
    with pytest.raises(ParameterError, match="unknown tiny VLM family"):
        build_tiny_vlm("llava")


def test_to_pil_accepts_arrays_and_tensors():
    image = IMAGES[0]
    assert np.array_equal(np.asarray(to_pil(image)), image)
    assert np.array_equal(np.asarray(to_pil(torch.from_numpy(image).permute(2, 0, 1))), image)
    with pytest.raises(InvalidDataError, match="uint8"):
        to_pil(image.astype(np.float32))


def test_load_vlm_names_the_problem(tmp_path):
    with pytest.raises(InvalidDataError, match="does not exist"):
        load_vlm(tmp_path / "missing")
    with pytest.raises(InvalidDataError, match="no config.json"):
        load_vlm(tmp_path)
    (tmp_path / "config.json").write_text(json.dumps({"model_type": "bert"}))
    with pytest.raises(InvalidDataError, match="cannot load an image-text-to-text model"):
        load_vlm(tmp_path)

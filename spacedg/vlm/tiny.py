"""Real transformers VLMs with tiny dimensions, built fully offline (tests and smoke runs).

:func:`build_tiny_vlm` returns the real model class of a family (Qwen2-VL, Qwen2.5-VL, Qwen3-VL,
InternVL) with random weights and a few thousand parameters per layer, and the family's real
processor class around

* a real ``Qwen2Tokenizer`` (the Qwen pre-tokenizer, byte-level BPE) whose vocab is the 256
  byte symbols plus about 200 merges learned in-process from :data:`_CORPUS`, followed by the
  Qwen-VL special tokens in their real order (``<|endoftext|>`` first, ...,
  ``<|video_pad|>`` last; InternVL appends ``<img>``, ``</img>``, ``<IMG_CONTEXT>``, ``<video>``);
  eos ``<|im_end|>``, pad ``<|endoftext|>``;
* a PIL image processor with a small pixel budget (a 64×64 image becomes 4 image tokens);
* :data:`CHAT_TEMPLATE`, a Qwen2.5-VL-style template whose assistant answers (with their
  ``<|im_end|>``) are inside ``{% generation %}`` blocks, so
  ``apply_chat_template(..., return_assistant_tokens_mask=True)`` marks exactly the supervised
  tokens.

The weights are a deterministic function of ``seed``; the global torch RNG state is restored
afterwards. Nothing is downloaded. :func:`save_tiny_vlm` writes a folder that
:func:`spacedg.vlm.load_vlm` reloads.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import torch

from spacedg.errors import ParameterError
from spacedg.vlm.processor import assemble_processor

__all__ = ["CHAT_TEMPLATE", "IMAGE_PLACEHOLDERS", "TINY_FAMILIES", "build_tiny_vlm", "save_tiny_vlm"]

#: Families :func:`build_tiny_vlm` can build (transformers ``model_type`` names).
TINY_FAMILIES = ("qwen2_vl", "qwen2_5_vl", "qwen3_vl", "internvl")

#: The Qwen-VL special tokens, in the order of the real tokenizers (ids 151643…151656 there).
QWEN_SPECIAL_TOKENS = (
    "<|endoftext|>", "<|im_start|>", "<|im_end|>", "<|object_ref_start|>", "<|object_ref_end|>",
    "<|box_start|>", "<|box_end|>", "<|quad_start|>", "<|quad_end|>", "<|vision_start|>",
    "<|vision_end|>", "<|vision_pad|>", "<|image_pad|>", "<|video_pad|>",
)
#: Extra special tokens of InternVL (named attributes its processor reads from the tokenizer).
INTERNVL_TOKENS = {
    "start_image_token": "<img>", "end_image_token": "</img>",
    "context_image_token": "<IMG_CONTEXT>", "video_token": "<video>",
}

#: Text the tiny BPE merges are learned from: words of spatial questions and answers.
_CORPUS = """\
Look at the image and answer the question. The answer is yes. The answer is no.
<answer>left</answer> <answer>right</answer> <answer>yes</answer> <answer>no</answer>
Is the chair to the left or to the right of the table? The chair is on the left.
Which object is closer to the camera? The sofa is closer than the lamp.
How many chairs are in the image? There are 2 chairs. There are 3 cups and 4 books.
How far is the bed from the camera in meters? About 1.5 meters. About 0.75 meters.
Did the camera move forward or backward between the two images? It moved forward.
Did the camera turn left or right? It turned right by 30 degrees.
Which direction is north of the door: front, back, left or right? The answer is front.
Is the image blurry, dark, hazy or clean? The first image is clean, the second is noisy.
Options: A. left B. right C. front D. back. Answer with the option letter. Answer: A
0 1 2 3 4 5 6 7 8 9 10 20 50 100 degrees meters object objects view views camera
You are a helpful assistant. Think step by step, then give the final answer.
"""

#: Qwen2.5-VL-style chat template. ``{image}`` is replaced by the family's image placeholder.
#: Supports system messages (a default one is added when the first message is not one), string
#: content, content lists of ``{"type": "image"}`` / ``{"type": "text", "text": ...}`` entries,
#: and ``add_generation_prompt``; assistant answers and their ``<|im_end|>`` are generation blocks.
CHAT_TEMPLATE = (
    "{% for message in messages %}"
    "{% if loop.first and message['role'] != 'system' %}"
    "<|im_start|>system\nYou are a helpful assistant.<|im_end|>\n"
    "{% endif %}"
    "<|im_start|>{{ message['role'] }}\n"
    "{% if message['content'] is string %}{% set text = message['content'] %}"
    "{% else %}{% set text = namespace(value='') %}"
    "{% for part in message['content'] %}"
    "{% if part['type'] == 'image' or 'image' in part %}{% set text.value = text.value + '{image}' %}"
    "{% elif part['type'] == 'text' %}{% set text.value = text.value + part['text'] %}{% endif %}"
    "{% endfor %}{% set text = text.value %}{% endif %}"
    "{% if message['role'] == 'assistant' %}"
    "{% generation %}{{ text }}<|im_end|>{% endgeneration %}{{ '\\n' }}"
    "{% else %}{{ text }}<|im_end|>\n{% endif %}"
    "{% endfor %}"
    "{% if add_generation_prompt %}<|im_start|>assistant\n{% endif %}"
)
#: Image placeholder of each family in the chat template (the processor expands it).
IMAGE_PLACEHOLDERS = {"qwen": "<|vision_start|><|image_pad|><|vision_end|>", "internvl": "<IMG_CONTEXT>\n"}

_TEXT = {"hidden_size": 64, "intermediate_size": 128, "num_hidden_layers": 2, "num_attention_heads": 4,
         "num_key_value_heads": 2, "max_position_embeddings": 2048}


def _tokenizer(family: str) -> Any:
    """A ``Qwen2Tokenizer``: byte vocab + learned merges + pinned special tokens (see module doc)."""
    from tokenizers import Regex, Tokenizer, models, pre_tokenizers, trainers
    from transformers import Qwen2Tokenizer
    from transformers.models.qwen2.tokenization_qwen2 import PRETOKENIZE_REGEX

    bpe = Tokenizer(models.BPE())
    bpe.pre_tokenizer = pre_tokenizers.Sequence([
        pre_tokenizers.Split(Regex(PRETOKENIZE_REGEX), behavior="isolated"),
        pre_tokenizers.ByteLevel(add_prefix_space=False, use_regex=False),
    ])
    alphabet = pre_tokenizers.ByteLevel.alphabet()
    trainer = trainers.BpeTrainer(vocab_size=len(alphabet) + 200, initial_alphabet=alphabet, show_progress=False)
    bpe.train_from_iterator(_CORPUS.splitlines(), trainer)
    model = json.loads(bpe.to_str())["model"]
    vocab: dict[str, int] = dict(model["vocab"])
    merges = [tuple(m) if isinstance(m, list) else tuple(m.split(" ")) for m in model["merges"]]
    specials = list(QWEN_SPECIAL_TOKENS)
    extra: dict[str, str] = {}
    if family == "internvl":
        specials += list(INTERNVL_TOKENS.values())
        extra = dict(INTERNVL_TOKENS)
    for token in specials:
        vocab[token] = len(vocab)
    tokenizer = Qwen2Tokenizer(vocab=vocab, merges=merges, unk_token=None, eos_token="<|im_end|>",
                               pad_token="<|endoftext|>", extra_special_tokens=specials, **extra)
    return tokenizer


def _image_processor(family: str) -> Any:
    if family == "internvl":
        from transformers import GotOcr2ImageProcessorPil

        # One 32×32 tile per image (crop_to_patches is on in InternVLProcessor; max_patches=1
        # keeps a single tile and no thumbnail); 32/8 = 4×4 patches, pixel shuffle 0.5 → 4 tokens.
        return GotOcr2ImageProcessorPil(size={"height": 32, "width": 32}, max_patches=1,
                                        image_mean=[0.485, 0.456, 0.406], image_std=[0.229, 0.224, 0.225])
    from transformers import Qwen2VLImageProcessorPil

    patch = 16 if family == "qwen3_vl" else 14
    side = patch * 2  # one merged token covers 2×2 patches
    return Qwen2VLImageProcessorPil(patch_size=patch, merge_size=2, temporal_patch_size=2,
                                    size={"shortest_edge": side * side, "longest_edge": 4 * side * side})


def _model(family: str, tok: Any) -> Any:
    import transformers as tf

    ids = {name: tok.convert_tokens_to_ids(t) for name, t in (
        ("image_token_id", "<|image_pad|>"), ("video_token_id", "<|video_pad|>"),
        ("vision_start_token_id", "<|vision_start|>"), ("vision_end_token_id", "<|vision_end|>"))}
    text = dict(_TEXT, vocab_size=len(tok), bos_token_id=tok.convert_tokens_to_ids("<|endoftext|>"),
                eos_token_id=tok.eos_token_id, pad_token_id=tok.pad_token_id)
    if family == "internvl":
        vision = {"hidden_size": 32, "intermediate_size": 64, "num_hidden_layers": 2, "num_attention_heads": 2,
                  "image_size": [32, 32], "patch_size": [8, 8]}
        config = tf.InternVLConfig(vision_config=vision, text_config=dict(text, model_type="qwen2"),
                                   image_token_id=tok.context_image_token_id, image_seq_length=4,
                                   tie_word_embeddings=False)
        return tf.InternVLForConditionalGeneration(config)
    if family == "qwen3_vl":
        text.update(head_dim=16, rope_parameters={"rope_type": "default", "rope_theta": 10000.0,
                                                  "mrope_section": [4, 2, 2], "mrope_interleaved": True})
        vision = {"depth": 2, "hidden_size": 32, "intermediate_size": 64, "num_heads": 2, "patch_size": 16,
                  "out_hidden_size": 64, "num_position_embeddings": 16, "deepstack_visual_indexes": [0]}
        config = tf.Qwen3VLConfig(text_config=text, vision_config=vision, **ids)
        return tf.Qwen3VLForConditionalGeneration(config)
    text.update(rope_parameters={"rope_type": "default", "rope_theta": 10000.0, "mrope_section": [2, 3, 3]})
    if family == "qwen2_5_vl":
        vision = {"depth": 2, "hidden_size": 32, "intermediate_size": 64, "num_heads": 2, "out_hidden_size": 64,
                  "fullatt_block_indexes": [1], "window_size": 56}
        return tf.Qwen2_5_VLForConditionalGeneration(tf.Qwen2_5_VLConfig(text_config=text, vision_config=vision, **ids))
    vision = {"depth": 2, "embed_dim": 32, "hidden_size": 64, "num_heads": 2, "mlp_ratio": 2}
    return tf.Qwen2VLForConditionalGeneration(tf.Qwen2VLConfig(text_config=text, vision_config=vision, **ids))


def _processor(family: str, tok: Any) -> Any:
    import transformers as tf

    cls = {"qwen2_vl": tf.Qwen2VLProcessor, "qwen2_5_vl": tf.Qwen2_5_VLProcessor,
           "qwen3_vl": tf.Qwen3VLProcessor, "internvl": tf.InternVLProcessor}[family]
    placeholder = IMAGE_PLACEHOLDERS["internvl" if family == "internvl" else "qwen"]
    template = CHAT_TEMPLATE.replace("{image}", placeholder)
    extra = {"image_seq_length": 4} if family == "internvl" else {}
    # A placeholder video processor stands in for the torchvision-only real one (see loading.py).
    return assemble_processor(cls, tok, _image_processor(family), chat_template=template, **extra)


def build_tiny_vlm(family: str = "qwen2_5_vl", *, seed: int = 0) -> tuple[Any, Any]:
    """A tiny real ``(model, processor)`` of ``family`` (one of :data:`TINY_FAMILIES`), in eval mode.

    Text model: hidden 64, 2 layers, 4 heads (2 KV heads), vocab = the tiny tokenizer's size.
    Vision tower: 2 layers, hidden 32. The weights depend only on ``seed``.
    """
    if family not in TINY_FAMILIES:
        raise ParameterError(f"unknown tiny VLM family {family!r}; choose one of {', '.join(TINY_FAMILIES)}")
    tok = _tokenizer(family)
    state = torch.random.get_rng_state()
    try:
        torch.manual_seed(seed)
        model = _model(family, tok)
    finally:
        torch.random.set_rng_state(state)
    model.generation_config.eos_token_id = tok.eos_token_id
    model.generation_config.pad_token_id = tok.pad_token_id
    return model.eval(), _processor(family, tok)


def save_tiny_vlm(out_dir: str | Path, family: str = "qwen2_5_vl", *, seed: int = 0) -> Path:
    """Build a tiny VLM and ``save_pretrained`` its model and processor into ``out_dir``."""
    out = Path(out_dir)
    model, processor = build_tiny_vlm(family, seed=seed)
    model.save_pretrained(out)
    processor.save_pretrained(out)
    return out
